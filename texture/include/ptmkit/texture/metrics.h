// Comparing a relit image with a photograph (or any two images of the same size).
#pragma once

#include <cstddef>

#include "ptmkit/core/image.h"

namespace ptmkit::texture {

struct ImageComparison {
  // PSNR with peak 1.0 in normalised units (full scale, as for 8-bit images); +inf when the
  // images are identical.
  double psnr_db = 0.0;
  double mean_abs = 0.0;       // normalised units
  double mean_abs_grey = 0.0;  // the same in grey levels (1/255 of full scale)
  double max_abs = 0.0;        // normalised units
  double rmse = 0.0;           // normalised units
  std::size_t pixels = 0;      // pixels compared (inside the mask)
  int channels = 0;            // channels compared per pixel
};

// Compares `test` with `reference` over the pixels where `mask` (if given: one channel, or
// its first channel, same size) is > 0.5. Channels: equal counts are compared channel by
// channel; a reference with one channel more (alpha) ignores it; a one-channel reference
// against a three-channel test compares the test's Rec. 601 luma. Values are taken as they
// are (not clamped). Throws ptmkit::Error (without a file name: the caller adds it) on
// different sizes, incompatible channels, different colour spaces, or an empty mask.
[[nodiscard]] ImageComparison compare_images(ConstImageViewF test, ConstImageViewF reference,
                                             const ConstImageViewF* mask = nullptr);

}  // namespace ptmkit::texture
