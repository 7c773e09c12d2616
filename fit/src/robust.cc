// Robust per-texel solvers: solver names and options, the driver (TexelSolver: set-up,
// dispatch to the solvers, weighted fits of further channels) and the weighted least-squares
// core the solvers share (residuals, robust scale, the cached Cholesky factorisation). The
// solvers themselves: robust_trim.cc, robust_lambert.cc, robust_ceres.cc.
#include "ptmkit/fit/robust.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstring>

#include <Eigen/Cholesky>

#include "kernels.h"
#include "ptmkit/core/coefficients.h"
#include "ptmkit/core/error.h"
#include "robust_detail.h"

namespace ptmkit::fit {

using internal::Packed;
using internal::packed_outer;
using internal::unpack_symmetric;
using internal::Vec6;

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
  if (!(keep_within_fraction >= 0.0) || !std::isfinite(keep_within_fraction)) {
    return "keep_within_fraction must be finite and >= 0 (0 = off)";
  }
  return {};
}

void TexelSolver::Impl::residuals(const double* value, const Vec6& c) {
  for (int i = 0; i < n; ++i)
    resid[static_cast<std::size_t>(i)] = value[i] - basis[static_cast<std::size_t>(i)].dot(c);
}

// Robust scale of the residuals where mask (if given) says inlier.
double TexelSolver::Impl::scale(const SampleLabel* labels) {
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

bool TexelSolver::Impl::factor(const double* weights) {
  if (llt_ok && !llt_weights.empty() &&
      std::memcmp(llt_weights.data(), weights, sizeof(double) * static_cast<std::size_t>(n)) == 0) {
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

bool TexelSolver::Impl::weighted(const double* value, const double* weights, Vec6* c) {
  if (!factor(weights)) return false;
  Vec6 rhs = Vec6::Zero();
  for (int i = 0; i < n; ++i) {
    if (weights[i] > 0.0) rhs += (weights[i] * value[i]) * basis[static_cast<std::size_t>(i)];
  }
  *c = llt.solve(rhs);
  return c->allFinite();
}

void TexelSolver::Impl::label_symmetric(double s, SampleLabel* labels) const {
  for (int i = 0; i < n; ++i) {
    const double r = resid[static_cast<std::size_t>(i)];
    labels[i] = r < -opt.label_k * s  ? SampleLabel::kShadow
                : r > opt.label_k * s ? SampleLabel::kHighlight
                                      : SampleLabel::kInlier;
  }
}

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
