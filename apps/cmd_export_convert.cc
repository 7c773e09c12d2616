// ptmkit export ptm|rti IN -o OUT [--format ...]: conversions between .ptm, .rti and web
// folders (texture/convert.h says which directions and why the others are refused).
#include <cstdio>
#include <memory>
#include <string>

#include "commands.h"
#include "ptmkit/texture/convert.h"

namespace ptmkit::app {

namespace {

struct ConvertArgs {
  std::string input;
  std::string output;
  texture::ConvertOptions options;
};

void print(const texture::ConvertReport& r) {
  std::printf("exported %s (%s) -> %s (%s), %zu bytes%s\n", r.input.string().c_str(),
              r.from.c_str(), r.output.string().c_str(), r.to.c_str(), r.file_bytes,
              r.bytes_kept ? "; coefficient bytes, scales and biases kept" : "");
  if (!r.quantisation.empty()) std::printf("  quantisation: %s\n", r.quantisation.c_str());
}

}  // namespace

void add_export_convert_commands(CLI::App& export_cmd) {
  {
    auto args = std::make_shared<ConvertArgs>();
    CLI::App* cmd = export_cmd.add_subcommand(
        "ptm",
        "Convert a .ptm (any readable variant) or a web folder of type ptm to a .ptm. The same "
        "colour model keeps the stored bytes, scales and biases; LRGB -> RGB and web folders are "
        "quantised; RGB -> LRGB and HSH sources are refused (lossy).");
    cmd->add_option("input", args->input,
                    "Source: .ptm, .rti, or a web folder (the folder or its info.json)")
        ->required();
    cmd->add_option("-o,--output", args->output, "Output .ptm (written atomically)")->required();
    cmd->add_option("--format", args->options.ptm_format,
                    "Target format: rgb, lrgb, jpeg-rgb or jpeg-lrgb (default: the source's "
                    "own)");
    cmd->add_option("--quality", args->options.jpeg_quality,
                    "JPEG quality 1..100 of jpeg-* targets (default: the source's own if it is "
                    "a JPEG .ptm, else 90)")
        ->check(CLI::Range(1, 100));
    cmd->add_flag("--integer-scales", args->options.write.integer_scales,
                  "Re-quantise with whole-number scales, so that readers which truncate "
                  "(byte - bias) * scale to an integer (RTIViewer) lose nothing to it; costs "
                  "precision in exact readers (docs/FORMATS.md)");
    cmd->callback(
        [args] { print(texture::convert_to_ptm(args->input, args->output, args->options)); });
  }
  {
    auto args = std::make_shared<ConvertArgs>();
    CLI::App* cmd = export_cmd.add_subcommand(
        "rti",
        "Convert an HSH .rti or a web folder of type hsh to an .rti (CRLF header lines, as "
        "CHI's tools write). Polynomial sources are refused (lossy).");
    cmd->add_option("input", args->input,
                    "Source: .rti, .ptm, or a web folder (the folder or its info.json)")
        ->required();
    cmd->add_option("-o,--output", args->output, "Output .rti (written atomically)")->required();
    cmd->callback(
        [args] { print(texture::convert_to_rti(args->input, args->output, args->options)); });
  }
}

}  // namespace ptmkit::app
