// Bases, the HSH streaming fit, and model selection (--model auto).
#include <gtest/gtest.h>

#include <cmath>
#include <random>
#include <string>

#include "ptmkit/core/error.h"
#include "ptmkit/core/light_layout.h"
#include "ptmkit/core/light_set.h"
#include "ptmkit/fit/basis.h"
#include "ptmkit/fit/fit.h"
#include "ptmkit/fit/model_select.h"
#include "ptmkit/texture/rti.h"
#include "test_util.h"
#include "tolerances.h"

namespace ptmkit {
namespace {

using test::ScratchDir;

// An exact HSH world sampled into float images (6e-8 relative per sample) and fitted with 16
// terms on the dome49 layout, whose pseudo-inverse amplifies that by at most 10: 6e-7
// (measured worst 1.4e-8).
constexpr double kExactHshCoeffTol = 1e-6;
// An exact world fitted from float samples: 255 x a few ulps (1.2e-7) is about 1e-4 grey
// levels RMS.
constexpr double kExactFitRmsGrey = 1e-3;
// The selection's default: a simpler model within 2% of the best held-out RMS counts as equal
// (ModelSelectOptions::tolerance).
constexpr double kSelectionRelTol = 1.02;
// The polynomial world (float, no noise) under its own six-term polynomial: held-out RMS is
// float rounding, 255 x a few ulps as kExactFitRmsGrey (measured 2.5e-6 grey levels).
constexpr double kExactModelHeldOutRmsGrey = 1e-3;

std::vector<Eigen::Vector3d> dome49() {
  std::vector<Eigen::Vector3d> dirs;
  const int rings[5][2] = {{10, 18}, {30, 12}, {50, 10}, {70, 8}, {90, 1}};
  for (const auto& r : rings) {
    for (int i = 0; i < r[1]; ++i) {
      dirs.push_back(direction_from_angles_deg(r[0], 360.0 * i / r[1]));
    }
  }
  return dirs;
}

TEST(BasisFit, RecoversAnExactHshFunction) {
  const auto dirs = dome49();
  const int w = 9, h = 7, t = 16;
  std::mt19937_64 rng(test::test_seed());
  std::uniform_real_distribution<double> u(-0.2, 0.2);
  std::vector<double> truth(static_cast<std::size_t>(w) * h * 3 * t);
  for (double& c : truth) c = u(rng);
  std::vector<Image> images;
  for (const auto& d : dirs) {
    Image im(w, h, 3, ColourSpace::kLinear);
    double b[16];
    fit::evaluate_basis(fit::Basis::kHsh4, d, b);
    for (int y = 0; y < h; ++y) {
      for (int x = 0; x < w; ++x) {
        for (int k = 0; k < 3; ++k) {
          double v = 0.0;
          for (int j = 0; j < t; ++j) {
            v += truth[((static_cast<std::size_t>(y) * w + x) * 3 + k) * t + j] * b[j];
          }
          im.at(x, y, k) = static_cast<float>(v);
        }
      }
    }
    images.push_back(std::move(im));
  }
  fit::FitOptions o;
  o.basis = fit::Basis::kHsh4;
  o.band_rows = 3;  // several bands
  CoefficientMap map;
  CoefficientMapSink sink(&map);
  const fit::FitReport rep = fit::fit_images(images, dirs, o, sink);
  EXPECT_EQ(map.basis, Basis::kHsh4);
  ASSERT_EQ(map.coeffs.size(), truth.size());
  double max_err = 0.0;
  for (std::size_t i = 0; i < truth.size(); ++i) {
    max_err = std::max(max_err, std::abs(map.coeffs[i] - truth[i]));
  }
  EXPECT_LT(max_err, kExactHshCoeffTol);
  EXPECT_LT(rep.residuals.rms_grey, kExactFitRmsGrey);
  // A basis with fewer terms than lights cannot: 16 terms on 12 lights is refused.
  std::vector<Eigen::Vector3d> few(dirs.begin(), dirs.begin() + 12);
  std::vector<Image> few_images(images.begin(), images.begin() + 12);
  EXPECT_THROW(fit::fit_images(few_images, few, o, sink), Error);
}

// Renders a synth preset at 32 px through the CLI and runs the selection on it.
fit::ModelReport select_on(const ScratchDir& dir, const std::string& preset) {
  const auto out = dir / preset;
  const test::RunResult r = test::run_ptmkit(
      {"synth", "--preset", preset, "--size", "32", "--out", out.string(), "--no-truth"});
  EXPECT_EQ(r.exit_code, 0) << r.err;
  return fit::select_model(read_lp(out / "lights.lp"));
}

TEST(ModelSelect, FollowsTheScene) {
  ScratchDir dir;
  const fit::ModelReport matte = select_on(dir, "matte");
  const fit::ModelReport glossy = select_on(dir, "glossy");
  const fit::ModelReport poly = select_on(dir, "polynomial");
  for (const auto* r : {&matte, &glossy, &poly}) {
    ASSERT_GE(r->chosen, 0);
    EXPECT_EQ(r->candidates.size(), 8u);  // 4 bases x {lrgb, rgb}
    int chosen = 0;
    for (const auto& c : r->candidates) chosen += c.chosen ? 1 : 0;
    EXPECT_EQ(chosen, 1);
    // The choice is never worse than the tolerance allows (or within one SE).
    const auto& best = r->candidates[static_cast<std::size_t>(r->best)];
    const auto& pick = r->choice();
    EXPECT_TRUE(pick.heldout_rms_grey <=
                    best.heldout_rms_grey * kSelectionRelTol + test::kDoubleRoundoff ||
                pick.excess_mse <= pick.excess_se);
  }
  // An exact biquadratic world needs exactly the six-term polynomial, per channel.
  EXPECT_EQ(poly.choice().basis, fit::Basis::kPtm);
  EXPECT_EQ(poly.choice().colour, ColourModel::kRGB);
  EXPECT_LT(poly.choice().heldout_rms_grey, kExactModelHeldOutRmsGrey);
  // Matte needs no more than glossy.
  EXPECT_LE(matte.choice().parameters, glossy.choice().parameters);
  // The report carries the evidence.
  const std::string json = glossy.to_json();
  EXPECT_NE(json.find("heldout_rms_grey"), std::string::npos);
  EXPECT_NE(glossy.table().find("<- chosen"), std::string::npos);
}

TEST(ModelSelect, CliWritesTheMatchingFormat) {
  ScratchDir dir;
  const auto cap = dir / "poly";
  ASSERT_EQ(test::run_ptmkit({"synth", "--preset", "polynomial", "--size", "16", "--out",
                              cap.string(), "--no-truth"})
                .exit_code,
            0);
  const std::string lp = (cap / "lights.lp").string();
  // auto chooses the PTM here: an .rti name is refused, saying what to use.
  const test::RunResult bad =
      test::run_ptmkit({"fit", lp, "--model", "auto", "-o", (dir / "x.rti").string()});
  EXPECT_EQ(bad.exit_code, 1);
  EXPECT_NE(bad.err.find("use -o NAME.ptm"), std::string::npos) << bad.err;
  EXPECT_FALSE(std::filesystem::exists(dir / "x.rti"));
  const test::RunResult ok =
      test::run_ptmkit({"fit", lp, "--model", "auto", "-o", (dir / "x.ptm").string(), "--report",
                        (dir / "r.json").string()});
  EXPECT_EQ(ok.exit_code, 0) << ok.err;
  EXPECT_TRUE(std::filesystem::exists(dir / "x.ptm"));
  // An HSH model writes an .rti that relights.
  const test::RunResult hsh =
      test::run_ptmkit({"fit", lp, "--model", "hsh3", "-o", (dir / "h.rti").string()});
  EXPECT_EQ(hsh.exit_code, 0) << hsh.err;
  EXPECT_EQ(texture::read_rti(dir / "h.rti").terms(), 9);
  const test::RunResult wrong =
      test::run_ptmkit({"fit", lp, "--model", "hsh3", "-o", (dir / "h.ptm").string()});
  EXPECT_EQ(wrong.exit_code, 1);
  EXPECT_NE(wrong.err.find("use -o NAME.rti"), std::string::npos) << wrong.err;
}

}  // namespace
}  // namespace ptmkit
