// What every held-out evaluation shares, whatever stage runs it: the k-fold split of a
// capture's lights and PSNR. Model selection (fit), the solver comparison (eval) and the
// relighting reports (texture) all use these, so their figures are defined once.
#pragma once

#include <vector>

namespace ptmkit {

// PSNR in dB of a mean squared error: 10 log10(peak^2 / mse). `peak` is full scale in the
// units of `mse` (1.0 for normalised values, 255 for grey levels). +inf when mse is 0.
[[nodiscard]] double psnr_db(double mse, double peak = 1.0);

// One fold of a k-fold split: the indices fitted on and the indices held out, ascending.
struct Fold {
  std::vector<int> train;
  std::vector<int> test;
};

// K folds over n items (lights): item i is held out in fold i mod K, so each item is held
// out exactly once and neighbours in a ring layout fall into different folds. Throws
// ptmkit::Error when folds < 2 or folds > n.
[[nodiscard]] std::vector<Fold> kfold_splits(int n, int folds);

}  // namespace ptmkit
