// Held-out evaluation: how well a fit predicts photographs taken under lights it did not
// see. Predictions are clamped to what a viewer shows: [0, 1] for integer files, >= 0 for
// float files. PSNR (core/holdout.h, peak 1.0) over every held-out sample and channel; SSIM
// (ssim.h) on Rec. 601 luma, averaged over the held-out images.
#pragma once

#include <cstdint>

#include <Eigen/Core>

#include "ptmkit/core/coefficients.h"
#include "ptmkit/core/image.h"

namespace ptmkit::eval {

// Sums over the held-out images scored so far.
class HeldOutScore {
 public:
  // Predicts `fit` at light `dir` (normalised here) and scores it against `observed` (same
  // size; its first three channels, a grey image's one). `integer_range`: clamp the
  // prediction to [0, 1] (integer files) rather than only to >= 0. `with_ssim`: also the
  // image's SSIM.
  void add(const CoefficientMap& fit, const Eigen::Vector3d& dir, const Image& observed,
           bool integer_range, bool with_ssim);
  // The same for rows [first_row, last_row) of `fit` and `observed`, a band of a capture
  // scored band by band: only those rows count. With SSIM, the rows within the window's radius
  // around them (ssim_sum) must be in the band too, except at the capture's top and bottom.
  void add_rows(const CoefficientMap& fit, const Eigen::Vector3d& dir, const Image& observed,
                bool integer_range, bool with_ssim, int first_row, int last_row);

  // 0 when nothing was scored, +inf for a perfect prediction.
  [[nodiscard]] double psnr_db() const;
  // Mean SSIM of the images scored with SSIM (over all their pixels); 0 when none.
  [[nodiscard]] double mean_ssim() const;
  [[nodiscard]] std::uint64_t samples() const { return samples_; }

 private:
  double sum_sq_ = 0.0;
  std::uint64_t samples_ = 0;
  double ssim_sum_ = 0.0;          // the SSIM maps' values, summed
  std::uint64_t ssim_pixels_ = 0;  // and their count
};

}  // namespace ptmkit::eval
