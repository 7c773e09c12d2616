// PtmStreamWriter: the fit streams bands in; texels are kept as half floats until end().
#include <Eigen/Core>

#include <stdexcept>
#include <string>

#include "ptm_internal.h"
#include "ptmkit/core/error.h"
#include "ptmkit/texture/ptm.h"

namespace ptmkit::texture {

struct PtmStreamWriter::Impl {
  int width = 0;
  int height = 0;
  ColourModel model = ColourModel::kRGB;
  PtmFormat format = PtmFormat::kRGB;
  // Halfs per texel: 18 (kRGB), 8 (kYCC: a0..a4 shared, then a5 of R, G, B), 6 (kLRGB).
  int halfs_per_texel = 18;
  std::vector<Eigen::half> coeffs;
  std::vector<std::uint8_t> rgb;  // kLRGB only
  std::array<double, kPtmTerms> lo{}, hi{};
  bool finite = true;
  bool begun = false;
  int next_row = 0;

  [[nodiscard]] std::size_t texel(int x, int y) const {
    return static_cast<std::size_t>(y) * width + x;
  }
};

namespace {

// The stored half values seen as an encoder source.
class HalfSource {
 public:
  explicit HalfSource(const PtmStreamWriter::Impl& s) : s_(s) {}

  void texel(int x, int y, float* polys, std::uint8_t* rgb) const {
    const std::size_t t = s_.texel(x, y);
    const Eigen::half* h = s_.coeffs.data() + t * s_.halfs_per_texel;
    switch (s_.model) {
      case ColourModel::kRGB:
        for (int k = 0; k < 3 * kPtmTerms; ++k) polys[k] = static_cast<float>(h[k]);
        break;
      case ColourModel::kYCC:
        for (int p = 0; p < 3; ++p) {
          for (int i = 0; i < kPtmTerms - 1; ++i)
            polys[p * kPtmTerms + i] = static_cast<float>(h[i]);
          polys[p * kPtmTerms + kPtmTerms - 1] = static_cast<float>(h[kPtmTerms - 1 + p]);
        }
        break;
      case ColourModel::kLRGB:
        for (int k = 0; k < kPtmTerms; ++k) polys[k] = static_cast<float>(h[k]);
        for (int c = 0; c < 3; ++c) rgb[c] = s_.rgb[t * 3 + c];
        break;
    }
  }

  void relit(int x, int y, double lu, double lv, float out[3]) const {
    float polys[3 * kPtmTerms] = {};
    std::uint8_t rgb[3] = {0, 0, 0};
    texel(x, y, polys, rgb);
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
      for (int c = 0; c < 3; ++c) out[c] = static_cast<float>(l * rgb[c] / 255.0);
    }
  }

 private:
  const PtmStreamWriter::Impl& s_;
};

}  // namespace

PtmStreamWriter::PtmStreamWriter(std::filesystem::path path, PtmWriteOptions options)
    : path_(std::move(path)), options_(std::move(options)), impl_(std::make_unique<Impl>()) {}

PtmStreamWriter::~PtmStreamWriter() = default;

std::size_t PtmStreamWriter::buffer_bytes() const {
  return impl_->coeffs.size() * sizeof(Eigen::half) + impl_->rgb.size();
}

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
  const std::size_t texels = static_cast<std::size_t>(width) * height;
  s.coeffs.assign(texels * s.halfs_per_texel, Eigen::half(0.0f));
  if (model == ColourModel::kLRGB) s.rgb.assign(texels * 3, 0);
  s.lo.fill(std::numeric_limits<double>::infinity());
  s.hi.fill(-std::numeric_limits<double>::infinity());
  s.begun = true;
}

void PtmStreamWriter::write_rows(int y0, int rows, const float* coeffs, const float* colour) {
  Impl& s = *impl_;
  if (!s.begun || y0 != s.next_row || rows < 0 || y0 + rows > s.height) {
    throw std::logic_error("PtmStreamWriter: bands must arrive in order after begin()");
  }
  const int np = polynomial_count(s.model) * kPtmTerms;
  const int nc = colour_count(s.model);
  const int file_planes = internal::planes(s.format);
  for (int y = y0; y < y0 + rows; ++y) {
    for (int x = 0; x < s.width; ++x) {
      const std::size_t band_texel = static_cast<std::size_t>(y - y0) * s.width + x;
      const float* a = coeffs + band_texel * np;
      const float* col = nc > 0 ? colour + band_texel * nc : nullptr;
      float polys[3 * kPtmTerms] = {};
      std::uint8_t rgb[3] = {0, 0, 0};
      internal::file_polynomials(s.model, a, col, polys, rgb);
      const std::size_t t = s.texel(x, y);
      Eigen::half* h = s.coeffs.data() + t * s.halfs_per_texel;
      if (s.model == ColourModel::kYCC) {
        for (int i = 0; i < kPtmTerms - 1; ++i) h[i] = Eigen::half(polys[i]);
        for (int p = 0; p < 3; ++p) h[kPtmTerms - 1 + p] = Eigen::half(polys[p * kPtmTerms + 5]);
      } else {
        for (int k = 0; k < file_planes * kPtmTerms; ++k) h[k] = Eigen::half(polys[k]);
      }
      if (s.model == ColourModel::kLRGB) {
        for (int c = 0; c < 3; ++c) s.rgb[t * 3 + c] = rgb[c];
      }
      // Range of the values before rounding to half: the quantisation (scales, biases) is then
      // exactly write_ptm's, and only bytes whose value sits within half-float rounding of a
      // byte boundary can differ. (A half rounded past the range's end clamps harmlessly.)
      for (int p = 0; p < file_planes; ++p) {
        for (int i = 0; i < kPtmTerms; ++i) {
          const double v = polys[p * kPtmTerms + i];
          if (!std::isfinite(v) || !std::isfinite(static_cast<float>(Eigen::half(v)))) {
            s.finite = false;
            continue;
          }
          s.lo[i] = std::min(s.lo[i], v);
          s.hi[i] = std::max(s.hi[i], v);
        }
      }
    }
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
  std::array<double, kPtmTerms> lo = s.lo, hi = s.hi;
  for (int i = 0; i < kPtmTerms; ++i) {
    lo[i] *= 255.0;
    hi[i] *= 255.0;
  }
  const PtmQuantisation q = choose_quantisation(lo, hi);
  report_ = PtmWriteReport{};
  const PtmFile file =
      internal::encode(HalfSource(s), s.width, s.height, s.format, q, options_, &report_);
  write_ptm_file(path_, file);
  report_.path = path_;
  report_.file_bytes = file.canonical_header().size() + file.data.size();
  s.coeffs = {};
  s.rgb = {};
  s.begun = false;
}

}  // namespace ptmkit::texture
