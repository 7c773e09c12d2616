// PTM per texel: the robust solvers (each texel's samples labelled and weighted first,
// robust.h) and near lights (each texel its own design rows from its light directions).
#include <algorithm>
#include <cstdint>
#include <vector>

#include <Eigen/Cholesky>
#include <Eigen/Core>

#include "ptm_rows.h"
#include "ptmkit/core/colour.h"

namespace ptmkit::fit::internal {

// Robust solvers: per texel, label the samples on the labelling channel, then fit every
// polynomial with the same weights.
void RobustRowFitter::fit_row(const StackBand& band, int r, float* c_out, float* col_out,
                              RowStats* st) const {
  const int n = band.images;
  const int ch = channels_;
  const int polys = polynomial_count(options_.model);
  const int ncol = colour_count(options_.model);
  const auto un = static_cast<std::size_t>(n);
  TexelSolver solver(design_.design(), options_.solver, options_.robust);
  std::vector<double> s, value(un), weights(un), chan(un);
  std::vector<std::uint8_t> saturated(un);
  std::vector<SampleLabel> labels(un);
  for (int x = 0; x < width_; ++x) {
    gather(band, r, x, &s);
    labelling_values(s, n, value.data(), saturated.data());
    double c[kPtmTerms];
    const TexelOutcome out =
        solver.solve(value.data(), saturated.data(), weights.data(), labels.data(), c);
    st->outliers.samples += un;
    st->outliers.shadows += static_cast<std::uint64_t>(out.shadows);
    st->outliers.highlights += static_cast<std::uint64_t>(out.highlights);
    st->outliers.fallback_texels += out.fallback ? 1u : 0u;
    st->outliers.ceres_texels += out.ceres_ran ? 1u : 0u;

    float* coef = c_out + static_cast<std::size_t>(x) * polys * kPtmTerms;
    float* col = col_out + static_cast<std::size_t>(x) * ncol;
    auto store = [&](const double* v, float* dst) {
      double cc[kPtmTerms];
      solver.weighted_fit(v, weights.data(), cc);
      for (int t = 0; t < kPtmTerms; ++t) dst[t] = static_cast<float>(cc[t]);
    };
    if (options_.model == ColourModel::kRGB) {
      if (ch == 3) {
        for (int k = 0; k < 3; ++k) {
          for (int i = 0; i < n; ++i)
            chan[static_cast<std::size_t>(i)] = s[static_cast<std::size_t>(i * 3 + k)];
          store(chan.data(), coef + k * kPtmTerms);
        }
      } else {
        store(value.data(), coef);
        std::copy_n(coef, kPtmTerms, coef + kPtmTerms);
        std::copy_n(coef, kPtmTerms, coef + 2 * kPtmTerms);
      }
    } else {
      store(value.data(), coef);
      texel_colour(s, n, value.data(), weights.data(), coef, col);
    }
    if (st->active) texel_residuals(s, n, coef, col, nullptr, st);
    if (extras_) {
      texel_extras(s, value.data(), weights.data(), labels.data(), coef, col, x, band.y0 + r);
    }
  }
}

// Near lights: every texel its own design rows A_t (from its light directions) and its own

// 6 x 6 normal equations A_t^T A_t c = A_t^T s, by Cholesky in double; samples first
// multiplied by the fall-off correction when asked.
void NearRowFitter::fit_row(const StackBand& band, int r, float* c_out, float* col_out,
                            RowStats* st) const {
  const int n = band.images;
  const int ch = channels_;
  const int polys = polynomial_count(options_.model);
  const int ncol = colour_count(options_.model);
  const auto un = static_cast<std::size_t>(n);
  const int y = band.y0 + r;
  TexelGeometry g;
  g.basis.resize(n, kPtmTerms);
  g.dirs.resize(n, 3);
  g.correction.resize(un);
  std::vector<double> s, value(un), weights(un, 1.0);
  const std::vector<SampleLabel> labels(un, SampleLabel::kInlier);
  const double ridge = setup_.near.ridge_lambda * static_cast<double>(n);
  for (int x = 0; x < width_; ++x) {
    setup_.near.model->texel(x + setup_.near.origin_x, y + setup_.near.origin_y, g.dirs.data(),
                             g.correction.data());
    for (int i = 0; i < n; ++i) {
      const auto b = ptm_basis(g.dirs(i, 0), g.dirs(i, 1));
      for (int t = 0; t < kPtmTerms; ++t) g.basis(i, t) = b[static_cast<std::size_t>(t)];
    }
    gather(band, r, x, &s);
    if (setup_.near.falloff) {
      for (int i = 0; i < n; ++i) {
        const double f = g.correction[static_cast<std::size_t>(i)];
        for (int k = 0; k < ch; ++k) {
          double& v = s[static_cast<std::size_t>(i * ch + k)];
          v = srgb_ ? linear_to_srgb(srgb_to_linear(v) * f) : v * f;
        }
      }
    }
    const bool rgb_model = options_.model == ColourModel::kRGB;
    if (!rgb_model || extras_) labelling_values(s, n, value.data(), nullptr);
    // Normal matrix and right-hand sides by hand, fixed sizes: Eigen's general products
    // allocate and cost several times more at these shapes (6 x N times N x 6).
    const int nrhs = rgb_model ? ch : 1;
    double mm[kPtmTerms][kPtmTerms] = {};
    double rr[kPtmTerms][3] = {};
    for (int i = 0; i < n; ++i) {
      const double* b = g.basis.data() + static_cast<std::ptrdiff_t>(i) * kPtmTerms;
      const double* v = rgb_model ? s.data() + static_cast<std::size_t>(i) * ch : value.data() + i;
      for (int a = 0; a < kPtmTerms; ++a) {
        for (int c = 0; c <= a; ++c) mm[a][c] += b[a] * b[c];
        for (int k = 0; k < nrhs; ++k) rr[a][k] += b[a] * v[k];
      }
    }
    Eigen::Matrix<double, kPtmTerms, kPtmTerms> m;
    Eigen::Matrix<double, kPtmTerms, 3> rhs = Eigen::Matrix<double, kPtmTerms, 3>::Zero();
    for (int a = 0; a < kPtmTerms; ++a) {
      for (int c = 0; c <= a; ++c) m(a, c) = m(c, a) = mm[a][c];
      for (int k = 0; k < nrhs; ++k) rhs(a, k) = rr[a][k];
    }
    if (ridge > 0.0) m.diagonal().array() += ridge;
    const Eigen::LLT<Eigen::Matrix<double, kPtmTerms, kPtmTerms>> llt(m);
    if (llt.info() != Eigen::Success) {
      ++st->singular_texels;  // coefficients stay 0
      continue;
    }
    const Eigen::Matrix<double, kPtmTerms, 3> c = llt.solve(rhs);
    float* coef = c_out + static_cast<std::size_t>(x) * polys * kPtmTerms;
    float* col = col_out + static_cast<std::size_t>(x) * ncol;
    auto store = [&](int from, float* dst) {
      for (int t = 0; t < kPtmTerms; ++t) dst[t] = static_cast<float>(c(t, from));
    };
    if (rgb_model) {
      for (int k = 0; k < 3; ++k) store(ch == 3 ? k : 0, coef + k * kPtmTerms);
    } else {
      store(0, coef);
      texel_colour(s, n, value.data(), weights.data(), coef, col);  // weights all 1
    }
    if (st->active) texel_residuals(s, n, coef, col, &g, st);
    if (extras_) {
      texel_extras(s, value.data(), weights.data(), labels.data(), coef, col, x, y, &g);
    }
  }
}

}  // namespace ptmkit::fit::internal
