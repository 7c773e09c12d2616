// Residual statistics of a fit against its own samples (FitReport::residuals): per-row sums
// and a 0.05-grey-level histogram, merged in row order so the totals do not depend on the
// threads; rows sampled at a fixed step on large images.
#pragma once

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <vector>

#include "ptmkit/fit/fit.h"

namespace ptmkit::fit::internal {

// Histogram of |residual| in grey levels: 0.05-grey bins up to 256, one overflow bin.
constexpr double kHistBinsPerGrey = 20.0;
constexpr int kHistBins = 5121;

struct RowStats {
  bool active = false;  // this row is in the residual-statistics sample
  OutlierSummary outliers;
  std::uint64_t singular_texels = 0;  // near lights: normal matrix not positive definite
  double sum_sq = 0.0;
  double sum_abs = 0.0;
  double max_abs = 0.0;
  std::uint64_t count = 0;
  std::vector<std::uint32_t> hist;
  void add(double r_grey) {
    const double a = std::abs(r_grey);
    sum_sq += a * a;
    sum_abs += a;
    max_abs = std::max(max_abs, a);
    ++count;
    ++hist[bin(a)];
  }
  // n residuals at once (an image's row of a sampled row, in the shared-matrix fit). The sums
  // run in 8 lanes combined in a fixed order (the same totals whatever the threads).
  void add_all(const float* r, std::size_t n);
  // The histogram bin of |residual| a (NaN in the overflow bin).
  static std::size_t bin(double a) {
    const double b = a * kHistBinsPerGrey;
    return b < kHistBins - 1 ? static_cast<std::size_t>(b) : kHistBins - 1;
  }
};

struct StatsTotal {
  double sum_sq = 0.0, sum_abs = 0.0, max_abs = 0.0;
  std::uint64_t count = 0;
  std::vector<std::uint64_t> hist = std::vector<std::uint64_t>(kHistBins, 0);
  OutlierSummary outliers;
  std::uint64_t singular_texels = 0;
  void merge_outliers(const RowStats& r) {
    singular_texels += r.singular_texels;
    outliers.samples += r.outliers.samples;
    outliers.shadows += r.outliers.shadows;
    outliers.highlights += r.outliers.highlights;
    outliers.fallback_texels += r.outliers.fallback_texels;
    outliers.ceres_texels += r.outliers.ceres_texels;
  }
  void merge(const RowStats& r);
  [[nodiscard]] ResidualStats finish() const;
};

// Residual statistics are a summary, not a product: above 65 536 texels they use every k-th
// row (a fixed choice, so reports are reproducible), which keeps their cost off large images:
// at 2^18 texels they were still a tenth of the fit's own CPU on a 12-megapixel stack. 2^16
// texels x 49 lights x 3 channels is 9.6 million residuals.
constexpr double kResidualSampleTexels = 1 << 16;
[[nodiscard]] int residual_row_step(int width, int height);

}  // namespace ptmkit::fit::internal
