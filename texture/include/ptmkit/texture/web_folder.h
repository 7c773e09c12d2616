// Reading the web format that relight exports and OpenLIME displays: a folder holding
// `info.json` and the coefficient planes as JPEGs.
//
// info.json: width, height, format ("jpg"), type ("ptm" | "hsh" read; "sh", "rbf",
// "bilinear", ... refused), colorspace ("rgb" | "lrgb" read; "mrgb", "mycc", "ycc" refused),
// nplanes, quality, materials[0].scale and .bias (one per plane), optional pixelSizeInMM and
// lights (flat x, y, z list). Plane k (0-based) is channel k % 3 (R, G, B) of JPEG k / 3 and
// decodes as coefficient = (byte / 255 - bias[k]) * scale[k], in normalised intensity units.
//   ptm, rgb:  18 planes; JPEG j holds basis term j of R, G, B, terms in the order
//              1, u, v, u^2, uv, v^2 (mapped here to the .ptm order u^2, v^2, uv, u, v, 1).
//   ptm, lrgb: 9 planes; JPEG 0 the RGB colour, JPEGs 1 and 2 the six luminance terms in the
//              order above; the value is colour * luminance.
//   hsh, rgb:  3 x T planes (T = 4, 9 or 16 terms); JPEG j holds term j of R, G, B (the .rti's
//              term order and basis, core/hsh.h).
// Layouts (found from the files present): `image` (plane_J.jpg) and `deepzoom` (plane_J.dzi
// and plane_J_files/LEVEL/COL_ROW.jpg; the highest level is read and its tiles stitched,
// overlaps dropped). Others (tarzoom's plane_J.tzi, ...) are refused. Rows are top to bottom
// as in any image. Every refusal of a variant uses texture/formats.h's wording.
#pragma once

#include <filesystem>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "ptmkit/core/coefficients.h"
#include "ptmkit/texture/rti.h"

namespace ptmkit::texture {

struct WebFolderInfo {
  std::filesystem::path folder;
  int width = 0;
  int height = 0;
  std::string type;        // "ptm" or "hsh"
  std::string colorspace;  // "rgb" or "lrgb"
  std::string layout;      // "image" or "deepzoom"
  int nplanes = 0;
  int quality = 0;  // 0 when info.json does not say
  std::vector<double> scale, bias;
  double pixel_size_mm = 0.0;  // 0 when unknown
  std::vector<Eigen::Vector3d> lights;
  int tile_size = 0;  // deepzoom only
  int overlap = 0;    // deepzoom only
  [[nodiscard]] int jpegs() const { return (nplanes + 2) / 3; }
};

// True for a folder that holds info.json, or a path to a file named info.json.
[[nodiscard]] bool is_web_folder(const std::filesystem::path& path);
// The folder (given as the folder or its info.json) described, every field checked: a
// missing or malformed info.json, a missing key, a type, colour space, format or layout not
// supported, a plane count that does not fit the type, scale/bias arrays of the wrong length
// or not finite, an absurd size, no plane files.
[[nodiscard]] WebFolderInfo read_web_info(const std::filesystem::path& path);

// The planes decoded into a texture. For type ptm (`ptm` set) or hsh (`hsh` set); the caller
// says what the values are (`colour_space`). Errors name the file: an unreadable or corrupt
// JPEG, a plane or tile of the wrong size, a missing tile.
struct WebTexture {
  WebFolderInfo info;
  bool is_hsh = false;
  CoefficientMap ptm;
  CoefficientMap hsh;  // an HSH basis in the rgb layout (rti.h)
};
[[nodiscard]] WebTexture read_web_folder(const std::filesystem::path& path,
                                         ColourSpace colour_space = ColourSpace::kSRGB);

}  // namespace ptmkit::texture
