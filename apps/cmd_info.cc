// ptmkit info IN.ptm|IN.rti [--json]: what a texture file holds.
#include <cstdio>
#include <memory>
#include <string>

#include <nlohmann/json.hpp>

#include "commands.h"
#include "ptmkit/texture/ptm.h"
#include "ptmkit/texture/rti.h"
#include "ptmkit/texture/web_folder.h"

namespace ptmkit::app {

namespace {

struct InfoArgs {
  std::string input;
  bool json = false;
};

// An HSH .rti: its basis and the range of each term's coefficients over texels and channels.
void run_rti_info(const InfoArgs& args) {
  const texture::RtiSummary s = texture::summarise_rti(args.input);
  if (args.json) {
    nlohmann::json j;
    j["file"] = args.input;
    j["format"] = "RTI_HSH";
    j["hsh_order"] = s.order;
    j["terms"] = s.terms;
    j["width"] = s.width;
    j["height"] = s.height;
    j["coeff_min"] = s.coeff_min;
    j["coeff_max"] = s.coeff_max;
    j["file_bytes"] = s.file_bytes;
    j["file_bytes_per_texel"] = s.file_bytes_per_texel;
    j["map_bytes_per_texel"] = s.map_bytes_per_texel;
    std::printf("%s\n", j.dump(2).c_str());
    return;
  }
  std::printf("%s: RTI HSH order %d (%d terms per channel), %d x %d texels, %zu bytes\n",
              args.input.c_str(), s.order, s.terms, s.width, s.height, s.file_bytes);
  std::printf("  coefficients (normalised units, after the file's scale and bias):\n");
  std::printf("    term   min          max\n");
  for (std::size_t k = 0; k < s.coeff_min.size(); ++k) {
    std::printf("    h%-3zu  %11.5f  %11.5f\n", k, s.coeff_min[k], s.coeff_max[k]);
  }
  std::printf("  memory per texel: %d bytes in the file, %d bytes as floats in memory\n",
              s.file_bytes_per_texel, s.map_bytes_per_texel);
}

// A relight/OpenLIME web folder: its info.json, checked, and each plane's scale and bias.
void run_web_info(const InfoArgs& args) {
  const texture::WebFolderInfo w = texture::read_web_info(args.input);
  if (args.json) {
    nlohmann::json j;
    j["file"] = args.input;
    j["format"] = "web";
    j["type"] = w.type;
    j["colorspace"] = w.colorspace;
    j["layout"] = w.layout;
    j["width"] = w.width;
    j["height"] = w.height;
    j["nplanes"] = w.nplanes;
    j["jpegs"] = w.jpegs();
    j["quality"] = w.quality;
    j["scale"] = w.scale;
    j["bias"] = w.bias;
    j["pixel_size_mm"] = w.pixel_size_mm;
    j["lights"] = w.lights.size();
    if (w.layout == "deepzoom") {
      j["tile_size"] = w.tile_size;
      j["overlap"] = w.overlap;
    }
    std::printf("%s\n", j.dump(2).c_str());
    return;
  }
  std::printf("%s: web folder, type %s, colour space %s, layout %s, %d x %d texels\n",
              args.input.c_str(), w.type.c_str(), w.colorspace.c_str(), w.layout.c_str(), w.width,
              w.height);
  std::printf("  %d planes in %d JPEGs, quality %d", w.nplanes, w.jpegs(), w.quality);
  if (w.layout == "deepzoom") std::printf(", tiles %d px, overlap %d", w.tile_size, w.overlap);
  std::printf("\n");
  if (w.pixel_size_mm > 0) std::printf("  pixel size %.6g mm\n", w.pixel_size_mm);
  if (!w.lights.empty()) std::printf("  %zu capture lights listed\n", w.lights.size());
  std::printf("  planes (coefficient = (byte / 255 - bias) * scale):\n");
  std::printf("    plane      scale        bias\n");
  for (int k = 0; k < w.nplanes; ++k) {
    std::printf("    %5d  %10.6g  %10.6g\n", k, w.scale[static_cast<std::size_t>(k)],
                w.bias[static_cast<std::size_t>(k)]);
  }
}

void run_info(const InfoArgs& args) {
  if (texture::is_web_folder(args.input)) {
    run_web_info(args);
    return;
  }
  if (texture::looks_like_rti(args.input)) {
    run_rti_info(args);
    return;
  }
  const texture::PtmSummary s = texture::summarise_ptm(args.input);
  const texture::PtmInfo& info = s.info;
  const auto& q = info.quantisation;
  if (args.json) {
    nlohmann::json j;
    j["file"] = args.input;
    j["version"] = std::string(texture::to_string(info.version));
    j["format"] = std::string(info.format_line());
    if (info.compression == texture::PtmCompression::kJpeg) {
      j["jpeg_quality"] = info.compression_parameter;
    }
    j["width"] = info.width;
    j["height"] = info.height;
    j["scales"] = q.scales;
    j["biases"] = q.biases;
    j["coeff_min"] = s.coeff_min;
    j["coeff_max"] = s.coeff_max;
    j["representable_min"] = s.representable_min;
    j["representable_max"] = s.representable_max;
    j["file_bytes"] = info.file_bytes;
    j["header_bytes"] = info.header_bytes;
    j["data_bytes"] = info.data_bytes;
    j["trailing_bytes"] = info.trailing_bytes;
    j["file_bytes_per_texel"] = s.file_bytes_per_texel;
    j["map_bytes_per_texel"] = s.map_bytes_per_texel;
    std::printf("%s\n", j.dump(2).c_str());
    return;
  }
  std::printf("%s: %s %s, %d x %d texels\n", args.input.c_str(),
              std::string(texture::to_string(info.version)).c_str(),
              std::string(info.format_line()).c_str(), info.width, info.height);
  if (info.luminance_only) {
    std::printf(
        "  one luminance polynomial a texel, no colour: relit as grey (read as LRGB, white)\n");
  }
  if (info.compression == texture::PtmCompression::kJpeg) {
    std::printf("  JPEG planes, quality %d (read into the uncompressed layout)\n",
                info.compression_parameter);
  }
  std::printf("  %zu bytes: header %zu, data %zu, trailing %zu\n", info.file_bytes,
              info.header_bytes, info.data_bytes, info.trailing_bytes);
  std::printf("  coefficients in 0..255 units:\n");
  std::printf("    term       scale  bias   stored min   stored max   representable\n");
  for (int i = 0; i < kPtmTerms; ++i) {
    std::printf("    a%d  %10.6g  %4d  %11.4f  %11.4f   [%.3f, %.3f]\n", i, q.scales[i],
                q.biases[i], s.coeff_min[i], s.coeff_max[i], s.representable_min[i],
                s.representable_max[i]);
  }
  std::printf("  memory per texel: %d bytes in the file, %d bytes as floats in memory\n",
              s.file_bytes_per_texel, s.map_bytes_per_texel);
}

}  // namespace

void add_info_command(CLI::App& root) {
  auto args = std::make_shared<InfoArgs>();
  CLI::App* cmd = root.add_subcommand(
      "info",
      "Describe a .ptm (any readable variant), an HSH .rti or a relight/OpenLIME web folder: "
      "format, size, scales and biases or basis, coefficient ranges, memory.");
  cmd->add_option("input", args->input,
                  "Texture: .ptm, .rti, or a web folder (the folder or its info.json)")
      ->required();
  cmd->add_flag("--json", args->json, "Print JSON instead of text");
  cmd->callback([args] { run_info(*args); });
}

}  // namespace ptmkit::app
