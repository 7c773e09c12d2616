#include "ptmkit/synth/rig.h"

#include <cmath>
#include <numbers>
#include <random>

#include "ptmkit/core/error.h"

namespace ptmkit::synth {

Image render_sphere_rig(const SphereRigOptions& o) {
  if (o.width < 8 || o.height < 8 || o.supersample < 1) throw Error("sphere rig: bad size");
  if (o.focal_px > 0.0 && !(o.centre_cam.z() > 1.0)) {
    throw Error("sphere rig: the sphere must lie in front of the camera");
  }
  const Eigen::Vector3d l_cam =
      Eigen::Vector3d(o.light_dir.x(), -o.light_dir.y(), -o.light_dir.z()).normalized();
  const double cos_light = std::cos(o.light_radius_deg * std::numbers::pi / 180.0);
  Image img(o.width, o.height, 1, ColourSpace::kLinear);
  const int ss = o.supersample;
  std::mt19937_64 rng(o.seed);
  std::normal_distribution<double> noise(0.0, o.noise_grey / 255.0);
  for (int y = 0; y < o.height; ++y) {
    for (int x = 0; x < o.width; ++x) {
      double acc = 0.0;
      for (int sy = 0; sy < ss; ++sy) {
        for (int sx = 0; sx < ss; ++sx) {
          const double u = x - 0.5 + (sx + 0.5) / ss;
          const double v = y - 0.5 + (sy + 0.5) / ss;
          Eigen::Vector3d d, n;
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
            d = Eigen::Vector3d((u - o.principal_px.x()) / o.focal_px,
                                (v - o.principal_px.y()) / o.focal_px, 1.0)
                    .normalized();
            const double b = d.dot(o.centre_cam);
            const double disc = b * b - (o.centre_cam.squaredNorm() - 1.0);
            if (disc > 0.0) {
              hit = true;
              n = ((b - std::sqrt(disc)) * d - o.centre_cam).normalized();
            }
          }
          if (!hit) {
            acc += o.background;
            continue;
          }
          const Eigen::Vector3d r = d - 2.0 * d.dot(n) * n;
          acc += o.body + (r.dot(l_cam) >= cos_light ? o.highlight : 0.0);
        }
      }
      double value = acc / (ss * ss);
      if (o.noise_grey > 0.0) value += noise(rng);
      img.at(x, y, 0) = static_cast<float>(std::clamp(value, 0.0, 1.0));
    }
  }
  return img;
}

}  // namespace ptmkit::synth
