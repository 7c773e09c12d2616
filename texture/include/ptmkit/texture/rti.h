// Hemispherical-harmonics (HSH) texture maps and Cultural Heritage Imaging's .rti file format
// (RTI type 3, HSH), the format RTIBuilder writes and RTIViewer-style viewers read. ptmkit
// writes .ptm for the six-term polynomial and .rti for the HSH bases (docs/MODELS.md).
//
// The HSH basis and its formula: core/hsh.h (the fit uses the same functions, so fit and
// viewer agree for every light).
//
// File layout (.rti, HSH, uncompressed), as written here and accepted on reading (header lines
// are written with CRLF ends, as CHI's HSH fitter does; CRLF and LF are both read):
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

#include "ptmkit/core/coefficients.h"
#include "ptmkit/core/collective.h"
#include "ptmkit/core/hsh.h"
#include "ptmkit/core/image.h"

namespace ptmkit::texture {

// Terms of an HSH basis of order 2, 3, 4: 4, 9, 16. Throws ptmkit::Error for other orders.
[[nodiscard]] int hsh_terms(int order);
// The HSH basis of 4, 9 or 16 terms (core/coefficients.h); throws ptmkit::Error otherwise.
[[nodiscard]] Basis hsh_basis_of_terms(int terms);
// Order of a basis with 4, 9 or 16 terms; 0 for any other count.
[[nodiscard]] int hsh_order(int terms);

using ptmkit::hsh_basis;  // core/hsh.h

// What quantisation to 8 bits cost (normalised units).
struct RtiWriteReport {
  std::filesystem::path path;
  std::size_t file_bytes = 0;
  double max_coeff_error = 0.0;
  double rms_coeff_error = 0.0;
};

// Quantises (per term, scale and bias from that term's range over all texels and channels)
// and writes atomically. The map (core/coefficients.h) is an HSH basis in the rgb layout
// (luminance fits multiplied out, as the fit delivers them). Throws ptmkit::Error naming the
// file when the map is malformed (not an HSH basis, not rgb; size mismatch; non-finite
// coefficients) or the write fails.
RtiWriteReport write_rti(const std::filesystem::path& path, const CoefficientMap& map);

// A sink (core/coefficients.h) that collects a fit in memory and writes it as an .rti at
// end(): the quantisation needs every texel's range, so the map is held whole (3 x terms
// floats per texel). begin() refuses layouts write_rti cannot store.
// A fit shared by several processes (core/collective.h): this process holds image rows
// [row_offset, row_offset + begin()'s layout height) of a file `full_height` rows tall. The
// processes agree on every term's range before any byte is written; rank 0 creates the
// temporary file, each process writes its rows into it, rank 0 renames it after all
// succeeded: the bytes one process would write.
struct RtiShare {
  Collective* collective = nullptr;
  int row_offset = 0;
  int full_height = 0;
};

class RtiWriter final : public CoefficientSink {
 public:
  explicit RtiWriter(std::filesystem::path path, RtiShare share = {})
      : path_(std::move(path)), share_(share) {}
  void begin(const CoefficientLayout& layout) override;
  void write_rows(int y0, int rows, const float* coeffs, const float* colour) override;
  void end() override;
  // Valid after end().
  [[nodiscard]] const RtiWriteReport& report() const { return report_; }

 private:
  std::filesystem::path path_;
  RtiShare share_;
  CoefficientMap map_;
  CoefficientMapSink sink_{&map_};
  RtiWriteReport report_;
};

// Reads an uncompressed HSH .rti. Errors (ptmkit::Error naming the file and the problem): a
// missing or unreadable file, a header that does not parse, an RTI type other than 3 (refused
// with texture/formats.h's wording), colour
// components other than 3, terms other than 4, 9, 16, an element size other than 1, an
// absurd size, a non-finite scale or bias, and a binary block shorter than the header implies
// (expected and present byte counts). The file does not say what the values are: the caller
// does (`colour_space`).
// The map has the HSH basis of the file and the rgb layout.
[[nodiscard]] CoefficientMap read_rti(const std::filesystem::path& path,
                                      ColourSpace colour_space = ColourSpace::kSRGB);

// What an .rti holds, for `ptmkit info`: its basis, size, and each term's coefficient range
// over every texel and channel (normalised units, after the file's scale and bias).
struct RtiSummary {
  int width = 0;
  int height = 0;
  int terms = 0;
  int order = 0;                             // HSH order: 2, 3 or 4
  std::vector<double> coeff_min, coeff_max;  // per term
  std::size_t file_bytes = 0;
  int file_bytes_per_texel = 0;  // 3 x terms
  int map_bytes_per_texel = 0;   // as floats in memory
};
// Reads and summarises an .rti (errors as read_rti).
[[nodiscard]] RtiSummary summarise_rti(const std::filesystem::path& path);

// True when the file starts like an .rti (a '#' comment line or the type line "3"), as
// opposed to a .ptm ("PTM_1."). Reads only the first bytes; false when unreadable.
[[nodiscard]] bool looks_like_rti(const std::filesystem::path& path);

}  // namespace ptmkit::texture
