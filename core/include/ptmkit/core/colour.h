// Colour conversions used by the fit and relighting. Values are whatever the images hold
// (usually sRGB-encoded, as the seed paper fits non-linear camera values).
#pragma once

#include <algorithm>

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

// The LRGB model's colour (rgb(l) = L(l) * colour), by least squares over a texel's samples:
// per channel c, k_c = max(0, sum w Y c / sum w Y^2), with Y the samples' luma; 1 when the
// texel's luma is all (near) zero, where the colour is undetermined. One definition for every
// fit of the model in double (per-texel solvers, near lights, other bases, model selection);
// the float row kernels of the shared-matrix fit (fit/src/kernels.h) compute the same
// quantity with the same IEEE operations.
struct LrgbSums {
  double yy = 0.0;                 // sum w Y^2
  double yc[3] = {0.0, 0.0, 0.0};  // sum w Y r, sum w Y g, sum w Y b
  void add(double w, double y, double r, double g, double b) {
    yy += w * y * y;
    yc[0] += w * y * r;
    yc[1] += w * y * g;
    yc[2] += w * y * b;
  }
  // k_c (see above).
  [[nodiscard]] double factor(int c) const { return yy > 1e-20 ? std::max(0.0, yc[c] / yy) : 1.0; }
};

[[nodiscard]] double srgb_to_linear(double v);
[[nodiscard]] double linear_to_srgb(double v);

}  // namespace ptmkit
