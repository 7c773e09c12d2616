#include "ptmkit/fit/robust.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstring>
#include <limits>

#include <ceres/ceres.h>
#include <Eigen/Cholesky>

#include "kernels.h"
#include "ptmkit/core/coefficients.h"
#include "ptmkit/core/error.h"

namespace ptmkit::fit {

namespace {

struct SolverName {
  Solver solver;
  const char* name;
};
constexpr std::array<SolverName, 14> kSolverNames = {{
    {Solver::kLS, "ls"},
    {Solver::kQR, "qr"},
    {Solver::kSVD, "svd"},
    {Solver::kRidge, "ridge"},
    {Solver::kIrlsHuber, "irls-huber"},
    {Solver::kIrlsTukey, "irls-tukey"},
    {Solver::kTrim, "trim"},
    {Solver::kSign, "sign"},
    {Solver::kLambert, "lambert"},
    {Solver::kQTrim, "qtrim"},
    {Solver::kCeresHuber, "ceres-huber"},
    {Solver::kCeresCauchy, "ceres-cauchy"},
    {Solver::kCeresTukey, "ceres-tukey"},
    {Solver::kRobust, "robust"},
}};

using Vec6 = Eigen::Matrix<double, kPtmTerms, 1>;
using Mat6 = Eigen::Matrix<double, kPtmTerms, kPtmTerms>;

// Normal matrices are summed as packed lower triangles (row by row) of per-light outer
// products computed once: N (N + 1) / 2 multiply-adds a sample.
template <int N>
using Packed = std::array<double, static_cast<std::size_t>(N*(N + 1) / 2)>;

template <int N>
Packed<N> packed_outer(const Eigen::Matrix<double, N, 1>& v) {
  Packed<N> p{};
  for (int a = 0, t = 0; a < N; ++a) {
    for (int c = 0; c <= a; ++c, ++t) p[static_cast<std::size_t>(t)] = v(a) * v(c);
  }
  return p;
}

template <int N>
Eigen::Matrix<double, N, N> unpack_symmetric(const Packed<N>& p) {
  Eigen::Matrix<double, N, N> m;
  for (int a = 0, t = 0; a < N; ++a) {
    for (int c = 0; c <= a; ++c, ++t) m(a, c) = m(c, a) = p[static_cast<std::size_t>(t)];
  }
  return m;
}

// One residual block per sample: r = b . c - y, with the analytic Jacobian b.
class SampleCost final : public ceres::SizedCostFunction<1, kPtmTerms> {
 public:
  SampleCost(const double* basis, const double* value) : basis_(basis), value_(value) {}
  bool Evaluate(double const* const* params, double* residuals, double** jacobians) const override {
    const double* c = params[0];
    double f = 0.0;
    for (int k = 0; k < kPtmTerms; ++k) f += basis_[k] * c[k];
    residuals[0] = f - *value_;
    if (jacobians != nullptr && jacobians[0] != nullptr) {
      for (int k = 0; k < kPtmTerms; ++k) jacobians[0][k] = basis_[k];
    }
    return true;
  }

