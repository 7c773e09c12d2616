// Distant lights, any basis other than PTM (row_fitter.h): every texel fitted in double by the
// basis's shared operator (basis.h). Luminance models (lrgb, grey input) fit Rec. 601 luma
// and a least-squares colour, delivered multiplied out (an rgb layout), as .rti stores them.
#pragma once

#include "row_fitter.h"

namespace ptmkit::fit::internal {

class BasisRowFitter final : public RowFitter {
 public:
  BasisRowFitter(const FitSetup& setup, const BasisDesign& design)
      : RowFitter(setup), design_(design) {}

 protected:
  void fit_row(const StackBand& band, int r, float* c_out, float* col_out,
               RowStats* st) const override;

 private:
  const BasisDesign& design_;
};

}  // namespace ptmkit::fit::internal
