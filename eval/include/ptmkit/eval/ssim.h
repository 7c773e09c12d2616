// Structural similarity (SSIM) of two single-channel images.
#pragma once

#include <vector>

namespace ptmkit::eval {

// Mean SSIM of images a and b (w x h, row-major, peak 1.0): local means, variances and
// covariance under an 11 x 11 Gaussian window (sigma 1.5, weights renormalised at the
// border), constants C1 = 0.01^2 and C2 = 0.03^2, averaged over every pixel. 1 for identical
// images; 0 for empty ones.
[[nodiscard]] double mean_ssim(const std::vector<double>& a, const std::vector<double>& b, int w,
                               int h);

// The SSIM map of a and b (w x h) summed over rows [first_row, last_row). A band of a larger
// image scores exactly as the whole image would when it carries the 5 rows of the window's
// radius above and below the rows scored (fewer only at the image's own top and bottom).
[[nodiscard]] double ssim_sum(const std::vector<double>& a, const std::vector<double>& b, int w,
                              int h, int first_row, int last_row);

}  // namespace ptmkit::eval
