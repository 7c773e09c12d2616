// The sample plane: where each pixel's texel lies, in millimetres. Near lights (a dome of
// finite radius) need it: every texel sees each light from its own direction, at its own
// distance.
//
// Frames. Pixels: x right, y down, origin at the centre of the top-left pixel. Plane frame =
// the light frame (core/light_set.h): x along the texture's s axis (the image's right), y
// along t (toward the image's top), z along the plane normal N (toward the camera), origin at
// the sample-plane centre, millimetres. Light positions (Light::position_mm) are in this
// frame, so a texel at plane point p = (X, Y, 0) sees light i along normalise(P_i - p).
#pragma once

#include <filesystem>
#include <optional>

#include <Eigen/Core>

namespace ptmkit {

// Where the camera is, when known (from `ptmkit calibrate plane`): the pose of the plane
// frame in the camera frame (OpenCV: x right, y down, z forward), X_cam = R * X_plane + t.
struct PlanePose {
  Eigen::Matrix3d camera_from_plane = Eigen::Matrix3d::Identity();      // R; columns s, t, N
  Eigen::Vector3d plane_origin_in_camera_mm = Eigen::Vector3d::Zero();  // t
};

struct SamplePlane {
  // The image size this geometry belongs to; a capture of another size is refused.
  int width_px = 0;
  int height_px = 0;
  // Homography from a pixel (x_px, y_px, 1) to the plane point (X_mm, Y_mm, W) / W. Exactly
  // affine for an orthographic camera; projective for a pinhole camera (then from the
  // board pose and the intrinsics, lens distortion removed beforehand).
  Eigen::Matrix3d pixel_to_plane_mm = Eigen::Matrix3d::Identity();
  std::optional<PlanePose> pose;

  // The plane point (mm) under a pixel.
  [[nodiscard]] Eigen::Vector2d plane_mm(const Eigen::Vector2d& pixel) const;
  // The same for a pixel centre (x, y) given as integers; cheap enough per texel.
  [[nodiscard]] Eigen::Vector2d plane_mm(int x_px, int y_px) const {
    return plane_mm(Eigen::Vector2d(x_px, y_px));
  }
  // Mean size of a pixel on the plane (mm), over the image: for reports.
  [[nodiscard]] double mean_mm_per_px() const;
};

// An orthographic camera looking straight down at the plane: square pixels of `mm_per_px`,
// the image centre at the plane origin, image up = plane +y.
[[nodiscard]] SamplePlane orthographic_plane(int width_px, int height_px, double mm_per_px);

// JSON file:
//   {"width_px": W, "height_px": H,
//    "pixel_to_plane_mm": [[h00, h01, h02], [h10, h11, h12], [h20, h21, h22]],
//    "camera_from_plane": [[..], [..], [..]],          optional (with the next)
//    "plane_origin_in_camera_mm": [tx, ty, tz],        optional
//    "mm_per_px": m}                                    informational, written only
// Errors (ptmkit::Error) name the file and the problem: unreadable, malformed, a singular
// homography, non-finite values, a non-orthonormal rotation, a size <= 0.
[[nodiscard]] SamplePlane read_plane_json(const std::filesystem::path& path);
void write_plane_json(const std::filesystem::path& path, const SamplePlane& plane);

}  // namespace ptmkit
