#include "ptmkit/fit/fit.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <functional>
#include <limits>
#include <optional>

#include <tbb/parallel_for.h>
#include <tbb/task_arena.h>
#include <tbb/task_group.h>
#include <Eigen/Cholesky>
#include <Eigen/Core>
#include <nlohmann/json.hpp>

#include "kernels.h"
#include "ptmkit/core/atomic_file.h"
#include "ptmkit/core/colour.h"
#include "ptmkit/core/error.h"
#include "ptmkit/core/image_io.h"
#include "ptmkit/core/stack_reader.h"

namespace ptmkit::fit {

namespace {

using Clock = std::chrono::steady_clock;
double seconds_since(Clock::time_point t0) {
  return std::chrono::duration<double>(Clock::now() - t0).count();
}

using RowMajorF = Eigen::Matrix<float, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;
using SampleMap = Eigen::Map<const RowMajorF, 0, Eigen::OuterStride<>>;
using CoeffMap = Eigen::Map<Eigen::Matrix<float, kPtmTerms, Eigen::Dynamic>>;

// Histogram of |residual| in grey levels: 0.05-grey bins up to 256, one overflow bin.
constexpr double kHistBinsPerGrey = 20.0;
constexpr int kHistBins = 5121;

struct RowStats {
  bool active = false;  // this row is in the residual-statistics sample
  OutlierSummary outliers;
  std::uint64_t singular_texels = 0;  // near lights: normal matrix not positive definite
  double sum_sq = 0.0;
  double sum_abs = 0.0;
  double max_abs = 0.0;
  std::uint64_t count = 0;
  std::vector<std::uint32_t> hist;
  void add(double r_grey) {
    const double a = std::abs(r_grey);
    sum_sq += a * a;
    sum_abs += a;
    max_abs = std::max(max_abs, a);
    ++count;
    ++hist[bin(a)];
  }
  // n residuals at once (an image's row of a sampled row, in the shared-matrix fit). The sums
  // run in 8 lanes combined in a fixed order (the same totals whatever the threads), and the
  // bins come from a loop of their own, which vectorises: a division per sample in add() had
  // been 3% of a 12-megapixel fit's CPU.
  void add_all(const float* r, std::size_t n) {
    double sq[8] = {}, ab[8] = {}, mx[8] = {};
    std::size_t k = 0;
    for (; k + 8 <= n; k += 8) {
      for (int j = 0; j < 8; ++j) {
        const double a = std::abs(static_cast<double>(r[k + j]));
        sq[j] += a * a;
        ab[j] += a;
        mx[j] = std::max(mx[j], a);
      }
    }
    for (; k < n; ++k) {
      const double a = std::abs(static_cast<double>(r[k]));
      sq[0] += a * a;
      ab[0] += a;
      mx[0] = std::max(mx[0], a);
    }
    for (int j = 0; j < 8; ++j) {
      sum_sq += sq[j];
      sum_abs += ab[j];
      max_abs = std::max(max_abs, mx[j]);
    }
    count += n;
    // The bins first (a loop that vectorises), then the counts.
    thread_local std::vector<std::uint32_t> bins;
    bins.resize(n);
    constexpr auto kLast = static_cast<float>(kHistBins - 1);
    for (k = 0; k < n; ++k) {
      const float b = std::abs(r[k]) * static_cast<float>(kHistBinsPerGrey);
      bins[k] = static_cast<std::uint32_t>(b < kLast ? b : kLast);  // NaN: the overflow bin
    }
    for (k = 0; k < n; ++k) ++hist[bins[k]];
  }
  // The histogram bin of |residual| a (NaN in the overflow bin).
  static std::size_t bin(double a) {
    const double b = a * kHistBinsPerGrey;
    return b < kHistBins - 1 ? static_cast<std::size_t>(b) : kHistBins - 1;
  }
};

struct StatsTotal {
  double sum_sq = 0.0, sum_abs = 0.0, max_abs = 0.0;
  std::uint64_t count = 0;
  std::vector<std::uint64_t> hist = std::vector<std::uint64_t>(kHistBins, 0);
  OutlierSummary outliers;
  std::uint64_t singular_texels = 0;
  void merge_outliers(const RowStats& r) {
    singular_texels += r.singular_texels;
    outliers.samples += r.outliers.samples;
    outliers.shadows += r.outliers.shadows;
    outliers.highlights += r.outliers.highlights;
    outliers.fallback_texels += r.outliers.fallback_texels;
    outliers.ceres_texels += r.outliers.ceres_texels;
  }
  void merge(const RowStats& r) {
    sum_sq += r.sum_sq;
    sum_abs += r.sum_abs;
    max_abs = std::max(max_abs, r.max_abs);
    count += r.count;
    for (int i = 0; i < kHistBins; ++i) hist[i] += r.hist[i];
  }
  ResidualStats finish() const {
    ResidualStats s;
    s.samples = count;
    if (count == 0) return s;
    s.rms_grey = std::sqrt(sum_sq / static_cast<double>(count));
    s.mean_abs_grey = sum_abs / static_cast<double>(count);
    s.max_abs_grey = max_abs;
    const auto target = static_cast<std::uint64_t>(std::ceil(0.99 * static_cast<double>(count)));
    std::uint64_t acc = 0;
    for (int i = 0; i < kHistBins; ++i) {
      acc += hist[i];
      if (acc >= target) {
        s.p99_abs_grey = (i + 1) / kHistBinsPerGrey;
        break;
      }
    }
    return s;
  }
};

// Residual statistics are a summary, not a product: above 65 536 texels they use every k-th
// row (a fixed choice, so reports are reproducible), which keeps their cost off large images:
// at 2^18 texels they were still a tenth of the fit's own CPU on a 12-megapixel stack. 2^16
// texels x 49 lights x 3 channels is 9.6 million residuals.
constexpr double kResidualSampleTexels = 1 << 16;
int residual_row_step(int width, int height) {
  const double texels = static_cast<double>(width) * height;
  return std::max(1, static_cast<int>(std::ceil(texels / kResidualSampleTexels)));
}

// The seed paper's constant chromaticity from luminance-weighted sums of Cb and Cr.
void finish_ycc_chroma(double sy, double scb, double scr, float* colour) {
  colour[0] = sy > 1e-20 ? static_cast<float>(scb / sy) : 0.0f;
  colour[1] = sy > 1e-20 ? static_cast<float>(scr / sy) : 0.0f;
}

// The near-light model of a fit (null model: distant lights, the shared-matrix path).
struct NearFit {
  const NearLightModel* model = nullptr;
  bool falloff = false;
  double ridge_lambda = 0.0;  // relative to the number of lights, as DesignOptions'
  // Photo pixel of texel (0, 0) (a crop or mask box): the plane maps photo pixels.
  int origin_x = 0;
  int origin_y = 0;
};

// One texel's light geometry under near lights: design rows, directions, sample corrections.
struct TexelGeometry {
  Eigen::Matrix<double, Eigen::Dynamic, kPtmTerms, Eigen::RowMajor> basis;  // N x 6
  Eigen::Matrix<double, Eigen::Dynamic, 3, Eigen::RowMajor> dirs;           // N x 3
  std::vector<double> correction;                                           // N
};

// Fits one band. Output buffers: coeffs [texel][poly][term], colour [texel][colours].
class BandFitter {
 public:
  BandFitter(const LightDesign& design, const FitOptions& options, int width, int height,
             int channels, ColourSpace colour_space, const NearFit& near = {})
      : design_(design),
        options_(options),
        width_(width),
        channels_(channels),
        srgb_(colour_space == ColourSpace::kSRGB),
        residual_row_step_(residual_row_step(width, height)),
        near_(near) {
    a_f_ = design.design().cast<float>();
    pinv_f255_ = (design.pseudo_inverse() / 255.0).cast<float>();
    const auto n = design.design().rows();
    light_.resize(n, 3);
    for (Eigen::Index i = 0; i < n; ++i) {
      const double lu = design.design()(i, 3);
      const double lv = design.design()(i, 4);
      light_.row(i) << lu, lv, std::sqrt(std::max(0.0, 1.0 - lu * lu - lv * lv));
    }
    robust_ = !is_shared_solver(options.solver);
    const FitOutputs* o = options.outputs;
    extras_ = o != nullptr &&
              (o->want_residual_map || o->want_outlier_counts || o->want_labels || o->want_normals);
  }

