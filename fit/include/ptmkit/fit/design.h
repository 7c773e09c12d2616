// The least-squares design of a light set: the N x 6 matrix A of the biquadratic's basis at
// each light's (lu, lv), its conditioning, and the shared 6 x N pseudo-inverse that fits every
// texel with one matrix product (distant lights: every texel sees the same directions).
#pragma once

#include <string>
#include <vector>

#include <Eigen/Core>

namespace ptmkit::fit {

// How the shared pseudo-inverse is computed. Cholesky of A^T A squares the condition number;
// QR and SVD of A do not (they matter only for badly conditioned layouts, cond(A) > ~1e3).
enum class PinvMethod { kCholesky, kQR, kSVD };

struct DesignOptions {
  // Refuse a design whose condition number cond(A) (ratio of largest to smallest singular
  // value) exceeds this. cond(A^T A) = cond(A)^2 is what the normal equations see; in double
  // precision 1e5 still leaves about 6 significant digits. A single elevation ring is exactly
  // rank-deficient (cond ~1e16) and always refused unless ridge_lambda > 0.
  double max_condition = 1e5;
  // Tikhonov regularisation weight, relative to the number of lights: P = (A^T A +
  // ridge_lambda * N * I)^-1 A^T. 0 (default) is the paper's plain fit. About 1e-3 is a
  // common choice; it makes rank-deficient layouts solvable, at the cost of bias.
  double ridge_lambda = 0.0;
  // Cholesky (default, the seed paper's normal equations), QR or SVD of A. With ridge_lambda
  // > 0 the augmented system [A; sqrt(lambda N) I] is factored the same way.
  PinvMethod method = PinvMethod::kCholesky;
};

// What is known about a light layout before any pixel is read.
struct DesignReport {
  int lights = 0;
  double condition_number = 0.0;  // cond(A), from the SVD; inf when rank-deficient
  double smallest_singular = 0.0;
  double largest_singular = 0.0;
  double min_elevation_deg = 0.0;
  double max_elevation_deg = 0.0;
  bool single_ring = false;  // every light at the same elevation
  bool regularised = false;  // ridge_lambda > 0 was applied
  // Empty when the design can be fitted; otherwise why not and what would fix it.
  std::string problem;
};

// Checks a layout without building anything: the rules that build() enforces.
[[nodiscard]] DesignReport analyse_design(const std::vector<Eigen::Vector3d>& light_dirs,
                                          const DesignOptions& options = {});

class LightDesign {
 public:
  // (lu, lv) of each light are the x and y of its unit direction (flat sample, camera
  // overhead). Throws ptmkit::Error with the DesignReport's problem when the layout cannot be
  // fitted: fewer than 6 lights, a single ring, or cond(A) above the limit.
  static LightDesign build(const std::vector<Eigen::Vector3d>& light_dirs,
                           const DesignOptions& options = {});

  [[nodiscard]] int lights() const { return static_cast<int>(design_.rows()); }
  [[nodiscard]] const DesignReport& report() const { return report_; }
  // N x 6, rows are ptm_basis(lu_i, lv_i).
  [[nodiscard]] const Eigen::MatrixXd& design() const { return design_; }
  // 6 x N: (A^T A + lambda N I)^-1 A^T, built in double by Cholesky of the normal matrix
  // (the seed paper's normal equations), or by QR or SVD of A (DesignOptions::method).
  [[nodiscard]] const Eigen::MatrixXd& pseudo_inverse() const { return pinv_; }
  [[nodiscard]] const Eigen::MatrixXf& pseudo_inverse_f() const { return pinv_f_; }

  // One texel: N samples in, six coefficients out, in double.
  void solve(const double* samples, double* coeffs) const;

 private:
  Eigen::MatrixXd design_;
  Eigen::MatrixXd pinv_;
  Eigen::MatrixXf pinv_f_;
  DesignReport report_;
};

}  // namespace ptmkit::fit
