// A coefficient map relit at known lights against reference images: the error figures the
// near-light tests and benchmark report.
#pragma once

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <vector>

#include <Eigen/Core>

#include "ptmkit/core/coefficients.h"
#include "ptmkit/core/holdout.h"
#include "ptmkit/core/image.h"

namespace ptmkit::test {

struct RelitError {
  double rms_grey = 0.0;  // RMS of (relit - reference), grey levels (1/255)
  double p99_grey = 0.0;  // 99th percentile of |relit - reference|, grey levels
  double psnr_db = 0.0;   // peak 1.0
};

// `map` relit (unclamped) at each of `dirs` against `ref[k]` (same size, first 3 channels).
inline RelitError relit_error(const CoefficientMap& map, const std::vector<Image>& ref,
                              const std::vector<Eigen::Vector3d>& dirs) {
  double sum = 0.0;
  std::vector<double> abs_err;
  for (std::size_t k = 0; k < dirs.size(); ++k) {
    for (int y = 0; y < map.height; ++y) {
      for (int x = 0; x < map.width; ++x) {
        float rgb[3];
        map.evaluate(x, y, dirs[k].x(), dirs[k].y(), rgb);
        for (int c = 0; c < 3; ++c) {
          const double d = rgb[c] - ref[k].at(x, y, c);
          sum += d * d;
          abs_err.push_back(std::abs(d) * 255.0);
        }
      }
    }
  }
  RelitError e;
  if (abs_err.empty()) return e;
  const double mse = sum / static_cast<double>(abs_err.size());
  e.rms_grey = 255.0 * std::sqrt(mse);
  e.psnr_db = ptmkit::psnr_db(mse);
  const auto p =
      abs_err.begin() + static_cast<std::ptrdiff_t>(0.99 * static_cast<double>(abs_err.size()));
  std::nth_element(abs_err.begin(), p, abs_err.end());
  e.p99_grey = *p;
  return e;
}

}  // namespace ptmkit::test
