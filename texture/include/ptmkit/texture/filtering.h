// Anti-aliased lookups of light-dependent textures: a mip-mapped coefficient pyramid and
// summed-area tables over the stored coefficient bytes.
//
// Evaluation is linear in the coefficients, so filtering the coefficients and then relighting
// equals relighting and then filtering (before any clamp or quantisation) — the seed paper's
// argument for mip-mapping A..F. This holds exactly for kRGB and kYCC (from_ycbcr is linear
// in (Y, Cb, Cr)); for kLRGB the output L * colour is a product, so averaging L and the colour
// separately is only an approximation (exact where the colour is constant over the block).
#pragma once

#include <cstdint>
#include <vector>

#include "ptmkit/core/coefficients.h"
#include "ptmkit/core/image.h"
#include "ptmkit/texture/ptm8.h"

namespace ptmkit::texture {

// Level k+1 has ceil(w/2) x ceil(h/2) texels; texel (X, Y) is the mean of the level-k texels
// 2X..2X+1, 2Y..2Y+1 that exist (a 2x2 box; 2x1, 1x2 or 1x1 on an odd edge). The last level is
// 1 x 1. Storage: at most 4/3 of level 0 plus O(w + h) for odd sizes.
struct CoefficientPyramid {
  std::vector<CoefficientMap> levels;
  [[nodiscard]] std::size_t total_texels() const;
  // Floats per texel of a lookup: polynomials * 6 + colour values.
  [[nodiscard]] int values_per_texel() const;
};
[[nodiscard]] CoefficientPyramid build_pyramid(const CoefficientMap& map);
// The same 2x2 box on an image (any channel count), for comparisons.
[[nodiscard]] Image downsample_box(const Image& image);
// Every level in the paper's 8-bit scheme, each with its own shifts.
[[nodiscard]] std::vector<Ptm8Texture> quantise_pyramid(const CoefficientPyramid& pyramid);

// Trilinear lookup: bilinear (clamp to edge) on levels floor(lod) and floor(lod) + 1, blended
// linearly; lod <= 0 is a bilinear lookup of level 0. (x, y) are level-0 texel coordinates,
// texel centres at i + 0.5. `out` gets values_per_texel() floats: the coefficients, then the
// colour, in CoefficientMap's order.
void sample_trilinear(const CoefficientPyramid& pyramid, double x, double y, double lod,
                      float* out);

// Summed-area table over interleaved 8-bit planes (here: the stored bytes of a Ptm8Texture).
// Type: 64-bit integers of the bytes. Sums are exact: a table entry is at most
// 255 * width * height, which overflows signed 32 bits from 2896 x 2896 and unsigned 32 bits
// from about 4104 x 4104 (the lecture's warning)
// but stays below 2^63 for any image of up to 2^55 texels. Float sums lose the small boxes
// next to large corner sums (cancellation); doubles would be exact only up to 2^53 / 255
// texels and cost the same 8 bytes. Memory: 8 bytes per texel per plane.
class SummedAreaTable {
 public:
  SummedAreaTable() = default;
  SummedAreaTable(const std::uint8_t* data, int width, int height, int channels);
  explicit SummedAreaTable(const Ptm8Texture& texture);  // channels: coefficients then colour

  [[nodiscard]] int width() const { return width_; }
  [[nodiscard]] int height() const { return height_; }
  [[nodiscard]] int channels() const { return channels_; }
  // Sum of channel c over texels [x0, x1) x [y0, y1) (clamped to the image), 4 lookups.
  [[nodiscard]] std::int64_t sum(int c, int x0, int y0, int x1, int y1) const;
  // Mean bytes of every channel over the (clamped, non-empty) box; `out` gets channels().
  void mean(int x0, int y0, int x1, int y1, double* out) const;

 private:
  [[nodiscard]] std::int64_t at(int x, int y, int c) const {
    return table_[(static_cast<std::size_t>(y) * (width_ + 1) + x) * channels_ + c];
  }
  int width_ = 0, height_ = 0, channels_ = 0;
  std::vector<std::int64_t> table_;  // (width + 1) x (height + 1) x channels, zero border
};

// Box-filtered coefficients of a Ptm8Texture over [x0, x1) x [y0, y1) via its table, in the
// map's normalised units (coefficients then colour, as CoefficientMap).
void sat_coefficients(const SummedAreaTable& sat, const Ptm8Texture& texture, int x0, int y0,
                      int x1, int y1, float* out);

}  // namespace ptmkit::texture
