// Light-direction bases other than (and including) the six-term PTM polynomial, and a
// streaming least-squares fitter for them.
//
// Bases (terms per fitted channel):
//   hsh2  4   hemispherical harmonics of order 2: a constant, a tilt in x and y, and a term
//             in cos(theta). The "fewer terms" model for matte scenes: it is what the .rti
//             format stores and viewers read (a 3-term (1, lu, lv) plane would need a format
//             of its own and cannot follow the brightening toward the zenith at all).
//   ptm   6   the seed paper's biquadratic in (lu, lv) (core/coefficients.h), stored as .ptm.
//   hsh3  9   hemispherical harmonics of order 3.
//   hsh4  16  hemispherical harmonics of order 4: the richest basis, for glossy scenes whose
//             lobes the six terms cannot follow.
// The HSH functions are those of the .rti format, formula and source in texture/rti.h (the
// fit stage keeps its own copy, checked equal to the texture stage's by tests/rti_test.cc).
//
// The PTM case is fitted by fit_capture (fit.h) and written as .ptm; fit_basis_capture below
// fits any basis with one shared pseudo-inverse (distant lights), streaming row bands like
// fit_capture, into a map held in memory (3 * terms floats per texel).
#pragma once

#include <cstdint>
#include <string>
#include <string_view>
#include <vector>

#include <Eigen/Core>

#include "ptmkit/core/coefficients.h"
#include "ptmkit/core/image.h"
#include "ptmkit/core/light_set.h"
#include "ptmkit/core/parallel.h"
#include "ptmkit/core/stack_reader.h"
#include "ptmkit/fit/design.h"

namespace ptmkit::fit {

enum class Basis { kHsh2, kPtm, kHsh3, kHsh4 };
// "hsh2", "ptm", "hsh3", "hsh4".
[[nodiscard]] std::string_view to_string(Basis basis);
// Throws ptmkit::Error listing the known names for an unknown one.
[[nodiscard]] Basis parse_basis(std::string_view name);
[[nodiscard]] int basis_terms(Basis basis);
[[nodiscard]] bool is_hsh(Basis basis);
// Every basis, fewest terms first.
[[nodiscard]] std::vector<Basis> all_bases();

// The basis functions at the unit direction `dir` (light frame), basis_terms(basis) values.
// PTM: ptm_basis(x, y). HSH: texture/rti.h's formula.
void evaluate_basis(Basis basis, const Eigen::Vector3d& dir, double* out);
// N x terms: one row per direction.
[[nodiscard]] Eigen::MatrixXd basis_matrix(Basis basis, const std::vector<Eigen::Vector3d>& dirs);

// The shared least-squares operator of a basis on a light layout.
struct BasisDesign {
  Basis basis = Basis::kPtm;
  Eigen::MatrixXd design;          // N x T
  Eigen::MatrixXd pseudo_inverse;  // T x N, (A^T A + lambda N I)^-1 A^T by SVD
  double condition_number = 0.0;   // cond(A)

  // Throws ptmkit::Error when the layout has fewer lights than terms, or cond(A) exceeds
  // options.max_condition (and ridge_lambda is 0): the message names the basis and the fix
  // (fewer terms, more lights, or --ridge).
  static BasisDesign build(Basis basis, const std::vector<Eigen::Vector3d>& dirs,
                           const DesignOptions& options = {});
};

// A fitted map in any basis: three colour channels of `terms` coefficients per texel
// (normalised units). Luminance fits (LRGB, grey input) are stored multiplied out: channel c's
// coefficients are colour_c times the luminance coefficients, which is exactly the LRGB model.
struct BasisMap {
  int width = 0;
  int height = 0;
  Basis basis = Basis::kHsh3;
  ColourSpace colour_space = ColourSpace::kSRGB;
  // [y][x][channel R, G, B][term], rows top to bottom.
  std::vector<float> coeffs;

  [[nodiscard]] int terms() const { return basis_terms(basis); }
  // RGB at texel (x, y) lit from unit direction `dir`, unclamped.
  void evaluate(int x, int y, const Eigen::Vector3d& dir, float rgb[3]) const;
};

struct BasisFitOptions {
  Basis basis = Basis::kHsh3;
  // kRGB: one fit per channel. kLRGB: one luminance fit (Rec. 601 luma) times a per-texel
  // least-squares colour, as fit.h's LRGB. kYCC is refused (a PTM-only model). Grey input
  // fits its one channel either way.
  ColourModel model = ColourModel::kRGB;
  DesignOptions design;
  // Worker threads; 0 = all cores. Results do not depend on it.
  int threads = 0;
  // Rows per band (memory as fit.h's FitOptions::band_rows).
  int band_rows = 8;
  ProgressFn progress;
  // How the photographs are read: crop or mask, colour space, damaged files (as
  // FitOptions::input).
  StackReadOptions input;

  [[nodiscard]] std::string validate() const;  // empty if valid
};

struct BasisFitReport {
  int lights = 0;
  int width = 0;
  int height = 0;
  int channels = 0;
  Basis basis = Basis::kHsh3;
  ColourModel model = ColourModel::kRGB;
  ColourSpace colour_space = ColourSpace::kSRGB;
  double condition_number = 0.0;
  // Residuals against the fitted samples, grey levels, every sample and channel.
  double residual_rms_grey = 0.0;
  double residual_max_abs_grey = 0.0;
  std::uint64_t residual_samples = 0;
  double total_seconds = 0.0;
  [[nodiscard]] std::string to_json() const;
};

// Fits the capture's images (StackReader bands) into `out`. Throws ptmkit::Error on a bad
// layout or unreadable images (naming the file).
BasisFitReport fit_basis_capture(const LightSet& lights, const BasisFitOptions& options,
                                 BasisMap* out);
// The same on images in memory (all one size), one per direction.
BasisFitReport fit_basis_images(const std::vector<Image>& images,
                                const std::vector<Eigen::Vector3d>& dirs,
                                const BasisFitOptions& options, BasisMap* out);

}  // namespace ptmkit::fit
