// Summed-area tables over coefficient bytes: exact against brute-force box sums, including the
// largest images (64-bit sums; 32 bits would overflow).
#include <gtest/gtest.h>

#include <cstdint>
#include <random>

#include "ptmkit/texture/filtering.h"
#include "test_util.h"
#include "tolerances.h"

namespace ptmkit::texture {
namespace {

std::int64_t brute(const std::vector<std::uint8_t>& d, int w, int ch, int c, int x0, int y0, int x1,
                   int y1) {
  std::int64_t s = 0;
  for (int y = y0; y < y1; ++y)
    for (int x = x0; x < x1; ++x) s += d[(static_cast<std::size_t>(y) * w + x) * ch + c];
  return s;
}

TEST(TextureSat, RandomBoxesMatchBruteForce) {
  std::mt19937_64 rng(test::test_seed());
  const int w = 57, h = 43, ch = 9;
  std::vector<std::uint8_t> d(static_cast<std::size_t>(w) * h * ch);
  for (auto& b : d) b = static_cast<std::uint8_t>(rng() & 0xff);
  const SummedAreaTable sat(d.data(), w, h, ch);
  std::uniform_int_distribution<int> ux(0, w), uy(0, h), uc(0, ch - 1);
  for (int i = 0; i < 500; ++i) {
    int x0 = ux(rng), x1 = ux(rng), y0 = uy(rng), y1 = uy(rng);
    if (x1 < x0) std::swap(x0, x1);
    if (y1 < y0) std::swap(y0, y1);
    const int c = uc(rng);
    ASSERT_EQ(sat.sum(c, x0, y0, x1, y1), brute(d, w, ch, c, x0, y0, x1, y1));
  }
  // Anisotropic: a 1-texel-high strip and a 1-texel-wide column.
  EXPECT_EQ(sat.sum(3, 0, 7, w, 8), brute(d, w, ch, 3, 0, 7, w, 8));
  EXPECT_EQ(sat.sum(3, 11, 0, 12, h), brute(d, w, ch, 3, 11, 0, 12, h));
}

TEST(TextureSat, LargestImageSumsStayExact) {
  // 4096 x 4096 at the largest stored byte: the full sum is about 254 * 2^24 > 2^31, beyond
  // signed 32-bit sums (unsigned ones overflow from about 4104 x 4104 at 255).
  const int n = 4096;
  std::vector<std::uint8_t> d(static_cast<std::size_t>(n) * n, 254);
  std::mt19937_64 rng(test::test_seed());
  for (int i = 0; i < 1000; ++i) d[rng() % d.size()] = static_cast<std::uint8_t>(rng() & 0xff);
  const SummedAreaTable sat(d.data(), n, n, 1);
  const std::int64_t total = sat.sum(0, 0, 0, n, n);
  EXPECT_GT(total, std::int64_t{1} << 31);
  EXPECT_EQ(total, brute(d, n, 1, 0, 0, 0, n, n));
  // Small boxes next to the far corner, where float tables cancel catastrophically.
  for (int i = 0; i < 50; ++i) {
    const int x0 = n - 1 - static_cast<int>(rng() % 64), y0 = n - 1 - static_cast<int>(rng() % 64);
    EXPECT_EQ(sat.sum(0, x0, y0, x0 + 1, y0 + 1), d[static_cast<std::size_t>(y0) * n + x0]);
  }
  double mean = 0.0;
  sat.mean(n - 2, n - 2, n, n, &mean);
  EXPECT_DOUBLE_EQ(mean, static_cast<double>(brute(d, n, 1, 0, n - 2, n - 2, n, n)) / 4.0);
}

TEST(TextureSat, CoefficientsFromTheTableMatchTheAveragedBytes) {
  Ptm8Texture t;
  t.width = 8;
  t.height = 6;
  t.model = ColourModel::kLRGB;
  t.shifts = {3, 1, -1};
  std::mt19937_64 rng(test::test_seed());
  t.coeffs.resize(t.texels() * 6);
  for (auto& b : t.coeffs) b = static_cast<std::uint8_t>(rng() % 255);
  t.colour.resize(t.texels() * 3);
  for (auto& b : t.colour) b = static_cast<std::uint8_t>(rng() & 0xff);
  const SummedAreaTable sat(t);
  ASSERT_EQ(sat.channels(), 9);
  float out[9];
  sat_coefficients(sat, t, 2, 1, 5, 3, out);
  for (int k = 0; k < 9; ++k) {
    double s = 0;
    for (int y = 1; y < 3; ++y)
      for (int x = 2; x < 5; ++x) s += k < 6 ? t.texel(x, y)[k] : t.texel_colour(x, y)[k - 6];
    const double m = s / 6.0;
    const double expect = k < 6 ? (m - 127.0) * t.step_grey(ptm8_group(k)) / 255.0 : m / 255.0;
    EXPECT_NEAR(out[k], expect, test::kFloatRoundoff) << k;
  }
}

}  // namespace
}  // namespace ptmkit::texture
