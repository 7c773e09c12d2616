// PtmStreamWriter: the fit streams bands in; texels are kept as half floats until end(), which
// encodes and writes the file in slices of rows.

#include <Eigen/Core>

#include <array>
#include <cerrno>
#include <cstring>
#include <optional>
#include <stdexcept>
#include <string>

#include <tbb/combinable.h>
#include <tbb/parallel_for.h>
#include <tbb/parallel_pipeline.h>
#include <tbb/task_group.h>

#include "half.h"
#include "ptm_internal.h"
#include "ptmkit/core/atomic_file.h"
#include "ptmkit/core/error.h"
#include "ptmkit/core/limits.h"
#include "ptmkit/core/raw_file.h"
#include "ptmkit/texture/ptm.h"

namespace ptmkit::texture {

using internal::colour_bytes;
using internal::from_half;
using internal::Range;
using internal::range_portable;
using internal::to_half;

namespace {

// Rows per slice of end()'s encoding: enough texels per slice for the threads to share, few
// enough that the slices in flight stay small (64 rows held 40 MiB more at the peak of a
// 12-megapixel RGB fit, for no speed).
constexpr int kSliceRows = 16;

}  // namespace

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
      from_half(h, 8, v);
      for (int p = 0; p < 3; ++p) {
        std::copy_n(v, kPtmTerms - 1, polys + p * kPtmTerms);
        polys[p * kPtmTerms + kPtmTerms - 1] = v[kPtmTerms - 1 + p];
      }
      return;
    }
    from_half(h, static_cast<std::size_t>(halfs_per_texel), polys);
  }
};

namespace {

// The relit-error sample as an encoder source: the half values, unquantised.
class SampleSource {
 public:
  // Unpacks every sampled texel once: its polynomials, and the same through the file's bytes
  // (scale * (byte - bias), file units), so each of the report's lights costs a dot product.
  SampleSource(const PtmStreamWriter::Impl& s, const PtmQuantisation& q) : s_(s) {
    const std::size_t n = s.sample_halfs.size() / static_cast<std::size_t>(s.halfs_per_texel);
    const int np = internal::planes(s.format);
    polys_.resize(n * 3 * kPtmTerms);
    dequantised_.resize(n * 3 * kPtmTerms);
    for (std::size_t k = 0; k < n; ++k) {
      float* p = polys_.data() + k * 3 * kPtmTerms;
      s.unpack(s.sample_halfs.data() + k * s.halfs_per_texel, p);
      for (int j = 0; j < np * kPtmTerms; ++j) {
        const int i = j % kPtmTerms;
        const std::uint8_t byte =
            internal::quantise(255.0 * static_cast<double>(p[j]), q.scales[i], q.biases[i]);
        dequantised_[k * 3 * kPtmTerms + j] =
            static_cast<double>(q.scales[i]) * (byte - q.biases[i]);
      }
    }
  }

  void relit(int x, int y, double lu, double lv, float out[3]) const {
    const std::size_t k = sample(x, y);
    const float* polys = polys_.data() + k * 3 * kPtmTerms;
    const auto basis = ptm_basis(lu, lv);
    auto poly = [&](int p) {
      double v = 0.0;
      for (int i = 0; i < kPtmTerms; ++i) v += polys[p * kPtmTerms + i] * basis[i];
      return v;
    };
    if (s_.format == PtmFormat::kRGB) {
      for (int c = 0; c < 3; ++c) out[c] = static_cast<float>(poly(c));
    } else {
      const double l = poly(0);
      for (int c = 0; c < 3; ++c) out[c] = static_cast<float>(l * s_.sample_rgb[k * 3 + c] / 255.0);
    }
  }

