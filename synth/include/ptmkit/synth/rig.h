// Rendered calibration rigs with known answers: a specular sphere (mirror or black glossy)
// in front of an orthographic or pinhole camera, lit by one small distant light; or several
// spheres of known size (millimetres) before a pinhole camera, lit by a distant light or a
// point light at a known position.
//
// Camera frame: x right, y down, z forward (into the scene), units of the sphere's radius
// for the pinhole camera, pixels for the orthographic one. Light directions are given in the
// light frame (x right, y toward the image top, z toward the camera).
#pragma once

#include <cstdint>
#include <optional>
#include <vector>

#include <Eigen/Core>

#include "ptmkit/core/image.h"

namespace ptmkit::synth {

// A sphere in the camera frame, millimetres.
struct RigSphere {
  Eigen::Vector3d centre_mm{0.0, 0.0, 500.0};
  double radius_mm = 25.0;
};

struct SphereRigOptions {
  int width = 400;
  int height = 400;
  // Orthographic (focal_px == 0): the sphere's circle in pixels.
  Eigen::Vector2d centre_px{200.0, 200.0};
  double radius_px = 160.0;
  // Pinhole (focal_px > 0): principal point (pixels) and the sphere's centre in the camera
  // frame in units of its radius (z > 1).
  double focal_px = 0.0;
  Eigen::Vector2d principal_px{199.5, 199.5};
  Eigen::Vector3d centre_cam{0.0, 0.0, 10.0};
  // Pinhole only: when not empty, these spheres (camera frame, mm) replace centre_cam.
  std::vector<RigSphere> spheres;
  // A point light at this position (camera frame, mm; pinhole only) instead of light_dir;
  // light_radius_deg is then its angular radius as seen from the spheres.
  std::optional<Eigen::Vector3d> light_position_mm;
  // The light: a disc of this angular radius seen in the mirror, of this brightness.
  Eigen::Vector3d light_dir{0.0, 0.0, 1.0};
  double light_radius_deg = 0.5;
  double highlight = 0.9;
  // The sphere's own dull reflection (black glossy: small; mirror of a dark room: small too)
  // and the background, full scale 1.
  double body = 0.03;
  double background = 0.35;
  // Sub-samples per pixel side (anti-aliasing), and Gaussian noise in grey levels of 8 bits.
  int supersample = 4;
  // Sub-samples per pixel side on and around the highlight (a second, finer pass; 0 or
  // <= supersample: none). A camera integrates over each pixel exactly; a few sub-samples
  // move a highlight of a pixel or two by hundredths of a pixel.
  int highlight_supersample = 0;
  double noise_grey = 0.0;
  std::uint64_t seed = 1;
};

// One grey image (1 channel, linear) of the sphere under the light.
[[nodiscard]] Image render_sphere_rig(const SphereRigOptions& options);

}  // namespace ptmkit::synth
