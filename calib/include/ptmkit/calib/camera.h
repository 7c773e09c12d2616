// Camera calibration and sample-plane geometry from photographs of an AprilTag board
// (core/board.h).
//
// Camera model: OpenCV's pinhole with Brown-Conrady distortion (k1, k2, p1, p2, k3); pixels x
// right, y down, origin at the centre of the top-left pixel; camera frame x right, y down,
// z forward. See synth/board.h for the formulas.
#pragma once

#include <filesystem>
#include <functional>
#include <optional>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "ptmkit/calib/apriltag.h"
#include "ptmkit/calib/sphere.h"
#include "ptmkit/core/board.h"
#include "ptmkit/core/image.h"
#include "ptmkit/core/plane.h"

namespace ptmkit::calib {

struct CameraIntrinsics {
  int width_px = 0;
  int height_px = 0;
  double fx = 0.0, fy = 0.0;  // focal lengths, pixels
  double cx = 0.0, cy = 0.0;  // principal point, pixels
  double k1 = 0.0, k2 = 0.0, p1 = 0.0, p2 = 0.0, k3 = 0.0;
  double rms_px = 0.0;  // reprojection rms of the calibration that produced it (0 = unknown)

  [[nodiscard]] std::string validate() const;  // empty if valid
  // Detected (distorted) pixels to ideal pinhole pixels with the same fx, fy, cx, cy.
  [[nodiscard]] std::vector<Eigen::Vector2d> undistort(
      const std::vector<Eigen::Vector2d>& pixels) const;
};

// JSON: {"width_px", "height_px", "fx", "fy", "cx", "cy", "k1", "k2", "p1", "p2", "k3",
// "rms_px"}. Errors (ptmkit::Error) name the file and the problem.
[[nodiscard]] CameraIntrinsics read_camera_json(const std::filesystem::path& path);

// The perspective camera of sphere calibration from intrinsics: the mean of fx and fy, and the
// principal point (lens distortion is not removed from the photographs: near the image centre
// it moves a highlight by a fraction of a pixel with a normal lens). Throws ptmkit::Error, naming
// `source`, when the photographs are not the size the camera was calibrated at.
[[nodiscard]] SphereCamera sphere_camera(const CameraIntrinsics& camera, int width_px,
                                         int height_px, const std::filesystem::path& source = {});

// Focal length in pixels of a lens of `focal_mm` on a sensor `sensor_width_mm` wide whose full
// width is `width_px` pixels. Throws ptmkit::Error unless both lengths are positive.
[[nodiscard]] double focal_px_from_lens(double focal_mm, double sensor_width_mm, int width_px);
void write_camera_json(const std::filesystem::path& path, const CameraIntrinsics& camera);

// The focal length the photographs' EXIF gives (core/image_io.h, ImageInfo::focal_px), when
// every photograph gives one and they agree within 0.5% (one lens, one zoom setting):
// focal_px > 0, and `note` says from which tags. Otherwise focal_px is 0 and `note` says why
// (none says, some do not, or they differ: a zoom turned during the capture). Reads headers
// only. Throws ptmkit::Error naming an unreadable file.
struct PhotoFocal {
  double focal_px = 0.0;
  std::string note;
};
[[nodiscard]] PhotoFocal focal_from_exif(const std::vector<std::filesystem::path>& photos);

// Where a sphere calibration's focal length comes from: at most one of a camera file
// (`ptmkit calibrate camera`), a lens (focal_mm on a sensor sensor_width_mm wide) or a focal
// length in pixels; none of them: the photographs' EXIF focal length (exif_focal_px, from
// focal_from_exif) where there is one, else an orthographic camera.
struct CameraSource {
  std::filesystem::path camera_json;  // empty: none
  double focal_mm = 0.0;              // 0: none; needs sensor_width_mm
  double sensor_width_mm = 0.0;
  double focal_px = 0.0;       // 0: none
  double exif_focal_px = 0.0;  // 0: none; used only when none of the above is given
  std::string exif_note;       // PhotoFocal::note
  // Overrides the camera file's principal point (pixels); nullopt: the file's, else the image
  // centre.
  std::optional<Eigen::Vector2d> principal_px;
};

// The camera of `source` for photographs width_px x height_px. Throws ptmkit::Error when more
// than one focal length is given ("give the focal length once"), a lens lacks its sensor
// width, or the camera file is unreadable or of another image size (naming the file).
[[nodiscard]] SphereCamera resolve_sphere_camera(const CameraSource& source, int width_px,
                                                 int height_px);

struct CameraCalibrationOptions {
  // Detector settings; the family comes from the board unless `family` is given.
  TagDetectorOptions detector;
  std::optional<TagFamily> family;
  // A view with fewer tags of the board than this is rejected (4 tags = 16 corners).
  int min_tags_per_view = 4;
  // Keep k3 at zero (cv::CALIB_FIX_K3). On: the sixth-order term is not identifiable from a
  // board that stays off the image corners. On 8 rendered views of a lens with k3 = 0 (see
  // tests/calib_camera_test.cc) freeing it gave the same focal error (0.038% against 0.034%)
  // and k3 = -3.8, with k2 pulled from 0.35 to 0.63 to compensate. Turn off for wide-angle
  // lenses, with views that put tags in the image corners.
  bool fix_k3 = true;
  // Keep p1 = p2 = 0 (cv::CALIB_ZERO_TANGENT_DIST). Off.
  bool zero_tangential = false;
  // Keep fx = fy (cv::CALIB_FIX_ASPECT_RATIO with aspect 1). Off.
  bool square_pixels = false;

