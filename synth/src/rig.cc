#include "ptmkit/synth/rig.h"

#include <cmath>
#include <limits>
#include <numbers>
#include <random>
#include <utility>
#include <vector>

#include <Eigen/Geometry>

#include "optics.h"
#include "ptmkit/core/error.h"

namespace ptmkit::synth {

Image render_sphere_rig(const SphereRigOptions& o) {
  if (o.width < 8 || o.height < 8 || o.supersample < 1) throw Error("sphere rig: bad size");
  // Pinhole spheres, camera frame: (centre, radius) in one unit (sphere radii or mm).
  std::vector<std::pair<Eigen::Vector3d, double>> spheres;
  if (o.focal_px > 0.0) {
    if (o.spheres.empty()) {
      spheres.emplace_back(o.centre_cam, 1.0);
    } else {
      for (const RigSphere& s : o.spheres) spheres.emplace_back(s.centre_mm, s.radius_mm);
    }
    for (const auto& [c, r] : spheres) {
      if (!(r > 0.0) || !(c.z() > r)) {
        throw Error("sphere rig: every sphere must lie wholly in front of the camera");
      }
    }
  } else if (o.light_position_mm || !o.spheres.empty()) {
    throw Error("sphere rig: several spheres and point lights need a pinhole camera");
  }
  const Eigen::Vector3d l_cam =
      Eigen::Vector3d(o.light_dir.x(), -o.light_dir.y(), -o.light_dir.z()).normalized();
  const double cos_light = std::cos(o.light_radius_deg * std::numbers::pi / 180.0);
  Image img(o.width, o.height, 1, ColourSpace::kLinear);
  const int ss = o.supersample;
  std::mt19937_64 rng(o.seed);
  std::normal_distribution<double> noise(0.0, o.noise_grey / 255.0);
  // One sub-sample at (u, v): its radiance; *lit when it sees the light.
  auto sample = [&](double u, double v, bool* lit) {
    Eigen::Vector3d d, n, hit_point = Eigen::Vector3d::Zero();
    bool hit = false;
    if (o.focal_px <= 0.0) {
      const Eigen::Vector2d q = (Eigen::Vector2d(u, v) - o.centre_px) / o.radius_px;
      const double rho2 = q.squaredNorm();
      if (rho2 < 1.0) {
        hit = true;
        d = {0.0, 0.0, 1.0};
        n = {q.x(), q.y(), -std::sqrt(1.0 - rho2)};
      }
    } else {
      d = detail::pinhole_ray(u, v, o.focal_px, o.principal_px);
      double nearest = std::numeric_limits<double>::infinity();
      for (const auto& [c, rad] : spheres) {
        const double t = detail::intersect_sphere(Eigen::Vector3d::Zero(), d, c, rad);
        if (!(t < nearest)) continue;
        hit = true;
        nearest = t;
        hit_point = nearest * d;
        n = (hit_point - c).normalized();
      }
    }
    if (!hit) return o.background;
    const Eigen::Vector3d r = detail::reflect(d, n);
    const Eigen::Vector3d to_light =
        o.light_position_mm ? Eigen::Vector3d((*o.light_position_mm - hit_point).normalized())
                            : l_cam;
    const bool sees = r.dot(to_light) >= cos_light;
    if (sees) *lit = true;
    return o.body + (sees ? o.highlight : 0.0);
  };
  auto pixel = [&](int x, int y, int n_side, bool* lit) {
    double acc = 0.0;
    for (int sy = 0; sy < n_side; ++sy) {
      for (int sx = 0; sx < n_side; ++sx) {
        acc += sample(x - 0.5 + (sx + 0.5) / n_side, y - 0.5 + (sy + 0.5) / n_side, lit);
      }
    }
    return acc / (n_side * n_side);
  };
  std::vector<double> value(static_cast<std::size_t>(o.width) * static_cast<std::size_t>(o.height));
  std::vector<std::uint8_t> lit(value.size(), 0);
  for (int y = 0; y < o.height; ++y) {
    for (int x = 0; x < o.width; ++x) {
      const std::size_t at = static_cast<std::size_t>(y) * static_cast<std::size_t>(o.width) +
                             static_cast<std::size_t>(x);
      // Pinhole: a pixel whose ray passes more than 2 pixels' worth clear of every sphere
      // sees only the background (saves the supersampling).
      bool background_only = o.focal_px > 0.0;
      if (background_only) {
        const Eigen::Vector3d d0 = Eigen::Vector3d((x - o.principal_px.x()) / o.focal_px,
                                                   (y - o.principal_px.y()) / o.focal_px, 1.0)
                                       .normalized();
        for (const auto& [c, rad] : spheres) {
          if (c.cross(d0).norm() < rad + 2.0 * c.norm() / o.focal_px) background_only = false;
        }
      }
      bool pixel_lit = false;
      value[at] = background_only ? o.background : pixel(x, y, ss, &pixel_lit);
      lit[at] = pixel_lit ? 1 : 0;
    }
  }
  if (o.highlight_supersample > ss) {
    // The highlight's pixels and their neighbours again, finer.
    for (int y = 0; y < o.height; ++y) {
      for (int x = 0; x < o.width; ++x) {
        bool near_lit = false;
        for (int dy = -1; dy <= 1 && !near_lit; ++dy) {
          for (int dx = -1; dx <= 1; ++dx) {
            const int xx = x + dx, yy = y + dy;
            if (xx < 0 || yy < 0 || xx >= o.width || yy >= o.height) continue;
            if (lit[static_cast<std::size_t>(yy) * static_cast<std::size_t>(o.width) +
                    static_cast<std::size_t>(xx)] != 0) {
              near_lit = true;
              break;
            }
          }
        }
        if (!near_lit) continue;
        bool unused = false;
        value[static_cast<std::size_t>(y) * static_cast<std::size_t>(o.width) +
              static_cast<std::size_t>(x)] = pixel(x, y, o.highlight_supersample, &unused);
      }
    }
  }
  for (int y = 0; y < o.height; ++y) {
    for (int x = 0; x < o.width; ++x) {
      double v = value[static_cast<std::size_t>(y) * static_cast<std::size_t>(o.width) +
                       static_cast<std::size_t>(x)];
      if (o.noise_grey > 0.0) v += noise(rng);
      img.at(x, y, 0) = static_cast<float>(std::clamp(v, 0.0, 1.0));
    }
  }
  return img;
}

}  // namespace ptmkit::synth
