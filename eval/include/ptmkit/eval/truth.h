// Scoring a fit against ground truth (a synthetic capture's truth/ folder, or any truth in
// memory). Used by `ptmkit compare`, the tests and docs/SOLVERS.md; definitions here are the
// ones the documented figures use.
#pragma once

#include <cstdint>
#include <vector>

#include <Eigen/Core>

#include "ptmkit/core/coefficients.h"
#include "ptmkit/core/image.h"

namespace ptmkit::eval {

// A sample (texel x, y under light i) is "lit" when the true normal faces the light:
// n . l > 0. Elsewhere the diffuse truth is the (constant) ambient level, which no polynomial
// in the light direction follows, and every solver is equally wrong there.
[[nodiscard]] bool is_lit(const Image& truth_normals, int x, int y, const Eigen::Vector3d& light);

struct TruthPsnr {
  // 10 log10(1 / MSE), peak 1.0 (full scale): MSE over every lit sample and every channel of
  // (fitted model at the light - diffuse truth), in normalised units; the model is not
  // clamped.
  double psnr_db = 0.0;
  std::uint64_t samples = 0;  // lit samples x channels
  double sum_sq = 0.0;        // the squared differences summed
  // Adds another band's sums (a capture scored band by band) and recomputes psnr_db.
  void add(const TruthPsnr& band);
};
// `diffuse[i]` is the diffuse truth under light_dirs[i]; `normals` the true normals (3 ch).
[[nodiscard]] TruthPsnr psnr_against_truth(const CoefficientMap& fit,
                                           const std::vector<Eigen::Vector3d>& light_dirs,
                                           const std::vector<Image>& diffuse, const Image& normals);

struct OutlierScores {
  // A sample is a true outlier when the Rec. 601 luma of (observed - diffuse truth) is more
  // than threshold_grey grey levels (1/255) in size; it is labelled an outlier when its
  // fit label is not kInlier. Scores over the samples selected (all, or lit only).
  double precision = 0.0;  // labelled outliers that are true outliers (1 if none labelled)
  double recall = 0.0;     // true outliers that are labelled (1 if none exist)
  std::uint64_t true_outliers = 0;
  std::uint64_t labelled = 0;
  std::uint64_t samples = 0;
  std::uint64_t hits = 0;  // labelled and true
  // Adds another band's counts and recomputes precision and recall.
  void add(const OutlierScores& band);
};
// labels: [y][x][light] as FitOutputs::labels.
[[nodiscard]] OutlierScores outlier_scores(const std::vector<std::uint8_t>& labels,
                                           const std::vector<Image>& observed,
                                           const std::vector<Image>& diffuse,
                                           const std::vector<Eigen::Vector3d>& light_dirs,
                                           const Image& normals, bool lit_only,
                                           double threshold_grey = 20.0);

struct NormalError {
  double mean_deg = 0.0;
  double median_deg = 0.0;
  std::uint64_t texels = 0;
};
// Angle between estimated and true unit normals (both 3 channels), over texels where mask
// (optional, first channel > 0.5) is set.
[[nodiscard]] NormalError normal_error(const Image& estimated, const Image& truth,
                                       const Image* mask = nullptr);
// normal_error gathered over bands of rows in fixed memory, whatever the texel count: the
// mean is exact (summed in texel order, so bands give the whole map's sum), the median is
// read from a histogram of 0.001-degree bins, interpolated by rank within its bin (within
// 0.001 degree of the exact median; the same whatever the banding).
class NormalAngles {
 public:
  NormalAngles();
  // Adds the texels of one band (masked and zero normals skipped).
  void add(const Image& estimated, const Image& truth, const Image* mask);
  [[nodiscard]] NormalError result() const;

  static constexpr double kBinDeg = 0.001;

 private:
  std::vector<std::uint64_t> bins_;
  double sum_deg_ = 0.0;
  std::uint64_t count_ = 0;
};

}  // namespace ptmkit::eval
