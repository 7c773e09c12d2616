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

// A light set for a layout, naming image i (1-based) by `pattern` with "%03d"-style
// substitution done by std::format-free zero padding: e.g. "image_%03d.png".
[[nodiscard]] LightSet layout_light_set(std::string_view spec,
                                        const std::string& name_pattern = "image_%03d.png");

}  // namespace ptmkit::calib
