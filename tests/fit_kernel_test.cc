// The fit's kernels: the run-time-chosen paths (AVX2/FMA where the CPU has it) give the same
// bits as the portable ones; the product matches double precision; 8-bit samples become exactly
// v / 255, and 255 times that is v again, so the byte paths give the float paths' bits.
#include <algorithm>
#include <bit>
#include <cmath>
#include <cstdint>
#include <limits>
#include <random>
#include <vector>

#include <gtest/gtest.h>

#include "../fit/src/kernels.h"
#include "test_util.h"

namespace ptmkit::fit {
namespace {

// A float sum of n products of magnitude up to `scale` (random signs: the running sum stays
// near sqrt(n) x scale) against the same sum in double: each addition rounds by half an ulp of
// the running sum (6e-8 relative), far under this per term.
constexpr double kFloatSumPerTermTol = 1e-5;

TEST(PinvKernel, DispatchedAndPortablePathsGiveTheSameBitsAndMatchDouble) {
  std::mt19937_64 rng(test::test_seed());
  std::uniform_real_distribution<float> u(-1.0f, 1.0f);
  for (const int n : {6, 7, 49, 240}) {
    for (const std::ptrdiff_t m : {1, 15, 16, 17, 100, 12003}) {
      const std::ptrdiff_t stride = m + 5;  // rows padded, as a band's images are
      std::vector<float> p(static_cast<std::size_t>(6 * n)),
          s(static_cast<std::size_t>(n * stride));
      for (float& v : p) v = u(rng);
      for (float& v : s) v = 0.5f * (u(rng) + 1.0f);
      for (const float scale : {1.0f, 255.0f}) {
        std::vector<float> fast(static_cast<std::size_t>(6 * m)), portable(fast.size());
        internal::apply_pinv(p.data(), n, s.data(), stride, m, fast.data(), scale);
        internal::apply_pinv_portable(p.data(), n, s.data(), stride, m, portable.data(), scale);
        ASSERT_EQ(fast, portable) << "n " << n << " m " << m << " scale " << scale;
        double worst = 0.0;
        for (std::ptrdiff_t j = 0; j < m; ++j) {
          for (int k = 0; k < 6; ++k) {
            double ref = 0.0;
            for (int i = 0; i < n; ++i) {
              ref += static_cast<double>(p[static_cast<std::size_t>(i * 6 + k)]) * scale *
                     s[static_cast<std::size_t>(i * stride + j)];
            }
            worst = std::max(worst, std::abs(ref - fast[static_cast<std::size_t>(j * 6 + k)]));
          }
        }
        EXPECT_LT(worst, kFloatSumPerTermTol * n * scale)
            << "n " << n << " m " << m << " scale " << scale;
      }
    }
  }
}

TEST(UnitBytes, EveryByteIsTheCorrectlyRoundedQuotient) {
  // Every value, at every position of an 8-wide vector and in the scalar tail.
  std::vector<std::uint8_t> in(256 * 8 + 5);
  for (std::size_t k = 0; k < in.size(); ++k) in[k] = static_cast<std::uint8_t>((k * 9) % 256);
  std::vector<float> out(in.size());
  internal::bytes_to_unit(in.data(), in.size(), out.data());
  for (std::size_t k = 0; k < in.size(); ++k) {
    ASSERT_EQ(out[k], static_cast<float>(in[k]) / 255.0f) << "byte " << int{in[k]};
  }
}

// What lets the 8-bit paths skip the division: for every byte, 255 * (v / 255) in float (each
// step rounded) is v again.
TEST(UnitBytes, TimesTwoHundredFiftyFiveIsTheByteAgain) {
  for (int v = 0; v < 256; ++v) {
    const float unit = static_cast<float>(v) / 255.0f;
    const float back = 255.0f * unit;
    ASSERT_EQ(back, static_cast<float>(v)) << "byte " << v;
  }
}

TEST(PinvKernel, BytesGiveTheBitsOfConvertingFirst) {
  std::mt19937_64 rng(test::test_seed());
  std::uniform_real_distribution<float> u(-1.0f, 1.0f);
  std::uniform_int_distribution<int> byte(0, 255);
  for (const int n : {6, 49}) {
    for (const std::ptrdiff_t m : {1, 15, 16, 17, 12003}) {
      const std::ptrdiff_t stride = m + 3;
      std::vector<float> p(static_cast<std::size_t>(6 * n));
      for (float& v : p) v = u(rng);
      std::vector<std::uint8_t> b(static_cast<std::size_t>(n * stride));
      for (auto& v : b) v = static_cast<std::uint8_t>(byte(rng));
      std::vector<float> f(b.size());
      internal::bytes_to_unit(b.data(), b.size(), f.data());
      std::vector<float> direct(static_cast<std::size_t>(6 * m)), converted(direct.size());
      internal::apply_pinv_u8(p.data(), n, b.data(), stride, m, direct.data());
      internal::apply_pinv(p.data(), n, f.data(), stride, m, converted.data(), 255.0f);
      ASSERT_EQ(direct, converted) << "n " << n << " m " << m;
    }
  }
}

// The one-pass LRGB row on bytes against its definition: convert, luma image by image in
// 0..255 units, then the product on the lumas. Widths around the 8-texel block, the images
// strided as a band's.
TEST(LrgbRowKernel, BytesGiveTheBitsOfLumaThenProduct) {
  std::mt19937_64 rng(test::test_seed());
  std::uniform_real_distribution<float> u(-1.0f, 1.0f);
  std::uniform_int_distribution<int> byte(0, 255);
  for (const int n : {6, 49}) {
    for (const int w : {1, 7, 8, 9, 10, 15, 16, 17, 23, 24, 31, 33, 4000}) {
      const std::ptrdiff_t stride = 3 * w * 2;  // two rows per image, the first one fitted
      std::vector<float> p(static_cast<std::size_t>(6 * n));
      for (float& v : p) v = u(rng);
      // The last image ends with its first row: a read past a row's end shows under ASan.
      std::vector<std::uint8_t> b(static_cast<std::size_t>((n - 1) * stride + 3 * w));
      for (auto& v : b) v = static_cast<std::uint8_t>(byte(rng));
      const auto nw = static_cast<std::size_t>(w);
      // The definition.
      std::vector<float> f(3 * nw), y(static_cast<std::size_t>(n) * nw), sums(4 * nw, 0.0f);
      for (int i = 0; i < n; ++i) {
        internal::bytes_to_unit(b.data() + i * stride, f.size(), f.data());
        internal::luma_lrgb_row(f.data(), w, 255.0f, y.data() + i * nw, &sums[0], &sums[nw],
                                &sums[2 * nw], &sums[3 * nw]);
      }
      std::vector<float> coeffs(6 * nw);
      internal::apply_pinv(p.data(), n, y.data(), w, w, coeffs.data());
      // The dispatched one-pass kernel, and each path this CPU has.
      for (const int path : {-1, 0, 1, 2}) {
        std::vector<float> c(6 * nw, -1.0f), s(4 * nw, -1.0f);
        if (path < 0) {
          internal::lrgb_row_u8(p.data(), n, b.data(), stride, w, c.data(), &s[0], &s[nw],
                                &s[2 * nw], &s[3 * nw]);
        } else if (!internal::lrgb_row_u8_path(static_cast<internal::KernelPath>(path), p.data(), n,
                                               b.data(), stride, w, c.data(), &s[0], &s[nw],
                                               &s[2 * nw], &s[3 * nw])) {
          continue;
        }
        ASSERT_EQ(c, coeffs) << "n " << n << " width " << w << " path " << path;
        ASSERT_EQ(s, sums) << "n " << n << " width " << w << " path " << path;
      }
    }
  }
}

// The row version of the LRGB colour against the per-texel one, on sums that reach every
// branch: unlit texels (yy at or below 1e-20), negative and zero colour sums, black texels
// (largest channel at or below 1e-12), NaN.
TEST(LrgbColourKernel, RowGivesTheBitsOfEachTexel) {
  std::mt19937_64 rng(test::test_seed());
  std::uniform_real_distribution<float> u(-0.2f, 2.0f);
  const float nan = std::numeric_limits<float>::quiet_NaN();
  const float special_yy[] = {0.0f, -0.0f, 1e-21f, 1e-20f, 1.01e-20f, 1.2e-20f, -1.0f, nan};
  const float near_black[] = {0.0f, -0.0f, -1.0f, 0.9e-12f, 1e-12f, 1.1e-12f, nan};
  for (const int w : {1, 3, 4, 5, 8, 1001}) {
    const auto n = static_cast<std::size_t>(w);
    std::vector<float> sums(4 * n), coeffs(6 * n);
    for (float& v : sums) v = u(rng);
    for (std::size_t x = 0; x < n; ++x) {
      switch (rng() % 4) {
        case 0:  // unlit
          sums[x] = special_yy[rng() % std::size(special_yy)];
          break;
        case 1:  // every channel at or near the black threshold (yy = 1: k = the sum)
          sums[x] = 1.0f;
          for (int c = 1; c <= 3; ++c) sums[c * n + x] = near_black[rng() % std::size(near_black)];
          break;
        default:
          break;
      }
    }
    for (float& c : coeffs) c = u(rng);
    std::vector<float> row_colour(3 * n), row_coeffs = coeffs;
    internal::finish_lrgb_row(&sums[0], &sums[n], &sums[2 * n], &sums[3 * n], w, row_colour.data(),
                              row_coeffs.data());
    for (std::size_t x = 0; x < n; ++x) {
      const double yc[3] = {sums[n + x], sums[2 * n + x], sums[3 * n + x]};
      float colour[3];
      float c[6];
      std::copy_n(&coeffs[6 * x], 6, c);
      internal::finish_lrgb_colour(sums[x], yc, colour, c);
      for (int k = 0; k < 3; ++k) {
        ASSERT_EQ(std::bit_cast<std::uint32_t>(row_colour[3 * x + k]),
                  std::bit_cast<std::uint32_t>(colour[k]))
            << "texel " << x << " of " << w;
      }
      for (int k = 0; k < 6; ++k) {
        ASSERT_EQ(std::bit_cast<std::uint32_t>(row_coeffs[6 * x + k]),
                  std::bit_cast<std::uint32_t>(c[k]))
            << "texel " << x << " of " << w;
      }
    }
  }
}

// The median by counting must be the exact median: both middle values for an even count,
// ties (many equal residuals, as clipped samples give), every size up to and past the
// counting limit of 64.
TEST(MedianKernel, CountingGivesTheExactMedianAndRank) {
  std::mt19937_64 rng(test::test_seed());
  std::normal_distribution<double> noise(0.0, 0.01);
  const auto reference = [](std::vector<double> v) {
    const auto mid = v.begin() + static_cast<std::ptrdiff_t>(v.size() / 2);
    std::nth_element(v.begin(), mid, v.end());
    if (v.size() % 2 == 1) return *mid;
    return 0.5 * (*std::max_element(v.begin(), mid) + *mid);
  };
  for (int n = 1; n <= 80; ++n) {
    for (int trial = 0; trial < 40; ++trial) {
      std::vector<double> v(static_cast<std::size_t>(n));
      for (double& x : v) x = noise(rng);
      if (trial % 4 == 1) {  // a block of ties at the middle
        for (int i = 0; i < n / 2 + 1; ++i) v[static_cast<std::size_t>(i)] = 0.0;
      }
      if (trial % 4 == 2) {  // a few distinct values only
        for (double& x : v) x = std::round(x * 100.0);
      }
      const double want = reference(v);
      std::vector<double> room(v);
      room.resize(static_cast<std::size_t>((n + 7) & ~7));
      ASSERT_EQ(internal::median_padded(room.data(), n), want) << "n " << n << " trial " << trial;
      std::vector<double> plain(v);
      ASSERT_EQ(internal::median_padded_portable(plain.data(), n), want) << "n " << n;
      const int k = static_cast<int>(rng() % static_cast<std::uint64_t>(n));  // any rank
      std::vector<double> sorted(v);
      std::sort(sorted.begin(), sorted.end());
      room.assign(v.begin(), v.end());
      room.resize(static_cast<std::size_t>((n + 7) & ~7));
      ASSERT_EQ(internal::select_padded(room.data(), n, k), sorted[static_cast<std::size_t>(k)])
          << "n " << n << " k " << k;
    }
  }
  std::vector<double> one_nan = {0.1, std::nan(""), 0.3, 0.2, 0, 0, 0, 0};
  EXPECT_NO_FATAL_FAILURE(internal::median_padded(one_nan.data(), 4));
}

}  // namespace
}  // namespace ptmkit::fit
