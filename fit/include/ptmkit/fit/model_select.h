// Choosing the model a scene needs: colour model x basis, from held-out error.
//
// A deterministic grid of texels (about sample_texels, evenly strided over the image) is read
// once through StackReader. For every candidate (basis in {hsh2, ptm, hsh3, hsh4} x colour in
// {lrgb, rgb}; grey captures: one luminance fit per basis), light i goes to fold i mod K; each
// fold's lights are predicted by a least-squares fit (shared pseudo-inverse) on the others, and
// the squared prediction error (grey levels, clamped predictions as a viewer shows) is summed
// per texel over every held-out light and channel.
//
// The rule (a complexity penalty in the "one standard error" form): let `best` be the candidate
// with the lowest held-out mean squared error. A candidate is equivalent to it when its held-out
// RMS is within `tolerance` (relative, default 2%) of the best's, or when its per-texel excess
// MSE over the best is within one standard error (paired over the sampled texels). Among the
// equivalent candidates the one with the fewest parameters per texel is chosen (LRGB: terms + 3;
// RGB: 3 x terms; grey: terms); ties go to fewer basis terms. A richer model must therefore
// earn its extra parameters by a visible, systematic held-out gain.
#pragma once

#include <string>
#include <vector>

#include <Eigen/Core>

#include "ptmkit/core/coefficients.h"
#include "ptmkit/core/image.h"
#include "ptmkit/core/light_set.h"
#include "ptmkit/core/stack_reader.h"
#include "ptmkit/fit/basis.h"
#include "ptmkit/fit/design.h"

namespace ptmkit::fit {

struct ModelSelectOptions {
  // Texels in the evaluation grid (a stride over rows and columns; the whole image when
  // smaller).
  int sample_texels = 4096;
  // Folds over the lights (light i in fold i mod folds); 2 .. lights.
  int folds = 5;
  // Relative held-out RMS within which a simpler model counts as equivalent (0.02 = 2%).
  double tolerance = 0.02;
  // Candidates. Empty lists mean every basis / {lrgb, rgb}. Colour models other than rgb and
  // lrgb are refused; grey captures ignore the colour list.
  std::vector<Basis> bases;
  std::vector<ColourModel> colours;
  DesignOptions design;
  int band_rows = 16;
  // How the photographs are read (crop, mask, colour space), as the fit will read them, so
  // the model is chosen on the region that is fitted.
  StackReadOptions input;

  [[nodiscard]] std::string validate() const;  // empty if valid
};

struct ModelCandidate {
  Basis basis = Basis::kPtm;
  ColourModel colour = ColourModel::kRGB;  // kLRGB for grey captures (one luminance fit)
  int terms = 0;                           // basis terms
  int parameters = 0;                      // stored values per texel
  double heldout_rms_grey = 0.0;           // over every held-out sample and channel
  double train_rms_grey = 0.0;             // fit on all lights, against those lights
  double excess_mse = 0.0;                 // mean per-texel MSE minus the best's
  double excess_se = 0.0;                  // its standard error (paired over texels)
  bool equivalent = false;                 // within the rule's reach of the best
  bool chosen = false;
  std::string problem;  // non-empty when the candidate could not be fitted (e.g. too few lights)
};

struct ModelReport {
  int lights = 0;
  int width = 0;
  int height = 0;
  int channels = 0;
  int texels = 0;  // sampled
  int stride = 0;  // grid stride in pixels
  int folds = 0;
  double tolerance = 0.0;
  std::vector<ModelCandidate> candidates;  // fewest parameters first
  int chosen = -1;                         // index into candidates
  int best = -1;                           // lowest held-out error
  double seconds = 0.0;

  [[nodiscard]] const ModelCandidate& choice() const { return candidates.at(chosen); }
  // The table as text (one line per candidate) and as JSON.
  [[nodiscard]] std::string table() const;
  [[nodiscard]] std::string to_json() const;
};

// Reads the sample grid of the capture and evaluates every candidate. Throws ptmkit::Error on
// unreadable images (naming the file) or when no candidate can be fitted.
ModelReport select_model(const LightSet& lights, const ModelSelectOptions& options = {});

}  // namespace ptmkit::fit
