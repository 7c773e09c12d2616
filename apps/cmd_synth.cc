// `ptmkit synth`: render a synthetic capture set with ground truth.
#include <cmath>
#include <cstdio>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "commands.h"
#include "ptmkit/core/error.h"
#include "ptmkit/core/parallel.h"
#include "ptmkit/synth/photo.h"
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
  // Photo presets.
  std::string spheres_material;
  int sphere_count = 0;
  std::string environment;
  int windows = 0;
  int lamps = 0;
  std::string distractor;
  int jpeg_quality = 92;
  int flare_spokes = 6;
  double flare_strength = 0.0;
  double vignetting = 0.0;
  double exposure_jitter_ev = 0.0;
  double shake_px = 0.0;
  double focal_px = 0.0;
  double light_radius_deg = 0.0;
  int supersample = 4;
};

// Photo-only flags: the options they set.
struct PhotoFlagOptions {
  CLI::Option* spheres_material = nullptr;
  CLI::Option* sphere_count = nullptr;
  CLI::Option* no_bases = nullptr;
  CLI::Option* no_object = nullptr;
  CLI::Option* environment = nullptr;
  CLI::Option* windows = nullptr;
  CLI::Option* lamps = nullptr;
  CLI::Option* no_scene_reflections = nullptr;
  CLI::Option* distractor = nullptr;
  CLI::Option* no_flare = nullptr;
  CLI::Option* flare_spokes = nullptr;
  CLI::Option* flare_strength = nullptr;
  CLI::Option* no_bloom = nullptr;
  CLI::Option* no_vignetting = nullptr;
  CLI::Option* vignetting = nullptr;
  CLI::Option* no_noise = nullptr;
  CLI::Option* exposure_jitter = nullptr;
  CLI::Option* shake = nullptr;
  CLI::Option* jpeg_quality = nullptr;
  CLI::Option* focal_px = nullptr;
  CLI::Option* light_radius = nullptr;
  CLI::Option* supersample = nullptr;
  CLI::Option* no_exif = nullptr;
  [[nodiscard]] std::vector<CLI::Option*> all() const {
    return {spheres_material, sphere_count,  no_bases,     no_object,
            environment,      windows,       lamps,        no_scene_reflections,
            distractor,       no_flare,      flare_spokes, flare_strength,
            no_bloom,         no_vignetting, vignetting,   no_noise,
            focal_px,         light_radius,  supersample,  no_exif,
            exposure_jitter,  shake};
  }
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
  cmd->add_option(
         "--preset", flags->preset,
         "Preset: default (256x256 relief, ks 0.3, exponent 40, cast shadows, 8-bit "
         "linear PNG, noise 1 grey level, dome49), matte (ks 0), glossy (ks 0.8, "
         "exponent 100), tall (relief twice as high), ambient (ambient 0.1), "
         "polynomial (64x64 exact biquadratic world, float EXR, no noise); photographs of a "
         "capture with calibration spheres (docs/SYNTH.md): photo-dome (640x360 sRGB "
         "JPEG, the relief between two black glossy spheres on cups, a coin, dark cloth "
         "and room, flare, bloom, vignetting, noise, 22 lights), photo-glass (glass "
         "marbles), photo-chrome (chrome spheres, a dish), photo-large-sphere (one "
         "black glossy sphere filling the frame on a pedestal, dark room, 8-spoke "
         "star flares, 12 lights)")
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
  auto* jpeg_quality = cmd->add_option("--jpeg-quality", flags->jpeg_quality,
                                       "JPEG quality 1..100 (relief presets: 95; photo presets: "
                                       "92)");
  PhotoFlagOptions p;
  p.spheres_material = cmd->add_option("--spheres-material", flags->spheres_material,
                                       "Photo presets: every sphere's material: black-glossy, "
                                       "chrome or glass");
  p.sphere_count = cmd->add_option("--spheres", flags->sphere_count,
                                   "Photo presets: keep the first N of the preset's spheres");
  p.no_bases = cmd->add_flag("--no-bases")
                   ->description("Photo presets: no cups or pedestals under the spheres");
  p.no_object =
      cmd->add_flag("--no-object")->description("Photo presets: no relief object on the ground");
  p.environment = cmd->add_option("--environment", flags->environment,
                                  "Photo presets: the room, dark (default) or lit");
  p.windows = cmd->add_option("--windows", flags->windows,
                              "Photo presets: bright windows in the room, 0..8 (default 2)");
  p.lamps = cmd->add_option("--lamps", flags->lamps,
                            "Photo presets: lamps in the room, 0..8 (default 2)");
  p.no_scene_reflections =
      cmd->add_flag("--no-scene-reflections")
          ->description(
              "Photo presets: the spheres reflect the room only, not the ground, object, "
              "bases and camera");
  p.distractor = cmd->add_option("--distractor", flags->distractor,
                                 "Photo presets: a round thing that is no sphere: coin, dish or "
                                 "none");
  p.no_flare = cmd->add_flag("--no-flare")->description("Photo presets: no flare streaks");
  p.flare_spokes = cmd->add_option("--flare-spokes", flags->flare_spokes,
                                   "Photo presets: streaks per flare, even, 2..16 (default 6)");
  p.flare_strength = cmd->add_option("--flare-strength", flags->flare_strength,
                                     "Photo presets: fraction of the saturated excess spread "
                                     "into the streaks, 0..1");
  p.no_bloom =
      cmd->add_flag("--no-bloom")->description("Photo presets: no bloom around saturated cores");
  p.no_vignetting = cmd->add_flag("--no-vignetting")->description("Photo presets: no vignetting");
  p.vignetting = cmd->add_option("--vignetting", flags->vignetting,
                                 "Photo presets: brightness lost in the corners, 0..1 (default "
                                 "0.35)");
  p.no_noise = cmd->add_flag("--no-noise")->description("Photo presets: no sensor noise");
  p.exposure_jitter = cmd->add_option("--exposure-jitter", flags->exposure_jitter_ev,
                                      "Photo presets: exposure that varies from image to image "
                                      "(automatic exposure, a flash's output), up to this many "
                                      "EV either way, 0..4 (default 0)");
  p.shake = cmd->add_option("--shake", flags->shake_px,
                            "Photo presets: a camera that moves between shots: each image "
                            "shifted by up to this many pixels, 0..20 (default 0)");
  p.focal_px = cmd->add_option("--focal-px", flags->focal_px,
                               "Photo presets: focal length in pixels (after --size/--width)");
  p.light_radius = cmd->add_option("--light-radius", flags->light_radius_deg,
                                   "Photo presets: angular radius of each light, degrees "
                                   "(default 0.6)");
  p.no_exif =
      cmd->add_flag("--no-exif")
          ->description(
              "Photo presets: no EXIF camera block in the JPEG files (by default they record the "
              "focal length as a camera does: FocalLength on a 23.5 mm wide sensor, its "
              "pixel pitch, the 35 mm equivalent)");
  p.supersample = cmd->add_option("--supersample", flags->supersample,
                                  "Photo presets: sub-samples per pixel side on edges and "
                                  "highlights, 1..16 (default 4)");

