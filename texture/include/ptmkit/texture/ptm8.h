// The seed paper's 8-bit coefficient storage: three per-texture shifts (high order a0 a1 a2,
// middle a3 a4, low a5), a bias of 127, six bytes per polynomial per texel. The full rule and
// the hardware model that evaluates it are in docs/INTEGER-MODEL.md.
//
// Container (`NAME.ptm8`, a folder, written atomically as a whole):
//   manifest.json      {"format": "ptmkit-ptm8", "version": 1, "width", "height",
//                       "model": "rgb" | "lrgb", "colour_space": "srgb" | "linear",
//                       "bias": 127, "shifts": {"high", "mid", "low"},
//                       "planes": [{"a012": FILE, "a345": FILE}, ...], "colour": FILE}
//   p0_a012.png        24-bit RGB: a0, a1, a2 bytes of polynomial 0 (R for rgb, L for lrgb)
//   p0_a345.png        24-bit RGB: a3, a4, a5 bytes of polynomial 0
//   p1_*, p2_*         the G and B polynomials (rgb only)
//   colour.png         24-bit RGB colour bytes (lrgb only)
// Images are top row first. A byte b of group g means a = (b - 127) * 2^-s_g grey levels
// (255 = full scale), i.e. (b - 127) * 2^-s_g / 255 in the map's normalised units.
#pragma once

#include <array>
#include <cstdint>
#include <filesystem>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "ptmkit/core/coefficients.h"

namespace ptmkit::texture {

inline constexpr int kPtm8Bias = 127;
inline constexpr int kPtm8MinShift = -8;
inline constexpr int kPtm8MaxShift = 24;

// Coefficient group of term i (0..5): 0 = high (a0 a1 a2), 1 = middle (a3 a4), 2 = low (a5).
[[nodiscard]] constexpr int ptm8_group(int term) { return term < 3 ? 0 : (term < 5 ? 1 : 2); }

struct Ptm8Texture {
  int width = 0;
  int height = 0;
  ColourModel model = ColourModel::kRGB;  // kRGB or kLRGB
  ColourSpace colour_space = ColourSpace::kSRGB;
  std::array<int, 3> shifts{0, 0, 0};  // s_high, s_mid, s_low
  // [y][x][polynomial][term] bytes, as CoefficientMap's float layout.
  std::vector<std::uint8_t> coeffs;
  // [y][x][3] colour bytes, kLRGB only (largest channel 255 when the colour is not black).
  std::vector<std::uint8_t> colour;

  [[nodiscard]] int polynomials() const { return model == ColourModel::kRGB ? 3 : 1; }
  [[nodiscard]] std::size_t texels() const { return static_cast<std::size_t>(width) * height; }
  [[nodiscard]] const std::uint8_t* texel(int x, int y) const {
    return coeffs.data() + (static_cast<std::size_t>(y) * width + x) * polynomials() * kPtmTerms;
  }
  [[nodiscard]] const std::uint8_t* texel_colour(int x, int y) const {
    return colour.data() + (static_cast<std::size_t>(y) * width + x) * 3;
  }
  // Grey levels per step of each group's bytes: 2^-s_g.
  [[nodiscard]] double step_grey(int group) const;
  // Stored bytes per texel: 18 (rgb) or 9 (lrgb); the shifts add 3 bytes per texture.
  [[nodiscard]] int bytes_per_texel() const { return model == ColourModel::kRGB ? 18 : 9; }
};

// The shift of a group whose largest coefficient magnitude is `max_abs_grey` (grey units).
[[nodiscard]] int choose_ptm8_shift(double max_abs_grey);

// A map in the paper's scheme. kYCC is first converted exactly to three polynomials (kRGB,
// shared a0..a4); kLRGB keeps its colour (renormalised to a largest channel of 1, the
// luminance scaled to match, as the .ptm writer does).
[[nodiscard]] Ptm8Texture quantise_ptm8(const CoefficientMap& map);
// The texture's polynomials as a float map (kRGB or kLRGB), normalised units.
[[nodiscard]] CoefficientMap dequantise_ptm8(const Ptm8Texture& texture);
// kYCC -> kRGB exactly (R, G, B polynomials share a0..a4); other models are returned as is.
[[nodiscard]] CoefficientMap to_rgb_polynomials(const CoefficientMap& map);

// Writes the container folder atomically (a temporary folder beside it renamed into place;
// an existing container of that name is replaced). Throws ptmkit::Error naming the path.
void write_ptm8(const std::filesystem::path& folder, const Ptm8Texture& texture);
// Reads a container; errors (missing files, wrong sizes, bad manifest) name the file.
[[nodiscard]] Ptm8Texture read_ptm8(const std::filesystem::path& folder);

// Both quantisation schemes on the same map, against the unquantised float map: relit
// (float evaluation, clamped) error at `lights` over every texel and channel.
struct SchemeError {
  double mean_abs_grey = 0.0;
  double max_abs_grey = 0.0;
  double psnr_db = 0.0;  // peak 255 grey levels; +inf when identical
};
struct QuantisationComparison {
  SchemeError ptm;      // .ptm per-coefficient scale and bias (ptm.h)
  SchemeError ptm8;     // the paper's shifts, float evaluation of the stored values
  SchemeError integer;  // the paper's shifts evaluated by the integer model
  std::array<int, 3> shifts{};
  std::size_t samples = 0;  // texels x lights x channels
  [[nodiscard]] std::string brief() const;
};
// Empty `lights`: the paper's 40-light geodesic dome.
[[nodiscard]] QuantisationComparison compare_quantisations(
    const CoefficientMap& map, std::vector<Eigen::Vector3d> lights = {});

}  // namespace ptmkit::texture
