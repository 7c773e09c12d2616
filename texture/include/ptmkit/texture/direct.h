// Direct light-dependent rendering (the seed paper, section 2): the photographs themselves,
// blended by the barycentric weights of the light inside a Delaunay triangulation of the
// input light directions projected to (lu, lv).
//
// Outside the triangulation (a light lower than the outermost input lights, or on a side with
// none) the light is replaced by the nearest point of the triangulated region (its convex
// hull) and that point's weights are used: the result is continuous everywhere and equals
// the nearest hull edge's blend. A light at or below the horizon (z <= 0) gives black.
#pragma once

#include <array>
#include <filesystem>
#include <vector>

#include <Eigen/Core>

#include "ptmkit/core/image.h"
#include "ptmkit/core/light_set.h"

namespace ptmkit::texture {

struct LightWeights {
  std::array<int, 3> index{0, 0, 0};  // photos blended
  std::array<double, 3> weight{1.0, 0.0, 0.0};
  bool inside = true;  // false: the nearest hull point was used
};

class LightTriangulation {
 public:
  // Throws ptmkit::Error when fewer than 3 distinct, non-collinear (lu, lv) points are given.
  // Duplicate directions (same (lu, lv)) keep the first.
  explicit LightTriangulation(const std::vector<Eigen::Vector3d>& light_dirs);
  [[nodiscard]] const std::vector<std::array<int, 3>>& triangles() const { return triangles_; }
  // Weights for a unit-or-not light direction (normalised here).
  [[nodiscard]] LightWeights weights(const Eigen::Vector3d& light_dir) const;

 private:
  std::vector<Eigen::Vector2d> points_;
  std::vector<std::array<int, 3>> triangles_;
};

// Blends `photos` (same size and channels, one per light of the triangulation) for a light.
[[nodiscard]] Image render_direct(const std::vector<Image>& photos,
                                  const LightTriangulation& triangulation,
                                  const Eigen::Vector3d& light_dir, LightWeights* used = nullptr);

struct DirectReport {
  LightWeights weights;
  int photos = 0;
  int triangles = 0;
  int width = 0, height = 0;
};
// Renders `light_dir` from the .lp's photos and writes `output` atomically. Checks every
// photo's header (one size and channel count) but decodes only the (at most three) photos
// the light blends.
DirectReport direct_from_light_set(const LightSet& lights, const Eigen::Vector3d& light_dir,
                                   const std::filesystem::path& output);

}  // namespace ptmkit::texture
