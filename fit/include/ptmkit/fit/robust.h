// Per-texel solvers: which samples of a texel to trust, and the fit on them.
//
// A texel's N samples (one per light) are fitted by the biquadratic of coefficients.h. Plain
// least squares lets cast shadows drag the fit down and specular highlights pull it up. The
// robust solvers here decide, per sample, whether it is an inlier, a shadow or a highlight,
// and fit the texel's polynomials on the inliers only (or with robust weights).
//
// Labelling works on one channel per texel (the Rec. 601 luma of RGB input, or the grey
// channel): every fitted polynomial of the texel (R, G, B, or Y) is then fitted with the same
// per-sample weights, so a sample is rejected in all channels at once (a shadow darkens every
// channel). The labelling rules are shared by every robust variant:
//   - a sample whose residual r = sample - fit is below -label_k * scale is a shadow, above
//     +label_k * scale a highlight (IRLS and Ceres variants, symmetric in size, sign names the
//     kind); `trim` and `sign` use their own one-sided rules below;
//   - scale = max(mad_factor * median |r - median r| over the current inliers, min_scale).
//
// Variants (see docs/SOLVERS.md for the measured speed and accuracy of each):
//   ls, qr, svd, ridge  the shared 6 x N pseudo-inverse (no labels): Cholesky of the normal
//                       matrix (the paper's), Householder QR of A, SVD of A, or ridge.
//   irls-huber/tukey    iteratively reweighted least squares with a MAD scale, fixed-size
//                       6 x 6 normal equations (symmetric losses).
//   trim                drop dark samples (shadows) and saturated ones (highlights), refit.
//   sign                trim, then the sign-aware rule: samples far below the fit are shadows,
//                       far above it highlights, with separate thresholds, iterated.
//   lambert             trim, then the sign-aware rule on the residuals of a Lambertian model
//                       with an ambient term, value ~ l . g + a (4 unknowns, photometric
//                       stereo), iterated; then the polynomial on the inliers. Knows what the
//                       polynomial cannot represent: its own misfit is not taken for an outlier.
//   qtrim               drop the darkest quarter and the brightest tenth of the texel's samples
//                       (RobustOptions::dark_quantile, bright_quantile) and clipped ones, refit.
//   ceres-huber/cauchy/tukey
//                       Ceres, one residual block per sample, robust loss of width k * scale,
//                       started from least squares; the loss weights then fit all channels.
//   robust              the default robust choice: `lambert` (measured best, docs/SOLVERS.md).
#pragma once

#include <cstdint>
#include <memory>
#include <string>
#include <string_view>
#include <vector>

#include <Eigen/Core>

#include "ptmkit/core/sample_label.h"

