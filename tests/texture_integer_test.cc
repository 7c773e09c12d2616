// The paper's 8-bit quantisation (shifts, bias 127, the .ptm8 container) and the integer
// hardware model (docs/INTEGER-MODEL.md): bit-exact fast path, error bound, extremes, and the
// measured error on a rendered relief.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdint>
#include <random>

#include "ptmkit/core/error.h"
#include "ptmkit/core/image_io.h"
#include "ptmkit/core/light_set.h"
#include "ptmkit/fit/fit.h"
#include "ptmkit/synth/synth.h"
#include "ptmkit/texture/integer_model.h"
#include "ptmkit/texture/ptm.h"
#include "ptmkit/texture/ptm8.h"
#include "ptmkit/texture/relight.h"
#include "test_util.h"
#include "tolerances.h"

namespace ptmkit::texture {
namespace {

using test::kDoubleSolveRoundoff;

// A float coefficient of order 1 in grey units (x 255): an ulp is 3e-5.
constexpr double kFloatGreyRoundoff = 1e-4;
// The derived bound is not vacuous: some sample comes within this factor of it (measured
// 0.94).
constexpr double kBoundTightnessRatio = 1.0 / 3.0;
// What the integer arithmetic adds to the stored bytes' own error (light quantisation, group
// alignment and two roundings: docs/INTEGER-MODEL.md section 3): measured +0.07 mean and +0.27
// max grey levels on the rendered relief.
constexpr double kArithmeticMeanAddGrey = 0.25;
constexpr double kArithmeticMaxAddGrey = 2.0;
// The requirement where the stored coefficients allow it (shifts >= -1): mean <= 1 and max
// <= 4 grey levels (docs/TARGETS.md).
constexpr double kIntegerTargetMeanGrey = 1.0;
constexpr double kIntegerTargetMaxGrey = 4.0;
// Steps of 4 grey levels: the stored bytes alone cost at least 0.5 mean (docs/INTEGER-MODEL.md
// section 3; measured 1.08), so the target is out of reach ...
constexpr double kCoarseStepFloorGrey = 0.5;
// ... and the model stays near that floor: measured mean 1.14, max 5.2 grey levels
// (docs/TEXTURE.md).
constexpr double kCoarseStepMeanGrey = 1.5;
constexpr double kCoarseStepMaxGrey = 8.0;
// The paper's shifts with float evaluation on the 32 px relief: measured mean 1.15 grey levels
// (docs/TEXTURE.md: 1.12).
constexpr double kPaperShiftsMeanGrey = 2.0;

// A fitted RGB map of a small rendered relief (the default preset, 48 x 48, dome49).
CoefficientMap relief_map(int size, ColourModel model = ColourModel::kRGB) {
  synth::SynthOptions so = synth::preset_options("default");
  so.width = so.height = size;
  const synth::Scene scene = synth::build_scene(so);
  const std::vector<Eigen::Vector3d> dirs = synth::resolve_lights(so);
  std::vector<Image> images;
  for (std::size_t i = 0; i < dirs.size(); ++i)
    images.push_back(synth::render_light(scene, so, dirs[i], static_cast<int>(i)).observed);
  CoefficientMap map;
  CoefficientMapSink sink(&map);
  fit::FitOptions fo;
  fo.model = model;
  fo.threads = 1;
  (void)fit::fit_images(images, dirs, fo, sink);
  return map;
}

std::vector<Eigen::Vector3d> elevation_sweep(double from_deg, double to_deg, double step_deg) {
  std::vector<Eigen::Vector3d> out;
  for (double e = from_deg; e <= to_deg + 1e-9; e += step_deg)
    for (double az = 0; az < 360; az += 45) out.push_back(direction_from_angles_deg(e, az + e));
  return out;
}

CoefficientMap random_map(int w, int h, std::uint64_t seed, double scale_high, double scale_mid,
                          double scale_low) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  CoefficientMap map(w, h, ColourModel::kRGB);
  for (std::size_t j = 0; j < map.coeffs.size(); ++j) {
    const int k = static_cast<int>(j % kPtmTerms);
    const double s = k < 3 ? scale_high : (k < 5 ? scale_mid : scale_low);
    map.coeffs[j] = static_cast<float>(k == 5 ? 0.5 * s * (1.0 + u(rng)) : s * u(rng));
  }
  return map;
}

TEST(TextureInteger, ShiftIsTheLargestThatNeverOverflows) {
  // The paper's example: 0.0128 (grey units here) needs a left shift of 13 and is stored as 105.
  EXPECT_EQ(choose_ptm8_shift(0.0128), 13);
  EXPECT_EQ(std::lround(0.0128 * 8192), 105);
  EXPECT_EQ(choose_ptm8_shift(127.0), 0);
  EXPECT_EQ(choose_ptm8_shift(127.6), -1);  // rounds to 128: would overflow
  EXPECT_EQ(choose_ptm8_shift(254.0), -1);
  EXPECT_EQ(choose_ptm8_shift(255.0), -2);  // 127.5 rounds to 128
  EXPECT_EQ(choose_ptm8_shift(300.0), -2);
  EXPECT_EQ(choose_ptm8_shift(0.0), kPtm8MaxShift);
  for (double m : {0.001, 0.3, 5.0, 90.0, 200.0, 1000.0}) {
    const int s = choose_ptm8_shift(m);
    EXPECT_LE(std::round(m * std::ldexp(1.0, s)), 127.0) << m;
    EXPECT_GT(std::round(m * std::ldexp(1.0, s + 1)), 127.0) << m;
  }
}

TEST(TextureInteger, QuantisedCoefficientsAreWithinHalfAStep) {
  const CoefficientMap map = random_map(9, 7, test::test_seed(), 0.3, 0.6, 1.1);
  const Ptm8Texture t = quantise_ptm8(map);
  const CoefficientMap back = dequantise_ptm8(t);
  for (std::size_t j = 0; j < map.coeffs.size(); ++j) {
    const int g = ptm8_group(static_cast<int>(j % kPtmTerms));
    EXPECT_LE(t.coeffs[j], 254);
    EXPECT_LE(std::abs(255.0 * (map.coeffs[j] - back.coeffs[j])),
              0.5 * t.step_grey(g) + kFloatGreyRoundoff);
  }
}

TEST(TextureInteger, ContainerRoundTripsRgbAndLrgb) {
  test::ScratchDir dir;
  for (ColourModel model : {ColourModel::kRGB, ColourModel::kLRGB}) {
    CoefficientMap map = random_map(6, 5, test::test_seed(), 0.2, 0.4, 0.8);
    if (model == ColourModel::kLRGB) {
      CoefficientMap l(6, 5, ColourModel::kLRGB);
      for (int y = 0; y < 5; ++y)
        for (int x = 0; x < 6; ++x) {
          for (int k = 0; k < kPtmTerms; ++k) l.texel_coeffs(x, y)[k] = map.texel_coeffs(x, y)[k];
          float* c = l.texel_colour(x, y);
          c[0] = 1.0f;
          c[1] = 0.1f * static_cast<float>(x);
          c[2] = 0.15f * static_cast<float>(y);
        }
      map = l;
    }
    const Ptm8Texture t = quantise_ptm8(map);
    const auto path = dir / (model == ColourModel::kRGB ? "a.ptm8" : "b.ptm8");
    write_ptm8(path, t);
    write_ptm8(path, t);  // replacing an existing container
    const Ptm8Texture r = read_ptm8(path);
    EXPECT_EQ(r.width, t.width);
    EXPECT_EQ(r.model, t.model);
    EXPECT_EQ(r.shifts, t.shifts);
    EXPECT_EQ(r.coeffs, t.coeffs);
    EXPECT_EQ(r.colour, t.colour);
  }
  EXPECT_THROW((void)read_ptm8(dir / "missing.ptm8"), Error);
  std::filesystem::remove(dir / "a.ptm8" / "p1_a345.png");
  try {
    (void)read_ptm8(dir / "a.ptm8");
    FAIL() << "a missing plane must be reported";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("p1_a345.png"), std::string::npos) << e.what();
  }
}

