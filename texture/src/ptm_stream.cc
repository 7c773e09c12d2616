// PtmStreamWriter: the fit streams bands in; texels are kept as half floats until end(), which
// encodes and writes the file in slices of rows.
#include <fcntl.h>
#include <immintrin.h>
#include <sys/mman.h>
#include <sys/stat.h>
#include <unistd.h>

#include <Eigen/Core>

#include <array>
#include <cerrno>
#include <cstring>
#include <stdexcept>
#include <string>

#include <tbb/combinable.h>
#include <tbb/parallel_for.h>
#include <tbb/parallel_pipeline.h>
#include <tbb/task_group.h>

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

// internal::colour_byte for 4 values: the same double arithmetic (255 v exact, clamped,
// + 0.5, truncated), so the same bytes. max(b, 0) is 0 for NaN, as b >= 0 ? b : 0 is.
__attribute__((target("avx2"))) inline __m128i colour_ints(const float* p) {
  const __m256d full = _mm256_set1_pd(255.0);
  __m256d b = _mm256_mul_pd(full, _mm256_cvtps_pd(_mm_loadu_ps(p)));
  b = _mm256_min_pd(_mm256_max_pd(b, _mm256_setzero_pd()), full);
  return _mm256_cvttpd_epi32(_mm256_add_pd(b, _mm256_set1_pd(0.5)));
}

// 16 values at a time (the compiler had left the loop scalar); returns the values done.
__attribute__((target("avx2"))) std::size_t colour_bytes_avx2(const float* in, std::size_t n,
                                                              std::uint8_t* out) {
  std::size_t k = 0;
  for (; k + 16 <= n; k += 16) {
    const __m128i lo = _mm_packs_epi32(colour_ints(in + k), colour_ints(in + k + 4));
    const __m128i hi = _mm_packs_epi32(colour_ints(in + k + 8), colour_ints(in + k + 12));
    _mm_storeu_si128(reinterpret_cast<__m128i*>(out + k), _mm_packus_epi16(lo, hi));
  }
  return k;
}

const bool kHaveAvx2 = __builtin_cpu_supports("avx2");

void colour_bytes(const float* in, std::size_t n, std::uint8_t* out) {
  const std::size_t done = kHaveAvx2 ? colour_bytes_avx2(in, n, out) : 0;
  for (std::size_t k = done; k < n; ++k) out[k] = internal::colour_byte(in[k]);
}

// Largest float that rounds to a finite half: 65504 plus just under half a step (16).
constexpr float kHalfLimit = 65520.0f;

// Per coefficient index (position mod 6 of a kRGB or kLRGB band), the smallest and largest
// value, and whether every value is finite and within half range. Both paths below give the
// same answer: a minimum or maximum does not depend on the order it is taken in (but for the
// sign of a zero bound, which write_rows makes +0).
struct Range {
  std::array<float, kPtmTerms> lo, hi;
  bool finite = true;
};

void range_portable(const float* in, std::size_t n, Range* r) {
  for (std::size_t k = 0; k < n; k += kPtmTerms) {
    for (int i = 0; i < kPtmTerms; ++i) {
      const float v = in[k + static_cast<std::size_t>(i)];
      r->finite &= std::abs(v) < kHalfLimit;  // NaN, inf, or beyond half range
      r->lo[static_cast<std::size_t>(i)] = std::min(r->lo[static_cast<std::size_t>(i)], v);
      r->hi[static_cast<std::size_t>(i)] = std::max(r->hi[static_cast<std::size_t>(i)], v);
    }
  }
}

