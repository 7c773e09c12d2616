// What every PTM row fitter shares: a texel's labelling values, LRGB colour or YCC chroma,
// model values, residuals, and the optional per-texel maps.
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <vector>

#include "kernels.h"
#include "photometric.h"
#include "ptm_rows.h"
#include "ptmkit/core/colour.h"

namespace ptmkit::fit::internal {

PtmRowFitter::PtmRowFitter(const FitSetup& setup, const LightDesign& design)
    : RowFitter(setup), design_(design), srgb_(setup.colour_space == ColourSpace::kSRGB) {
  const auto n = design.design().rows();
  light_.resize(n, 3);
  for (Eigen::Index i = 0; i < n; ++i) {
    const double lu = design.design()(i, 3);
    const double lv = design.design()(i, 4);
    light_.row(i) << lu, lv, std::sqrt(std::max(0.0, 1.0 - lu * lu - lv * lv));
  }
  const FitOutputs* o = setup.outputs;
  extras_ = o != nullptr &&
            (o->want_residual_map || o->want_outlier_counts || o->want_labels || o->want_normals);
}

void PtmRowFitter::labelling_values(const std::vector<double>& s, int n, double* value,
                                    std::uint8_t* saturated) const {
  const int ch = channels_;
  const double sat = options_.robust.saturation_level;
  for (int i = 0; i < n; ++i) {
    const double* p = s.data() + static_cast<std::size_t>(i) * ch;
    value[i] = ch == 3 ? luma(p[0], p[1], p[2]) : p[0];
    bool clipped = false;
    for (int k = 0; k < ch; ++k) clipped = clipped || p[k] >= sat;
    if (saturated != nullptr) saturated[i] = clipped ? 1 : 0;
  }
}

// One texel's LRGB colour (which also rescales coef, see finish_lrgb_colour) or YCC chroma,
// from its samples s (n x channels), labelling values and per-sample weights.
void PtmRowFitter::texel_colour(const std::vector<double>& s, int n, const double* value,
                                const double* weights, float* coef, float* col) const {
  const int ch = channels_;
  if (options_.model == ColourModel::kLRGB) {
    LrgbSums sums;
    for (int i = 0; i < n; ++i) {
      const double* p = s.data() + static_cast<std::size_t>(i) * ch;
      sums.add(weights[i], value[i], p[0], p[ch == 3 ? 1 : 0], p[ch == 3 ? 2 : 0]);
    }
    internal::finish_lrgb_colour(sums.yy, sums.yc, col, coef);
    return;
  }
  double sy = 0.0, scb = 0.0, scr = 0.0;
  if (ch == 3) {
    for (int i = 0; i < n; ++i) {
      const double* p = s.data() + static_cast<std::size_t>(i) * 3;
      const auto ycc = to_ycbcr(p[0], p[1], p[2]);
      const double wgt = weights[i] * std::max(0.0, ycc.y);
      sy += wgt;
      scb += wgt * ycc.cb;
      scr += wgt * ycc.cr;
    }
  }
  finish_ycc_chroma(sy, scb, scr, col);
}

// Residuals of one texel's fit against its samples, into the row's statistics.
void PtmRowFitter::texel_residuals(const std::vector<double>& s, int n, const float* coef,
                                   const float* col, const TexelGeometry* g, RowStats* st) const {
  const int ch = channels_;
  for (int i = 0; i < n; ++i) {
    double rgb[3];
    model_rgb(coef, col, i, rgb, g);
    for (int k = 0; k < ch; ++k)
      st->add(255.0 * (s[static_cast<std::size_t>(i * ch + k)] - rgb[k]));
  }
}

void PtmRowFitter::model_rgb(const float* coef, const float* col, int i, double rgb[3],
                             const TexelGeometry* g) const {
  const auto b = design_.design().row(i);
  const double* gb =
      g != nullptr ? g->basis.data() + static_cast<std::ptrdiff_t>(i) * kPtmTerms : nullptr;
  auto eval = [&](const float* c) {
    double v = 0.0;
    if (gb != nullptr) {
      for (int t = 0; t < kPtmTerms; ++t) v += gb[t] * c[t];
    } else {
      for (int t = 0; t < kPtmTerms; ++t) v += b(t) * c[t];
    }
    return v;
  };
  switch (options_.model) {
    case ColourModel::kRGB:
      for (int k = 0; k < 3; ++k) rgb[k] = eval(coef + k * kPtmTerms);
      break;
    case ColourModel::kLRGB: {
      const double l = eval(coef);
      for (int k = 0; k < 3; ++k) rgb[k] = l * col[k];
      break;
    }
    case ColourModel::kYCC:
      from_ycbcr({eval(coef), col[0], col[1]}, &rgb[0], &rgb[1], &rgb[2]);
      break;
  }
}

// Residual map, counts, labels, normals and albedo of one texel from its samples, weights
// (0 = rejected) and labels, and its fitted coefficients.
void PtmRowFitter::texel_extras(const std::vector<double>& s, const double* value,
                                const double* weights, const SampleLabel* labels, const float* coef,
                                const float* col, int x, int y, const TexelGeometry* geo) const {
  FitOutputs& o = *setup_.outputs;
  const int n = design_.lights();
  const int ch = channels_;
  if (o.want_residual_map) {
    double sum = 0.0;
    std::uint64_t cnt = 0;
    for (int i = 0; i < n; ++i) {
      if (labels[i] != SampleLabel::kInlier) continue;
      double rgb[3];
      model_rgb(coef, col, i, rgb, geo);
      for (int k = 0; k < ch; ++k) {
        const double d = 255.0 * (s[static_cast<std::size_t>(i * ch + k)] - rgb[k]);
        sum += d * d;
        ++cnt;
      }
    }
    o.residual_map.at(x, y, 0) =
        cnt > 0 ? static_cast<float>(std::sqrt(sum / static_cast<double>(cnt))) : 0.0f;
  }
  if (o.want_outlier_counts) {
    int sh = 0, hi = 0;
    for (int i = 0; i < n; ++i) {
      sh += labels[i] == SampleLabel::kShadow ? 1 : 0;
      hi += labels[i] == SampleLabel::kHighlight ? 1 : 0;
    }
    o.outlier_counts.at(x, y, 0) = static_cast<float>(sh);
    o.outlier_counts.at(x, y, 1) = static_cast<float>(hi);
  }
  if (o.want_labels) {
    std::uint8_t* dst = o.labels.data() + (static_cast<std::size_t>(y) * width_ + x) * n;
    for (int i = 0; i < n; ++i) dst[i] = static_cast<std::uint8_t>(labels[i]);
  }
  if (o.want_normals) {
    float normal[3], albedo[3];
    if (geo != nullptr) {
      lambertian_stereo(geo->dirs, n, ch, srgb_, s, value, weights, normal, albedo);
    } else {
      lambertian_stereo(light_, n, ch, srgb_, s, value, weights, normal, albedo);
    }
    for (int k = 0; k < 3; ++k) {
      o.normals.at(x, y, k) = normal[k];
      o.albedo.at(x, y, k) = albedo[k];
    }
  }
}

// Least-squares solvers: every sample is an inlier.
void PtmRowFitter::row_extras(const StackBand& band, int r, const float* c_out,
                              const float* col_out) const {
  const int n = band.images;
  const int polys = polynomial_count(options_.model);
  const int ncol = colour_count(options_.model);
  std::vector<double> s, value(static_cast<std::size_t>(n)),
      weights(static_cast<std::size_t>(n), 1.0);
  std::vector<SampleLabel> labels;
  labels.assign(static_cast<std::size_t>(n), SampleLabel::kInlier);
  for (int x = 0; x < width_; ++x) {
    gather(band, r, x, &s);
    labelling_values(s, n, value.data(), nullptr);
    texel_extras(s, value.data(), weights.data(), labels.data(),
                 c_out + static_cast<std::size_t>(x) * polys * kPtmTerms,
                 col_out + static_cast<std::size_t>(x) * ncol, x, band.y0 + r);
  }
}

}  // namespace ptmkit::fit::internal
