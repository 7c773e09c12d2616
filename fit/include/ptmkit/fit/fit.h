// Fitting a capture: photographs under known distant lights in, a coefficient map out.
//
// The stack is read in bands of rows (all images at once, decoded in parallel) and each band
// is fitted while the next one decodes, so memory stays at two bands plus what the sink keeps,
// never the whole decoded stack. Every texel is fitted with the same pseudo-inverse (see
// design.h); results are identical whatever the thread count.
#pragma once

#include <string>
#include <vector>

#include "ptmkit/core/coefficients.h"
#include "ptmkit/core/image.h"
#include "ptmkit/core/light_set.h"
#include "ptmkit/core/parallel.h"
#include "ptmkit/fit/design.h"

namespace ptmkit::fit {

enum class Precision {
  kFloat,   // pseudo-inverse applied in float: 2x the speed; error ~1e-6 of full scale
  kDouble,  // everything in double (for exactness checks)
};

struct FitOptions {
  // Colour model (see core/coefficients.h). kRGB is the default: it is the most accurate on
  // the measured sets (docs/FITTING.md) and what RGB .ptm viewers show; kLRGB halves storage.
  ColourModel model = ColourModel::kRGB;
  DesignOptions design;
  Precision precision = Precision::kFloat;
  // Worker threads; 0 = all cores. Results do not depend on it.
  int threads = 0;
  // Rows per band. Memory is about 2 * band_rows * width * channels * lights * 4 bytes.
  int band_rows = 16;
  // Compute residual statistics (costs about as much as the fit itself).
  bool residual_stats = true;
  // Called with the fraction done after each band.
  ProgressFn progress;

  // Empty if valid, else what is wrong.
  [[nodiscard]] std::string validate() const;
};

// Residuals of the fit against its own input samples, in 8-bit grey levels (1/255 of full
// scale), over every sample of every channel.
struct ResidualStats {
  double rms_grey = 0.0;
  double mean_abs_grey = 0.0;
  double p99_abs_grey = 0.0;  // from a 0.05-grey-level histogram
  double max_abs_grey = 0.0;
  std::uint64_t samples = 0;
};

struct FitReport {
  int lights = 0;
  int width = 0;
  int height = 0;
  int channels = 0;
  ColourModel model = ColourModel::kRGB;
  ColourSpace colour_space = ColourSpace::kSRGB;
  DesignReport design;
  ResidualStats residuals;
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
};

// Fits the images of `lights` (read through core's StackReader) into `sink`. Throws
// ptmkit::Error on a bad layout or unreadable/mismatched images (naming the file); the sink
// has then received begin() at most, never end().
FitReport fit_capture(const LightSet& lights, const FitOptions& options, CoefficientSink& sink);

// The same on images already in memory (all the same size), one per direction.
FitReport fit_images(const std::vector<Image>& images,
                     const std::vector<Eigen::Vector3d>& light_dirs, const FitOptions& options,
                     CoefficientSink& sink);

}  // namespace ptmkit::fit
