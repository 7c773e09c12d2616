// The .ptm stream writer's conversions: floats to IEEE half and back, colour floats to bytes,
// and a band's coefficient range. F16C / AVX2 where the CPU has them (chosen at run time, x86
// builds only), else portable code giving the same bits: both are IEEE conversions and the
// same double arithmetic. Builds on other architectures (or with PTMKIT_NO_X86_SIMD defined)
// have the portable code alone.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>

#include "ptmkit/core/coefficients.h"

namespace ptmkit::texture::internal {

void to_half(const float* in, std::size_t n, std::uint16_t* out);
void from_half(const std::uint16_t* in, std::size_t n, float* out);

// internal::colour_byte (ptm_internal.h) of n values.
void colour_bytes(const float* in, std::size_t n, std::uint8_t* out);

// Largest float that rounds to a finite half: 65504 plus just under half a step (16).
inline constexpr float kHalfLimit = 65520.0f;

// Per coefficient index (position mod 6 of a kRGB or kLRGB band), the smallest and largest
// value, and whether every value is finite and within half range. Every path gives the same
// answer: a minimum or maximum does not depend on the order it is taken in (but for the sign
// of a zero bound, which the writer makes +0).
struct Range {
  std::array<float, kPtmTerms> lo, hi;
  bool finite = true;
};

// Adds n values (whole texels of 6 terms) to the range.
void range_portable(const float* in, std::size_t n, Range* r);

// to_half and range_portable in one pass over a band's coefficients (n a multiple of 6).
void half_and_range(const float* in, std::size_t n, std::uint16_t* out, Range* r);

// The portable paths alone (for tests: the same bits as the dispatched ones).
void to_half_portable(const float* in, std::size_t n, std::uint16_t* out);
void from_half_portable(const std::uint16_t* in, std::size_t n, float* out);

}  // namespace ptmkit::texture::internal
