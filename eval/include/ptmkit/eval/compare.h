// Comparing solvers on one capture: held-out lights, timings and (for synthetic captures)
// ground truth, so each solver's place on the speed/accuracy trade is measured, not guessed.
//
// For every solver:
//   - timing: one fit of the whole capture from images in memory (no decoding), no optional
//     outputs and no residual statistics, so the figure is the solver's own cost;
//   - held-out accuracy: predictions at lights the fit did not see, against the photographs
//     taken under them. Either a separate test set (`test_lp`: fitted on every capture light,
//     predicted at each test light) or K folds over the capture's lights (light i is in fold
//     i mod K; each fold is predicted by a fit on the others). Predictions are clamped to
//     [0, 1] for integer files (what a viewer shows), to >= 0 for float files;
//   - ground truth, when the capture's folder holds a `ptmkit synth` set (truth.json,
//     truth/diffuse/, truth/normals.exr or .png): PSNR against the diffuse truth, normal error
//     and outlier precision/recall, with the definitions of evaluate.h; or, without
//     truth.json, a 16-bit normal map `normals.png` ((n + 1) / 2, light frame) beside the light
//     file (and optionally `mask.png`), as the SynthRTI benchmark ships: normal error only.
// PSNR is 10 log10(1 / MSE) with peak 1.0 (full scale) over every sample and channel
// (core/holdout.h); the held-out scores are heldout.h's, the folds core/holdout.h's.
#pragma once

#include <cstdint>
#include <filesystem>
#include <optional>
#include <string>
#include <vector>

#include "ptmkit/core/coefficients.h"
#include "ptmkit/core/image.h"
#include "ptmkit/eval/truth.h"
#include "ptmkit/fit/design.h"
#include "ptmkit/fit/robust.h"

namespace ptmkit::eval {

struct CompareOptions {
  // Solvers to compare, in table order; at least one, no repeats.
  std::vector<fit::Solver> solvers;
  // Folds over the capture's lights when no test set is given: 2 .. lights. Each fold's
  // training set (the other folds) must still be a fittable layout.
  int folds = 5;
  ColourModel model = ColourModel::kRGB;
  // Worker threads; 0 = all cores. Timings are for this many.
  int threads = 0;
  // Timing fits per solver; the fastest is reported (less noise on a shared machine).
  int timing_repeats = 1;
  // Mean SSIM of the held-out predictions (luma, 11x11 Gaussian window, sigma 1.5).
  bool ssim = true;
  fit::RobustOptions robust;
  fit::DesignOptions design;
  // Rows of the capture read and fitted at a time; 0: as many as fit in about 64 MiB of
  // samples over every stack read together (capture, test set, diffuse truth), at least 16.
  // The scores do not depend on it beyond rounding (SSIM windows reach across bands).
  int band_rows = 0;

  [[nodiscard]] std::string validate() const;  // empty if valid
};

struct SolverResult {
  fit::Solver solver = fit::Solver::kLS;
  // Timing fit (all capture lights).
  double fit_seconds = 0.0;         // fitting only
  double wall_seconds = 0.0;        // the whole fit call
  double us_per_texel = 0.0;        // fit_seconds / texels, in microseconds
  double mtexels_per_second = 0.0;  // texels / wall_seconds / 1e6
  // Held-out lights.
  double heldout_psnr_db = 0.0;
  double heldout_ssim = 0.0;  // 0 when not computed
  std::uint64_t heldout_samples = 0;
  // Labels of the whole-capture fit (zero for the least-squares solvers).
  double shadow_fraction = 0.0;
  double highlight_fraction = 0.0;
  // Ground truth (CompareReport::has_truth; normals: has_normals).
  double truth_psnr_db = 0.0;
  NormalError normals;
  OutlierScores outliers;  // over lit samples
  // On the Pareto front of (us_per_texel lower, accuracy higher); see CompareReport::accuracy.
  bool pareto = false;
};

struct CompareReport {
  std::filesystem::path capture;
  std::filesystem::path test;  // empty with folds
  int width = 0;
  int height = 0;
  int channels = 0;
  int lights = 0;
  int test_lights = 0;  // the test set's lights, or the capture's (every fold held out once)
  int folds = 0;        // 0 when a test set was given
  int threads = 0;
  bool has_truth = false;         // a `ptmkit synth` truth: diffuse images, normals
  bool has_normals = false;       // true normals (a synth truth, or a normals.png beside the .lp)
  double condition_number = 0.0;  // cond(A) of the capture's lights
  std::vector<SolverResult> results;

  // The accuracy the Pareto front and the plot use: truth PSNR when truth exists (it measures
  // the rejection directly), else held-out PSNR.
  [[nodiscard]] double accuracy(const SolverResult& r) const {
    return has_truth ? r.truth_psnr_db : r.heldout_psnr_db;
  }
  [[nodiscard]] std::string accuracy_name() const {
    return has_truth ? "PSNR vs diffuse truth (dB)" : "held-out PSNR (dB)";
  }
  [[nodiscard]] std::string to_json() const;
  [[nodiscard]] std::string to_markdown() const;
  [[nodiscard]] std::string to_csv() const;
};

// Runs the comparison. Throws ptmkit::Error naming the file on an unreadable or mismatched
// input (a light file, an image, a truth file), on invalid options, or when a fold's training
// lights cannot be fitted. Streams the images band by band, like a fit (options.band_rows),
// in memory that does not grow with the texel count (the true normals' angles are gathered in
// a fixed histogram, NormalAngles).
[[nodiscard]] CompareReport compare_solvers(const std::filesystem::path& capture_lp,
                                            const std::optional<std::filesystem::path>& test_lp,
                                            const CompareOptions& options);

// Accuracy against time (log scale), one point per solver, the Pareto front joined in red.
// 3-channel linear image, values in [0, 1].
[[nodiscard]] Image plot_tradeoff(const CompareReport& report);

// Writes table.md, results.csv, results.json and plot.png into `out_dir` (created if needed);
// each file atomically, all built in memory first.
void write_compare(const CompareReport& report, const std::filesystem::path& out_dir);

}  // namespace ptmkit::eval