  // The same texel through the bytes the file holds (as file_relit evaluates a file).
  void file_value(int x, int y, double lu, double lv, float out[3]) const {
    const std::size_t k = sample(x, y);
    const double* d = dequantised_.data() + k * 3 * kPtmTerms;
    const auto basis = ptm_basis(lu, lv);
    auto poly = [&](int p) {
      double v = 0.0;
      for (int i = 0; i < kPtmTerms; ++i) v += d[p * kPtmTerms + i] * basis[i];
      return v;
    };
    if (s_.format == PtmFormat::kRGB) {
      for (int c = 0; c < 3; ++c) out[c] = static_cast<float>(poly(c) / 255.0);
    } else {
      const double l = poly(0) / 255.0;
      for (int c = 0; c < 3; ++c) out[c] = static_cast<float>(l * s_.sample_rgb[k * 3 + c] / 255.0);
    }
  }

 private:
  [[nodiscard]] std::size_t sample(int x, int y) const {
    return (static_cast<std::size_t>(y) * s_.width + x) / s_.sample_stride;
  }
  const PtmStreamWriter::Impl& s_;
  std::vector<float> polys_;         // per sample: planes x 6, normalised units
  std::vector<double> dequantised_;  // per sample: planes x 6, file units
};

}  // namespace

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

