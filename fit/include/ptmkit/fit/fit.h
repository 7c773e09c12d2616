// Fitting a capture: photographs under known lights in, a coefficient map out.
//
// The stack is read in bands of rows (all images at once, decoded in parallel) and each band
// is fitted while the next one decodes, so memory stays at two bands plus what the sink keeps,
// never the whole decoded stack. The least-squares solvers fit every texel with the same
// pseudo-inverse (see design.h); the robust ones label and weight each texel's samples first
// (see robust.h). Results are identical whatever the thread count.
//
// The pipeline: a band source (the capture's files through core's StackReader, or images in
// memory, one channel rule) -> a row fitter (the shared pseudo-inverse for distant lights;
// per texel for robust solvers and near lights; any basis, FitOptions::basis) -> a
// CoefficientSink (core/coefficients.h: a .ptm or .rti writer, or a map in memory).
//
// Near lights (near_light.h): given a sample plane (FitOptions::near.plane) and a position for
// every light, each texel gets its own design rows and 6 x 6 normal equations (double), and
// optionally a fall-off correction. Only the least-squares solvers ls and ridge support it so
// far; others are refused. Without a plane the shared-matrix path above runs unchanged.
#pragma once

#include <cstdint>
#include <filesystem>
#include <string>
#include <vector>

#include "ptmkit/core/coefficients.h"
#include "ptmkit/core/image.h"
#include "ptmkit/core/light_set.h"
#include "ptmkit/core/parallel.h"
#include "ptmkit/core/stack_reader.h"
#include "ptmkit/fit/basis.h"
#include "ptmkit/fit/design.h"
#include "ptmkit/fit/near_light.h"
#include "ptmkit/fit/robust.h"

namespace ptmkit::fit {

enum class Precision {
  kFloat,   // pseudo-inverse applied in float: 2x the speed; error ~1e-6 of full scale
  kDouble,  // everything in double (for exactness checks)
};

// Per-texel maps a fit can fill on request (the `outputs` argument of fit_capture, PTM basis). Each
// is produced only when its want_ flag is set; sizes are the capture's.
struct FitOutputs {
  bool want_residual_map = false;
  bool want_outlier_counts = false;
  bool want_labels = false;
  bool want_normals = false;
  // 1 channel: RMS residual of the fit over the texel's inlier samples and all fitted
  // channels, in grey levels (1/255 of full scale).
  Image residual_map;
  // 2 channels: number of samples labelled shadow, highlight.
  Image outlier_counts;
  // [y][x][light] SampleLabel codes (0 inlier, 1 shadow, 2 highlight), row-major texels.
  std::vector<std::uint8_t> labels;
  // 3 channels: unit normals (x, y, z in the light frame) by Lambertian photometric stereo
  // on the labelling channel over the inlier samples (all samples for least-squares solvers);
  // (0, 0, 1) where the system is singular. sRGB-encoded input is linearised first.
  Image normals;
  // 3 channels: per-channel Lambertian albedo with those normals, linear (grey input: three
  // equal).
  Image albedo;
};

// Writes outputs.labels as one 8-bit image per light into `dir` (created if missing), named
// after the light's photograph with a .png extension; the codes are `ptmkit synth`'s
// truth/labels (0 inlier, 1 shadow, 2 highlight).
void write_label_images(const std::filesystem::path& dir, const FitOutputs& outputs,
                        const LightSet& lights, int width, int height);

struct FitOptions {
  // The function basis (core/coefficients.h). kPtm (default): the six-term polynomial, every
  // solver, near lights and the optional maps. The HSH bases: the least-squares solvers
  // (ls, qr, svd, ridge; the operator is built by SVD whichever), distant lights, rgb or lrgb.
  Basis basis = Basis::kPtm;
  // Colour model (see core/coefficients.h). kRGB is the default: it is the most accurate on
  // the measured sets (docs/FITTING.md) and what RGB .ptm viewers show; kLRGB halves storage.
  ColourModel model = ColourModel::kRGB;
  DesignOptions design;
  Precision precision = Precision::kFloat;
  // Worker threads; 0 = all cores. Results do not depend on it.
  int threads = 0;
  // Rows per band. Memory is about 2 * band_rows * width * channels * lights * bytes per
  // sample (1 for 8-bit files, else 4; two bands: one fitted while the next decodes): 19 MB
  // for 49 8-bit RGB images 4000 px wide. Fewer, longer bands decode faster (each image's
  // decoder keeps its caches longer): 16 rows took 15% less time to decode than 8 on a
  // 12-megapixel stack, and the whole fit 5% less (docs/PERFORMANCE.md).
  int band_rows = 16;
  // Compute residual statistics (on a fixed row sample, ResidualStats; a few percent of a
  // 12-megapixel fit's time).
  bool residual_stats = true;
  // Called with the fraction done after each band.
  ProgressFn progress;
  // Per-texel solver. kLS (default) is the shared pseudo-inverse by Cholesky; kQR and kSVD
  // build it by QR or SVD of A; kRidge uses design.ridge_lambda, or 1e-3 if that is 0. The
  // others label each texel's samples (robust.h) and cost microseconds per texel.
  Solver solver = Solver::kLS;
  RobustOptions robust;
  // Near lights: the sample plane and fall-off correction (near_light.h). With a plane, every
  // light must have a position_mm, the solver must be ls or ridge, and `precision` is ignored
  // (per-texel solves are in double).
  NearLightOptions near;
  // How the photographs are read (fit_capture only): a crop or mask (only that region is
  // fitted and written; the near-light geometry and the plane keep the photos' pixel
  // coordinates), the colour space they are taken to be in, damaged files accepted or not.
  StackReadOptions input;

