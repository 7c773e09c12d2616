#include "basis_rows.h"

#include <algorithm>

#include "ptmkit/core/colour.h"

namespace ptmkit::fit::internal {

void BasisRowFitter::fit_row(const StackBand& band, int r, float* c_out, float* /*col_out*/,
                             RowStats* st) const {
  const int n = band.images;
  const int t = basis_terms(design_.basis);
  const int ch = channels_;
  const bool lum = options_.model == ColourModel::kLRGB || ch != 3;
  Eigen::VectorXd v(n), c(t), pred(n);
  Eigen::MatrixXd rgb(n, 3);
  for (int x = 0; x < width_; ++x) {
    float* dst = c_out + static_cast<std::size_t>(x) * 3 * t;
    for (int i = 0; i < n; ++i) {
      for (int k = 0; k < 3; ++k) rgb(i, k) = band.sample(i, r, x, ch == 3 ? k : 0);
    }
    if (lum) {
      LrgbSums sums;
      for (int i = 0; i < n; ++i) {
        v(i) = ch == 3 ? luma(rgb(i, 0), rgb(i, 1), rgb(i, 2)) : rgb(i, 0);
        sums.add(1.0, v(i), rgb(i, 0), rgb(i, 1), rgb(i, 2));
      }
      c.noalias() = design_.pseudo_inverse * v;
      // The least-squares colour of the LRGB model, multiplied out; grey input gives (1, 1, 1).
      for (int k = 0; k < 3; ++k) {
        const double kc = sums.factor(k);
        for (int j = 0; j < t; ++j) dst[k * t + j] = static_cast<float>(kc * c(j));
      }
    } else {
      for (int k = 0; k < 3; ++k) {
        c.noalias() = design_.pseudo_inverse * rgb.col(k);
        for (int j = 0; j < t; ++j) dst[k * t + j] = static_cast<float>(c(j));
      }
    }
    if (!st->active) continue;
    for (int k = 0; k < ch; ++k) {
      for (int j = 0; j < t; ++j) c(j) = dst[k * t + j];
      pred.noalias() = design_.design * c;
      for (int i = 0; i < n; ++i) st->add(255.0 * (rgb(i, k) - pred(i)));
    }
  }
}

}  // namespace ptmkit::fit::internal
