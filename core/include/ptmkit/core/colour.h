// Colour conversions used by the fit and relighting. Values are whatever the images hold
// (usually sRGB-encoded, as the seed paper fits non-linear camera values).
#pragma once

namespace ptmkit {

// Rec. 601 luma weights, as in JPEG's YCbCr (the seed paper's colour space).
inline constexpr double kLumaR = 0.299;
inline constexpr double kLumaG = 0.587;
inline constexpr double kLumaB = 0.114;

[[nodiscard]] inline double luma(double r, double g, double b) {
  return kLumaR * r + kLumaG * g + kLumaB * b;
}

// Full-range YCbCr (JPEG), chroma centred on 0 rather than 0.5.
struct YCbCr {
  double y = 0.0, cb = 0.0, cr = 0.0;
};
[[nodiscard]] inline YCbCr to_ycbcr(double r, double g, double b) {
  const double y = luma(r, g, b);
  return {y, (b - y) / 1.772, (r - y) / 1.402};
}
// Returns r, g, b.
inline void from_ycbcr(const YCbCr& c, double* r, double* g, double* b) {
  *r = c.y + 1.402 * c.cr;
  *b = c.y + 1.772 * c.cb;
  *g = (c.y - kLumaR * *r - kLumaB * *b) / kLumaG;
}

[[nodiscard]] double srgb_to_linear(double v);
[[nodiscard]] double linear_to_srgb(double v);

}  // namespace ptmkit
