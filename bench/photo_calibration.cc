// Sphere calibration on the photographic renders (synth/photo.h), as a user runs it: each
// preset rendered to JPEG files exactly as `ptmkit synth --preset P --seed S` writes them,
// calibrated from the files without hints (the preset's sphere count and focal length given,
// as `ptmkit calibrate sphere ... --spheres N --focal-px F` does), then compared with the
// render's truth: each circle's centre and radius, each highlight against the mirror
// highlight of its light, and each combined light direction.
//
//   photo_calibration WORK_DIR [--size WxH] [--lights SPEC] [--no-bases] [--spheres N]
//                     [--spheres-material M]
//                     [--environment dark|lit] [--noise SIGMA] [--exposure X]
//                     [--exposure-jitter EV] [--shake PX] [--per-light]
//                     [PRESET[:SEED,...] ...]
//       default: photo-dome:1,2,3 photo-glass:1,2,3 photo-chrome:1,2,3 photo-large-sphere:1,2,3
//       --size: the renders at W x H (the scene kept, the focal length scaled with the width, as
//       `ptmkit synth --width W --height H` does); default the presets' 640 x 360
//       --lights: the light layout instead of the preset's, as `ptmkit synth --lights SPEC`
//       (e.g. rings:15:3,40:3,65:2,80:4)
//       --no-bases: the spheres lying on the ground, as `ptmkit synth --no-bases`
//       --spheres N: only the first N of the preset's spheres, as `ptmkit synth --spheres N`
//       (and calibrated with --spheres N)
//       --spheres-material M: every sphere of M (black-glossy, chrome, glass), as `ptmkit synth`
//       --environment E: the room the spheres mirror, dark (the presets') or lit, as `ptmkit
//       synth --environment E`
//       --noise SIGMA: the sensor's read noise, grey levels of 8 bits (the presets': 1), as
//       `ptmkit synth --noise SIGMA`
//       --exposure X: the exposure (the presets': 1; 3 clips every highlight into a wide disc of
//       bloom), as `ptmkit synth --exposure X`
//       --exposure-jitter EV: each image's exposure 2^u times the stack's, u uniform in
//       [-EV, EV] per image, as `ptmkit synth --exposure-jitter EV` (a camera on automatic
//       exposure, a flash whose output varies)
//       --shake PX: each image shifted by up to PX pixels, as `ptmkit synth --shake PX` (a
//       camera that moves between shots)
//       --per-light: also one line per light: its elevation, each sphere's highlight error (px)
//       and the combined direction's error (degrees)
//
// Prints one line per preset and seed; the figures are in docs/CALIBRATION.md.
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <numbers>
#include <string>
#include <vector>

#include "ptmkit/calib/sphere_stack.h"
#include "ptmkit/core/error.h"
#include "ptmkit/synth/photo.h"

namespace fs = std::filesystem;
using namespace ptmkit;