// to_half and the range in one pass over a band's coefficients (they were two, each reading
// the whole band): 24 values (4 texels' terms) a step, in three vectors whose lanes hold
// terms 0-5 0-1, 2-5 0-3 and 4-5 0-5.
__attribute__((target("avx,f16c"))) void half_and_range_f16c(const float* in, std::size_t n,
                                                             std::uint16_t* out, Range* r) {
  constexpr std::size_t kStep = 24;
  __m256 lo[3], hi[3];
  for (int j = 0; j < 3; ++j) {
    lo[j] = _mm256_set1_ps(std::numeric_limits<float>::infinity());
    hi[j] = _mm256_set1_ps(-std::numeric_limits<float>::infinity());
  }
  const __m256 limit = _mm256_set1_ps(kHalfLimit);
  const __m256 abs_mask = _mm256_castsi256_ps(_mm256_set1_epi32(0x7fffffff));
  __m256 ok = _mm256_castsi256_ps(_mm256_set1_epi32(-1));
  std::size_t k = 0;
  for (; k + kStep <= n; k += kStep) {
    for (int j = 0; j < 3; ++j) {
      const __m256 v = _mm256_loadu_ps(in + k + 8 * j);
      _mm_storeu_si128(reinterpret_cast<__m128i*>(out + k + 8 * j),
                       _mm256_cvtps_ph(v, _MM_FROUND_TO_NEAREST_INT));
      ok = _mm256_and_ps(ok, _mm256_cmp_ps(_mm256_and_ps(v, abs_mask), limit, _CMP_LT_OQ));
      lo[j] = _mm256_min_ps(v, lo[j]);  // a NaN leaves lo (and is caught by ok)
      hi[j] = _mm256_max_ps(v, hi[j]);
    }
  }
  alignas(32) float l[3][8], h[3][8];
  for (int j = 0; j < 3; ++j) {
    _mm256_store_ps(l[j], lo[j]);
    _mm256_store_ps(h[j], hi[j]);
  }
  for (int j = 0; j < 3; ++j) {
    for (int t = 0; t < 8; ++t) {
      const auto i = static_cast<std::size_t>((8 * j + t) % kPtmTerms);
      r->lo[i] = std::min(r->lo[i], l[j][t]);
      r->hi[i] = std::max(r->hi[i], h[j][t]);
    }
  }
  r->finite &= _mm256_movemask_ps(ok) == 0xff;
  to_half(in + k, n - k, out + k);
  range_portable(in + k, n - k, r);
}

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

// The whole pages inside the bytes [begin, end) (addresses or file offsets): [lo, hi), none
// when hi <= lo.
struct PageSpan {
  std::uintptr_t lo = 0, hi = 0;
};
PageSpan whole_pages(std::uintptr_t begin, std::uintptr_t end) {
  const auto page = static_cast<std::uintptr_t>(::sysconf(_SC_PAGESIZE));
  return {(begin + page - 1) / page * page, end / page * page};
}

// A whole image's worth of bytes (the half floats, LRGB's colours) in anonymous memory: the
// kernel's zero pages, first touched by the band that fills them, while the next band
// decodes, instead of an up-front fill on one thread. (Transparent huge pages were tried:
// fewer faults, but clearing 2 MiB pages cost more CPU than the faults saved.) end() gives
// each slice's pages back once it is encoded (discard).
template <class T>
class LargeBuffer {
 public:
  LargeBuffer() = default;
  LargeBuffer(const LargeBuffer&) = delete;
  LargeBuffer& operator=(const LargeBuffer&) = delete;
  LargeBuffer(LargeBuffer&& o) noexcept { swap(o); }
  LargeBuffer& operator=(LargeBuffer&& o) noexcept {
    swap(o);
    return *this;
  }
  ~LargeBuffer() { release(); }

  // n zeroed elements; throws std::bad_alloc when the memory is not there.
  void allocate(std::size_t n) {
    release();
    if (n == 0) return;
    void* p =
        ::mmap(nullptr, n * sizeof(T), PROT_READ | PROT_WRITE, MAP_PRIVATE | MAP_ANONYMOUS, -1, 0);
    if (p == MAP_FAILED) throw std::bad_alloc();
    data_ = static_cast<T*>(p);
    size_ = n;
  }
  // Gives back to the kernel the whole pages inside elements [first, first + n), whose values
  // are no longer needed (they read as zero afterwards). Pages shared with the elements either
  // side stay.
  void discard(std::size_t first, std::size_t n) {
    if (data_ == nullptr || n == 0) return;
    const PageSpan p = whole_pages(reinterpret_cast<std::uintptr_t>(data_ + first),
                                   reinterpret_cast<std::uintptr_t>(data_ + first + n));
    if (p.hi > p.lo) ::madvise(reinterpret_cast<void*>(p.lo), p.hi - p.lo, MADV_DONTNEED);
  }
  [[nodiscard]] T* data() { return data_; }
  [[nodiscard]] const T* data() const { return data_; }
  [[nodiscard]] std::size_t size() const { return size_; }
  T& operator[](std::size_t k) { return data_[k]; }
  const T& operator[](std::size_t k) const { return data_[k]; }

