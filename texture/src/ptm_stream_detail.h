// PtmStreamWriter's storage, shared by the bands' side (ptm_stream.cc: begin, write_rows) and
// the encoding and writing of the file (ptm_stream_end.cc: end).
#pragma once

#include <algorithm>
#include <array>
#include <cstddef>
#include <cstdint>
#include <vector>

#include "half.h"
#include "ptmkit/core/raw_file.h"
#include "ptmkit/texture/ptm.h"

namespace ptmkit::texture {

struct PtmStreamWriter::Impl {
  int width = 0;
  int height = 0;  // rows this process holds
  // The file's rows: this process's are full_height - row_offset - height .. (stored rows,
  // bottom-up) of full_height; one process: 0 and height.
  int row_offset = 0;
  int full_height = 0;
  ColourModel model = ColourModel::kRGB;
  PtmFormat format = PtmFormat::kRGB;
  // Halfs per texel: 18 (kRGB), 8 (kYCC: a0..a4 shared, then a5 of R, G, B), 6 (kLRGB).
  int halfs_per_texel = 18;
  // Rows 0 .. memory_rows - 1 of half floats are held in memory; the rest (when the whole
  // would exceed PtmWriteOptions::spill_above_bytes) in an unnamed temporary file, row y at
  // (y - memory_rows) row_halfs() halfs.
  int memory_rows = 0;
  LargeBuffer<std::uint16_t> halfs;
  RawFile spill;
  LargeBuffer<std::uint8_t> rgb;  // kLRGB only
  std::array<float, kPtmTerms> lo{}, hi{};
  bool finite = true;
  bool begun = false;
  int next_row = 0;
  // The relit-error sample (every stride-th texel), kept aside so end() needs no random
  // access into the halfs.
  std::size_t sample_stride = 0;
  std::vector<std::uint16_t> sample_halfs;
  std::vector<std::uint8_t> sample_rgb;
  // Per-band scratch.
  std::vector<std::uint16_t> band_halfs;
  std::vector<float> band_polys;

  [[nodiscard]] std::size_t texels() const { return static_cast<std::size_t>(width) * height; }
  [[nodiscard]] std::size_t row_halfs() const {
    return static_cast<std::size_t>(width) * halfs_per_texel;
  }

  // The file polynomials of a texel from its halfs: planes x 6 floats.
  void unpack(const std::uint16_t* h, float* polys) const {
    if (model == ColourModel::kYCC) {
      float v[8];
      internal::from_half(h, 8, v);
      for (int p = 0; p < 3; ++p) {
        std::copy_n(v, kPtmTerms - 1, polys + p * kPtmTerms);
        polys[p * kPtmTerms + kPtmTerms - 1] = v[kPtmTerms - 1 + p];
      }
      return;
    }
    internal::from_half(h, static_cast<std::size_t>(halfs_per_texel), polys);
  }
};

}  // namespace ptmkit::texture