 private:
  const double* basis_;
  const double* value_;
};

}  // namespace

std::string_view to_string(Solver solver) {
  for (const auto& s : kSolverNames) {
    if (s.solver == solver) return s.name;
  }
  return "?";
}

Solver parse_solver(std::string_view name) {
  for (const auto& s : kSolverNames) {
    if (name == s.name) return s.solver;
  }
  std::string known;
  for (const auto& s : kSolverNames) known += (known.empty() ? "" : ", ") + std::string(s.name);
  throw Error("unknown solver '" + std::string(name) + "' (expected one of " + known + ")");
}

std::vector<std::string> solver_names() {
  std::vector<std::string> names;
  for (const auto& s : kSolverNames) names.emplace_back(s.name);
  return names;
}

Solver resolve_solver(Solver solver) {
  return solver == Solver::kRobust ? Solver::kLambert : solver;
}

bool is_shared_solver(Solver solver) {
  return solver == Solver::kLS || solver == Solver::kQR || solver == Solver::kSVD ||
         solver == Solver::kRidge;
}

std::string RobustOptions::validate() const {
  const auto pos = [](double v) { return std::isfinite(v) && v > 0.0; };
  if (!pos(mad_factor) || !pos(min_scale)) return "robust scale factors must be finite and > 0";
  if (!pos(huber_k) || !pos(cauchy_k) || !pos(tukey_k) || !pos(label_k)) {
    return "robust loss widths must be finite and > 0";
  }
  if (!pos(shadow_k) || !pos(highlight_k)) return "sign thresholds must be finite and > 0";
  if (!(dark_fraction >= 0.0 && dark_fraction < 1.0)) return "dark_fraction must be in [0, 1)";
  if (!(saturation_level > 0.0)) return "saturation_level must be > 0 (+inf disables it)";
  if (max_iterations < 1 || ceres_max_iterations < 1) return "iterations must be >= 1";
  if (min_inliers < kPtmTerms) return "min_inliers must be at least 6";
  if (!(dark_quantile >= 0.0 && bright_quantile >= 0.0 && dark_quantile + bright_quantile < 0.9)) {
    return "dark_quantile and bright_quantile must be >= 0 with a sum below 0.9";
  }
  if (!(readmit_k >= 0.0)) return "readmit_k must be >= 0 (0 = off)";
  if (!(keep_within >= 0.0) || !std::isfinite(keep_within)) {
    return "keep_within must be finite and >= 0 (0 = off)";
  }
  return {};
}

struct TexelSolver::Impl {
  Solver solver;
  RobustOptions opt;
  int n = 0;
  std::vector<Vec6> basis;                                // rows of the design
  std::vector<Packed<kPtmTerms>> outer;                   // b b^T per light
  std::vector<Eigen::Vector4d> lambert_rows;              // (lx, ly, lz, 1) per light
  std::vector<Packed<4>> lambert_outer;                   // q q^T per light
  Eigen::Matrix<double, kPtmTerms, Eigen::Dynamic> pinv;  // unweighted least squares
  // Scratch.
  std::vector<double> resid, scratch, value_copy;
  Eigen::VectorXd fill_values;
  // lambert_fit's cache: the samples of the last factorisation, and its result.
  std::vector<std::uint8_t> lambert_mask;
  Eigen::LDLT<Eigen::Matrix4d> lambert_ldlt;
  bool lambert_cached = false, lambert_ok = false;
  bool fill_ok = false;  // the last solve() found the Lambertian model fit to fill with
  std::vector<SampleLabel> trial;
  std::vector<double> trial_weights;
  std::vector<std::uint8_t> hard;  // label fixed by trimming
  std::vector<int> order;          // quantile_trim's ranks
  // Cached factorisation of the last weighted system.
  std::vector<double> llt_weights;
  Eigen::LLT<Mat6> llt;
  bool llt_ok = false;
  // Ceres, built once and reused for every texel: the residual blocks read value_copy.
  std::unique_ptr<ceres::Problem> problem;
  ceres::LossFunctionWrapper* loss = nullptr;  // owned by loss_owner
  std::unique_ptr<ceres::LossFunctionWrapper> loss_owner;
  std::array<double, kPtmTerms> params{};
  ceres::Solver::Options ceres_options;

  void residuals(const double* value, const Vec6& c) {
    for (int i = 0; i < n; ++i)
      resid[static_cast<std::size_t>(i)] = value[i] - basis[static_cast<std::size_t>(i)].dot(c);
  }

  // Robust scale of the residuals where mask (if given) says inlier.
  double scale(const SampleLabel* labels) {
    scratch.clear();
    for (int i = 0; i < n; ++i) {
      if (labels == nullptr || labels[i] == SampleLabel::kInlier)
        scratch.push_back(resid[static_cast<std::size_t>(i)]);
    }
    const int count = static_cast<int>(scratch.size());
    scratch.resize(static_cast<std::size_t>((count + 7) & ~7));  // median_padded's room
    const double med = internal::median_padded(scratch.data(), count);
    for (int i = 0; i < count; ++i) {
      double& v = scratch[static_cast<std::size_t>(i)];
      v = std::abs(v - med);
    }
    return std::max(opt.mad_factor * internal::median_padded(scratch.data(), count), opt.min_scale);
  }

  bool factor(const double* weights) {
    if (llt_ok && !llt_weights.empty() &&
        std::memcmp(llt_weights.data(), weights, sizeof(double) * static_cast<std::size_t>(n)) ==
            0) {
      return true;
    }
    // sum_i w_i b_i b_i^T from the precomputed products (a rank update through Eigen's
    // general 6 x 6 path cost a tenth of the robust fit).
    Packed<kPtmTerms> acc{};
    int used = 0;
    for (int i = 0; i < n; ++i) {
      const double w = weights[i];
      if (w <= 0.0) continue;
      ++used;
      const auto& o = outer[static_cast<std::size_t>(i)];
      for (std::size_t t = 0; t < acc.size(); ++t) acc[t] += w * o[t];
    }
    llt_weights.assign(weights, weights + n);
    llt_ok = false;
    if (used < kPtmTerms) return false;
    llt.compute(unpack_symmetric<kPtmTerms>(acc));
    if (llt.info() != Eigen::Success) return false;
    // Cheap conditioning check from the Cholesky diagonal: cond(M) >= (max L_ii / min L_ii)^2.
    const auto d = llt.matrixLLT().diagonal();
    const double ratio = d.minCoeff() / d.maxCoeff();
    if (!(ratio * ratio > 1e-12)) return false;
    llt_ok = true;
    return true;
  }

