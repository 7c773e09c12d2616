// The Lambertian model of the robust solvers: value ~ max(0, l . g) + a fitted on a texel's
// inliers (the factorisation cached across channels), its residuals for the lambert solver's
// labels, the keep-close step, the check that it explains the inliers, and the fill of
// rejected samples (RobustOptions::keep_within, fill_rejected).
#include <algorithm>
#include <cmath>

#include "ptmkit/fit/robust.h"
#include "robust_detail.h"

namespace ptmkit::fit {

using internal::Packed;
using internal::unpack_symmetric;
using internal::Vec6;

// RobustOptions::keep_within: rejected, unclipped samples within the keep window
// (keep_within, at most keep_within_fraction of the texel's albedo) of the Lambertian model
// fitted on the settled inliers become inliers again.
void TexelSolver::Impl::keep_close(const double* value, const std::uint8_t* saturated,
                                   double* weights, SampleLabel* labels) {
  Eigen::Vector4d g;
  if (!lambert_fit(
          value, [&](int i) { return labels[i] == SampleLabel::kInlier; }, &g))
    return;
  double window = opt.keep_within;
  if (opt.keep_within_fraction > 0.0) {
    window = std::min(window, opt.keep_within_fraction * g.head<3>().norm());
  }
  for (int i = 0; i < n; ++i) {
    if (labels[i] == SampleLabel::kInlier || saturated[i] != 0) continue;
    // Only where the model says the light reaches the surface: an attached shadow's dark
    // sample matches the model's zero, but it carries no direction for the normal.
    const double direct = lambert_rows[static_cast<std::size_t>(i)].head<3>().dot(g.head<3>());
    if (direct > 0.0 && std::abs(value[i] - lambert_shade(i, g)) <= window) {
      labels[i] = SampleLabel::kInlier;
      weights[i] = 1.0;
    }
  }
}

// value ~ max(0, l . g) + a by least squares over the samples where include(i): g and a.
// The factorisation is kept for the next call with the same samples (the same texel's
// other channels, its inlier set checked twice).
template <typename Include>
bool TexelSolver::Impl::lambert_fit(const double* value, Include include, Eigen::Vector4d* g) {
  bool same = lambert_cached;
  for (int i = 0; i < n; ++i) {
    const std::uint8_t in = include(i) ? 1 : 0;
    auto& slot = lambert_mask[static_cast<std::size_t>(i)];
    same = same && slot == in;
    slot = in;
  }
  if (!same) {
    lambert_cached = true;
    lambert_ok = false;
    Packed<4> acc{};
    int used = 0;
    for (int i = 0; i < n; ++i) {
      if (lambert_mask[static_cast<std::size_t>(i)] == 0) continue;
      const auto& o = lambert_outer[static_cast<std::size_t>(i)];
      for (std::size_t t = 0; t < acc.size(); ++t) acc[t] += o[t];
      ++used;
    }
    if (used < 4) return false;
    lambert_ldlt.compute(unpack_symmetric<4>(acc));
    lambert_ok = lambert_ldlt.info() == Eigen::Success && lambert_ldlt.isPositive();
  }
  if (!lambert_ok) return false;
  Eigen::Vector4d rhs = Eigen::Vector4d::Zero();
  for (int i = 0; i < n; ++i) {
    if (lambert_mask[static_cast<std::size_t>(i)] != 0)
      rhs += value[i] * lambert_rows[static_cast<std::size_t>(i)];
  }
  *g = lambert_ldlt.solve(rhs);
  return g->allFinite();
}

double TexelSolver::Impl::lambert_shade(int i, const Eigen::Vector4d& g) const {
  const Eigen::Vector4d& q = lambert_rows[static_cast<std::size_t>(i)];
  return std::max(0.0, q.head<3>().dot(g.head<3>())) + g(3);
}

// Residuals against value ~ max(0, l . g) + a, fitted on the inliers.
bool TexelSolver::Impl::lambert_residuals(const double* value, const SampleLabel* labels) {
  Eigen::Vector4d g;
  if (!lambert_fit(
          value, [&](int i) { return labels[i] == SampleLabel::kInlier; }, &g)) {
    return false;
  }
  for (int i = 0; i < n; ++i) resid[static_cast<std::size_t>(i)] = value[i] - lambert_shade(i, g);
  return true;
}

// Whether the Lambertian model fits the inliers at least as well as the polynomial c, per
// degree of freedom (4 parameters against 6): only then is it trusted where samples were
// rejected. A surface the polynomial follows and the model does not keeps its own fit.
bool TexelSolver::Impl::lambert_explains(const double* value, const double* weights,
                                         const Vec6& c) {
  Eigen::Vector4d g;
  const auto inlier = [&](int i) { return weights[i] > 0.0; };
  if (!lambert_fit(value, inlier, &g)) return false;
  double rss_poly = 0.0, rss_lambert = 0.0;
  int m = 0;
  for (int i = 0; i < n; ++i) {
    if (!inlier(i)) continue;
    ++m;
    const double rp = value[i] - basis[static_cast<std::size_t>(i)].dot(c);
    const double rl = value[i] - lambert_shade(i, g);
    rss_poly += rp * rp;
    rss_lambert += rl * rl;
  }
  if (m <= kPtmTerms) return false;
  return rss_lambert / (m - 4) <= rss_poly / (m - kPtmTerms);
}

// RobustOptions::fill_rejected: the rejected samples (weight 0) replaced by the Lambertian
// model fitted on the others, then the shared least-squares pseudo-inverse.
bool TexelSolver::Impl::filled(const double* value, const double* weights, Vec6* c) {
  if (std::all_of(weights, weights + n, [](double w) { return w > 0.0; })) {
    *c = pinv * Eigen::Map<const Eigen::VectorXd>(value, n);
    return true;
  }
  Eigen::Vector4d g;
  if (!lambert_fit(
          value, [&](int i) { return weights[i] > 0.0; }, &g))
    return false;
  Eigen::VectorXd& v = fill_values;
  for (int i = 0; i < n; ++i) v(i) = weights[i] > 0.0 ? value[i] : lambert_shade(i, g);
  *c = pinv * v;
  return c->allFinite();
}

}  // namespace ptmkit::fit
