#include "ptmkit/core/coefficients.h"

#include <algorithm>
#include <string>

#include "ptmkit/core/colour.h"
#include "ptmkit/core/error.h"

namespace ptmkit {

std::string_view to_string(ColourModel model) {
  switch (model) {
    case ColourModel::kRGB:
      return "rgb";
    case ColourModel::kLRGB:
      return "lrgb";
    case ColourModel::kYCC:
      return "ycc";
  }
  return "unknown";
}

ColourModel parse_colour_model(std::string_view name) {
  if (name == "rgb") return ColourModel::kRGB;
  if (name == "lrgb") return ColourModel::kLRGB;
  if (name == "ycc") return ColourModel::kYCC;
  throw Error("unknown colour model '" + std::string(name) + "' (expected rgb, lrgb or ycc)");
}

int polynomial_count(ColourModel model) { return model == ColourModel::kRGB ? 3 : 1; }

int colour_count(ColourModel model) {
  switch (model) {
    case ColourModel::kRGB:
      return 0;
    case ColourModel::kLRGB:
      return 3;
    case ColourModel::kYCC:
      return 2;
  }
  return 0;
}

CoefficientMap::CoefficientMap(int w, int h, ColourModel m, ColourSpace cs)
    : width(w),
      height(h),
      model(m),
      colour_space(cs),
      coeffs(static_cast<std::size_t>(w) * h * polynomial_count(m) * kPtmTerms, 0.0f),
      colour(static_cast<std::size_t>(w) * h * colour_count(m), 0.0f) {}

void CoefficientMap::evaluate(int x, int y, double lu, double lv, float rgb[3]) const {
  const auto basis = ptm_basis(lu, lv);
  const float* a = texel_coeffs(x, y);
  auto poly = [&](const float* c) {
    double v = 0.0;
    for (int i = 0; i < kPtmTerms; ++i) v += c[i] * basis[i];
    return v;
  };
  switch (model) {
    case ColourModel::kRGB:
      for (int c = 0; c < 3; ++c) rgb[c] = static_cast<float>(poly(a + c * kPtmTerms));
      break;
    case ColourModel::kLRGB: {
      const double l = poly(a);
      const float* col = texel_colour(x, y);
      for (int c = 0; c < 3; ++c) rgb[c] = static_cast<float>(l * col[c]);
      break;
    }
    case ColourModel::kYCC: {
      const float* col = texel_colour(x, y);
      double r = 0, g = 0, b = 0;
      from_ycbcr({poly(a), col[0], col[1]}, &r, &g, &b);
      rgb[0] = static_cast<float>(r);
      rgb[1] = static_cast<float>(g);
      rgb[2] = static_cast<float>(b);
      break;
    }
  }
}

void CoefficientMapSink::begin(int width, int height, ColourModel model, ColourSpace colour_space) {
  *map_ = CoefficientMap(width, height, model, colour_space);
}

void CoefficientMapSink::write_rows(int y0, int rows, const float* coeffs, const float* colour) {
  const std::size_t nc = static_cast<std::size_t>(map_->polynomials()) * kPtmTerms;
  const std::size_t texels = static_cast<std::size_t>(rows) * map_->width;
  std::copy_n(coeffs, texels * nc, map_->texel_coeffs(0, y0));
  if (map_->colours() > 0) {
    std::copy_n(colour, texels * map_->colours(), map_->texel_colour(0, y0));
  }
}

}  // namespace ptmkit
