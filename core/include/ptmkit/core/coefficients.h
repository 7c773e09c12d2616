// Fitted light-dependent textures in memory: what the fit stage produces and the texture
// stage stores, filters and evaluates.
//
// Per texel and per fitted channel, the seed paper's biquadratic in the projected light
// direction (lu, lv) — the first two components of the unit vector toward the light in the
// texture frame (s, t, N):
//   L(lu, lv) = a0 lu^2 + a1 lv^2 + a2 lu lv + a3 lu + a4 lv + a5
// The order a0..a5 is the .ptm file's order. Coefficients are in normalised intensity units
// (the polynomial gives 1.0 at full scale; the .ptm file's 0..255 units are a texture-stage
// concern). Light behind the surface (z <= 0) gives no light.
#pragma once

#include <array>
#include <string_view>
#include <vector>

#include "ptmkit/core/image.h"

namespace ptmkit {

inline constexpr int kPtmTerms = 6;

// The six basis functions at (lu, lv), in a0..a5 order.
template <class T>
constexpr std::array<T, kPtmTerms> ptm_basis(T lu, T lv) {
  return {lu * lu, lv * lv, lu * lv, lu, lv, T(1)};
}

// How colour is modelled.
enum class ColourModel {
  // Three polynomials per texel, one each for R, G, B (PTM_FORMAT_RGB).
  kRGB,
  // One polynomial for luminance times a per-texel RGB colour (PTM_FORMAT_LRGB):
  //   rgb(l) = L(l) * colour, with colour scaled so its largest channel is 1.
  kLRGB,
  // The seed paper: one polynomial for Y of YCbCr, per-texel constant Cb and Cr:
  //   rgb(l) = from_ycbcr(Y(l), cb, cr). Exactly an RGB texture whose three polynomials share
  //   a0..a4 and differ in a5, which is how it is written to .ptm.
  kYCC,
};
[[nodiscard]] std::string_view to_string(ColourModel model);
// Accepts "rgb", "lrgb", "ycc"; throws ptmkit::Error otherwise.
[[nodiscard]] ColourModel parse_colour_model(std::string_view name);
// Polynomials per texel: 3 for kRGB, 1 otherwise.
[[nodiscard]] int polynomial_count(ColourModel model);
// Per-texel colour values: 0 for kRGB, 3 for kLRGB (rgb), 2 for kYCC (cb, cr).
[[nodiscard]] int colour_count(ColourModel model);

struct CoefficientMap {
  int width = 0;
  int height = 0;
  ColourModel model = ColourModel::kRGB;
  // What the fitted values are (the images' colour space; relit images carry it on).
  ColourSpace colour_space = ColourSpace::kSRGB;
  // [y][x][polynomial][term], rows top to bottom.
  std::vector<float> coeffs;
  // [y][x][colour_count(model)], empty for kRGB.
  std::vector<float> colour;

  CoefficientMap() = default;
  CoefficientMap(int w, int h, ColourModel m, ColourSpace cs = ColourSpace::kSRGB);

  [[nodiscard]] int polynomials() const { return polynomial_count(model); }
  [[nodiscard]] int colours() const { return colour_count(model); }
  [[nodiscard]] std::size_t texel_index(int x, int y) const {
    return static_cast<std::size_t>(y) * width + x;
  }
  [[nodiscard]] float* texel_coeffs(int x, int y) {
    return coeffs.data() + texel_index(x, y) * polynomials() * kPtmTerms;
  }
  [[nodiscard]] const float* texel_coeffs(int x, int y) const {
    return coeffs.data() + texel_index(x, y) * polynomials() * kPtmTerms;
  }
  [[nodiscard]] float* texel_colour(int x, int y) {
    return colour.data() + texel_index(x, y) * colours();
  }
  [[nodiscard]] const float* texel_colour(int x, int y) const {
    return colour.data() + texel_index(x, y) * colours();
  }

  // RGB of texel (x, y) lit from (lu, lv), unclamped, in normalised units. The caller checks
  // that the light is above the surface.
  void evaluate(int x, int y, double lu, double lv, float rgb[3]) const;
};

// Receives a fit row band by row band, so a fit can be stored or written without holding the
// whole map in float. Calls: begin, then write_rows for consecutive bands top to bottom, then
// end. Buffers are laid out as CoefficientMap's, for rows [y0, y0 + rows).
class CoefficientSink {
 public:
  virtual ~CoefficientSink() = default;
  virtual void begin(int width, int height, ColourModel model, ColourSpace colour_space) = 0;
  virtual void write_rows(int y0, int rows, const float* coeffs, const float* colour) = 0;
  virtual void end() = 0;
};

// Sink that fills a CoefficientMap in memory.
class CoefficientMapSink final : public CoefficientSink {
 public:
  explicit CoefficientMapSink(CoefficientMap* map) : map_(map) {}
  void begin(int width, int height, ColourModel model, ColourSpace colour_space) override;
  void write_rows(int y0, int rows, const float* coeffs, const float* colour) override;
  void end() override {}

 private:
  CoefficientMap* map_;
};

}  // namespace ptmkit
