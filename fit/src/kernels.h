// The fit's inner loops: the 6 x N pseudo-inverse applied to a band's N x M samples, 8-bit
// samples to floats, the LRGB and YCC luminance passes (and the one-pass LRGB row on bytes),
// and the robust solvers' exact medians of a texel's samples.
#pragma once

#include <cstddef>
#include <cstdint>

namespace ptmkit::fit::internal {

// out (6 x m, column-major: texel-channel j's coefficients at out[6 j .. 6 j + 5]) =
// p (6 x n, column-major) * (scale * s) (n x m; row i starts at s + i * stride).
//
// Every output is the sum over i = 0..n-1, in that order, of fused multiply-adds in float, each
// sample first multiplied by `scale` in float (exact when it is 1), so the result is the same
// bits on every machine and thread count: AVX2 with FMA where the CPU has them (chosen at run
// time), else the same sequence with std::fma.
//
// The fit's 8-bit arithmetic: with p the pseudo-inverse divided by 255 and scale 255, samples
// v / 255 (bytes_to_unit) become v again (255 * (v / 255) rounds back to v for every byte), so
// apply_pinv_u8 on the bytes, which needs no division, gives the same bits.
void apply_pinv(const float* p, int n, const float* s, std::ptrdiff_t stride, std::ptrdiff_t m,
                float* out, float scale = 1.0f);

// apply_pinv on 8-bit samples s (row i starts at s + i * stride bytes), each taken as its value
// v (exact in float): the same bits as apply_pinv at scale 255 on v / 255 (bytes_to_unit).
void apply_pinv_u8(const float* p, int n, const std::uint8_t* s, std::ptrdiff_t stride,
                   std::ptrdiff_t m, float* out);

// The portable path alone (for tests: it must give the same bits as the dispatched one).
void apply_pinv_portable(const float* p, int n, const float* s, std::ptrdiff_t stride,
                         std::ptrdiff_t m, float* out, float scale = 1.0f);

// 8-bit samples to 0..1: out[k] = in[k] / 255.0f correctly rounded, the same floats the
// stack reader's table gives, so a fit from bytes and one from floats agree to the bit.
void bytes_to_unit(const std::uint8_t* in, std::size_t count, float* out);

// One image's row of w RGB texels for the luminance models, each sample first multiplied by
// `scale` (255 for the fit's 8-bit arithmetic, see apply_pinv): luma (Rec. 601 weights) into
// yi, and the per-texel sums s0 += l * l, s1 += l * r, s2 += l * g, s3 += l * b that give
// LRGB's colour. Fused multiply-adds in a fixed order: the same bits on every dispatch path.
void luma_lrgb_row(const float* s, int w, float scale, float* yi, float* s0, float* s1, float* s2,
                   float* s3);

// The YCC model's row (the seed paper's constant chromaticity): luma into yi, and the sums
// s0 += max(l, 0), s1 += max(l, 0) * Cb, s2 += max(l, 0) * Cr.
void luma_ycc_row(const float* s, int w, float* yi, float* s0, float* s1, float* s2);

// The whole LRGB fit of one row of w texels of 8-bit RGB, in one pass: image i's row starts at
// s + i * stride bytes. Per texel, coeffs[6 x .. 6 x + 5] = p (6 x n, as apply_pinv's) times
// its n lumas of the byte values, and s0..s3[x] the colour sums of luma_lrgb_row (from zero).
// The same bits as converting the bytes (bytes_to_unit), luma_lrgb_row at scale 255 image by
// image, then apply_pinv (scale 1) on the lumas; without writing and re-reading a luma row per
// image.
void lrgb_row_u8(const float* p, int n, const std::uint8_t* s, std::ptrdiff_t stride, int w,
                 float* coeffs, float* s0, float* s1, float* s2, float* s3);

// The instruction sets a kernel has a path for; every path gives the same bits.
enum class KernelPath { kPortable, kAvx2, kAvx512 };

// lrgb_row_u8 through one path (for tests and benchmarks); false, with nothing written, where
// this CPU (or this build) lacks it. kAvx512 needs AVX-512 F, BW and VBMI.
bool lrgb_row_u8_path(KernelPath path, const float* p, int n, const std::uint8_t* s,
                      std::ptrdiff_t stride, int w, float* coeffs, float* s0, float* s1, float* s2,
                      float* s3);

// lrgb_row_u8's portable path alone, for texels x0 .. w - 1 (for tests: the same bits).
void lrgb_row_u8_portable(const float* p, int n, const std::uint8_t* s, std::ptrdiff_t stride,
                          int x0, int w, float* coeffs, float* s0, float* s1, float* s2, float* s3);

// LRGB colour from the sums yy = sum w Y^2 and yc = sum w Y rgb: the least-squares colour
// k_c = yc / yy, scaled so its largest channel is 1 (colour[0..2]), the luminance polynomial
// (coeffs[0..5]) carrying the scale.
void finish_lrgb_colour(double yy, const double yc[3], float* colour, float* coeffs);

// finish_lrgb_colour for a row of w texels from lrgb_row_u8's sums: colour[3 x ..],
// coeffs[6 x ..]. The same bits (4 texels at a time in double with AVX2).
void finish_lrgb_row(const float* s0, const float* s1, const float* s2, const float* s3, int w,
                     float* colour, float* coeffs);

// The exact median of x[0..n) (the mean of the two middle values when n is even), for the
// robust solvers' scale. x must have room for n rounded up to a multiple of 8: the tail is
// overwritten with +inf, and x[0..n) may be reordered. Up to 64 values, by counting for each
// value how many are smaller (8 values at a time with AVX2): no data-dependent branches,
// about 3x as fast as std::nth_element at 30-60 samples; above that, and when x holds a NaN, by
// std::nth_element.
double median_padded(double* x, int n);

// The k-th smallest (0-based, 0 <= k < n) of x[0..n), by the same means, with the same room.
double select_padded(double* x, int n, int k);

// median_padded's portable path alone (for tests; no padding needed; NaN when x holds one).
double median_padded_portable(double* x, int n);

}  // namespace ptmkit::fit::internal
