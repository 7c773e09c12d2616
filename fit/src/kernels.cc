#include "kernels.h"

#include <algorithm>
#include <cmath>
#include <vector>

#include "ptmkit/core/colour.h"

#if defined(__x86_64__) || defined(__i386__)
#include <immintrin.h>
#define PTMKIT_PINV_X86 1
#endif

namespace ptmkit::fit::internal {

namespace {

constexpr int kTerms = 6;
constexpr std::ptrdiff_t kBlock = 16;   // columns per register block (two 8-float vectors)
constexpr std::ptrdiff_t kAhead = 512;  // software prefetch distance in bytes (8-bit samples)

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

// block_portable on 8-bit samples: the block converted to floats (v / 255), then the same sums.
void block_portable_u8(const float* p, int n, const std::uint8_t* s, std::ptrdiff_t stride,
                       std::ptrdiff_t j0, std::ptrdiff_t count, float* out) {
  thread_local std::vector<float> unit;
  unit.resize(static_cast<std::size_t>(n) * kBlock);
  for (int i = 0; i < n; ++i) {
    for (std::ptrdiff_t t = 0; t < count; ++t) {
      unit[static_cast<std::size_t>(i * kBlock + t)] =
          static_cast<float>(s[static_cast<std::ptrdiff_t>(i) * stride + j0 + t]) / 255.0f;
    }
  }
  // Columns j0.. of `out` from columns 0.. of `unit`.
  block_portable(p, n, unit.data(), kBlock, 0, count, out + j0 * kTerms);
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

// v / 255 for 8 integers 0..255, correctly rounded: q = v * (1/255) is off by an ulp for about
// half of them; one Newton step with the exact remainder v - 255 q (an FMA) repairs every one
// (UnitBytes.EveryByteIsTheCorrectlyRoundedQuotient checks all 256). A division instead was a
// tenth of an LRGB fit's CPU.
__attribute__((target("avx2,fma"))) inline __m256 unit8_fma(__m256i v_i32) {
  const __m256 v = _mm256_cvtepi32_ps(v_i32);
  const __m256 inv = _mm256_set1_ps(1.0f / 255.0f);
  const __m256 q = _mm256_mul_ps(v, inv);
  const __m256 e = _mm256_fnmadd_ps(q, _mm256_set1_ps(255.0f), v);
  return _mm256_fmadd_ps(e, inv, q);
}

// apply_avx2 on 8-bit samples, converted in registers as bytes_to_unit converts them: the
// same floats into the same fused multiply-adds, so the same bits as converting the band
// first, without writing and re-reading four bytes per sample.
__attribute__((target("avx2,fma"))) void apply_avx2_u8(const float* p, int n, const std::uint8_t* s,
                                                       std::ptrdiff_t stride, std::ptrdiff_t m,
                                                       float* out) {
  std::ptrdiff_t j = 0;
  for (; j + kBlock <= m; j += kBlock) {
    __m256 a0[kTerms], a1[kTerms];
    for (int k = 0; k < kTerms; ++k) a0[k] = a1[k] = _mm256_setzero_ps();
    // One stream per image is more than the hardware prefetcher follows: fetch each
    // image's line kAhead bytes on, once per 64 bytes.
    const bool fetch = (j % 64) == 0;
    for (int i = 0; i < n; ++i) {
      const std::uint8_t* row = s + static_cast<std::ptrdiff_t>(i) * stride + j;
      if (fetch) _mm_prefetch(reinterpret_cast<const char*>(row + kAhead), _MM_HINT_T0);
      const __m128i b = _mm_loadu_si128(reinterpret_cast<const __m128i*>(row));
      const __m256 x0 = unit8_fma(_mm256_cvtepu8_epi32(b));
      const __m256 x1 = unit8_fma(_mm256_cvtepu8_epi32(_mm_srli_si128(b, 8)));
      const float* pi = p + static_cast<std::ptrdiff_t>(i) * kTerms;
      for (int k = 0; k < kTerms; ++k) {
        const __m256 c = _mm256_broadcast_ss(pi + k);
        a0[k] = _mm256_fmadd_ps(c, x0, a0[k]);
        a1[k] = _mm256_fmadd_ps(c, x1, a1[k]);
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
  if (j < m) block_portable_u8(p, n, s, stride, j, m - j, out);
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

void apply_pinv_u8(const float* p, int n, const std::uint8_t* s, std::ptrdiff_t stride,
                   std::ptrdiff_t m, float* out) {
#ifdef PTMKIT_PINV_X86
  if (has_avx2_fma()) {
    apply_avx2_u8(p, n, s, stride, m, out);
    return;
  }
#endif
  for (std::ptrdiff_t j = 0; j < m; j += kBlock) {
    block_portable_u8(p, n, s, stride, j, std::min(kBlock, m - j), out);
  }
}

// ---- 8-bit samples and the LRGB luminance pass ----

namespace {

#ifdef PTMKIT_PINV_X86
__attribute__((target("avx2,fma"))) void bytes_to_unit_fma(const std::uint8_t* in,
                                                           std::size_t count, float* out) {
  std::size_t k = 0;
  for (; k + 8 <= count; k += 8) {
    const __m128i b = _mm_loadl_epi64(reinterpret_cast<const __m128i*>(in + k));
    _mm256_storeu_ps(out + k, unit8_fma(_mm256_cvtepu8_epi32(b)));
  }
  for (; k < count; ++k) out[k] = static_cast<float>(in[k]) / 255.0f;
}

// luma_lrgb_row on 8-bit RGB: the same operations in the same order on the same floats, so
// the same bits. The compiler leaves the interleaved form scalar, so by hand: 8 texels at a
// time, de-interleaved with byte shuffles. Returns the texels done; the caller finishes.
__attribute__((target("avx2,fma"))) int luma_lrgb_u8_avx2(const std::uint8_t* s, int w, float* yi,
                                                          float* s0, float* s1, float* s2,
                                                          float* s3) {
  const __m128i gather = _mm_setr_epi8(0, 3, 6, 9, 1, 4, 7, 10, 2, 5, 8, 11, -1, -1, -1, -1);
  const __m256 kr = _mm256_set1_ps(static_cast<float>(kLumaR));
  const __m256 kg = _mm256_set1_ps(static_cast<float>(kLumaG));
  const __m256 kb = _mm256_set1_ps(static_cast<float>(kLumaB));
  int x = 0;
  // Two 16-byte loads at 3x and 3x + 12 read up to byte 3x + 27 of the row.
  for (; 3 * x + 28 <= 3 * w; x += 8) {
    __m128i a = _mm_loadu_si128(reinterpret_cast<const __m128i*>(s + 3 * x));
    __m128i b = _mm_loadu_si128(reinterpret_cast<const __m128i*>(s + 3 * x + 12));
    a = _mm_shuffle_epi8(a, gather);              // R0-3 G0-3 B0-3 .
    b = _mm_shuffle_epi8(b, gather);              // R4-7 G4-7 B4-7 .
    const __m128i rg = _mm_unpacklo_epi32(a, b);  // R0-3 R4-7 G0-3 G4-7
    const __m128i bb = _mm_unpackhi_epi32(a, b);  // B0-3 B4-7 . .
    const __m256 r = unit8_fma(_mm256_cvtepu8_epi32(rg));
    const __m256 g = unit8_fma(_mm256_cvtepu8_epi32(_mm_srli_si128(rg, 8)));
    const __m256 bl = unit8_fma(_mm256_cvtepu8_epi32(bb));
    // Separate multiplies and adds (the build forbids contraction): luma_lrgb_row's bits.
    const __m256 l = _mm256_add_ps(_mm256_add_ps(_mm256_mul_ps(kr, r), _mm256_mul_ps(kg, g)),
                                   _mm256_mul_ps(kb, bl));
    _mm256_storeu_ps(yi + x, l);
    _mm256_storeu_ps(s0 + x, _mm256_add_ps(_mm256_loadu_ps(s0 + x), _mm256_mul_ps(l, l)));
    _mm256_storeu_ps(s1 + x, _mm256_add_ps(_mm256_loadu_ps(s1 + x), _mm256_mul_ps(l, r)));
    _mm256_storeu_ps(s2 + x, _mm256_add_ps(_mm256_loadu_ps(s2 + x), _mm256_mul_ps(l, g)));
    _mm256_storeu_ps(s3 + x, _mm256_add_ps(_mm256_loadu_ps(s3 + x), _mm256_mul_ps(l, bl)));
  }
  return x;
}
#endif

}  // namespace

void bytes_to_unit(const std::uint8_t* in, std::size_t count, float* out) {
#ifdef PTMKIT_PINV_X86
  if (has_avx2_fma()) {
    bytes_to_unit_fma(in, count, out);
    return;
  }
#endif
  for (std::size_t k = 0; k < count; ++k) out[k] = static_cast<float>(in[k]) / 255.0f;
}

// Compiled for AVX2 and for the baseline, chosen at run time; element-wise float operations
// in a fixed order, so both give the same bits.
__attribute__((target_clones("avx2", "default"))) void luma_lrgb_row(const float* s, int w,
                                                                     float* yi, float* s0,
                                                                     float* s1, float* s2,
                                                                     float* s3) {
  constexpr auto kR = static_cast<float>(kLumaR);
  constexpr auto kG = static_cast<float>(kLumaG);
  constexpr auto kB = static_cast<float>(kLumaB);
  for (int x = 0; x < w; ++x) {
    const float l = kR * s[3 * x] + kG * s[3 * x + 1] + kB * s[3 * x + 2];
    yi[x] = l;
    s0[x] += l * l;
    s1[x] += l * s[3 * x];
    s2[x] += l * s[3 * x + 1];
    s3[x] += l * s[3 * x + 2];
  }
}

void luma_lrgb_row_u8(const std::uint8_t* s, int w, float* yi, float* s0, float* s1, float* s2,
                      float* s3) {
  int done = 0;
#ifdef PTMKIT_PINV_X86
  if (has_avx2_fma()) done = luma_lrgb_u8_avx2(s, w, yi, s0, s1, s2, s3);
#endif
  float rgb[3 * 8];
  for (int x = done; x < w; x += 8) {  // the rest (or all) through the float row code
    const int m = std::min(8, w - x);
    bytes_to_unit(s + 3 * x, static_cast<std::size_t>(3 * m), rgb);
    luma_lrgb_row(rgb, m, yi + x, s0 + x, s1 + x, s2 + x, s3 + x);
  }
}

}  // namespace ptmkit::fit::internal
