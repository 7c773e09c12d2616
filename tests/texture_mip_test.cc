// Mip-mapped coefficients: relighting a level equals box-downsampling the relit image (the
// evaluation is linear), storage is 4/3, and per-level re-quantisation error is measured.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <random>

#include "ptmkit/core/light_layout.h"
#include "ptmkit/texture/filtering.h"
#include "ptmkit/texture/integer_model.h"
#include "ptmkit/texture/relight.h"
#include "test_util.h"
#include "tolerances.h"

namespace ptmkit::texture {
namespace {

using test::kFloatRoundoff;

// Above 4/3: the series stops at 1 x 1 in whole texels (64 x 32: 2731 texels, 4/3 + 1.6e-4).
constexpr double kStorageAboveFourThirds = 1e-3;
// Below 4/3: a pyramid missing any level of 32 texels or more (1.6% of 64 x 32) falls below.
constexpr double kStorageBelowFourThirds = 0.01;
// Relit levels against box-downsampled relit images: every value is an average of at most 4^k
// floats of magnitude ~1.
constexpr double kBoxAverageFloatTol = 2e-6;
// Re-quantised levels with coefficients up to ~0.8 (205 grey units): steps of at most 2 grey
// levels, for which the integer model's derived bound is ~3.4 (docs/INTEGER-MODEL.md section 3);
// measured at most 2.2 (docs/TEXTURE.md).
constexpr double kRequantisedWorstGrey = 4.0;

CoefficientMap random_map(int w, int h, ColourModel model, std::uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  CoefficientMap map(w, h, model);
  for (std::size_t j = 0; j < map.coeffs.size(); ++j) {
    const bool constant = j % kPtmTerms == 5;
    map.coeffs[j] = static_cast<float>(constant ? 0.5 + 0.3 * u(rng) : 0.3 * u(rng));
  }
  for (auto& c : map.colour) c = static_cast<float>(0.2 * u(rng));
  return map;
}

TEST(TextureMip, StorageIsFourThirds) {
  const CoefficientPyramid p = build_pyramid(random_map(64, 32, ColourModel::kRGB, 1));
  ASSERT_EQ(p.levels.size(), 7u);  // 64x32 ... 1x1
  EXPECT_EQ(p.levels.back().width, 1);
  EXPECT_EQ(p.levels.back().height, 1);
  const double ratio = static_cast<double>(p.total_texels()) / (64.0 * 32.0);
  EXPECT_LT(ratio, 4.0 / 3.0 + kStorageAboveFourThirds);
  EXPECT_GT(ratio, 4.0 / 3.0 - kStorageBelowFourThirds);
  const CoefficientPyramid odd = build_pyramid(random_map(37, 21, ColourModel::kRGB, 2));
  EXPECT_EQ(odd.levels[1].width, 19);
  EXPECT_EQ(odd.levels[1].height, 11);
  // Ceil sizes add at most a row and a column per level: under 2 (w + h) over the series.
  EXPECT_LT(static_cast<double>(odd.total_texels()), 4.0 / 3.0 * 37 * 21 + 2.0 * (37 + 21));
}

TEST(TextureMip, RelitLevelEqualsDownsampledRelitImage) {
  for (ColourModel model : {ColourModel::kRGB, ColourModel::kYCC}) {
    const CoefficientMap map = random_map(32, 24, model, test::test_seed());
    const CoefficientPyramid p = build_pyramid(map);
    RelightOptions raw;
    raw.clamp = false;  // before clamping
    for (const auto& l : {Eigen::Vector3d(0, 0, 1), direction_from_angles_deg(20, 130)}) {
      Image down = relight(map, l, raw);
      for (std::size_t k = 1; k < p.levels.size(); ++k) {
        down = downsample_box(down);
        const Image lit = relight(p.levels[k], l, raw);
        ASSERT_EQ(lit.width(), down.width());
        double worst = 0.0;
        for (std::size_t i = 0; i < lit.size(); ++i)
          worst = std::max(worst, static_cast<double>(std::abs(lit.data()[i] - down.data()[i])));
        EXPECT_LT(worst, kBoxAverageFloatTol) << "level " << k << " model " << to_string(model);
      }
    }
  }
}

TEST(TextureMip, RequantisedLevelsStayWithinTheIntegerBound) {
  const CoefficientMap map = random_map(32, 32, ColourModel::kRGB, test::test_seed());
  const CoefficientPyramid p = build_pyramid(map);
  const std::vector<Ptm8Texture> q = quantise_pyramid(p);
  ASSERT_EQ(q.size(), p.levels.size());
  const Eigen::Vector3d l = direction_from_angles_deg(35, 60);
  Image down = relight(map, l);
  RelightOptions raw;
  raw.clamp = false;
  Image down_raw = relight(map, l, raw);
  for (std::size_t k = 1; k < p.levels.size(); ++k) {
    down_raw = downsample_box(down_raw);
    const auto bytes = relight_integer_bytes(q[k], l);
    double sum = 0.0, worst = 0.0;
    for (std::size_t i = 0; i < bytes.size(); ++i) {
      const double ref = 255.0 * std::clamp(down_raw.data()[i], 0.0f, 1.0f);
      const double d = std::abs(bytes[i] - ref);
      sum += d;
      worst = std::max(worst, d);
    }
    std::printf("level %zu (%dx%d) shifts (%d,%d,%d): quantisation adds mean %.3f max %.3f grey\n",
                k, q[k].width, q[k].height, q[k].shifts[0], q[k].shifts[1], q[k].shifts[2],
                sum / static_cast<double>(bytes.size()), worst);
    EXPECT_LE(worst, kRequantisedWorstGrey) << "level " << k;
  }
}

TEST(TextureMip, TrilinearLookupHitsTexelCentresAndBlendsLevels) {
  const CoefficientMap map = random_map(16, 16, ColourModel::kRGB, test::test_seed());
  const CoefficientPyramid p = build_pyramid(map);
  std::vector<float> v(static_cast<std::size_t>(p.values_per_texel()));
  sample_trilinear(p, 5.5, 9.5, 0.0, v.data());
  for (int k = 0; k < 18; ++k)
    EXPECT_FLOAT_EQ(v[static_cast<std::size_t>(k)], map.texel_coeffs(5, 9)[k]);
  // lod 1 at the centre of level-1 texel (2, 4) = level-0 coordinates (5, 9).
  sample_trilinear(p, 5.0, 9.0, 1.0, v.data());
  for (int k = 0; k < 18; ++k)
    EXPECT_NEAR(v[static_cast<std::size_t>(k)], p.levels[1].texel_coeffs(2, 4)[k], kFloatRoundoff);
  std::vector<float> a(v.size()), b(v.size());
  sample_trilinear(p, 5.0, 9.0, 1.0, a.data());
  sample_trilinear(p, 5.0, 9.0, 2.0, b.data());
  sample_trilinear(p, 5.0, 9.0, 1.25, v.data());
  for (std::size_t k = 0; k < v.size(); ++k)
    EXPECT_NEAR(v[k], 0.75 * a[k] + 0.25 * b[k], kFloatRoundoff);
}

}  // namespace
}  // namespace ptmkit::texture
