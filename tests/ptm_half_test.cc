// The .ptm stream writer's conversions (texture/src/half.h): the dispatched paths (F16C / AVX2
// where the CPU has them) give the same bits as the portable ones, which are all that builds
// on other architectures.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdint>
#include <cstring>
#include <limits>
#include <random>
#include <vector>

#include "../texture/src/half.h"
#include "test_util.h"

namespace ptmkit {
namespace {

using namespace texture::internal;

TEST(PtmHalf, DispatchedAndPortableConversionsAgree) {
  // Every half value back to float, and that float to half again.
  std::vector<std::uint16_t> bits(65536);
  for (std::size_t h = 0; h < bits.size(); ++h) bits[h] = static_cast<std::uint16_t>(h);
  std::vector<float> a(bits.size()), b(bits.size());
  from_half(bits.data(), bits.size(), a.data());
  from_half_portable(bits.data(), bits.size(), b.data());
  // Bit for bit but for NaN payloads (F16C quiets a signalling NaN; the writer refuses NaN
  // before any conversion, so no NaN is ever converted).
  int nans = 0;
  for (std::size_t h = 0; h < bits.size(); ++h) {
    if (std::isnan(a[h])) {
      EXPECT_TRUE(std::isnan(b[h])) << h;
      ++nans;
      continue;
    }
    std::uint32_t ua = 0, ub = 0;
    std::memcpy(&ua, &a[h], sizeof ua);
    std::memcpy(&ub, &b[h], sizeof ub);
    ASSERT_EQ(ua, ub) << "half " << h;
  }
  EXPECT_EQ(nans, 2 * 1023);  // exponent all ones, mantissa non-zero, either sign
  // Floats between and beyond the halves (ties, subnormals, overflow), an odd count so the
  // vector paths' tails run too.
  std::mt19937_64 rng(test::test_seed());
  std::uniform_real_distribution<float> u(-70000.0f, 70000.0f);
  std::uniform_real_distribution<float> small(-1e-4f, 1e-4f);
  std::vector<float> f(100003);
  for (std::size_t k = 0; k < f.size(); ++k) f[k] = k % 2 ? u(rng) : small(rng);
  std::vector<std::uint16_t> x(f.size()), y(f.size());
  to_half(f.data(), f.size(), x.data());
  to_half_portable(f.data(), f.size(), y.data());
  EXPECT_EQ(x, y);
}

TEST(PtmHalf, HalfAndRangeIsToHalfAndRangePortable) {
  std::mt19937_64 rng(test::test_seed() + 1);
  std::uniform_real_distribution<float> u(-3.0f, 3.0f);
  for (std::size_t texels : {1u, 4u, 5u, 1001u}) {
    std::vector<float> c(texels * kPtmTerms);
    for (float& v : c) v = u(rng);
    std::vector<std::uint16_t> h1(c.size()), h2(c.size());
    Range r1{}, r2{};
    r1.lo.fill(std::numeric_limits<float>::infinity());
    r1.hi.fill(-std::numeric_limits<float>::infinity());
    r2 = r1;
    half_and_range(c.data(), c.size(), h1.data(), &r1);
    to_half_portable(c.data(), c.size(), h2.data());
    range_portable(c.data(), c.size(), &r2);
    EXPECT_EQ(h1, h2) << texels;
    EXPECT_EQ(r1.lo, r2.lo) << texels;
    EXPECT_EQ(r1.hi, r2.hi) << texels;
    EXPECT_TRUE(r1.finite && r2.finite);
    // A value beyond half range is caught by both.
    c[c.size() / 2] = 1e6f;
    Range r3 = r2, r4 = r2;
    half_and_range(c.data(), c.size(), h1.data(), &r3);
    range_portable(c.data(), c.size(), &r4);
    EXPECT_FALSE(r3.finite);
    EXPECT_FALSE(r4.finite);
  }
}

}  // namespace
}  // namespace ptmkit
