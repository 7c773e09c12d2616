// Streamed sphere calibration of a photo-sized stack: time and peak memory.
//
//   calibration_stream generate DIR [COUNT=41] [WIDTH=4000] [HEIGHT=3000]
//       writes COUNT JPEGs of a black glossy sphere (radius a fifth of the height) under
//       lights of a dome, plus DIR/truth.txt (circle, then one light direction a line)
//   calibration_stream run DIR
//       calibrates DIR/img*.jpg without hints; prints seconds, peak RSS (MiB), the circle's
//       error and the lights' mean and max error in degrees
// Run `run` in its own process so that the peak RSS is the calibration's alone.
#include <sys/resource.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <numbers>
#include <string>

#include "ptmkit/calib/dome.h"
#include "ptmkit/calib/sphere_stack.h"
#include "ptmkit/core/error.h"
#include "ptmkit/core/image_io.h"
#include "ptmkit/synth/rig.h"

namespace fs = std::filesystem;
using namespace ptmkit;

int main(int argc, char** argv) {
  try {
    if (argc < 3) {
      std::fprintf(stderr, "usage: calibration_stream generate|run DIR [COUNT W H]\n");
      return 2;
    }
    const std::string mode = argv[1];
    const fs::path dir = argv[2];
    if (mode == "generate") {
      const int count = argc > 3 ? std::stoi(argv[3]) : 41;
      synth::SphereRigOptions rig;
      rig.width = argc > 4 ? std::stoi(argv[4]) : 4000;
      rig.height = argc > 5 ? std::stoi(argv[5]) : 3000;
      rig.radius_px = rig.height / 5.0;
      rig.centre_px = {rig.width * 0.3 + 0.37, rig.height * 0.55 + 0.21};
      rig.supersample = 1;
      rig.highlight_supersample = 8;
      rig.light_radius_deg = 0.5;
      rig.background = 0.12;
      rig.body = 0.03;
      rig.noise_grey = 1.0;
      fs::create_directories(dir);
      const auto lights = calib::layout_directions("rings:30:16:0,50:12:10,70:8:20,85:5:0");
      std::ofstream truth(dir / "truth.txt");
      truth.precision(10);
      truth << rig.centre_px.x() << " " << rig.centre_px.y() << " " << rig.radius_px << "\n";
      for (int i = 0; i < count; ++i) {
        rig.light_dir = lights[static_cast<std::size_t>(i) % lights.size()];
        rig.seed = static_cast<std::uint64_t>(i) + 1;
        char name[32];
        std::snprintf(name, sizeof(name), "img%03d.jpg", i);
        write_image(dir / name, synth::render_sphere_rig(rig).view());
        truth << rig.light_dir.x() << " " << rig.light_dir.y() << " " << rig.light_dir.z() << "\n";
      }
      return 0;
    }
    std::vector<fs::path> files;
    for (const auto& e : fs::directory_iterator(dir)) {
      if (e.path().extension() == ".jpg") files.push_back(e.path());
    }
    std::sort(files.begin(), files.end());
    std::ifstream truth(dir / "truth.txt");
    double cx = 0, cy = 0, r = 0;
    truth >> cx >> cy >> r;
    const auto t0 = std::chrono::steady_clock::now();
    const calib::StackCalibration result = calib::calibrate_sphere_stack(files, {});
    const double seconds =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    rusage ru{};
    getrusage(RUSAGE_SELF, &ru);
    const calib::Circle& c = result.rig.spheres.at(0).sphere;
    double mean = 0.0, max = 0.0;
    for (const auto& l : result.rig.lights) {
      Eigen::Vector3d d;
      truth >> d.x() >> d.y() >> d.z();
      const double a =
          std::acos(std::clamp(l.direction.normalized().dot(d.normalized()), -1.0, 1.0)) * 180.0 /
          std::numbers::pi;
      mean += a / static_cast<double>(result.rig.lights.size());
      max = std::max(max, a);
    }
    std::printf(
        "%zu images %dx%d: %.2f s, peak RSS %.0f MiB; analysis scale %d; centre off %.3f px, "
        "radius off %.3f%%; %d of %zu lights usable, mean %.3f max %.3f deg\n",
        files.size(), result.width, result.height, seconds,
        static_cast<double>(ru.ru_maxrss) / 1024.0, result.analysis_scale,
        std::hypot(c.centre_px.x() - cx, c.centre_px.y() - cy),
        100.0 * std::abs(c.radius_px - r) / r, result.rig.usable(), result.rig.lights.size(), mean,
        max);
    return 0;
  } catch (const Error& e) {
    std::fprintf(stderr, "calibration_stream: %s\n", e.what());
    return 1;
  }
}
