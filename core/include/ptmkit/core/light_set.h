// Lights of a capture: one per photograph, and the .lp file that lists them.
//
// Frame ("light frame"): x to the image's right, y to the image's top, z toward the camera.
// A distant light is a unit direction toward the light in that frame. A near light (a dome of
// finite radius) also has a position in millimetres in the sample-plane frame; the fit uses it
// to give every texel its own direction when the plane geometry is known.
#pragma once

#include <cstdint>
#include <filesystem>
#include <optional>
#include <string>
#include <vector>

#include <Eigen/Core>

namespace ptmkit {

struct Light {
  // The photograph taken under this light. Paths read from an .lp are resolved against the
  // .lp's folder, so they can be opened from anywhere.
  std::filesystem::path image;
  // Unit vector toward the light, light frame. z > 0 (above the sample plane).
  Eigen::Vector3d direction{0.0, 0.0, 1.0};
  // Position of a near light in millimetres, light frame, origin at the sample-plane centre.
  std::optional<Eigen::Vector3d> position_mm;
  // Relative intensity (1 = nominal); a calibration may estimate it.
  double intensity = 1.0;
};

struct LightSet {
  std::vector<Light> lights;
  // The file this set was read from (empty if built in memory).
  std::filesystem::path source;

  [[nodiscard]] std::size_t size() const { return lights.size(); }
  [[nodiscard]] bool empty() const { return lights.empty(); }
  [[nodiscard]] std::vector<std::filesystem::path> images() const;
  [[nodiscard]] std::vector<Eigen::Vector3d> directions() const;
};

// Reads an .lp file. Accepted: an optional first line with the count (if present it must
// match the number of entries), entries `name x y z` separated by spaces or tabs, CRLF line
// ends, blank lines, names relative to the .lp's folder (including ../), non-unit vectors
// (normalised). Errors, each naming the file and line: a missing or unreadable file, a line
// that does not parse, NaN or infinite components, a zero vector, a direction with z <= 0,
// a duplicate image, a count that does not match, no entries.
[[nodiscard]] LightSet read_lp(const std::filesystem::path& path);

// The lights of one capture applied to the photographs of another taken on the same rig in
// the same order (a light file calibrated from a chrome-sphere capture, used for an object's
// photos): light i gets images[i]; directions, positions and intensities are kept. Throws
// ptmkit::Error naming the light file when the counts differ or an image is listed twice.
[[nodiscard]] LightSet with_images(const LightSet& lights,
                                   const std::vector<std::filesystem::path>& images);

struct LpWriteOptions {
  bool count_line = true;  // write the count as the first line (most tools expect it)
  int precision = 9;       // significant digits of each component
};

// Writes an .lp atomically. Image names are written relative to the .lp's folder.
void write_lp(const std::filesystem::path& path, const LightSet& lights,
              const LpWriteOptions& options = {});

// Light JSON: the companion of the .lp for near lights, whose positions the .lp cannot hold
// (written by `ptmkit calibrate dome --json`, `calibrate sphere --json` and `ptmkit synth`
// near sets; read by `ptmkit fit --lights-json`):
//   {"frame": "...",                   informative only
//    "radius_mm": 500,                 optional: lights given by direction get
//                                      position_mm = radius_mm * direction
//    "yaw_deg": 0,                     optional: rotation about the camera axis (z), degrees
//                                      counter-clockwise seen from the camera
//    "lights": [                       one entry per light, in image order, each with
//      {"image": "a.jpg",              a name relative to the JSON's folder (optional),
//       "direction": [x, y, z],        a direction, a position (mm, light frame, origin at
//       "position_mm": [x, y, z],      the sample-plane centre) or both (they must agree),
//       "intensity": 1.0}              and optionally a relative intensity (> 0)
//    ]}
struct LightJsonReadOptions {
  // Name of light i (1-based, printf-style) when an entry has no "image".
  std::string name_pattern = "image_%03d.png";
  // Used when the file does not give them.
  double radius_mm = 0.0;
  double yaw_deg = 0.0;
};

// Reads a light JSON. Errors name the file and the entry: a missing or malformed file,
// non-numeric, non-finite or zero vectors, a light not above the plane (z <= 0), a direction
// that does not point at its position, a non-positive intensity, a dome description
// ("layout", calib's read_dome_json) given where lights are expected.
[[nodiscard]] LightSet read_light_json(const std::filesystem::path& path,
                                       const LightJsonReadOptions& options = {});

// Writes every light (image, direction, position_mm when known, intensity) atomically.
// Image names are written relative to the file's folder, as write_lp does.
void write_light_json(const std::filesystem::path& path, const LightSet& lights);

// Near lights: copies the positions of the light JSON at `light_json` onto `lights` (an .lp's
// set), matched in order. Throws ptmkit::Error naming the file when the counts or image
// names differ or a light has no position.
void attach_light_positions(LightSet* lights, const std::filesystem::path& light_json);

// Light direction from elevation above the plane and azimuth (counter-clockwise from +x, in
// the light frame), both in degrees.
[[nodiscard]] Eigen::Vector3d direction_from_angles_deg(double elevation_deg, double azimuth_deg);
[[nodiscard]] double elevation_deg(const Eigen::Vector3d& direction);

}  // namespace ptmkit
