// The fit's inner product: the 6 x N pseudo-inverse applied to a band's N x M samples.
#pragma once

#include <cstddef>

namespace ptmkit::fit::internal {

// out (6 x m, column-major: texel-channel j's coefficients at out[6 j .. 6 j + 5]) =
// p (6 x n, column-major) * s (n x m; row i starts at s + i * stride).
//
// Every output is the sum over i = 0..n-1, in that order, of fused multiply-adds in float, so
// the result is the same bits on every machine and thread count: AVX2 with FMA where the CPU
// has them (chosen at run time), else the same sequence with std::fma.
void apply_pinv(const float* p, int n, const float* s, std::ptrdiff_t stride, std::ptrdiff_t m,
                float* out);

// The portable path alone (for tests: it must give the same bits as the dispatched one).
void apply_pinv_portable(const float* p, int n, const float* s, std::ptrdiff_t stride,
                         std::ptrdiff_t m, float* out);

}  // namespace ptmkit::fit::internal
