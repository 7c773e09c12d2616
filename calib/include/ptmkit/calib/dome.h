// Light directions from dome geometry (no photographs needed).
//
// A layout spec names a standard dome:
//   icosa              the seed paper's once-subdivided icosahedron: 40 lights
//   geodesic:F         geodesic dome of frequency F (F = 2 is icosa)
//   dome49             5 rings at 10/30/50/70/90 degrees with 18/12/10/8/1 lights (a common
//                      49-light dome, also the SynthRTI layout)
//   rings:SPEC         elevation:count[:azimuth_offset],... in degrees
//   FILE.lp            the directions of an existing light file
#pragma once

#include <filesystem>
#include <string>
#include <string_view>
#include <vector>

#include <Eigen/Core>

#include "ptmkit/core/light_set.h"

namespace ptmkit::calib {

// Directions of a layout spec (see above), unit vectors in the light frame. Throws
// ptmkit::Error on an unknown or malformed spec.
[[nodiscard]] std::vector<Eigen::Vector3d> layout_directions(std::string_view spec);

// A dome: a layout of lights, optionally at a finite radius (near lights), rotated about the
// camera axis relative to the image.
struct DomeOptions {
  // Layout spec (above) or a dome description file (.json, see read_dome_json).
  std::string layout = "icosa";
  // Image file names, printf-style with the 1-based light index.
  std::string name_pattern = "image_%03d.png";
  // Dome radius in millimetres; 0 = distant lights (directions only). With a radius every
  // light gets position_mm = radius * direction (dome centred on the sample-plane origin).
  double radius_mm = 0.0;
  // Rotation of the dome about the camera axis (z), degrees counter-clockwise seen from the
  // camera: where the dome's azimuth 0 lies relative to the image's x axis.
  double yaw_deg = 0.0;

  [[nodiscard]] std::string validate() const;  // empty if valid
};

// The light set of a dome (directions, and positions when the radius is known). Throws
// ptmkit::Error naming the problem (and the file, for .json).
[[nodiscard]] LightSet dome_light_set(const DomeOptions& options);

// A dome description (JSON):
//   {"radius_mm": 500,                 optional: distant lights when absent or 0
//    "yaw_deg": 0,                     optional rotation about the camera axis
//    "layout": "dome49",               either a layout spec ...
//    "lights": [...]}                  ... or the lights themselves: the light JSON
//                                      (core/light_set.h, read_light_json)
// Image names default to the pattern. Errors name the file and the entry. Lights are written
// back as light JSON with write_light_json (core/light_set.h).
[[nodiscard]] LightSet read_dome_json(const std::filesystem::path& path,
                                      const DomeOptions& defaults = {});

}  // namespace ptmkit::calib