TEST(TextureInteger, FastPathAgreesBitForBitWithTheReference) {
  std::mt19937_64 rng(test::test_seed());
  std::uniform_int_distribution<int> byte(0, 255), shift(kPtm8MinShift, kPtm8MaxShift);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  for (int trial = 0; trial < 24; ++trial) {
    Ptm8Texture t;
    t.width = 13;
    t.height = 11;
    t.model = trial % 3 == 0 ? ColourModel::kLRGB : ColourModel::kRGB;
    t.shifts = {shift(rng), shift(rng), shift(rng)};
    if (trial % 4 == 1) t.shifts = {kPtm8MinShift, kPtm8MinShift, kPtm8MinShift};
    t.coeffs.resize(t.texels() * t.polynomials() * kPtmTerms);
    for (auto& b : t.coeffs) b = static_cast<std::uint8_t>(byte(rng));  // 255 included
    if (t.model == ColourModel::kLRGB) {
      t.colour.resize(t.texels() * 3);
      for (auto& b : t.colour) b = static_cast<std::uint8_t>(byte(rng));
    }
    for (int li = 0; li < 12; ++li) {
      Eigen::Vector3d l(u(rng), u(rng), li == 0 ? 1e-6 : u(rng));
      if (li == 1) l = {1, 0, 1e-9};  // grazing: lu rounds to 128 and clamps
      const auto fast = relight_integer_bytes(t, l);
      const Eigen::Vector3d n = l.normalized();
      const IntegerLight il = quantise_light(n.x(), n.y(), n.z());
      for (int y = 0; y < t.height; ++y)
        for (int x = 0; x < t.width; ++x) {
          std::uint8_t rgb[3];
          integer_texel_reference(t, x, y, il, rgb);
          for (int c = 0; c < 3; ++c)
            ASSERT_EQ(fast[(static_cast<std::size_t>(y) * t.width + x) * 3 + c], rgb[c])
                << "trial " << trial << " light " << li << " at " << x << "," << y;
        }
    }
  }
}

