#include "ptmkit/texture/metrics.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <string>
#include <vector>

#include "ptmkit/core/colour.h"
#include "ptmkit/core/error.h"
#include "ptmkit/core/holdout.h"

namespace ptmkit::texture {

ImageComparison compare_images(ConstImageViewF test, ConstImageViewF reference,
                               const ConstImageViewF* mask) {
  if (test.width != reference.width || test.height != reference.height) {
    throw Error("size " + std::to_string(reference.width) + " x " +
                std::to_string(reference.height) + " differs from the relit image's " +
                std::to_string(test.width) + " x " + std::to_string(test.height));
  }
  const bool luma_only = reference.channels == 1 && test.channels == 3;
  const bool same = reference.channels == test.channels || reference.channels == test.channels + 1;
  if (!luma_only && !same) {
    throw Error(std::to_string(reference.channels) + " channels cannot be compared with " +
                std::to_string(test.channels));
  }
  if (test.colour_space != reference.colour_space) {
    throw Error("colour space " + std::string(to_string(reference.colour_space)) +
                " differs from the relit image's " + std::string(to_string(test.colour_space)));
  }
  if (mask != nullptr &&
      (mask->width != test.width || mask->height != test.height || mask->channels < 1)) {
    throw Error("the mask's size " + std::to_string(mask->width) + " x " +
                std::to_string(mask->height) + " differs from the image's");
  }
  const int channels = luma_only ? 1 : test.channels;
  // Rows are summed separately and combined in order: the result does not depend on threads
  // (this runs serially, but keeps the same shape as the parallel code elsewhere).
  double sum_abs = 0.0, sum_sq = 0.0, max_abs = 0.0;
  std::size_t pixels = 0;
  for (int y = 0; y < test.height; ++y) {
    for (int x = 0; x < test.width; ++x) {
      if (mask != nullptr && !(mask->at(x, y, 0) > 0.5f)) continue;
      ++pixels;
      for (int c = 0; c < channels; ++c) {
        const double t = luma_only ? luma(test.at(x, y, 0), test.at(x, y, 1), test.at(x, y, 2))
                                   : static_cast<double>(test.at(x, y, c));
        const double d = std::abs(t - static_cast<double>(reference.at(x, y, c)));
        sum_abs += d;
        sum_sq += d * d;
        max_abs = std::max(max_abs, d);
      }
    }
  }
  if (pixels == 0) throw Error("no pixel to compare (the mask is empty)");
  ImageComparison r;
  const double n = static_cast<double>(pixels) * channels;
  r.pixels = pixels;
  r.channels = channels;
  r.mean_abs = sum_abs / n;
  r.mean_abs_grey = 255.0 * r.mean_abs;
  r.max_abs = max_abs;
  const double mse = sum_sq / n;
  r.rmse = std::sqrt(mse);
  r.psnr_db = psnr_db(mse);
  return r;
}

}  // namespace ptmkit::texture
