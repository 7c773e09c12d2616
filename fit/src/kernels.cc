#include "kernels.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <vector>

#include "ptmkit/core/colour.h"

#if (defined(__x86_64__) || defined(__i386__)) && !defined(PTMKIT_NO_X86_SIMD)
#include <immintrin.h>
#define PTMKIT_PINV_X86 1
// An AVX2 clone beside the portable code, chosen at load time.
#define PTMKIT_AVX2_CLONE __attribute__((target_clones("avx2", "default")))
#else
#define PTMKIT_AVX2_CLONE
#endif

namespace ptmkit::fit::internal {

namespace {

constexpr int kTerms = 6;
// Rec. 601 luma weights in float, for every luminance kernel below.
constexpr auto kLumaRf = static_cast<float>(kLumaR);
constexpr auto kLumaGf = static_cast<float>(kLumaG);
constexpr auto kLumaBf = static_cast<float>(kLumaB);
constexpr std::ptrdiff_t kBlock = 16;   // columns per register block (two 8-float vectors)
constexpr std::ptrdiff_t kAhead = 512;  // software prefetch distance in bytes (8-bit samples)
// The same for the one-pass LRGB row, which reads 24 bytes per image where the product reads
// 16: at 49 images, 512 bytes ahead is 25 KB of lines in flight, most of the L1 cache; 256 was
// faster (bench/kernel_benchmark), and none at all 1.6x slower.
constexpr std::ptrdiff_t kAheadLrgb = 256;

// Columns [j0, j0 + count) with count <= kBlock, portable; each sample times `scale` (rounded
// to float; exact when scale is 1) before its fused multiply-add.
void block_portable(const float* p, int n, const float* s, std::ptrdiff_t stride, std::ptrdiff_t j0,
                    std::ptrdiff_t count, float* out, float scale = 1.0f) {
  float acc[kTerms][kBlock] = {};
  for (int i = 0; i < n; ++i) {
    const float* row = s + static_cast<std::ptrdiff_t>(i) * stride + j0;
    const float* pi = p + static_cast<std::ptrdiff_t>(i) * kTerms;
    float v[kBlock];
    for (std::ptrdiff_t t = 0; t < count; ++t) v[t] = scale * row[t];
    for (int k = 0; k < kTerms; ++k) {
      for (std::ptrdiff_t t = 0; t < count; ++t) acc[k][t] = std::fma(pi[k], v[t], acc[k][t]);
    }
  }
  for (std::ptrdiff_t t = 0; t < count; ++t) {
    for (int k = 0; k < kTerms; ++k) out[(j0 + t) * kTerms + k] = acc[k][t];
  }
}

// block_portable on 8-bit samples: the block converted to floats (the values themselves,
// exact), then the same sums.
void block_portable_u8(const float* p, int n, const std::uint8_t* s, std::ptrdiff_t stride,
                       std::ptrdiff_t j0, std::ptrdiff_t count, float* out) {
  thread_local std::vector<float> unit;
  unit.resize(static_cast<std::size_t>(n) * kBlock);
  for (int i = 0; i < n; ++i) {
    for (std::ptrdiff_t t = 0; t < count; ++t) {
      unit[static_cast<std::size_t>(i * kBlock + t)] =
          static_cast<float>(s[static_cast<std::ptrdiff_t>(i) * stride + j0 + t]);
    }
  }
  // Columns j0.. of `out` from columns 0.. of `unit`.
  block_portable(p, n, unit.data(), kBlock, 0, count, out + j0 * kTerms);
}

#ifdef PTMKIT_PINV_X86
// One sample row's contribution to a 16-column block: acc[k] += pi[k] * x for the 6 terms.
__attribute__((target("avx2,fma"))) inline void accumulate(const float* pi, __m256 x0, __m256 x1,
                                                           __m256* a0, __m256* a1) {
  for (int k = 0; k < kTerms; ++k) {
    const __m256 c = _mm256_broadcast_ss(pi + k);
    a0[k] = _mm256_fmadd_ps(c, x0, a0[k]);
    a1[k] = _mm256_fmadd_ps(c, x1, a1[k]);
  }
}

// The block's sums, term-major in registers, stored texel-major: out[6 t + k].
__attribute__((target("avx2,fma"))) inline void store_block(const __m256* a0, const __m256* a1,
                                                            float* out) {
  alignas(32) float tmp[kTerms][kBlock];
  for (int k = 0; k < kTerms; ++k) {
    _mm256_store_ps(tmp[k], a0[k]);
    _mm256_store_ps(tmp[k] + 8, a1[k]);
  }
  for (std::ptrdiff_t t = 0; t < kBlock; ++t) {
    for (int k = 0; k < kTerms; ++k) out[t * kTerms + k] = tmp[k][t];
  }
}

__attribute__((target("avx2,fma"))) void apply_avx2(const float* p, int n, const float* s,
                                                    std::ptrdiff_t stride, std::ptrdiff_t m,
                                                    float* out, float scale) {
  const __m256 k = _mm256_set1_ps(scale);
  std::ptrdiff_t j = 0;
  for (; j + kBlock <= m; j += kBlock) {
    __m256 a0[kTerms], a1[kTerms];
    for (int t = 0; t < kTerms; ++t) a0[t] = a1[t] = _mm256_setzero_ps();
    for (int i = 0; i < n; ++i) {
      const float* row = s + static_cast<std::ptrdiff_t>(i) * stride + j;
      const __m256 x0 = _mm256_mul_ps(k, _mm256_loadu_ps(row));
      const __m256 x1 = _mm256_mul_ps(k, _mm256_loadu_ps(row + 8));
      accumulate(p + static_cast<std::ptrdiff_t>(i) * kTerms, x0, x1, a0, a1);
    }
    store_block(a0, a1, out + j * kTerms);
  }
  if (j < m) block_portable(p, n, s, stride, j, m - j, out, scale);
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

// apply_avx2 on 8-bit samples, each converted in registers to its value (exact): the same
// floats as 255 * (v / 255) into the same fused multiply-adds, so the same bits as apply_avx2
// at scale 255 on the band converted to 0..1 floats, without writing and re-reading four bytes
// per sample or dividing by 255.
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
      const __m256 x0 = _mm256_cvtepi32_ps(_mm256_cvtepu8_epi32(b));
      const __m256 x1 = _mm256_cvtepi32_ps(_mm256_cvtepu8_epi32(_mm_srli_si128(b, 8)));
      accumulate(p + static_cast<std::ptrdiff_t>(i) * kTerms, x0, x1, a0, a1);
    }
    store_block(a0, a1, out + j * kTerms);
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
                         std::ptrdiff_t m, float* out, float scale) {
  for (std::ptrdiff_t j = 0; j < m; j += kBlock) {
    block_portable(p, n, s, stride, j, std::min(kBlock, m - j), out, scale);
  }
}

void apply_pinv(const float* p, int n, const float* s, std::ptrdiff_t stride, std::ptrdiff_t m,
                float* out, float scale) {
#ifdef PTMKIT_PINV_X86
  if (has_avx2_fma()) {
    apply_avx2(p, n, s, stride, m, out, scale);
    return;
  }
#endif
  apply_pinv_portable(p, n, s, stride, m, out, scale);
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

// Eight texels of 8-bit RGB, interleaved, to three vectors of their values: 24 bytes from s,
// read as two 16-byte loads at s and s + 8 (no byte past s + 23 is touched, so the last
// texels of a buffer are safe), de-interleaved with byte shuffles.
__attribute__((target("avx2,fma"))) inline void rgb8_values(const std::uint8_t* s, __m256* r,
                                                            __m256* g, __m256* b) {
  const __m128i lo_mask = _mm_setr_epi8(0, 3, 6, 9, 1, 4, 7, 10, 2, 5, 8, 11, -1, -1, -1, -1);
  const __m128i hi_mask = _mm_setr_epi8(4, 7, 10, 13, 5, 8, 11, 14, 6, 9, 12, 15, -1, -1, -1, -1);
  const __m128i a = _mm_shuffle_epi8(_mm_loadu_si128(reinterpret_cast<const __m128i*>(s)),
                                     lo_mask);  // R0-3 G0-3 B0-3 .
  const __m128i c = _mm_shuffle_epi8(_mm_loadu_si128(reinterpret_cast<const __m128i*>(s + 8)),
                                     hi_mask);  // R4-7 G4-7 B4-7 .
  const __m128i rg = _mm_unpacklo_epi32(a, c);  // R0-3 R4-7 G0-3 G4-7
  const __m128i bb = _mm_unpackhi_epi32(a, c);  // B0-3 B4-7 . .
  *r = _mm256_cvtepi32_ps(_mm256_cvtepu8_epi32(rg));
  *g = _mm256_cvtepi32_ps(_mm256_cvtepu8_epi32(_mm_srli_si128(rg, 8)));
  *b = _mm256_cvtepi32_ps(_mm256_cvtepu8_epi32(bb));
}

// lrgb_row_u8, 8 texels at a time; returns the texels done (a multiple of 8), the caller
// finishes. Per block, image after image: the luma and the four colour sums (the fused
// multiply-adds of luma_lrgb_texel, in the same order), and the product's, all in registers: no
// luma row is written and read back.
__attribute__((target("avx2,fma"))) int lrgb_row_u8_avx2(const float* p, int n,
                                                         const std::uint8_t* s,
                                                         std::ptrdiff_t stride, int w,
                                                         float* coeffs, float* s0, float* s1,
                                                         float* s2, float* s3) {
  const __m256 kr = _mm256_set1_ps(kLumaRf);
  const __m256 kg = _mm256_set1_ps(kLumaGf);
  const __m256 kb = _mm256_set1_ps(kLumaBf);
  int x = 0;
  for (; x + 8 <= w; x += 8) {
    __m256 acc[kTerms];
    for (int k = 0; k < kTerms; ++k) acc[k] = _mm256_setzero_ps();
    __m256 yy = _mm256_setzero_ps(), yr = yy, yg = yy, yb = yy;
    const std::ptrdiff_t at = 3 * static_cast<std::ptrdiff_t>(x);
    // One stream per image is more than the hardware prefetcher follows: fetch each image's
    // line kAheadLrgb bytes on, once per 64 bytes (a block is 24).
    const bool fetch = (at & 63) < 24;
    for (int i = 0; i < n; ++i) {
      const std::uint8_t* row = s + static_cast<std::ptrdiff_t>(i) * stride + at;
      if (fetch) _mm_prefetch(reinterpret_cast<const char*>(row + kAheadLrgb), _MM_HINT_T0);
      __m256 r, g, b;
      rgb8_values(row, &r, &g, &b);
      const __m256 l = _mm256_fmadd_ps(kb, b, _mm256_fmadd_ps(kg, g, _mm256_mul_ps(kr, r)));
      yy = _mm256_fmadd_ps(l, l, yy);
      yr = _mm256_fmadd_ps(l, r, yr);
      yg = _mm256_fmadd_ps(l, g, yg);
      yb = _mm256_fmadd_ps(l, b, yb);
      const float* pi = p + static_cast<std::ptrdiff_t>(i) * kTerms;
      for (int k = 0; k < kTerms; ++k) {
        acc[k] = _mm256_fmadd_ps(_mm256_broadcast_ss(pi + k), l, acc[k]);
      }
    }
    _mm256_storeu_ps(s0 + x, yy);
    _mm256_storeu_ps(s1 + x, yr);
    _mm256_storeu_ps(s2 + x, yg);
    _mm256_storeu_ps(s3 + x, yb);
    alignas(32) float tmp[kTerms][8];
    for (int k = 0; k < kTerms; ++k) _mm256_store_ps(tmp[k], acc[k]);
    for (int t = 0; t < 8; ++t) {
      for (int k = 0; k < kTerms; ++k) coeffs[(x + t) * kTerms + k] = tmp[k][t];
    }
  }
  return x;
}

bool has_avx512_vbmi() {
  static const bool yes = __builtin_cpu_supports("avx512f") && __builtin_cpu_supports("avx512bw") &&
                          __builtin_cpu_supports("avx512vbmi") && has_avx2_fma();
  return yes;
}

// Sixteen integers to floats: the zero-masked form with every lane set, because GCC 12 warns
// on the plain one's undefined pass-through operand.
__attribute__((target("avx512f"))) inline __m512 to_floats(__m512i v) {
  return _mm512_maskz_cvtepi32_ps(0xFFFF, v);
}

// lrgb_row_u8_avx2's arithmetic, 16 texels at a time with AVX-512: the same fused
// multiply-adds in the same order on each lane, so the same bits. A block's 48 bytes of an
// image come in one masked load (nothing past them is touched) and each channel goes to 16
// integers in one byte permutation (VBMI) that zeroes the other bytes; AVX2 needed two loads,
// five byte shuffles and three widenings per 8 texels, which kept its FMAs waiting.
__attribute__((target("avx512f,avx512bw,avx512vbmi,fma"))) int lrgb_row_u8_avx512(
    const float* p, int n, const std::uint8_t* s, std::ptrdiff_t stride, int w, float* coeffs,
    float* s0, float* s1, float* s2, float* s3) {
  const __m512 kr = _mm512_set1_ps(kLumaRf);
  const __m512 kg = _mm512_set1_ps(kLumaGf);
  const __m512 kb = _mm512_set1_ps(kLumaBf);
  // Byte 4 t of lane t takes texel t's channel c (byte 3 t + c); the other three are zeroed.
  alignas(64) std::uint8_t idx[3][64] = {};
  for (int c = 0; c < 3; ++c) {
    for (int t = 0; t < 16; ++t) idx[c][4 * t] = static_cast<std::uint8_t>(3 * t + c);
  }
  const __m512i ir = _mm512_load_si512(idx[0]);
  const __m512i ig = _mm512_load_si512(idx[1]);
  const __m512i ib = _mm512_load_si512(idx[2]);
  constexpr __mmask64 kLowBytes = 0x1111111111111111ULL;
  constexpr __mmask64 kBlockBytes = (__mmask64{1} << 48) - 1;
  int x = 0;
  for (; x + 16 <= w; x += 16) {
    __m512 acc[kTerms];
    for (int k = 0; k < kTerms; ++k) acc[k] = _mm512_setzero_ps();
    __m512 yy = _mm512_setzero_ps(), yr = yy, yg = yy, yb = yy;
    const std::ptrdiff_t at = 3 * static_cast<std::ptrdiff_t>(x);
    for (int i = 0; i < n; ++i) {
      const std::uint8_t* row = s + static_cast<std::ptrdiff_t>(i) * stride + at;
      _mm_prefetch(reinterpret_cast<const char*>(row + kAheadLrgb), _MM_HINT_T0);
      const __m512i bytes = _mm512_maskz_loadu_epi8(kBlockBytes, row);
      const __m512 r = to_floats(_mm512_maskz_permutexvar_epi8(kLowBytes, ir, bytes));
      const __m512 g = to_floats(_mm512_maskz_permutexvar_epi8(kLowBytes, ig, bytes));
      const __m512 b = to_floats(_mm512_maskz_permutexvar_epi8(kLowBytes, ib, bytes));
      const __m512 l = _mm512_fmadd_ps(kb, b, _mm512_fmadd_ps(kg, g, _mm512_mul_ps(kr, r)));
      yy = _mm512_fmadd_ps(l, l, yy);
      yr = _mm512_fmadd_ps(l, r, yr);
      yg = _mm512_fmadd_ps(l, g, yg);
      yb = _mm512_fmadd_ps(l, b, yb);
      const float* pi = p + static_cast<std::ptrdiff_t>(i) * kTerms;
      for (int k = 0; k < kTerms; ++k) {
        acc[k] = _mm512_fmadd_ps(_mm512_set1_ps(pi[k]), l, acc[k]);
      }
    }
    _mm512_storeu_ps(s0 + x, yy);
    _mm512_storeu_ps(s1 + x, yr);
    _mm512_storeu_ps(s2 + x, yg);
    _mm512_storeu_ps(s3 + x, yb);
    alignas(64) float tmp[kTerms][16];
    for (int k = 0; k < kTerms; ++k) _mm512_store_ps(tmp[k], acc[k]);
    for (int t = 0; t < 16; ++t) {
      for (int k = 0; k < kTerms; ++k) coeffs[(x + t) * kTerms + k] = tmp[k][t];
    }
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

namespace {

// One texel of one image for the luminance models: its luma l of (r, g, b) and the colour sums
// yy += l l, yr += l r, yg += l g, yb += l b, by fused multiply-adds in a fixed order
// (std::fma is exact whether or not the caller is compiled with FMA instructions, so every
// path gives the same bits). The luma r kR + g kG + b kB as (r kR + g kG) + b kB, each
// addition fused: 2 of the 5 operations, and one per colour sum, saved over separate
// multiplies and adds. lrgb_row_u8_avx2 does the same, 8 texels at a time.
__attribute__((always_inline)) inline float luma_lrgb_texel(float r, float g, float b, float* yy,
                                                            float* yr, float* yg, float* yb) {
  const float l = std::fma(kLumaBf, b, std::fma(kLumaGf, g, kLumaRf * r));
  *yy = std::fma(l, l, *yy);
  *yr = std::fma(l, r, *yr);
  *yg = std::fma(l, g, *yg);
  *yb = std::fma(l, b, *yb);
  return l;
}

// luma_lrgb_row's loop, for a caller compiled with or without FMA instructions.
__attribute__((always_inline)) inline void luma_lrgb_loop(const float* s, int w, float scale,
                                                          float* yi, float* s0, float* s1,
                                                          float* s2, float* s3) {
  for (int x = 0; x < w; ++x) {
    yi[x] = luma_lrgb_texel(scale * s[3 * x], scale * s[3 * x + 1], scale * s[3 * x + 2], &s0[x],
                            &s1[x], &s2[x], &s3[x]);
  }
}

#ifdef PTMKIT_PINV_X86
__attribute__((target("avx2,fma"))) void luma_lrgb_row_fma(const float* s, int w, float scale,
                                                           float* yi, float* s0, float* s1,
                                                           float* s2, float* s3) {
  luma_lrgb_loop(s, w, scale, yi, s0, s1, s2, s3);
}
#endif

}  // namespace

void luma_lrgb_row(const float* s, int w, float scale, float* yi, float* s0, float* s1, float* s2,
                   float* s3) {
#ifdef PTMKIT_PINV_X86
  if (has_avx2_fma()) {
    luma_lrgb_row_fma(s, w, scale, yi, s0, s1, s2, s3);
    return;
  }
#endif
  luma_lrgb_loop(s, w, scale, yi, s0, s1, s2, s3);
}

// The seed paper's constant chromaticity: luma, and luminance-weighted sums of Cb and Cr.
PTMKIT_AVX2_CLONE void luma_ycc_row(const float* s, int w, float* yi, float* s0, float* s1,
                                    float* s2) {
  for (int x = 0; x < w; ++x) {
    const float l = kLumaRf * s[3 * x] + kLumaGf * s[3 * x + 1] + kLumaBf * s[3 * x + 2];
    yi[x] = l;
    const float wgt = std::max(0.0f, l);
    s0[x] += wgt;
    s1[x] += wgt * (s[3 * x + 2] - l) * static_cast<float>(1.0 / 1.772);
    s2[x] += wgt * (s[3 * x] - l) * static_cast<float>(1.0 / 1.402);
  }
}

void lrgb_row_u8_portable(const float* p, int n, const std::uint8_t* s, std::ptrdiff_t stride,
                          int x0, int w, float* coeffs, float* s0, float* s1, float* s2,
                          float* s3) {
  for (int x = x0; x < w; ++x) {
    float acc[kTerms] = {};
    float yy = 0.0f, yr = 0.0f, yg = 0.0f, yb = 0.0f;
    for (int i = 0; i < n; ++i) {
      const std::uint8_t* t = s + static_cast<std::ptrdiff_t>(i) * stride + 3 * x;
      const float l = luma_lrgb_texel(t[0], t[1], t[2], &yy, &yr, &yg, &yb);
      for (int k = 0; k < kTerms; ++k) acc[k] = std::fma(p[i * kTerms + k], l, acc[k]);
    }
    s0[x] = yy;
    s1[x] = yr;
    s2[x] = yg;
    s3[x] = yb;
    std::copy_n(acc, kTerms, coeffs + static_cast<std::ptrdiff_t>(x) * kTerms);
  }
}

bool lrgb_row_u8_path(KernelPath path, const float* p, int n, const std::uint8_t* s,
                      std::ptrdiff_t stride, int w, float* coeffs, float* s0, float* s1, float* s2,
                      float* s3) {
  int done = 0;
  switch (path) {
    case KernelPath::kPortable:
      break;
    case KernelPath::kAvx2:
#ifdef PTMKIT_PINV_X86
      if (!has_avx2_fma()) return false;
      done = lrgb_row_u8_avx2(p, n, s, stride, w, coeffs, s0, s1, s2, s3);
      break;
#else
      return false;
#endif
    case KernelPath::kAvx512:
#ifdef PTMKIT_PINV_X86
      if (!has_avx512_vbmi()) return false;
      done = lrgb_row_u8_avx512(p, n, s, stride, w, coeffs, s0, s1, s2, s3);
      // The last 8 to 15 texels: a block of 8.
      done += lrgb_row_u8_avx2(p, n, s + 3 * static_cast<std::ptrdiff_t>(done), stride, w - done,
                               coeffs + static_cast<std::ptrdiff_t>(done) * kTerms, s0 + done,
                               s1 + done, s2 + done, s3 + done);
      break;
#else
      return false;
#endif
  }
  lrgb_row_u8_portable(p, n, s, stride, done, w, coeffs, s0, s1, s2, s3);
  return true;
}

void lrgb_row_u8(const float* p, int n, const std::uint8_t* s, std::ptrdiff_t stride, int w,
                 float* coeffs, float* s0, float* s1, float* s2, float* s3) {
  KernelPath path = KernelPath::kPortable;
#ifdef PTMKIT_PINV_X86
  if (has_avx512_vbmi()) {
    path = KernelPath::kAvx512;
  } else if (has_avx2_fma()) {
    path = KernelPath::kAvx2;
  }
#endif
  lrgb_row_u8_path(path, p, n, s, stride, w, coeffs, s0, s1, s2, s3);
}

// ---- LRGB colour ----

void finish_lrgb_colour(double yy, const double yc[3], float* colour, float* coeffs) {
  const LrgbSums sums{yy, {yc[0], yc[1], yc[2]}};
  double k[3] = {sums.factor(0), sums.factor(1), sums.factor(2)};
  double m = std::max({k[0], k[1], k[2]});
  if (m <= 1e-12) {
    k[0] = k[1] = k[2] = 1.0;
    m = 1.0;
  }
  for (int c = 0; c < 3; ++c) colour[c] = static_cast<float>(k[c] / m);
  for (int t = 0; t < kTerms; ++t) coeffs[t] = static_cast<float>(coeffs[t] * m);
}

namespace {

#ifdef PTMKIT_PINV_X86
// Four texels at a time; returns the texels done. Six double divisions per texel were most of
// the scalar version's cost. The same IEEE operations as finish_lrgb_colour: max(v, 0) keeps
// +0 for -0 and 0 for NaN as std::max(0.0, v) does, and both selections are exact.
__attribute__((target("avx2,fma"))) int finish_lrgb_row_avx2(const float* s0, const float* s1,
                                                             const float* s2, const float* s3,
                                                             int w, float* colour, float* coeffs) {
  const __m256d zero = _mm256_setzero_pd();
  const __m256d one = _mm256_set1_pd(1.0);
  const __m256d tiny_yy = _mm256_set1_pd(1e-20);
  const __m256d tiny_m = _mm256_set1_pd(1e-12);
  const float* sums[3] = {s1, s2, s3};
  int x = 0;
  for (; x + 4 <= w; x += 4) {
    const __m256d yy = _mm256_cvtps_pd(_mm_loadu_ps(s0 + x));
    const __m256d lit = _mm256_cmp_pd(yy, tiny_yy, _CMP_GT_OQ);
    __m256d k[3];
    for (int c = 0; c < 3; ++c) {
      const __m256d yc = _mm256_cvtps_pd(_mm_loadu_ps(sums[c] + x));
      k[c] = _mm256_blendv_pd(one, _mm256_max_pd(_mm256_div_pd(yc, yy), zero), lit);
    }
    __m256d m = _mm256_max_pd(_mm256_max_pd(k[0], k[1]), k[2]);
    const __m256d dark = _mm256_cmp_pd(m, tiny_m, _CMP_LE_OQ);
    for (int c = 0; c < 3; ++c) k[c] = _mm256_blendv_pd(k[c], one, dark);
    m = _mm256_blendv_pd(m, one, dark);
    alignas(16) float col[3][4];
    for (int c = 0; c < 3; ++c) _mm_store_ps(col[c], _mm256_cvtpd_ps(_mm256_div_pd(k[c], m)));
    alignas(32) double scale[4];
    _mm256_store_pd(scale, m);
    for (int t = 0; t < 4; ++t) {
      float* out = colour + static_cast<std::ptrdiff_t>(x + t) * 3;
      for (int c = 0; c < 3; ++c) out[c] = col[c][t];
      float* coef = coeffs + static_cast<std::ptrdiff_t>(x + t) * kTerms;
      for (int i = 0; i < kTerms; ++i) coef[i] = static_cast<float>(coef[i] * scale[t]);
    }
  }
  return x;
}
#endif

}  // namespace

void finish_lrgb_row(const float* s0, const float* s1, const float* s2, const float* s3, int w,
                     float* colour, float* coeffs) {
  int x = 0;
#ifdef PTMKIT_PINV_X86
  if (has_avx2_fma()) x = finish_lrgb_row_avx2(s0, s1, s2, s3, w, colour, coeffs);
#endif
  for (; x < w; ++x) {
    const double yc[3] = {s1[x], s2[x], s3[x]};
    finish_lrgb_colour(s0[x], yc, colour + static_cast<std::ptrdiff_t>(x) * 3,
                       coeffs + static_cast<std::ptrdiff_t>(x) * kTerms);
  }
}

// ---- exact medians of small sets ----

namespace {

// The k-th smallest (0-based) of x[0..n) is the largest value with at most k values below
// it, and the (k - 1)-th comes from the same counts: *lo and *hi get the (k - 1)-th and k-th
// smallest. A NaN anywhere makes the counts meaningless: returns false.
bool rank_pair_portable(const double* x, int n, int k, double* lo, double* hi) {
  *lo = *hi = -std::numeric_limits<double>::infinity();
  for (int i = 0; i < n; ++i) {
    const double v = x[i];
    if (std::isnan(v)) return false;
    int less = 0;
    for (int j = 0; j < n; ++j) less += x[j] < v ? 1 : 0;
    if (less <= k) *hi = std::max(*hi, v);
    if (less <= k - 1) *lo = std::max(*lo, v);
  }
  return true;
}

#ifdef PTMKIT_PINV_X86
// v where its count of values below is at most limit, else -inf.
__attribute__((target("avx2"))) inline __m256d at_most(__m256d v, __m256i below, __m256i limit) {
  const __m256d none = _mm256_set1_pd(-std::numeric_limits<double>::infinity());
  return _mm256_blendv_pd(v, none, _mm256_castsi256_pd(_mm256_cmpgt_epi64(below, limit)));
}

// The same counts, for 8 candidates at a time (two independent chains): each x[j] is compared
// with 8 values at once, and the candidates with too many below are masked out. x is padded
// with +inf to a multiple of 8; a +inf candidate has every finite value below it.
__attribute__((target("avx2"))) bool rank_pair_avx2(const double* x, int n, int padded, int rank,
                                                    double* lo, double* hi) {
  const __m256d none = _mm256_set1_pd(-std::numeric_limits<double>::infinity());
  const __m256i k = _mm256_set1_epi64x(rank);
  const __m256i k1 = _mm256_set1_epi64x(rank - 1);
  __m256d hv = none, lv = none, nan = _mm256_setzero_pd();
  for (int i = 0; i < padded; i += 8) {
    const __m256d v0 = _mm256_loadu_pd(x + i);
    const __m256d v1 = _mm256_loadu_pd(x + i + 4);
    nan = _mm256_or_pd(nan, _mm256_cmp_pd(v0, v1, _CMP_UNORD_Q));
    __m256i c0 = _mm256_setzero_si256(), c1 = _mm256_setzero_si256();  // counts below
    for (int j = 0; j < n; ++j) {
      const __m256d b = _mm256_broadcast_sd(x + j);
      c0 = _mm256_sub_epi64(c0, _mm256_castpd_si256(_mm256_cmp_pd(b, v0, _CMP_LT_OQ)));
      c1 = _mm256_sub_epi64(c1, _mm256_castpd_si256(_mm256_cmp_pd(b, v1, _CMP_LT_OQ)));
    }
    hv = _mm256_max_pd(hv, _mm256_max_pd(at_most(v0, c0, k), at_most(v1, c1, k)));
    lv = _mm256_max_pd(lv, _mm256_max_pd(at_most(v0, c0, k1), at_most(v1, c1, k1)));
  }
  if (_mm256_movemask_pd(nan) != 0) return false;
  alignas(32) double h[4], l[4];
  _mm256_store_pd(h, hv);
  _mm256_store_pd(l, lv);
  *hi = std::max(std::max(h[0], h[1]), std::max(h[2], h[3]));
  *lo = std::max(std::max(l[0], l[1]), std::max(l[2], l[3]));
  return true;
}
#endif

// The (k - 1)-th and k-th smallest of x[0..n), x padded as median_padded says.
void rank_pair(double* x, int n, int k, double* lo, double* hi) {
  const int padded = (n + 7) & ~7;
  for (int i = n; i < padded; ++i) x[i] = std::numeric_limits<double>::infinity();
  // Counting is quadratic: past 64 values selection wins.
  bool ok = false;
  if (n <= 64) {
#ifdef PTMKIT_PINV_X86
    ok = has_avx2_fma() ? rank_pair_avx2(x, n, padded, k, lo, hi)
                        : rank_pair_portable(x, n, k, lo, hi);
#else
    ok = rank_pair_portable(x, n, k, lo, hi);
#endif
  }
  if (!ok) {  // many values, or a NaN (then whatever nth_element makes of it)
    double* at = x + k;
    std::nth_element(x, at, x + n);
    *hi = *at;
    *lo = k > 0 ? *std::max_element(x, at) : -std::numeric_limits<double>::infinity();
  }
}

}  // namespace

double median_padded(double* x, int n) {
  if (n <= 0) return 0.0;
  double lo = 0.0, hi = 0.0;
  rank_pair(x, n, n / 2, &lo, &hi);
  return n % 2 == 1 ? hi : 0.5 * (lo + hi);
}

double select_padded(double* x, int n, int k) {
  double lo = 0.0, hi = 0.0;
  rank_pair(x, n, k, &lo, &hi);
  return hi;
}

// The portable path alone, for the tests.
double median_padded_portable(double* x, int n) {
  if (n <= 0) return 0.0;
  double lo = 0.0, hi = 0.0;
  if (!rank_pair_portable(x, n, n / 2, &lo, &hi)) return std::numeric_limits<double>::quiet_NaN();
  return n % 2 == 1 ? hi : 0.5 * (lo + hi);
}

}  // namespace ptmkit::fit::internal
