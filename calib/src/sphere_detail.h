// Shared by the sphere finders (sphere_circle.cc, sphere.cc, the streamed sphere_stack*.cc):
// circle fitting and refinement, a pixel's luma, drawings as images; not public.
#pragma once

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <vector>

#include <Eigen/Core>
#include <opencv2/core.hpp>

#include "ptmkit/calib/sphere.h"
#include "ptmkit/core/colour.h"
#include "ptmkit/core/image.h"

namespace ptmkit::calib::detail {

// The k-th smallest of v (0-based, k < v.size()); v is reordered.
template <class T>
T kth_smallest(std::vector<T>& v, std::size_t k) {
  const auto at = v.begin() + static_cast<std::ptrdiff_t>(k);
  std::nth_element(v.begin(), at, v.end());
  return *at;
}

// The upper median of a non-empty v (its element v.size() / 2 once sorted); v is reordered.
template <class T>
T upper_median(std::vector<T>& v) {
  return kth_smallest(v, v.size() / 2);
}

// Luma of pixel (x, y) of a colour image; the first channel of a grey one.
inline double luma_at(ConstImageViewF img, int x, int y) {
  const float* p = img.row(y) + static_cast<std::ptrdiff_t>(x) * img.channels;
  return img.channels >= 3 ? luma(p[0], p[1], p[2]) : p[0];
}

// Bilinear value of a CV_32F plane at (x, y); false (and *v untouched) where the 2 x 2
// neighbourhood leaves the plane.
inline bool bilinear_at(const cv::Mat& m, double x, double y, double* v) {
  const int x0 = static_cast<int>(std::floor(x)), y0 = static_cast<int>(std::floor(y));
  if (x0 < 0 || y0 < 0 || x0 + 1 >= m.cols || y0 + 1 >= m.rows) return false;
  const double fx = x - x0, fy = y - y0;
  const float* r0 = m.ptr<float>(y0);
  const float* r1 = m.ptr<float>(y0 + 1);
  *v =
      (1 - fy) * ((1 - fx) * r0[x0] + fx * r0[x0 + 1]) + fy * ((1 - fx) * r1[x0] + fx * r1[x0 + 1]);
  return true;
}

// Geometric least-squares circle through points: algebraic (Kasa) start, Gauss-Newton on
// |p - c| - r, then once more without points beyond 3 robust scales. Throws ptmkit::Error
// with fewer than 5 points or a degenerate fit.
[[nodiscard]] Circle fit_circle(const std::vector<Eigen::Vector2d>& pts,
                                std::vector<Eigen::Vector2d>* inliers = nullptr);

// The centre of the circle of the given radius nearest the points (least squares on
// |p - c| - radius), by Gauss-Newton from `start`: for an arc too short to fix its own radius.
[[nodiscard]] Eigen::Vector2d fit_circle_centre(const std::vector<Eigen::Vector2d>& pts,
                                                double radius_px, const Eigen::Vector2d& start);

// Sub-pixel edge along rays from a rough circle: the largest radial derivative of the
// composite (CV_32F) within 15% of the radius, then a trimmed geometric circle fit; rays that
// leave the image are skipped. Returns `rough` when fewer than 20 rays have an edge.
[[nodiscard]] Circle refine_circle(const Circle& rough, const cv::Mat& composite);

// An 8-bit BGR OpenCV drawing (an overlay, a plot) as an sRGB image.
[[nodiscard]] Image from_bgr8(const cv::Mat& bgr);

}  // namespace ptmkit::calib::detail
