// PtmStreamWriter: the fit streams bands in; texels are kept as half floats until end(), which
// encodes and writes the file in slices of rows.
#include <fcntl.h>
#include <immintrin.h>
#include <unistd.h>

#include <Eigen/Core>

#include <cerrno>
#include <cstring>
#include <stdexcept>
#include <string>

#include <tbb/combinable.h>

#include "ptm_internal.h"
#include "ptmkit/core/atomic_file.h"
#include "ptmkit/core/error.h"
#include "ptmkit/texture/ptm.h"

namespace ptmkit::texture {

namespace {

// Float <-> IEEE half, round to nearest even. F16C where the CPU has it (one instruction per 8
// values; Eigen's portable conversion is bit manipulation per value), else Eigen: the same
// bits either way, both being IEEE conversions.
__attribute__((target("avx,f16c"))) void to_half_f16c(const float* in, std::size_t n,
                                                      std::uint16_t* out) {
  std::size_t k = 0;
  for (; k + 8 <= n; k += 8) {
    _mm_storeu_si128(reinterpret_cast<__m128i*>(out + k),
                     _mm256_cvtps_ph(_mm256_loadu_ps(in + k), _MM_FROUND_TO_NEAREST_INT));
  }
  for (; k < n; ++k) out[k] = Eigen::numext::bit_cast<std::uint16_t>(Eigen::half(in[k]));
}

__attribute__((target("avx,f16c"))) void from_half_f16c(const std::uint16_t* in, std::size_t n,
                                                        float* out) {
  std::size_t k = 0;
  for (; k + 8 <= n; k += 8) {
    _mm256_storeu_ps(out + k,
                     _mm256_cvtph_ps(_mm_loadu_si128(reinterpret_cast<const __m128i*>(in + k))));
  }
  for (; k < n; ++k) out[k] = static_cast<float>(Eigen::numext::bit_cast<Eigen::half>(in[k]));
}

const bool kHaveF16C = __builtin_cpu_supports("f16c") && __builtin_cpu_supports("avx");

void to_half(const float* in, std::size_t n, std::uint16_t* out) {
  if (kHaveF16C) return to_half_f16c(in, n, out);
  for (std::size_t k = 0; k < n; ++k) {
    out[k] = Eigen::numext::bit_cast<std::uint16_t>(Eigen::half(in[k]));
  }
}

void from_half(const std::uint16_t* in, std::size_t n, float* out) {
  if (kHaveF16C) return from_half_f16c(in, n, out);
  for (std::size_t k = 0; k < n; ++k) {
    out[k] = static_cast<float>(Eigen::numext::bit_cast<Eigen::half>(in[k]));
  }
}

__attribute__((target_clones("avx2", "default"))) void colour_bytes(const float* in, std::size_t n,
                                                                    std::uint8_t* out) {
  for (std::size_t k = 0; k < n; ++k) out[k] = internal::colour_byte(in[k]);
}

// Largest float that rounds to a finite half: 65504 plus just under half a step (16).
constexpr float kHalfLimit = 65520.0f;

// A POSIX file descriptor closed on scope exit.
struct Fd {
  int fd = -1;
  Fd() = default;
  explicit Fd(int f) : fd(f) {}
  Fd(const Fd&) = delete;
  Fd& operator=(const Fd&) = delete;
  Fd(Fd&& o) noexcept : fd(o.fd) { o.fd = -1; }
  Fd& operator=(Fd&& o) noexcept {
    std::swap(fd, o.fd);
    return *this;
  }
  ~Fd() {
    if (fd >= 0) ::close(fd);
  }
};

void pwrite_all(int fd, const void* data, std::size_t bytes, std::size_t offset,
                const std::filesystem::path& what) {
  const auto* p = static_cast<const char*>(data);
  while (bytes > 0) {
    const ssize_t n = ::pwrite(fd, p, bytes, static_cast<off_t>(offset));
    if (n < 0 && errno == EINTR) continue;
    if (n <= 0) throw Error(where(what) + ": write failed: " + std::strerror(errno));
    p += n;
    bytes -= static_cast<std::size_t>(n);
    offset += static_cast<std::size_t>(n);
  }
}

void pread_all(int fd, void* data, std::size_t bytes, std::size_t offset,
               const std::filesystem::path& what) {
  auto* p = static_cast<char*>(data);
  while (bytes > 0) {
    const ssize_t n = ::pread(fd, p, bytes, static_cast<off_t>(offset));
    if (n < 0 && errno == EINTR) continue;
    if (n <= 0) throw Error(where(what) + ": cannot read back the temporary coefficients");
    p += n;
    bytes -= static_cast<std::size_t>(n);
    offset += static_cast<std::size_t>(n);
  }
}

// Rows per slice of end()'s encoding: enough texels per slice for the threads to share.
constexpr int kSliceRows = 64;

}  // namespace

struct PtmStreamWriter::Impl {
  int width = 0;
  int height = 0;
  ColourModel model = ColourModel::kRGB;
  PtmFormat format = PtmFormat::kRGB;
  // Halfs per texel: 18 (kRGB), 8 (kYCC: a0..a4 shared, then a5 of R, G, B), 6 (kLRGB).
  int halfs_per_texel = 18;
  std::vector<std::uint16_t> halfs;  // in memory, unless spilled
  Fd spill;                          // unnamed temporary file holding the halfs
  std::vector<std::uint8_t> rgb;     // kLRGB only
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

bool PtmStreamWriter::spilled() const { return impl_->spill.fd >= 0; }

void PtmStreamWriter::begin(int width, int height, ColourModel model, ColourSpace colour_space) {
  (void)colour_space;  // the .ptm format does not record it
  if (width <= 0 || height <= 0 || width > kMaxPtmSide || height > kMaxPtmSide) {
    throw Error(where(path_) + ": cannot write a " + std::to_string(width) + " x " +
                std::to_string(height) + " PTM");
  }
  Impl& s = *impl_;
  s = Impl{};
  s.width = width;
  s.height = height;
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
    Fd fd(::open(temp.c_str(), O_RDWR | O_CREAT | O_EXCL | O_CLOEXEC, 0600));
    if (fd.fd < 0) {
      throw Error(where(temp) +
                  ": cannot create the temporary coefficient file: " + std::strerror(errno));
    }
    ::unlink(temp.c_str());
    s.spill = std::move(fd);
  } else {
    s.halfs.assign(texels * s.halfs_per_texel, 0);
  }
  if (model == ColourModel::kLRGB) s.rgb.assign(texels * 3, 0);
  s.sample_stride = internal::relit_sample_stride(texels, options_);
  if (s.sample_stride > 0) {
    const std::size_t samples = (texels + s.sample_stride - 1) / s.sample_stride;
    s.sample_halfs.assign(samples * s.halfs_per_texel, 0);
    if (model == ColourModel::kLRGB) s.sample_rgb.assign(samples * 3, 0);
  }
  s.lo.fill(std::numeric_limits<float>::infinity());
  s.hi.fill(-std::numeric_limits<float>::infinity());
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
  std::uint16_t* dst = nullptr;
  if (s.spill.fd >= 0) {
    s.band_halfs.resize(band_texels * hpt);
    dst = s.band_halfs.data();
  } else {
    dst = s.halfs.data() + first * hpt;
  }
  // The values whose range sets the quantisation: the file polynomials as floats, before
  // rounding to half (so the scales and biases are exactly write_ptm's).
  const float* polys = coeffs;  // kRGB and kLRGB: the fit's layout is the file's
  std::size_t polys_per_texel = hpt;
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
    polys = s.band_polys.data();
    polys_per_texel = 3 * kPtmTerms;
    to_half(packed.data(), packed.size(), dst);
  } else {
    to_half(coeffs, band_texels * hpt, dst);
  }
  // Range and finiteness, one accumulator per coefficient index (the loop vectorises).
  {
    std::array<float, kPtmTerms> lo = s.lo, hi = s.hi;
    bool bad = false;
    const std::size_t n = band_texels * polys_per_texel;
    for (std::size_t k = 0; k < n; k += kPtmTerms) {
      for (int i = 0; i < kPtmTerms; ++i) {
        const float v = polys[k + i];
        bad |= !(std::abs(v) < kHalfLimit);  // NaN, inf, or beyond half range
        lo[i] = std::min(lo[i], v);
        hi[i] = std::max(hi[i], v);
      }
    }
    if (bad) s.finite = false;
    s.lo = lo;
    s.hi = hi;
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
  if (s.spill.fd >= 0) {
    pwrite_all(s.spill.fd, dst, band_texels * hpt * sizeof(std::uint16_t),
               first * hpt * sizeof(std::uint16_t), path_);
  }
  s.next_row = y0 + rows;
}

void PtmStreamWriter::end() {
  Impl& s = *impl_;
  if (!s.begun || s.next_row != s.height) {
    throw std::logic_error("PtmStreamWriter: end() before every row was written");
  }
  if (!s.finite) {
    throw Error(where(path_) +
                ": the fit produced NaN or infinite coefficients (or beyond half-float range); "
                "nothing was written");
  }
  std::array<double, kPtmTerms> lo{}, hi{};
  for (int i = 0; i < kPtmTerms; ++i) {
    lo[i] = 255.0 * static_cast<double>(s.lo[i]);
    hi[i] = 255.0 * static_cast<double>(s.hi[i]);
  }
  PtmFile meta;  // header fields only; the data is written slice by slice
  meta.version = PtmVersion::k1_2;
  meta.format = s.format;
  meta.width = s.width;
  meta.height = s.height;
  meta.quantisation = choose_quantisation(lo, hi);
  const PtmQuantisation& q = meta.quantisation;
  const std::string header = meta.canonical_header();
  const int np = internal::planes(s.format);
  const std::size_t texels = s.texels();
  const std::size_t hpt = static_cast<std::size_t>(s.halfs_per_texel);
  const std::size_t w = static_cast<std::size_t>(s.width);

  report_ = PtmWriteReport{};
  // A coefficient's byte depends only on its index and its half value, so each index gets a
  // table of all 65536 (a libm-free division per coefficient was most of a 12-megapixel
  // kRGB write). The coefficient error likewise: counts of each (index, half) pair give its
  // max and RMS exactly, summed in a fixed order whatever the threads.
  constexpr std::size_t kHalves = 65536;
  std::vector<std::uint8_t> byte_of(kPtmTerms * kHalves);
  std::vector<double> error_of(kPtmTerms * kHalves);
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
  tbb::combinable<std::vector<std::uint32_t>> counts(
      [] { return std::vector<std::uint32_t>(kPtmTerms * kHalves, 0); });
  // Where plane p's term i sits among a texel's halfs.
  auto half_index = [&](int p, int i) {
    if (s.model == ColourModel::kYCC) return i < kPtmTerms - 1 ? i : kPtmTerms - 1 + p;
    return p * kPtmTerms + i;
  };
  AtomicOutput out(path_);
  {
    Fd fd(::open(out.temp_path().c_str(), O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0644));
    if (fd.fd < 0) throw Error(where(path_) + ": cannot open for writing");
    pwrite_all(fd.fd, header.data(), header.size(), 0, path_);
    const std::size_t data0 = header.size();
    std::vector<std::uint16_t> slice_halfs;
    std::vector<std::uint8_t> slice_bytes;
    // Slices of kSliceRows stored rows; stored row j is image row height - 1 - j (bottom-up).
    for (int j0 = 0; j0 < s.height; j0 += kSliceRows) {
      const int nrows = std::min(kSliceRows, s.height - j0);
      const int y_top = s.height - j0 - nrows;  // image rows y_top .. y_top + nrows - 1
      const std::uint16_t* halfs = nullptr;
      if (s.spill.fd >= 0) {
        slice_halfs.resize(static_cast<std::size_t>(nrows) * w * hpt);
        pread_all(s.spill.fd, slice_halfs.data(), slice_halfs.size() * sizeof(std::uint16_t),
                  static_cast<std::size_t>(y_top) * w * hpt * sizeof(std::uint16_t), path_);
        halfs = slice_halfs.data();
      } else {
        halfs = s.halfs.data() + static_cast<std::size_t>(y_top) * w * hpt;
      }
      const std::size_t plane_bytes = static_cast<std::size_t>(nrows) * w * kPtmTerms;
      slice_bytes.resize(plane_bytes * np);
      tbb::parallel_for(0, nrows, [&](int jr) {
        const int y = s.height - 1 - (j0 + jr);
        const std::uint16_t* h = halfs + static_cast<std::size_t>(y - y_top) * w * hpt;
        std::uint32_t* count = counts.local().data();
        for (int p = 0; p < np; ++p) {
          std::uint8_t* b =
              slice_bytes.data() + p * plane_bytes + static_cast<std::size_t>(jr) * w * kPtmTerms;
          for (int i = 0; i < kPtmTerms; ++i) {
            const std::uint8_t* lut = byte_of.data() + i * kHalves;
            std::uint32_t* cnt = count + i * kHalves;
            const std::uint16_t* src = h + half_index(p, i);
            for (std::size_t x = 0; x < w; ++x) {
              const std::uint16_t v = src[x * hpt];
              b[x * kPtmTerms + i] = lut[v];
              ++cnt[v];
            }
          }
        }
      });
      for (int p = 0; p < np; ++p) {
        const std::size_t at =
            data0 +
            (static_cast<std::size_t>(p) * texels + static_cast<std::size_t>(j0) * w) * kPtmTerms;
        pwrite_all(fd.fd, slice_bytes.data() + p * plane_bytes, plane_bytes, at, path_);
      }
      if (s.format == PtmFormat::kLRGB) {
        // The colour block follows the coefficients, in the same bottom-up row order.
        std::vector<std::uint8_t> rgb(static_cast<std::size_t>(nrows) * w * 3);
        for (int jr = 0; jr < nrows; ++jr) {
          const int y = s.height - 1 - (j0 + jr);
          std::copy_n(s.rgb.data() + static_cast<std::size_t>(y) * w * 3, w * 3,
                      rgb.data() + static_cast<std::size_t>(jr) * w * 3);
        }
        pwrite_all(fd.fd, rgb.data(), rgb.size(),
                   data0 + texels * kPtmTerms + static_cast<std::size_t>(j0) * w * 3, path_);
      }
    }
    if (::close(fd.fd) != 0) {
      fd.fd = -1;
      throw Error(where(path_) + ": write failed: " + std::strerror(errno));
    }
    fd.fd = -1;
  }
  report_.format = s.format;
  report_.quantisation = q;
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
  report_.max_coeff_error = mx;
  report_.rms_coeff_error = std::sqrt(sq / static_cast<double>(texels * np * kPtmTerms));
  if (s.sample_stride > 0) {
    const SampleSource source(s, q);
    const auto file_value = [&](int x, int y, double lu, double lv, float v[3]) {
      source.file_value(x, y, lu, lv, v);
    };
    internal::relit_error(source, file_value, s.width, texels, options_, &report_);
  }
  out.commit();
  report_.path = path_;
  report_.file_bytes = header.size() + texels * internal::bytes_per_texel(s.format);
  s = Impl{};
}

}  // namespace ptmkit::texture