TEST(TextureInteger, ErrorStaysWithinTheDerivedBound) {
  const CoefficientMap map = random_map(16, 16, test::test_seed(), 0.25, 0.5, 1.0);
  const Ptm8Texture t = quantise_ptm8(map);
  double worst_ratio = 0.0;
  for (const auto& l : elevation_sweep(1.0, 90.0, 7.0)) {
    const IntegerLight il = quantise_light(l.x(), l.y(), l.z());
    for (int y = 0; y < map.height; ++y)
      for (int x = 0; x < map.width; ++x) {
        std::uint8_t rgb[3];
        integer_texel_reference(t, x, y, il, rgb);
        const float* a = map.texel_coeffs(x, y);
        for (int c = 0; c < 3; ++c) {
          double grey[kPtmTerms];
          double f = 0.0;
          const auto b = ptm_basis(l.x(), l.y());
          for (int k = 0; k < kPtmTerms; ++k) {
            grey[k] = 255.0 * a[c * kPtmTerms + k];
            f += grey[k] * b[k];
          }
          const double err = std::abs(rgb[c] - std::clamp(f, 0.0, 255.0));
          const double bound = integer_error_bound_grey(grey, t.shifts, l.x(), l.y());
          ASSERT_LE(err, bound + kDoubleSolveRoundoff)
              << "texel " << x << "," << y << " light " << l.transpose();
          worst_ratio = std::max(worst_ratio, err / bound);
        }
      }
  }
  EXPECT_GT(worst_ratio, kBoundTightnessRatio);
}

TEST(TextureInteger, ExtremesSaturateAndHorizonLightsClamp) {
  Ptm8Texture t;
  t.width = 2;
  t.height = 1;
  t.model = ColourModel::kRGB;
  t.shifts = {-8, -8, -8};                // the largest coefficient range: +-127 * 256 grey levels
  t.coeffs.assign(t.texels() * 18, 254);  // every coefficient at its top
  for (int k = 0; k < 18; ++k) t.coeffs[18 + k] = 0;  // second texel: every one at the bottom
  for (const Eigen::Vector3d& l :
       {Eigen::Vector3d(0, 0, 1), Eigen::Vector3d(1, 0, 1e-9), Eigen::Vector3d(-1, -1, 0.01)}) {
    const auto out = relight_integer_bytes(t, l);
    for (int c = 0; c < 3; ++c) {
      EXPECT_EQ(out[c], 255) << "overflow must saturate, light " << l.transpose();
      EXPECT_EQ(out[3 + c], 0) << "underflow must saturate, light " << l.transpose();
    }
  }
  // The accumulator itself does not wrap at the extreme range: 127 * 256 * (1 + 1 + 1 + ...)
  const std::uint8_t top[6] = {254, 254, 254, 254, 254, 254};
  const IntegerLight il = quantise_light(std::sqrt(0.5), std::sqrt(0.5), 1e-6);
  EXPECT_GT(integer_accumulator(top, {-8, -8, -8}, il), 0);
  // Horizon: lu = 1 is clamped to 127/128, B0 = round(127^2 / 128) = 126.
  const IntegerLight h = quantise_light(1.0, 0.0, 1e-9);
  EXPECT_EQ(h.lu_q, 127);
  EXPECT_EQ(h.basis[0], 126);
  EXPECT_EQ(quantise_light(-1.0, 0.0, 1e-9).lu_q, -127);
  // Below the horizon: black whatever the coefficients.
  const auto below = relight_integer_bytes(t, Eigen::Vector3d(0.3, 0.2, -0.5));
  for (auto v : below) EXPECT_EQ(v, 0);
  // A foreign byte 255 (+128) saturates to +127: same output as 254.
  Ptm8Texture u = t;
  u.coeffs.assign(u.texels() * 18, 127);
  u.shifts = {0, 0, 0};
  u.coeffs[5] = 255;
  Ptm8Texture v = u;
  v.coeffs[5] = 254;
  EXPECT_EQ(relight_integer_bytes(u, {0, 0, 1}), relight_integer_bytes(v, {0, 0, 1}));
  EXPECT_EQ(relight_integer_bytes(v, {0, 0, 1})[0], 127);
}

