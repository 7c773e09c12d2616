#include "ptmkit/fit/near_light.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <numbers>
#include <utility>

#include <Eigen/Geometry>

#include "ptmkit/core/error.h"

namespace ptmkit::fit {

std::string_view to_string(LightModel model) {
  return model == LightModel::kNear ? "near" : "distant";
}

std::string NearLightOptions::validate() const {
  if (falloff && !plane) {
    return "fall-off correction needs the near-light model: a sample plane and light positions";
  }
  if (plane && (plane->width_px <= 0 || plane->height_px <= 0)) {
    return "the sample plane has no size";
  }
  if (plane && !plane->pixel_to_plane_mm.allFinite()) {
    return "the sample plane's homography is not finite";
  }
  return {};
}

NearLightModel::NearLightModel(std::vector<Eigen::Vector3d> positions_mm, SamplePlane plane)
    : positions_(std::move(positions_mm)), plane_(std::move(plane)) {
  for (std::size_t i = 0; i < positions_.size(); ++i) {
    const Eigen::Vector3d& p = positions_[i];
    if (!p.allFinite() || !(p.z() > 0.0)) {
      throw Error("near lights: light " + std::to_string(i + 1) +
                  " has a non-finite position or one not above the sample plane (z <= 0 mm)");
    }
    centre_sq_.push_back(p.squaredNorm());
  }
}

NearLightModel NearLightModel::from_lights(const LightSet& lights, const SamplePlane& plane) {
  std::vector<Eigen::Vector3d> pos;
  for (std::size_t i = 0; i < lights.size(); ++i) {
    const Light& l = lights.lights[i];
    if (!l.position_mm) {
      throw Error("near lights: light " + std::to_string(i + 1) + " (" +
                  l.image.filename().string() +
                  ") has no position_mm; the near-light model needs every light's position "
                  "(a lights JSON with position_mm, e.g. from `ptmkit calibrate dome --radius` "
                  "or `ptmkit synth --dome-radius`)");
    }
    pos.push_back(*l.position_mm);
  }
  return NearLightModel(std::move(pos), plane);
}

void NearLightModel::texel(int x, int y, double* dirs, double* correction) const {
  const Eigen::Vector2d p = plane_.plane_mm(x, y);
  const std::size_t n = positions_.size();
  for (std::size_t i = 0; i < n; ++i) {
    const double vx = positions_[i].x() - p.x();
    const double vy = positions_[i].y() - p.y();
    const double vz = positions_[i].z();
    const double d_sq = vx * vx + vy * vy + vz * vz;
    if (dirs != nullptr) {
      const double inv = 1.0 / std::sqrt(d_sq);
      dirs[3 * i] = vx * inv;
      dirs[3 * i + 1] = vy * inv;
      dirs[3 * i + 2] = vz * inv;
    }
    if (correction != nullptr) correction[i] = d_sq / centre_sq_[i];
  }
}

NearLightReport NearLightModel::field_report() const {
  NearLightReport r;
  r.model = LightModel::kNear;
  const std::size_t n = positions_.size();
  if (n == 0) return r;
  constexpr int kGrid = 17;
  std::vector<double> spread(n, 0.0);
  std::vector<double> dirs(3 * n), corr(n);
  r.min_falloff = std::numeric_limits<double>::infinity();
  r.max_falloff = 0.0;
  for (int gy = 0; gy < kGrid; ++gy) {
    for (int gx = 0; gx < kGrid; ++gx) {
      const int x = static_cast<int>(std::lround((plane_.width_px - 1) * gx / (kGrid - 1.0)));
      const int y = static_cast<int>(std::lround((plane_.height_px - 1) * gy / (kGrid - 1.0)));
      texel(x, y, dirs.data(), corr.data());
      for (std::size_t i = 0; i < n; ++i) {
        const Eigen::Vector3d centre = positions_[i].normalized();
        const Eigen::Vector3d d(dirs[3 * i], dirs[3 * i + 1], dirs[3 * i + 2]);
        // atan2 of the cross and dot products: accurate for small angles too.
        const double angle = std::atan2(centre.cross(d).norm(), centre.dot(d));
        spread[i] = std::max(spread[i], angle * 180.0 / std::numbers::pi);
        r.min_falloff = std::min(r.min_falloff, 1.0 / corr[i]);
        r.max_falloff = std::max(r.max_falloff, 1.0 / corr[i]);
      }
    }
  }
  double sum = 0.0;
  for (double s : spread) {
    r.max_spread_deg = std::max(r.max_spread_deg, s);
    sum += s;
  }
  r.mean_spread_deg = sum / static_cast<double>(n);
  return r;
}

}  // namespace ptmkit::fit
