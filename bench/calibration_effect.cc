// The effect of light-calibration error on a fit (docs/CALIBRATION.md): a relief fitted with
// the true lights, with lights calibrated from rendered sphere photographs of two sizes, and
// with lights perturbed on purpose (random per-light errors; one systematic tilt), each relit
// at held-out directions and scored against the diffuse truth.
//
// Usage: calibration_effect [SIZE_PX] [PRESET]   (defaults: 256 matte)
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <string>

#include "calibration_study.h"

using namespace ptmkit;

int main(int argc, char** argv) {
  const int size = argc > 1 ? std::atoi(argv[1]) : 256;
  const std::string preset = argc > 2 ? argv[2] : "matte";
  const auto lights = calib::layout_directions("dome49");
  const auto test_lights = calib::layout_directions("rings:20:7:13,40:7:5,60:5:29");
  const study::Capture capture = study::render_capture(preset, size, lights, test_lights);
  const CoefficientMap reference = study::fit_with(capture, lights);

  struct Row {
    std::string name;
    std::vector<Eigen::Vector3d> dirs;
  };
  std::vector<Row> rows{{"true lights", lights}};
  for (double r : {150.0, 50.0}) {
    char name[96];
    std::snprintf(name, sizeof name, "sphere r = %.0f px, noise 1 grey", r);
    rows.push_back({name, study::sphere_calibrated(lights, r, 1.0, 7)});
  }
  for (double deg : {1.0, 2.0, 5.0}) {
    char name[64];
    std::snprintf(name, sizeof name, "random %.0f deg per light", deg);
    rows.push_back({name, study::perturbed_random(lights, deg, 11)});
  }
  rows.push_back({"systematic 2 deg tilt", study::perturbed_tilt(lights, 2.0)});

  std::printf("preset %s, %d x %d, dome49 (49 lights), 19 held-out lights\n\n", preset.c_str(),
              size, size);
  std::printf("| lights | error mean / max deg | truth PSNR dB | relit change grey |\n");
  std::printf("|---|---|---|---|\n");
  for (const auto& row : rows) {
    bool ok = true;
    for (const auto& d : row.dirs) ok = ok && std::isfinite(d.x());
    if (!ok) {
      std::printf("| %s | a light was not calibrated | - | - |\n", row.name.c_str());
      continue;
    }
    const study::AngleStats err = study::angle_stats(row.dirs, lights);
    const study::RelightScore s =
        study::score(capture, study::fit_with(capture, row.dirs), reference);
    std::printf("| %s | %.3f / %.3f | %.2f | %.3f |\n", row.name.c_str(), err.mean_deg, err.max_deg,
                s.psnr_db, s.mean_change_grey);
  }
  return 0;
}