  void fit(const StackBand& band, std::vector<float>* coeffs, std::vector<float>* colour,
           std::vector<RowStats>* stats) const {
    const int polys = polynomial_count(options_.model);
    const int ncol = colour_count(options_.model);
    const std::size_t n_coeffs = static_cast<std::size_t>(band.rows) * width_ * polys * kPtmTerms;
    const std::size_t n_colour = static_cast<std::size_t>(band.rows) * width_ * ncol;
#ifdef __SANITIZE_ADDRESS__
    // Every path writes every value, so release builds only size the buffers (filling them
    // was a memset of a band's whole output per band). Sanitizer builds fill them with NaN:
    // a value some path leaves unwritten then fails the tests (the writers refuse NaN).
    coeffs->assign(n_coeffs, std::numeric_limits<float>::quiet_NaN());
    colour->assign(n_colour, std::numeric_limits<float>::quiet_NaN());
#else
    coeffs->resize(n_coeffs);
    colour->resize(n_colour);
#endif
    stats->assign(static_cast<std::size_t>(band.rows), RowStats{});
    tbb::parallel_for(0, band.rows, [&](int r) {
      RowStats& st = (*stats)[static_cast<std::size_t>(r)];
      st.active = options_.residual_stats && (band.y0 + r) % residual_row_step_ == 0;
      if (st.active) st.hist.assign(kHistBins, 0);
      float* c_out = coeffs->data() + static_cast<std::size_t>(r) * width_ * polys * kPtmTerms;
      float* col_out = colour->data() + static_cast<std::size_t>(r) * width_ * ncol;
      if (near_.model != nullptr) {
        fit_row_near(band, r, c_out, col_out, &st);
      } else if (robust_) {
        fit_row_texels(band, r, c_out, col_out, &st);
      } else {
        fit_row(band, r, c_out, col_out, &st);
        if (extras_) row_extras(band, r, c_out, col_out);
      }
    });
  }

 private:
  // How apply() takes its samples in float precision: as they are (times P), or in 0..255
  // units (times P / 255), either scaled from 0..1 on the way or already so (LRGB's lumas).
  enum class Units { kAsIs, kScaleTo255, kIn255 };

  // P (6 x N) times a sample matrix (N x M) into a 6 x M column-major output. Double precision
  // takes every sample as it is (kAsIs only).
  template <class Samples>
  void apply(const Samples& s, float* out, Eigen::Index m, Units units = Units::kAsIs) const {
    CoeffMap c(out, kPtmTerms, m);
    if (options_.precision == Precision::kDouble) {
      c = (design_.pseudo_inverse() * s.template cast<double>()).template cast<float>();
      return;
    }
    const Eigen::MatrixXf& p = units == Units::kAsIs ? design_.pseudo_inverse_f() : pinv_f255_;
    const float scale = units == Units::kScaleTo255 ? 255.0f : 1.0f;
    internal::apply_pinv(p.data(), static_cast<int>(p.cols()), s.data(),
                         static_cast<std::ptrdiff_t>(s.outerStride()), m, out, scale);
  }

  void fit_row(const StackBand& band, int r, float* c_out, float* col_out, RowStats* st) const {
    // 8-bit RGB bands: the RGB product and the one-pass LRGB row read the bytes themselves;
    // everything else gets this row of every image as floats first.
    const bool fast_bytes = band.is_u8 && channels_ == 3 &&
                            options_.precision == Precision::kFloat &&
                            options_.model != ColourModel::kYCC;
    if (fast_bytes) {
      fit_row_bytes(band, r, c_out, col_out);
      if (st->active) row_residuals(row_samples(band, r), c_out, col_out, st);
      return;
    }
    const SampleMap samples = row_samples(band, r);
    fit_row_samples(samples, c_out, col_out);
    if (st->active) row_residuals(samples, c_out, col_out, st);
  }

  // Row r of every image as floats: the band's own, or its bytes converted (v / 255) into a
  // per-thread buffer that stays valid until this thread's next call.
  SampleMap row_samples(const StackBand& band, int r) const {
    const int n = band.images;
    const std::size_t m = static_cast<std::size_t>(width_) * channels_;
    const std::size_t row_offset = static_cast<std::size_t>(r) * m;
    if (!band.is_u8) {
      return {band.image(0) + row_offset, n, static_cast<Eigen::Index>(m),
              Eigen::OuterStride<>(static_cast<Eigen::Index>(band.image_stride()))};
    }
    thread_local std::vector<float> row_floats;
    row_floats.resize(static_cast<std::size_t>(n) * m);
    for (int i = 0; i < n; ++i) {
      internal::bytes_to_unit(band.image_u8(i) + row_offset, m, row_floats.data() + i * m);
    }
    return {row_floats.data(), n, static_cast<Eigen::Index>(m),
            Eigen::OuterStride<>(static_cast<Eigen::Index>(m))};
  }