namespace {

double angle_deg(const Eigen::Vector3d& a, const Eigen::Vector3d& b) {
  return std::acos(std::clamp(a.normalized().dot(b.normalized()), -1.0, 1.0)) * 180.0 /
         std::numbers::pi;
}

void run(const fs::path& work, const std::string& preset, unsigned seed, int width, int height,
         const std::string& light_layout, bool bases, const std::string& material,
         const std::string& environment, double noise, double exposure, double jitter_ev,
         double shake_px, bool per_light, int spheres) {
  synth::PhotoOptions po = synth::photo_preset_options(preset);
  po.seed = seed;
  if (spheres > 0 && static_cast<std::size_t>(spheres) < po.spheres.size()) {
    po.spheres.resize(static_cast<std::size_t>(spheres));
  }
  if (!bases) po.sphere_bases = false;
  if (!material.empty()) {
    for (synth::PhotoSphere& s : po.spheres) s.material = synth::parse_sphere_material(material);
  }
  if (!light_layout.empty()) po.lights = light_layout;
  if (!environment.empty()) po.environment = synth::parse_environment(environment);
  if (noise >= 0.0) po.artefacts.read_noise_grey = noise;
  if (exposure > 0.0) po.exposure = exposure;
  if (jitter_ev > 0.0) po.artefacts.exposure_jitter_ev = jitter_ev;
  if (shake_px > 0.0) po.artefacts.shake_px = shake_px;
  if (width > 0) synth::resize_photo(width, height, &po);
  const fs::path dir = work / (preset + "-" + std::to_string(seed));
  fs::remove_all(dir);
  const synth::PhotoReport rendered = synth::render_photo_capture(po, dir);
  const synth::PhotoTruth truth = synth::PhotoRenderer(po).truth();

  calib::StackCalibrationOptions o;
  o.rig.sphere_count = static_cast<int>(po.spheres.size());
  o.rig.detection.camera.focal_px = po.focal_px;
  std::vector<fs::path> photos;  // the report lists the truth masks too
  for (const fs::path& f : rendered.files) {
    if (f.parent_path() == dir && f.filename().string().rfind("image_", 0) == 0) {
      photos.push_back(f);
    }
  }
  const auto t0 = std::chrono::steady_clock::now();
  const calib::StackCalibration r = calib::calibrate_sphere_stack(photos, o);
  const double seconds =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();

  std::printf("%s seed %u:", preset.c_str(), seed);
  for (std::size_t k = 0; k < r.rig.spheres.size() && k < truth.spheres.size(); ++k) {
    const calib::Circle& c = r.rig.spheres[k].sphere;
    const synth::SphereOutline& t = truth.spheres[k].outline;
    // Highlights against the mirror highlight of each light (where the truth has one).
    double sum = 0.0, worst = 0.0;
    int n = 0;
    const auto& lights = r.rig.spheres[k].lights;
    for (std::size_t i = 0; i < lights.size() && i < truth.spheres[k].highlight_px.size(); ++i) {
      if (!lights[i].found || !truth.spheres[k].highlight_px[i]) continue;
      const double d = (lights[i].highlight_px - *truth.spheres[k].highlight_px[i]).norm();
      sum += d;
      worst = std::max(worst, d);
      ++n;
    }
    std::printf(" sphere %zu centre %.3f px radius %+.3f%% highlights mean %.3f max %.3f px;", k,
                (c.centre_px - t.centre_px).norm(),
                100.0 * (c.radius_px - t.radius_px) / t.radius_px, n ? sum / n : 0.0, worst);
  }
  double mean = 0.0, max = 0.0;
  int used = 0;
  for (std::size_t i = 0; i < r.rig.lights.size() && i < truth.light_dirs.size(); ++i) {
    if (!r.rig.lights[i].found) continue;
    const double a = angle_deg(r.rig.lights[i].direction, truth.light_dirs[i]);
    mean += a;
    max = std::max(max, a);
    ++used;
  }
  std::printf(" lights %d of %zu, mean %.3f max %.3f deg;%s %.2f s\n", used,
              truth.light_dirs.size(), used ? mean / used : 0.0, max,
              r.search_note.empty() ? "" : " second search;", seconds);
  // The camera's measured shifts against the render's, both taken about their own mean (the
  // stack's median, which the shifts are measured against, sits near the images' mean place).
  if (!r.image_shifts_px.empty() && r.image_shifts_px.size() == truth.light_dirs.size()) {
    const synth::ShakeError e = synth::shake_error(po, r.image_shifts_px);
    std::printf("  camera moved: shifts %s, off the render's by %.3f px rms, %.3f at worst\n",
                r.image_shifts_undone ? "undone" : "not undone", e.rms_px, e.worst_px);
  }
  for (std::size_t i = 0; per_light && i < truth.light_dirs.size(); ++i) {
    const double elevation =
        std::asin(std::clamp(truth.light_dirs[i].normalized().z(), -1.0, 1.0)) * 180.0 /
        std::numbers::pi;
    std::printf("  light %2zu elevation %5.1f:", i, elevation);
    for (std::size_t k = 0; k < r.rig.spheres.size() && k < truth.spheres.size(); ++k) {
      const auto& lights = r.rig.spheres[k].lights;
      if (i >= lights.size() || !lights[i].found) {
        std::printf(" sphere %zu none;", k);
      } else if (i >= truth.spheres[k].highlight_px.size() || !truth.spheres[k].highlight_px[i]) {
        std::printf(" sphere %zu (%.2f, %.2f) no truth;", k, lights[i].highlight_px.x(),
                    lights[i].highlight_px.y());
      } else {
        const Eigen::Vector2d d = lights[i].highlight_px - *truth.spheres[k].highlight_px[i];
        std::printf(" sphere %zu (%.2f, %.2f) off (%+.2f, %+.2f);", k, lights[i].highlight_px.x(),
                    lights[i].highlight_px.y(), d.x(), d.y());
      }
    }
    if (i < r.rig.lights.size() && r.rig.lights[i].found) {
      std::printf(" light %.3f deg\n", angle_deg(r.rig.lights[i].direction, truth.light_dirs[i]));
    } else {
      std::printf(" light not found\n");
    }
  }
  std::fflush(stdout);
}

}  // namespace

constexpr const char* kUsage =
    "usage: photo_calibration WORK_DIR [--size WxH] [--lights SPEC] [--no-bases] [--spheres N] "
    "[--spheres-material M] [--environment dark|lit] [--noise SIGMA] [--exposure X] "
    "[--exposure-jitter EV] [--shake PX] [--per-light] [PRESET[:SEED,...] ...]\n";

