// AprilTag detection (the apriltag library), for camera calibration and sample-plane geometry.
//
// Pixel coordinates: x to the right, y down, origin at the centre of the top-left pixel (the
// apriltag library's convention, and OpenCV's).
#pragma once

#include <array>
#include <string>
#include <string_view>
#include <vector>

#include <Eigen/Core>

#include "ptmkit/core/image.h"

namespace ptmkit::calib {

// The standard families shipped with the apriltag library.
enum class TagFamily {
  k36h11,
  k25h9,
  k16h5,
  kCircle21h7,
  kCircle49h12,
  kStandard41h12,
  kStandard52h13,
  kCustom48h12,
};
// "tag36h11" or "36h11", "tagStandard41h12" or "standard41h12", ...; throws ptmkit::Error.
[[nodiscard]] TagFamily parse_tag_family(std::string_view name);
[[nodiscard]] std::string_view to_string(TagFamily family);  // "tag36h11", ...

struct TagDetectorOptions {
  TagFamily family = TagFamily::k36h11;
  // Quad detection on an image decimated by this factor (1 = full resolution: slowest, most
  // accurate corners; 2 is the library's speed default).
  double quad_decimate = 1.0;
  // Gaussian blur sigma in pixels before quad detection (0 = none).
  double quad_sigma = 0.0;
  // Refine quad edges on the full-resolution image (better corners when decimating).
  bool refine_edges = true;
  // Largest number of corrected bits accepted (0..3; more bits, more false positives).
  int max_hamming = 2;
  // Detections with a smaller decision margin are dropped (0 keeps all).
  double min_decision_margin = 0.0;
  int threads = 1;

  [[nodiscard]] std::string validate() const;  // empty if valid
};

struct TagDetection {
  int id = 0;
  int hamming = 0;
  double decision_margin = 0.0;
  Eigen::Vector2d centre_px{0.0, 0.0};
  // Corners in the tag's own order (counter-clockwise in the tag frame, starting bottom-left),
  // as the library reports them.
  std::array<Eigen::Vector2d, 4> corners_px{};
};

// Detects tags in an image (grey, RGB or RGBA; RGB is reduced to Rec. 601 luma, as JPEG's Y).
// Values are taken as stored (0..1 full scale). Results are sorted by id, then by centre
// (top to bottom, left to right), so the order is deterministic.
[[nodiscard]] std::vector<TagDetection> detect_tags(ConstImageViewF image,
                                                    const TagDetectorOptions& options = {});

}  // namespace ptmkit::calib
