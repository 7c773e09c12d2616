// The robust solvers' tuning flags, shared by `ptmkit fit` and `ptmkit compare`.
#include <cstdio>
#include <string>

#include "commands.h"
#include "ptmkit/fit/robust.h"

namespace ptmkit::app {

namespace {
std::string grey_text(double grey) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%g", grey);
  return buf;
}
}  // namespace

void add_robust_flags(CLI::App* cmd, fit::RobustOptions* robust) {
  cmd->add_option("--shadow-k", robust->shadow_k,
                  "sign/lambert: samples more than this many robust scales below the fit are "
                  "shadows")
      ->capture_default_str()
      ->check(CLI::PositiveNumber);
  cmd->add_option("--highlight-k", robust->highlight_k,
                  "sign/lambert: samples more than this many robust scales above the fit are "
                  "highlights")
      ->capture_default_str()
      ->check(CLI::PositiveNumber);
  cmd->add_option("--readmit-k", robust->readmit_k,
                  "sign/lambert: after the fit, re-admit rejected samples within this many "
                  "robust scales of it and refit (0 = off). Raises label precision, costs "
                  "truth PSNR (docs/SOLVERS.md)")
      ->capture_default_str()
      ->check(CLI::NonNegativeNumber);
  cmd->add_option("--min-inliers", robust->min_inliers,
                  "robust solvers: the fewest samples a texel keeps; where a solver's labels "
                  "would keep fewer, the texel keeps its earlier fit. With as many lights or "
                  "fewer, nothing is rejected")
      ->capture_default_str()
      ->check(CLI::Range(6, 1 << 20));
  cmd->add_option("--dark-fraction", robust->dark_fraction,
                  "trim/sign/lambert: samples darker than this fraction of the texel's "
                  "75th-percentile sample are shadows")
      ->capture_default_str()
      ->check(CLI::Range(0.0, 0.99));
  cmd->add_option_function<double>(
         "--keep-within-grey", [robust](double grey) { robust->keep_within = grey / 255.0; },
         "lambert: once the labels settle, rejected samples (not clipped, lit by the model) "
         "within this many grey levels of an 8-bit image (1/255 of full scale each) of the "
         "Lambertian model are inliers again (0 = off). Higher: fewer, surer labels")
      ->default_str(grey_text(robust->keep_within * 255.0))
      ->check(CLI::NonNegativeNumber);
  cmd->add_option("--keep-within-fraction", robust->keep_within_fraction,
                  "lambert: the keep window of --keep-within-grey is also at most this "
                  "fraction of the texel's albedo, so a dark or intensity-normalised capture "
                  "is labelled as at full exposure (0 = the grey levels alone)")
      ->capture_default_str()
      ->check(CLI::Range(0.0, 1.0));
  cmd->add_flag(
      "!--no-fill", robust->fill_rejected,
      "lambert: fit the polynomial to the inliers alone, instead of to every sample with the "
      "rejected ones replaced by the Lambertian model (done only where that model fits the "
      "inliers at least as well as the polynomial)");
}

}  // namespace ptmkit::app