namespace {

constexpr std::size_t kHalves = 65536;

// A coefficient's byte depends only on its index and its half value, so each index gets a
// table of all 65536 (a libm-free division per coefficient was most of a 12-megapixel kRGB
// write). The coefficient error likewise: counts of each (index, half) pair give its max and
// RMS exactly, summed in a fixed order whatever the threads.
struct HalfTables {
  std::vector<std::uint8_t> byte_of = std::vector<std::uint8_t>(kPtmTerms * kHalves);
  std::vector<double> error_of = std::vector<double>(kPtmTerms * kHalves);
};

HalfTables half_tables(const PtmQuantisation& q) {
  HalfTables tables;
  std::vector<std::uint8_t>& byte_of = tables.byte_of;
  std::vector<double>& error_of = tables.error_of;
  tbb::parallel_for(0, kPtmTerms, [&](int i) {
    std::vector<float> v(kHalves);
    std::vector<std::uint16_t> bits(kHalves);
    for (std::size_t h = 0; h < kHalves; ++h) bits[h] = static_cast<std::uint16_t>(h);
    from_half(bits.data(), kHalves, v.data());
    for (std::size_t h = 0; h < kHalves; ++h) {
      const double c = 255.0 * static_cast<double>(v[h]);
      const std::uint8_t b = internal::quantise(c, q.scales[i], q.biases[i]);
      byte_of[i * kHalves + h] = b;
      error_of[i * kHalves + h] =
          std::isfinite(c)
              ? std::abs(static_cast<double>(q.scales[i]) * (b - q.biases[i]) - c) / 255.0
              : 0.0;
    }
  });
  return tables;
}

// Rows of the file, kSliceRows at a time: stored rows j0 .. j0 + nrows - 1 (bottom-up).
struct Slice {
  int j0 = 0, nrows = 0;
  std::vector<std::uint16_t> halfs;
  std::vector<std::uint8_t> bytes, rgb;
};

// Encodes a slice: reads its half floats (from memory, or the spill file), turns them into
// the file's bytes through the tables (counting each (index, half) pair in `count`), copies
// the LRGB colour bytes, and gives the slice's half floats back to the kernel.
void encode_slice(PtmStreamWriter::Impl& s, const std::filesystem::path& path,
                  const HalfTables& tables, std::uint32_t* count, Slice& buf) {
  const int np = internal::planes(s.format);
  const std::size_t hpt = static_cast<std::size_t>(s.halfs_per_texel);
  const std::size_t w = static_cast<std::size_t>(s.width);
  const std::vector<std::uint8_t>& byte_of = tables.byte_of;
  const int j0 = buf.j0;
  const int nrows = buf.nrows;
  const int y_top = s.height - j0 - nrows;  // image rows y_top .. y_top + nrows - 1
  const std::uint16_t* halfs = nullptr;
  const std::size_t row_halfs = s.row_halfs();
  if (y_top + nrows <= s.memory_rows) {
    halfs = s.halfs.data() + static_cast<std::size_t>(y_top) * row_halfs;
  } else {
    buf.halfs.resize(static_cast<std::size_t>(nrows) * row_halfs);
    const int kept = std::clamp(s.memory_rows - y_top, 0, nrows);
    if (kept > 0) {
      std::copy_n(s.halfs.data() + static_cast<std::size_t>(y_top) * row_halfs,
                  static_cast<std::size_t>(kept) * row_halfs, buf.halfs.data());
    }
    s.spill.read_at(
        buf.halfs.data() + static_cast<std::size_t>(kept) * row_halfs,
        static_cast<std::size_t>(nrows - kept) * row_halfs * sizeof(std::uint16_t),
        static_cast<std::size_t>(y_top + kept - s.memory_rows) * row_halfs * sizeof(std::uint16_t),
        path);
    halfs = buf.halfs.data();
  }
  const std::size_t plane_bytes = static_cast<std::size_t>(nrows) * w * kPtmTerms;
  buf.bytes.resize(plane_bytes * np);
  for (int jr = 0; jr < nrows; ++jr) {
    const int y = s.height - 1 - (j0 + jr);
    const std::uint16_t* h = halfs + static_cast<std::size_t>(y - y_top) * w * hpt;
    std::uint8_t* b = buf.bytes.data() + static_cast<std::size_t>(jr) * w * kPtmTerms;
    // Texel by texel, each of its coefficients in turn: the halfs are read in order, and
    // a run of equal values (smooth regions) does not chain one count update to the next.
    // Where plane p's term i sits among a texel's halfs is known at compile time (kRGB
    // and kLRGB: p * 6 + i; kYCC shares a0..a4, then a5 per plane): a table of positions
    // read per coefficient had been reloaded after every byte store (a byte store may
    // alias anything), as had the table pointer.
    const std::uint8_t* const table = byte_of.data();
    const auto encode = [&](auto planes, auto shared) {
      constexpr int kPlanes = decltype(planes)::value;
      constexpr bool kShared = decltype(shared)::value;
      constexpr std::size_t kHalfsPerTexel =
          kShared ? kPtmTerms + 2 : std::size_t{kPlanes} * kPtmTerms;
      for (std::size_t x = 0; x < w; ++x) {
        const std::uint16_t* hx = h + x * kHalfsPerTexel;
        for (int p = 0; p < kPlanes; ++p) {
          std::uint8_t* bx = b + p * plane_bytes + x * kPtmTerms;
          for (int i = 0; i < kPtmTerms; ++i) {
            const int at =
                kShared ? (i < kPtmTerms - 1 ? i : kPtmTerms - 1 + p) : p * kPtmTerms + i;
            const std::uint16_t v = hx[at];
            bx[i] = table[i * kHalves + v];
            ++count[i * kHalves + v];
          }
        }
      }
    };
    if (s.model == ColourModel::kYCC) {
      encode(std::integral_constant<int, 3>{}, std::true_type{});
    } else if (np == 3) {
      encode(std::integral_constant<int, 3>{}, std::false_type{});
    } else {
      encode(std::integral_constant<int, 1>{}, std::false_type{});
    }
  }
  if (s.format == PtmFormat::kLRGB) {
    // The colour block follows the coefficients, in the same bottom-up row order.
    buf.rgb.resize(static_cast<std::size_t>(nrows) * w * 3);
    for (int jr = 0; jr < nrows; ++jr) {
      const int y = s.height - 1 - (j0 + jr);
      std::copy_n(s.rgb.data() + static_cast<std::size_t>(y) * w * 3, w * 3,
                  buf.rgb.data() + static_cast<std::size_t>(jr) * w * 3);
    }
    s.rgb.discard(static_cast<std::size_t>(y_top) * w * 3, static_cast<std::size_t>(nrows) * w * 3);
  }
  // This slice's coefficients are no longer needed: their memory goes back to the kernel
  // now, so that the file's pages written next reuse it. Fresh pages cost a fault and a
  // clearing each (on a virtual machine, often a fault in the host too): without this, a
  // 12-megapixel RGB fit touched 216 MB more of them.
  {
    const int in_memory = std::clamp(s.memory_rows - y_top, 0, nrows);
    s.halfs.discard(static_cast<std::size_t>(y_top) * row_halfs,
                    static_cast<std::size_t>(in_memory) * row_halfs);
    if (in_memory < nrows) {
      s.spill.punch_hole(
          static_cast<std::size_t>(y_top + in_memory - s.memory_rows) * row_halfs *
              sizeof(std::uint16_t),
          static_cast<std::size_t>(nrows - in_memory) * row_halfs * sizeof(std::uint16_t));
    }
  }
}

// The coefficient error over every stored coefficient, from the counts of (index, half)
// pairs and each pair's error.
void coefficient_errors(tbb::combinable<std::vector<std::uint32_t>>& counts,
                        const std::vector<double>& error_of, std::size_t coefficients,
                        PtmWriteReport* report) {
  std::vector<std::uint64_t> total(kPtmTerms * kHalves, 0);
  counts.combine_each([&](const std::vector<std::uint32_t>& c) {
    for (std::size_t k = 0; k < total.size(); ++k) total[k] += c[k];
  });
  double mx = 0.0, sq = 0.0;
  for (std::size_t k = 0; k < total.size(); ++k) {
    if (total[k] == 0) continue;
    mx = std::max(mx, error_of[k]);
    sq += static_cast<double>(total[k]) * error_of[k] * error_of[k];
  }
  report->max_coeff_error = mx;
  report->rms_coeff_error = std::sqrt(sq / static_cast<double>(coefficients));
}

}  // namespace

