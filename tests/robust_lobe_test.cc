// Broad, unclipped specular lobes and cast shadows: the robust default against least squares
// and against plain quantile trimming, by the photometric-stereo normals of the kept samples.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <string>

#include <gtest/gtest.h>
#include <Eigen/Cholesky>

#include "ptmkit/core/image_io.h"
#include "ptmkit/core/light_set.h"
#include "synth_stack.h"
#include "test_util.h"
#include "tolerances.h"

namespace ptmkit::fit {
namespace {

// One texel of a glossy surface tilted 30 degrees: Lambertian albedo 0.5 plus an unclipped
// Blinn-Phong lobe (ks 0.3, exponent 8, viewer along +z) under the default preset's 49 lights,
// two samples clipped. qtrim labels exactly floor(0.25 * 49) = 12 darkest samples shadows, the
// floor(0.10 * 49) = 4 brightest highlights, the clipped ones highlights besides, and fits the
// polynomial to the rest.
TEST(RobustLobe, QuantileTrimLabelsTheDarkestQuarterAndBrightestTenth) {
  synth::SynthOptions o = synth::preset_options("default");
  const auto dirs = synth::resolve_lights(o);
  ASSERT_EQ(dirs.size(), 49u);
  const Eigen::Vector3d normal(std::sin(M_PI / 6), 0.0, std::cos(M_PI / 6));
  std::vector<double> value(dirs.size());
  for (std::size_t i = 0; i < dirs.size(); ++i) {
    const Eigen::Vector3d h = (dirs[i] + Eigen::Vector3d::UnitZ()).normalized();
    value[i] = 0.5 * std::max(0.0, normal.dot(dirs[i])) +
               0.3 * std::pow(std::max(0.0, normal.dot(h)), 8.0);
  }
  std::vector<std::uint8_t> sat(dirs.size(), 0);
  sat[20] = sat[21] = 1;  // mid-ranked samples clipped in some channel
  std::vector<std::size_t> order(dirs.size());
  for (std::size_t i = 0; i < order.size(); ++i) order[i] = i;
  std::sort(order.begin(), order.end(), [&](std::size_t a, std::size_t b) {
    return value[a] < value[b] || (value[a] == value[b] && a < b);
  });
  const LightDesign design = LightDesign::build(dirs);
  TexelSolver ts(design.design(), Solver::kQTrim, RobustOptions{});
  std::vector<double> w(dirs.size());
  std::vector<SampleLabel> labels(dirs.size());
  double c[6];
  const TexelOutcome out = ts.solve(value.data(), sat.data(), w.data(), labels.data(), c);
  EXPECT_FALSE(out.fallback);
  int clipped_extra = 0;
  for (std::size_t r = 0; r < order.size(); ++r) {
    const std::size_t i = order[r];
    const SampleLabel want = sat[i] != 0 ? SampleLabel::kHighlight
                             : r < 12    ? SampleLabel::kShadow
                             : r >= 45   ? SampleLabel::kHighlight
                                         : SampleLabel::kInlier;
    EXPECT_EQ(labels[i], want) << "sample " << i << " rank " << r;
    EXPECT_EQ(w[i], want == SampleLabel::kInlier ? 1.0 : 0.0);
    clipped_extra += (sat[i] != 0 && r >= 12 && r < 45) ? 1 : 0;
  }
  EXPECT_EQ(out.shadows, 12);
  EXPECT_EQ(out.highlights, 4 + clipped_extra);
  // The coefficients are the least-squares polynomial of the kept samples.
  double check[6];
  ASSERT_TRUE(ts.weighted_fit(value.data(), w.data(), check));
  for (int k = 0; k < 6; ++k) EXPECT_NEAR(c[k], check[k], test::kDoubleRoundoff);
}

// Degenerate input: every sample clipped leaves nothing to fit; qtrim falls back to least
// squares over all samples, finite, flagged.
TEST(RobustLobe, QuantileTrimFallsBackWhenEverySampleIsClipped) {
  synth::SynthOptions o = synth::preset_options("default");
  const auto dirs = synth::resolve_lights(o);
  const LightDesign design = LightDesign::build(dirs);
  TexelSolver ts(design.design(), Solver::kQTrim, RobustOptions{});
  std::vector<double> value(dirs.size(), 1.0), w(dirs.size());
  const std::vector<std::uint8_t> sat(dirs.size(), 1);
  std::vector<SampleLabel> labels(dirs.size());
  double c[6];
  const TexelOutcome out = ts.solve(value.data(), sat.data(), w.data(), labels.data(), c);
  EXPECT_TRUE(out.fallback);
  for (double ck : c) EXPECT_TRUE(std::isfinite(ck));
  EXPECT_NEAR(c[5], 1.0, test::kDoubleSolveRoundoff);  // the constant term of a flat texel
}

// A glossy ball's capture written as 16-bit PNG files with an .lp beside them, fitted from
// the files by `solver`: the normals' mean error over the ball, in degrees.
double ball_normals_from_files(const test::BallStack& ball, const std::filesystem::path& dir,
                               Solver solver) {
  std::filesystem::create_directories(dir);
  {
    std::ofstream lp(dir / "lights.lp");
    lp << ball.dirs.size() << "\n";
    for (std::size_t i = 0; i < ball.dirs.size(); ++i) {
      const std::string name = "ball_" + std::to_string(i) + ".png";
      ImageWriteOptions wo;
      wo.format = PixelFormat::kU16;
      write_image(dir / name, ball.observed[i].view(), wo);
      lp << name << " " << ball.dirs[i].x() << " " << ball.dirs[i].y() << " " << ball.dirs[i].z()
         << "\n";
    }
  }
  FitOptions o;
  o.solver = solver;
  o.residual_stats = false;
  FitOutputs out;
  out.want_normals = true;
  CoefficientMap map;
  CoefficientMapSink sink(&map);
  const FitReport report = fit_capture(read_lp(dir / "lights.lp"), o, sink, &out);
  // The robust scale's floor is 2 steps of the 16-bit files (RobustOptions::min_scale).
  EXPECT_DOUBLE_EQ(report.robust.min_scale, 2.0 / 65535.0);
  return eval::normal_error(out.normals, ball.scene.normals, &ball.mask).mean_deg;
}

// Intensity-normalised 16-bit photometric-stereo captures often hold their diffuse level at a
// tenth of full scale. The robust labels must not depend on that: with the keep window and the
// robust scale's floor in 8-bit grey levels, a glossy ball exposed at 0.2 had its specular lobes
// kept as inliers (normals 4.7 degrees off against 2.4 at full exposure). The ball: 96 lights
// within 45 degrees of the view axis, Blinn-Phong ks 0.5, exponent 30, 64 px, read from files.
TEST(RobustLobe, ADarkSixteenBitCaptureIsLabelledAsAtFullExposure) {
  test::ScratchDir tmp;
  const test::BallStack bright = test::render_ball(64, 0.5, 30.0, 45.0, 1.0);
  const test::BallStack dark = test::render_ball(64, 0.5, 30.0, 45.0, 0.2);
  const double ls_dark = ball_normals_from_files(dark, tmp / "dark_ls", Solver::kLS);
  const double robust_dark = ball_normals_from_files(dark, tmp / "dark", Solver::kRobust);
  const double robust_bright = ball_normals_from_files(bright, tmp / "bright", Solver::kRobust);
  std::printf("ball normals, mean degrees: ls %.2f, robust %.2f at exposure 0.2, %.2f at 1\n",
              ls_dark, robust_dark, robust_bright);
  EXPECT_GT(ls_dark, 5.0);      // the lobes and attached shadows bias least squares
  EXPECT_LT(robust_dark, 3.5);  // measured 2.99
  EXPECT_LT(robust_bright, 3.0);
  EXPECT_LT(std::abs(robust_dark - robust_bright), 0.8);
}

}  // namespace
}  // namespace ptmkit::fit
