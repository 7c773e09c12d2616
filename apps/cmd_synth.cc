// `ptmkit synth`: render a synthetic capture set with ground truth.
#include <cstdio>
#include <memory>
#include <optional>
#include <string>

#include "commands.h"
#include "ptmkit/core/error.h"
#include "ptmkit/core/parallel.h"
#include "ptmkit/synth/synth.h"

namespace ptmkit::app {

namespace {

struct SynthFlags {
  std::string out;
  std::string preset = "default";
  std::string scene;
  int size = 0;
  int width = 0;
  int height = 0;
  std::string lights;
  std::uint64_t seed = 1;
  int bits = 8;
  std::string format;
  double noise = 0.0;
  double exposure = 1.0;
  double ks = 0.0;
  double exponent = 0.0;
  double ambient = 0.0;
  double height_frac = 0.0;
  bool srgb = false;
  bool no_shadows = false;
  bool no_truth = false;
  int threads = 0;
  double dome_radius_mm = 0.0;
  double mm_per_px = 0.0;
  bool no_falloff = false;
};

}  // namespace

void add_synth_command(CLI::App& root) {
  auto flags = std::make_shared<SynthFlags>();
  CLI::App* cmd = root.add_subcommand(
      "synth",
      "Render a synthetic capture set with known ground truth: images, lights.lp, and truth/ "
      "(diffuse-only images, outlier labels, normals, albedo, height or polynomial "
      "coefficients) described by truth.json. Explicit flags override the preset.");
  cmd->add_option("--out", flags->out, "Output folder (created if missing)")->required();
  cmd->add_option("--preset", flags->preset,
                  "Preset: default (256x256 relief, ks 0.3, exponent 40, cast shadows, 8-bit "
                  "linear PNG, noise 1 grey level, dome49), matte (ks 0), glossy (ks 0.8, "
                  "exponent 100), tall (relief twice as high), ambient (ambient 0.1), "
                  "polynomial (64x64 exact biquadratic world, float EXR, no noise)")
      ->capture_default_str();
  auto* scene = cmd->add_option("--scene", flags->scene, "Scene: relief or polynomial");
  auto* size = cmd->add_option("--size", flags->size, "Image width and height, pixels (>= 8)");
  auto* width = cmd->add_option("--width", flags->width, "Image width, pixels (>= 8)");
  auto* height = cmd->add_option("--height", flags->height, "Image height, pixels (>= 8)");
  auto* lights = cmd->add_option(
      "--lights", flags->lights,
      "Light layout: icosa (40-light geodesic dome), dome49 (rings 10:18,30:12,50:10,70:8,90:1), "
      "rings:ELEV:COUNT[:AZIMUTH],... (degrees), or an .lp file (its directions)");
  auto* seed = cmd->add_option("--seed", flags->seed, "Seed of the scene and the noise");
  auto* bits = cmd->add_option("--bits", flags->bits,
                               "Bits per sample: 8, 16 (png, tif) or 32 (float: exr, tif)");
  auto* format = cmd->add_option("--format", flags->format,
                                 "Image file type: png, tif, exr or jpg (8-bit, quality 95)");
  auto* srgb = cmd->add_flag("--srgb", flags->srgb, "Encode images with the sRGB curve");
  auto* noise = cmd->add_option("--noise", flags->noise,
                                "Gaussian noise sigma in grey levels of the output bit depth "
                                "(1/255 for float)");
  auto* exposure = cmd->add_option("--exposure", flags->exposure,
                                   "Exposure: file value = exposure x radiance before encoding");
  auto* ks = cmd->add_option("--ks", flags->ks, "Blinn-Phong specular weight (white)");
  auto* exponent = cmd->add_option("--exponent", flags->exponent, "Blinn-Phong exponent");
  auto* ambient = cmd->add_option("--ambient", flags->ambient, "Ambient term, x albedo");
  auto* height_frac = cmd->add_option("--height-frac", flags->height_frac,
                                      "Relief height as a fraction of the width (default 0.10)");
  auto* no_shadows = cmd->add_flag("--no-shadows", flags->no_shadows, "Do not cast shadows");
  auto* no_truth =
      cmd->add_flag("--no-truth", flags->no_truth, "Write only the images and lights.lp");
  cmd->add_option("--threads", flags->threads, "Worker threads (0 = all cores)")
      ->capture_default_str();
  auto* dome_radius = cmd->add_option(
      "--dome-radius", flags->dome_radius_mm,
      "Near lights: dome radius in mm (0 = distant lights, the default). Each light sits at "
      "radius x direction above the plane centre; writes lights.json (positions) and "
      "plane.json beside lights.lp");
  auto* mm_per_px = cmd->add_option("--mm-per-px", flags->mm_per_px,
                                    "Scene scale on the sample plane, mm per pixel (default "
                                    "0.5: 256 px span 128 mm)");
  auto* no_falloff =
      cmd->add_flag("--no-falloff", flags->no_falloff, "Near lights: no inverse-square fall-off");

  cmd->callback([=]() {
    const SynthFlags& f = *flags;
    synth::SynthOptions o = synth::preset_options(f.preset);
    if (scene->count() > 0) o.scene = synth::parse_scene_kind(f.scene);
    if (size->count() > 0) o.width = o.height = f.size;
    if (width->count() > 0) o.width = f.width;
    if (height->count() > 0) o.height = f.height;
    if (lights->count() > 0) o.lights = f.lights;
    if (seed->count() > 0) o.seed = f.seed;
    if (format->count() > 0) {
      o.sensor.file_type = synth::parse_file_type(f.format);
      // A float-only or 8-bit-only type picks its depth unless --bits says otherwise.
      if (bits->count() == 0 && o.sensor.file_type == synth::FileType::kExr) o.sensor.bits = 32;
      if (bits->count() == 0 && o.sensor.file_type == synth::FileType::kJpeg) o.sensor.bits = 8;
      if (bits->count() == 0 && o.sensor.file_type == synth::FileType::kPng &&
          o.sensor.bits == 32) {
        o.sensor.bits = 16;
      }
    }
    if (bits->count() > 0) {
      o.sensor.bits = f.bits;
      if (format->count() == 0 && f.bits == 32) o.sensor.file_type = synth::FileType::kExr;
      if (format->count() == 0 && f.bits != 32 && o.sensor.file_type == synth::FileType::kExr) {
        o.sensor.file_type = synth::FileType::kPng;
      }
    }
    if (srgb->count() > 0) o.sensor.srgb = f.srgb;
    if (noise->count() > 0) o.sensor.noise_sigma_grey = f.noise;
    if (exposure->count() > 0) o.sensor.exposure = f.exposure;
    if (ks->count() > 0) o.material.ks = f.ks;
    if (exponent->count() > 0) o.material.exponent = f.exponent;
    if (ambient->count() > 0) o.material.ambient = f.ambient;
    if (height_frac->count() > 0) o.relief.relief_height_frac = f.height_frac;
    if (no_shadows->count() > 0) o.cast_shadows = false;
    if (no_truth->count() > 0) o.write_truth = false;
    if (dome_radius->count() > 0) o.dome_radius_mm = f.dome_radius_mm;
    if (mm_per_px->count() > 0) o.mm_per_px = f.mm_per_px;
    if (no_falloff->count() > 0) o.inverse_square_falloff = false;
    if (f.threads < 0) throw Error("synth: --threads must be >= 0");

    ThreadLimit limit(f.threads);
    const synth::SynthReport report = synth::render_capture(o, f.out);
    std::printf("synth: wrote %d images (%dx%d, %s %s) to %s in %.2f s\n", report.images,
                report.width, report.height, o.preset.c_str(),
                std::string(synth::to_string(o.scene)).c_str(), report.folder.string().c_str(),
                report.seconds);
  });
}

}  // namespace ptmkit::app