  // RGB or LRGB of a row of 8-bit RGB texels, from the bytes (the same bits as converting them
  // first and fit_row_samples).
  void fit_row_bytes(const StackBand& band, int r, float* c_out, float* col_out) const {
    const int w = width_;
    const std::size_t row_offset = static_cast<std::size_t>(r) * w * 3;
    const auto& p = pinv_f255_;  // the bytes are the samples in 0..255 units
    const std::uint8_t* first = band.image_u8(0) + row_offset;
    const auto stride = static_cast<std::ptrdiff_t>(band.image_stride());
    if (options_.model == ColourModel::kRGB) {
      internal::apply_pinv_u8(p.data(), static_cast<int>(p.cols()), first, stride,
                              static_cast<std::ptrdiff_t>(w) * 3, c_out);
      return;
    }
    // The luma, the colour sums and the product in one pass over the bytes.
    thread_local std::vector<float> sums;
    sums.resize(static_cast<std::size_t>(w) * 4);
    float* s0 = sums.data();
    float* s1 = s0 + w;
    float* s2 = s1 + w;
    float* s3 = s2 + w;
    internal::lrgb_row_u8(p.data(), static_cast<int>(p.cols()), first, stride, w, c_out, s0, s1, s2,
                          s3);
    internal::finish_lrgb_row(s0, s1, s2, s3, w, col_out, c_out);
  }

  // Any model from a row's float samples (N x W * channels).
  void fit_row_samples(const SampleMap& samples, float* c_out, float* col_out) const {
    const int n = static_cast<int>(samples.rows());
    const int w = width_;
    const int ch = channels_;
    // Float precision fits colour samples in 0..255 units, as the 8-bit path does (the same
    // bits for 8-bit images, whichever way they were read).
    const bool float_colour = ch == 3 && options_.precision == Precision::kFloat;
    if (options_.model == ColourModel::kRGB) {
      if (ch == 3) {
        apply(samples, c_out, static_cast<Eigen::Index>(w) * 3,
              float_colour ? Units::kScaleTo255 : Units::kAsIs);
        return;
      }
      // Grey input: the same polynomial for R, G and B.
      std::vector<float> grey(static_cast<std::size_t>(w) * kPtmTerms);
      apply(samples, grey.data(), w);
      for (int x = 0; x < w; ++x) {
        for (int c = 0; c < 3; ++c) {
          std::copy_n(grey.data() + x * kPtmTerms, kPtmTerms, c_out + (x * 3 + c) * kPtmTerms);
        }
      }
      return;
    }

    // Luminance models: fit Y, then a per-texel colour. One pass over the samples, image by
    // image (each image's row is contiguous), makes the luma and the per-texel sums the colour
    // needs; walking texel by texel instead would stride across all N images per texel.
    const bool lrgb = options_.model == ColourModel::kLRGB;
    const int ncol = colour_count(options_.model);
    // In chunks of texels, so that the N luma rows written here are still in the core's
    // cache when the product reads them back (a whole 4000-texel row of 49 images is 0.8 MB).
    // Every texel's arithmetic is the same whatever the chunk: the same bits.
    constexpr int kChunk = 1024;
    // Scratch reused chunk after chunk (a fresh buffer per row would be mapped and unmapped
    // by the allocator each time, and the page faults and TLB flushes cost more than the fit).
    thread_local std::vector<float> y_scratch, sum_scratch;
    for (int x0 = 0; x0 < w; x0 += kChunk) {
      const int cw = std::min(kChunk, w - x0);
      y_scratch.resize(static_cast<std::size_t>(n) * cw);
      sum_scratch.assign(static_cast<std::size_t>(cw) * 4, 0.0f);
      const Eigen::Map<const RowMajorF> y(y_scratch.data(), n, cw);
      // Per texel, one array each (so the loop vectorises): LRGB sum Y^2, sum Y r, sum Y g,
      // sum Y b; YCC sum w, sum w Cb, sum w Cr. Float sums of N terms below 1 keep a relative
      // error near N * 6e-8, far below what an 8-bit colour can show.
      float* s0 = sum_scratch.data();
      float* s1 = s0 + cw;
      float* s2 = s1 + cw;
      float* s3 = s2 + cw;
      for (int i = 0; i < n; ++i) {
        float* yi = y_scratch.data() + static_cast<std::ptrdiff_t>(i) * cw;
        const float* s =
            samples.data() + static_cast<std::ptrdiff_t>(i) * samples.outerStride() + x0 * ch;
        if (ch != 3) {  // grey: colour (1, 1, 1) up to scale, chroma 0
          for (int x = 0; x < cw; ++x) {
            yi[x] = s[x];
            s0[x] += s[x] * s[x];
          }
          continue;
        }
        if (lrgb) {
          internal::luma_lrgb_row(s, cw, float_colour ? 255.0f : 1.0f, yi, s0, s1, s2, s3);
        } else {
          internal::luma_ycc_row(s, cw, yi, s0, s1, s2);
        }
      }
      if (ch != 3) {
        std::copy_n(s0, cw, s1);
        std::copy_n(s0, cw, s2);
        std::copy_n(s0, cw, s3);
        if (!lrgb) std::fill_n(s0, 3 * static_cast<std::size_t>(cw), 0.0f);
      }
      float* c_chunk = c_out + static_cast<std::ptrdiff_t>(x0) * kPtmTerms;
      apply(y, c_chunk, cw, lrgb && float_colour ? Units::kIn255 : Units::kAsIs);
      for (int x = 0; x < cw; ++x) {
        float* col = col_out + static_cast<std::ptrdiff_t>(x0 + x) * ncol;
        if (lrgb) {
          const double yc[3] = {s1[x], s2[x], s3[x]};
          internal::finish_lrgb_colour(s0[x], yc, col, c_chunk + x * kPtmTerms);
        } else {
          finish_ycc_chroma(s0[x], s1[x], s2[x], col);
        }
      }
    }
  }

