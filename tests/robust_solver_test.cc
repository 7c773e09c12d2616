// Robust per-texel solvers: quality against synth truth, labels, determinism, CLI, extremes.
#include <cmath>
#include <fstream>
#include <limits>
#include <ostream>
#include <random>

#include <gmock/gmock.h>
#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include "ptmkit/core/error.h"
#include "ptmkit/core/image_io.h"
#include "ptmkit/core/light_layout.h"
#include "synth_stack.h"
#include "test_util.h"
#include "tolerances.h"

using ::testing::HasSubstr;

namespace ptmkit::fit {
namespace {

constexpr int kSize = 64;  // pixels: the presets' relief scaled down, same scene

// Outlier labels over lit samples: precision >= 0.8 and recall >= 0.6, the requirement
// (docs/TARGETS.md); measured at 64 px: precision 0.86-0.97, recall 0.78-1.00.
constexpr double kOutlierPrecisionTarget = 0.8;
constexpr double kOutlierRecallTarget = 0.6;
// QR and SVD against Cholesky on dome49: cond(A^T A) = 28, so they agree to about 1e-15 x 28
// relative.
constexpr double kPinvMethodsAgreeTol = 1e-12;
// The Ceres losses over least squares on the glossy preset at 24 px: measured +1.8 to +2.9 dB.
constexpr double kCeresMinGainDb = 1.0;
// Normals of the command's robust fit (32 px glossy capture, 16-bit PNG) against the truth:
// measured mean 0.36 degrees.
constexpr double kCliNormalsMeanTolDeg = 2.0;
// Readmission's gain in label precision: measured 0.52 to 0.78 (+0.26).
constexpr double kReadmitPrecisionGain = 0.1;
// Recall with readmission: measured 0.61.
constexpr double kReadmitMinRecall = 0.5;
// Filling rejected samples with the Lambertian model: measured +1.35 dB truth PSNR.
constexpr double kFillGainDb = 0.5;
// Keeping samples close to the Lambertian model: label precision measured 0.96 against 0.56.
constexpr double kKeepPrecisionGain = 0.2;
// The price of keeping: the kept samples' deviations go into the fit, measured -0.52 dB.
constexpr double kKeepPsnrCostDb = 1.0;

struct PresetCase {
  const char* preset;
  // The required gain (docs/TARGETS.md) of the default robust solver over least squares, PSNR
  // against the diffuse truth over lit samples (eval/truth.h). Measured at 64 px: 3.22 / 0.87 /
  // 5.99 / 4.48 / 3.22 dB.
  double min_gain_db;
};
// Readable test names in listings (gtest would otherwise print the struct's bytes).
void PrintTo(const PresetCase& c, std::ostream* os) {
  *os << c.preset << ", min gain " << c.min_gain_db << " dB";
}

class RobustPresets : public ::testing::TestWithParam<PresetCase> {};

TEST_P(RobustPresets, BeatsLeastSquaresOnTheDiffuseTruthAndOnNormals) {
  const PresetCase c = GetParam();
  const auto stack = test::render_preset(c.preset, kSize);
  const auto ls = test::score_solver(stack, Solver::kLS);
  const auto robust = test::score_solver(stack, Solver::kRobust);
  EXPECT_GE(robust.psnr_db - ls.psnr_db, c.min_gain_db) << c.preset;
  // Normals from the inliers beat normals from every sample (required on every preset).
  EXPECT_LT(robust.normals.mean_deg, ls.normals.mean_deg) << c.preset;
  // Samples more than 20 grey levels off the truth, labelled.
  if (robust.outliers_lit.true_outliers > 0) {
    EXPECT_GE(robust.outliers_lit.recall, kOutlierRecallTarget) << c.preset;
  }
  EXPECT_GE(robust.outliers_lit.precision, kOutlierPrecisionTarget) << c.preset;
  EXPECT_EQ(robust.report.outliers.samples, static_cast<std::uint64_t>(kSize * kSize * 49));
  EXPECT_GT(robust.report.outliers.shadows, 0u);
}

INSTANTIATE_TEST_SUITE_P(Presets, RobustPresets,
                         ::testing::Values(PresetCase{"default", 2.0}, PresetCase{"matte", -0.1},
                                           PresetCase{"glossy", 4.0}, PresetCase{"tall", 4.0},
                                           PresetCase{"ambient", 1.5}),
                         [](const ::testing::TestParamInfo<PresetCase>& p) {
                           return std::string(p.param.preset);
                         });

TEST(RobustSolver, SolverNamesRoundTripAndUnknownNamesAreRefused) {
  for (const auto& name : solver_names()) EXPECT_EQ(to_string(parse_solver(name)), name);
  EXPECT_EQ(resolve_solver(Solver::kRobust), Solver::kLambert);
  try {
    (void)parse_solver("fastest");
    FAIL();
  } catch (const Error& e) {
    EXPECT_THAT(e.what(), HasSubstr("irls-huber"));
  }
}

std::vector<Eigen::Vector3d> dome49() {
  return ring_layout(parse_rings("10:18,30:12,50:10,70:8,90:1"));
}

// A polynomial texel with injected shadows (value 0) and highlights (+0.4): the sign rule
// recovers the polynomial and labels exactly the injected samples; least squares does not.
TEST(RobustSolver, SignRuleRecoversAPolynomialUnderInjectedOutliers) {
  const auto dirs = dome49();
  const LightDesign design = LightDesign::build(dirs);
  TexelSolver solver(design.design(), Solver::kSign, RobustOptions{});
  std::mt19937_64 rng(test::test_seed());
  std::uniform_real_distribution<double> small(-0.08, 0.08);
  const std::size_t n = dirs.size();
  for (int trial = 0; trial < 50; ++trial) {
    double truth[6];
    for (double& t : truth) t = small(rng);
    truth[5] = 0.6;
    std::vector<double> v(n), w(n);
    std::vector<std::uint8_t> sat(n, 0);
    std::vector<SampleLabel> expect(n, SampleLabel::kInlier), got(n);
    for (std::size_t i = 0; i < n; ++i) {
      const auto b = ptm_basis(dirs[i].x(), dirs[i].y());
      for (int k = 0; k < 6; ++k) v[i] += truth[k] * b[static_cast<std::size_t>(k)];
    }
    for (int k = 0; k < 4; ++k) {  // distinct lights: 2 shadows, 2 highlights
      const auto i = static_cast<std::size_t>((trial * 7 + k * 11) % 49);
      if (k < 2) {
        v[i] = 0.0;
        expect[i] = SampleLabel::kShadow;
      } else {
        v[i] += 0.4;
        expect[i] = SampleLabel::kHighlight;
      }
    }
    double c[6];
    const TexelOutcome out = solver.solve(v.data(), sat.data(), w.data(), got.data(), c);
    EXPECT_EQ(got, expect) << "trial " << trial;
    EXPECT_EQ(out.shadows, 2);
    EXPECT_EQ(out.highlights, 2);
    // Exact data: only rounding remains.
    for (int k = 0; k < 6; ++k) {
      EXPECT_NEAR(c[k], truth[k], test::kDoubleSolveRoundoff) << "trial " << trial;
    }
  }
}

TEST(RobustSolver, QrAndSvdAgreeWithCholeskyOnAWellConditionedDome) {
  const auto dirs = dome49();
  const LightDesign chol = LightDesign::build(dirs);
  for (PinvMethod m : {PinvMethod::kQR, PinvMethod::kSVD}) {
    DesignOptions o;
    o.method = m;
    const LightDesign other = LightDesign::build(dirs, o);
    EXPECT_LT((other.pseudo_inverse() - chol.pseudo_inverse()).cwiseAbs().maxCoeff(),
              kPinvMethodsAgreeTol);
  }
}

TEST(RobustSolver, ResultsDoNotDependOnThreadsOrBands) {
  const auto stack = test::render_preset("glossy", 24);
  for (Solver solver : {Solver::kRobust, Solver::kIrlsTukey, Solver::kCeresHuber}) {
    std::vector<float> first;
    std::vector<std::uint8_t> first_labels;
    for (int threads : {1, 2}) {
      for (int band : {1, 7}) {
        FitOptions o;
        o.solver = solver;
        o.threads = threads;
        o.band_rows = band;
        FitOutputs out;
        out.want_labels = true;
        CoefficientMap map;
        CoefficientMapSink sink(&map);
        (void)fit_images(stack.observed, stack.dirs, o, sink, &out);
        if (first.empty()) {
          first = map.coeffs;
          first_labels = out.labels;
        } else {
          EXPECT_EQ(map.coeffs, first) << to_string(solver) << " threads " << threads;
          EXPECT_EQ(out.labels, first_labels) << to_string(solver);
        }
      }
    }
  }
}

TEST(RobustSolver, CeresVariantsRejectOutliersToo) {
  const auto stack = test::render_preset("glossy", 24);
  const auto ls = test::score_solver(stack, Solver::kLS);
  for (Solver s : {Solver::kCeresHuber, Solver::kCeresCauchy, Solver::kCeresTukey}) {
    const auto r = test::score_solver(stack, s);
    // Symmetric losses help on highlights.
    EXPECT_GT(r.psnr_db - ls.psnr_db, kCeresMinGainDb) << to_string(s);
    EXPECT_GT(r.report.outliers.ceres_texels, 0u);
  }
}

// Every luminance model and grey input go through the robust path and stay finite.
TEST(RobustSolver, AllModelsAndDarkOrSaturatedTexelsStayFinite) {
  auto stack = test::render_preset("default", 16);
  // Texel (0, 0) black under every light, texel (1, 0) saturated under every light.
  for (auto& img : stack.observed) {
    for (int c = 0; c < 3; ++c) {
      img.at(0, 0, c) = 0.0f;
      img.at(1, 0, c) = 1.0f;
    }
  }
  for (ColourModel m : {ColourModel::kRGB, ColourModel::kLRGB, ColourModel::kYCC}) {
    FitOptions o;
    o.solver = Solver::kRobust;
    o.model = m;
    FitOutputs out;
    out.want_normals = true;
    out.want_residual_map = true;
    out.want_outlier_counts = true;
    CoefficientMap map;
    CoefficientMapSink sink(&map);
    const FitReport rep = fit_images(stack.observed, stack.dirs, o, sink, &out);
    for (float v : map.coeffs) ASSERT_TRUE(std::isfinite(v));
    for (float v : map.colour) ASSERT_TRUE(std::isfinite(v));
    float rgb[3];
    map.evaluate(0, 0, 0.3, 0.2, rgb);
    EXPECT_NEAR(rgb[0], 0.0f, static_cast<float>(test::kFloatRoundoff));  // black stays black
    map.evaluate(1, 0, 0.3, 0.2, rgb);
    // Saturated everywhere: kept (min_inliers), fits 1.
    EXPECT_NEAR(rgb[0], 1.0f, static_cast<float>(test::kFloatSumRoundoff));
    EXPECT_GT(rep.outliers.fallback_texels + rep.outliers.highlights, 0u);
    EXPECT_EQ(out.normals.width(), 16);
    EXPECT_NEAR(out.normals.at(5, 5, 0) * out.normals.at(5, 5, 0) +
                    out.normals.at(5, 5, 1) * out.normals.at(5, 5, 1) +
                    out.normals.at(5, 5, 2) * out.normals.at(5, 5, 2),
                1.0, test::kFloatSumRoundoff);
  }
}

TEST(RobustCli, FitsWithTheRobustSolverAndWritesMapsAndReport) {
  test::ScratchDir dir;
  synth::SynthOptions so = synth::preset_options("glossy");
  so.width = 32;
  so.height = 32;
  (void)synth::render_capture(so, dir.path() / "cap");
  const auto r = test::run_ptmkit(
      {"fit", (dir.path() / "cap" / "lights.lp").string(), "-o", (dir / "out.ptm").string(),
       "--solver", "robust", "--normals", (dir / "n.png").string(), "--residual-map",
       (dir / "res.exr").string(), "--outlier-map", (dir / "out.exr").string(), "--report",
       (dir / "rep.json").string()});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_THAT(r.out, HasSubstr("highlight"));
  const Image n = read_image(dir / "n.png");
  EXPECT_EQ(n.width(), 32);
  EXPECT_EQ(read_image(dir / "res.exr").channels(), 1);
  EXPECT_EQ(read_image(dir / "out.exr").channels(), 2);
  std::ifstream in(dir / "rep.json");
  const auto j = nlohmann::json::parse(in);
  EXPECT_EQ(j["solver"], "robust");
  EXPECT_GT(j["outliers"]["highlight"].get<double>(), 0.0);
  // Normals against the truth (16-bit PNG, (n + 1) / 2 both).
  const Image truth = read_image(dir.path() / "cap" / "truth" / "normals.png");
  Image est = n, tru = truth;
  for (std::size_t i = 0; i < est.size(); ++i) est.data()[i] = 2 * est.data()[i] - 1;
  for (std::size_t i = 0; i < tru.size(); ++i) tru.data()[i] = 2 * tru.data()[i] - 1;
  EXPECT_LT(eval::normal_error(est, tru).mean_deg, kCliNormalsMeanTolDeg);

  const auto bad = test::run_ptmkit({"fit", (dir.path() / "cap" / "lights.lp").string(), "-o",
                                     (dir / "o2.ptm").string(), "--solver", "nope"});
  EXPECT_NE(bad.exit_code, 0);
  const auto bad_map =
      test::run_ptmkit({"fit", (dir.path() / "cap" / "lights.lp").string(), "-o",
                        (dir / "o3.ptm").string(), "--residual-map", (dir / "r.png").string()});
  EXPECT_EQ(bad_map.exit_code, 1);
  EXPECT_THAT(bad_map.err, HasSubstr("r.png"));
  EXPECT_FALSE(std::filesystem::exists(dir / "o3.ptm"));
}

}  // namespace
}  // namespace ptmkit::fit

