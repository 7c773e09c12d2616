// The PTM row fitters (row_fitter.h): what they share (PtmRowFitter: a texel's labelling
// values, colour, model values, residuals and optional maps) and the three ways of fitting.
#pragma once

#include <cstdint>
#include <vector>

#include <Eigen/Core>

#include "ptmkit/fit/robust.h"
#include "row_fitter.h"

namespace ptmkit::fit::internal {

// One texel's light geometry under near lights: design rows, directions, sample corrections.
struct TexelGeometry {
  Eigen::Matrix<double, Eigen::Dynamic, kPtmTerms, Eigen::RowMajor> basis;  // N x 6
  Eigen::Matrix<double, Eigen::Dynamic, 3, Eigen::RowMajor> dirs;           // N x 3
  std::vector<double> correction;                                           // N
};

class PtmRowFitter : public RowFitter {
 public:
  PtmRowFitter(const FitSetup& setup, const LightDesign& design);

 protected:
  // The labelling value of each sample (luma, or the grey value) and whether it is clipped.
  void labelling_values(const std::vector<double>& s, int n, double* value,
                        std::uint8_t* saturated) const;
  // One texel's LRGB colour (which also rescales coef, see finish_lrgb_colour) or YCC chroma,
  // from its samples s (n x channels), labelling values and per-sample weights.
  void texel_colour(const std::vector<double>& s, int n, const double* value, const double* weights,
                    float* coef, float* col) const;
  // Residuals of one texel's fit against its samples, into the row's statistics.
  void texel_residuals(const std::vector<double>& s, int n, const float* coef, const float* col,
                       const TexelGeometry* g, RowStats* st) const;
  // The fitted model's RGB for light i of a texel (grey input: rgb[0] is the grey value);
  // `g`: the texel's own geometry under near lights (null: the shared design).
  void model_rgb(const float* coef, const float* col, int i, double rgb[3],
                 const TexelGeometry* g = nullptr) const;
  // Residual map, counts, labels, normals and albedo of one texel from its samples, weights
  // (0 = rejected) and labels, and its fitted coefficients.
  void texel_extras(const std::vector<double>& s, const double* value, const double* weights,
                    const SampleLabel* labels, const float* coef, const float* col, int x, int y,
                    const TexelGeometry* geo = nullptr) const;
  // The optional maps of a least-squares row: every sample is an inlier.
  void row_extras(const StackBand& band, int r, const float* c_out, const float* col_out) const;

  const LightDesign& design_;
  // sRGB-encoded input: photometric stereo linearises first.
  bool srgb_ = false;
  bool extras_ = false;     // some optional map is wanted
  Eigen::MatrixX3d light_;  // unit light directions (for normals)
};

// Distant lights: one shared pseudo-inverse for every texel (shared_rows.cc).
class SharedRowFitter final : public PtmRowFitter {
 public:
  SharedRowFitter(const FitSetup& setup, const LightDesign& design);

 protected:
  void fit_row(const StackBand& band, int r, float* c_out, float* col_out,
               RowStats* st) const override;

 private:
  using RowMajorF = Eigen::Matrix<float, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;
  using SampleMap = Eigen::Map<const RowMajorF, 0, Eigen::OuterStride<>>;
  // How apply() takes its samples in float precision: as they are (times P), or in 0..255
  // units (times P / 255), either scaled from 0..1 on the way or already so (LRGB's lumas).
  enum class Units { kAsIs, kScaleTo255, kIn255 };
  // P (6 x N) times a sample matrix (N x M) into a 6 x M column-major output. Double precision
  // takes every sample as it is (kAsIs only).
  template <class Samples>
  void apply(const Samples& s, float* out, Eigen::Index m, Units units = Units::kAsIs) const;
  // Row r of every image as floats: the band's own, or its bytes converted (v / 255) into a
  // per-thread buffer that stays valid until this thread's next call.
  SampleMap row_samples(const StackBand& band, int r) const;
  // RGB or LRGB of a row of 8-bit RGB texels, from the bytes (the same bits as converting them
  // first and fit_row_samples).
  void fit_row_bytes(const StackBand& band, int r, float* c_out, float* col_out) const;
  // Any model from a row's float samples (N x W * channels).
  void fit_row_samples(const SampleMap& samples, float* c_out, float* col_out) const;
  // The residual statistics of a sampled row.
  void row_residuals(const SampleMap& samples, const float* c_out, const float* col_out,
                     RowStats* st) const;

  Eigen::MatrixXf a_f_;
  // The pseudo-inverse over 255 (rounded once, from double): the float fit of colour samples
  // works in 0..255 units, where an 8-bit sample is its byte value and needs no division (see
  // internal::apply_pinv).
  Eigen::MatrixXf pinv_f255_;
};

// Robust solvers: per texel, label the samples on the labelling channel, then fit every
// polynomial with the same weights (texel_rows.cc).
class RobustRowFitter final : public PtmRowFitter {
 public:
  using PtmRowFitter::PtmRowFitter;

 protected:
  void fit_row(const StackBand& band, int r, float* c_out, float* col_out,
               RowStats* st) const override;
};

// Near lights: every texel its own design rows and 6 x 6 normal equations (texel_rows.cc).
class NearRowFitter final : public PtmRowFitter {
 public:
  using PtmRowFitter::PtmRowFitter;

 protected:
  void fit_row(const StackBand& band, int r, float* c_out, float* col_out,
               RowStats* st) const override;
};

}  // namespace ptmkit::fit::internal