  // The residual statistics of a sampled row: every sample against the fitted model, in grey
  // levels, image by image (a row of residuals at a time keeps the buffer in the cache).
  void row_residuals(const SampleMap& samples, const float* c_out, const float* col_out,
                     RowStats* st) const {
    const int n = static_cast<int>(samples.rows());
    const int w = width_;
    const int ch = channels_;
    thread_local std::vector<float> res;
    res.resize(static_cast<std::size_t>(w) * ch);
    // The model values, reused row after row: a fresh matrix per row (N x 3W floats, 2.4 MB
    // for a 4000-texel row of 49 images) was mapped, faulted in and unmapped each time.
    thread_local RowMajorF model;
    if (options_.model == ColourModel::kRGB) {
      // Model values for every (light, texel, channel) at once: A (N x 6) times coeffs.
      const Eigen::Map<const Eigen::Matrix<float, kPtmTerms, Eigen::Dynamic>> c(
          c_out, kPtmTerms, static_cast<Eigen::Index>(w) * 3);
      model.noalias() = a_f_ * c;  // N x 3W
      for (int i = 0; i < n; ++i) {
        for (int x = 0; x < w; ++x) {
          for (int k = 0; k < ch; ++k) {
            res[static_cast<std::size_t>(x * ch + k)] =
                255.0f * (samples(i, x * ch + k) - model(i, x * 3 + k));
          }
        }
        st->add_all(res.data(), res.size());
      }
      return;
    }
    const int ncol = colour_count(options_.model);
    const Eigen::Map<const Eigen::Matrix<float, kPtmTerms, Eigen::Dynamic>> c(c_out, kPtmTerms, w);
    model.noalias() = a_f_ * c;  // N x W: L (LRGB, scaled) or Y (YCC)
    for (int i = 0; i < n; ++i) {
      for (int x = 0; x < w; ++x) {
        const float* col = col_out + static_cast<std::ptrdiff_t>(x) * ncol;
        float rgb[3];
        if (options_.model == ColourModel::kLRGB) {
          for (int k = 0; k < 3; ++k) rgb[k] = model(i, x) * col[k];
        } else {
          double d[3];
          from_ycbcr({model(i, x), col[0], col[1]}, &d[0], &d[1], &d[2]);
          for (int k = 0; k < 3; ++k) rgb[k] = static_cast<float>(d[k]);
        }
        for (int k = 0; k < ch; ++k) {
          res[static_cast<std::size_t>(x * ch + k)] = 255.0f * (samples(i, x * ch + k) - rgb[k]);
        }
      }
      st->add_all(res.data(), res.size());
    }
  }

  // One texel's samples in double: s[i * ch + k].
  void gather(const StackBand& band, int r, int x, std::vector<double>* s) const {
    const int n = band.images;
    const int ch = channels_;
    s->resize(static_cast<std::size_t>(n) * ch);
    const std::size_t offset = (static_cast<std::size_t>(r) * width_ + x) * ch;
    for (int i = 0; i < n; ++i) {
      for (int k = 0; k < ch; ++k) {
        // The same float either way (v / 255 for bytes), then widened.
        const float v = band.is_u8 ? static_cast<float>(band.image_u8(i)[offset + k]) / 255.0f
                                   : band.image(i)[offset + k];
        (*s)[static_cast<std::size_t>(i * ch + k)] = v;
      }
    }
  }

  void labelling_values(const std::vector<double>& s, int n, double* value,
                        std::uint8_t* saturated) const {
    const int ch = channels_;
    const double sat = options_.robust.saturation_level;
    for (int i = 0; i < n; ++i) {
      const double* p = s.data() + static_cast<std::size_t>(i) * ch;
      value[i] = ch == 3 ? luma(p[0], p[1], p[2]) : p[0];
      bool clipped = false;
      for (int k = 0; k < ch; ++k) clipped = clipped || p[k] >= sat;
      if (saturated != nullptr) saturated[i] = clipped ? 1 : 0;
    }
  }

  // The fitted model's RGB for light i of a texel (grey input: rgb[0] is the grey value);
  // `g`: the texel's own geometry under near lights (null: the shared design).
  // One texel's LRGB colour (which also rescales coef, see finish_lrgb_colour) or YCC chroma,
  // from its samples s (n x channels), labelling values and per-sample weights.
  void texel_colour(const std::vector<double>& s, int n, const double* value, const double* weights,
                    float* coef, float* col) const {
    const int ch = channels_;
    if (options_.model == ColourModel::kLRGB) {
      double yy = 0.0;
      double yc[3] = {0.0, 0.0, 0.0};
      for (int i = 0; i < n; ++i) {
        const double w = weights[i];
        const double yi = value[i];
        yy += w * yi * yi;
        for (int k = 0; k < 3; ++k)
          yc[k] += w * yi * s[static_cast<std::size_t>(i * ch + (ch == 3 ? k : 0))];
      }
      internal::finish_lrgb_colour(yy, yc, col, coef);
      return;
    }
    double sy = 0.0, scb = 0.0, scr = 0.0;
    if (ch == 3) {
      for (int i = 0; i < n; ++i) {
        const double* p = s.data() + static_cast<std::size_t>(i) * 3;
        const auto ycc = to_ycbcr(p[0], p[1], p[2]);
        const double wgt = weights[i] * std::max(0.0, ycc.y);
        sy += wgt;
        scb += wgt * ycc.cb;
        scr += wgt * ycc.cr;
      }
    }
    finish_ycc_chroma(sy, scb, scr, col);
  }

  // Residuals of one texel's fit against its samples, into the row's statistics.
  void texel_residuals(const std::vector<double>& s, int n, const float* coef, const float* col,
                       const TexelGeometry* g, RowStats* st) const {
    const int ch = channels_;
    for (int i = 0; i < n; ++i) {
      double rgb[3];
      model_rgb(coef, col, i, rgb, g);
      for (int k = 0; k < ch; ++k)
        st->add(255.0 * (s[static_cast<std::size_t>(i * ch + k)] - rgb[k]));
    }
  }

  void model_rgb(const float* coef, const float* col, int i, double rgb[3],
                 const TexelGeometry* g = nullptr) const {
    const auto b = design_.design().row(i);
    const double* gb =
        g != nullptr ? g->basis.data() + static_cast<std::ptrdiff_t>(i) * kPtmTerms : nullptr;
    auto eval = [&](const float* c) {
      double v = 0.0;
      if (gb != nullptr) {
        for (int t = 0; t < kPtmTerms; ++t) v += gb[t] * c[t];
      } else {
        for (int t = 0; t < kPtmTerms; ++t) v += b(t) * c[t];
      }
      return v;
    };
    switch (options_.model) {
      case ColourModel::kRGB:
        for (int k = 0; k < 3; ++k) rgb[k] = eval(coef + k * kPtmTerms);
        break;
      case ColourModel::kLRGB: {
        const double l = eval(coef);
        for (int k = 0; k < 3; ++k) rgb[k] = l * col[k];
        break;
      }
      case ColourModel::kYCC:
        from_ycbcr({eval(coef), col[0], col[1]}, &rgb[0], &rgb[1], &rgb[2]);
        break;
    }
  }

