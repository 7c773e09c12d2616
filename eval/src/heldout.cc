#include "ptmkit/eval/heldout.h"

#include <algorithm>
#include <vector>

#include "ptmkit/core/colour.h"
#include "ptmkit/core/error.h"
#include "ptmkit/core/holdout.h"
#include "ptmkit/eval/ssim.h"

namespace ptmkit::eval {

void HeldOutScore::add(const CoefficientMap& fit, const Eigen::Vector3d& dir, const Image& observed,
                       bool integer_range, bool with_ssim) {
  add_rows(fit, dir, observed, integer_range, with_ssim, 0, fit.height);
}

void HeldOutScore::add_rows(const CoefficientMap& fit, const Eigen::Vector3d& dir,
                            const Image& observed, bool integer_range, bool with_ssim,
                            int first_row, int last_row) {
  const int w = fit.width;
  const int h = fit.height;
  if (observed.width() != w || observed.height() != h) {
    throw Error("held-out image is " + std::to_string(observed.width()) + "x" +
                std::to_string(observed.height()) + ", the fit " + std::to_string(w) + "x" +
                std::to_string(h));
  }
  const int ch = std::min(observed.channels(), 3);
  const Eigen::Vector3d l = dir.normalized();
  std::vector<double> pl, ol;
  if (with_ssim) {
    pl.resize(static_cast<std::size_t>(w) * h);
    ol.resize(pl.size());
  }
  for (int y = 0; y < h; ++y) {
    for (int x = 0; x < w; ++x) {
      float rgb[3];
      fit.evaluate(x, y, l.x(), l.y(), rgb);
      double p[3], o[3];
      for (int c = 0; c < 3; ++c) {
        p[c] = std::max(0.0, static_cast<double>(rgb[c]));
        if (integer_range) p[c] = std::min(p[c], 1.0);
        o[c] = observed.at(x, y, std::min(c, observed.channels() - 1));
      }
      if (y >= first_row && y < last_row) {
        for (int c = 0; c < ch; ++c) {
          sum_sq_ += (p[c] - o[c]) * (p[c] - o[c]);
          ++samples_;
        }
      }
      if (with_ssim) {
        const auto i = static_cast<std::size_t>(y) * w + x;
        pl[i] = ch == 3 ? luma(p[0], p[1], p[2]) : p[0];
        ol[i] = ch == 3 ? luma(o[0], o[1], o[2]) : o[0];
      }
    }
  }
  if (with_ssim) {
    ssim_sum_ += eval::ssim_sum(pl, ol, w, h, first_row, last_row);
    ssim_pixels_ +=
        static_cast<std::uint64_t>(last_row - first_row) * static_cast<std::uint64_t>(w);
  }
}

double HeldOutScore::psnr_db() const {
  if (samples_ == 0) return 0.0;
  return ptmkit::psnr_db(sum_sq_ / static_cast<double>(samples_));
}

double HeldOutScore::mean_ssim() const {
  return ssim_pixels_ > 0 ? ssim_sum_ / static_cast<double>(ssim_pixels_) : 0.0;
}

}  // namespace ptmkit::eval
