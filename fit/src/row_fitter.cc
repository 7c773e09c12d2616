#include "row_fitter.h"

#include <limits>

#include <tbb/parallel_for.h>

#include "basis_rows.h"
#include "ptm_rows.h"

namespace ptmkit::fit::internal {

RowFitter::RowFitter(const FitSetup& setup)
    : setup_(setup),
      options_(*setup_.options),
      width_(setup.width),
      channels_(setup.channels),
      residual_row_step_(residual_row_step(setup.width, setup.height)) {}

void RowFitter::fit(const StackBand& band, std::vector<float>* coeffs, std::vector<float>* colour,
                    std::vector<RowStats>* stats) const {
  const std::size_t per_texel = setup_.layout.coeffs_per_texel();
  const auto ncol = static_cast<std::size_t>(setup_.layout.colours());
  const std::size_t row_texels = static_cast<std::size_t>(width_);
  const std::size_t n_coeffs = static_cast<std::size_t>(band.rows) * row_texels * per_texel;
  const std::size_t n_colour = static_cast<std::size_t>(band.rows) * row_texels * ncol;
#ifdef PTMKIT_ASAN
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
    float* c_out = coeffs->data() + static_cast<std::size_t>(r) * row_texels * per_texel;
    float* col_out = colour->data() + static_cast<std::size_t>(r) * row_texels * ncol;
    fit_row(band, r, c_out, col_out, &st);
  });
}

void RowFitter::gather(const StackBand& band, int r, int x, std::vector<double>* s) const {
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

std::unique_ptr<RowFitter> make_row_fitter(const FitSetup& setup, const LightDesign* design,
                                           const BasisDesign* basis_design) {
  if (setup.options->basis != Basis::kPtm) {
    return std::make_unique<BasisRowFitter>(setup, *basis_design);
  }
  if (setup.near.model != nullptr) return std::make_unique<NearRowFitter>(setup, *design);
  if (!is_shared_solver(setup.options->solver)) {
    return std::make_unique<RobustRowFitter>(setup, *design);
  }
  return std::make_unique<SharedRowFitter>(setup, *design);
}

void finish_ycc_chroma(double sy, double scb, double scr, float* colour) {
  colour[0] = sy > 1e-20 ? static_cast<float>(scb / sy) : 0.0f;
  colour[1] = sy > 1e-20 ? static_cast<float>(scr / sy) : 0.0f;
}

}  // namespace ptmkit::fit::internal
