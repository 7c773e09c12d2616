#include "half.h"

#include <algorithm>
#include <cmath>
#include <limits>

#include <Eigen/Core>

#include "ptm_internal.h"

#if (defined(__x86_64__) || defined(__i386__)) && !defined(PTMKIT_NO_X86_SIMD)
#include <cpuid.h>
#include <immintrin.h>
#define PTMKIT_HALF_X86 1
#endif

namespace ptmkit::texture::internal {

void range_portable(const float* in, std::size_t n, Range* r) {
  for (std::size_t k = 0; k < n; k += kPtmTerms) {
    for (int i = 0; i < kPtmTerms; ++i) {
      const float v = in[k + static_cast<std::size_t>(i)];
      r->finite &= std::abs(v) < kHalfLimit;  // NaN, inf, or beyond half range
      r->lo[static_cast<std::size_t>(i)] = std::min(r->lo[static_cast<std::size_t>(i)], v);
      r->hi[static_cast<std::size_t>(i)] = std::max(r->hi[static_cast<std::size_t>(i)], v);
    }
  }
}

void to_half_portable(const float* in, std::size_t n, std::uint16_t* out) {
  for (std::size_t k = 0; k < n; ++k) {
    out[k] = Eigen::numext::bit_cast<std::uint16_t>(Eigen::half(in[k]));
  }
}

void from_half_portable(const std::uint16_t* in, std::size_t n, float* out) {
  for (std::size_t k = 0; k < n; ++k) {
    out[k] = static_cast<float>(Eigen::numext::bit_cast<Eigen::half>(in[k]));
  }
}

#ifdef PTMKIT_HALF_X86

namespace {

// Float <-> IEEE half, round to nearest even. F16C where the CPU has it (one instruction per 8
// values; Eigen's portable conversion is bit manipulation per value), else Eigen: the same
// bits either way, both being IEEE conversions.
__attribute__((target("avx,f16c"))) void to_half_f16c(const float* in, std::size_t n,
                                                      std::uint16_t* out) {
  std::size_t k = 0;
  for (; k + 8 <= n; k += 8) {
    _mm_storeu_si128(reinterpret_cast<__m128i*>(out + k),
                     _mm256_cvtps_ph(_mm256_loadu_ps(in + k), _MM_FROUND_TO_NEAREST_INT));
  }
  for (; k < n; ++k) out[k] = Eigen::numext::bit_cast<std::uint16_t>(Eigen::half(in[k]));
}

__attribute__((target("avx,f16c"))) void from_half_f16c(const std::uint16_t* in, std::size_t n,
                                                        float* out) {
  std::size_t k = 0;
  for (; k + 8 <= n; k += 8) {
    _mm256_storeu_ps(out + k,
                     _mm256_cvtph_ps(_mm_loadu_si128(reinterpret_cast<const __m128i*>(in + k))));
  }
  for (; k < n; ++k) out[k] = static_cast<float>(Eigen::numext::bit_cast<Eigen::half>(in[k]));
}

// internal::colour_byte for 4 values: the same double arithmetic (255 v exact, clamped,
// + 0.5, truncated), so the same bytes. max(b, 0) is 0 for NaN, as b >= 0 ? b : 0 is.
__attribute__((target("avx2"))) inline __m128i colour_ints(const float* p) {
  const __m256d full = _mm256_set1_pd(255.0);
  __m256d b = _mm256_mul_pd(full, _mm256_cvtps_pd(_mm_loadu_ps(p)));
  b = _mm256_min_pd(_mm256_max_pd(b, _mm256_setzero_pd()), full);
  return _mm256_cvttpd_epi32(_mm256_add_pd(b, _mm256_set1_pd(0.5)));
}

// 16 values at a time (the compiler had left the loop scalar); returns the values done.
__attribute__((target("avx2"))) std::size_t colour_bytes_avx2(const float* in, std::size_t n,
                                                              std::uint8_t* out) {
  std::size_t k = 0;
  for (; k + 16 <= n; k += 16) {
    const __m128i lo = _mm_packs_epi32(colour_ints(in + k), colour_ints(in + k + 4));
    const __m128i hi = _mm_packs_epi32(colour_ints(in + k + 8), colour_ints(in + k + 12));
    _mm_storeu_si128(reinterpret_cast<__m128i*>(out + k), _mm_packus_epi16(lo, hi));
  }
  return k;
}

// to_half and the range in one pass over a band's coefficients (they were two, each reading
// the whole band): 24 values (4 texels' terms) a step, in three vectors whose lanes hold
// terms 0-5 0-1, 2-5 0-3 and 4-5 0-5.
__attribute__((target("avx,f16c"))) void half_and_range_f16c(const float* in, std::size_t n,
                                                             std::uint16_t* out, Range* r) {
  constexpr std::size_t kStep = 24;
  __m256 lo[3], hi[3];
  for (int j = 0; j < 3; ++j) {
    lo[j] = _mm256_set1_ps(std::numeric_limits<float>::infinity());
    hi[j] = _mm256_set1_ps(-std::numeric_limits<float>::infinity());
  }
  const __m256 limit = _mm256_set1_ps(kHalfLimit);
  const __m256 abs_mask = _mm256_castsi256_ps(_mm256_set1_epi32(0x7fffffff));
  __m256 ok = _mm256_castsi256_ps(_mm256_set1_epi32(-1));
  std::size_t k = 0;
  for (; k + kStep <= n; k += kStep) {
    for (int j = 0; j < 3; ++j) {
      const __m256 v = _mm256_loadu_ps(in + k + 8 * j);
      _mm_storeu_si128(reinterpret_cast<__m128i*>(out + k + 8 * j),
                       _mm256_cvtps_ph(v, _MM_FROUND_TO_NEAREST_INT));
      ok = _mm256_and_ps(ok, _mm256_cmp_ps(_mm256_and_ps(v, abs_mask), limit, _CMP_LT_OQ));
      lo[j] = _mm256_min_ps(v, lo[j]);  // a NaN leaves lo (and is caught by ok)
      hi[j] = _mm256_max_ps(v, hi[j]);
    }
  }
  alignas(32) float l[3][8], h[3][8];
  for (int j = 0; j < 3; ++j) {
    _mm256_store_ps(l[j], lo[j]);
    _mm256_store_ps(h[j], hi[j]);
  }
  for (int j = 0; j < 3; ++j) {
    for (int t = 0; t < 8; ++t) {
      const auto i = static_cast<std::size_t>((8 * j + t) % kPtmTerms);
      r->lo[i] = std::min(r->lo[i], l[j][t]);
      r->hi[i] = std::max(r->hi[i], h[j][t]);
    }
  }
  r->finite &= _mm256_movemask_ps(ok) == 0xff;
  to_half(in + k, n - k, out + k);
  range_portable(in + k, n - k, r);
}

// F16C from CPUID leaf 1 (clang's __builtin_cpu_supports does not know "f16c").
bool have_f16c() {
  unsigned a = 0, b = 0, c = 0, d = 0;
  return __builtin_cpu_supports("avx") && __get_cpuid(1, &a, &b, &c, &d) != 0 &&
         (c & bit_F16C) != 0;
}
const bool kHaveF16C = have_f16c();
const bool kHaveAvx2 = __builtin_cpu_supports("avx2");

}  // namespace

void to_half(const float* in, std::size_t n, std::uint16_t* out) {
  if (kHaveF16C) return to_half_f16c(in, n, out);
  to_half_portable(in, n, out);
}

void from_half(const std::uint16_t* in, std::size_t n, float* out) {
  if (kHaveF16C) return from_half_f16c(in, n, out);
  from_half_portable(in, n, out);
}

void colour_bytes(const float* in, std::size_t n, std::uint8_t* out) {
  const std::size_t done = kHaveAvx2 ? colour_bytes_avx2(in, n, out) : 0;
  for (std::size_t k = done; k < n; ++k) out[k] = colour_byte(in[k]);
}

void half_and_range(const float* in, std::size_t n, std::uint16_t* out, Range* r) {
  if (kHaveF16C) return half_and_range_f16c(in, n, out, r);
  to_half_portable(in, n, out);
  range_portable(in, n, r);
}

#else  // portable only

void to_half(const float* in, std::size_t n, std::uint16_t* out) { to_half_portable(in, n, out); }

void from_half(const std::uint16_t* in, std::size_t n, float* out) {
  from_half_portable(in, n, out);
}

void colour_bytes(const float* in, std::size_t n, std::uint8_t* out) {
  for (std::size_t k = 0; k < n; ++k) out[k] = colour_byte(in[k]);
}

void half_and_range(const float* in, std::size_t n, std::uint16_t* out, Range* r) {
  to_half_portable(in, n, out);
  range_portable(in, n, r);
}

#endif

}  // namespace ptmkit::texture::internal