  cmd->callback([=]() {
    const SynthFlags& f = *flags;
    if (f.threads < 0) throw Error("synth: --threads must be >= 0");
    if (synth::is_photo_preset(f.preset)) {
      for (CLI::Option* relief_only : {scene, ks, exponent, ambient, height_frac, no_shadows,
                                       no_truth, dome_radius, mm_per_px, no_falloff, srgb}) {
        if (relief_only->count() > 0) {
          throw Error("synth: " + relief_only->get_name() +
                      " applies to the relief presets, "
                      "not to " +
                      f.preset);
        }
      }
      synth::PhotoOptions o = synth::photo_preset_options(f.preset);
      int w = o.width, h = o.height;
      if (size->count() > 0) w = h = f.size;
      if (width->count() > 0) w = f.width;
      if (height->count() > 0) h = f.height;
      if (width->count() > 0 && height->count() == 0) {
        h = static_cast<int>(std::lround(static_cast<double>(w) * o.height / o.width));
      }
      if (w != o.width || h != o.height) synth::resize_photo(w, h, &o);
      if (p.focal_px->count() > 0) o.focal_px = f.focal_px;
      if (lights->count() > 0) o.lights = f.lights;
      if (seed->count() > 0) o.seed = f.seed;
      if (format->count() > 0) o.file_type = synth::parse_file_type(f.format);
      if (bits->count() > 0) o.bits = f.bits;
      if (jpeg_quality->count() > 0) o.jpeg_quality = f.jpeg_quality;
      if (exposure->count() > 0) o.exposure = f.exposure;
      if (noise->count() > 0) o.artefacts.read_noise_grey = f.noise;
      if (p.spheres_material->count() > 0) {
        const synth::SphereMaterial m = synth::parse_sphere_material(f.spheres_material);
        for (synth::PhotoSphere& s : o.spheres) s.material = m;
      }
      if (p.sphere_count->count() > 0) {
        if (f.sphere_count < 1 || f.sphere_count > static_cast<int>(o.spheres.size())) {
          throw Error("synth: --spheres must be 1.." + std::to_string(o.spheres.size()) + " for " +
                      f.preset);
        }
        o.spheres.resize(static_cast<std::size_t>(f.sphere_count));
      }
      if (p.no_bases->count() > 0) o.sphere_bases = false;
      if (p.no_object->count() > 0) o.object = false;
      if (p.environment->count() > 0) o.environment = synth::parse_environment(f.environment);
      if (p.windows->count() > 0) o.windows = f.windows;
      if (p.lamps->count() > 0) o.lamps = f.lamps;
      if (p.no_scene_reflections->count() > 0) o.reflect_scene = false;
      if (p.distractor->count() > 0) o.distractor = synth::parse_distractor(f.distractor);
      if (p.no_flare->count() > 0) o.artefacts.flare = false;
      if (p.flare_spokes->count() > 0) o.artefacts.flare_spokes = f.flare_spokes;
      if (p.flare_strength->count() > 0) o.artefacts.flare_strength = f.flare_strength;
      if (p.no_bloom->count() > 0) o.artefacts.bloom = false;
      if (p.no_vignetting->count() > 0) o.artefacts.vignetting = false;
      if (p.vignetting->count() > 0) o.artefacts.vignetting_corner_loss = f.vignetting;
      if (p.no_noise->count() > 0) o.artefacts.noise = false;
      if (p.exposure_jitter->count() > 0) o.artefacts.exposure_jitter_ev = f.exposure_jitter_ev;
      if (p.shake->count() > 0) o.artefacts.shake_px = f.shake_px;
      if (p.light_radius->count() > 0) o.light_radius_deg = f.light_radius_deg;
      if (p.supersample->count() > 0) o.supersample = f.supersample;
      if (p.no_exif->count() > 0) o.exif_sensor_width_mm = 0.0;
      ThreadLimit limit(f.threads);
      const synth::PhotoReport report = synth::render_photo_capture(o, f.out);
      std::printf("synth: wrote %d images (%dx%d, %s, %zu %s sphere(s)) to %s in %.2f s\n",
                  report.images, report.width, report.height, o.preset.c_str(), o.spheres.size(),
                  std::string(synth::to_string(o.spheres.front().material)).c_str(),
                  report.folder.string().c_str(), report.seconds);
      return;
    }
    for (CLI::Option* photo_only : p.all()) {
      if (photo_only->count() > 0) {
        throw Error("synth: " + photo_only->get_name() + " applies to the photo presets (" +
                    "photo-dome, photo-glass, photo-chrome, photo-large-sphere), not to " +
                    f.preset);
      }
    }
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
    if (jpeg_quality->count() > 0) o.sensor.jpeg_quality = f.jpeg_quality;

    ThreadLimit limit(f.threads);
    const synth::SynthReport report = synth::render_capture(o, f.out);
    std::printf("synth: wrote %d images (%dx%d, %s %s) to %s in %.2f s\n", report.images,
                report.width, report.height, o.preset.c_str(),
                std::string(synth::to_string(o.scene)).c_str(), report.folder.string().c_str(),
                report.seconds);
  });
}

}  // namespace ptmkit::app
