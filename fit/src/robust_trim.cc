// Robust per-texel solvers by trimming and reweighting: trim (clipped and dark samples out),
// sign (then residual signs against the polynomial), lambert (residual signs against the
// Lambertian model, robust_lambert.cc), qtrim (quantiles out), the optional re-admission step,
// and IRLS (Huber, Tukey).
#include <algorithm>
#include <cmath>

#include "kernels.h"
#include "ptmkit/fit/robust.h"
#include "robust_detail.h"

namespace ptmkit::fit {

using internal::Vec6;

int TexelSolver::Impl::count_inliers(const SampleLabel* labels) const {
  int k = 0;
  for (int i = 0; i < n; ++i) k += labels[i] == SampleLabel::kInlier ? 1 : 0;
  return k;
}

void TexelSolver::Impl::to_weights(const SampleLabel* labels, int count, double* weights) {
  for (int i = 0; i < count; ++i) weights[i] = labels[i] == SampleLabel::kInlier ? 1.0 : 0.0;
}

// Trimming: saturated samples are highlights, dark ones shadows; keeps at least
// min_inliers by readmitting the brightest unsaturated rejected samples.
void TexelSolver::Impl::trim(const double* value, const std::uint8_t* saturated,
                             SampleLabel* labels) {
  scratch.assign(value, value + n);
  scratch.resize(static_cast<std::size_t>((n + 7) & ~7));  // select_padded's room
  const double q = internal::select_padded(scratch.data(), n, (3 * (n - 1)) / 4);
  const double dark = opt.dark_fraction * std::max(q, 0.0);
  for (int i = 0; i < n; ++i) {
    labels[i] = saturated[i] != 0 ? SampleLabel::kHighlight
                : value[i] < dark ? SampleLabel::kShadow
                                  : SampleLabel::kInlier;
  }
  const int need = std::min(opt.min_inliers, n);
  for (int have = count_inliers(labels); have < need; ++have) {
    int best = -1;
    for (int i = 0; i < n; ++i) {
      if (labels[i] == SampleLabel::kInlier) continue;
      const bool better = best < 0 || (saturated[i] < saturated[best]) ||
                          (saturated[i] == saturated[best] && value[i] > value[best]);
      if (better) best = i;
    }
    labels[best] = SampleLabel::kInlier;
  }
  for (int i = 0; i < n; ++i)
    hard[static_cast<std::size_t>(i)] = labels[i] != SampleLabel::kInlier ? 1 : 0;
}

// Least squares on the samples `labels` keeps. When they are too few or degenerate
// (trimming or clipping took too many): plain least squares on all, nothing rejected, and
// false.
bool TexelSolver::Impl::fit_kept(const double* value, double* weights, SampleLabel* labels,
                                 Vec6* c) {
  to_weights(labels, n, weights);
  if (weighted(value, weights, c)) return true;
  std::fill(labels, labels + n, SampleLabel::kInlier);
  std::fill(weights, weights + n, 1.0);
  *c = pinv * Eigen::Map<const Eigen::VectorXd>(value, n);
  return false;
}

TexelOutcome TexelSolver::Impl::solve_trim_sign(const double* value, const std::uint8_t* saturated,
                                                double* weights, SampleLabel* labels, Vec6* c) {
  TexelOutcome out;
  trim(value, saturated, labels);
  if (!fit_kept(value, weights, labels, c)) {
    out.fallback = true;
    return out;
  }
  if (solver == Solver::kSign || solver == Solver::kLambert) {
    for (int it = 0; it < opt.max_iterations; ++it) {
      out.iterations = it + 1;
      if (solver == Solver::kLambert) {
        if (!lambert_residuals(value, labels)) {
          out.fallback = true;
          break;
        }
      } else {
        residuals(value, *c);
      }
      const double s = scale(labels);
      for (int i = 0; i < n; ++i) {
        const auto ui = static_cast<std::size_t>(i);
        if (hard[ui] != 0) {
          trial[ui] = labels[i];
          continue;
        }
        const double r = resid[ui];
        trial[ui] = r < -opt.shadow_k * s     ? SampleLabel::kShadow
                    : r > opt.highlight_k * s ? SampleLabel::kHighlight
                                              : SampleLabel::kInlier;
      }
      if (std::equal(trial.begin(), trial.end(), labels)) break;
      if (count_inliers(trial.data()) < std::min(opt.min_inliers, n)) {
        out.fallback = true;
        break;
      }
      std::vector<double>& w = trial_weights;
      to_weights(trial.data(), n, w.data());
      if (solver == Solver::kLambert) {
        // The polynomial is fitted once, after the labels settle.
        std::copy(trial.begin(), trial.end(), labels);
        std::copy(w.begin(), w.end(), weights);
        continue;
      }
      Vec6 next;
      if (!weighted(value, w.data(), &next)) {
        out.fallback = true;
        break;
      }
      std::copy(trial.begin(), trial.end(), labels);
      std::copy(w.begin(), w.end(), weights);
      *c = next;
    }
    if (solver == Solver::kLambert && opt.keep_within > 0.0 && !out.fallback) {
      keep_close(value, saturated, weights, labels);
    }
    if (solver == Solver::kLambert && !weighted(value, weights, c)) {
      // The settled inliers leave the polynomial degenerate: back to the trimmed set.
      trim(value, saturated, labels);
      to_weights(labels, n, weights);
      if (!weighted(value, weights, c)) *c = pinv * Eigen::Map<const Eigen::VectorXd>(value, n);
      out.fallback = true;
    }
    if (opt.readmit_k > 0.0 && !out.fallback) readmit(value, saturated, weights, labels, c);
    fill_ok = solver == Solver::kLambert && opt.fill_rejected && !out.fallback &&
              lambert_explains(value, weights, *c);
  }
  for (int i = 0; i < n; ++i) {
    out.shadows += labels[i] == SampleLabel::kShadow ? 1 : 0;
    out.highlights += labels[i] == SampleLabel::kHighlight ? 1 : 0;
  }
  return out;
}

// Quantile trimming: clipped samples are highlights; of the rest, the darkest
// dark_quantile of all samples are shadows and the brightest bright_quantile highlights
// (ranks by value, NaN last, ties by index: a strict order, so the result does not depend
// on the sort).
void TexelSolver::Impl::quantile_trim(const double* value, const std::uint8_t* saturated,
                                      SampleLabel* labels) {
  const int n_dark = static_cast<int>(std::floor(opt.dark_quantile * n));
  const int n_bright = static_cast<int>(std::floor(opt.bright_quantile * n));
  order.resize(static_cast<std::size_t>(n));
  for (int i = 0; i < n; ++i) order[static_cast<std::size_t>(i)] = i;
  std::sort(order.begin(), order.end(), [value](int a, int b) {
    const bool na = std::isnan(value[a]), nb = std::isnan(value[b]);
    if (na != nb) return nb;
    if (!na && value[a] != value[b]) return value[a] < value[b];
    return a < b;
  });
  for (int r = 0; r < n; ++r) {
    const int i = order[static_cast<std::size_t>(r)];
    labels[i] = saturated[i] != 0   ? SampleLabel::kHighlight
                : r < n_dark        ? SampleLabel::kShadow
                : r >= n - n_bright ? SampleLabel::kHighlight
                                    : SampleLabel::kInlier;
  }
}

TexelOutcome TexelSolver::Impl::solve_quantile(const double* value, const std::uint8_t* saturated,
                                               double* weights, SampleLabel* labels, Vec6* c) {
  TexelOutcome out;
  quantile_trim(value, saturated, labels);
  if (!fit_kept(value, weights, labels, c)) out.fallback = true;
  for (int i = 0; i < n; ++i) {
    out.shadows += labels[i] == SampleLabel::kShadow ? 1 : 0;
    out.highlights += labels[i] == SampleLabel::kHighlight ? 1 : 0;
  }
  return out;
}

// Re-admits rejected, unclipped samples within readmit_k scales of the polynomial fitted on
// the inliers, and refits once (RobustOptions::readmit_k). Keeps everything on failure.
void TexelSolver::Impl::readmit(const double* value, const std::uint8_t* saturated, double* weights,
                                SampleLabel* labels, Vec6* c) {
  residuals(value, *c);
  const double s = scale(labels);
  std::copy(labels, labels + n, trial.begin());
  bool changed = false;
  for (int i = 0; i < n; ++i) {
    const auto ui = static_cast<std::size_t>(i);
    if (labels[i] == SampleLabel::kInlier || saturated[i] != 0) continue;
    if (std::abs(resid[ui]) <= opt.readmit_k * s) {
      trial[ui] = SampleLabel::kInlier;
      changed = true;
    }
  }
  if (!changed) return;
  to_weights(trial.data(), n, trial_weights.data());
  Vec6 next;
  if (!weighted(value, trial_weights.data(), &next)) return;
  std::copy(trial.begin(), trial.end(), labels);
  std::copy(trial_weights.begin(), trial_weights.end(), weights);
  *c = next;
}

double TexelSolver::Impl::irls_weight(double u) const {
  const double a = std::abs(u);
  if (solver == Solver::kIrlsHuber) return a <= 1.0 ? 1.0 : 1.0 / a;
  if (a >= 1.0) return 0.0;
  const double t = 1.0 - a * a;
  return t * t;
}

TexelOutcome TexelSolver::Impl::solve_irls(const double* value, double* weights,
                                           SampleLabel* labels, Vec6* c) {
  TexelOutcome out;
  const double k = solver == Solver::kIrlsHuber ? opt.huber_k : opt.tukey_k;
  *c = pinv * Eigen::Map<const Eigen::VectorXd>(value, n);
  std::fill(weights, weights + n, 1.0);
  std::vector<double>& w = trial_weights;
  double s = 0.0;
  for (int it = 0; it < opt.max_iterations; ++it) {
    out.iterations = it + 1;
    residuals(value, *c);
    s = scale(nullptr);
    for (int i = 0; i < n; ++i)
      w[static_cast<std::size_t>(i)] = irls_weight(resid[static_cast<std::size_t>(i)] / (k * s));
    Vec6 next;
    if (!weighted(value, w.data(), &next)) {
      out.fallback = true;
      break;
    }
    std::copy(w.begin(), w.end(), weights);
    const double step = (next - *c).cwiseAbs().maxCoeff();
    *c = next;
    if (step < 1e-7) break;
  }
  residuals(value, *c);
  label_symmetric(s > 0.0 ? s : scale(nullptr), labels);
  for (int i = 0; i < n; ++i) {
    out.shadows += labels[i] == SampleLabel::kShadow ? 1 : 0;
    out.highlights += labels[i] == SampleLabel::kHighlight ? 1 : 0;
  }
  return out;
}

}  // namespace ptmkit::fit