  // Residual map, counts, labels, normals and albedo of one texel from its samples, weights
  // (0 = rejected) and labels, and its fitted coefficients.
  void texel_extras(const std::vector<double>& s, const double* value, const double* weights,
                    const SampleLabel* labels, const float* coef, const float* col, int x, int y,
                    const TexelGeometry* geo = nullptr) const {
    FitOutputs& o = *options_.outputs;
    const int n = design_.lights();
    const int ch = channels_;
    if (o.want_residual_map) {
      double sum = 0.0;
      std::uint64_t cnt = 0;
      for (int i = 0; i < n; ++i) {
        if (labels[i] != SampleLabel::kInlier) continue;
        double rgb[3];
        model_rgb(coef, col, i, rgb, geo);
        for (int k = 0; k < ch; ++k) {
          const double d = 255.0 * (s[static_cast<std::size_t>(i * ch + k)] - rgb[k]);
          sum += d * d;
          ++cnt;
        }
      }
      o.residual_map.at(x, y, 0) =
          cnt > 0 ? static_cast<float>(std::sqrt(sum / static_cast<double>(cnt))) : 0.0f;
    }
    if (o.want_outlier_counts) {
      int sh = 0, hi = 0;
      for (int i = 0; i < n; ++i) {
        sh += labels[i] == SampleLabel::kShadow ? 1 : 0;
        hi += labels[i] == SampleLabel::kHighlight ? 1 : 0;
      }
      o.outlier_counts.at(x, y, 0) = static_cast<float>(sh);
      o.outlier_counts.at(x, y, 1) = static_cast<float>(hi);
    }
    if (o.want_labels) {
      std::uint8_t* dst = o.labels.data() + (static_cast<std::size_t>(y) * width_ + x) * n;
      for (int i = 0; i < n; ++i) dst[i] = static_cast<std::uint8_t>(labels[i]);
    }
    if (o.want_normals) {
      // Lambertian photometric stereo: value_i = l_i . g with g = albedo * normal, over the
      // inlier samples. Samples at or below zero carry no direction (attached shadow).
      Eigen::Matrix3d m = Eigen::Matrix3d::Zero();
      Eigen::Vector3d rhs = Eigen::Vector3d::Zero();
      for (int i = 0; i < n; ++i) {
        const double w = weights[i];
        if (w <= 0.0) continue;
        const Eigen::Vector3d l = geo != nullptr ? Eigen::Vector3d(geo->dirs.row(i).transpose())
                                                 : Eigen::Vector3d(light_.row(i).transpose());
        m.noalias() += w * l * l.transpose();
        rhs += (w * (srgb_ ? srgb_to_linear(value[i]) : value[i])) * l;
      }
      Eigen::Vector3d nrm(0.0, 0.0, 1.0);
      const Eigen::LDLT<Eigen::Matrix3d> ldlt(m);
      if (ldlt.info() == Eigen::Success && ldlt.isPositive()) {
        const Eigen::Vector3d g = ldlt.solve(rhs);
        if (g.allFinite() && g.norm() > 1e-12 && g.z() > 0.0) nrm = g.normalized();
      }
      double num[3] = {0.0, 0.0, 0.0};
      double den = 0.0;
      for (int i = 0; i < n; ++i) {
        const double w = weights[i];
        if (w <= 0.0) continue;
        const double shade =
            std::max(0.0, geo != nullptr ? geo->dirs.row(i).dot(nrm) : light_.row(i).dot(nrm));
        den += w * shade * shade;
        for (int k = 0; k < 3; ++k) {
          const double v = s[static_cast<std::size_t>(i * ch + (ch == 3 ? k : 0))];
          num[k] += w * shade * (srgb_ ? srgb_to_linear(v) : v);
        }
      }
      for (int k = 0; k < 3; ++k) {
        o.normals.at(x, y, k) = static_cast<float>(nrm(k));
        o.albedo.at(x, y, k) = den > 1e-20 ? static_cast<float>(num[k] / den) : 0.0f;
      }
    }
  }

  // Least-squares solvers: every sample is an inlier.
  void row_extras(const StackBand& band, int r, const float* c_out, const float* col_out) const {
    const int n = band.images;
    const int polys = polynomial_count(options_.model);
    const int ncol = colour_count(options_.model);
    std::vector<double> s, value(static_cast<std::size_t>(n)),
        weights(static_cast<std::size_t>(n), 1.0);
    std::vector<SampleLabel> labels;
    labels.assign(static_cast<std::size_t>(n), SampleLabel::kInlier);
    for (int x = 0; x < width_; ++x) {
      gather(band, r, x, &s);
      labelling_values(s, n, value.data(), nullptr);
      texel_extras(s, value.data(), weights.data(), labels.data(),
                   c_out + static_cast<std::size_t>(x) * polys * kPtmTerms,
                   col_out + static_cast<std::size_t>(x) * ncol, x, band.y0 + r);
    }
  }

  // Robust solvers: per texel, label the samples on the labelling channel, then fit every
  // polynomial with the same weights.
  void fit_row_texels(const StackBand& band, int r, float* c_out, float* col_out,
                      RowStats* st) const {
    const int n = band.images;
    const int ch = channels_;
    const int polys = polynomial_count(options_.model);
    const int ncol = colour_count(options_.model);
    const auto un = static_cast<std::size_t>(n);
    TexelSolver solver(design_.design(), options_.solver, options_.robust);
    std::vector<double> s, value(un), weights(un), chan(un);
    std::vector<std::uint8_t> saturated(un);
    std::vector<SampleLabel> labels(un);
    for (int x = 0; x < width_; ++x) {
      gather(band, r, x, &s);
      labelling_values(s, n, value.data(), saturated.data());
      double c[kPtmTerms];
      const TexelOutcome out =
          solver.solve(value.data(), saturated.data(), weights.data(), labels.data(), c);
      st->outliers.samples += un;
      st->outliers.shadows += static_cast<std::uint64_t>(out.shadows);
      st->outliers.highlights += static_cast<std::uint64_t>(out.highlights);
      st->outliers.fallback_texels += out.fallback ? 1u : 0u;
      st->outliers.ceres_texels += out.ceres_ran ? 1u : 0u;

      float* coef = c_out + static_cast<std::size_t>(x) * polys * kPtmTerms;
      float* col = col_out + static_cast<std::size_t>(x) * ncol;
      auto store = [&](const double* v, float* dst) {
        double cc[kPtmTerms];
        solver.weighted_fit(v, weights.data(), cc);
        for (int t = 0; t < kPtmTerms; ++t) dst[t] = static_cast<float>(cc[t]);
      };
      if (options_.model == ColourModel::kRGB) {
        if (ch == 3) {
          for (int k = 0; k < 3; ++k) {
            for (int i = 0; i < n; ++i)
              chan[static_cast<std::size_t>(i)] = s[static_cast<std::size_t>(i * 3 + k)];
            store(chan.data(), coef + k * kPtmTerms);
          }
        } else {
          store(value.data(), coef);
          std::copy_n(coef, kPtmTerms, coef + kPtmTerms);
          std::copy_n(coef, kPtmTerms, coef + 2 * kPtmTerms);
        }
      } else {
        store(value.data(), coef);
        texel_colour(s, n, value.data(), weights.data(), coef, col);
      }
      if (st->active) texel_residuals(s, n, coef, col, nullptr, st);
      if (extras_) {
        texel_extras(s, value.data(), weights.data(), labels.data(), coef, col, x, band.y0 + r);
      }
    }
  }

