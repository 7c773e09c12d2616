// Ray geometry shared by the calibration rig (rig.cc) and the photo renderer (photo.cc):
// pinhole rays, ray-sphere intersection, reflection and refraction. Camera frame: x right,
// y down, z forward.
#pragma once

#include <algorithm>
#include <cmath>
#include <limits>

#include <Eigen/Core>

namespace ptmkit::synth::detail {

// The unit ray through pixel (u, v) of a pinhole camera at the origin.
[[nodiscard]] inline Eigen::Vector3d pinhole_ray(double u, double v, double focal_px,
                                                 const Eigen::Vector2d& principal_px) {
  return Eigen::Vector3d((u - principal_px.x()) / focal_px, (v - principal_px.y()) / focal_px, 1.0)
      .normalized();
}

// Distance along the unit ray (origin o, direction d) to its first intersection with the
// sphere (centre c, radius r) beyond t_min, or infinity.
[[nodiscard]] inline double intersect_sphere(const Eigen::Vector3d& o, const Eigen::Vector3d& d,
                                             const Eigen::Vector3d& c, double r,
                                             double t_min = 0.0) {
  const Eigen::Vector3d oc = c - o;
  const double b = d.dot(oc);
  const double disc = b * b - (oc.squaredNorm() - r * r);
  if (disc <= 0.0) return std::numeric_limits<double>::infinity();
  const double s = std::sqrt(disc);
  if (b - s > t_min) return b - s;
  if (b + s > t_min) return b + s;
  return std::numeric_limits<double>::infinity();
}

// Mirror reflection of direction d about unit normal n.
[[nodiscard]] inline Eigen::Vector3d reflect(const Eigen::Vector3d& d, const Eigen::Vector3d& n) {
  return d - 2.0 * d.dot(n) * n;
}

// Refraction of unit direction d through a surface of unit normal n (facing against d) with
// eta = n_from / n_to; false on total internal reflection.
[[nodiscard]] inline bool refract(const Eigen::Vector3d& d, const Eigen::Vector3d& n, double eta,
                                  Eigen::Vector3d* out) {
  const double cos_i = -d.dot(n);
  const double k = 1.0 - eta * eta * (1.0 - cos_i * cos_i);
  if (k < 0.0) return false;
  *out = (eta * d + (eta * cos_i - std::sqrt(k)) * n).normalized();
  return true;
}

// Schlick's approximation of the Fresnel reflectance at incidence cosine cos_i.
[[nodiscard]] inline double schlick(double f0, double cos_i) {
  const double m = 1.0 - std::clamp(cos_i, 0.0, 1.0);
  const double m2 = m * m;
  return f0 + (1.0 - f0) * m2 * m2 * m;
}

}  // namespace ptmkit::synth::detail
