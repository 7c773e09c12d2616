// ptmkit info IN.ptm|IN.rti [--json]: what a texture file holds.
#include <cstdio>
#include <memory>
#include <string>

#include <nlohmann/json.hpp>

#include "commands.h"
#include "ptmkit/texture/ptm.h"
#include "ptmkit/texture/rti.h"

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

void run_info(const InfoArgs& args) {
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
    j["format"] = std::string(texture::to_string(info.format));
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
              std::string(texture::to_string(info.format)).c_str(), info.width, info.height);
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
      "Describe a .ptm or an HSH .rti: format, size, scales and biases or basis, coefficient "
      "ranges, memory.");
  cmd->add_option("input", args->input, "Texture file (.ptm or .rti)")->required();
  cmd->add_flag("--json", args->json, "Print JSON instead of text");
  cmd->callback([args] { run_info(*args); });
}

}  // namespace ptmkit::app
