// Robust per-texel solvers through Ceres (Huber, Cauchy, Tukey losses): one problem built
// per solver and reused for every texel, warm-started from least squares; the loss's weights
// then serve every channel's weighted fit.
#include <algorithm>
#include <memory>

#include <ceres/ceres.h>

#include "ptmkit/core/coefficients.h"
#include "ptmkit/fit/robust.h"
#include "robust_detail.h"

namespace ptmkit::fit {

using internal::Vec6;

namespace {

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

void TexelSolver::Impl::build_ceres() {
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

ceres::LossFunction* TexelSolver::Impl::make_loss(double width) const {
  switch (solver) {
    case Solver::kCeresCauchy:
      return new ceres::CauchyLoss(width);
    case Solver::kCeresTukey:
      return new ceres::TukeyLoss(width);
    default:
      return new ceres::HuberLoss(width);
  }
}

TexelOutcome TexelSolver::Impl::solve_ceres(const double* value, double* weights,
                                            SampleLabel* labels, Vec6* c) {
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

}  // namespace ptmkit::fit
