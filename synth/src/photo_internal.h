// Internals of the photo renderer (photo.h): the scene (photo.cc), shading (photo_render.cc),
// the lens and sensor (photo_sensor.cc) and the capture folder (photo_capture.cc).
#pragma once

#include <cstdint>
#include <limits>
#include <vector>

#include <Eigen/Core>

#include "ptmkit/core/image.h"
#include "ptmkit/synth/photo.h"
#include "ptmkit/synth/synth.h"

namespace ptmkit::synth::detail {

enum class HitKind : std::uint8_t { kNone, kGround, kSphere, kBase, kCamera };

struct Hit {
  double t = std::numeric_limits<double>::infinity();
  HitKind kind = HitKind::kNone;
  int index = -1;
  Eigen::Vector3d point = Eigen::Vector3d::Zero();
};

// What a primary sample saw: its radiance and an id of the surface (edges between ids, and
// bright samples, are supersampled).
struct Sample {
  Eigen::Array3d rgb = Eigen::Array3d::Zero();
  int id = 0;
  bool hot = false;
};

struct Window {
  double azimuth = 0.0, elevation = 0.0, half_width = 0.0, half_height = 0.0;  // radians
};
struct Lamp {
  Eigen::Vector3d dir = Eigen::Vector3d::UnitZ();
  double cos_radius = 1.0;
};
// A sphere's cup: a cylinder along "down" from the rim that holds the sphere to the ground.
struct Base {
  bool on = false;
  Eigen::Vector3d rim_mm = Eigen::Vector3d::Zero();
  double radius_mm = 0.0;        // the cup: where the sphere rests
  double outer_radius_mm = 0.0;  // the stand's side
  double length_mm = 0.0;
};

// The per-light state of a render: the light in the camera frame and the object's shading.
struct LightState {
  int index = 0;
  Eigen::Vector3d l_cam = Eigen::Vector3d::UnitZ();  // toward the light, camera frame
  Image relief;                                      // the object's radiance, 3 channels
};

class PhotoScene {
 public:
  explicit PhotoScene(const PhotoOptions& options);

  PhotoOptions o;
  std::vector<Eigen::Vector3d> light_dirs;
  Eigen::Vector2d pp{0.0, 0.0};
  // World up (the ground's normal) in the camera frame; ground plane up . p = ground_offset;
  // ground coordinates (u, v) = ((p - ground_origin) . g1, (p - ground_origin) . g2); room
  // azimuth basis a1, a2.
  Eigen::Vector3d up, ground_origin, g1, g2, a1, a2;
  double ground_offset = 0.0;
  std::vector<Base> bases;
  std::vector<Window> windows;
  std::vector<Lamp> lamps;
  double ambient = 0.0;  // irradiance of the room on every surface (static)
  double light_cos_radius = 1.0, light_radiance = 0.0;
  double glass_cos_radius = 1.0, glass_radiance = 0.0;
  bool has_object = false;
  SynthOptions relief_options;
  Scene relief;
  PhotoTruth truth;
  // Pixels supersampled in every image (edges, contrast and saturation of the static scene),
  // so what does not change with the light is sampled alike in every image.
  std::vector<std::uint8_t> static_refine;

  [[nodiscard]] Eigen::Array3d environment(const Eigen::Vector3d& w) const;
  [[nodiscard]] double light_term(const Eigen::Vector3d& w, const Eigen::Vector3d& l,
                                  bool through_glass) const;
  [[nodiscard]] Hit intersect(const Eigen::Vector3d& origin, const Eigen::Vector3d& d,
                              bool camera_body, int skip_sphere) const;
  [[nodiscard]] double light_visibility(const Eigen::Vector3d& p, const Eigen::Vector3d& l,
                                        int skip_sphere) const;
  [[nodiscard]] double caustic(const Eigen::Vector3d& p, const Eigen::Vector3d& l) const;

  // photo_render.cc
  [[nodiscard]] LightState light_state(int index) const;
  // Radiance along a ray. `light` null: static (room light only: what reflections show).
  [[nodiscard]] Eigen::Array3d radiance(const Eigen::Vector3d& origin, const Eigen::Vector3d& d,
                                        const LightState* light, int depth, int skip_sphere,
                                        int* id) const;
  // One primary sample; `light` null: the static scene.
  [[nodiscard]] Sample sample(double x, double y, const LightState* light) const;
  // Linear radiance (exposure applied), before the lens artefacts.
  [[nodiscard]] Image trace(const LightState& light) const;

 private:
  void build_truth();
  void build_static_refine();
  [[nodiscard]] Eigen::Array3d ground(const Eigen::Vector3d& p, const Eigen::Vector3d& view,
                                      const LightState* light, int* id) const;
  [[nodiscard]] Eigen::Array3d sphere(int i, const Eigen::Vector3d& p, const Eigen::Vector3d& d,
                                      const LightState* light, int depth) const;
  [[nodiscard]] Eigen::Array3d reflection(int i, const Eigen::Vector3d& p, const Eigen::Vector3d& r,
                                          const LightState* light, int depth) const;
};

// photo_sensor.cc: image `index`'s exposure factor (PhotoArtefacts::exposure_jitter_ev; 1
// without jitter) and its shake (PhotoArtefacts::shake_px; zero without), pure functions of
// the seed and the index.
[[nodiscard]] double exposure_jitter(const PhotoOptions& o, int index);
[[nodiscard]] Eigen::Vector2d shake_offset(const PhotoOptions& o, int index);
// The image shifted by `offset` pixels (bilinear; edges repeat), in place.
void apply_shake(const Eigen::Vector2d& offset, Image* radiance);
// Vignetting, flare and bloom on linear radiance, in place.
void apply_lens(const PhotoOptions& o, Image* radiance);
// Noise, clipping, encoding and quantisation: the file's values.
[[nodiscard]] Image apply_sensor(const PhotoOptions& o, const Image& radiance, int image_index);

}  // namespace ptmkit::synth::detail