 private:
  void swap(LargeBuffer& o) noexcept {
    std::swap(data_, o.data_);
    std::swap(size_, o.size_);
  }
  void release() {
    if (data_ != nullptr) ::munmap(data_, size_ * sizeof(T));
    data_ = nullptr;
    size_ = 0;
  }
  T* data_ = nullptr;
  std::size_t size_ = 0;
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

// Frees the whole pages of a file's bytes [offset, offset + bytes) that are no longer needed.
// Only an economy: a file system without hole punching keeps them until the file is closed.
void punch_hole(int fd, std::size_t offset, std::size_t bytes) {
  const PageSpan p = whole_pages(offset, offset + bytes);
  if (p.hi > p.lo) {
    (void)::fallocate(fd, FALLOC_FL_PUNCH_HOLE | FALLOC_FL_KEEP_SIZE, static_cast<off_t>(p.lo),
                      static_cast<off_t>(p.hi - p.lo));
  }
}

// A regular file about to be replaced by the output: its cached pages go anyway when the new
// file is renamed over it. Dropping them now hands their memory to this write (the
// coefficients, the temporary file, the new file's pages), which otherwise takes memory the
// process has never touched; that costs more (on a virtual machine, a fault in the host too):
// a 12-megapixel RGB fit over its previous output took 0.1 s less (docs/PERFORMANCE.md). The
// file's contents are untouched, so a failed run leaves it as it was; only clean pages go (the
// kernel starts the write-back of dirty ones and keeps them). Anything else at the path (no
// file, a symbolic link, a FIFO, a device) is left alone; O_NONBLOCK keeps a FIFO's open from
// waiting for a writer.
void drop_cached(const std::filesystem::path& path) {
  const Fd fd(::open(path.c_str(), O_RDONLY | O_CLOEXEC | O_NOFOLLOW | O_NONBLOCK));
  struct stat st {};
  if (fd.fd < 0 || ::fstat(fd.fd, &st) != 0 || !S_ISREG(st.st_mode)) return;
  (void)::posix_fadvise(fd.fd, 0, 0, POSIX_FADV_DONTNEED);
}

// Rows per slice of end()'s encoding: enough texels per slice for the threads to share, few
// enough that the slices in flight stay small (64 rows held 40 MiB more at the peak of a
// 12-megapixel RGB fit, for no speed).
constexpr int kSliceRows = 16;

}  // namespace

