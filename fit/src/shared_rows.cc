// Distant lights, PTM: every texel of a band fitted by one shared pseudo-inverse (design.h),
// on the bytes of 8-bit RGB files or on floats, for the three colour models.
#include <algorithm>
#include <cstdint>
#include <vector>

#include <Eigen/Core>

#include "kernels.h"
#include "ptm_rows.h"
#include "ptmkit/core/colour.h"

namespace ptmkit::fit::internal {

namespace {
using CoeffMap = Eigen::Map<Eigen::Matrix<float, kPtmTerms, Eigen::Dynamic>>;
}  // namespace

SharedRowFitter::SharedRowFitter(const FitSetup& setup, const LightDesign& design)
    : PtmRowFitter(setup, design) {
  a_f_ = design.design().cast<float>();
  pinv_f255_ = (design.pseudo_inverse() / 255.0).cast<float>();
}

template <class Samples>
void SharedRowFitter::apply(const Samples& s, float* out, Eigen::Index m, Units units) const {
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

void SharedRowFitter::fit_row(const StackBand& band, int r, float* c_out, float* col_out,
                              RowStats* st) const {
  // 8-bit RGB bands: the RGB product and the one-pass LRGB row read the bytes themselves;
  // everything else gets this row of every image as floats first.
  const bool fast_bytes = band.is_u8 && channels_ == 3 && options_.precision == Precision::kFloat &&
                          options_.model != ColourModel::kYCC;
  if (fast_bytes) {
    fit_row_bytes(band, r, c_out, col_out);
    if (st->active) row_residuals(row_samples(band, r), c_out, col_out, st);
  } else {
    const SampleMap samples = row_samples(band, r);
    fit_row_samples(samples, c_out, col_out);
    if (st->active) row_residuals(samples, c_out, col_out, st);
  }
  if (extras_) row_extras(band, r, c_out, col_out);
}

// Row r of every image as floats: the band's own, or its bytes converted (v / 255) into a
// per-thread buffer that stays valid until this thread's next call.
SharedRowFitter::SampleMap SharedRowFitter::row_samples(const StackBand& band, int r) const {
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
void SharedRowFitter::fit_row_bytes(const StackBand& band, int r, float* c_out,
                                    float* col_out) const {
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
void SharedRowFitter::fit_row_samples(const SampleMap& samples, float* c_out,
                                      float* col_out) const {
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
void SharedRowFitter::row_residuals(const SampleMap& samples, const float* c_out,
                                    const float* col_out, RowStats* st) const {
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

}  // namespace ptmkit::fit::internal