int main(int argc, char** argv) {
  try {
    if (argc < 2) {
      std::fputs(kUsage, stderr);
      return 2;
    }
    // A flag in the work folder's place (--help) is not a folder to write renders into.
    if (argv[1][0] == '-') {
      std::fputs(kUsage, stderr);
      return 2;
    }
    const fs::path work = argv[1];
    std::vector<std::string> specs(argv + 2, argv + argc);
    int width = 0, height = 0;
    std::string lights;
    bool bases = true;
    bool per_light = false;
    std::string material, environment;
    double noise = -1.0, exposure = 0.0, jitter_ev = 0.0, shake_px = 0.0;
    int spheres = 0;
    while (!specs.empty() &&
           (specs[0] == "--size" || specs[0] == "--lights" || specs[0] == "--no-bases" ||
            specs[0] == "--spheres-material" || specs[0] == "--environment" ||
            specs[0] == "--noise" || specs[0] == "--exposure" || specs[0] == "--exposure-jitter" ||
            specs[0] == "--shake" || specs[0] == "--per-light" || specs[0] == "--spheres")) {
      if (specs[0] == "--no-bases" || specs[0] == "--per-light") {
        if (specs[0] == "--no-bases") {
          bases = false;
        } else {
          per_light = true;
        }
        specs.erase(specs.begin());
        continue;
      }
      if (specs.size() < 2) {
        std::fprintf(stderr, "photo_calibration: %s needs a value\n", specs[0].c_str());
        return 2;
      }
      if (specs[0] == "--lights") {
        lights = specs[1];
      } else if (specs[0] == "--spheres") {
        char* end = nullptr;
        const long v = std::strtol(specs[1].c_str(), &end, 10);
        if (end == specs[1].c_str() || *end != '\0' || v < 1 || v > 8) {
          std::fprintf(stderr, "photo_calibration: --spheres needs a count of 1 to 8\n");
          return 2;
        }
        spheres = static_cast<int>(v);
      } else if (specs[0] == "--spheres-material") {
        material = specs[1];
      } else if (specs[0] == "--environment") {
        environment = specs[1];
      } else if (specs[0] == "--noise" || specs[0] == "--exposure" ||
                 specs[0] == "--exposure-jitter" || specs[0] == "--shake") {
        char* end = nullptr;
        const double v = std::strtod(specs[1].c_str(), &end);
        if (end == specs[1].c_str() || *end != '\0' || !std::isfinite(v) || v < 0.0 ||
            (specs[0] == "--exposure" && v <= 0.0)) {
          std::fprintf(stderr, "photo_calibration: %s needs a number%s\n", specs[0].c_str(),
                       specs[0] == "--exposure" ? " above 0" : " of at least 0");
          return 2;
        }
        (specs[0] == "--noise"      ? noise
         : specs[0] == "--exposure" ? exposure
         : specs[0] == "--shake"    ? shake_px
                                    : jitter_ev) = v;
      } else if (std::sscanf(specs[1].c_str(), "%dx%d", &width, &height) != 2 || width < 32 ||
                 height < 32) {
        std::fprintf(stderr, "photo_calibration: --size needs WxH, e.g. 2560x1440\n");
        return 2;
      }
      specs.erase(specs.begin(), specs.begin() + 2);
    }
    if (specs.empty()) {
      specs = {"photo-dome:1,2,3", "photo-glass:1,2,3", "photo-chrome:1,2,3",
               "photo-large-sphere:1,2,3"};
    }
    for (const std::string& spec : specs) {
      const auto colon = spec.find(':');
      const std::string preset = spec.substr(0, colon);
      std::vector<unsigned> seeds;
      if (colon == std::string::npos) {
        seeds = {1};
      } else {
        std::string rest = spec.substr(colon + 1);
        std::size_t at = 0;
        while (at <= rest.size()) {
          const auto comma = rest.find(',', at);
          seeds.push_back(static_cast<unsigned>(std::stoul(rest.substr(at, comma - at))));
          if (comma == std::string::npos) break;
          at = comma + 1;
        }
      }
      for (const unsigned s : seeds) {
        try {
          run(work, preset, s, width, height, lights, bases, material, environment, noise, exposure,
              jitter_ev, shake_px, per_light, spheres);
        } catch (const calib::SphereSearchError& e) {
          std::printf("%s seed %u: spheres not told apart: %s\n", preset.c_str(), s, e.what());
        }
      }
    }
    return 0;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "photo_calibration: %s\n", e.what());
    return 1;
  }
}
