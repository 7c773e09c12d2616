// Near lights: a dome of finite radius lights every texel from its own direction.
//
// With distant lights every texel sees light i along the same unit vector, so one 6 x N
// pseudo-inverse fits the whole image (design.h). A light at a finite position P_i (mm, light
// frame, origin at the sample-plane centre; core/light_set.h) is seen from the plane point p of
// a texel (core/plane.h) along normalise(P_i - p): across a 100 mm field under a 300 mm dome
// that direction turns by ten degrees or more, which the distant model mistakes for the
// surface's response. The near-light model gives each texel its own design rows
// ptm_basis(lu, lv) of those directions and solves its 6 x 6 normal equations (Cholesky, in
// double); optionally it also divides out the inverse-square fall-off, scaling each sample by
// (|P_i - p| / |P_i|)^2 so every light has the intensity it has at the plane centre.
//
// The texel's plane point has z = 0: heights on the sample are unknown to the fit (for a relief
// of height h under a light at distance d the direction error is about h / d radians).
#pragma once

#include <cstdint>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include <Eigen/Core>

#include "ptmkit/core/light_set.h"
#include "ptmkit/core/plane.h"

namespace ptmkit::fit {

struct NearLightOptions {
  // The sample plane of the capture. When set, every light must have a position_mm and the
  // fit uses per-texel directions ("near" light model); when unset the fit uses the lights'
  // directions (the distant model), positions or not.
  std::optional<SamplePlane> plane;
  // Near model only: divide out the inverse-square fall-off relative to the plane centre
  // (sRGB-encoded samples are linearised, scaled and re-encoded). Off by default: the fitted
  // polynomial then also carries the intensity variation across the field.
  bool falloff = false;

  [[nodiscard]] std::string validate() const;  // empty if valid
};

// How a fit treats its lights: distant (one direction per light, the shared design) or near
// (each texel its own directions from the lights' positions and the sample plane).
enum class LightModel { kDistant, kNear };
// "distant", "near".
[[nodiscard]] std::string_view to_string(LightModel model);

// What the light model is and how much the field matters (FitReport::light_model).
struct NearLightReport {
  LightModel model = LightModel::kDistant;
  // Near model: over a 17 x 17 grid of texels spanning the image (corners included), the
  // largest and the mean (over lights) of each light's largest angle between its direction at
  // a texel and its direction at the plane centre, degrees.
  double max_spread_deg = 0.0;
  double mean_spread_deg = 0.0;
  // Near model: relative intensity (|P_i| / |P_i - p|)^2 over the same grid and all lights.
  double min_falloff = 1.0;
  double max_falloff = 1.0;
  bool falloff_corrected = false;
  // Texels whose per-texel normal matrix was not positive definite (coefficients left 0).
  std::uint64_t singular_texels = 0;
  // Why the model is what it is, e.g. "positions ignored: no sample plane given".
  std::string note;
};

// Per-texel light geometry of a capture under near lights.
class NearLightModel {
 public:
  // positions_mm: one per light (light frame, mm). Throws ptmkit::Error when a position is not
  // finite, or is not above the plane (z <= 0).
  NearLightModel(std::vector<Eigen::Vector3d> positions_mm, SamplePlane plane);

  // The model for a light set: every light must have a position_mm, else ptmkit::Error names
  // the first light without one.
  static NearLightModel from_lights(const LightSet& lights, const SamplePlane& plane);

  [[nodiscard]] int lights() const { return static_cast<int>(positions_.size()); }
  [[nodiscard]] const SamplePlane& plane() const { return plane_; }
  [[nodiscard]] const std::vector<Eigen::Vector3d>& positions_mm() const { return positions_; }

  // Texel (x, y): unit directions toward each light (dirs, N x 3 row-major, may be null) and
  // the sample correction factor (|P_i - p| / |P_i|)^2 of each light (correction, N, may be
  // null). Every direction has z > 0: the plane points have z = 0 and the lights z > 0.
  void texel(int x, int y, double* dirs, double* correction) const;

  // Spread and fall-off over the field (NearLightReport, model "near").
  [[nodiscard]] NearLightReport field_report() const;

 private:
  std::vector<Eigen::Vector3d> positions_;
  std::vector<double> centre_sq_;  // |P_i|^2
  SamplePlane plane_;
};

}  // namespace ptmkit::fit
