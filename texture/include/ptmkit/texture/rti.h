// Hemispherical-harmonics (HSH) texture maps and Cultural Heritage Imaging's .rti file format
// (RTI type 3, HSH), the format RTIBuilder writes and RTIViewer-style viewers read. ptmkit
// writes .ptm for the six-term polynomial and .rti for the HSH bases (docs/MODELS.md).
//
// The HSH basis (Gautron, Krivanek, Pattanaik, Bouatouch, "A novel hemispherical basis for
// accurate and efficient rendering", EGSR 2004), in the form and order the .rti viewers
// evaluate it. With the light direction (x, y, z) in the light frame (x right, y up the image,
// z toward the camera), theta = min(acos z, pi/2 - 0.04), phi = atan2(y, x), c = cos theta,
// s = sqrt(c - c^2):
//   order 2 (4 terms):
//     h0 = 1/sqrt(2 pi)              h1 = sqrt(6/pi) cos(phi) s
//     h2 = sqrt(3/(2 pi)) (2c - 1)   h3 = sqrt(6/pi) sin(phi) s
//   order 3 (9 terms) adds:
//     h4 = sqrt(30/pi) cos(2 phi) (c^2 - c)      h5 = sqrt(30/pi) cos(phi) (2c - 1) s
//     h6 = sqrt(5/(2 pi)) (6c^2 - 6c + 1)        h7 = sqrt(30/pi) sin(phi) (2c - 1) s
//     h8 = sqrt(30/pi) sin(2 phi) (c^2 - c)
//   order 4 (16 terms) adds:
//     h9  = 2 sqrt(35/pi) cos(3 phi) s^3          h10 = sqrt(210/pi) cos(2 phi) (2c - 1)(c^2 - c)
//     h11 = 2 sqrt(21/pi) cos(phi) s (5c^2 - 5c + 1)
//     h12 = sqrt(7/(2 pi)) (20c^3 - 30c^2 + 12c - 1)
//     h13 = 2 sqrt(21/pi) sin(phi) s (5c^2 - 5c + 1)
//     h14 = sqrt(210/pi) sin(2 phi) (2c - 1)(c^2 - c)  h15 = 2 sqrt(35/pi) sin(3 phi) s^3
// The clamp of theta at pi/2 - 0.04 rad (87.7 degrees) is the viewers' (it keeps s away from
// the horizon); the fit uses the same clamp so fit and viewer agree for every light.
//
// File layout (.rti, HSH, uncompressed), as written here and accepted on reading:
//   #HSH1.2                        comment lines starting with '#' (any number)
//   3                              RTI type: 3 = HSH
//   W H 3                          width, height, colour components (3)
//   T 2 1                          basis terms (4, 9 or 16), basis type, element size (bytes)
//   T float32 scales, then T float32 biases, binary, little-endian
//   W*H*3*T bytes: rows top to bottom, per pixel R[0..T), G[0..T), B[0..T)
// Coefficient k of a channel = byte / 255 * scale[k] + bias[k]; the sum over k of
// coefficient * h_k is the channel's value in normalised units (1.0 = full scale).
#pragma once

#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <vector>

#include <Eigen/Core>

#include "ptmkit/core/image.h"

namespace ptmkit::texture {

// Terms of an HSH basis of order 2, 3, 4: 4, 9, 16. Throws ptmkit::Error for other orders.
[[nodiscard]] int hsh_terms(int order);
// Order of a basis with 4, 9 or 16 terms; 0 for any other count.
[[nodiscard]] int hsh_order(int terms);

// The first `terms` (4, 9 or 16) HSH basis functions at `dir` (normalised here; must be
// non-zero and finite, z may be anything: theta is clamped as above).
void hsh_basis(int terms, const Eigen::Vector3d& dir, double* out);

// An HSH texture in memory: three colour channels, `terms` coefficients each per texel, in
// normalised units.
struct RtiMap {
  int width = 0;
  int height = 0;
  int terms = 9;
  ColourSpace colour_space = ColourSpace::kSRGB;
  // [y][x][channel R, G, B][term], rows top to bottom.
  std::vector<float> coeffs;

  RtiMap() = default;
  RtiMap(int w, int h, int t, ColourSpace cs = ColourSpace::kSRGB);
  [[nodiscard]] std::size_t texels() const { return static_cast<std::size_t>(width) * height; }
  [[nodiscard]] const float* texel(int x, int y) const {
    return coeffs.data() + (static_cast<std::size_t>(y) * width + x) * 3 * terms;
  }
  [[nodiscard]] float* texel(int x, int y) {
    return coeffs.data() + (static_cast<std::size_t>(y) * width + x) * 3 * terms;
  }
};

// What quantisation to 8 bits cost (normalised units).
struct RtiWriteReport {
  std::filesystem::path path;
  std::size_t file_bytes = 0;
  double max_coeff_error = 0.0;
  double rms_coeff_error = 0.0;
};

// Quantises (per term, scale and bias from that term's range over all texels and channels)
// and writes atomically. Throws ptmkit::Error naming the file when the map is malformed
// (terms not 4, 9 or 16; size mismatch; non-finite coefficients) or the write fails.
RtiWriteReport write_rti(const std::filesystem::path& path, const RtiMap& map);

// Reads an uncompressed HSH .rti. Errors (ptmkit::Error naming the file and the problem): a
// missing or unreadable file, a header that does not parse, an RTI type other than 3, colour
// components other than 3, terms other than 4, 9, 16, an element size other than 1, an
// absurd size, a non-finite scale or bias, and a binary block shorter than the header implies
// (expected and present byte counts). The file does not say what the values are: the caller
// does (`colour_space`).
[[nodiscard]] RtiMap read_rti(const std::filesystem::path& path,
                              ColourSpace colour_space = ColourSpace::kSRGB);

// True when the file starts like an .rti (a '#' comment line or the type line "3"), as
// opposed to a .ptm ("PTM_1."). Reads only the first bytes; false when unreadable.
[[nodiscard]] bool looks_like_rti(const std::filesystem::path& path);

}  // namespace ptmkit::texture
