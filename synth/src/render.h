// Internals shared by render.cc and capture.cc.
#pragma once

#include <cstdint>
#include <vector>

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

// Renders one light into whichever of observed / diffuse / labels are non-null (images are
// (re)allocated only if their size differs). `shadow` is a cast-shadow mask or null.
void render_into(const Scene& scene, const SynthOptions& options, const Eigen::Vector3d& light_dir,
                 int image_index, const std::uint8_t* shadow, Image* observed, Image* diffuse,
                 std::vector<std::uint8_t>* labels);

}  // namespace ptmkit::synth::detail
