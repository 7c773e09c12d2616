// The fit pipeline's middle stage: a row fitter turns a band of samples (core/stack_reader.h)
// into coefficients, one image row at a time, rows in parallel. One interface, one
// implementation per way of fitting:
//   shared_rows.cc   distant lights, PTM: one shared pseudo-inverse for every texel (bytes or
//                    floats, RGB / LRGB / YCC), the fast path
//   texel_rows.cc    PTM per texel: robust solvers (labels and weights first), near lights
//                    (each texel its own design), and the optional maps of least squares
//   basis_rows.cc    distant lights, any other basis (HSH): the basis's shared operator in
//                    double, luminance models multiplied out
// The pipeline (pipeline.cc) feeds it bands and hands its output to the sink.
#pragma once

#include <cstddef>
#include <memory>
#include <vector>

#include <Eigen/Core>

#include "ptmkit/core/coefficients.h"
#include "ptmkit/core/stack_reader.h"
#include "ptmkit/fit/basis.h"
#include "ptmkit/fit/design.h"
#include "ptmkit/fit/fit.h"
#include "ptmkit/fit/near_light.h"
#include "residual_stats.h"

namespace ptmkit::fit::internal {

// The near-light model of a fit (null model: distant lights).
struct NearFit {
  const NearLightModel* model = nullptr;
  bool falloff = false;
  double ridge_lambda = 0.0;  // relative to the number of lights, as DesignOptions'
  // Photo pixel of texel (0, 0) (a crop or mask box): the plane maps photo pixels.
  int origin_x = 0;
  int origin_y = 0;
};

// What every row fitter knows about the fit.
struct FitSetup {
  const FitOptions* options = nullptr;
  FitOutputs* outputs = nullptr;  // optional maps, null when none is wanted
  int width = 0;
  int height = 0;
  int channels = 0;  // sample channels: 1 or 3
  ColourSpace colour_space = ColourSpace::kSRGB;
  NearFit near;
  // The delivered layout (CoefficientSink::begin).
  CoefficientLayout layout;
};

class RowFitter {
 public:
  explicit RowFitter(const FitSetup& setup);
  virtual ~RowFitter() = default;
  RowFitter(const RowFitter&) = delete;
  RowFitter& operator=(const RowFitter&) = delete;

  // Fits one band. Output buffers: coeffs [texel][poly][term], colour [texel][colours], one
  // RowStats per row.
  void fit(const StackBand& band, std::vector<float>* coeffs, std::vector<float>* colour,
           std::vector<RowStats>* stats) const;

 protected:
  // Row r of the band into c_out / col_out (that row's part of the buffers).
  virtual void fit_row(const StackBand& band, int r, float* c_out, float* col_out,
                       RowStats* st) const = 0;

  // One texel's samples in double: s[i * channels + k] (the band's floats, or v / 255).
  void gather(const StackBand& band, int r, int x, std::vector<double>* s) const;

  const FitSetup setup_;
  const FitOptions& options_;
  const int width_;
  const int channels_;

 private:
  int residual_row_step_;
};

// The row fitter a fit's options call for: `design` is the PTM design (distant lights; needed
// for every PTM fit, including near lights for its light count), `basis_design` the design of
// any other basis (null for PTM).
std::unique_ptr<RowFitter> make_row_fitter(const FitSetup& setup, const LightDesign* design,
                                           const BasisDesign* basis_design);

// The seed paper's constant chromaticity from luminance-weighted sums of Cb and Cr.
void finish_ycc_chroma(double sy, double scb, double scr, float* colour);

}  // namespace ptmkit::fit::internal
