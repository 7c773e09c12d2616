#include "ptmkit/core/coefficients.h"

#include <algorithm>
#include <string>

#include "ptmkit/core/colour.h"
#include "ptmkit/core/error.h"
#include "ptmkit/core/hsh.h"

namespace ptmkit {

std::string_view to_string(Basis basis) {
  switch (basis) {
    case Basis::kHsh2:
      return "hsh2";
    case Basis::kPtm:
      return "ptm";
    case Basis::kHsh3:
      return "hsh3";
    case Basis::kHsh4:
      return "hsh4";
  }
  return "?";
}

Basis parse_basis(std::string_view name) {
  for (Basis b : all_bases()) {
    if (name == to_string(b)) return b;
  }
  throw Error("unknown basis '" + std::string(name) + "' (known: hsh2, ptm, hsh3, hsh4)");
}

std::vector<Basis> all_bases() { return {Basis::kHsh2, Basis::kPtm, Basis::kHsh3, Basis::kHsh4}; }

void evaluate_basis(Basis basis, const Eigen::Vector3d& dir, double* out) {
  if (basis == Basis::kPtm) {
    const auto b = ptm_basis(dir.x(), dir.y());
    std::copy(b.begin(), b.end(), out);
    return;
  }
  hsh_basis(basis_terms(basis), dir, out);
}

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

CoefficientMap::CoefficientMap(const CoefficientLayout& layout)
    : width(layout.width),
      height(layout.height),
      basis(layout.basis),
      model(layout.model),
      colour_space(layout.colour_space),
      coeffs(static_cast<std::size_t>(layout.width) * layout.height * layout.coeffs_per_texel(),
             0.0f),
      colour(static_cast<std::size_t>(layout.width) * layout.height * layout.colours(), 0.0f) {}

void CoefficientMap::evaluate(int x, int y, const Eigen::Vector3d& dir, float rgb[3]) const {
  if (basis == Basis::kPtm) {
    evaluate(x, y, dir.x(), dir.y(), rgb);
    return;
  }
  double b[kMaxBasisTerms];
  evaluate_basis(basis, dir, b);
  const int t = terms();
  const float* a = texel_coeffs(x, y);
  double l[3] = {0.0, 0.0, 0.0};
  for (int p = 0; p < polynomials(); ++p) {
    for (int j = 0; j < t; ++j) l[p] += a[p * t + j] * b[j];
  }
  switch (model) {
    case ColourModel::kRGB:
      for (int c = 0; c < 3; ++c) rgb[c] = static_cast<float>(l[c]);
      break;
    case ColourModel::kLRGB:
      for (int c = 0; c < 3; ++c) rgb[c] = static_cast<float>(l[0] * texel_colour(x, y)[c]);
      break;
    case ColourModel::kYCC: {
      const float* col = texel_colour(x, y);
      double r = 0, g = 0, bl = 0;
      from_ycbcr({l[0], col[0], col[1]}, &r, &g, &bl);
      rgb[0] = static_cast<float>(r);
      rgb[1] = static_cast<float>(g);
      rgb[2] = static_cast<float>(bl);
      break;
    }
  }
}

void CoefficientMap::evaluate(int x, int y, double lu, double lv, float rgb[3]) const {
  const auto b = ptm_basis(lu, lv);
  const float* a = texel_coeffs(x, y);
  auto poly = [&](const float* c) {
    double v = 0.0;
    for (int i = 0; i < kPtmTerms; ++i) v += c[i] * b[i];
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
      double r = 0, g = 0, bl = 0;
      from_ycbcr({poly(a), col[0], col[1]}, &r, &g, &bl);
      rgb[0] = static_cast<float>(r);
      rgb[1] = static_cast<float>(g);
      rgb[2] = static_cast<float>(bl);
      break;
    }
  }
}

void CoefficientMapSink::begin(const CoefficientLayout& layout) { *map_ = CoefficientMap(layout); }

void CoefficientMapSink::write_rows(int y0, int rows, const float* coeffs, const float* colour) {
  const std::size_t nc = map_->layout().coeffs_per_texel();
  const std::size_t texels = static_cast<std::size_t>(rows) * map_->width;
  std::copy_n(coeffs, texels * nc, map_->texel_coeffs(0, y0));
  if (map_->colours() > 0) {
    std::copy_n(colour, texels * map_->colours(), map_->texel_colour(0, y0));
  }
}

}  // namespace ptmkit
