// PtmStreamWriter: the fit streams bands in; texels are kept as half floats until end()
// (ptm_stream_end.cc), which encodes and writes the file in slices of rows.

#include <algorithm>
#include <array>
#include <cstdint>
#include <filesystem>
#include <limits>
#include <stdexcept>
#include <string>
#include <vector>

#include "half.h"
#include "ptm_internal.h"
#include "ptm_stream_detail.h"
#include "ptmkit/core/atomic_file.h"
#include "ptmkit/core/error.h"
#include "ptmkit/core/limits.h"
#include "ptmkit/core/raw_file.h"
#include "ptmkit/texture/ptm.h"

namespace ptmkit::texture {

using internal::colour_bytes;
using internal::Range;
using internal::range_portable;
using internal::to_half;

PtmStreamWriter::PtmStreamWriter(std::filesystem::path path, PtmWriteOptions options)
    : path_(std::move(path)), options_(std::move(options)), impl_(std::make_unique<Impl>()) {}

PtmStreamWriter::~PtmStreamWriter() = default;

std::size_t PtmStreamWriter::buffer_bytes() const {
  return impl_->texels() * impl_->halfs_per_texel * sizeof(std::uint16_t) + impl_->rgb.size();
}

bool PtmStreamWriter::spilled() const { return impl_->spill.is_open(); }

void PtmStreamWriter::begin(const CoefficientLayout& layout) {
  // The .ptm format does not record the colour space.
  const int width = layout.width;
  const int height = layout.height;
  const ColourModel model = layout.model;
  if (layout.basis != Basis::kPtm) {
    throw Error(where(path_) + ": a .ptm holds the ptm basis, not " +
                std::string(to_string(layout.basis)) + " (write an .rti)");
  }
  if (width <= 0 || height <= 0 || width > kMaxPtmSide || height > kMaxPtmSide) {
    throw Error(where(path_) + ": cannot write a " + std::to_string(width) + " x " +
                std::to_string(height) + " PTM");
  }
  Impl& s = *impl_;
  s = Impl{};
  s.width = width;
  s.height = height;
  s.row_offset = 0;
  s.full_height = height;
  if (options_.collective != nullptr) {
    if (options_.row_offset < 0 || options_.full_height < height ||
        options_.row_offset > options_.full_height - height) {
      throw std::logic_error("PtmStreamWriter: rows outside the distributed file's height");
    }
    s.row_offset = options_.row_offset;
    s.full_height = options_.full_height;
    if (s.full_height > kMaxPtmSide) {
      throw Error(where(path_) + ": cannot write a " + std::to_string(width) + " x " +
                  std::to_string(s.full_height) + " PTM");
    }
  }
  s.model = model;
  s.format = internal::format_for(model);
  s.halfs_per_texel = model == ColourModel::kRGB ? 18 : model == ColourModel::kYCC ? 8 : 6;
  const std::size_t texels = s.texels();
  const std::size_t half_bytes = texels * s.halfs_per_texel * sizeof(std::uint16_t);
  if (options_.spill_above_bytes > 0 && half_bytes > options_.spill_above_bytes) {
    // In the output's folder (the user chose that disk for a file of this order of size),
    // unlinked at once: nothing is left behind whatever happens to the process.
    AtomicOutput name(path_);
    std::filesystem::path temp = name.temp_path();
    temp += ".coeffs";
    s.spill = RawFile::create_unlinked(temp);
    // As many whole rows as the budget allows stay in memory: only the excess round-trips
    // through the file.
    const std::size_t row_bytes = s.row_halfs() * sizeof(std::uint16_t);
    s.memory_rows = static_cast<int>(std::min<std::size_t>(options_.spill_above_bytes / row_bytes,
                                                           static_cast<std::size_t>(height)));
  } else {
    s.memory_rows = height;
  }
  s.halfs.allocate(static_cast<std::size_t>(s.memory_rows) * s.row_halfs());
  if (model == ColourModel::kLRGB) s.rgb.allocate(texels * 3);
  // Distributed: no relit sample (its figures would need every process's texels).
  s.sample_stride =
      options_.collective != nullptr ? 0 : internal::relit_sample_stride(texels, options_);
  if (s.sample_stride > 0) {
    const std::size_t samples = (texels + s.sample_stride - 1) / s.sample_stride;
    s.sample_halfs.assign(samples * s.halfs_per_texel, 0);
    if (model == ColourModel::kLRGB) s.sample_rgb.assign(samples * 3, 0);
  }
  s.lo.fill(std::numeric_limits<float>::infinity());
  s.hi.fill(-std::numeric_limits<float>::infinity());
  // A regular file about to be replaced by the output: its cached pages go anyway when the
  // new file is renamed over it. Dropping them now hands their memory to this write (the
  // coefficients, the temporary file, the new file's pages), which otherwise takes memory the
  // process has never touched; that costs more (on a virtual machine, a fault in the host
  // too): a 12-megapixel RGB fit over its previous output took 0.1 s less
  // (docs/PERFORMANCE.md). The file's contents are untouched, so a failed run leaves it as it
  // was; only clean pages go.
  drop_cached_pages(path_);
  s.begun = true;
}

void PtmStreamWriter::write_rows(int y0, int rows, const float* coeffs, const float* colour) {
  Impl& s = *impl_;
  if (!s.begun || y0 != s.next_row || rows < 0 || y0 + rows > s.height) {
    throw std::logic_error("PtmStreamWriter: bands must arrive in order after begin()");
  }
  const std::size_t band_texels = static_cast<std::size_t>(rows) * s.width;
  const std::size_t first = static_cast<std::size_t>(y0) * s.width;
  const std::size_t hpt = static_cast<std::size_t>(s.halfs_per_texel);
  // Straight into memory when the whole band lives there, else via a scratch band.
  const bool in_memory = y0 + rows <= s.memory_rows;
  std::uint16_t* dst = nullptr;
  if (in_memory) {
    dst = s.halfs.data() + first * hpt;
  } else {
    s.band_halfs.resize(band_texels * hpt);
    dst = s.band_halfs.data();
  }
  // The values whose range sets the quantisation: the file polynomials as floats, before
  // rounding to half (so the scales and biases are exactly write_ptm's).
  Range range{s.lo, s.hi, true};
  if (s.model == ColourModel::kYCC) {
    s.band_polys.resize(band_texels * 3 * kPtmTerms);
    std::vector<float> packed(band_texels * hpt);
    for (std::size_t t = 0; t < band_texels; ++t) {
      float* p = s.band_polys.data() + t * 3 * kPtmTerms;
      std::uint8_t unused[3];
      internal::file_polynomials(s.model, coeffs + t * kPtmTerms, colour + t * 2, p, unused);
      float* k = packed.data() + t * hpt;
      std::copy_n(p, kPtmTerms - 1, k);
      for (int c = 0; c < 3; ++c) k[kPtmTerms - 1 + c] = p[c * kPtmTerms + kPtmTerms - 1];
    }
    to_half(packed.data(), packed.size(), dst);
    range_portable(s.band_polys.data(), s.band_polys.size(), &range);
  } else {
    // kRGB and kLRGB: the fit's layout is the file's.
    half_and_range(coeffs, band_texels * hpt, dst, &range);
  }
  // A zero bound is +0 whichever zero was met first (0.0f + -0.0f is +0).
  for (int i = 0; i < kPtmTerms; ++i) {
    s.lo[static_cast<std::size_t>(i)] = range.lo[static_cast<std::size_t>(i)] + 0.0f;
    s.hi[static_cast<std::size_t>(i)] = range.hi[static_cast<std::size_t>(i)] + 0.0f;
  }
  if (!range.finite) {
    // Name the texel (the inputs, not their half-float rounding, are what is wrong).
    const int per_texel = polynomial_count(s.model) * kPtmTerms;
    check_coefficients(path_, coeffs, band_texels * static_cast<std::size_t>(per_texel), s.width,
                       per_texel, y0);
    s.finite = false;
  }
  if (s.model == ColourModel::kLRGB) {
    std::uint8_t* rgb = s.rgb.data() + first * 3;
    colour_bytes(colour, band_texels * 3, rgb);
  }
  // The relit-error sample's texels in this band.
  if (s.sample_stride > 0) {
    std::size_t t = (first + s.sample_stride - 1) / s.sample_stride * s.sample_stride;
    for (; t < first + band_texels; t += s.sample_stride) {
      const std::size_t k = t / s.sample_stride;
      std::copy_n(dst + (t - first) * hpt, hpt, s.sample_halfs.data() + k * hpt);
      if (s.model == ColourModel::kLRGB) std::copy_n(&s.rgb[t * 3], 3, &s.sample_rgb[k * 3]);
    }
  }
  if (!in_memory) {
    const int kept = std::max(0, s.memory_rows - y0);  // leading rows that live in memory
    const std::size_t kept_halfs = static_cast<std::size_t>(kept) * s.row_halfs();
    if (kept > 0) std::copy_n(dst, kept_halfs, s.halfs.data() + first * hpt);
    const std::size_t spilled_row = static_cast<std::size_t>(y0 + kept - s.memory_rows);
    s.spill.write_at(dst + kept_halfs, (band_texels * hpt - kept_halfs) * sizeof(std::uint16_t),
                     spilled_row * s.row_halfs() * sizeof(std::uint16_t), path_);
  }
  s.next_row = y0 + rows;
}

}  // namespace ptmkit::texture
