// The bit-exact integer evaluator of the paper's 8-bit polynomials (docs/INTEGER-MODEL.md
// states every operation and width). Two implementations: a scalar reference that follows the
// document step by step, and a fast path (per-light product tables, rows in parallel) that
// agrees with it bit for bit.
#pragma once

#include <array>
#include <cstdint>
#include <vector>

#include <Eigen/Core>

#include "ptmkit/core/image.h"
#include "ptmkit/texture/ptm8.h"

namespace ptmkit::texture {

// A light in the model's fixed point.
struct IntegerLight {
  bool above = false;                  // lz > 0; otherwise every output is 0
  int lu_q = 0, lv_q = 0;              // 8-bit signed, value / 128
  std::array<int, kPtmTerms> basis{};  // B0..B5 (B5 = 128), value / 128
};
// (lu, lv, lz) = a unit direction toward the light in the texture frame.
[[nodiscard]] IntegerLight quantise_light(double lu, double lv, double lz);

// Fraction bits of the accumulator.
inline constexpr int kAccumulatorFraction = 8;

// Scalar reference, one polynomial: the accumulator A (grey levels * 2^8, before rounding and
// clamping), and the clamped 8-bit output.
[[nodiscard]] std::int32_t integer_accumulator(const std::uint8_t bytes[kPtmTerms],
                                               const std::array<int, 3>& shifts,
                                               const IntegerLight& light);
[[nodiscard]] std::uint8_t integer_output(std::int32_t accumulator);
// Scalar reference, one texel: 8-bit RGB.
void integer_texel_reference(const Ptm8Texture& texture, int x, int y, const IntegerLight& light,
                             std::uint8_t rgb[3]);
// The same for bytes given directly (a filtered lookup): `coeffs` has polynomials*6 bytes,
// `colour` 3 bytes for kLRGB (ignored otherwise).
void integer_evaluate(const std::uint8_t* coeffs, const std::uint8_t* colour, ColourModel model,
                      const std::array<int, 3>& shifts, const IntegerLight& light,
                      std::uint8_t rgb[3]);

// Fast path: the whole texture lit from `light_dir` (light frame, normalised here; z <= 0
// gives black), 8-bit RGB interleaved, rows top first. Bit-exact with the reference.
[[nodiscard]] std::vector<std::uint8_t> relight_integer_bytes(const Ptm8Texture& texture,
                                                              const Eigen::Vector3d& light_dir);
// The same as a float image (bytes / 255) in the texture's colour space.
[[nodiscard]] Image relight_integer(const Ptm8Texture& texture, const Eigen::Vector3d& light_dir);

// The bound of docs/INTEGER-MODEL.md section 3 for one polynomial: |Y - clamp(f)| in grey
// levels, where `coeffs_grey` are the unquantised coefficients (grey units) and (lu, lv) the
// exact light.
[[nodiscard]] double integer_error_bound_grey(const double coeffs_grey[kPtmTerms],
                                              const std::array<int, 3>& shifts, double lu,
                                              double lv);

// Integer vs float relighting of the same map over a set of lights.
struct IntegerErrorReport {
  double mean_abs_grey = 0.0;
  double max_abs_grey = 0.0;
  double psnr_db = 0.0;  // peak 255
  std::size_t samples = 0;
};
// Compares relight_integer(quantise_ptm8(map)) with float relight(map) (clamped, unrounded
// grey levels) at every light.
[[nodiscard]] IntegerErrorReport integer_vs_float(const CoefficientMap& map,
                                                  const std::vector<Eigen::Vector3d>& lights);

}  // namespace ptmkit::texture
