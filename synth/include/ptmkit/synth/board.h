// Rendered AprilTag boards with known geometry: camera calibration and sample-plane tests.
//
// The board (core/board.h) is white paper with black-and-white tags drawn from the family's
// codes (the apriltag library's bitmaps, white quiet zone included), on a grey surround. It
// is seen either by a pinhole camera with Brown-Conrady lens distortion (OpenCV's model and
// conventions) at a given pose, or by an orthographic camera looking straight down. Every
// pixel averages supersample x supersample point samples (box filter over the pixel), then
// gets optional Gaussian noise. The ground truth is the inputs: intrinsics, pose, board.
//
// Output: one grey channel, values 0..1, linear colour space.
#pragma once

#include <cstdint>
#include <string>

#include <Eigen/Core>

#include "ptmkit/core/board.h"
#include "ptmkit/core/image.h"

namespace ptmkit::synth {

// OpenCV's camera model: normalised x = X / Z, y = Y / Z; r^2 = x^2 + y^2;
//   x' = x (1 + k1 r^2 + k2 r^4 + k3 r^6) + 2 p1 x y + p2 (r^2 + 2 x^2)
//   y' = y (1 + k1 r^2 + k2 r^4 + k3 r^6) + p1 (r^2 + 2 y^2) + 2 p2 x y
//   u = fx x' + cx, v = fy y' + cy (pixels, origin at the top-left pixel's centre).
struct PinholeCamera {
  int width_px = 640;
  int height_px = 480;
  double fx = 1000.0, fy = 1000.0;  // pixels
  double cx = 319.5, cy = 239.5;    // pixels
  double k1 = 0.0, k2 = 0.0, p1 = 0.0, p2 = 0.0, k3 = 0.0;

  [[nodiscard]] std::string validate() const;  // empty if valid
  // Camera-frame point (mm, z forward) to pixel.
  [[nodiscard]] Eigen::Vector2d project(const Eigen::Vector3d& point_camera) const;
  // The normalised undistorted ray (x, y) for a pixel (Newton's method on the model above;
  // converges to ~1e-12 for distortion that keeps the mapping monotonic over the image).
  [[nodiscard]] Eigen::Vector2d undistort(const Eigen::Vector2d& pixel) const;
};

// Board to camera: X_camera = camera_from_board * X_board + board_origin_in_camera_mm.
struct BoardPose {
  Eigen::Matrix3d camera_from_board = Eigen::Matrix3d::Identity();
  Eigen::Vector3d board_origin_in_camera_mm = Eigen::Vector3d::Zero();
};
// A pose looking at the board: the board's origin at `distance_mm` along the optical axis,
// the board facing the camera (board +y = image up) and then tilted by `tilt_deg` about the
// axis in the board plane at `tilt_axis_deg` from board +x (counter-clockwise), then rolled by
// `roll_deg` about the optical axis.
[[nodiscard]] BoardPose facing_pose(double distance_mm, double tilt_deg = 0.0,
                                    double tilt_axis_deg = 0.0, double roll_deg = 0.0);

struct BoardRenderOptions {
  int supersample = 4;       // samples per pixel along each axis (>= 1)
  double noise_sigma = 0.0;  // Gaussian noise, in 8-bit grey levels (/255 of full scale)
  std::uint64_t seed = 1;    // noise seed; results are a pure function of the inputs
  float paper = 0.9f;        // white paper and the tags' white cells
  float ink = 0.08f;         // the tags' black cells
  float surround = 0.5f;     // everything off the paper (and behind the camera)

  [[nodiscard]] std::string validate() const;  // empty if valid
};

// The board through a pinhole camera. Throws ptmkit::Error for an unknown family, an invalid
// board, camera or options.
[[nodiscard]] Image render_board(const TagBoard& board, const PinholeCamera& camera,
                                 const BoardPose& pose, const BoardRenderOptions& options = {});

// The board seen straight down by an orthographic camera: square pixels of `mm_per_px`, the
// image centre (pixel ((w - 1) / 2, (h - 1) / 2)) over the board origin, image up = board +y:
// the geometry of core/plane.h's orthographic_plane(width_px, height_px, mm_per_px).
[[nodiscard]] Image render_board_orthographic(const TagBoard& board, int width_px, int height_px,
                                              double mm_per_px,
                                              const BoardRenderOptions& options = {});

}  // namespace ptmkit::synth