  // Empty if valid, else what is wrong.
  [[nodiscard]] std::string validate() const;
};

// Residuals of the fit against its own input samples, in 8-bit grey levels (1/255 of full
// scale), over every sample of every channel of the rows sampled: every row up to 2^16
// texels, every row_step-th row above (a fixed choice, so reports are reproducible; 2^16
// texels x N lights x channels is millions of samples, plenty for these statistics).
struct ResidualStats {
  double rms_grey = 0.0;
  double mean_abs_grey = 0.0;
  double p99_abs_grey = 0.0;  // from a 0.05-grey-level histogram
  double max_abs_grey = 0.0;
  std::uint64_t samples = 0;
  int row_step = 1;
};

// Labels over the whole fit (robust solvers; zero for the least-squares ones).
struct OutlierSummary {
  std::uint64_t samples = 0;          // texels x lights
  std::uint64_t shadows = 0;          // samples labelled shadow
  std::uint64_t highlights = 0;       // samples labelled highlight
  std::uint64_t fallback_texels = 0;  // texels that kept an earlier fit (too few inliers)
  std::uint64_t ceres_texels = 0;     // texels on which Ceres ran
};

struct FitReport {
  int lights = 0;
  int width = 0;
  int height = 0;
  int channels = 0;
  Basis basis = Basis::kPtm;
  // The colour model fitted (grey input to an HSH basis: kLRGB, its luminance).
  ColourModel model = ColourModel::kRGB;
  ColourSpace colour_space = ColourSpace::kSRGB;
  DesignReport design;
  ResidualStats residuals;
  Solver solver = Solver::kLS;
  OutlierSummary outliers;
  // The robust solvers' options in force: the ones given, with min_scale in steps of the
  // input's sample type and saturation_level +inf for float files (written to the JSON for
  // robust solvers only).
  RobustOptions robust;
  // The light model used: distant (shared matrix) or near (per-texel), its direction spread
  // and fall-off range over the field.
  NearLightReport light_model;
  // How the images were read (fit_capture): region, orientation, colour space and why.
  StackInputSummary input;
  // Processes that shared the fit (combine_shares); 1 for one process. With more, the
  // residual percentile (p99) is not known (NaN): the others are exact over every process.
  int processes = 1;
  int threads = 0;
  // Wall-clock seconds. Decoding and fitting overlap, so decode + fit can exceed total.
  double decode_seconds = 0.0;  // summed over bands
  double fit_seconds = 0.0;     // summed over bands
  double total_seconds = 0.0;
  [[nodiscard]] double texels_per_second() const {
    return total_seconds > 0 ? width * static_cast<double>(height) / total_seconds : 0.0;
  }
  // JSON text of the whole report.
  [[nodiscard]] std::string to_json() const;
  // One line: lights, size, basis and colour model, cond(A), residual, time.
  [[nodiscard]] std::string brief() const;
};

// Fits the images of `lights` (read through core's StackReader) into `sink`, and fills the
// maps `outputs` asks for (optional). Throws ptmkit::Error on a bad layout or
// unreadable/mismatched images (naming the file); the sink has then received begin() at most,
// never end(). With options.near.plane set, the lights' position_mm give the near-light model:
// a light without one, a plane of another size than the images, or a solver other than
// ls/ridge is an error. The sink receives options.basis's layout (CoefficientSink::begin).
FitReport fit_capture(const LightSet& lights, const FitOptions& options, CoefficientSink& sink,
                      FitOutputs* outputs = nullptr);

// A fit shared by several processes, each of its rows (FitOptions::input.rows): turns each
// process's report into the whole fit's, on every process (a collective call). Sizes,
// regions, sample and label counts are summed, residual RMS, mean and max combined exactly,
// times are the slowest process's.
void combine_shares(FitReport* report, Collective& peers);

// The same on images already in memory (all the same size and channel count), one per
// direction. An alpha channel is not a sample (RGBA is fitted as RGB, grey + alpha as grey),
// as from files.
FitReport fit_images(const std::vector<Image>& images,
                     const std::vector<Eigen::Vector3d>& light_dirs, const FitOptions& options,
                     CoefficientSink& sink, FitOutputs* outputs = nullptr);
// The same with a light set (its directions, and its positions for the near-light model as in
// fit_capture; the lights' image paths are not used).
FitReport fit_images(const std::vector<Image>& images, const LightSet& lights,
                     const FitOptions& options, CoefficientSink& sink,
                     FitOutputs* outputs = nullptr);

}  // namespace ptmkit::fit
