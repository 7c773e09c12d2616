// ptmkit relight IN.ptm (--light x,y,z -o OUT.png | --lights TEST.lp --out-dir DIR): the
// texture lit from one direction, or from every light of a set, compared with its photos.
#include <charconv>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <memory>
#include <string>
#include <vector>

#include "commands.h"
#include "flags.h"
#include "ptmkit/core/error.h"
#include "ptmkit/core/image_io.h"
#include "ptmkit/core/light_set.h"
#include "ptmkit/texture/integer_model.h"
#include "ptmkit/texture/ptm.h"
#include "ptmkit/texture/ptm8.h"
#include "ptmkit/texture/relight.h"
#include "ptmkit/texture/rti.h"
#include "ptmkit/texture/texture_file.h"

namespace fs = std::filesystem;

namespace ptmkit::app {

namespace {

struct RelightArgs {
  std::string input;
  std::string light;
  std::string lights;
  std::string output;
  std::string out_dir;
  std::string report;
  std::string mask;
  std::string colour_space = "srgb";
  int bits = 8;
  bool no_clamp = false;
  bool integer = false;
};

void run_relight(const RelightArgs& args) {
  const bool one = !args.light.empty();
  if (one == !args.lights.empty()) {
    throw CLI::ValidationError("relight", "give either --light x,y,z or --lights FILE.lp");
  }
  if (one && args.output.empty()) {
    throw CLI::ValidationError("relight", "--light needs -o OUT (an image file)");
  }
  if (!one && args.out_dir.empty()) {
    throw CLI::ValidationError("relight", "--lights needs --out-dir DIR");
  }
  if (one && (!args.out_dir.empty() || !args.report.empty() || !args.mask.empty())) {
    throw CLI::ValidationError("relight", "--out-dir, --report and --mask go with --lights");
  }
  if (args.integer && (!one || args.no_clamp)) {
    throw CLI::ValidationError("relight", "--integer goes with --light and without --no-clamp");
  }
  ColourSpace space = ColourSpace::kSRGB;
  if (args.colour_space == "linear") {
    space = ColourSpace::kLinear;
  } else if (args.colour_space != "srgb") {
    throw CLI::ValidationError("relight", "--colour-space must be srgb or linear");
  }
  texture::RelightOptions relight_options;
  relight_options.clamp = !args.no_clamp;
  ImageWriteOptions write;
  write.format = args.bits == 16 ? PixelFormat::kU16 : PixelFormat::kU8;

  if (one) {
    Eigen::Vector3d dir = parse_vector3(args.light, "--light");
    try {
      dir = texture::normalised_light(dir);
    } catch (const Error& e) {
      throw Error(std::string("--light: ") + e.what());
    }
    const texture::LoadedTexture tex = texture::read_texture(args.input, space);
    if (tex.is_hsh) {
      if (args.integer) {
        throw Error(args.input + ": --integer needs a polynomial texture (it is " + tex.format +
                    ")");
      }
      const CoefficientMap& rti = tex.hsh;
      const Image image = texture::relight(rti, dir, relight_options);
      write_image(args.output, image.view(), write);
      std::printf("relit %s (%d x %d, HSH %d terms) from (%.4f, %.4f, %.4f): wrote %s\n",
                  args.input.c_str(), rti.width, rti.height, rti.terms(), dir.x(), dir.y(), dir.z(),
                  args.output.c_str());
      return;
    }
    const CoefficientMap& map = tex.ptm;
    if (dir.z() <= 0.0) {
      std::fprintf(stderr,
                   "ptmkit: warning: the light is at or below the horizon (z <= 0): "
                   "the image is black\n");
    }
    if (args.integer) {
      const texture::Ptm8Texture t = texture::quantise_ptm8(map);
      const Image image = texture::relight_integer(t, dir);
      write_image(args.output, image.view(), write);
      std::printf(
          "relit %s (%d x %d) from (%.4f, %.4f, %.4f) with the integer model (shifts "
          "high %d, mid %d, low %d): wrote %s\n",
          args.input.c_str(), map.width, map.height, dir.x(), dir.y(), dir.z(), t.shifts[0],
          t.shifts[1], t.shifts[2], args.output.c_str());
      return;
    }
    const Image image = texture::relight(map, dir, relight_options);
    write_image(args.output, image.view(), write);
    std::printf("relit %s (%d x %d) from (%.4f, %.4f, %.4f): wrote %s\n", args.input.c_str(),
                map.width, map.height, dir.x(), dir.y(), dir.z(), args.output.c_str());
    return;
  }

  const LightSet lights = read_lp(args.lights);
  texture::RelightSetOptions options;
  options.out_dir = args.out_dir;
  options.relight = relight_options;
  options.write = write;
  options.mask = args.mask;
  options.report_json = args.report;
  const texture::LoadedTexture tex = texture::read_texture(args.input, space);
  const texture::RelightSetReport report =
      tex.is_hsh ? texture::relight_light_set(tex.hsh, lights, options)
                 : texture::relight_light_set(tex.ptm, lights, options);
  for (const auto& e : report.entries) {
    if (e.compared) {
      std::printf("  %-32s PSNR %6.2f dB  mean abs %6.2f grey\n",
                  e.output.filename().string().c_str(), e.comparison.psnr_db,
                  e.comparison.mean_abs_grey);
    }
  }
  std::printf("relight: %s; images in %s\n", report.brief().c_str(), args.out_dir.c_str());
  if (!args.report.empty()) std::printf("report: %s\n", args.report.c_str());
}

}  // namespace

void add_relight_command(CLI::App& root) {
  auto args = std::make_shared<RelightArgs>();
  CLI::App* cmd = root.add_subcommand(
      "relight",
      "Relight a .ptm (any readable variant, JPEG included), an HSH .rti or a relight/OpenLIME "
      "web folder (the folder or its info.json): one image lit from --light x,y,z, or one image "
      "per light of a .lp "
      "(--lights) compared with that light's photo where it exists (PSNR, mean abs error).");
  cmd->add_option("input", args->input,
                  "Texture: .ptm, HSH .rti, or a web folder (its folder or info.json)")
      ->required();
  auto* light = cmd->add_option(
      "--light", args->light,
      "Direction toward the light, x,y,z in the light frame (x right, y up the image, z toward "
      "the camera); normalised. z <= 0 gives a black image; NaN or zero is an error");
  auto* lights =
      cmd->add_option("--lights", args->lights, "Light file (.lp): relight at each of its lights");
  light->excludes(lights);
  cmd->add_option("-o,--output", args->output,
                  "Output image for --light (.png, .tif, .exr; written atomically)");
  cmd->add_option("--out-dir", args->out_dir,
                  "Folder for the images of --lights, named as the .lp's images (created if "
                  "missing)");
  cmd->add_option("--report", args->report,
                  "JSON report for --lights: per-light and mean PSNR and mean abs error");
  cmd->add_option("--mask", args->mask,
                  "Mask image for --lights comparisons: only pixels > 0.5 count");
  cmd->add_option("--bits", args->bits, "Bits per sample of the written images: 8 or 16")
      ->check(CLI::IsMember({8, 16}))
      ->capture_default_str();
  cmd->add_option("--colour-space", args->colour_space,
                  "What the .ptm's values are (the format does not say): srgb or linear")
      ->capture_default_str();
  cmd->add_flag("--no-clamp", args->no_clamp,
                "Keep values outside [0, 1] (only useful with .exr output)");
  cmd->add_flag("--integer", args->integer,
                "Re-quantise into the seed paper's 8-bit scheme (three shifts, bias 127) and "
                "evaluate with the integer hardware model of docs/INTEGER-MODEL.md (with --light)");
  cmd->callback([args] { run_relight(*args); });
}

}  // namespace ptmkit::app
