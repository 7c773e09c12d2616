// The shared least-squares operator of any basis (core/coefficients.h: Basis, basis_terms,
// evaluate_basis) on a distant-light layout. Fits in any basis run through fit_capture
// (fit.h, FitOptions::basis); this header is the design those fits and model selection share.
//
// The HSH functions are core/hsh.h's, the ones the .rti viewers evaluate.
#pragma once

#include <vector>

#include <Eigen/Core>

#include "ptmkit/core/coefficients.h"
#include "ptmkit/fit/design.h"

namespace ptmkit::fit {

using ptmkit::all_bases;
using ptmkit::Basis;
using ptmkit::basis_terms;
using ptmkit::evaluate_basis;
using ptmkit::parse_basis;
using ptmkit::to_string;
[[nodiscard]] bool is_hsh(Basis basis);

// N x terms: one row per direction.
[[nodiscard]] Eigen::MatrixXd basis_matrix(Basis basis, const std::vector<Eigen::Vector3d>& dirs);

// The shared least-squares operator of a basis on a light layout.
struct BasisDesign {
  Basis basis = Basis::kPtm;
  Eigen::MatrixXd design;          // N x T
  Eigen::MatrixXd pseudo_inverse;  // T x N, (A^T A + lambda N I)^-1 A^T by SVD
  double condition_number = 0.0;   // cond(A)

  // Throws ptmkit::Error when the layout has fewer lights than terms, or cond(A) exceeds
  // options.max_condition (and ridge_lambda is 0): the message names the basis and the fix
  // (fewer terms, more lights, or --ridge).
  static BasisDesign build(Basis basis, const std::vector<Eigen::Vector3d>& dirs,
                           const DesignOptions& options = {});
};

}  // namespace ptmkit::fit
