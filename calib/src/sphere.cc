// Light directions from a specular sphere: options and report, the reflection of a highlight
// (orthographic or pinhole camera, the sphere's centre from its outline's cone), the highlight
// located in every image (blob, centroid, shape, second peak), the light set, the report's
// JSON and the user's drops. The circle itself: sphere_circle.cc; pictures: sphere_plot.cc.
#include "ptmkit/calib/sphere.h"

#include <algorithm>
#include <cmath>
#include <numbers>
#include <string>

#include <Eigen/QR>
#include <nlohmann/json.hpp>

#include "ptmkit/core/error.h"
#include "sphere_detail.h"

namespace ptmkit::calib {

using detail::luma_at;
using detail::upper_median;

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
    const double limit = 3.0 * 1.4826 * upper_median(sorted) + 1e-12;
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
      const double base = upper_median(level);
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
                        {"spot_rank", l.spot_rank},
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

}  // namespace ptmkit::calib
