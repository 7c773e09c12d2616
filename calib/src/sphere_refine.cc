#include "ptmkit/calib/sphere_refine.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <memory>
#include <numbers>

#include <ceres/ceres.h>
#include <Eigen/Dense>
#include <nlohmann/json.hpp>

#include "ptmkit/core/error.h"

namespace ptmkit::calib {

namespace {

template <typename T>
using V3 = Eigen::Matrix<T, 3, 1>;

// Orthographic: the highlight (pixels) of unit light direction l (light frame) on the
// circle (cx, cy, r): the normal bisects l and the view direction (0, 0, 1).
template <typename T>
void ortho_highlight(const T* circle, const T* l, T* uv) {
  const V3<T> n = (V3<T>(l[0], l[1], l[2]) + V3<T>(T(0), T(0), T(1))).normalized();
  uv[0] = circle[0] + circle[2] * n.x();
  uv[1] = circle[1] - circle[2] * n.y();
}

// Pinhole, camera frame: the specular point on the sphere (centre c, radius rho) for a
// distant light along unit l (near = false) or a point light at l (near = true). The normal
// bisects the directions to the camera and to the light; a fixed-point iteration, which
// contracts by about rho / distance per step (12 steps: far below a pixel's worth).
template <typename T>
V3<T> specular_point(const T* c, double rho, const T* l, bool near) {
  const V3<T> centre(c[0], c[1], c[2]);
  const V3<T> light(l[0], l[1], l[2]);
  V3<T> to_light = near ? V3<T>((light - centre).normalized()) : light;
  V3<T> n = ((-centre).normalized() + to_light).normalized();
  for (int it = 0; it < 12; ++it) {
    const V3<T> p = centre + T(rho) * n;
    if (near) to_light = (light - p).normalized();
    n = ((-p).normalized() + to_light).normalized();
  }
  return centre + T(rho) * n;
}

struct OrthoRim {
  Eigen::Vector2d p;
  template <typename T>
  bool operator()(const T* circle, T* r) const {
    const T dx = T(p.x()) - circle[0], dy = T(p.y()) - circle[1];
    r[0] = ceres::sqrt(dx * dx + dy * dy) - circle[2];
    return true;
  }
};

struct OrthoHighlight {
  Eigen::Vector2d measured;
  template <typename T>
  bool operator()(const T* circle, const T* l, T* r) const {
    T uv[2];
    ortho_highlight(circle, l, uv);
    r[0] = uv[0] - T(measured.x());
    r[1] = uv[1] - T(measured.y());
    return true;
  }
};

struct PinholeRim {
  Eigen::Vector3d ray;  // unit
  double focal_px, rho;
  template <typename T>
  bool operator()(const T* c, T* r) const {
    const V3<T> centre(c[0], c[1], c[2]);
    const V3<T> e = ray.cast<T>();
    const T dist = centre.norm();
    const T angle = ceres::atan2(e.cross(centre).norm(), e.dot(centre));
    r[0] = T(focal_px) * (angle - ceres::asin(T(rho) / dist));
    return true;
  }
};

struct PinholeHighlight {
  Eigen::Vector2d measured, principal;
  double focal_px, rho;
  bool near;
  template <typename T>
  bool operator()(const T* c, const T* l, T* r) const {
    const V3<T> p = specular_point(c, rho, l, near);
    r[0] = T(focal_px) * p.x() / p.z() + T(principal.x()) - T(measured.x());
    r[1] = T(focal_px) * p.y() / p.z() + T(principal.y()) - T(measured.y());
    return true;
  }
};

Eigen::Vector3d flip(const Eigen::Vector3d& v) { return {v.x(), -v.y(), -v.z()}; }

Eigen::Vector3d pixel_ray(const Eigen::Vector2d& px, const Eigen::Vector2d& pp, double f) {
  return Eigen::Vector3d((px.x() - pp.x()) / f, (px.y() - pp.y()) / f, 1.0).normalized();
}

std::string format(const char* fmt, double a, double b = 0.0, double c = 0.0) {
  char buf[160];
  std::snprintf(buf, sizeof(buf), fmt, a, b, c);
  return buf;
}

void append_flag(std::string* flag, const std::string& text) {
  if (!flag->empty()) flag->append("; ");
  flag->append(text);
}

}  // namespace

std::string RigOptions::validate() const {
  if (auto e = detection.validate(); !e.empty()) return e;
  if (spheres.empty() && sphere_count < 1) return "sphere count must be at least 1";
  for (const Circle& c : spheres) {
    if (!(c.radius_px > 1.0)) return "sphere radius must be > 1 pixel";
  }
  if (!(sphere_radius_mm >= 0.0)) return "sphere radius must be >= 0 mm";
  if (!(loss_scale_px > 0.0)) return "loss scale must be > 0 pixels";
  if (!(outlier_px > 0.0)) return "outlier threshold must be > 0 pixels";
  if (!(max_shape_ratio > 1.0)) return "max shape ratio must be > 1";
  if (!(ambiguous_fraction > 0.0 && ambiguous_fraction <= 1.0)) {
    return "ambiguous fraction must be in (0, 1]";
  }
  if (max_iterations < 1) return "max iterations must be at least 1";
  return {};
}

int RigReport::usable() const {
  return static_cast<int>(
      std::count_if(lights.begin(), lights.end(), [](const RigLight& l) { return l.found; }));
}

int RigReport::outliers() const {
  return static_cast<int>(std::count_if(lights.begin(), lights.end(),
                                        [](const RigLight& l) { return l.found && l.outlier; }));
}

bool RigReport::most_lights_outliers() const { return 2 * outliers() > usable(); }

RigReport calibrate_rig(const std::vector<Image>& images,
                        const std::vector<std::filesystem::path>& names,
                        const RigOptions& options) {
  if (const auto err = options.validate(); !err.empty()) throw Error("sphere rig: " + err);
  if (images.empty()) throw Error("sphere rig: no images");
  const bool detected = options.spheres.empty();
  const std::vector<Circle> circles =
      detected ? find_spheres(images, options.sphere_count) : options.spheres;
  std::vector<SphereReport> spheres;
  for (const Circle& c : circles) {
    SphereOptions det = options.detection;
    det.sphere = c;
    spheres.push_back(calibrate_sphere(images, names, det));
    spheres.back().sphere_detected = detected;
  }
  return refine_rig(std::move(spheres), names, images[0].width(), images[0].height(), options);
}

namespace {

RigReport refine_rig_model(std::vector<SphereReport> spheres,
                           const std::vector<std::filesystem::path>& names, int w, int h,
                           const RigOptions& options) {
  if (const auto err = options.validate(); !err.empty()) throw Error("sphere rig: " + err);
  if (spheres.empty()) throw Error("sphere rig: no spheres");
  const SphereCamera& camera = options.detection.camera;
  const bool pinhole = camera.focal_px > 0.0;
  RigReport report;
  std::vector<Circle> circles;
  for (const SphereReport& s : spheres) {
    if (s.lights.size() != names.size()) throw Error("sphere rig: a sphere misses lights");
    circles.push_back(s.sphere);
  }
  const std::size_t k_spheres = circles.size();
  report.near = pinhole && options.sphere_radius_mm > 0.0 && k_spheres >= 2;
  if (options.sphere_radius_mm > 0.0 && !report.near) {
    throw Error(
        "light positions need a pinhole camera (--focal-px) and two or more spheres; "
        "without them leave out --sphere-radius-mm");
  }
  if (pinhole && options.plane) {
    if (!options.plane->pose) {
      throw Error("the sample plane has no pose (camera_from_plane): it cannot place the lights");
    }
    if (options.plane->width_px != w || options.plane->height_px != h) {
      throw Error("the sample plane belongs to " + std::to_string(options.plane->width_px) + "x" +
                  std::to_string(options.plane->height_px) + " images, these are " +
                  std::to_string(w) + "x" + std::to_string(h));
    }
  }
  report.model = !pinhole      ? "orthographic distant"
                 : report.near ? "pinhole near"
                               : "pinhole distant";
  report.spheres = std::move(spheres);
  const std::size_t n_lights = names.size();
  const double rho = report.near ? options.sphere_radius_mm : 1.0;
  const Eigen::Vector2d pp = principal_point(camera, w, h);
  const double f = camera.focal_px;

  // Sphere parameters: orthographic circles, or pinhole centres (camera frame).
  std::vector<std::array<double, 3>> sphere_params(k_spheres);
  for (std::size_t k = 0; k < k_spheres; ++k) {
    if (!pinhole) {
      sphere_params[k] = {circles[k].centre_px.x(), circles[k].centre_px.y(), circles[k].radius_px};
    } else {
      const Eigen::Vector3d c = rho * sphere_centre_in_camera(circles[k], camera, w, h);
      sphere_params[k] = {c.x(), c.y(), c.z()};
      report.centres_camera_initial.push_back(c);
    }
  }

  // Lights: initial directions (mean over the spheres) or positions (triangulation).
  const std::size_t min_seen = report.near ? 2 : 1;
  std::vector<std::array<double, 3>> light_params(n_lights, {0.0, 0.0, 1.0});
  report.lights.resize(n_lights);
  for (std::size_t i = 0; i < n_lights; ++i) {
    RigLight& rl = report.lights[i];
    rl.image = names.at(i);
    Eigen::Vector3d sum = Eigen::Vector3d::Zero();
    Eigen::Matrix3d a = Eigen::Matrix3d::Zero();
    Eigen::Vector3d b = Eigen::Vector3d::Zero();
    std::string why;
    for (std::size_t k = 0; k < k_spheres; ++k) {
      const SphereLight& sl = report.spheres[k].lights[i];
      if (!sl.found) {
        append_flag(&why,
                    k_spheres == 1 ? sl.flag : "sphere " + std::to_string(k) + ": " + sl.flag);
        continue;
      }
      ++rl.spheres_seen;
      sum += pinhole ? flip(sl.direction) : sl.direction;
      if (report.near) {
        // The highlight's ray, reflected at the sphere: a line through the light.
        const Eigen::Vector3d c(sphere_params[k][0], sphere_params[k][1], sphere_params[k][2]);
        const Eigen::Vector3d d = pixel_ray(sl.highlight_px, pp, f);
        const double bq = d.dot(c);
        const double t = bq - std::sqrt(std::max(0.0, bq * bq - (c.squaredNorm() - rho * rho)));
        const Eigen::Vector3d p = t * d;
        const Eigen::Vector3d n = (p - c).normalized();
        const Eigen::Vector3d r = (d - 2.0 * d.dot(n) * n).normalized();
        const Eigen::Matrix3d proj = Eigen::Matrix3d::Identity() - r * r.transpose();
        a += proj;
        b += proj * p;
      }
    }
    if (static_cast<std::size_t>(rl.spheres_seen) < min_seen) {
      rl.flag = rl.spheres_seen == 0 ? why : "seen on one sphere only: no position (" + why + ")";
      continue;
    }
    rl.found = true;
    if (report.near) {
      const Eigen::JacobiSVD<Eigen::Matrix3d> svd(a);
      if (svd.singularValues()(2) < 1e-6 * svd.singularValues()(0)) {
        rl.found = false;
        rl.flag = "the reflected rays are parallel: no position";
        continue;
      }
      const Eigen::Vector3d s = a.ldlt().solve(b);
      light_params[i] = {s.x(), s.y(), s.z()};
    } else {
      const Eigen::Vector3d l = sum.normalized();
      light_params[i] = {l.x(), l.y(), l.z()};
    }
  }

  // Outline rays (pinhole) or points (orthographic), per sphere.
  auto outline_of = [](const Circle& c) {
    std::vector<Eigen::Vector2d> pts = c.outline_px;
    if (pts.size() < 8) {
      pts.clear();
      for (int k = 0; k < 72; ++k) {
        const double a = 2.0 * std::numbers::pi * k / 72.0;
        pts.push_back(c.centre_px + c.radius_px * Eigen::Vector2d(std::cos(a), std::sin(a)));
      }
    }
    return pts;
  };

  if (options.refine) {
    ceres::Problem problem;
    for (std::size_t k = 0; k < k_spheres; ++k) {
      for (const Eigen::Vector2d& p : outline_of(circles[k])) {
        if (!pinhole) {
          problem.AddResidualBlock(new ceres::AutoDiffCostFunction<OrthoRim, 1, 3>(new OrthoRim{p}),
                                   new ceres::HuberLoss(options.loss_scale_px),
                                   sphere_params[k].data());
        } else {
          problem.AddResidualBlock(new ceres::AutoDiffCostFunction<PinholeRim, 1, 3>(
                                       new PinholeRim{pixel_ray(p, pp, f), f, rho}),
                                   new ceres::HuberLoss(options.loss_scale_px),
                                   sphere_params[k].data());
        }
      }
    }
    for (std::size_t i = 0; i < n_lights; ++i) {
      if (!report.lights[i].found) continue;
      for (std::size_t k = 0; k < k_spheres; ++k) {
        const SphereLight& sl = report.spheres[k].lights[i];
        if (!sl.found) continue;
        ceres::CostFunction* cost =
            pinhole ? static_cast<ceres::CostFunction*>(
                          new ceres::AutoDiffCostFunction<PinholeHighlight, 2, 3, 3>(
                              new PinholeHighlight{sl.highlight_px, pp, f, rho, report.near}))
                    : new ceres::AutoDiffCostFunction<OrthoHighlight, 2, 3, 3>(
                          new OrthoHighlight{sl.highlight_px});
        problem.AddResidualBlock(cost, new ceres::HuberLoss(options.loss_scale_px),
                                 sphere_params[k].data(), light_params[i].data());
      }
      if (!report.near) {
        problem.SetManifold(light_params[i].data(), new ceres::SphereManifold<3>());
      }
    }
    ceres::Solver::Options so;
    so.linear_solver_type = ceres::DENSE_SCHUR;
    so.max_num_iterations = options.max_iterations;
    so.num_threads = 1;  // deterministic
    so.function_tolerance = 1e-12;
    so.gradient_tolerance = 1e-12;
    so.parameter_tolerance = 1e-12;
    ceres::Solver::Summary summary;
    ceres::Solve(so, &problem, &summary);
    if (!summary.IsSolutionUsable()) {
      throw Error("sphere rig refinement failed: " + summary.BriefReport());
    }
    report.refined = true;
    report.iterations = static_cast<int>(summary.iterations.size());
  }

  // Outline residual after refinement (or of the initial geometry).
  {
    double ss = 0.0;
    std::size_t count = 0;
    for (std::size_t k = 0; k < k_spheres; ++k) {
      for (const Eigen::Vector2d& p : outline_of(circles[k])) {
        double r = 0.0;
        if (!pinhole) {
          OrthoRim{p}(sphere_params[k].data(), &r);
        } else {
          PinholeRim{pixel_ray(p, pp, f), f, rho}(sphere_params[k].data(), &r);
        }
        ss += r * r;
        ++count;
      }
    }
    report.outline_rms_px = count > 0 ? std::sqrt(ss / static_cast<double>(count)) : 0.0;
  }
  for (std::size_t k = 0; k < k_spheres; ++k) {
    if (!pinhole) {
      Circle c;
      c.centre_px = {sphere_params[k][0], sphere_params[k][1]};
      c.radius_px = sphere_params[k][2];
      report.refined_circles.push_back(c);
    } else {
      report.centres_camera.emplace_back(sphere_params[k][0], sphere_params[k][1],
                                         sphere_params[k][2]);
    }
  }

  // The light frame: from the plane's pose, or the camera's turned about x, origin on the
  // optical axis at the spheres' mean depth.
  Eigen::Matrix3d plane_from_camera = Eigen::Vector3d(1.0, -1.0, -1.0).asDiagonal();
  Eigen::Vector3d origin_cam = Eigen::Vector3d::Zero();
  if (pinhole && options.plane) {
    plane_from_camera = options.plane->pose->camera_from_plane.transpose();
    origin_cam = options.plane->pose->plane_origin_in_camera_mm;
    report.origin = "the sample-plane centre (from the plane's pose)";
  } else if (report.near) {
    double z = 0.0;
    for (const auto& c : report.centres_camera) z += c.z() / static_cast<double>(k_spheres);
    origin_cam = {0.0, 0.0, z};
    report.origin =
        format("the optical axis at the spheres' mean depth (%.2f mm from the camera)", z);
  } else {
    report.origin = "none (distant lights)";
  }

  // Per light and sphere: residual, shape, ambiguity, confidence, flags.
  for (std::size_t i = 0; i < n_lights; ++i) {
    RigLight& rl = report.lights[i];
    if (!rl.found) continue;
    const double* lp = light_params[i].data();
    if (!pinhole) {
      rl.direction = Eigen::Vector3d(lp[0], lp[1], lp[2]).normalized();
    } else if (!report.near) {
      rl.direction = (plane_from_camera * Eigen::Vector3d(lp[0], lp[1], lp[2])).normalized();
    } else {
      const Eigen::Vector3d s(lp[0], lp[1], lp[2]);
      rl.position_camera_mm = s;
      rl.position_mm = plane_from_camera * (s - origin_cam);
      rl.direction = rl.position_mm->normalized();
    }
    double ss = 0.0;
    rl.confidence = 1.0;
    for (std::size_t k = 0; k < k_spheres; ++k) {
      SphereLight& sl = report.spheres[k].lights[i];
      if (!sl.found) continue;
      double r[2];
      double cos_theta = 1.0;
      if (!pinhole) {
        OrthoHighlight{sl.highlight_px}(sphere_params[k].data(), lp, r);
        const Eigen::Vector3d n =
            (Eigen::Vector3d(lp[0], lp[1], lp[2]) + Eigen::Vector3d::UnitZ()).normalized();
        cos_theta = n.z();
      } else {
        PinholeHighlight{sl.highlight_px, pp, f, rho, report.near}(sphere_params[k].data(), lp, r);
        const Eigen::Vector3d p = specular_point(sphere_params[k].data(), rho, lp, report.near);
        const Eigen::Vector3d c(sphere_params[k][0], sphere_params[k][1], sphere_params[k][2]);
        cos_theta = (p - c).normalized().dot(-p.normalized());
      }
      sl.residual_px = std::hypot(r[0], r[1]);
      ss += sl.residual_px * sl.residual_px;
      // Shape: a small round light, seen in the mirror at angle theta, is foreshortened by
      // cos^2(theta) across its major (tangential) axis.
      const double c2 = std::clamp(cos_theta * cos_theta, 0.05, 1.0);
      const double maj2 = sl.blob_major_px * sl.blob_major_px;
      const double measured =
          std::sqrt((maj2 + 0.25) / (sl.blob_minor_px * sl.blob_minor_px + 0.25));
      const double expected = std::sqrt((maj2 + 0.25) / (maj2 * c2 * c2 + 0.25));
      const double shape = std::min(measured / expected, expected / measured);
      const double ambiguity =
          sl.peak > 0.0 ? std::clamp(1.0 - sl.second_peak / sl.peak, 0.0, 1.0) : 0.0;
      const double min_peak = options.detection.min_peak;
      const double strength =
          min_peak > 0.0 ? std::clamp((sl.peak - min_peak) / min_peak, 0.0, 1.0) : 1.0;
      const double res_factor = 1.0 / (1.0 + std::pow(sl.residual_px / options.outlier_px, 2));
      sl.confidence = res_factor * shape * ambiguity * strength;
      rl.confidence = std::min(rl.confidence, sl.confidence);
      std::string why;
      if (sl.residual_px > options.outlier_px) {
        append_flag(&why, format("residual %.2f px > %.2f px", sl.residual_px, options.outlier_px));
      }
      if (1.0 / shape > options.max_shape_ratio) {
        append_flag(&why, std::string(measured > expected ? "blob elongated" : "blob too round") +
                              format(": elongation %.2f, expected %.2f", measured, expected));
      }
      if (sl.second_peak >= options.ambiguous_fraction * sl.peak) {
        append_flag(&why, format("a second candidate elsewhere on the sphere at %.2f of the peak",
                                 sl.second_peak / sl.peak));
      }
      sl.outlier = !why.empty();
      if (sl.outlier) {
        append_flag(&sl.flag, why);
        rl.outlier = true;
        append_flag(&rl.flag, k_spheres == 1 ? why : "sphere " + std::to_string(k) + ": " + why);
      }
    }
    rl.residual_px = std::sqrt(ss / std::max(1, rl.spheres_seen));
  }
  return report;
}

}  // namespace

RigReport refine_rig(std::vector<SphereReport> spheres,
                     const std::vector<std::filesystem::path>& names, int w, int h,
                     const RigOptions& options) {
  const bool may_be_near = options.near_from_evidence && options.sphere_radius_mm == 0.0 &&
                           options.detection.camera.focal_px > 0.0 && spheres.size() >= 2 &&
                           !options.plane;
  if (!may_be_near) return refine_rig_model(std::move(spheres), names, w, h, options);
  RigReport distant = refine_rig_model(spheres, names, w, h, options);
  if (!distant.most_lights_outliers()) return distant;
  RigOptions near_options = options;
  near_options.sphere_radius_mm = 1.0;  // distances in units of the sphere radius
  RigReport near = refine_rig_model(std::move(spheres), names, w, h, near_options);
  const bool better = 4 * near.outliers() <= near.usable() &&
                      2 * near.outliers() <= distant.outliers() && near.usable() > 0;
  if (!better) return distant;
  near.near_scale_free = true;
  char note[300];
  std::snprintf(note, sizeof note,
                "near lights, chosen from the evidence: as distant lights %d of %d are "
                "outliers (the spheres see them along different directions), as near ones %d "
                "of %d; directions from the origin, distances unknown (give "
                "--sphere-radius-mm for positions)",
                distant.outliers(), distant.usable(), near.outliers(), near.usable());
  near.model_note = note;
  for (std::size_t i = 0; i < near.lights.size(); ++i) {
    RigLight& l = near.lights[i];
    l.position_mm.reset();
    l.position_camera_mm.reset();
    // A near light needs two spheres; one seen on a single sphere keeps that sphere's
    // direction (off by the parallax between that sphere and the origin).
    if (!l.found && distant.lights[i].found) {
      l = distant.lights[i];
      append_flag(&l.flag, "seen on one sphere: its direction from that sphere alone");
      l.outlier = true;
    }
  }
  return near;
}

LightSet rig_light_set(const RigReport& report) {
  LightSet set;
  for (const RigLight& l : report.lights) {
    if (!l.found) continue;
    Light light;
    light.image = l.image;
    light.direction = l.direction;
    light.position_mm = l.position_mm;
    set.lights.push_back(std::move(light));
  }
  return set;
}

void drop_rig_lights(const std::vector<int>& indices, RigReport* report) {
  for (int i : indices) {
    if (i < 0 || i >= static_cast<int>(report->lights.size())) {
      throw Error("--drop " + std::to_string(i) + ": there are " +
                  std::to_string(report->lights.size()) + " lights (0-based indices)");
    }
    RigLight& l = report->lights[static_cast<std::size_t>(i)];
    l.found = false;
    append_flag(&l.flag, "dropped by the user");
    for (SphereReport& s : report->spheres) drop_lights({i}, &s);
  }
}

int drop_outliers(RigReport* report) {
  int n = 0;
  for (std::size_t i = 0; i < report->lights.size(); ++i) {
    RigLight& l = report->lights[i];
    if (!l.found || !l.outlier) continue;
    l.found = false;
    append_flag(&l.flag, "dropped as an outlier");
    for (SphereReport& s : report->spheres) {
      s.lights[i].found = false;
      append_flag(&s.lights[i].flag, "dropped as an outlier");
    }
    ++n;
  }
  return n;
}

std::string RigReport::to_json() const {
  nlohmann::json j;
  j["model"] = model;
  if (!model_note.empty()) j["model_note"] = model_note;
  j["refined"] = refined;
  j["iterations"] = iterations;
  j["origin"] = origin;
  j["outline_rms_px"] = outline_rms_px;
  j["spheres"] = nlohmann::json::array();
  for (std::size_t k = 0; k < spheres.size(); ++k) {
    nlohmann::json s = nlohmann::json::parse(spheres[k].to_json());
    if (k < refined_circles.size()) {
      const Circle& c = refined_circles[k];
      s["refined"] = {{"centre_px", {c.centre_px.x(), c.centre_px.y()}},
                      {"radius_px", c.radius_px}};
    }
    if (k < centres_camera.size()) {
      const auto& a = centres_camera_initial[k];
      const auto& b = centres_camera[k];
      const char* unit = near && !near_scale_free ? "centre_camera_mm" : "centre_camera_radii";
      s["initial"] = {{unit, {a.x(), a.y(), a.z()}}};
      s["refined"] = {{unit, {b.x(), b.y(), b.z()}}};
    }
    j["spheres"].push_back(s);
  }
  j["lights"] = nlohmann::json::array();
  for (const RigLight& l : lights) {
    nlohmann::json e = {{"image", l.image.filename().string()},
                        {"found", l.found},
                        {"outlier", l.outlier},
                        {"spheres_seen", l.spheres_seen},
                        {"residual_px", l.residual_px},
                        {"confidence", l.confidence}};
    if (l.found) e["direction"] = {l.direction.x(), l.direction.y(), l.direction.z()};
    if (l.found && l.position_mm) {
      e["position_mm"] = {l.position_mm->x(), l.position_mm->y(), l.position_mm->z()};
      e["position_camera_mm"] = {l.position_camera_mm->x(), l.position_camera_mm->y(),
                                 l.position_camera_mm->z()};
    }
    if (!l.flag.empty()) e["flag"] = l.flag;
    j["lights"].push_back(e);
  }
  j["usable"] = usable();
  j["outliers"] = outliers();
  return j.dump(2);
}

}  // namespace ptmkit::calib