void PtmStreamWriter::end() {
  Impl& s = *impl_;
  if (!s.begun || s.next_row != s.height) {
    throw std::logic_error("PtmStreamWriter: end() before every row was written");
  }
  Collective* const peers = options_.collective;
  const auto non_finite = [&] {
    return Error(where(path_) +
                 ": the fit produced NaN or infinite coefficients (or beyond half-float range); "
                 "nothing was written");
  };
  if (peers != nullptr && !peers->all(s.finite)) {
    if (!s.finite) throw non_finite();
    throw PeerFailure(where(path_) + ": another process of the job failed (its message says why)");
  }
  if (!s.finite) throw non_finite();
  std::array<double, kPtmTerms> lo{}, hi{};
  for (int i = 0; i < kPtmTerms; ++i) {
    lo[i] = 255.0 * static_cast<double>(s.lo[i]);
    hi[i] = 255.0 * static_cast<double>(s.hi[i]);
  }
  if (peers != nullptr) {
    // The range over every process's rows: the scales and biases one process would choose.
    peers->min(lo.data(), lo.size());
    peers->max(hi.data(), hi.size());
  }
  PtmFile meta;  // header fields only; the data is written slice by slice
  meta.version = PtmVersion::k1_2;
  meta.format = s.format;
  meta.width = s.width;
  meta.height = s.full_height;
  meta.quantisation = choose_quantisation(lo, hi, options_.integer_scales);
  const PtmQuantisation& q = meta.quantisation;
  const std::string header = meta.canonical_header();
  const int np = internal::planes(s.format);
  const std::size_t texels = s.texels();
  const std::size_t w = static_cast<std::size_t>(s.width);
  // The whole file's texels (plane stride), and where this process's stored rows start.
  const std::size_t file_texels = static_cast<std::size_t>(s.full_height) * w;
  const std::size_t stored_row0 = static_cast<std::size_t>(s.full_height - s.row_offset - s.height);

  report_ = PtmWriteReport{};
  const HalfTables tables = half_tables(q);
  tbb::combinable<std::vector<std::uint32_t>> counts(
      [] { return std::vector<std::uint32_t>(kPtmTerms * kHalves, 0); });
  // The relit error needs only the sample and the quantisation: it runs beside the encoding,
  // whose in-order writing leaves a core idle part of the time.
  PtmWriteReport relit_report;
  tbb::task_group relit;
  if (s.sample_stride > 0) {
    relit.run([&] {
      const SampleSource source(s, q);
      const auto file_value = [&](int x, int y, double lu, double lv, float v[3]) {
        source.file_value(x, y, lu, lv, v);
      };
      internal::relit_error(source, file_value, s.width, texels, options_, &relit_report);
    });
  }
  // On an error below, the relit task must end before what it reads goes away (its own error,
  // if any, then matters less than the one being thrown).
  struct WaitOnExit {
    tbb::task_group& group;
    ~WaitOnExit() {
      try {
        group.wait();
      } catch (...) {
      }
    }
  } wait_relit{relit};
  // Rank 0 (or the one process) creates the temporary; the others write into it.
  std::optional<AtomicOutput> out;
  RawFile file = open_shared_output(peers, path_, header, &out);
  {
    const std::size_t data0 = header.size();
    // Slices of kSliceRows stored rows, through a pipeline: slices read their half floats
    // (from the spill file, if any) and are encoded in parallel, and are written in order by
    // one thread at a time (writes to one file serialise in the kernel anyway; two threads
    // writing at once only spin on its lock). Stored row j is image row height - 1 - j
    // (bottom-up).
    const int slices = (s.height + kSliceRows - 1) / kSliceRows;
    constexpr int kTokens = 4;
    std::array<Slice, kTokens> pool;
    int next_slice = 0;
    const auto read_slice = [&](tbb::flow_control& fc) -> Slice* {
      if (next_slice == slices) {
        fc.stop();
        return nullptr;
      }
      // At most kTokens slices are in flight and they finish in order: slot reuse is safe.
      Slice* slice = &pool[static_cast<std::size_t>(next_slice % kTokens)];
      slice->j0 = next_slice * kSliceRows;
      slice->nrows = std::min(kSliceRows, s.height - slice->j0);
      ++next_slice;
      return slice;
    };
    const auto encode = [&](Slice* slice) -> Slice* {
      encode_slice(s, path_, tables, counts.local().data(), *slice);
      return slice;
    };
    const auto write_slice = [&](Slice* slice) {
      const Slice& buf = *slice;
      const std::size_t plane_bytes = static_cast<std::size_t>(buf.nrows) * w * kPtmTerms;
      const std::size_t j = stored_row0 + static_cast<std::size_t>(buf.j0);
      for (int p = 0; p < np; ++p) {
        const std::size_t at =
            data0 + (static_cast<std::size_t>(p) * file_texels + j * w) * kPtmTerms;
        file.write_at(buf.bytes.data() + p * plane_bytes, plane_bytes, at, path_);
      }
      if (s.format == PtmFormat::kLRGB) {
        file.write_at(buf.rgb.data(), buf.rgb.size(), data0 + file_texels * kPtmTerms + j * w * 3,
                      path_);
      }
    };
    tbb::parallel_pipeline(
        kTokens,
        tbb::make_filter<void, Slice*>(tbb::filter_mode::serial_in_order, read_slice) &
            tbb::make_filter<Slice*, Slice*>(tbb::filter_mode::parallel, encode) &
            tbb::make_filter<Slice*, void>(tbb::filter_mode::serial_in_order, write_slice));
    file.close(path_);
  }
  report_.format = s.format;
  report_.quantisation = q;
  coefficient_errors(counts, tables.error_of, texels * np * kPtmTerms, &report_);
  if (peers != nullptr) {
    // Every process's rows written (and closed) before rank 0 renames the file.
    peers->agree(true, where(path_));
    double mx = report_.max_coeff_error;
    double sq[2] = {report_.rms_coeff_error * report_.rms_coeff_error *
                        static_cast<double>(texels * np * kPtmTerms),
                    static_cast<double>(texels * np * kPtmTerms)};
    peers->max(&mx, 1);
    peers->sum(sq, 2);
    report_.max_coeff_error = mx;
    report_.rms_coeff_error = sq[1] > 0.0 ? std::sqrt(sq[0] / sq[1]) : 0.0;
    peers->finish();
  }
  relit.wait();
  report_.relit_mean_abs_grey = relit_report.relit_mean_abs_grey;
  report_.relit_max_abs_grey = relit_report.relit_max_abs_grey;
  report_.relit_psnr_db = relit_report.relit_psnr_db;
  report_.relit_samples = relit_report.relit_samples;
  if (out) out->commit();
  report_.path = path_;
  report_.file_bytes = header.size() + file_texels * internal::bytes_per_texel(s.format);
  s = Impl{};
}

}  // namespace ptmkit::texture
