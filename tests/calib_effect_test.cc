// How light-calibration error carries into a fit (tests/support/calibration_study.h): a relief
// fitted with lights calibrated from rendered sphere photographs relights like one fitted with the
// true lights; deliberate errors move the relit values in proportion.
#include <cstdio>

#include <gtest/gtest.h>

#include "calibration_study.h"

namespace ptmkit {
namespace {

struct Fixture {
  std::vector<Eigen::Vector3d> lights = calib::layout_directions("dome49");
  study::Capture capture = study::render_capture(
      "matte", 64, lights, calib::layout_directions("rings:20:7:13,40:7:5,60:5:29"));
  CoefficientMap reference = study::fit_with(capture, lights);

  study::RelightScore score(const std::vector<Eigen::Vector3d>& dirs) const {
    return study::score(capture, study::fit_with(capture, dirs), reference);
  }
};

TEST(CalibrationEffect, SphereCalibratedLightsRelightLikeTheTrueOnes) {
  const Fixture f;
  const auto calibrated = study::sphere_calibrated(f.lights, 100.0, 1.0, 7);
  for (const auto& d : calibrated) ASSERT_TRUE(std::isfinite(d.x())) << "a light not calibrated";
  const study::AngleStats err = study::angle_stats(calibrated, f.lights);
  const study::RelightScore truth = f.score(f.lights);
  const study::RelightScore cal = f.score(calibrated);
  std::printf(
      "sphere r = 100 px: light error mean %.3f max %.3f deg; truth PSNR %.3f dB "
      "(true lights %.3f); relit change %.3f grey\n",
      err.mean_deg, err.max_deg, cal.psnr_db, truth.psnr_db, cal.mean_change_grey);
  EXPECT_LE(err.mean_deg, 0.3);
  EXPECT_NEAR(cal.psnr_db, truth.psnr_db, 0.1);
  EXPECT_LT(cal.mean_change_grey, 0.15);
}

TEST(CalibrationEffect, RelitChangeGrowsWithTheLightErrorAndSystematicErrorCarriesOver) {
  const Fixture f;
  const double c1 = f.score(study::perturbed_random(f.lights, 1.0, 11)).mean_change_grey;
  const double c2 = f.score(study::perturbed_random(f.lights, 2.0, 11)).mean_change_grey;
  const double c5 = f.score(study::perturbed_random(f.lights, 5.0, 11)).mean_change_grey;
  const double tilt = f.score(study::perturbed_tilt(f.lights, 2.0)).mean_change_grey;
  std::printf("relit change: random 1/2/5 deg %.3f / %.3f / %.3f grey; 2 deg tilt %.3f grey\n", c1,
              c2, c5, tilt);
  EXPECT_GT(c1, 0.05);
  EXPECT_LT(c1, c2);
  EXPECT_LT(c2, c5);
  // About proportional to the error (between 3x and 7x for 5x the error).
  EXPECT_GT(c5 / c1, 3.0);
  EXPECT_LT(c5 / c1, 7.0);
  // Random per-light errors partly average out over 49 lights; one tilt of every light does not.
  EXPECT_GT(tilt, 1.5 * c2);
}

}  // namespace
}  // namespace ptmkit
