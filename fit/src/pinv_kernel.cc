#include "pinv_kernel.h"

#include <algorithm>
#include <cmath>

#if defined(__x86_64__) || defined(__i386__)
#include <immintrin.h>
#define PTMKIT_PINV_X86 1
#endif

namespace ptmkit::fit::internal {

namespace {

constexpr int kTerms = 6;
constexpr std::ptrdiff_t kBlock = 16;  // columns per register block (two 8-float vectors)

// Columns [j0, j0 + count) with count <= kBlock, portable.
void block_portable(const float* p, int n, const float* s, std::ptrdiff_t stride, std::ptrdiff_t j0,
                    std::ptrdiff_t count, float* out) {
  float acc[kTerms][kBlock] = {};
  for (int i = 0; i < n; ++i) {
    const float* row = s + static_cast<std::ptrdiff_t>(i) * stride + j0;
    const float* pi = p + static_cast<std::ptrdiff_t>(i) * kTerms;
    for (int k = 0; k < kTerms; ++k) {
      for (std::ptrdiff_t t = 0; t < count; ++t) acc[k][t] = std::fma(pi[k], row[t], acc[k][t]);
    }
  }
  for (std::ptrdiff_t t = 0; t < count; ++t) {
    for (int k = 0; k < kTerms; ++k) out[(j0 + t) * kTerms + k] = acc[k][t];
  }
}

#ifdef PTMKIT_PINV_X86
__attribute__((target("avx2,fma"))) void apply_avx2(const float* p, int n, const float* s,
                                                    std::ptrdiff_t stride, std::ptrdiff_t m,
                                                    float* out) {
  std::ptrdiff_t j = 0;
  for (; j + kBlock <= m; j += kBlock) {
    __m256 a0[kTerms], a1[kTerms];
    for (int k = 0; k < kTerms; ++k) a0[k] = a1[k] = _mm256_setzero_ps();
    for (int i = 0; i < n; ++i) {
      const float* row = s + static_cast<std::ptrdiff_t>(i) * stride + j;
      const __m256 x0 = _mm256_loadu_ps(row);
      const __m256 x1 = _mm256_loadu_ps(row + 8);
      const float* pi = p + static_cast<std::ptrdiff_t>(i) * kTerms;
      for (int k = 0; k < kTerms; ++k) {
        const __m256 b = _mm256_broadcast_ss(pi + k);
        a0[k] = _mm256_fmadd_ps(b, x0, a0[k]);
        a1[k] = _mm256_fmadd_ps(b, x1, a1[k]);
      }
    }
    alignas(32) float tmp[kTerms][kBlock];
    for (int k = 0; k < kTerms; ++k) {
      _mm256_store_ps(tmp[k], a0[k]);
      _mm256_store_ps(tmp[k] + 8, a1[k]);
    }
    for (std::ptrdiff_t t = 0; t < kBlock; ++t) {
      for (int k = 0; k < kTerms; ++k) out[(j + t) * kTerms + k] = tmp[k][t];
    }
  }
  if (j < m) block_portable(p, n, s, stride, j, m - j, out);
}

bool has_avx2_fma() {
  static const bool yes = __builtin_cpu_supports("avx2") && __builtin_cpu_supports("fma");
  return yes;
}
#endif

}  // namespace

void apply_pinv_portable(const float* p, int n, const float* s, std::ptrdiff_t stride,
                         std::ptrdiff_t m, float* out) {
  for (std::ptrdiff_t j = 0; j < m; j += kBlock) {
    block_portable(p, n, s, stride, j, std::min(kBlock, m - j), out);
  }
}

void apply_pinv(const float* p, int n, const float* s, std::ptrdiff_t stride, std::ptrdiff_t m,
                float* out) {
#ifdef PTMKIT_PINV_X86
  if (has_avx2_fma()) {
    apply_avx2(p, n, s, stride, m, out);
    return;
  }
#endif
  apply_pinv_portable(p, n, s, stride, m, out);
}

}  // namespace ptmkit::fit::internal
