// Circles of calibration spheres in images: the least-squares circle fit, circles from a
// mask, and detection in a stack (Hough circles on the brightest-of-all composite, refined on
// sub-pixel edges along rays).
#include <algorithm>
#include <cmath>
#include <numbers>
#include <string>

#include <Eigen/Cholesky>
#include <Eigen/QR>
#include <opencv2/imgproc.hpp>

#include "ptmkit/calib/sphere.h"
#include "ptmkit/core/error.h"
#include "sphere_detail.h"

namespace ptmkit::calib {

namespace detail {

Circle fit_circle(const std::vector<Eigen::Vector2d>& pts, std::vector<Eigen::Vector2d>* inliers) {
  if (pts.size() < 5) throw Error("too few edge points to fit a circle");
  Eigen::MatrixXd a(static_cast<Eigen::Index>(pts.size()), 3);
  Eigen::VectorXd b(static_cast<Eigen::Index>(pts.size()));
  for (std::size_t i = 0; i < pts.size(); ++i) {
    const auto k = static_cast<Eigen::Index>(i);
    a(k, 0) = pts[i].x();
    a(k, 1) = pts[i].y();
    a(k, 2) = 1.0;
    b(k) = -(pts[i].squaredNorm());
  }
  const Eigen::Vector3d s = a.colPivHouseholderQr().solve(b);
  Circle c;
  c.centre_px = {-s(0) / 2.0, -s(1) / 2.0};
  c.radius_px = std::sqrt(std::max(1e-12, c.centre_px.squaredNorm() - s(2)));
  std::vector<Eigen::Vector2d> use = pts;
  for (int round = 0; round < 2; ++round) {
    for (int it = 0; it < 20; ++it) {
      Eigen::Matrix3d jtj = Eigen::Matrix3d::Zero();
      Eigen::Vector3d jtr = Eigen::Vector3d::Zero();
      for (const auto& p : use) {
        const Eigen::Vector2d d = p - c.centre_px;
        const double len = std::max(d.norm(), 1e-12);
        const double r = len - c.radius_px;
        const Eigen::Vector3d j(-d.x() / len, -d.y() / len, -1.0);
        jtj += j * j.transpose();
        jtr += j * r;
      }
      const Eigen::Vector3d step = jtj.ldlt().solve(-jtr);
      c.centre_px += step.head<2>();
      c.radius_px += step(2);
      if (step.norm() < 1e-10) break;
    }
    if (round == 1) break;
    std::vector<double> res;
    for (const auto& p : use) res.push_back(std::abs((p - c.centre_px).norm() - c.radius_px));
    std::vector<double> sorted = res;
    const double limit = std::max(3.0 * 1.4826 * upper_median(sorted), 0.05);
    std::vector<Eigen::Vector2d> kept;
    for (std::size_t i = 0; i < use.size(); ++i) {
      if (res[i] <= limit) kept.push_back(use[i]);
    }
    if (kept.size() < 5) break;
    use = std::move(kept);
  }
  if (!(c.radius_px > 1.0) || !c.centre_px.allFinite()) throw Error("circle fit failed");
  if (inliers != nullptr) *inliers = std::move(use);
  return c;
}

Eigen::Vector2d fit_circle_centre(const std::vector<Eigen::Vector2d>& pts, double radius_px,
                                  const Eigen::Vector2d& start) {
  Eigen::Vector2d c = start;
  for (int it = 0; it < 20; ++it) {
    Eigen::Matrix2d jtj = Eigen::Matrix2d::Zero();
    Eigen::Vector2d jtr = Eigen::Vector2d::Zero();
    for (const Eigen::Vector2d& p : pts) {
      const Eigen::Vector2d d = p - c;
      const double len = std::max(d.norm(), 1e-9);
      const Eigen::Vector2d j = -d / len;
      jtj += j * j.transpose();
      jtr += j * (len - radius_px);
    }
    const Eigen::Vector2d step = jtj.ldlt().solve(-jtr);
    if (!step.allFinite()) break;
    c += step;
    if (step.norm() < 1e-8) break;
  }
  return c;
}

}  // namespace detail
namespace {

using detail::fit_circle;
using detail::luma_at;

double bilinear(const cv::Mat& m, double x, double y) {
  double v = 0.0;
  return detail::bilinear_at(m, x, y, &v) ? v : 0.0;
}

}  // namespace

Circle circle_from_mask(ConstImageViewF mask) {
  if (mask.empty()) throw Error("sphere mask is empty");
  std::vector<Eigen::Vector2d> pts;
  auto inside = [&](int x, int y) { return luma_at(mask, x, y) > 0.5; };
  for (int y = 0; y < mask.height; ++y) {
    for (int x = 0; x < mask.width; ++x) {
      const bool in = inside(x, y);
      if (x + 1 < mask.width && in != inside(x + 1, y)) pts.emplace_back(x + 0.5, y);
      if (y + 1 < mask.height && in != inside(x, y + 1)) pts.emplace_back(x, y + 0.5);
    }
  }
  if (pts.size() < 12)
    throw Error("sphere mask has no usable region (pixels > 0.5 are the sphere)");
  std::vector<Eigen::Vector2d> kept;
  Circle c = fit_circle(pts, &kept);
  c.outline_px = std::move(kept);
  return c;
}

namespace {

cv::Mat max_composite(const std::vector<Image>& images) {
  if (images.empty()) throw Error("find sphere: no images");
  const int w = images[0].width(), h = images[0].height();
  cv::Mat composite(h, w, CV_32F, cv::Scalar(0.0f));
  for (const Image& img : images) {
    for (int y = 0; y < h; ++y) {
      float* out = composite.ptr<float>(y);
      for (int x = 0; x < w; ++x) {
        out[x] = std::max(out[x], static_cast<float>(luma_at(img.view(), x, y)));
      }
    }
  }
  return composite;
}

std::vector<cv::Vec3f> hough_circles(const cv::Mat& composite) {
  cv::Mat grey8;
  composite.convertTo(grey8, CV_8U, 255.0);
  cv::GaussianBlur(grey8, grey8, cv::Size(5, 5), 1.5);
  std::vector<cv::Vec3f> circles;
  const int min_side = std::min(composite.cols, composite.rows);
  cv::HoughCircles(grey8, circles, cv::HOUGH_GRADIENT, 1.0, min_side / 4.0, 100.0, 30.0,
                   std::max(8, min_side / 20), min_side / 2);
  return circles;
}

}  // namespace

namespace detail {

Circle refine_circle(const Circle& rough, const cv::Mat& composite) {
  const int w = composite.cols, h = composite.rows;
  cv::Mat smooth;
  cv::GaussianBlur(composite, smooth, cv::Size(0, 0), 1.0);
  std::vector<Eigen::Vector2d> edge;
  std::vector<double> strength;
  constexpr int kRays = 720;
  for (int k = 0; k < kRays; ++k) {
    const double a = 2.0 * std::numbers::pi * k / kRays;
    const Eigen::Vector2d dir(std::cos(a), std::sin(a));
    double best = 0.0, best_r = 0.0;
    std::vector<double> prof;
    const double r0 = 0.85 * rough.radius_px, r1 = 1.15 * rough.radius_px, dr = 0.25;
    bool inside_image = true;
    for (double r = r0; r <= r1; r += dr) {
      const Eigen::Vector2d p = rough.centre_px + r * dir;
      // A ray that leaves the image (a cropped sphere) has no edge to measure.
      if (p.x() < 1.0 || p.y() < 1.0 || p.x() > w - 2.0 || p.y() > h - 2.0) {
        inside_image = false;
        break;
      }
      prof.push_back(bilinear(smooth, p.x(), p.y()));
    }
    if (!inside_image) continue;
    for (std::size_t i = 1; i + 1 < prof.size(); ++i) {
      const double g = std::abs(prof[i + 1] - prof[i - 1]);
      if (g > best) {
        // Parabolic sub-sample peak of |gradient|.
        const double gm = std::abs(prof[i] - (i >= 2 ? prof[i - 2] : prof[i - 1]));
        const double gp = std::abs((i + 2 < prof.size() ? prof[i + 2] : prof[i + 1]) - prof[i]);
        const double den = gm - 2.0 * g + gp;
        const double off =
            std::abs(den) > 1e-12 ? std::clamp(0.5 * (gm - gp) / den, -0.5, 0.5) : 0.0;
        best = g;
        best_r = r0 + (static_cast<double>(i) + off) * dr;
      }
    }
    if (best > 0.0) {
      edge.push_back(rough.centre_px + best_r * dir);
      strength.push_back(best);
    }
  }
  if (edge.size() < 20) return rough;
  std::vector<double> sorted = strength;
  const double median = upper_median(sorted);
  std::vector<Eigen::Vector2d> strong;
  for (std::size_t i = 0; i < edge.size(); ++i) {
    if (strength[i] >= 0.3 * median) strong.push_back(edge[i]);
  }
  std::vector<Eigen::Vector2d> kept;
  Circle c = fit_circle(strong, &kept);
  c.outline_px = std::move(kept);
  return c;
}

}  // namespace detail

namespace {
using detail::refine_circle;
}  // namespace

Circle find_sphere(const std::vector<Image>& images) {
  const cv::Mat composite = max_composite(images);
  const std::vector<cv::Vec3f> circles = hough_circles(composite);
  if (circles.empty()) {
    throw Error(
        "no sphere found in the images: give its circle with --sphere cx,cy,r (pixels) "
        "or a mask with --mask");
  }
  Circle rough;
  rough.centre_px = {circles[0][0], circles[0][1]};
  rough.radius_px = circles[0][2];
  return refine_circle(rough, composite);
}

std::vector<Circle> find_spheres(const std::vector<Image>& images, int count) {
  if (count < 1) throw Error("find spheres: the count must be at least 1");
  if (count == 1) return {find_sphere(images)};
  const cv::Mat composite = max_composite(images);
  const std::vector<cv::Vec3f> circles = hough_circles(composite);
  std::vector<Circle> out;
  for (const cv::Vec3f& c : circles) {  // strongest first
    Circle rough;
    rough.centre_px = {c[0], c[1]};
    rough.radius_px = c[2];
    const bool overlaps = std::any_of(out.begin(), out.end(), [&](const Circle& o) {
      return (o.centre_px - rough.centre_px).norm() < o.radius_px + rough.radius_px;
    });
    if (overlaps) continue;
    out.push_back(refine_circle(rough, composite));
    if (static_cast<int>(out.size()) == count) break;
  }
  if (static_cast<int>(out.size()) < count) {
    throw Error("found " + std::to_string(out.size()) + " of " + std::to_string(count) +
                " spheres in the images: give each circle with --sphere cx,cy,r (pixels), "
                "once per sphere");
  }
  std::sort(out.begin(), out.end(), [](const Circle& a, const Circle& b) {
    if (std::abs(a.centre_px.x() - b.centre_px.x()) > 0.5 * std::min(a.radius_px, b.radius_px)) {
      return a.centre_px.x() < b.centre_px.x();
    }
    return a.centre_px.y() < b.centre_px.y();
  });
  return out;
}

}  // namespace ptmkit::calib
