// Internals shared by render.cc and capture.cc.
#pragma once

#include <cstdint>
#include <vector>

#include "ptmkit/core/plane.h"
#include "ptmkit/synth/synth.h"

namespace ptmkit::synth::detail {

// The sensor model: radiance -> encoded value (exposure, optional sRGB) -> + noise ->
// quantised and clipped (integer outputs). Values are normalised (1 = full scale).
class Sensor {
 public:
  explicit Sensor(const SynthOptions& options);
  [[nodiscard]] double encode(double radiance) const;
  // Clipping and quantisation of an encoded (possibly noisy) value.
  [[nodiscard]] double finish(double encoded) const;
  [[nodiscard]] double sigma() const { return sigma_; }
  [[nodiscard]] double highlight_threshold() const { return highlight_; }
  [[nodiscard]] bool integer() const { return integer_; }
  [[nodiscard]] std::uint64_t seed() const { return seed_; }

 private:
  double exposure_;
  bool srgb_;
  bool integer_;
  double levels_;     // grey levels at full scale (255, 65535; 255 for float output)
  double sigma_;      // noise standard deviation, normalised units
  double highlight_;  // highlight threshold, normalised units
  std::uint64_t seed_;
};

// One light as each texel sees it: the nominal direction everywhere (distant), or the
// direction toward the light's position and its inverse-square fall-off (near lights, see
// SynthOptions::dome_radius_mm).
class TexelLight {
 public:
  TexelLight(const Scene& scene, const SynthOptions& options, const Eigen::Vector3d& light_dir);
  [[nodiscard]] bool near() const { return near_; }
  [[nodiscard]] const Eigen::Vector3d& nominal() const { return dir_; }
  // Unit direction toward the light from texel (x, y); *falloff (if non-null) its relative
  // intensity (1 for distant lights or with fall-off off).
  [[nodiscard]] Eigen::Vector3d at(int x, int y, double* falloff) const;

 private:
  const Scene& scene_;
  Eigen::Vector3d dir_;
  bool near_ = false;
  bool falloff_ = false;
  Eigen::Vector3d position_mm_ = Eigen::Vector3d::Zero();
  double position_sq_ = 0.0;
  double mm_per_px_ = 1.0;
  SamplePlane plane_;
};

// Renders one light into whichever of observed / diffuse / labels are non-null (images are
// (re)allocated only if their size differs). `shadow` is a cast-shadow mask or null.
void render_into(const Scene& scene, const SynthOptions& options, const Eigen::Vector3d& light_dir,
                 int image_index, const std::uint8_t* shadow, Image* observed, Image* diffuse,
                 std::vector<std::uint8_t>* labels);

}  // namespace ptmkit::synth::detail