struct PtmStreamWriter::Impl {
  int width = 0;
  int height = 0;
  ColourModel model = ColourModel::kRGB;
  PtmFormat format = PtmFormat::kRGB;
  // Halfs per texel: 18 (kRGB), 8 (kYCC: a0..a4 shared, then a5 of R, G, B), 6 (kLRGB).
  int halfs_per_texel = 18;
  // Rows 0 .. memory_rows - 1 of half floats are held in memory; the rest (when the whole
  // would exceed PtmWriteOptions::spill_above_bytes) in an unnamed temporary file, row y at
  // (y - memory_rows) row_halfs() halfs.
  int memory_rows = 0;
  LargeBuffer<std::uint16_t> halfs;
  Fd spill;
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

bool PtmStreamWriter::spilled() const { return impl_->spill.fd >= 0; }

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
  s.sample_stride = internal::relit_sample_stride(texels, options_);
  if (s.sample_stride > 0) {
    const std::size_t samples = (texels + s.sample_stride - 1) / s.sample_stride;
    s.sample_halfs.assign(samples * s.halfs_per_texel, 0);
    if (model == ColourModel::kLRGB) s.sample_rgb.assign(samples * 3, 0);
  }
  s.lo.fill(std::numeric_limits<float>::infinity());
  s.hi.fill(-std::numeric_limits<float>::infinity());
  drop_cached(options_.replaces.empty() ? path_ : options_.replaces);
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
  } else if (kHaveF16C) {
    // kRGB and kLRGB: the fit's layout is the file's.
    half_and_range_f16c(coeffs, band_texels * hpt, dst, &range);
  } else {
    to_half(coeffs, band_texels * hpt, dst);
    range_portable(coeffs, band_texels * hpt, &range);
  }
  // A zero bound is +0 whichever zero was met first (0.0f + -0.0f is +0).
  for (int i = 0; i < kPtmTerms; ++i) {
    s.lo[static_cast<std::size_t>(i)] = range.lo[static_cast<std::size_t>(i)] + 0.0f;
    s.hi[static_cast<std::size_t>(i)] = range.hi[static_cast<std::size_t>(i)] + 0.0f;
  }
  if (!range.finite) s.finite = false;
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
    pwrite_all(s.spill.fd, dst + kept_halfs,
               (band_texels * hpt - kept_halfs) * sizeof(std::uint16_t),
               spilled_row * s.row_halfs() * sizeof(std::uint16_t), path_);
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
  AtomicOutput out(path_);
  {
    Fd fd(::open(out.temp_path().c_str(), O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0644));
    if (fd.fd < 0) throw Error(where(path_) + ": cannot open for writing");
    pwrite_all(fd.fd, header.data(), header.size(), 0, path_);
    const std::size_t data0 = header.size();
    // Slices of kSliceRows stored rows, through a pipeline: slices read their half floats
    // (from the spill file, if any) and are encoded in parallel, and are written in order by
    // one thread at a time (writes to one file serialise in the kernel anyway; two threads
    // writing at once only spin on its lock). Stored row j is image row height - 1 - j
    // (bottom-up).
    const int slices = (s.height + kSliceRows - 1) / kSliceRows;
    struct Slice {
      int j0 = 0, nrows = 0;
      std::vector<std::uint16_t> halfs;
      std::vector<std::uint8_t> bytes, rgb;
    };
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
    const auto encode_slice = [&](Slice* slice) -> Slice* {
      Slice& buf = *slice;
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
        pread_all(s.spill.fd, buf.halfs.data() + static_cast<std::size_t>(kept) * row_halfs,
                  static_cast<std::size_t>(nrows - kept) * row_halfs * sizeof(std::uint16_t),
                  static_cast<std::size_t>(y_top + kept - s.memory_rows) * row_halfs *
                      sizeof(std::uint16_t),
                  path_);
        halfs = buf.halfs.data();
      }
      const std::size_t plane_bytes = static_cast<std::size_t>(nrows) * w * kPtmTerms;
      buf.bytes.resize(plane_bytes * np);
      std::uint32_t* count = counts.local().data();
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
        s.rgb.discard(static_cast<std::size_t>(y_top) * w * 3,
                      static_cast<std::size_t>(nrows) * w * 3);
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
          punch_hole(
              s.spill.fd,
              static_cast<std::size_t>(y_top + in_memory - s.memory_rows) * row_halfs *
                  sizeof(std::uint16_t),
              static_cast<std::size_t>(nrows - in_memory) * row_halfs * sizeof(std::uint16_t));
        }
      }
      return slice;
    };
    const auto write_slice = [&](Slice* slice) {
      const Slice& buf = *slice;
      const std::size_t plane_bytes = static_cast<std::size_t>(buf.nrows) * w * kPtmTerms;
      for (int p = 0; p < np; ++p) {
        const std::size_t at =
            data0 + (static_cast<std::size_t>(p) * texels + static_cast<std::size_t>(buf.j0) * w) *
                        kPtmTerms;
        pwrite_all(fd.fd, buf.bytes.data() + p * plane_bytes, plane_bytes, at, path_);
      }
      if (s.format == PtmFormat::kLRGB) {
        pwrite_all(fd.fd, buf.rgb.data(), buf.rgb.size(),
                   data0 + texels * kPtmTerms + static_cast<std::size_t>(buf.j0) * w * 3, path_);
      }
    };
    tbb::parallel_pipeline(
        kTokens,
        tbb::make_filter<void, Slice*>(tbb::filter_mode::serial_in_order, read_slice) &
            tbb::make_filter<Slice*, Slice*>(tbb::filter_mode::parallel, encode_slice) &
            tbb::make_filter<Slice*, void>(tbb::filter_mode::serial_in_order, write_slice));
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
  relit.wait();
  report_.relit_mean_abs_grey = relit_report.relit_mean_abs_grey;
  report_.relit_max_abs_grey = relit_report.relit_max_abs_grey;
  report_.relit_psnr_db = relit_report.relit_psnr_db;
  report_.relit_samples = relit_report.relit_samples;
  out.commit();
  report_.path = path_;
  report_.file_bytes = header.size() + texels * internal::bytes_per_texel(s.format);
  s = Impl{};
}

}  // namespace ptmkit::texture
