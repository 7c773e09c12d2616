#include "ptmkit/fit/fit.h"

#include <cstring>
#include <random>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "ptmkit/calib/dome.h"
#include "ptmkit/core/colour.h"
#include "ptmkit/core/error.h"
#include "ptmkit/core/image_io.h"
#include "ptmkit/core/light_layout.h"
#include "ptmkit/core/light_set.h"
#include "ptmkit/core/stack_reader.h"
#include "ptmkit/synth/synth.h"
#include "test_util.h"
#include "tolerances.h"

using ::testing::HasSubstr;

namespace fs = std::filesystem;

namespace ptmkit::fit {
namespace {

using test::kDoubleSolveRoundoff;
using test::kFloatRoundoff;
using test::kFloatSumRoundoff;

// The float path rounds the pseudo-inverse and the products as well as the samples: a few
// roundings per coefficient more than the double path.
constexpr double kFloatPathRoundings = 8.0;
// Residuals of an exact world fitted from float samples: a few float ulps, in grey levels.
constexpr double kExactResidualUlps = 8.0;
// The RMS of 158k residuals of noise sigma 2.4 grey levels varies by 0.004 (sigma / sqrt(2N)):
// this is 25 of those.
constexpr double kNoiseRmsTolGrey = 0.1;
// An exact luminance-times-colour texture fitted in float: 255 x a few ulps (1.2e-7) is about
// 1e-4 grey levels.
constexpr double kExactFitMaxResidualGrey = 1e-3;
// Six lights interpolated by the exact 6 x 6 solve in double: eps 2.2e-16 times its
// condition number (cond 21.7 here: 5e-15; measured 3e-16).
constexpr double kSixLightInterpolationTol = 1e-10;
// One ring leaves A rank-deficient: its condition number is infinite up to rounding (1/eps is
// 4.5e15; a ring measures 1.5e16); the fit refuses layouts above 1e5.
constexpr double kSingularCondition = 1e12;

std::vector<Eigen::Vector3d> dome49() { return calib::layout_directions("dome49"); }

// Per-texel random polynomials whose values stay inside (0, 1) over the upper hemisphere:
// a5 around 0.5 and the other terms small (|sum| <= 0.4 for lu^2 + lv^2 <= 1).
CoefficientMap random_world(int w, int h, std::uint64_t seed) {
  CoefficientMap map(w, h, ColourModel::kRGB, ColourSpace::kLinear);
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<float> small(-0.08f, 0.08f);
  std::uniform_real_distribution<float> base(0.4f, 0.6f);
  for (std::size_t i = 0; i < map.coeffs.size(); ++i) {
    map.coeffs[i] = (i % kPtmTerms == 5) ? base(rng) : small(rng);
  }
  return map;
}

std::vector<Image> render_world(const CoefficientMap& map,
                                const std::vector<Eigen::Vector3d>& dirs) {
  std::vector<Image> images;
  for (const auto& d : dirs) {
    Image img(map.width, map.height, 3, map.colour_space);
    for (int y = 0; y < map.height; ++y)
      for (int x = 0; x < map.width; ++x) map.evaluate(x, y, d.x(), d.y(), &img.at(x, y, 0));
    images.push_back(std::move(img));
  }
  return images;
}

// Bit-for-bit equality of two float arrays (memcmp must not see the null data() of an empty one).
bool same_bits(const std::vector<float>& a, const std::vector<float>& b) {
  return a.size() == b.size() &&
         (a.empty() || std::memcmp(a.data(), b.data(), a.size() * sizeof(float)) == 0);
}

// Largest absolute row sum of the pseudo-inverse: how much an error in the samples can move a
// coefficient (infinity-norm amplification).
double pinv_gain(const LightDesign& design) {
  return design.pseudo_inverse().cwiseAbs().rowwise().sum().maxCoeff();
}

TEST(LightDesign, RecoversAnExactPolynomialToDoublePrecision) {
  std::mt19937_64 rng(test::test_seed());
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  for (const auto& dirs : {dome49(), geodesic_dome(2), ring_layout(parse_rings("5:8,45:8,85:4"))}) {
    const LightDesign design = LightDesign::build(dirs);
    for (int trial = 0; trial < 100; ++trial) {
      double truth[6];
      for (double& t : truth) t = u(rng);
      std::vector<double> samples;
      for (const auto& d : dirs) {
        const auto b = ptm_basis(d.x(), d.y());
        double v = 0.0;
        for (int k = 0; k < 6; ++k) v += truth[k] * b[k];
        samples.push_back(v);
      }
      double got[6];
      design.solve(samples.data(), got);
      for (int k = 0; k < 6; ++k)
        ASSERT_NEAR(got[k], truth[k], kDoubleSolveRoundoff) << "term " << k;
    }
  }
}

TEST(FitImages, RecoversThePolynomialWorldWithinFloatInputPrecision) {
  const auto dirs = dome49();
  const CoefficientMap truth = random_world(24, 16, test::test_seed());
  const auto images = render_world(truth, dirs);
  const LightDesign design = LightDesign::build(dirs);
  for (Precision precision : {Precision::kDouble, Precision::kFloat}) {
    CoefficientMap got;
    CoefficientMapSink sink(&got);
    FitOptions options;
    options.precision = precision;
    const FitReport report = fit_images(images, dirs, options, sink);
    // Samples are floats (relative rounding 2^-24 of values below 1) and so is the stored
    // result; the float path also rounds the pseudo-inverse and the products.
    const double eps = std::ldexp(1.0, -24);
    const double tol =
        pinv_gain(design) * eps * (precision == Precision::kFloat ? kFloatPathRoundings : 1.0) +
        2.0 * eps;
    ASSERT_EQ(got.coeffs.size(), truth.coeffs.size());
    for (std::size_t i = 0; i < got.coeffs.size(); ++i) {
      ASSERT_NEAR(got.coeffs[i], truth.coeffs[i], tol) << "index " << i;
    }
    EXPECT_LT(report.residuals.rms_grey, 255.0 * kExactResidualUlps * eps);
    EXPECT_EQ(report.lights, 49);
    EXPECT_NEAR(report.design.condition_number, test::kDome49Condition, test::kDome49ConditionTol);
  }
}

TEST(FitImages, ResultsDoNotDependOnThreadsOrBandSize) {
  const auto dirs = dome49();
  auto images = render_world(random_world(37, 29, test::test_seed()), dirs);
  std::mt19937_64 rng(test::test_seed());
  std::normal_distribution<float> noise(0.0f, 0.01f);
  for (auto& img : images)
    for (std::size_t i = 0; i < img.size(); ++i) img.data()[i] += noise(rng);
  std::vector<CoefficientMap> maps;
  std::vector<FitReport> reports;
  for (auto [threads, band] : {std::pair{1, 16}, std::pair{2, 3}, std::pair{2, 64}}) {
    for (ColourModel model : {ColourModel::kRGB, ColourModel::kLRGB, ColourModel::kYCC}) {
      CoefficientMap got;
      CoefficientMapSink sink(&got);
      FitOptions options;
      options.threads = threads;
      options.band_rows = band;
      options.model = model;
      reports.push_back(fit_images(images, dirs, options, sink));
      maps.push_back(std::move(got));
    }
  }
  for (std::size_t i = 3; i < maps.size(); ++i) {
    const auto& a = maps[i % 3];
    const auto& b = maps[i];
    EXPECT_TRUE(same_bits(a.coeffs, b.coeffs));
    EXPECT_TRUE(same_bits(a.colour, b.colour));
    EXPECT_EQ(reports[i % 3].residuals.rms_grey, reports[i].residuals.rms_grey);
    EXPECT_EQ(reports[i % 3].residuals.p99_abs_grey, reports[i].residuals.p99_abs_grey);
  }
  // Noise of sigma 0.01 (2.55 grey) leaves residuals of sigma * sqrt((N - 6) / N) in RGB.
  EXPECT_NEAR(reports[0].residuals.rms_grey, 2.55 * std::sqrt(43.0 / 49.0), kNoiseRmsTolGrey);
}

TEST(FitImages, LuminanceModelsReproduceAConstantChromaTexture) {
  // Every texel is Y(l) times a fixed colour: LRGB reproduces it exactly; for YCC, a grey
  // texel (Cb = Cr = 0) is exact.
  const auto dirs = dome49();
  CoefficientMap lum = random_world(8, 8, test::test_seed());
  std::vector<Image> images;
  const float colour[3] = {0.9f, 0.5f, 0.2f};
  for (const auto& d : dirs) {
    Image img(8, 8, 3);
    for (int y = 0; y < 8; ++y)
      for (int x = 0; x < 8; ++x) {
        float rgb[3];
        lum.evaluate(x, y, d.x(), d.y(), rgb);
        const float grey = x < 4 ? 1.0f : 0.0f;  // left half grey, right half coloured
        for (int c = 0; c < 3; ++c) img.at(x, y, c) = rgb[0] * (grey + (1 - grey) * colour[c]);
      }
    images.push_back(std::move(img));
  }
  CoefficientMap lrgb;
  CoefficientMapSink lrgb_sink(&lrgb);
  FitOptions options;
  options.model = ColourModel::kLRGB;
  const FitReport rl = fit_images(images, dirs, options, lrgb_sink);
  EXPECT_LT(rl.residuals.max_abs_grey, kExactFitMaxResidualGrey);
  EXPECT_NEAR(lrgb.texel_colour(6, 3)[0], 1.0f, kFloatRoundoff);
  EXPECT_NEAR(lrgb.texel_colour(6, 3)[2], colour[2] / colour[0], kFloatSumRoundoff);

  CoefficientMap ycc;
  CoefficientMapSink ycc_sink(&ycc);
  options.model = ColourModel::kYCC;
  (void)fit_images(images, dirs, options, ycc_sink);
  for (int x = 0; x < 4; ++x) {
    EXPECT_NEAR(ycc.texel_colour(x, 2)[0], 0.0f, kFloatRoundoff);
    float got[3], want[3];
    ycc.evaluate(x, 2, 0.3, 0.4, got);
    lum.evaluate(x, 2, 0.3, 0.4, want);
    EXPECT_NEAR(got[1], want[0], kFloatSumRoundoff);
  }
}

// 8-bit photographs are streamed as bytes (BandStorage::kNative8) and converted inside the
// fit, with its own AVX2 luminance pass; results must be the same bits as the float route
// (fit_images on the decoded images), for every colour model and solver family, and for a
// width that leaves a tail after the 8-texel blocks.
TEST(FitCapture, EightBitStreamingMatchesTheFloatPathBitForBit) {
  test::ScratchDir dir;
  const auto dirs = dome49();
  const auto world = render_world(random_world(37, 11, test::test_seed()), dirs);
  LightSet lights;
  std::vector<Image> decoded;
  for (std::size_t i = 0; i < dirs.size(); ++i) {
    const fs::path file = dir / ("img" + std::to_string(i) + ".png");
    write_image(file, world[i].view(), {.format = PixelFormat::kU8});
    Light l;
    l.image = file;
    l.direction = dirs[i];
    lights.lights.push_back(l);
  }
  // The reader's float route (v / 255 by table) decodes the same files.
  decoded = read_stack(lights.images());
  for (const Solver solver : {Solver::kLS, Solver::kSign}) {
    for (const ColourModel model : {ColourModel::kRGB, ColourModel::kLRGB, ColourModel::kYCC}) {
      SCOPED_TRACE(std::string(to_string(model)) + " " + std::string(to_string(solver)));
      FitOptions options;
      options.model = model;
      options.solver = solver;
      options.band_rows = 4;
      CoefficientMap streamed, in_memory;
      CoefficientMapSink a(&streamed), b(&in_memory);
      const FitReport ra = fit_capture(lights, options, a);
      const FitReport rb = fit_images(decoded, dirs, options, b);
      EXPECT_TRUE(same_bits(streamed.coeffs, in_memory.coeffs));
      EXPECT_TRUE(same_bits(streamed.colour, in_memory.colour));
      EXPECT_EQ(ra.residuals.rms_grey, rb.residuals.rms_grey);
    }
  }
}

TEST(LightDesign, RefusesLayoutsThatCannotBeFittedAndSaysWhy) {
  auto expect_problem = [](const std::vector<Eigen::Vector3d>& dirs, const std::string& what) {
    try {
      (void)LightDesign::build(dirs);
      FAIL() << "expected a refusal mentioning: " << what;
    } catch (const Error& e) {
      EXPECT_THAT(e.what(), HasSubstr(what));
    }
  };
  expect_problem(ring_layout(parse_rings("30:3,60:2")), "at least 6 lights");
  expect_problem(ring_layout(parse_rings("30:12")), "same elevation");
  expect_problem(ring_layout(parse_rings("30:12")), "--ridge");
  // Ridge makes the single ring solvable, and the report says it was regularised.
  DesignOptions ridge;
  ridge.ridge_lambda = 1e-3;
  const LightDesign d = LightDesign::build(ring_layout(parse_rings("30:12")), ridge);
  EXPECT_TRUE(d.report().regularised);
  EXPECT_TRUE(d.report().single_ring);
  EXPECT_GT(d.report().condition_number, kSingularCondition);
  // A tiny condition limit refuses even a good dome.
  DesignOptions strict;
  strict.max_condition = 2.0;
  try {
    (void)LightDesign::build(dome49(), strict);
    FAIL();
  } catch (const Error& e) {
    EXPECT_THAT(e.what(), HasSubstr("badly conditioned"));
  }
}

TEST(LightDesign, ExactlySixLightsInterpolate) {
  const std::vector<Eigen::Vector3d> dirs = {
      direction_from_angles_deg(90, 0),  direction_from_angles_deg(30, 0),
      direction_from_angles_deg(30, 90), direction_from_angles_deg(30, 200),
      direction_from_angles_deg(60, 45), direction_from_angles_deg(60, 250)};
  const LightDesign design = LightDesign::build(dirs);
  const double samples[6] = {0.1, 0.7, 0.3, 0.9, 0.2, 0.5};
  double c[6];
  design.solve(samples, c);
  for (std::size_t i = 0; i < dirs.size(); ++i) {
    const auto b = ptm_basis(dirs[i].x(), dirs[i].y());
    double v = 0;
    for (int k = 0; k < 6; ++k) v += c[k] * b[k];
    EXPECT_NEAR(v, samples[i], kSixLightInterpolationTol);
  }
}

TEST(FitImages, RejectsNaNAndMismatchedInput) {
  const auto dirs = dome49();
  auto images = render_world(random_world(4, 4, 1), dirs);
  CoefficientMap got;
  CoefficientMapSink sink(&got);
  auto short_dirs = dirs;
  short_dirs.pop_back();
  EXPECT_THROW((void)fit_images(images, short_dirs, {}, sink), Error);
  images[7].at(2, 3, 1) = std::nanf("");
  try {
    (void)fit_images(images, dirs, {}, sink);
    FAIL();
  } catch (const Error& e) {
    EXPECT_THAT(e.what(), HasSubstr("NaN"));
  }
}

TEST(FitImages, GreyInputGivesThreeEqualPolynomials) {
  const auto dirs = dome49();
  const auto rgb_images = render_world(random_world(6, 5, 3), dirs);
  std::vector<Image> grey;
  for (const auto& img : rgb_images) {
    Image g(6, 5, 1);
    for (int y = 0; y < 5; ++y)
      for (int x = 0; x < 6; ++x) g.at(x, y, 0) = img.at(x, y, 1);
    grey.push_back(std::move(g));
  }
  CoefficientMap got;
  CoefficientMapSink sink(&got);
  (void)fit_images(grey, dirs, {}, sink);
  for (int k = 0; k < 6; ++k) {
    EXPECT_EQ(got.texel_coeffs(2, 2)[k], got.texel_coeffs(2, 2)[6 + k]);
    EXPECT_EQ(got.texel_coeffs(2, 2)[k], got.texel_coeffs(2, 2)[12 + k]);
  }
}

// synth's polynomial world (every texel an exact biquadratic), sampled in double at its own
// lights: the least-squares solve gives back the stored coefficients to 1e-9, before any
// quantisation, at every texel and channel.
TEST(PolynomialWorld, ExactRecoveryOfEveryTexelInDouble) {
  const synth::SynthOptions options = synth::preset_options("polynomial");
  const synth::Scene scene = synth::build_scene(options);
  const auto dirs = synth::resolve_lights(options);
  const LightDesign design = LightDesign::build(dirs);
  std::vector<double> samples[3];
  for (auto& s : samples) s.resize(dirs.size());
  double worst = 0.0;
  for (int y = 0; y < scene.height; ++y) {
    for (int x = 0; x < scene.width; ++x) {
      for (std::size_t i = 0; i < dirs.size(); ++i) {
        double rgb[3];
        synth::evaluate_polynomial(scene, x, y, dirs[i].x(), dirs[i].y(), rgb);
        for (int c = 0; c < 3; ++c) samples[c][i] = rgb[c];
      }
      const float* truth = scene.coefficients.texel_coeffs(x, y);
      for (int c = 0; c < 3; ++c) {
        double got[6];
        design.solve(samples[c].data(), got);
        for (int k = 0; k < 6; ++k) worst = std::max(worst, std::abs(got[k] - truth[c * 6 + k]));
      }
    }
  }
  EXPECT_LT(worst, kDoubleSolveRoundoff);
  std::printf("polynomial world %dx%d, %zu lights: max coefficient error %.3g\n", scene.width,
              scene.height, dirs.size(), worst);
}

}  // namespace
}  // namespace ptmkit::fit
