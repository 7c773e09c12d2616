#include "ptmkit/fit/basis.h"

#include <cstdio>
#include <limits>
#include <string>

#include <Eigen/SVD>

#include "ptmkit/core/error.h"

namespace ptmkit::fit {

bool is_hsh(Basis basis) { return basis != Basis::kPtm; }

Eigen::MatrixXd basis_matrix(Basis basis, const std::vector<Eigen::Vector3d>& dirs) {
  const int t = basis_terms(basis);
  Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor> a(
      static_cast<Eigen::Index>(dirs.size()), t);
  for (std::size_t i = 0; i < dirs.size(); ++i) {
    evaluate_basis(basis, dirs[i].normalized(), a.data() + i * static_cast<std::size_t>(t));
  }
  return a;
}

BasisDesign BasisDesign::build(Basis basis, const std::vector<Eigen::Vector3d>& dirs,
                               const DesignOptions& options) {
  BasisDesign d;
  d.basis = basis;
  const int t = basis_terms(basis);
  const auto n = static_cast<int>(dirs.size());
  const std::string name(to_string(basis));
  if (n < t) {
    throw Error("basis " + name + " has " + std::to_string(t) + " terms but the layout has " +
                std::to_string(n) + " lights: use a basis with fewer terms");
  }
  d.design = basis_matrix(basis, dirs);
  const Eigen::JacobiSVD<Eigen::MatrixXd> svd(d.design, Eigen::ComputeThinU | Eigen::ComputeThinV);
  const Eigen::VectorXd sv = svd.singularValues();
  const double smallest = sv(sv.size() - 1);
  d.condition_number = smallest > 0 ? sv(0) / smallest : std::numeric_limits<double>::infinity();
  const double lambda = options.ridge_lambda * n;
  if (options.ridge_lambda <= 0 && !(d.condition_number <= options.max_condition)) {
    char buf[256];
    std::snprintf(buf, sizeof buf,
                  "basis %s: the light layout is too ill-conditioned for %d terms (cond(A) "
                  "%.3g > %.3g): use a basis with fewer terms, more lights, or --ridge",
                  name.c_str(), t, d.condition_number, options.max_condition);
    throw Error(buf);
  }
  // P = V diag(s / (s^2 + lambda)) U^T: the (ridge) least-squares solution by SVD.
  Eigen::VectorXd inv(sv.size());
  for (Eigen::Index i = 0; i < sv.size(); ++i) {
    const double den = sv(i) * sv(i) + lambda;
    inv(i) = den > 0 ? sv(i) / den : 0.0;
  }
  d.pseudo_inverse = svd.matrixV() * inv.asDiagonal() * svd.matrixU().transpose();
  return d;
}

}  // namespace ptmkit::fit
