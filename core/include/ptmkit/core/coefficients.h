// Fitted light-dependent textures in memory: what the fit stage produces and the texture
// stage stores, filters and evaluates. One model for every basis and colour layout: a map is
// (basis, colour model) plus, per texel, `polynomials()` sets of `terms()` coefficients and
// `colours()` colour values; one sink interface receives it band by band (.ptm and .rti
// writers, the in-memory map).
//
// Bases (terms per fitted channel, Basis):
//   hsh2  4   hemispherical harmonics of order 2 (core/hsh.h), stored as .rti
//   ptm   6   the seed paper's biquadratic below, stored as .ptm
//   hsh3  9   hemispherical harmonics of order 3
//   hsh4  16  hemispherical harmonics of order 4
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
#include <cstddef>
#include <string_view>
#include <vector>

#include <Eigen/Core>

#include "ptmkit/core/image.h"

namespace ptmkit {

inline constexpr int kPtmTerms = 6;
// The most terms of any basis (hsh4).
inline constexpr int kMaxBasisTerms = 16;

// The function basis of the light direction a map is fitted in.
enum class Basis { kHsh2, kPtm, kHsh3, kHsh4 };
// "hsh2", "ptm", "hsh3", "hsh4".
[[nodiscard]] std::string_view to_string(Basis basis);
// Throws ptmkit::Error listing the known names for an unknown one.
[[nodiscard]] Basis parse_basis(std::string_view name);
// Terms per fitted channel: 4, 6, 9, 16.
[[nodiscard]] constexpr int basis_terms(Basis basis) {
  switch (basis) {
    case Basis::kHsh2:
      return 4;
    case Basis::kPtm:
      return kPtmTerms;
    case Basis::kHsh3:
      return 9;
    case Basis::kHsh4:
      return 16;
  }
  return 0;
}
// Every basis, fewest terms first.
[[nodiscard]] std::vector<Basis> all_bases();
// The basis functions at the unit direction `dir` (light frame), basis_terms(basis) values.
// PTM: ptm_basis(x, y) below. HSH: core/hsh.h.
void evaluate_basis(Basis basis, const Eigen::Vector3d& dir, double* out);

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

// What a map holds, without its values: what a sink is told before the first band.
struct CoefficientLayout {
  int width = 0;
  int height = 0;
  Basis basis = Basis::kPtm;
  ColourModel model = ColourModel::kRGB;
  ColourSpace colour_space = ColourSpace::kSRGB;

  [[nodiscard]] int terms() const { return basis_terms(basis); }
  [[nodiscard]] int polynomials() const { return polynomial_count(model); }
  [[nodiscard]] int colours() const { return colour_count(model); }
  // Floats per texel: coefficients, then (separately) colour values.
  [[nodiscard]] std::size_t coeffs_per_texel() const {
    return static_cast<std::size_t>(polynomials()) * static_cast<std::size_t>(terms());
  }
};

// A fitted map. The layout per texel is [polynomial][term] coefficients and, for the luminance
// models, colour values. Bases other than PTM are fitted as kRGB layouts: a luminance fit
// (lrgb, grey input) of an HSH basis is delivered multiplied out (channel c's coefficients are
// colour_c times the luminance coefficients, exactly the LRGB model), which is what .rti
// stores.
struct CoefficientMap {
  int width = 0;
  int height = 0;
  Basis basis = Basis::kPtm;
  ColourModel model = ColourModel::kRGB;
  // What the fitted values are (the images' colour space; relit images carry it on).
  ColourSpace colour_space = ColourSpace::kSRGB;
  // [y][x][polynomial][term], rows top to bottom.
  std::vector<float> coeffs;
  // [y][x][colour_count(model)], empty for kRGB.
  std::vector<float> colour;

  CoefficientMap() = default;
  // A PTM map of zeros.
  CoefficientMap(int w, int h, ColourModel m, ColourSpace cs = ColourSpace::kSRGB);
  // A map of zeros of any layout.
  explicit CoefficientMap(const CoefficientLayout& layout);

  [[nodiscard]] CoefficientLayout layout() const {
    return {width, height, basis, model, colour_space};
  }
  [[nodiscard]] int terms() const { return basis_terms(basis); }
  [[nodiscard]] int polynomials() const { return polynomial_count(model); }
  [[nodiscard]] int colours() const { return colour_count(model); }
  [[nodiscard]] std::size_t texels() const { return static_cast<std::size_t>(width) * height; }
  [[nodiscard]] std::size_t texel_index(int x, int y) const {
    return static_cast<std::size_t>(y) * width + x;
  }
  [[nodiscard]] float* texel_coeffs(int x, int y) {
    return coeffs.data() + texel_index(x, y) * polynomials() * terms();
  }
  [[nodiscard]] const float* texel_coeffs(int x, int y) const {
    return coeffs.data() + texel_index(x, y) * polynomials() * terms();
  }
  [[nodiscard]] float* texel_colour(int x, int y) {
    return colour.data() + texel_index(x, y) * colours();
  }
  [[nodiscard]] const float* texel_colour(int x, int y) const {
    return colour.data() + texel_index(x, y) * colours();
  }

  // RGB of texel (x, y) of a PTM map lit from (lu, lv), unclamped, in normalised units. The
  // caller checks that the light is above the surface.
  void evaluate(int x, int y, double lu, double lv, float rgb[3]) const;
  // RGB of texel (x, y) of a map in any basis lit from the unit direction `dir`, unclamped.
  void evaluate(int x, int y, const Eigen::Vector3d& dir, float rgb[3]) const;
};

// Receives a fit row band by row band, so a fit can be stored or written without holding the
// whole map in float. Calls: begin, then write_rows for consecutive bands top to bottom, then
// end. Buffers are laid out as CoefficientMap's, for rows [y0, y0 + rows). A sink that cannot
// store a layout (a .ptm writer given an HSH basis) throws ptmkit::Error from begin.
class CoefficientSink {
 public:
  virtual ~CoefficientSink() = default;
  virtual void begin(const CoefficientLayout& layout) = 0;
  virtual void write_rows(int y0, int rows, const float* coeffs, const float* colour) = 0;
  virtual void end() = 0;
};

// Sink that fills a CoefficientMap in memory.
class CoefficientMapSink final : public CoefficientSink {
 public:
  explicit CoefficientMapSink(CoefficientMap* map) : map_(map) {}
  void begin(const CoefficientLayout& layout) override;
  void write_rows(int y0, int rows, const float* coeffs, const float* colour) override;
  void end() override {}

 private:
  CoefficientMap* map_;
};

}  // namespace ptmkit
