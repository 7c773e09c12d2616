#include "ptmkit/fit/design.h"

#include <cmath>
#include <limits>
#include <sstream>

#include <Eigen/Cholesky>
#include <Eigen/QR>
#include <Eigen/SVD>

#include "ptmkit/core/coefficients.h"
#include "ptmkit/core/error.h"
#include "ptmkit/core/light_set.h"

namespace ptmkit::fit {

namespace {

Eigen::MatrixXd basis_matrix(const std::vector<Eigen::Vector3d>& dirs) {
  Eigen::MatrixXd a(static_cast<Eigen::Index>(dirs.size()), kPtmTerms);
  for (std::size_t i = 0; i < dirs.size(); ++i) {
    const Eigen::Vector3d u = dirs[i].normalized();
    const auto b = ptm_basis(u.x(), u.y());
    for (int k = 0; k < kPtmTerms; ++k) a(static_cast<Eigen::Index>(i), k) = b[k];
  }
  return a;
}

std::string fmt(double v) {
  std::ostringstream s;
  s.precision(3);
  s << v;
  return s.str();
}

}  // namespace

DesignReport analyse_design(const std::vector<Eigen::Vector3d>& dirs,
                            const DesignOptions& options) {
  DesignReport r;
  r.lights = static_cast<int>(dirs.size());
  r.regularised = options.ridge_lambda > 0.0;
  for (const auto& d : dirs) {
    if (!d.allFinite() || d.norm() < 1e-12 || d.normalized().z() <= 0.0) {
      r.problem = "a light direction is not finite or not above the sample plane (z <= 0)";
      return r;
    }
  }
  if (r.lights == 0) {
    r.problem = "no lights";
    return r;
  }
  r.min_elevation_deg = 90.0;
  r.max_elevation_deg = 0.0;
  for (const auto& d : dirs) {
    const double e = elevation_deg(d);
    r.min_elevation_deg = std::min(r.min_elevation_deg, e);
    r.max_elevation_deg = std::max(r.max_elevation_deg, e);
  }
  r.single_ring = r.max_elevation_deg - r.min_elevation_deg < 1e-6;

  if (r.lights < kPtmTerms) {
    r.problem = "only " + std::to_string(r.lights) +
                " light(s): the polynomial has 6 coefficients, so at least 6 lights are "
                "needed (more than 20, spread over elevations, give a stable fit)";
    return r;
  }
  const Eigen::MatrixXd a = basis_matrix(dirs);
  const Eigen::JacobiSVD<Eigen::MatrixXd> svd(a);
  const auto& sv = svd.singularValues();
  r.largest_singular = sv(0);
  r.smallest_singular = sv(sv.size() - 1);
  r.condition_number = r.smallest_singular > 0.0 ? r.largest_singular / r.smallest_singular
                                                 : std::numeric_limits<double>::infinity();
  if (r.regularised) return r;  // ridge makes any layout solvable; the report says so
  if (r.single_ring) {
    r.problem = "all " + std::to_string(r.lights) + " lights are at the same elevation (" +
                fmt(r.min_elevation_deg) +
                " degrees): on a single ring lu^2 + lv^2 is constant, so the lu^2, lv^2 and "
                "constant terms cannot be separated (cond(A) = " +
                fmt(r.condition_number) +
                "). Add lights at a second elevation, or fit with ridge regularisation "
                "(--ridge 1e-3) and accept a biased constant term";
    return r;
  }
  if (!(r.condition_number <= options.max_condition)) {
    r.problem = "the light layout is badly conditioned: cond(A) = " + fmt(r.condition_number) +
                " exceeds the limit " + fmt(options.max_condition) + " (lights span elevations " +
                fmt(r.min_elevation_deg) + ".." + fmt(r.max_elevation_deg) +
                " degrees). Spread the lights over more elevations and azimuths, or fit with "
                "ridge regularisation (--ridge 1e-3)";
  }
  return r;
}

LightDesign LightDesign::build(const std::vector<Eigen::Vector3d>& dirs,
                               const DesignOptions& options) {
  LightDesign d;
  d.report_ = analyse_design(dirs, options);
  if (!d.report_.problem.empty()) throw Error("cannot fit this light layout: " + d.report_.problem);
  d.design_ = basis_matrix(dirs);
  const auto n = d.design_.rows();
  if (options.method == PinvMethod::kCholesky) {
    Eigen::MatrixXd normal = d.design_.transpose() * d.design_;
    if (options.ridge_lambda > 0.0) {
      normal.diagonal().array() += options.ridge_lambda * static_cast<double>(n);
    }
    const Eigen::LLT<Eigen::MatrixXd> llt(normal);
    if (llt.info() != Eigen::Success) {
      throw Error(
          "cannot fit this light layout: the normal matrix A^T A is not positive "
          "definite (rank-deficient layout); use --ridge");
    }
    d.pinv_ = llt.solve(d.design_.transpose());
  } else {
    // Ridge as an augmented least-squares problem: [A; sqrt(lambda N) I] c = [s; 0].
    Eigen::MatrixXd aug = d.design_;
    if (options.ridge_lambda > 0.0) {
      aug.conservativeResize(n + kPtmTerms, Eigen::NoChange);
      aug.bottomRows(kPtmTerms) = Eigen::MatrixXd::Identity(kPtmTerms, kPtmTerms) *
                                  std::sqrt(options.ridge_lambda * static_cast<double>(n));
    }
    const Eigen::MatrixXd eye = Eigen::MatrixXd::Identity(aug.rows(), aug.rows());
    Eigen::MatrixXd full;
    if (options.method == PinvMethod::kQR) {
      full = aug.colPivHouseholderQr().solve(eye);
    } else {
      full = aug.jacobiSvd(Eigen::ComputeThinU | Eigen::ComputeThinV).solve(eye);
    }
    d.pinv_ = full.leftCols(n);
  }
  d.pinv_f_ = d.pinv_.cast<float>();
  return d;
}

void LightDesign::solve(const double* samples, double* coeffs) const {
  const Eigen::Map<const Eigen::VectorXd> s(samples, design_.rows());
  Eigen::Map<Eigen::Matrix<double, kPtmTerms, 1>> c(coeffs);
  c = pinv_ * s;
}

}  // namespace ptmkit::fit