  bool weighted(const double* value, const double* weights, Vec6* c) {
    if (!factor(weights)) return false;
    Vec6 rhs = Vec6::Zero();
    for (int i = 0; i < n; ++i) {
      if (weights[i] > 0.0) rhs += (weights[i] * value[i]) * basis[static_cast<std::size_t>(i)];
    }
    *c = llt.solve(rhs);
    return c->allFinite();
  }

  int count_inliers(const SampleLabel* labels) const {
    int k = 0;
    for (int i = 0; i < n; ++i) k += labels[i] == SampleLabel::kInlier ? 1 : 0;
    return k;
  }

  static void to_weights(const SampleLabel* labels, int count, double* weights) {
    for (int i = 0; i < count; ++i) weights[i] = labels[i] == SampleLabel::kInlier ? 1.0 : 0.0;
  }

  void label_symmetric(double s, SampleLabel* labels) const {
    for (int i = 0; i < n; ++i) {
      const double r = resid[static_cast<std::size_t>(i)];
      labels[i] = r < -opt.label_k * s  ? SampleLabel::kShadow
                  : r > opt.label_k * s ? SampleLabel::kHighlight
                                        : SampleLabel::kInlier;
    }
  }

  // Trimming: saturated samples are highlights, dark ones shadows; keeps at least
  // min_inliers by readmitting the brightest unsaturated rejected samples.
  void trim(const double* value, const std::uint8_t* saturated, SampleLabel* labels) {
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
  bool fit_kept(const double* value, double* weights, SampleLabel* labels, Vec6* c) {
    to_weights(labels, n, weights);
    if (weighted(value, weights, c)) return true;
    std::fill(labels, labels + n, SampleLabel::kInlier);
    std::fill(weights, weights + n, 1.0);
    *c = pinv * Eigen::Map<const Eigen::VectorXd>(value, n);
    return false;
  }

  TexelOutcome solve_trim_sign(const double* value, const std::uint8_t* saturated, double* weights,
                               SampleLabel* labels, Vec6* c) {
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
  void quantile_trim(const double* value, const std::uint8_t* saturated, SampleLabel* labels) {
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

  TexelOutcome solve_quantile(const double* value, const std::uint8_t* saturated, double* weights,
                              SampleLabel* labels, Vec6* c) {
    TexelOutcome out;
    quantile_trim(value, saturated, labels);
    if (!fit_kept(value, weights, labels, c)) out.fallback = true;
    for (int i = 0; i < n; ++i) {
      out.shadows += labels[i] == SampleLabel::kShadow ? 1 : 0;
      out.highlights += labels[i] == SampleLabel::kHighlight ? 1 : 0;
    }
    return out;
  }

  // RobustOptions::keep_within: rejected, unclipped samples within keep_within of the
  // Lambertian model fitted on the settled inliers become inliers again.
  void keep_close(const double* value, const std::uint8_t* saturated, double* weights,
                  SampleLabel* labels) {
    Eigen::Vector4d g;
    if (!lambert_fit(
            value, [&](int i) { return labels[i] == SampleLabel::kInlier; }, &g))
      return;
    for (int i = 0; i < n; ++i) {
      if (labels[i] == SampleLabel::kInlier || saturated[i] != 0) continue;
      // Only where the model says the light reaches the surface: an attached shadow's dark
      // sample matches the model's zero, but it carries no direction for the normal.
      const double direct = lambert_rows[static_cast<std::size_t>(i)].head<3>().dot(g.head<3>());
      if (direct > 0.0 && std::abs(value[i] - lambert_shade(i, g)) <= opt.keep_within) {
        labels[i] = SampleLabel::kInlier;
        weights[i] = 1.0;
      }
    }
  }

  // Re-admits rejected, unclipped samples within readmit_k scales of the polynomial fitted on
  // the inliers, and refits once (RobustOptions::readmit_k). Keeps everything on failure.
  void readmit(const double* value, const std::uint8_t* saturated, double* weights,
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

  // value ~ max(0, l . g) + a by least squares over the samples where include(i): g and a.
  // The factorisation is kept for the next call with the same samples (the same texel's
  // other channels, its inlier set checked twice).
  template <typename Include>
  bool lambert_fit(const double* value, Include include, Eigen::Vector4d* g) {
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

  double lambert_shade(int i, const Eigen::Vector4d& g) const {
    const Eigen::Vector4d& q = lambert_rows[static_cast<std::size_t>(i)];
    return std::max(0.0, q.head<3>().dot(g.head<3>())) + g(3);
  }

  // Residuals against value ~ max(0, l . g) + a, fitted on the inliers.
  bool lambert_residuals(const double* value, const SampleLabel* labels) {
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
  bool lambert_explains(const double* value, const double* weights, const Vec6& c) {
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
  bool filled(const double* value, const double* weights, Vec6* c) {
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

  double irls_weight(double u) const {
    const double a = std::abs(u);
    if (solver == Solver::kIrlsHuber) return a <= 1.0 ? 1.0 : 1.0 / a;
    if (a >= 1.0) return 0.0;
    const double t = 1.0 - a * a;
    return t * t;
  }

  TexelOutcome solve_irls(const double* value, double* weights, SampleLabel* labels, Vec6* c) {
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

  void build_ceres() {
    ceres::Problem::Options po;
    po.cost_function_ownership = ceres::TAKE_OWNERSHIP;
    po.loss_function_ownership = ceres::DO_NOT_TAKE_OWNERSHIP;
    po.enable_fast_removal = false;
    problem = std::make_unique<ceres::Problem>(po);
    loss_owner = std::make_unique<ceres::LossFunctionWrapper>(new ceres::HuberLoss(1.0),
                                                              ceres::TAKE_OWNERSHIP);
    loss = loss_owner.get();
    value_copy.assign(static_cast<std::size_t>(n), 0.0);
    for (int i = 0; i < n; ++i) {
      problem->AddResidualBlock(new SampleCost(basis[static_cast<std::size_t>(i)].data(),
                                               &value_copy[static_cast<std::size_t>(i)]),
                                loss, params.data());
    }
    ceres_options.linear_solver_type = ceres::DENSE_NORMAL_CHOLESKY;
    ceres_options.max_num_iterations = opt.ceres_max_iterations;
    ceres_options.num_threads = 1;
    ceres_options.logging_type = ceres::SILENT;
    ceres_options.minimizer_progress_to_stdout = false;
    ceres_options.function_tolerance = 1e-8;
    ceres_options.gradient_tolerance = 1e-12;
    ceres_options.parameter_tolerance = 1e-9;
  }

  ceres::LossFunction* make_loss(double width) const {
    switch (solver) {
      case Solver::kCeresCauchy:
        return new ceres::CauchyLoss(width);
      case Solver::kCeresTukey:
        return new ceres::TukeyLoss(width);
      default:
        return new ceres::HuberLoss(width);
    }
  }

  TexelOutcome solve_ceres(const double* value, double* weights, SampleLabel* labels, Vec6* c) {
    TexelOutcome out;
    *c = pinv * Eigen::Map<const Eigen::VectorXd>(value, n);
    residuals(value, *c);
    const double s = scale(nullptr);
    std::fill(weights, weights + n, 1.0);
    if (opt.ceres_only_where_needed) {
      double worst = 0.0;
      for (double r : resid) worst = std::max(worst, std::abs(r));
      if (worst <= opt.label_k * s) {
        std::fill(labels, labels + n, SampleLabel::kInlier);
        return out;
      }
    }
    const double k = solver == Solver::kCeresCauchy  ? opt.cauchy_k
                     : solver == Solver::kCeresTukey ? opt.tukey_k
                                                     : opt.huber_k;
    if (!problem) build_ceres();
    std::copy(value, value + n, value_copy.begin());
    loss->Reset(make_loss(k * s), ceres::TAKE_OWNERSHIP);
    for (int t = 0; t < kPtmTerms; ++t)
      params[static_cast<std::size_t>(t)] = (*c)(t);  // warm start: least squares
    ceres::Solver::Summary summary;
    ceres::Solve(ceres_options, problem.get(), &summary);
    out.ceres_ran = true;
    out.iterations = static_cast<int>(summary.iterations.size());
    Vec6 robust_c;
    for (int t = 0; t < kPtmTerms; ++t) robust_c(t) = params[static_cast<std::size_t>(t)];
    if (!robust_c.allFinite()) {
      out.fallback = true;
      std::fill(labels, labels + n, SampleLabel::kInlier);
      return out;
    }
    residuals(value, robust_c);
    // The loss's weights rho'(r^2) give the same fit by weighted least squares (the M
    // estimator's fixed point), so every channel is fitted with them.
    const ceres::LossFunction* l = loss;
    for (int i = 0; i < n; ++i) {
      double rho[3];
      const double r = resid[static_cast<std::size_t>(i)];
      l->Evaluate(r * r, rho);
      weights[i] = std::clamp(rho[1], 0.0, 1.0);
    }
    Vec6 check;
    if (!factor(weights) || !weighted(value, weights, &check)) {
      out.fallback = true;
      std::fill(weights, weights + n, 1.0);
      std::fill(labels, labels + n, SampleLabel::kInlier);
      return out;
    }
    *c = robust_c;
    label_symmetric(s, labels);
    for (int i = 0; i < n; ++i) {
      out.shadows += labels[i] == SampleLabel::kShadow ? 1 : 0;
      out.highlights += labels[i] == SampleLabel::kHighlight ? 1 : 0;
    }
    return out;
  }
};

TexelSolver::TexelSolver(const Eigen::MatrixXd& design, Solver solver, const RobustOptions& options)
    : impl_(std::make_unique<Impl>()) {
  if (const auto err = options.validate(); !err.empty()) throw Error("robust options: " + err);
  impl_->solver = resolve_solver(solver);
  if (is_shared_solver(impl_->solver)) {
    throw Error("TexelSolver: solver '" + std::string(to_string(solver)) +
                "' is a shared pseudo-inverse, not a per-texel solver");
  }
  impl_->opt = options;
  impl_->n = static_cast<int>(design.rows());
  const auto n = static_cast<std::size_t>(impl_->n);
  impl_->basis.resize(n);
  impl_->lambert_rows.resize(n);
  for (std::size_t i = 0; i < n; ++i) {
    impl_->basis[i] = design.row(static_cast<Eigen::Index>(i)).transpose();
    impl_->outer.push_back(packed_outer<kPtmTerms>(impl_->basis[i]));
    const double lu = impl_->basis[i](3);
    const double lv = impl_->basis[i](4);
    impl_->lambert_rows[i] << lu, lv, std::sqrt(std::max(0.0, 1.0 - lu * lu - lv * lv)), 1.0;
    impl_->lambert_outer.push_back(packed_outer<4>(impl_->lambert_rows[i]));
  }
  const Eigen::MatrixXd normal = design.transpose() * design;
  impl_->pinv = normal.ldlt().solve(design.transpose());
  impl_->resid.assign(n, 0.0);
  impl_->fill_values.resize(impl_->n);
  impl_->lambert_mask.assign(n, 0);
  impl_->trial.assign(n, SampleLabel::kInlier);
  impl_->trial_weights.assign(n, 0.0);
  impl_->hard.assign(n, 0);
  impl_->scratch.reserve(n + 8);
}

TexelSolver::~TexelSolver() = default;

TexelOutcome TexelSolver::solve(const double* value, const std::uint8_t* saturated, double* weights,
                                SampleLabel* labels, double coeffs[6]) {
  Impl& m = *impl_;
  Vec6 c;
  TexelOutcome out;
  m.fill_ok = false;
  switch (m.solver) {
    case Solver::kTrim:
    case Solver::kSign:
    case Solver::kLambert:
      out = m.solve_trim_sign(value, saturated, weights, labels, &c);
      break;
    case Solver::kQTrim:
      out = m.solve_quantile(value, saturated, weights, labels, &c);
      break;
    case Solver::kIrlsHuber:
    case Solver::kIrlsTukey:
      out = m.solve_irls(value, weights, labels, &c);
      break;
    default:
      out = m.solve_ceres(value, weights, labels, &c);
      break;
  }
  for (int k = 0; k < kPtmTerms; ++k) coeffs[k] = c(k);
  return out;
}

bool TexelSolver::weighted_fit(const double* value, const double* weights, double coeffs[6]) {
  Impl& m = *impl_;
  Vec6 c;
  const bool ok = m.fill_ok ? m.filled(value, weights, &c) : m.weighted(value, weights, &c);
  if (!ok) c = m.pinv * Eigen::Map<const Eigen::VectorXd>(value, m.n);
  for (int k = 0; k < kPtmTerms; ++k) coeffs[k] = c(k);
  return ok;
}

}  // namespace ptmkit::fit
