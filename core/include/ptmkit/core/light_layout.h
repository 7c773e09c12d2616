// Standard light layouts: geodesic domes and rings of lights. Directions are unit vectors in
// the light frame (see light_set.h), all strictly above the horizon.
#pragma once

#include <string_view>
#include <vector>

#include <Eigen/Core>

namespace ptmkit {

// Geodesic dome: an icosahedron (a vertex at the zenith) whose faces are each split into
// frequency^2 triangles and projected onto the unit sphere; one light at the centre of each
// face above the horizon. frequency 1 is the plain icosahedron (10 lights); frequency 2 is the
// seed paper's once-subdivided icosahedron (40 lights). Order: by elevation, then azimuth.
[[nodiscard]] std::vector<Eigen::Vector3d> geodesic_dome(int frequency);

struct Ring {
  double elevation_deg = 45.0;
  int count = 8;
  double azimuth_offset_deg = 0.0;  // azimuth of the first light, counter-clockwise from +x
};

// Parses "elevation:count[:azimuth_offset],..." (degrees). Throws ptmkit::Error on a
// malformed spec, a count < 1, or an elevation outside (0, 90].
[[nodiscard]] std::vector<Ring> parse_rings(std::string_view spec);

// Lights evenly spaced in azimuth on each ring; a ring at 90 degrees is one light.
[[nodiscard]] std::vector<Eigen::Vector3d> ring_layout(const std::vector<Ring>& rings);

}  // namespace ptmkit
