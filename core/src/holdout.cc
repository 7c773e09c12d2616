#include "ptmkit/core/holdout.h"

#include <cmath>
#include <limits>
#include <string>

#include "ptmkit/core/error.h"

namespace ptmkit {

double psnr_db(double mse, double peak) {
  if (!(mse > 0.0)) return std::numeric_limits<double>::infinity();
  return 10.0 * std::log10(peak * peak / mse);
}

std::vector<Fold> kfold_splits(int n, int folds) {
  if (folds < 2) throw Error("folds must be at least 2, not " + std::to_string(folds));
  if (folds > n) {
    throw Error(std::to_string(folds) + " folds but only " + std::to_string(n) + " lights");
  }
  std::vector<Fold> out(static_cast<std::size_t>(folds));
  for (int i = 0; i < n; ++i) {
    for (int f = 0; f < folds; ++f) {
      auto& fold = out[static_cast<std::size_t>(f)];
      (i % folds == f ? fold.test : fold.train).push_back(i);
    }
  }
  return out;
}

}  // namespace ptmkit