namespace ptmkit::fit {
namespace {

// RobustOptions::readmit_k trades truth PSNR for label precision (docs/SOLVERS.md, "Outlier
// labelling precision"); measured here on its own (keep_within, which does the same job
// against the Lambertian model and is on by default, off on both sides).
TEST(RobustSolver, ReadmissionRaisesLabelPrecision) {
  const auto stack = test::render_preset("default", 48);
  RobustOptions base;
  base.keep_within = 0.0;
  RobustOptions readmit = base;
  readmit.readmit_k = 2.5;
  const auto off = test::score_solver(stack, Solver::kRobust, base);
  const auto on = test::score_solver(stack, Solver::kRobust, readmit);
  ASSERT_GT(on.outliers_lit.true_outliers, 0u);
  EXPECT_GT(on.outliers_lit.precision, off.outliers_lit.precision + kReadmitPrecisionGain);
  EXPECT_LT(on.outliers_lit.labelled, off.outliers_lit.labelled);
  EXPECT_GE(on.outliers_lit.recall, kReadmitMinRecall);
  RobustOptions bad;
  bad.readmit_k = -1.0;
  EXPECT_FALSE(bad.validate().empty());
}

}  // namespace
}  // namespace ptmkit::fit

namespace ptmkit::fit {
namespace {

// Filling the rejected samples with the Lambertian model (RobustOptions::fill_rejected) keeps
// the polynomial from extrapolating into rejected regions; keeping the samples close to that
// model (keep_within) leaves only sure labels. Each measured against the default with it off.
TEST(RobustSolver, FillingAndKeepingCloseSamplesEachEarnTheirPlace) {
  const auto stack = test::render_preset("tall", 48);
  const auto both = test::score_solver(stack, Solver::kRobust);
  RobustOptions no_fill;
  no_fill.fill_rejected = false;
  const auto unfilled = test::score_solver(stack, Solver::kRobust, no_fill);
  EXPECT_GT(both.psnr_db, unfilled.psnr_db + kFillGainDb);
  RobustOptions no_keep;
  no_keep.keep_within = 0.0;
  const auto unkept = test::score_solver(stack, Solver::kRobust, no_keep);
  // Measured recall 0.89 against 0.93 without keeping.
  EXPECT_GT(both.outliers_lit.precision, unkept.outliers_lit.precision + kKeepPrecisionGain);
  EXPECT_GE(both.outliers_lit.recall, kOutlierRecallTarget);
  EXPECT_GT(both.psnr_db, unkept.psnr_db - kKeepPsnrCostDb);
  RobustOptions bad;
  bad.keep_within = -1.0;
  EXPECT_FALSE(bad.validate().empty());
  RobustOptions bad_fraction;
  bad_fraction.keep_within_fraction = std::numeric_limits<double>::quiet_NaN();
  EXPECT_FALSE(bad_fraction.validate().empty());
}

}  // namespace
}  // namespace ptmkit::fit