  // Near lights: every texel its own design rows A_t (from its light directions) and its own
  // 6 x 6 normal equations A_t^T A_t c = A_t^T s, by Cholesky in double; samples first
  // multiplied by the fall-off correction when asked.
  void fit_row_near(const StackBand& band, int r, float* c_out, float* col_out,
                    RowStats* st) const {
    const int n = band.images;
    const int ch = channels_;
    const int polys = polynomial_count(options_.model);
    const int ncol = colour_count(options_.model);
    const auto un = static_cast<std::size_t>(n);
    const int y = band.y0 + r;
    TexelGeometry g;
    g.basis.resize(n, kPtmTerms);
    g.dirs.resize(n, 3);
    g.correction.resize(un);
    std::vector<double> s, value(un), weights(un, 1.0);
    const std::vector<SampleLabel> labels(un, SampleLabel::kInlier);
    const double ridge = near_.ridge_lambda * static_cast<double>(n);
    for (int x = 0; x < width_; ++x) {
      near_.model->texel(x + near_.origin_x, y + near_.origin_y, g.dirs.data(),
                         g.correction.data());
      for (int i = 0; i < n; ++i) {
        const auto b = ptm_basis(g.dirs(i, 0), g.dirs(i, 1));
        for (int t = 0; t < kPtmTerms; ++t) g.basis(i, t) = b[static_cast<std::size_t>(t)];
      }
      gather(band, r, x, &s);
      if (near_.falloff) {
        for (int i = 0; i < n; ++i) {
          const double f = g.correction[static_cast<std::size_t>(i)];
          for (int k = 0; k < ch; ++k) {
            double& v = s[static_cast<std::size_t>(i * ch + k)];
            v = srgb_ ? linear_to_srgb(srgb_to_linear(v) * f) : v * f;
          }
        }
      }
      const bool rgb_model = options_.model == ColourModel::kRGB;
      if (!rgb_model || extras_) labelling_values(s, n, value.data(), nullptr);
      // Normal matrix and right-hand sides by hand, fixed sizes: Eigen's general products
      // allocate and cost several times more at these shapes (6 x N times N x 6).
      const int nrhs = rgb_model ? ch : 1;
      double mm[kPtmTerms][kPtmTerms] = {};
      double rr[kPtmTerms][3] = {};
      for (int i = 0; i < n; ++i) {
        const double* b = g.basis.data() + static_cast<std::ptrdiff_t>(i) * kPtmTerms;
        const double* v =
            rgb_model ? s.data() + static_cast<std::size_t>(i) * ch : value.data() + i;
        for (int a = 0; a < kPtmTerms; ++a) {
          for (int c = 0; c <= a; ++c) mm[a][c] += b[a] * b[c];
          for (int k = 0; k < nrhs; ++k) rr[a][k] += b[a] * v[k];
        }
      }
      Eigen::Matrix<double, kPtmTerms, kPtmTerms> m;
      Eigen::Matrix<double, kPtmTerms, 3> rhs = Eigen::Matrix<double, kPtmTerms, 3>::Zero();
      for (int a = 0; a < kPtmTerms; ++a) {
        for (int c = 0; c <= a; ++c) m(a, c) = m(c, a) = mm[a][c];
        for (int k = 0; k < nrhs; ++k) rhs(a, k) = rr[a][k];
      }
      if (ridge > 0.0) m.diagonal().array() += ridge;
      const Eigen::LLT<Eigen::Matrix<double, kPtmTerms, kPtmTerms>> llt(m);
      if (llt.info() != Eigen::Success) {
        ++st->singular_texels;  // coefficients stay 0
        continue;
      }
      const Eigen::Matrix<double, kPtmTerms, 3> c = llt.solve(rhs);
      float* coef = c_out + static_cast<std::size_t>(x) * polys * kPtmTerms;
      float* col = col_out + static_cast<std::size_t>(x) * ncol;
      auto store = [&](int from, float* dst) {
        for (int t = 0; t < kPtmTerms; ++t) dst[t] = static_cast<float>(c(t, from));
      };
      if (rgb_model) {
        for (int k = 0; k < 3; ++k) store(ch == 3 ? k : 0, coef + k * kPtmTerms);
      } else {
        store(0, coef);
        texel_colour(s, n, value.data(), weights.data(), coef, col);  // weights all 1
      }
      if (st->active) texel_residuals(s, n, coef, col, &g, st);
      if (extras_) {
        texel_extras(s, value.data(), weights.data(), labels.data(), coef, col, x, y, &g);
      }
    }
  }