TEST(TextureInteger, RenderedReliefErrorAgainstFloatRelighting) {
  // The same .ptm file relit in float and by the integer model, lights 10..90 degrees.
  test::ScratchDir dir;
  const CoefficientMap fitted = relief_map(48);
  (void)write_ptm(dir / "relief.ptm", fitted);
  const CoefficientMap file_map = read_ptm(dir / "relief.ptm", fitted.colour_space);
  const auto lights = elevation_sweep(10.0, 90.0, 10.0);
  const IntegerErrorReport r = integer_vs_float(file_map, lights);
  const QuantisationComparison q = compare_quantisations(file_map, lights);
  std::printf(
      "relief 48x48, shifts (%d,%d,%d): integer model mean %.3f max %.3f grey, PSNR "
      "%.2f dB; exact evaluation of the same stored bytes mean %.3f max %.3f\n",
      q.shifts[0], q.shifts[1], q.shifts[2], r.mean_abs_grey, r.max_abs_grey, r.psnr_db,
      q.ptm8.mean_abs_grey, q.ptm8.max_abs_grey);
  // The arithmetic adds little to what the stored bytes already lose.
  EXPECT_LE(r.mean_abs_grey, q.ptm8.mean_abs_grey + kArithmeticMeanAddGrey);
  EXPECT_LE(r.max_abs_grey, q.ptm8.max_abs_grey + kArithmeticMaxAddGrey);
  const bool fine_steps = q.shifts[0] >= -1 && q.shifts[1] >= -1 && q.shifts[2] >= -1;
  if (fine_steps) {
    EXPECT_LE(r.mean_abs_grey, kIntegerTargetMeanGrey);
    EXPECT_LE(r.max_abs_grey, kIntegerTargetMaxGrey);
  } else {
    // A step of 4 grey levels: exact arithmetic on the stored bytes already misses the target
    // (the floor documented in docs/INTEGER-MODEL.md), and the model stays near that floor.
    EXPECT_GT(q.ptm8.mean_abs_grey, kCoarseStepFloorGrey);
    EXPECT_LE(r.mean_abs_grey, kCoarseStepMeanGrey);
    EXPECT_LE(r.max_abs_grey, kCoarseStepMaxGrey);
  }
}

TEST(TextureInteger, BothSchemesAreReportedOnTheSameTexture) {
  const CoefficientMap map = relief_map(32);
  const QuantisationComparison q = compare_quantisations(map);
  std::printf("%s\n", q.brief().c_str());
  EXPECT_GT(q.samples, 0u);
  // The .ptm per-coefficient scale is never coarser than a power-of-two shift of the same
  // range, so its error is the smaller one.
  EXPECT_LE(q.ptm.mean_abs_grey, q.ptm8.mean_abs_grey + kDoubleSolveRoundoff);
  EXPECT_LT(q.ptm8.mean_abs_grey, kPaperShiftsMeanGrey);
  EXPECT_GE(q.integer.mean_abs_grey + kDoubleSolveRoundoff, 0.0);
}

TEST(TextureInteger, RelightCliIntegerMatchesTheLibrary) {
  test::ScratchDir dir;
  const CoefficientMap map = random_map(12, 9, test::test_seed(), 0.2, 0.3, 0.8);
  (void)write_ptm(dir / "in.ptm", map);
  const auto r = test::run_ptmkit({"relight", (dir / "in.ptm").string(), "--light", "0.3,0.2,0.9",
                                   "--integer", "-o", (dir / "out.png").string()});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_NE(r.out.find("integer model"), std::string::npos) << r.out;
  const Image got = read_image(dir / "out.png");
  const Image expect =
      relight_integer(quantise_ptm8(read_ptm(dir / "in.ptm")), Eigen::Vector3d(0.3, 0.2, 0.9));
  ASSERT_EQ(got.size(), expect.size());
  for (std::size_t i = 0; i < got.size(); ++i)
    ASSERT_EQ(std::lround(255.0 * got.data()[i]), std::lround(255.0 * expect.data()[i])) << i;
  const auto bad = test::run_ptmkit({"relight", (dir / "in.ptm").string(), "--lights", "x.lp",
                                     "--out-dir", (dir / "o").string(), "--integer"});
  EXPECT_NE(bad.exit_code, 0);
}

}  // namespace
}  // namespace ptmkit::texture
