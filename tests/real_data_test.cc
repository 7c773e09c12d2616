// Fits of real third-party captures from ../shared/data (skipped where absent).
#include <gtest/gtest.h>

#include "ptmkit/core/image_io.h"
#include "ptmkit/core/light_set.h"
#include "ptmkit/fit/fit.h"
#include "ptmkit/texture/metrics.h"
#include "ptmkit/texture/ptm.h"
#include "ptmkit/texture/relight.h"
#include "test_util.h"

namespace ptmkit {
namespace {

// SynthRTI multi2/mat5 relit at its 20 test lights: mean PSNR >= 20.0 dB, the requirement
// (docs/TARGETS.md); measured 20.18 dB.
constexpr double kSynthRtiTargetPsnrDb = 20.0;
// Loewenkopf's 240 lights: measured cond(A) 5.37.
constexpr double kLoewenkopfMaxCondition = 20.0;
// The stored 8-bit .ptm's RMS error at the capture lights against the fit's own residual: apart
// by at most half a grey level plus 5% of the residual (measured 0.34 grey levels apart, the
// residual 11.3).
constexpr double kQuantisationAddsGrey = 0.5;
constexpr double kQuantisationAddsRel = 0.05;

// SynthRTI Multi/Object2/material5: 49 training lights, 20 test lights at other elevations.
// Plain least squares, three polynomials, stored as an 8-bit .ptm, relit at the test lights.
TEST(RealData, SynthRtiRgbFitRelightsHeldOutLightsAbove20dB) {
  const auto root = test::shared_data("synthrti-multi2-mat5");
  if (!root) GTEST_SKIP() << "../shared/data/synthrti-multi2-mat5 is absent";
  test::ScratchDir dir;
  const LightSet train = read_lp(*root / "Dome" / "dirs.lp");
  const LightSet test_set = read_lp(*root / "Test" / "dirs.lp");
  fit::FitOptions options;
  options.model = ColourModel::kRGB;
  texture::PtmStreamWriter writer(dir / "mat5.ptm");
  const fit::FitReport report = fit::fit_capture(train, options, writer);
  EXPECT_EQ(report.lights, 49);
  const CoefficientMap map = texture::read_ptm(dir / "mat5.ptm");
  double sum_psnr = 0.0;
  for (const Light& light : test_set.lights) {
    const Image photo = read_image(light.image);
    const Image relit = texture::relight(map, light.direction);
    sum_psnr += texture::compare_images(relit.view(), photo.view()).psnr_db;
  }
  const double mean_psnr = sum_psnr / static_cast<double>(test_set.size());
  RecordProperty("mean_psnr_db", std::to_string(mean_psnr));
  std::printf("SynthRTI multi2/mat5, rgb LS, .ptm, 20 test lights: mean PSNR %.3f dB\n", mean_psnr);
  EXPECT_GE(mean_psnr, kSynthRtiTargetPsnrDb);
}

// Loewenkopf: 240 real photographs (64x43 JPEG) of a carved lion head.
TEST(RealData, LoewenkopfFitsAndReproducesItsPhotographs) {
  const auto root = test::shared_data("loewenkopf");
  if (!root) GTEST_SKIP() << "../shared/data/loewenkopf is absent";
  test::ScratchDir dir;
  const LightSet lights = read_lp(*root / "dirs.lp");
  ASSERT_EQ(lights.size(), 240u);
  for (ColourModel model : {ColourModel::kRGB, ColourModel::kLRGB}) {
    fit::FitOptions options;
    options.model = model;
    texture::PtmStreamWriter writer(dir / "lion.ptm");
    const fit::FitReport report = fit::fit_capture(lights, options, writer);
    EXPECT_EQ(report.width, 64);
    EXPECT_EQ(report.height, 43);
    EXPECT_LT(report.design.condition_number, kLoewenkopfMaxCondition);
    const CoefficientMap map = texture::read_ptm(dir / "lion.ptm");
    // The fit's own residual (unquantised) and the stored file's error at the capture lights
    // agree to within what 8-bit quantisation adds.
    double sum_sq = 0.0;
    std::size_t n = 0;
    for (const Light& light : lights.lights) {
      const auto cmp = texture::compare_images(texture::relight(map, light.direction).view(),
                                               read_image(light.image).view());
      sum_sq += cmp.rmse * cmp.rmse;
      ++n;
    }
    const double rms_grey = 255.0 * std::sqrt(sum_sq / static_cast<double>(n));
    std::printf("loewenkopf %s: fit residual rms %.2f grey, stored .ptm rms %.2f grey\n",
                std::string(to_string(model)).c_str(), report.residuals.rms_grey, rms_grey);
    EXPECT_NEAR(rms_grey, report.residuals.rms_grey,
                kQuantisationAddsGrey + kQuantisationAddsRel * report.residuals.rms_grey);
  }
}

}  // namespace
}  // namespace ptmkit
