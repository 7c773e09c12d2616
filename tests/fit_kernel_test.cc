// The fit's pseudo-inverse product: the run-time-chosen path (AVX2/FMA where the CPU has it)
// gives the same bits as the portable one, and matches a double-precision product.
#include <random>
#include <vector>

#include <gtest/gtest.h>

#include "../fit/src/pinv_kernel.h"
#include "test_util.h"

namespace ptmkit::fit {
namespace {

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
      std::vector<float> fast(static_cast<std::size_t>(6 * m)), portable(fast.size());
      internal::apply_pinv(p.data(), n, s.data(), stride, m, fast.data());
      internal::apply_pinv_portable(p.data(), n, s.data(), stride, m, portable.data());
      ASSERT_EQ(fast, portable) << "n " << n << " m " << m;
      double worst = 0.0;
      for (std::ptrdiff_t j = 0; j < m; ++j) {
        for (int k = 0; k < 6; ++k) {
          double ref = 0.0;
          for (int i = 0; i < n; ++i) {
            ref += static_cast<double>(p[static_cast<std::size_t>(i * 6 + k)]) *
                   s[static_cast<std::size_t>(i * stride + j)];
          }
          worst = std::max(worst, std::abs(ref - fast[static_cast<std::size_t>(j * 6 + k)]));
        }
      }
      EXPECT_LT(worst, 1e-5 * n) << "n " << n << " m " << m;
    }
  }
}

}  // namespace
}  // namespace ptmkit::fit
