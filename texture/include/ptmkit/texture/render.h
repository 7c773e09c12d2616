// Rendering a light-dependent texture onto geometry: a small software rasteriser.
//
// World frame = the light frame (x right, y up, z toward the default camera). Geometry, with
// texture coordinates (u, v) in [0, 1]^2 (u to the texture's right, v to its top):
//   plane     z = 0, x in +-W/(2M), y in +-H/(2M) (M = max(W, H): the texture's aspect kept);
//             N = +z, s = +x, t = +y
//   cylinder  axis y, radius 0.3, y in [-0.5, 0.5]; u = 0.5 faces +z; N outward, s around
//   sphere    radius 0.5; u longitude (0.5 faces +z), v latitude (0 south pole)
// The surface is tessellated into triangles; each is projected (orthographic or perspective)
// and rasterised with a depth buffer. Texture coordinates, normal and tangent are interpolated
// perspective-correctly (attributes / w interpolated linearly in screen space, divided by the
// interpolated 1 / w). Per pixel the tangent frame (s, t, N) is re-orthonormalised and the
// light is projected into it: (lu, lv) = (L.s, L.t); L.N <= 0 gives black (no light from
// behind). The texture footprint comes from the screen-space derivatives of the texel
// coordinates (the same triangle's interpolation one pixel right and one pixel down):
//   lod = log2(max(|d/dx|, |d/dy|)); trilinear lookup of the coefficient pyramid, or, when the
//   footprint's anisotropy max/min exceeds RenderOptions::sat_anisotropy, a summed-area box
//   of the footprint's axis-aligned extent.
#pragma once

#include <Eigen/Core>

#include "ptmkit/core/coefficients.h"
#include "ptmkit/core/image.h"

namespace ptmkit::texture {

enum class Geometry { kPlane, kCylinder, kSphere };
// "plane", "cylinder", "sphere"; throws ptmkit::Error otherwise.
[[nodiscard]] Geometry parse_geometry(std::string_view name);

enum class RenderShading {
  kPtm,           // the polynomials, evaluated at each pixel's (lu, lv)
  kPhongTexture,  // the paper's figure 1: the texture as lit from straight above its own
                  // surface (lu = lv = 0), modulated by Phong shading of the smooth geometry:
                  // tex * (0.1 + 0.9 max(0, N.L)) + 0.2 max(0, N.H)^40
  kLuminance,     // the paper's figure 6: an RGB texture reduced to one luminance polynomial
                  // (Rec. 601 combination of the three) with constant chroma per texel
};

enum class RenderFilter {
  kAuto,       // trilinear, or summed-area when the footprint is anisotropic
  kBilinear,   // level 0 only (aliases when minified; for references and comparisons)
  kTrilinear,  // always the pyramid
  kSat,        // always the summed-area box
};

struct RenderCamera {
  Eigen::Vector3d position{0.0, 0.0, 3.0};
  Eigen::Vector3d target{0.0, 0.0, 0.0};
  Eigen::Vector3d up{0.0, 1.0, 0.0};
  // Vertical field of view in degrees; 0 = orthographic.
  double fov_y_deg = 0.0;
  // Orthographic only: world units covered by the image height.
  double ortho_height = 1.2;
  int width = 256;   // pixels
  int height = 256;  // pixels
};

struct RenderOptions {
  Geometry geometry = Geometry::kPlane;
  // Direction toward a distant light, world frame (normalised here).
  Eigen::Vector3d light_dir{0.0, 0.0, 1.0};
  RenderCamera camera;
  RenderShading shading = RenderShading::kPtm;
  RenderFilter filter = RenderFilter::kAuto;
  // Evaluate with the integer model (the paper's bytes, docs/INTEGER-MODEL.md) instead of
  // float. Filtered coefficients are re-quantised with the level-0 shifts (an average never
  // exceeds the range they were chosen for).
  bool integer = false;
  // Quads per side of the (u, v) grid (2 triangles each).
  int tessellation = 48;
  // Footprints more anisotropic than this use the summed-area table (kAuto).
  double sat_anisotropy = 2.0;
  float background = 0.0f;
  // Debug output instead of shading: channels (u, v, lod) where covered, background elsewhere.
  bool output_texcoords = false;
};

struct RenderReport {
  int triangles = 0;          // rasterised (in front of the camera)
  std::size_t covered = 0;    // pixels covered
  std::size_t trilinear = 0;  // pixels filtered by the pyramid
  std::size_t sat = 0;        // pixels filtered by the summed-area table
  double mean_lod = 0.0;      // over covered pixels
};

// Renders `map` on the geometry. Output: 3 channels in the map's colour space, clamped to
// [0, 1]. Throws ptmkit::Error for an empty map, a bad size (1..16384), a camera at its target
// or with a degenerate up vector, a non-finite or zero light.
[[nodiscard]] Image render_texture(const CoefficientMap& map, const RenderOptions& options,
                                   RenderReport* report = nullptr);

// kRGB -> kYCC: Y = 0.299 R + 0.587 G + 0.114 B polynomial, (Cb, Cr) from the texel's value
// under an overhead light (its a5 terms). Other models are returned unchanged.
[[nodiscard]] CoefficientMap to_luminance_polynomial(const CoefficientMap& map);

}  // namespace ptmkit::texture