  const LightDesign& design_;
  const FitOptions& options_;
  int width_;
  int channels_;
  // sRGB-encoded input: photometric stereo linearises first (Lambert's law holds for
  // radiance, not for the encoded values the polynomial is fitted to).
  bool srgb_ = false;
  int residual_row_step_;
  Eigen::MatrixXf a_f_;
  // The pseudo-inverse over 255 (rounded once, from double): the float fit of colour samples
  // works in 0..255 units, where an 8-bit sample is its byte value and needs no division (see
  // internal::apply_pinv).
  Eigen::MatrixXf pinv_f255_;
  Eigen::MatrixX3d light_;  // unit light directions (for normals)
  bool robust_ = false;
  bool extras_ = false;
  NearFit near_;
};

using BandSource = std::function<bool(int rows, StackBand* band)>;

FitReport run_fit(const LightDesign& design, const FitOptions& options, int width, int height,
                  int channels, ColourSpace colour_space, const BandSource& next_band,
                  CoefficientSink& sink, const NearFit& near = {}) {
  const auto t0 = Clock::now();
  FitReport report;
  report.lights = design.lights();
  report.width = width;
  report.height = height;
  report.channels = channels;
  report.model = options.model;
  report.colour_space = colour_space;
  report.design = design.report();
  report.solver = options.solver;
  if (FitOutputs* o = options.outputs) {
    const auto px = static_cast<std::size_t>(width) * static_cast<std::size_t>(height);
    o->residual_map =
        o->want_residual_map ? Image(width, height, 1, ColourSpace::kLinear) : Image();
    o->outlier_counts =
        o->want_outlier_counts ? Image(width, height, 2, ColourSpace::kLinear) : Image();
    o->labels.assign(o->want_labels ? px * static_cast<std::size_t>(design.lights()) : 0, 0);
    o->normals = o->want_normals ? Image(width, height, 3, ColourSpace::kLinear) : Image();
    o->albedo = o->want_normals ? Image(width, height, 3, ColourSpace::kLinear) : Image();
  }
  report.threads = options.threads > 0 ? options.threads : tbb::this_task_arena::max_concurrency();

  BandFitter fitter(design, options, width, height, channels, colour_space, near);
  StatsTotal totals;
  // Three bands in flight: band k is fitted while band k + 1 is decoded and band k - 1 is
  // handed to the sink, so neither the decoding nor the sink (the .ptm writer converts and
  // checks every coefficient) waits for the other on a machine with few cores.
  struct Fitted {
    int y0 = 0, rows = 0;
    std::vector<float> coeffs, colour;
    std::vector<RowStats> row_stats;
  };
  StackBand bands[2];
  Fitted fitted[2];
  sink.begin(width, height, options.model, colour_space);

  auto td = Clock::now();
  bool have = next_band(options.band_rows, &bands[0]);
  report.decode_seconds += seconds_since(td);
  int cur = 0;
  const Fitted* pending = nullptr;  // fitted, not yet given to the sink
  const auto deliver = [&](const Fitted& f) {
    sink.write_rows(f.y0, f.rows, f.coeffs.data(), f.colour.data());
  };
  while (have) {
    bool have_next = false;
    double decode_s = 0.0;
    tbb::task_group group;
    group.run([&] {
      const auto t = Clock::now();
      have_next = next_band(options.band_rows, &bands[1 - cur]);
      decode_s = seconds_since(t);
    });
    if (pending) group.run([&deliver, pending] { deliver(*pending); });
    Fitted& out = fitted[cur];
    const auto tf = Clock::now();
    try {
      out.y0 = bands[cur].y0;
      out.rows = bands[cur].rows;
      fitter.fit(bands[cur], &out.coeffs, &out.colour, &out.row_stats);
    } catch (...) {
      group.wait();
      throw;
    }
    report.fit_seconds += seconds_since(tf);
    group.wait();  // rethrows a decode or sink error
    report.decode_seconds += decode_s;
    // Merged in band order: the totals are the same whatever the threads.
    for (const auto& rs : out.row_stats) {
      if (rs.active) totals.merge(rs);
      totals.merge_outliers(rs);
    }
    if (pending && options.progress) {
      options.progress(static_cast<double>(pending->y0 + pending->rows) / height);
    }
    pending = &out;
    cur = 1 - cur;
    have = have_next;
  }
  if (pending) {
    deliver(*pending);
    if (options.progress) options.progress(1.0);
  }
  // The caller ends the sink once the images are closed and the bands freed: the sink may
  // need memory of its own to finish (the .ptm writer encodes the whole file then).
  report.residuals = totals.finish();
  report.residuals.row_step = residual_row_step(width, height);
  report.outliers = totals.outliers;
  report.light_model.singular_texels = totals.singular_texels;
  report.total_seconds = seconds_since(t0);
  return report;
}

// The design options a solver implies: QR/SVD factorisations, ridge's default weight.
DesignOptions design_options_for(const FitOptions& options) {
  DesignOptions d = options.design;
  if (options.solver == Solver::kQR) d.method = PinvMethod::kQR;
  if (options.solver == Solver::kSVD) d.method = PinvMethod::kSVD;
  if (options.solver == Solver::kRidge && d.ridge_lambda == 0.0) d.ridge_lambda = 1e-3;
  return d;
}

// Ends the sink and counts its time (writing the file) in the total.
void finish_sink(CoefficientSink& sink, FitReport* report) {
  const auto t = Clock::now();
  sink.end();
  report->total_seconds += seconds_since(t);
}

// The light model of a fit: near (per-texel directions) when a sample plane is given, else
// distant. Checks what can be checked before any image is read.
struct LightModelSetup {
  std::optional<NearLightModel> model;
  NearLightReport report;
  NearFit fit(const FitOptions& options) const {
    NearFit f;
    if (!model) return f;
    f.model = &*model;
    f.falloff = options.near.falloff;
    f.ridge_lambda = design_options_for(options).ridge_lambda;
    return f;
  }
  // The images' size must be the plane's.
  void check_size(int width, int height) const {
    if (!model) return;
    const SamplePlane& p = model->plane();
    if (p.width_px != width || p.height_px != height) {
      throw Error("fit: the sample plane is for " + std::to_string(p.width_px) + "x" +
                  std::to_string(p.height_px) + " images but the capture is " +
                  std::to_string(width) + "x" + std::to_string(height));
    }
  }
  void finish(FitReport* out) const {
    NearLightReport r = report;
    r.singular_texels = out->light_model.singular_texels;
    out->light_model = r;
  }
};

LightModelSetup light_model_setup(const LightSet& lights, const FitOptions& options) {
  LightModelSetup setup;
  if (!options.near.plane) {
    const bool positions = std::any_of(lights.lights.begin(), lights.lights.end(),
                                       [](const Light& l) { return l.position_mm.has_value(); });
    if (positions) setup.report.note = "light positions ignored: no sample plane given";
    return setup;
  }
  if (options.solver != Solver::kLS && options.solver != Solver::kRidge) {
    throw Error(
        "fit: near lights (a sample plane was given) are supported by the ls and ridge "
        "solvers only, not '" +
        std::string(to_string(options.solver)) +
        "' (its per-texel labelling uses the shared distant-light design); fit near "
        "lights with --solver ls or ridge, or drop the plane for the distant model");
  }
  setup.model = NearLightModel::from_lights(lights, *options.near.plane);
  setup.report = setup.model->field_report();
  setup.report.falloff_corrected = options.near.falloff;
  return setup;
}

FitReport fit_in_memory(const std::vector<Image>& images,
                        const std::vector<Eigen::Vector3d>& light_dirs, const FitOptions& options,
                        CoefficientSink& sink, const LightModelSetup& setup) {
  if (images.size() != light_dirs.size()) {
    throw Error("fit: " + std::to_string(images.size()) + " images but " +
                std::to_string(light_dirs.size()) + " light directions");
  }
  if (images.empty()) throw Error("fit: no images");
  const ThreadLimit limit(options.threads);
  const LightDesign design = LightDesign::build(light_dirs, design_options_for(options));
  const int w = images[0].width();
  const int h = images[0].height();
  const int src_ch = images[0].channels();
  const int ch = (src_ch == 4 || src_ch == 2) ? src_ch - 1 : std::min(src_ch, 3);
  for (std::size_t i = 0; i < images.size(); ++i) {
    if (images[i].width() != w || images[i].height() != h || images[i].channels() != src_ch) {
      throw Error("fit: image " + std::to_string(i) + " differs in size or channels from image 0");
    }
  }
  setup.check_size(w, h);
  int next_row = 0;
  const auto source = [&](int rows, StackBand* band) {
    if (next_row >= h) return false;
    band->y0 = next_row;
    band->rows = std::min(rows, h - next_row);
    band->width = w;
    band->channels = ch;
    band->images = static_cast<int>(images.size());
    band->samples.resize(band->image_stride() * images.size());
    for (std::size_t i = 0; i < images.size(); ++i) {
      float* dst = band->image(static_cast<int>(i));
      for (int r = 0; r < band->rows; ++r) {
        const float* src = images[i].row(band->y0 + r);
        for (int x = 0; x < w; ++x) {
          for (int c = 0; c < ch; ++c) *dst++ = src[x * src_ch + c];
          for (int c = 0; c < ch; ++c) {
            if (!std::isfinite(dst[c - ch])) {
              throw Error("fit: image " + std::to_string(i) + " has a NaN or infinite sample");
            }
          }
        }
      }
    }
    next_row += band->rows;
    return true;
  };
  FitReport report = run_fit(design, options, w, h, ch, images[0].colour_space(), source, sink,
                             setup.fit(options));
  setup.finish(&report);
  finish_sink(sink, &report);
  return report;
}

}  // namespace

std::string FitOptions::validate() const {
  if (band_rows < 1) return "band_rows must be at least 1";
  if (threads < 0) return "threads must be >= 0 (0 = all cores)";
  if (!(design.max_condition > 1.0)) return "max_condition must be > 1";
  if (!(design.ridge_lambda >= 0.0) || !std::isfinite(design.ridge_lambda)) {
    return "ridge lambda must be a finite number >= 0";
  }
  if (const auto err = robust.validate(); !err.empty()) return err;
  if (const auto err = near.validate(); !err.empty()) return err;
  return {};
}

FitReport fit_capture(const LightSet& lights, const FitOptions& options, CoefficientSink& sink) {
  if (const auto err = options.validate(); !err.empty()) throw Error("fit options: " + err);
  const ThreadLimit limit(options.threads);
  // Check the layout before opening a single image: a bad layout fails fast.
  const LightDesign design = LightDesign::build(lights.directions(), design_options_for(options));
  const LightModelSetup setup = light_model_setup(lights, options);
  FitReport report;
  {
    StackReader reader(lights.images(), options.input);
    setup.check_size(reader.summary().full_width, reader.summary().full_height);
    FitOptions run_options = options;
    if (reader.info().format == PixelFormat::kF32) {
      // Float files are not clipped at full scale (HDR): no sample is "saturated".
      run_options.robust.saturation_level = std::numeric_limits<double>::infinity();
    }
    const auto source = [&](int rows, StackBand* band) {
      return reader.read_band(rows, band, BandStorage::kNative8);
    };
    NearFit near = setup.fit(run_options);
    near.origin_x = reader.origin_x();
    near.origin_y = reader.origin_y();
    report = run_fit(design, run_options, reader.width(), reader.height(), reader.channels(),
                     reader.info().colour_space, source, sink, near);
    report.input = reader.summary();
    setup.finish(&report);
  }  // images closed before the sink finishes
  finish_sink(sink, &report);
  return report;
}

FitReport fit_images(const std::vector<Image>& images,
                     const std::vector<Eigen::Vector3d>& light_dirs, const FitOptions& options,
                     CoefficientSink& sink) {
  if (const auto err = options.validate(); !err.empty()) throw Error("fit options: " + err);
  LightSet lights;
  for (const auto& d : light_dirs) {
    Light l;
    l.direction = d;
    lights.lights.push_back(l);
  }
  return fit_in_memory(images, light_dirs, options, sink, light_model_setup(lights, options));
}

FitReport fit_images(const std::vector<Image>& images, const LightSet& lights,
                     const FitOptions& options, CoefficientSink& sink) {
  if (const auto err = options.validate(); !err.empty()) throw Error("fit options: " + err);
  return fit_in_memory(images, lights.directions(), options, sink,
                       light_model_setup(lights, options));
}

std::string FitReport::to_json() const {
  nlohmann::json j;
  j["lights"] = lights;
  j["width"] = width;
  j["height"] = height;
  j["channels"] = channels;
  j["model"] = std::string(to_string(model));
  j["colour_space"] = std::string(to_string(colour_space));
  auto num = [](double v) -> nlohmann::json {
    if (std::isfinite(v)) return v;
    return "inf";
  };
  j["design"] = {{"condition_number", num(design.condition_number)},
                 {"smallest_singular_value", design.smallest_singular},
                 {"largest_singular_value", design.largest_singular},
                 {"min_elevation_deg", design.min_elevation_deg},
                 {"max_elevation_deg", design.max_elevation_deg},
                 {"single_ring", design.single_ring},
                 {"regularised", design.regularised}};
  j["residuals_grey"] = {{"rms", residuals.rms_grey},         {"mean_abs", residuals.mean_abs_grey},
                         {"p99_abs", residuals.p99_abs_grey}, {"max_abs", residuals.max_abs_grey},
                         {"samples", residuals.samples},      {"row_step", residuals.row_step}};
  j["solver"] = std::string(to_string(solver));
  j["outliers"] = {{"samples", outliers.samples},
                   {"shadow", outliers.shadows},
                   {"highlight", outliers.highlights},
                   {"fallback_texels", outliers.fallback_texels},
                   {"ceres_texels", outliers.ceres_texels}};
  {
    nlohmann::json lm = {{"model", light_model.model}};
    if (light_model.model == "near") {
      lm["max_spread_deg"] = light_model.max_spread_deg;
      lm["mean_spread_deg"] = light_model.mean_spread_deg;
      lm["falloff_range"] = {light_model.min_falloff, light_model.max_falloff};
      lm["falloff_corrected"] = light_model.falloff_corrected;
      lm["singular_texels"] = light_model.singular_texels;
    }
    if (!light_model.note.empty()) lm["note"] = light_model.note;
    j["light_model"] = lm;
  }
  if (input.full_width > 0) j["images"] = nlohmann::json::parse(input.to_json());
  j["threads"] = threads;
  j["timings_s"] = {{"decode", decode_seconds},
                    {"fit", fit_seconds},
                    {"total", total_seconds},
                    {"texels_per_second", texels_per_second()}};
  return j.dump(2);
}

void write_label_images(const std::filesystem::path& dir, const FitOutputs& outputs,
                        const LightSet& lights, int width, int height) {
  const std::size_t n = lights.size();
  const std::size_t texels = static_cast<std::size_t>(width) * static_cast<std::size_t>(height);
  if (outputs.labels.size() != texels * n) {
    throw Error(where(dir) + ": no labels of this size to write (" +
                std::to_string(outputs.labels.size()) + " for " + std::to_string(texels) +
                " texels x " + std::to_string(n) + " lights)");
  }
  ensure_directory(dir);
  Image lab(width, height, 1, ColourSpace::kLinear);
  for (std::size_t i = 0; i < n; ++i) {
    for (std::size_t t = 0; t < texels; ++t) {
      lab.data()[t] = static_cast<float>(outputs.labels[t * n + i]) / 255.0f;
    }
    const auto name = lights.lights[i].image.filename().replace_extension(".png");
    write_image(dir / name, lab.view(), ImageWriteOptions{PixelFormat::kU8});
  }
}

}  // namespace ptmkit::fit
