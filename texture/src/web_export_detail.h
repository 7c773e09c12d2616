// Internal to the web export (web_export.h): the planes of a map (web_export_planes.cc), and a
// JPEG's three planes quantised, halved and coded (web_export_jpeg.cc), for web_export.cc.
#pragma once

#include <algorithm>
#include <array>
#include <cmath>
#include <functional>
#include <string>
#include <vector>

#include "ptmkit/core/coefficients.h"

namespace ptmkit::texture::internal {

// ---- The planes of a map (web_export_planes.cc). --------------------------------------------

// The one place the texture maps are read: what a map is in the web format's terms, and a
// function that fills one row of texels with every plane's coefficient (normalised units).
struct PlaneSource {
  std::string type;        // "ptm" or "hsh"
  std::string colorspace;  // "rgb" or "lrgb"
  int width = 0, height = 0;
  int planes = 0;
  // Planes holding a colour in 0..1, written with scale 1 and bias 0 (lrgb's plane_0).
  int fixed_unit_planes = 0;
  // out: width * planes floats, [x][plane].
  std::function<void(int y, float* out)> fill_row;
};

// A PTM map's planes (rgb, lrgb, or ycc written as rgb), the terms in the web order.
PlaneSource planes_of(const CoefficientMap& map);
// An HSH map's planes (the rgb layout .rti holds).
PlaneSource hsh_planes_of(const CoefficientMap& map);
// Per-plane minimum and maximum over every texel; throws on a non-finite coefficient.
void plane_ranges(const PlaneSource& src, std::vector<double>* lo, std::vector<double>* hi);

// ---- A JPEG's three planes (web_export_jpeg.cc). ---------------------------------------------

// One JPEG's three planes at one pyramid level, floats [y][x][3].
struct Level {
  int width = 0, height = 0;
  std::vector<float> v;
};

// The next pyramid level: half the size, each value the mean of four.
Level half(const Level& src);

// 8-bit plane value of a coefficient: round((v - min) / (max - min) * 255).
struct Quantiser {
  std::array<double, 3> lo{}, inv_range{};
  [[nodiscard]] unsigned char byte(int c, float v) const {
    const double q = (v - lo[c]) * inv_range[c] * 255.0;
    return static_cast<unsigned char>(std::clamp(std::lround(q), 0L, 255L));
  }
};

// The bytes of the w x h region of `l` at (x0, y0), interleaved.
std::vector<unsigned char> quantise_region(const Level& l, const Quantiser& q, int x0, int y0,
                                           int w, int h);

// Encodes interleaved 8-bit RGB (`ycbcr`: the ordinary colour transform, else R, G, B as they
// are). No chroma subsampling.
std::vector<unsigned char> encode_jpeg(const unsigned char* rgb, int width, int height, int quality,
                                       bool ycbcr);
// Decodes to interleaved RGB (for measuring what the coding lost).
std::vector<unsigned char> decode_jpeg(const std::vector<unsigned char>& data, int width,
                                       int height);

}  // namespace ptmkit::texture::internal
