// Rendered calibration rigs with known answers: a specular sphere (mirror or black glossy)
// in front of an orthographic or pinhole camera, lit by one small distant light.
//
// Camera frame: x right, y down, z forward (into the scene), units of the sphere's radius
// for the pinhole camera, pixels for the orthographic one. Light directions are given in the
// light frame (x right, y toward the image top, z toward the camera).
#pragma once

#include <cstdint>

#include <Eigen/Core>

#include "ptmkit/core/image.h"

namespace ptmkit::synth {

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
  double noise_grey = 0.0;
  std::uint64_t seed = 1;
};

// One grey image (1 channel, linear) of the sphere under the light.
[[nodiscard]] Image render_sphere_rig(const SphereRigOptions& options);

}  // namespace ptmkit::synth
