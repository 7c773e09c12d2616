// Export to the web format that relight writes and OpenLIME displays: a folder with
// `info.json` and the coefficient planes as JPEG images, three planes per JPEG, optionally
// tiled as deep-zoom pyramids, plus this project's own WebGL2 viewer (`index.html`).
//
// Folder layout (docs/WEB.md):
//   info.json            width, height, format "jpg", type "ptm" | "hsh", colorspace "rgb" |
//                        "lrgb", nplanes, quality, materials [{scale: [...], bias: [...]}]
//                        (one value per plane), optional pixelSizeInMM; a "ptmkit" object
//                        names the layout and whether normals.png exists
//   plane_J.jpg          (layout image) JPEG J holds planes 3J, 3J+1, 3J+2 as its R, G, B
//   plane_J.dzi          (layout deepzoom) the DZI descriptor, Overlap 1, and
//   plane_J_files/L/X_Y.jpg   tiles; level 0 is the single tile, the last level is full size;
//                        each tile holds one more pixel on each side that has a neighbour
//   normals.png          optional, (n + 1) / 2 with x right, y up the image, z toward the viewer
//   index.html, viewer.js, viewer.css   the viewer (served over HTTP: `ptmkit view DIR`)
//
// Planes: plane k decodes as coef = (byte / 255 - bias[k]) * scale[k], coefficients in the
// texture's normalised units (1.0 = full scale). Which coefficient is plane k:
//   ptm rgb  (18): JPEG j holds basis term j of R, G, B, terms ordered 1, u, v, u^2, uv, v^2
//                  (the .ptm's a5, a3, a4, a0, a2, a1)
//   ptm lrgb (9):  plane_0 the per-texel RGB colour (scale 1, bias 0), planes 3..8 the six
//                  luminance terms in the order above
//   hsh rgb  (3T): JPEG j holds HSH term j (the .rti's order) of R, G, B; T = 4, 9 or 16
// A YCC-model map (an RGB map whose three polynomials share a0..a4) is exported as ptm rgb.
#pragma once

#include <cstddef>
#include <filesystem>
#include <string>
#include <string_view>
#include <vector>

#include "ptmkit/core/coefficients.h"
#include "ptmkit/texture/rti.h"

namespace ptmkit::texture {

enum class WebLayout {
  kImage,     // one plane_J.jpg per JPEG
  kDeepZoom,  // plane_J.dzi and plane_J_files/LEVEL/X_Y.jpg
};
// "image" or "deepzoom"; parse throws ptmkit::Error for anything else.
[[nodiscard]] std::string to_string(WebLayout layout);
[[nodiscard]] WebLayout parse_web_layout(const std::string& name);

// The JPEG colour transform of the planes.
enum class WebJpegColour {
  kAuto,   // the format's convention: YCbCr for colorspace rgb, none (RGB components) otherwise
  kYCbCr,  // the ordinary JPEG transform (smaller files; about 1-2 more bytes of plane error)
  kNone,   // R, G, B stored as components (Adobe marker), the least plane error
};
// "auto", "ycbcr", "none"; parse throws ptmkit::Error for anything else.
[[nodiscard]] std::string to_string(WebJpegColour colour);
[[nodiscard]] WebJpegColour parse_web_jpeg_colour(const std::string& name);

struct WebExportOptions {
  WebLayout layout = WebLayout::kImage;
  // Tile side in pixels for the deep-zoom layout (16..4096).
  int tile_size_px = 256;
  // JPEG quality, 1..100 (100: the smallest loss libjpeg offers; the planes stay lossy).
  int quality = 95;
  WebJpegColour jpeg_colour = WebJpegColour::kAuto;
  // Optional normal map to copy as normals.png: an .exr holding x, y, z in -1..1, or an
  // 8/16-bit image holding (n + 1) / 2 (what `ptmkit fit --normals` writes). Same size as the
  // texture. Empty: no normals.png.
  std::filesystem::path normals;
  // Physical size of a pixel in mm (written as pixelSizeInMM; the viewer's scale bar). 0 =
  // unknown (not written).
  double pixel_size_mm = 0.0;
  // Write index.html, viewer.js and viewer.css beside the planes.
  bool viewer = true;
  // Replace an existing export at the output folder (one holding info.json). An existing
  // folder that does not look like an export is never replaced.
  bool overwrite = true;
};

struct WebExportReport {
  std::filesystem::path dir;
  std::string type;        // "ptm" or "hsh"
  std::string colorspace;  // "rgb" or "lrgb"
  int width = 0, height = 0;
  int planes = 0;
  int jpegs = 0;   // ceil(planes / 3)
  int levels = 1;  // deep-zoom levels (1 for the image layout)
  std::size_t files = 0;
  std::size_t bytes = 0;
  std::vector<double> scale, bias;  // per plane, as written to info.json
  // Largest difference between a coefficient and its 8-bit plane value before JPEG coding
  // (normalised units): the rounding step's half, at most.
  double max_quantisation_error = 0.0;
  // Per-plane JPEG coding error of the full-size planes, measured by decoding what was written:
  // the largest and mean absolute difference in bytes (0..255) over every plane.
  double jpeg_max_abs_byte = 0.0;
  double jpeg_mean_abs_byte = 0.0;
  bool normals = false;
  [[nodiscard]] std::string brief() const;
};

// Writes the export into `dir`, built in a temporary folder beside it and renamed into place
// when complete (a failure leaves no partial folder; an existing export is replaced only
// once the new one is complete). Throws ptmkit::Error naming the path and the problem: a
// malformed or empty map, non-finite coefficients, a normal map of the wrong size, bad
// options, or a failed write.
// Any basis: a PTM map (rgb, lrgb, ycc) or an HSH map (.rti's rgb layout).
WebExportReport export_web(const CoefficientMap& map, const std::filesystem::path& dir,
                           const WebExportOptions& options = {});

// The deep-zoom level count OpenLIME computes for an image: ceil(log2(max(w, h) / tile)) + 1,
// at least 1. Level 0 is the single tile; level sizes halve with floor from the full size.
[[nodiscard]] int web_deepzoom_levels(int width, int height, int tile_size_px);

// The viewer's files, as embedded in the library: name ("index.html", "viewer.js",
// "viewer.css") and contents.
struct WebViewerFile {
  const char* name;
  std::string_view contents;
};
[[nodiscard]] const std::vector<WebViewerFile>& web_viewer_files();

}  // namespace ptmkit::texture
