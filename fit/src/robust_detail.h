// Internal to fit: the per-texel robust solver's state (TexelSolver::Impl) and the packed
// normal-matrix helpers its units share. The Impl's members are defined in:
//   robust.cc          solver names and options, the driver (TexelSolver) and the weighted
//                      least-squares core (residuals, robust scale, cached Cholesky)
//   robust_trim.cc     trimming, sign-aware and Lambertian labelling, quantile trimming,
//                      re-admission, IRLS
//   robust_lambert.cc  the Lambertian model: its fit, residuals, keep-close and fill steps
//   robust_ceres.cc    the Ceres M-estimators
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <vector>

#include <ceres/ceres.h>
#include <Eigen/Cholesky>

#include "ptmkit/core/coefficients.h"
#include "ptmkit/fit/robust.h"

namespace ptmkit::fit {

namespace internal {

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

}  // namespace internal

struct TexelSolver::Impl {
  using Vec6 = internal::Vec6;

  Solver solver;
  RobustOptions opt;
  int n = 0;
  std::vector<Vec6> basis;                                // rows of the design
  std::vector<internal::Packed<kPtmTerms>> outer;         // b b^T per light
  std::vector<Eigen::Vector4d> lambert_rows;              // (lx, ly, lz, 1) per light
  std::vector<internal::Packed<4>> lambert_outer;         // q q^T per light
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
  Eigen::LLT<internal::Mat6> llt;
  bool llt_ok = false;
  // Ceres, built once and reused for every texel: the residual blocks read value_copy.
  std::unique_ptr<ceres::Problem> problem;
  ceres::LossFunctionWrapper* loss = nullptr;  // owned by loss_owner
  std::unique_ptr<ceres::LossFunctionWrapper> loss_owner;
  std::array<double, kPtmTerms> params{};
  ceres::Solver::Options ceres_options;

  // robust.cc: the weighted least-squares core.
  void residuals(const double* value, const Vec6& c);
  double scale(const SampleLabel* labels);
  bool factor(const double* weights);
  bool weighted(const double* value, const double* weights, Vec6* c);
  void label_symmetric(double s, SampleLabel* labels) const;

  // robust_trim.cc: trimming and the solvers built on it, IRLS.
  int count_inliers(const SampleLabel* labels) const;
  static void to_weights(const SampleLabel* labels, int count, double* weights);
  void trim(const double* value, const std::uint8_t* saturated, SampleLabel* labels);
  bool fit_kept(const double* value, double* weights, SampleLabel* labels, Vec6* c);
  TexelOutcome solve_trim_sign(const double* value, const std::uint8_t* saturated, double* weights,
                               SampleLabel* labels, Vec6* c);
  void quantile_trim(const double* value, const std::uint8_t* saturated, SampleLabel* labels);
  TexelOutcome solve_quantile(const double* value, const std::uint8_t* saturated, double* weights,
                              SampleLabel* labels, Vec6* c);
  void readmit(const double* value, const std::uint8_t* saturated, double* weights,
               SampleLabel* labels, Vec6* c);
  double irls_weight(double u) const;
  TexelOutcome solve_irls(const double* value, double* weights, SampleLabel* labels, Vec6* c);

  // robust_lambert.cc: the Lambertian model (lambert_fit is a template used there only).
  void keep_close(const double* value, const std::uint8_t* saturated, double* weights,
                  SampleLabel* labels);
  template <typename Include>
  bool lambert_fit(const double* value, Include include, Eigen::Vector4d* g);
  double lambert_shade(int i, const Eigen::Vector4d& g) const;
  bool lambert_residuals(const double* value, const SampleLabel* labels);
  bool lambert_explains(const double* value, const double* weights, const Vec6& c);
  bool filled(const double* value, const double* weights, Vec6* c);

  // robust_ceres.cc: the Ceres M-estimators.
  void build_ceres();
  ceres::LossFunction* make_loss(double width) const;
  TexelOutcome solve_ceres(const double* value, double* weights, SampleLabel* labels, Vec6* c);
};

}  // namespace ptmkit::fit