namespace ptmkit::fit {

enum class Solver {
  kLS,
  kQR,
  kSVD,
  kRidge,
  kIrlsHuber,
  kIrlsTukey,
  kTrim,
  kSign,
  kLambert,
  kQTrim,
  kCeresHuber,
  kCeresCauchy,
  kCeresTukey,
  kRobust,
};
// The --solver names: ls, qr, svd, ridge, irls-huber, irls-tukey, trim, sign, lambert, qtrim,
// ceres-huber, ceres-cauchy, ceres-tukey, robust.
[[nodiscard]] std::string_view to_string(Solver solver);
// Throws ptmkit::Error listing the known names for an unknown one.
[[nodiscard]] Solver parse_solver(std::string_view name);
[[nodiscard]] std::vector<std::string> solver_names();
// `robust` resolved to the variant it stands for; any other solver unchanged.
[[nodiscard]] Solver resolve_solver(Solver solver);
// True for the solvers that apply one shared pseudo-inverse to every texel (no labels).
[[nodiscard]] bool is_shared_solver(Solver solver);

// Per-sample labels (core/sample_label.h: the codes of label files and of synth's truth).
using ptmkit::SampleLabel;

// Tuning of the robust variants. Sample values are in normalised units (1.0 = full scale,
// 1/255 = one 8-bit grey level). Defaults were chosen on the synth presets (docs/SOLVERS.md).
struct RobustOptions {
  // Robust scale: mad_factor * MAD of the residuals (1.4826 makes it the standard deviation
  // for Gaussian noise), never below min_scale: 8-bit noise and the polynomial's own misfit
  // are never smaller than about 2 grey levels, and a tiny scale would reject good samples.
  // min_scale is counted in steps of 8-bit input: a fit from 16-bit or float files
  // (fit_capture) multiplies it by 255 / 65535, 2 steps of 16 bits; images in memory
  // (fit_images) are taken as 8-bit.
  double mad_factor = 1.4826;
  double min_scale = 2.0 / 255.0;
  // Loss widths in scales (the usual 95%-efficiency constants).
  double huber_k = 1.345;
  double cauchy_k = 2.385;
  double tukey_k = 4.685;
  // IRLS / Ceres labelling: |r| > label_k * scale is an outlier (shadow below, highlight above).
  double label_k = 3.0;
  // trim / sign: a sample whose labelling value is below dark_fraction times the texel's
  // reference brightness (its 75th-percentile sample) is a shadow before any fit.
  double dark_fraction = 0.15;
  // trim / sign: a sample with any channel at or above this is clipped: a highlight. Set to
  // +inf for HDR input (fit_capture does so for float files).
  double saturation_level = 254.5 / 255.0;
  // sign / lambert: residual below -shadow_k * scale is a shadow, above +highlight_k * scale
  // a highlight. Asymmetric: broad specular lobes add many moderate positive residuals that
  // bias the fit (a low threshold above pays), while a cast shadow is far below the fit
  // anyway (measured on the synth presets, docs/SOLVERS.md).
  double shadow_k = 3.0;
  double highlight_k = 2.0;
  // qtrim: per texel, the darkest dark_quantile of the samples (by labelling value) are
  // shadows and the brightest bright_quantile highlights, whatever their level (clipped
  // samples are highlights besides). The plain trimming that robust rules are measured
  // against (docs/SOLVERS.md, "Glossy balls and broad lobes").
  double dark_quantile = 0.25;
  double bright_quantile = 0.10;
  // Iterations of IRLS / the sign rule (each a 6 x 6 solve); stops early when labels settle.
  int max_iterations = 6;
  // Fewest inliers a texel keeps: below that the previous labelling stands (a polynomial on
  // too few samples extrapolates wildly to the rejected lights).
  int min_inliers = 12;
  // sign / lambert: once the labels settle and the polynomial is fitted on the inliers, a
  // rejected sample (not clipped) whose residual against that fit is within readmit_k robust
  // scales is re-admitted and the polynomial refitted once: it was rejected while the fit was
  // still pulled by outliers. 0 turns this off. Labels are the final rejected set.
  double readmit_k = 0.0;
  // lambert: once the labels settle, a rejected sample that is not clipped and that the
  // Lambertian model (fitted on the inliers) says is lit, within keep_within of that model's
  // value, is an inlier again: a deviation that small costs the fit little, and calling the
  // sample a shadow or a highlight would mostly be a false alarm. 0 turns this off. Normalised
  // units, like min_scale (17 / 255: 17 grey levels of an 8-bit image); scale it with HDR data.
  // Chosen on the synth presets for label precision against truth PSNR (docs/SOLVERS.md, "Labels:
  // keeping samples close to the model").
  double keep_within = 17.0 / 255.0;
  // lambert: the keep window is also at most keep_within_fraction of the texel's albedo (the
  // Lambertian model's value with the light along the normal): the window is
  // min(keep_within, keep_within_fraction * albedo). An absolute window alone keeps nearly
  // every sample of a dark or intensity-normalised capture (16-bit photometric-stereo data
  // often has its diffuse level at a tenth of full scale), so its broad specular lobes were
  // never rejected; a relative one labels a capture the same at any exposure. 0 turns the
  // relative bound off (the absolute window alone). 0.13 binds only below an albedo of 0.5
  // (17 / 255 / 0.13), so the synth presets keep their labels; it is the smallest fraction
  // that keeps label precision at 0.84 or more on every preset (docs/SOLVERS.md).
  double keep_within_fraction = 0.13;
  // lambert: the polynomial is fitted to every sample, each rejected one replaced by the
  // Lambertian + ambient model's value (its diffuse estimate from the inliers), instead of to
  // the inliers alone, which leaves the polynomial free to swing where samples were rejected
  // (mostly the grazing lights). Only for texels where that model fits the inliers at least
  // as well as the polynomial does, per degree of freedom (4 parameters against 6); elsewhere
  // the inliers alone, so a surface that is not Lambertian keeps its own fit.
  bool fill_rejected = true;
  // Ceres: run only on texels whose least-squares residuals show an outlier
  // (|r| > label_k * scale); other texels keep the least-squares fit. Saves most of the cost.
  bool ceres_only_where_needed = true;
  // Ceres: iteration limit per texel.
  int ceres_max_iterations = 25;

  [[nodiscard]] std::string validate() const;  // empty if valid
};

// What one texel's robust solve did.
struct TexelOutcome {
  int shadows = 0;
  int highlights = 0;
  int iterations = 0;
  bool fallback = false;  // too few inliers or a singular weighted system: kept an earlier fit
  bool ceres_ran = false;
};

// Decides the per-sample weights and labels of one texel. Not thread-safe (holds scratch
// space and, for Ceres, a reusable problem): use one per thread or per row.
class TexelSolver {
 public:
  // design: N x 6 rows ptm_basis(lu_i, lv_i). solver must not be a shared one.
  TexelSolver(const Eigen::MatrixXd& design, Solver solver, const RobustOptions& options);
  ~TexelSolver();
  TexelSolver(const TexelSolver&) = delete;
  TexelSolver& operator=(const TexelSolver&) = delete;

  // value[i]: labelling value of sample i (luma or grey); saturated[i]: some channel of sample
  // i is clipped. Outputs: weights[i] in [0, 1] (0 = rejected), labels[i], coeffs: the
  // polynomial of `value` under those weights.
  TexelOutcome solve(const double* value, const std::uint8_t* saturated, double* weights,
                     SampleLabel* labels, double coeffs[6]);

  // Weighted least squares of any channel with the given weights (the same normal matrix as
  // the last solve() when weights are unchanged). For lambert, where the last solve() found
  // the Lambertian model fit (RobustOptions::fill_rejected), the fit to every sample with the
  // rejected ones (weight 0) replaced by that model, fitted to this channel's inliers.
  // Returns false if the weighted system is singular; coeffs are then the unweighted
  // least-squares fit.
  bool weighted_fit(const double* value, const double* weights, double coeffs[6]);

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace ptmkit::fit
