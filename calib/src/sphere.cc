#include "ptmkit/calib/sphere.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <numbers>

#include <Eigen/Cholesky>
#include <Eigen/QR>
#include <nlohmann/json.hpp>
#include <opencv2/imgproc.hpp>
#include <string>

#include "ptmkit/core/colour.h"
#include "ptmkit/core/error.h"
#include "sphere_detail.h"

namespace ptmkit::calib {

namespace {

double luma_at(ConstImageViewF img, int x, int y) {
  const float* p = img.row(y) + static_cast<std::ptrdiff_t>(x) * img.channels;
  return img.channels >= 3 ? luma(p[0], p[1], p[2]) : p[0];
}

}  // namespace

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
    std::nth_element(sorted.begin(),
                     sorted.begin() + static_cast<std::ptrdiff_t>(sorted.size() / 2), sorted.end());
    const double limit = std::max(3.0 * 1.4826 * sorted[sorted.size() / 2], 0.05);
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

}  // namespace detail

namespace {

using detail::fit_circle;

double bilinear(const cv::Mat& m, double x, double y) {
  const int x0 = static_cast<int>(std::floor(x)), y0 = static_cast<int>(std::floor(y));
  if (x0 < 0 || y0 < 0 || x0 + 1 >= m.cols || y0 + 1 >= m.rows) return 0.0;
  const double fx = x - x0, fy = y - y0;
  const float* r0 = m.ptr<float>(y0);
  const float* r1 = m.ptr<float>(y0 + 1);
  return (1 - fy) * ((1 - fx) * r0[x0] + fx * r0[x0 + 1]) +
         fy * ((1 - fx) * r1[x0] + fx * r1[x0 + 1]);
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
  std::nth_element(sorted.begin(), sorted.begin() + static_cast<std::ptrdiff_t>(sorted.size() / 2),
                   sorted.end());
  const double median = sorted[sorted.size() / 2];
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

std::string SphereOptions::validate() const {
  if (!(blob_fraction > 0.0 && blob_fraction < 1.0)) return "blob_fraction must be in (0, 1)";
  if (!(min_peak >= 0.0 && min_peak < 1.0)) return "min_peak must be in [0, 1)";
  if (!(max_blob_area_fraction > 0.0 && max_blob_area_fraction <= 1.0)) {
    return "max_blob_area_fraction must be in (0, 1]";
  }
  if (!(search_radius_fraction > 0.1 && search_radius_fraction <= 1.0)) {
    return "search_radius_fraction must be in (0.1, 1]";
  }
  if (!(camera.focal_px >= 0.0)) return "focal length must be >= 0 pixels";
  if (sphere && !(sphere->radius_px > 1.0)) return "sphere radius must be > 1 pixel";
  return {};
}

int SphereReport::usable() const {
  return static_cast<int>(
      std::count_if(lights.begin(), lights.end(), [](const SphereLight& l) { return l.found; }));
}

Eigen::Vector2d principal_point(const SphereCamera& camera, int width, int height) {
  return camera.principal_px.value_or(Eigen::Vector2d(0.5 * (width - 1), 0.5 * (height - 1)));
}

Eigen::Vector3d sphere_centre_in_camera(const Circle& sphere, const SphereCamera& camera, int width,
                                        int height) {
  if (!(camera.focal_px > 0.0)) throw Error("sphere centre in the camera: needs a focal length");
  const Eigen::Vector2d pp = principal_point(camera, width, height);
  const double f = camera.focal_px;
  auto ray = [&](const Eigen::Vector2d& px) {
    return Eigen::Vector3d((px.x() - pp.x()) / f, (px.y() - pp.y()) / f, 1.0).normalized();
  };
  // The outline's rays are the cone tangent to the sphere: e . c = cos(alpha) for the unit
  // axis c, which is linear in w = c / cos(alpha): solve e_i . w = 1 in least squares. The
  // distance to the centre is then R / sin(alpha) (R = 1).
  std::vector<Eigen::Vector2d> outline = sphere.outline_px;
  if (outline.size() < 8) {
    outline.clear();
    for (int k = 0; k < 72; ++k) {
      const double a = 2.0 * std::numbers::pi * k / 72.0;
      outline.push_back(sphere.centre_px +
                        sphere.radius_px * Eigen::Vector2d(std::cos(a), std::sin(a)));
    }
  }
  Eigen::MatrixXd e(static_cast<Eigen::Index>(outline.size()), 3);
  for (std::size_t i = 0; i < outline.size(); ++i) {
    e.row(static_cast<Eigen::Index>(i)) = ray(outline[i]).transpose();
  }
  Eigen::Vector3d wcone = e.colPivHouseholderQr().solve(Eigen::VectorXd::Ones(e.rows()));
  {
    // Once more without outline points beyond 3 robust scales.
    const Eigen::VectorXd res = (e * wcone).array() - 1.0;
    std::vector<double> a(static_cast<std::size_t>(res.size()));
    for (Eigen::Index i = 0; i < res.size(); ++i) a[static_cast<std::size_t>(i)] = std::abs(res(i));
    std::vector<double> sorted = a;
    std::nth_element(sorted.begin(),
                     sorted.begin() + static_cast<std::ptrdiff_t>(sorted.size() / 2), sorted.end());
    const double limit = 3.0 * 1.4826 * sorted[sorted.size() / 2] + 1e-12;
    std::vector<Eigen::Index> keep;
    for (Eigen::Index i = 0; i < res.size(); ++i) {
      if (a[static_cast<std::size_t>(i)] <= limit) keep.push_back(i);
    }
    if (keep.size() >= 8 && keep.size() < static_cast<std::size_t>(res.size())) {
      Eigen::MatrixXd ek(static_cast<Eigen::Index>(keep.size()), 3);
      for (std::size_t k = 0; k < keep.size(); ++k)
        ek.row(static_cast<Eigen::Index>(k)) = e.row(keep[k]);
      wcone = ek.colPivHouseholderQr().solve(Eigen::VectorXd::Ones(ek.rows()));
    }
  }
  const Eigen::Vector3d axis = wcone.normalized();
  const double cos_alpha = std::clamp(1.0 / wcone.norm(), 0.0, 1.0 - 1e-12);
  return axis / std::sqrt(1.0 - cos_alpha * cos_alpha);
}

Eigen::Vector3d reflect_highlight(const Circle& sphere, const SphereCamera& camera,
                                  const Eigen::Vector2d& h, int width, int height) {
  if (camera.focal_px <= 0.0) {
    Eigen::Vector3d n((h.x() - sphere.centre_px.x()) / sphere.radius_px,
                      -(h.y() - sphere.centre_px.y()) / sphere.radius_px, 0.0);
    n.z() = std::sqrt(std::max(0.0, 1.0 - n.x() * n.x() - n.y() * n.y()));
    n.normalize();
    const Eigen::Vector3d v(0.0, 0.0, 1.0);
    return (2.0 * n.dot(v) * n - v).normalized();
  }
  // Pinhole, camera frame x right, y down, z forward; sphere of unit radius.
  const Eigen::Vector2d pp = principal_point(camera, width, height);
  const double f = camera.focal_px;
  const Eigen::Vector3d centre = sphere_centre_in_camera(sphere, camera, width, height);
  const Eigen::Vector3d d =
      Eigen::Vector3d((h.x() - pp.x()) / f, (h.y() - pp.y()) / f, 1.0).normalized();
  const double bq = d.dot(centre);
  const double disc = bq * bq - (centre.squaredNorm() - 1.0);
  const double t = bq - std::sqrt(std::max(0.0, disc));  // near side (grazing if disc < 0)
  const Eigen::Vector3d n = (t * d - centre).normalized();
  const Eigen::Vector3d v = -d;
  const Eigen::Vector3d l_cam = (2.0 * n.dot(v) * n - v).normalized();
  return {l_cam.x(), -l_cam.y(), -l_cam.z()};
}

SphereReport calibrate_sphere(const std::vector<Image>& images,
                              const std::vector<std::filesystem::path>& names,
                              const SphereOptions& options) {
  if (const auto err = options.validate(); !err.empty()) throw Error("sphere: " + err);
  if (images.empty()) throw Error("sphere: no images");
  SphereReport report;
  report.sphere_detected = !options.sphere.has_value();
  report.sphere = options.sphere ? *options.sphere : find_sphere(images);
  const Circle& s = report.sphere;
  const int w = images[0].width(), h = images[0].height();
  const double search_r = options.search_radius_fraction * s.radius_px;
  const double sphere_area = std::numbers::pi * s.radius_px * s.radius_px;
  for (std::size_t i = 0; i < images.size(); ++i) {
    const Image& img = images[i];
    if (img.width() != w || img.height() != h) {
      throw Error(where(names.at(i)) + ": image size differs from the first image's");
    }
    SphereLight light;
    light.image = names.at(i);
    const auto view = img.view();
    const int x0 = std::max(0, static_cast<int>(std::floor(s.centre_px.x() - search_r)));
    const int x1 = std::min(w - 1, static_cast<int>(std::ceil(s.centre_px.x() + search_r)));
    const int y0 = std::max(0, static_cast<int>(std::floor(s.centre_px.y() - search_r)));
    const int y1 = std::min(h - 1, static_cast<int>(std::ceil(s.centre_px.y() + search_r)));
    auto on_sphere = [&](int x, int y) {
      return (Eigen::Vector2d(x, y) - s.centre_px).squaredNorm() <= search_r * search_r;
    };
    int px = -1, py = -1;
    double peak = -1.0;
    for (int y = y0; y <= y1; ++y) {
      for (int x = x0; x <= x1; ++x) {
        if (!on_sphere(x, y)) continue;
        const double v = luma_at(view, x, y);
        if (v > peak) {
          peak = v;
          px = x;
          py = y;
        }
      }
    }
    light.peak = std::max(0.0, peak);
    if (px < 0 || peak < options.min_peak) {
      light.flag = "no highlight on the sphere (peak " + std::to_string(light.peak) + ")";
      report.lights.push_back(light);
      continue;
    }
    // Connected blob around the peak; saturated peaks weigh every clipped pixel equally.
    light.saturated = peak >= 0.995;
    const double threshold = options.blob_fraction * peak;
    std::vector<std::uint8_t> seen(static_cast<std::size_t>(w) * h, 0);
    std::vector<std::pair<int, int>> stack{{px, py}};
    seen[static_cast<std::size_t>(py) * w + px] = 1;
    // Weighted samples (x, y, weight) that locate the highlight and give its shape.
    std::vector<Eigen::Vector3d> samples;
    while (!stack.empty()) {
      const auto [x, y] = stack.back();
      stack.pop_back();
      const double v = luma_at(view, x, y);
      const double wgt = light.saturated ? (v >= 0.995 ? 1.0 : 0.0) : v - threshold;
      samples.emplace_back(x, y, wgt);
      ++light.blob_pixels;
      const int nx[4] = {x + 1, x - 1, x, x};
      const int ny[4] = {y, y, y + 1, y - 1};
      for (int k = 0; k < 4; ++k) {
        if (nx[k] < 0 || ny[k] < 0 || nx[k] >= w || ny[k] >= h) continue;
        auto& mark = seen[static_cast<std::size_t>(ny[k]) * w + nx[k]];
        if (mark || !on_sphere(nx[k], ny[k]) || luma_at(view, nx[k], ny[k]) < threshold) continue;
        mark = 1;
        stack.emplace_back(nx[k], ny[k]);
      }
    }
    int bx0 = w, by0 = h, bx1 = -1, by1 = -1;
    for (const auto& q : samples) {
      bx0 = std::min(bx0, static_cast<int>(q.x()));
      bx1 = std::max(bx1, static_cast<int>(q.x()));
      by0 = std::min(by0, static_cast<int>(q.y()));
      by1 = std::max(by1, static_cast<int>(q.y()));
    }
    // A highlight is often only a few pixels wide, so a centroid over the blob's own pixels
    // snaps toward pixel centres. Instead: every pixel within two of the blob, weighted by its
    // brightness above the sphere's own level (the median over the search disc); for an
    // image that integrates light over each pixel this is the centroid of the highlight.
    if (!light.saturated) {
      std::vector<double> level;
      for (int y = y0; y <= y1; y += 2) {
        for (int x = x0; x <= x1; x += 2) {
          if (on_sphere(x, y)) level.push_back(luma_at(view, x, y));
        }
      }
      std::nth_element(level.begin(), level.begin() + static_cast<std::ptrdiff_t>(level.size() / 2),
                       level.end());
      const double base = level[level.size() / 2];
      samples.clear();
      for (int y = std::max(0, by0 - 2); y <= std::min(h - 1, by1 + 2); ++y) {
        for (int x = std::max(0, bx0 - 2); x <= std::min(w - 1, bx1 + 2); ++x) {
          if (!on_sphere(x, y)) continue;
          samples.emplace_back(x, y, std::max(0.0, luma_at(view, x, y) - base));
        }
      }
    }
    double sw = 0.0, sx = 0.0, sy = 0.0;
    for (const auto& q : samples) {
      sw += q.z();
      sx += q.z() * q.x();
      sy += q.z() * q.y();
    }
    light.highlight_px = sw > 0.0 ? Eigen::Vector2d(sx / sw, sy / sw) : Eigen::Vector2d(px, py);
    if (sw > 0.0) {
      Eigen::Matrix2d m = Eigen::Matrix2d::Zero();
      for (const auto& q : samples) {
        const Eigen::Vector2d d = q.head<2>() - light.highlight_px;
        m += q.z() * d * d.transpose();
      }
      m /= sw;
      const double tr = m.trace(), det = m(0, 0) * m(1, 1) - m(0, 1) * m(1, 0);
      const double disc = std::sqrt(std::max(0.0, 0.25 * tr * tr - det));
      light.blob_major_px = std::sqrt(std::max(0.0, 0.5 * tr + disc));
      light.blob_minor_px = std::sqrt(std::max(0.0, 0.5 * tr - disc));
      // Image y points down; the angle is measured toward the image top.
      light.blob_angle_deg =
          -0.5 * std::atan2(2.0 * m(0, 1), m(0, 0) - m(1, 1)) * 180.0 / std::numbers::pi;
    }
    {
      // A second candidate: the brightest pixel on the sphere clear of the blob.
      const int margin = std::max({3, bx1 - bx0 + 1, by1 - by0 + 1});
      double second = 0.0;
      for (int y = y0; y <= y1; ++y) {
        for (int x = x0; x <= x1; ++x) {
          if (!on_sphere(x, y)) continue;
          if (x >= bx0 - margin && x <= bx1 + margin && y >= by0 - margin && y <= by1 + margin) {
            continue;
          }
          second = std::max(second, luma_at(view, x, y));
        }
      }
      light.second_peak = second;
    }
    if (light.blob_pixels > options.max_blob_area_fraction * sphere_area) {
      light.flag = "highlight blob covers " + std::to_string(light.blob_pixels) +
                   " pixels: not a compact highlight (a reflection of the scene?)";
      report.lights.push_back(light);
      continue;
    }
    light.direction = reflect_highlight(s, options.camera, light.highlight_px, w, h);
    light.found = light.direction.z() > 0.0;
    if (!light.found) light.flag = "reflected direction is below the sample plane";
    report.lights.push_back(light);
  }
  return report;
}

LightSet sphere_light_set(const SphereReport& report) {
  LightSet set;
  for (const SphereLight& l : report.lights) {
    if (!l.found) continue;
    Light light;
    light.image = l.image;
    light.direction = l.direction;
    set.lights.push_back(std::move(light));
  }
  return set;
}

std::string SphereReport::to_json() const {
  nlohmann::json j;
  j["sphere"] = {{"centre_px", {sphere.centre_px.x(), sphere.centre_px.y()}},
                 {"radius_px", sphere.radius_px},
                 {"detected", sphere_detected}};
  j["lights"] = nlohmann::json::array();
  for (const SphereLight& l : lights) {
    nlohmann::json e = {{"image", l.image.filename().string()},
                        {"found", l.found},
                        {"highlight_px", {l.highlight_px.x(), l.highlight_px.y()}},
                        {"peak", l.peak},
                        {"blob_pixels", l.blob_pixels},
                        {"saturated", l.saturated},
                        {"blob_axes_px", {l.blob_major_px, l.blob_minor_px}},
                        {"blob_angle_deg", l.blob_angle_deg},
                        {"second_peak", l.second_peak},
                        {"residual_px", l.residual_px},
                        {"confidence", l.confidence},
                        {"outlier", l.outlier}};
    if (l.found) e["direction"] = {l.direction.x(), l.direction.y(), l.direction.z()};
    if (!l.flag.empty()) e["flag"] = l.flag;
    j["lights"].push_back(e);
  }
  j["usable"] = usable();
  return j.dump(2);
}

void drop_lights(const std::vector<int>& indices, SphereReport* report) {
  for (int i : indices) {
    if (i < 0 || i >= static_cast<int>(report->lights.size())) {
      throw Error("--drop " + std::to_string(i) + ": there are " +
                  std::to_string(report->lights.size()) + " lights (0-based indices)");
    }
    SphereLight& l = report->lights[static_cast<std::size_t>(i)];
    l.found = false;
    l.flag = "dropped by the user";
  }
}

namespace {

cv::Mat to_bgr8(const Image& img) {
  cv::Mat out(img.height(), img.width(), CV_8UC3);
  for (int y = 0; y < img.height(); ++y) {
    auto* row = out.ptr<cv::Vec3b>(y);
    for (int x = 0; x < img.width(); ++x) {
      for (int c = 0; c < 3; ++c) {
        const float v = img.at(x, y, img.channels() >= 3 ? 2 - c : 0);
        row[x][c] = static_cast<unsigned char>(std::lround(std::clamp(v, 0.0f, 1.0f) * 255.0f));
      }
    }
  }
  return out;
}

Image from_bgr8(const cv::Mat& m) {
  Image out(m.cols, m.rows, 3, ColourSpace::kSRGB);
  for (int y = 0; y < m.rows; ++y) {
    const auto* row = m.ptr<cv::Vec3b>(y);
    for (int x = 0; x < m.cols; ++x) {
      for (int c = 0; c < 3; ++c) out.at(x, y, c) = static_cast<float>(row[x][2 - c]) / 255.0f;
    }
  }
  return out;
}

cv::Point to_point(const Eigen::Vector2d& p, int shift) {
  return {static_cast<int>(std::lround(p.x() * (1 << shift))),
          static_cast<int>(std::lround(p.y() * (1 << shift)))};
}

}  // namespace

Image sphere_overlay(const Image& image, const SphereReport& report, std::size_t light_index,
                     double scale, int text_row) {
  cv::Mat m = to_bgr8(image);
  constexpr int kShift = 4;  // sub-pixel drawing
  const Circle& s = report.sphere;
  const Eigen::Vector2d centre = s.centre_px * scale;
  cv::circle(m, to_point(centre, kShift), static_cast<int>(s.radius_px * scale * (1 << kShift)),
             cv::Scalar(255, 200, 0), 1, cv::LINE_AA, kShift);
  cv::drawMarker(m, to_point(centre, 0), cv::Scalar(255, 200, 0), cv::MARKER_CROSS, 9, 1);
  const SphereLight& l = report.lights.at(light_index);
  // Green: used; orange: used but doubtful (an outlier); red: not used.
  const cv::Scalar colour = !l.found    ? cv::Scalar(0, 0, 255)
                            : l.outlier ? cv::Scalar(0, 150, 255)
                                        : cv::Scalar(0, 220, 0);
  if (l.peak > 0.0 && (l.highlight_px.x() != 0.0 || l.highlight_px.y() != 0.0)) {
    const Eigen::Vector2d h = l.highlight_px * scale;
    cv::circle(m, to_point(h, kShift), 6 << kShift, colour, 1, cv::LINE_AA, kShift);
    cv::drawMarker(m, to_point(h, 0), colour, cv::MARKER_CROSS, 5, 1);
  }
  std::string text = std::to_string(light_index) + ": " + l.image.filename().string();
  if (l.found) {
    char buf[48];
    std::snprintf(buf, sizeof(buf), " confidence %.2f", l.confidence);
    text += buf;
  }
  if (!l.found || l.outlier) text += " - " + l.flag;
  cv::putText(m, text, cv::Point(6, 18 + 16 * text_row), cv::FONT_HERSHEY_SIMPLEX, 0.45, colour, 1,
              cv::LINE_AA);
  return from_bgr8(m);
}

Image light_polar_plot(const SphereReport& report, int size_px) {
  if (size_px < 100) throw Error("polar plot: size must be at least 100 pixels");
  cv::Mat m(size_px, size_px, CV_8UC3, cv::Scalar(255, 255, 255));
  const cv::Point centre(size_px / 2, size_px / 2);
  const double rim = 0.44 * size_px;
  for (int el = 0; el < 90; el += 30) {
    const int r = static_cast<int>(rim * (90.0 - el) / 90.0);
    cv::circle(m, centre, r, cv::Scalar(200, 200, 200), 1, cv::LINE_AA);
    cv::putText(m, std::to_string(el), centre + cv::Point(r + 2, -2), cv::FONT_HERSHEY_SIMPLEX,
                0.35, cv::Scalar(150, 150, 150), 1, cv::LINE_AA);
  }
  cv::line(m, centre - cv::Point(static_cast<int>(rim), 0),
           centre + cv::Point(static_cast<int>(rim), 0), cv::Scalar(220, 220, 220));
  cv::line(m, centre - cv::Point(0, static_cast<int>(rim)),
           centre + cv::Point(0, static_cast<int>(rim)), cv::Scalar(220, 220, 220));
  int flagged_row = 0;
  for (std::size_t i = 0; i < report.lights.size(); ++i) {
    const SphereLight& l = report.lights[i];
    if (!l.found) {
      cv::putText(m, std::to_string(i) + ": " + l.flag.substr(0, 60),
                  cv::Point(6, size_px - 8 - 14 * flagged_row++), cv::FONT_HERSHEY_SIMPLEX, 0.38,
                  cv::Scalar(0, 0, 255), 1, cv::LINE_AA);
      continue;
    }
    const double el = std::asin(std::clamp(l.direction.z(), -1.0, 1.0)) * 180.0 / std::numbers::pi;
    const double az = std::atan2(l.direction.y(), l.direction.x());
    const double r = rim * (90.0 - el) / 90.0;
    // Light frame y points up the image; the plot's y axis points down.
    const cv::Point p = centre + cv::Point(static_cast<int>(std::lround(r * std::cos(az))),
                                           static_cast<int>(std::lround(-r * std::sin(az))));
    cv::circle(m, p, 4, cv::Scalar(180, 90, 0), cv::FILLED, cv::LINE_AA);
    cv::putText(m, std::to_string(i), p + cv::Point(5, -4), cv::FONT_HERSHEY_SIMPLEX, 0.38,
                cv::Scalar(60, 60, 60), 1, cv::LINE_AA);
  }
  cv::putText(m, "light directions (elevation rings 0/30/60, x right, y up)", cv::Point(6, 16),
              cv::FONT_HERSHEY_SIMPLEX, 0.42, cv::Scalar(0, 0, 0), 1, cv::LINE_AA);
  return from_bgr8(m);
}

}  // namespace ptmkit::calib