  [[nodiscard]] std::string validate() const;  // empty if valid
};

struct CameraView {
  std::string image;      // file name (or "view N")
  int tags_detected = 0;  // all detections of the family
  int tags_used = 0;      // detections matched to a board tag (unique id)
  bool used = false;
  std::string reason;   // why the view was rejected
  double rms_px = 0.0;  // reprojection rms of this view's corners
  Eigen::Matrix3d camera_from_board = Eigen::Matrix3d::Identity();
  Eigen::Vector3d board_origin_in_camera_mm = Eigen::Vector3d::Zero();
};

struct CameraReport {
  CameraIntrinsics camera;
  std::vector<CameraView> views;
  int views_used = 0;
  int corners_used = 0;
  double rms_px = 0.0;  // overall reprojection rms over all used corners
  int flags = 0;        // the cv::calibrateCamera flags used
  [[nodiscard]] std::string to_json() const;
};

// Calibrates from views of the board (any image size, all the same). Uses
// cv::calibrateCamera on the matched tag corners (object points z = 0). `names` (optional,
// else "view N") label the views in the report. Throws ptmkit::Error when fewer than 3 views
// are usable (the message lists why each was rejected), for mixed image sizes, bad options,
// or an unknown family.
[[nodiscard]] CameraReport calibrate_camera(const std::vector<Image>& images,
                                            const std::vector<std::filesystem::path>& names,
                                            const TagBoard& board,
                                            const CameraCalibrationOptions& options = {});
// The same, loading view i by load(i) when it is needed, so only one photograph is in memory
// at a time (what `ptmkit calibrate camera` uses: a board shot at 24 megapixels is 290 MB as
// floats).
[[nodiscard]] CameraReport calibrate_camera(std::size_t views,
                                            const std::function<Image(std::size_t)>& load,
                                            const std::vector<std::filesystem::path>& names,
                                            const TagBoard& board,
                                            const CameraCalibrationOptions& options = {});

struct PlaneOptions {
  TagDetectorOptions detector;
  std::optional<TagFamily> family;
  // The plane frame's origin, in board mm: the sample-plane centre (light positions are
  // relative to it). Default: the board's origin.
  Eigen::Vector2d origin_mm = Eigen::Vector2d::Zero();
  [[nodiscard]] std::string validate() const;
};

struct PlaneReport {
  SamplePlane plane;  // homography for UNDISTORTED pixels (see estimate_plane), with pose
  int tags_used = 0;
  int corners_used = 0;
  std::vector<int> tag_ids;
  double rms_px = 0.0;  // reprojection rms in the photograph (distortion applied)
  // Angle between the plane normal and the optical axis (0 = camera looks straight down).
  double tilt_deg = 0.0;
  double distance_mm = 0.0;  // camera centre to the plane origin
  [[nodiscard]] std::string to_json() const;
};

// The board's pose from one photograph: tag corners undistorted with the intrinsics,
// cv::solvePnP (IPPE for a planar target, then Levenberg-Marquardt refinement), giving the
// plane frame = the board frame shifted to `origin_mm` (x along the board's rows, y up the
// board, z toward the camera). plane.pixel_to_plane_mm is the inverse of K [r1 r2 t]: it maps
// an UNDISTORTED pixel (lens distortion removed with the same intrinsics) to plane mm; for a
// photograph with distortion, undistort the pixel first. Throws ptmkit::Error when the image
// size differs from the intrinsics', or fewer than 1 board tag (4 corners) is found.
[[nodiscard]] PlaneReport estimate_plane(const Image& image, const TagBoard& board,
                                         const CameraIntrinsics& camera,
                                         const PlaneOptions& options = {});

}  // namespace ptmkit::calib
