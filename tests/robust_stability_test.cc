// Solvers at the extremes of light layouts and sample ranges.
#include <cmath>
#include <random>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "ptmkit/core/error.h"
#include "ptmkit/core/light_layout.h"
#include "ptmkit/fit/fit.h"
#include "test_util.h"

using ::testing::HasSubstr;

namespace ptmkit::fit {
namespace {

// Lights at 1-5 degrees: lu^2 + lv^2 = cos^2(elevation) varies by under 1%, nearly a single
// ring. Measured cond(A) = 698: under the fit's limit of 1e5, so it is fitted (cond(A^T A) ~
// 5e5 in double).
constexpr double kLowRingsMinCondition = 300.0;
constexpr double kLowRingsMaxCondition = 1e4;
// The fit's report and analyse_design compute the same condition number: rounding only.
constexpr double kSameConditionRelTol = 1e-6;
// Float input rounding (6e-8 relative) times cond(A) ~ 700: about 4e-5.
constexpr double kLowRingsCoeffRelTol = 1e-4;
// Relative coefficient errors against cond(A^T A) x float input rounding (6e-8), measured over
// every solver and precision. 12 lights within 15 degrees of one direction: cond(A) = 650 gives
// 0.025, the bound itself (measured worst 1e-5).
constexpr double kConeCoeffRelTol = 0.025;
// Exactly six lights (an interpolation): cond(A) = 24 gives 3.5e-5 (measured worst 3.6e-7).
constexpr double kSixCoeffRelTol = 1e-4;
// A dome with two lights 1e-7 apart: cond(A) = 5.1 gives 1.6e-6 (measured worst 1.5e-7).
constexpr double kNearDuplicateCoeffRelTol = 1e-5;
// Float input rounding (6e-8 relative) amplified by the pseudo-inverse (gain < 10).
constexpr double kHdrCoeffRelTol = 1e-5;

// Images of one random polynomial per texel (values around `level`), exact in double.
std::vector<Image> poly_images(const std::vector<Eigen::Vector3d>& dirs, double level,
                               std::vector<std::array<double, 6>>* truth) {
  std::mt19937_64 rng(test::test_seed());
  std::uniform_real_distribution<double> small(-0.1, 0.1);
  const int w = 8, h = 4;
  truth->assign(static_cast<std::size_t>(w * h), {});
  for (auto& t : *truth) {
    for (int k = 0; k < 5; ++k) t[static_cast<std::size_t>(k)] = level * small(rng);
    t[5] = level * 0.6;
  }
  std::vector<Image> images;
  for (const auto& d : dirs) {
    Image img(w, h, 1, ColourSpace::kLinear);
    const auto b = ptm_basis(d.x(), d.y());
    for (int y = 0; y < h; ++y)
      for (int x = 0; x < w; ++x) {
        double v = 0.0;
        for (int k = 0; k < 6; ++k)
          v += (*truth)[static_cast<std::size_t>(y * w + x)][static_cast<std::size_t>(k)] *
               b[static_cast<std::size_t>(k)];
        img.at(x, y, 0) = static_cast<float>(v);
      }
    images.push_back(std::move(img));
  }
  return images;
}

double max_rel_error(const CoefficientMap& map, const std::vector<std::array<double, 6>>& truth,
                     double level) {
  double worst = 0.0;
  for (int y = 0; y < map.height; ++y)
    for (int x = 0; x < map.width; ++x)
      for (int k = 0; k < 6; ++k) {
        const double d =
            map.texel_coeffs(x, y)[k] -
            truth[static_cast<std::size_t>(y * map.width + x)][static_cast<std::size_t>(k)];
        worst = std::max(worst, std::abs(d) / level);
      }
  return worst;
}

TEST(RobustStability, LightsAtOneToFiveDegreesFitWithTheirConditionReported) {
  const auto dirs = ring_layout(parse_rings("1:8,3:8,5:8"));
  const DesignReport r = analyse_design(dirs);
  EXPECT_GT(r.condition_number, kLowRingsMinCondition);
  EXPECT_LT(r.condition_number, kLowRingsMaxCondition);
  EXPECT_TRUE(r.problem.empty()) << r.problem;
  std::vector<std::array<double, 6>> truth;
  const auto images = poly_images(dirs, 1.0, &truth);
  for (Solver s : {Solver::kLS, Solver::kQR, Solver::kSVD, Solver::kRobust}) {
    FitOptions o;
    o.solver = s;
    o.precision = Precision::kDouble;
    CoefficientMap map;
    CoefficientMapSink sink(&map);
    const FitReport rep = fit_images(images, dirs, o, sink);
    EXPECT_NEAR(rep.design.condition_number, r.condition_number,
                kSameConditionRelTol * r.condition_number);
    EXPECT_LT(max_rel_error(map, truth, 1.0), kLowRingsCoeffRelTol) << to_string(s);
  }
}

TEST(RobustStability, SingleRingIsAnErrorNamingTheRingOrARidgeFitWhenAsked) {
  const auto dirs = ring_layout(parse_rings("30:16"));
  std::vector<std::array<double, 6>> truth;
  const auto images = poly_images(dirs, 1.0, &truth);
  FitOptions o;
  o.solver = Solver::kRobust;
  CoefficientMap map;
  CoefficientMapSink sink(&map);
  try {
    (void)fit_images(images, dirs, o, sink);
    FAIL();
  } catch (const Error& e) {
    EXPECT_THAT(e.what(), HasSubstr("same elevation"));
  }
  o.solver = Solver::kRidge;
  EXPECT_TRUE(fit_images(images, dirs, o, sink).design.regularised);
}

TEST(RobustStability, ClusteredExactlySixAndNearDuplicateLights) {
  struct Case {
    const char* what;
    std::vector<Eigen::Vector3d> dirs;
    double tol;  // relative coefficient error
  };
  std::vector<Eigen::Vector3d> cone;  // 12 lights within 15 degrees of (elev 60, az 30)
  for (int i = 0; i < 12; ++i) {
    cone.push_back(
        direction_from_angles_deg(52.5 + 15.0 * (i % 3) / 2.0, 22.5 + 15.0 * (i / 3) / 3.0));
  }
  auto dup = ring_layout(parse_rings("20:8,50:8,80:4"));
  dup.push_back((dup[3] + Eigen::Vector3d(1e-7, 0, 0)).normalized());
  std::vector<Case> cases = {{"cone", cone, kConeCoeffRelTol},
                             {"six", ring_layout(parse_rings("20:3,60:3")), kSixCoeffRelTol},
                             {"near-duplicate", dup, kNearDuplicateCoeffRelTol}};
  for (const auto& c : cases) {
    const DesignReport r = analyse_design(c.dirs);
    std::vector<std::array<double, 6>> truth;
    const auto images = poly_images(c.dirs, 1.0, &truth);
    for (Solver s : {Solver::kLS, Solver::kQR, Solver::kSVD}) {
      for (Precision p : {Precision::kDouble, Precision::kFloat}) {
        FitOptions o;
        o.solver = s;
        o.precision = p;
        CoefficientMap map;
        CoefficientMapSink sink(&map);
        if (!r.problem.empty()) {
          EXPECT_THROW((void)fit_images(images, c.dirs, o, sink), Error) << c.what;
          continue;
        }
        (void)fit_images(images, c.dirs, o, sink);
        RecordProperty(std::string(c.what) + "_cond", std::to_string(r.condition_number));
        EXPECT_LT(max_rel_error(map, truth, 1.0), c.tol)
            << c.what << " cond " << r.condition_number << " " << to_string(s);
      }
    }
  }
}

TEST(RobustStability, HdrFloatInputFrom1em4To1e4ScalesExactly) {
  const auto dirs = ring_layout(parse_rings("10:18,30:12,50:10,70:8,90:1"));
  for (double level : {1e-4, 1.0, 1e4}) {
    std::vector<std::array<double, 6>> truth;
    const auto images = poly_images(dirs, level, &truth);
    for (Solver s : {Solver::kLS, Solver::kRobust, Solver::kIrlsHuber}) {
      FitOptions o;
      o.solver = s;
      o.robust.saturation_level = std::numeric_limits<double>::infinity();  // HDR: no clipping
      CoefficientMap map;
      CoefficientMapSink sink(&map);
      (void)fit_images(images, dirs, o, sink);
      EXPECT_LT(max_rel_error(map, truth, level), kHdrCoeffRelTol) << level << " " << to_string(s);
    }
  }
}

}  // namespace
}  // namespace ptmkit::fit
