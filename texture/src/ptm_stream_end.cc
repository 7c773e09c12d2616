// PtmStreamWriter::end(): the quantisation from every band's range, the file encoded through
// per-coefficient tables of all half values in slices of rows, and the report.

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <filesystem>
#include <optional>
#include <stdexcept>
#include <string>
#include <type_traits>
#include <vector>

#include <tbb/combinable.h>
#include <tbb/parallel_for.h>
#include <tbb/parallel_pipeline.h>
#include <tbb/task_group.h>

#include "half.h"
#include "ptm_internal.h"
#include "ptm_stream_detail.h"
#include "ptmkit/core/atomic_file.h"
#include "ptmkit/core/collective.h"
#include "ptmkit/core/error.h"
#include "ptmkit/core/raw_file.h"
#include "ptmkit/texture/ptm.h"

namespace ptmkit::texture {

using internal::from_half;

namespace {

// Rows per slice of end()'s encoding: enough texels per slice for the threads to share, few
// enough that the slices in flight stay small (64 rows held 40 MiB more at the peak of a
// 12-megapixel RGB fit, for no speed).
constexpr int kSliceRows = 16;

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
        file.start_writeback(at, plane_bytes);
      }
      if (s.format == PtmFormat::kLRGB) {
        const std::size_t at = data0 + file_texels * kPtmTerms + j * w * 3;
        file.write_at(buf.rgb.data(), buf.rgb.size(), at, path_);
        file.start_writeback(at, buf.rgb.size());
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
