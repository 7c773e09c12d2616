// What `ptmkit fit` works out before and around the fit, as library calls: which model is
// fitted (the PTM polynomial, an HSH basis, or one chosen from held-out error), what file it
// is written as, which solvers, maps and light models go with it; and the run's report.
//
//   FitRequest (what was asked) --plan_fit--> FitPlan (FitOptions with the basis decided,
//   the output format, the model-selection evidence) --fit_capture--> FitReport
//   --> FitRunReport (plus input, output, what writing the file cost): to_json(), brief().
#pragma once

#include <cstddef>
#include <filesystem>
#include <optional>
#include <string>
#include <string_view>

#include "ptmkit/core/collective.h"
#include "ptmkit/core/light_set.h"
#include "ptmkit/fit/fit.h"
#include "ptmkit/fit/model_select.h"

namespace ptmkit::fit {

// The model asked for: one basis, or chosen per capture.
enum class ModelRequest { kPtm, kHsh2, kHsh3, kHsh4, kAuto };
// "ptm", "hsh2", "hsh3", "hsh4", "auto".
[[nodiscard]] std::string_view to_string(ModelRequest model);
// Throws ptmkit::Error for an unknown name.
[[nodiscard]] ModelRequest parse_model_request(std::string_view name);

// The file a basis is written as: .ptm for the PTM polynomial, .rti for HSH.
enum class CoefficientFormat { kPtm, kRti };
[[nodiscard]] CoefficientFormat format_for(Basis basis);
// ".ptm" or ".rti".
[[nodiscard]] std::string_view extension(CoefficientFormat format);

struct FitRequest {
  ModelRequest model = ModelRequest::kPtm;
  // The fit's options; options.basis is decided by plan_fit from `model`, and with kAuto the
  // colour model too unless colour_given.
  FitOptions options;
  // With kAuto: the colour model (options.model) was given, so only the basis is chosen.
  bool colour_given = false;
  // Per-texel maps asked for (residual, outlier counts, normals, albedo, labels): PTM only.
  bool wants_maps = false;
  // The output file: its extension must be the chosen basis's (.ptm or .rti).
  std::filesystem::path output;
};

struct FitPlan {
  FitOptions options;  // basis and colour model decided
  CoefficientFormat format = CoefficientFormat::kPtm;
  std::optional<ModelReport> selection;  // kAuto's evidence
};

// Decides the model (running model selection for kAuto, on `lights`' images) and checks what
// goes together, before the fit reads a pixel: near lights (options.near.plane) with ptm only;
// other bases with the least-squares solvers, without maps; the output's extension. Throws
// ptmkit::Error saying what does not go together and what would.
[[nodiscard]] FitPlan plan_fit(const LightSet& lights, const FitRequest& request);

// The same when several processes share the fit (`peers`, a collective call; null: one
// process). With kAuto only rank 0 runs model selection, on the whole capture, and the others
// plan what it chose, so every process fits the same model.
[[nodiscard]] FitPlan plan_fit(const LightSet& lights, FitRequest request, Collective* peers);

// One process's share of the rows the fit reads (the region after crop and mask).
struct RowShare {
  RowRange rows;        // in the region, [begin, end)
  int full_height = 0;  // the region's height
};

// Splits the region's rows between `peers` (rows_of_rank) and restricts `options` to this
// process's share (options->input.rows). Throws ptmkit::Error when there are more processes
// than rows.
[[nodiscard]] RowShare share_rows(const LightSet& lights, Collective& peers, FitOptions* options);

// What writing the coefficients cost (texture's .ptm or .rti writer reports), kept here so a
// run's report is one typed struct.
struct WriteSummary {
  std::size_t file_bytes = 0;
  double max_coeff_error = 0.0;
  double rms_coeff_error = 0.0;
  // .ptm only: relit error of the quantised file against its unquantised values.
  std::optional<double> relit_mean_abs_grey, relit_max_abs_grey, relit_psnr_db;
};

// A whole `ptmkit fit` run.
struct FitRunReport {
  FitReport fit;
  std::optional<ModelReport> selection;
  std::filesystem::path input;   // the light file
  std::filesystem::path output;  // the coefficient file
  WriteSummary written;
  // The fit report's JSON with input, output, quantisation and model_selection added.
  [[nodiscard]] std::string to_json() const;
  // The lines `ptmkit fit` prints: the fit, the light model, the solver's outliers (and a note
  // where the lights are too few for it to reject any), the file.
  [[nodiscard]] std::string brief() const;
};

}  // namespace ptmkit::fit
