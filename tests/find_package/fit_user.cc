// Uses an installed ptmkit::fit (its Ceres dependency found by the package) and ptmkit::eval.
#include <cmath>
#include <cstdio>
#include <vector>

#include "ptmkit/core/light_layout.h"
#include "ptmkit/eval/ssim.h"
#include "ptmkit/fit/design.h"

int main() {
  // The seed paper's 40-light dome fits; one ring of lights cannot (lu^2 + lv^2 is constant).
  const auto dome = ptmkit::fit::analyse_design(ptmkit::geodesic_dome(2));
  const auto ring = ptmkit::fit::analyse_design(ptmkit::ring_layout({{45.0, 12, 0.0}}));
  if (!dome.problem.empty() || !std::isfinite(dome.condition_number)) return 1;
  if (ring.problem.empty() || !ring.single_ring) return 1;
  const std::vector<double> img = {0.1, 0.5, 0.9, 0.3, 0.7, 0.2, 0.4, 0.8, 0.6};
  if (std::abs(ptmkit::eval::mean_ssim(img, img, 3, 3) - 1.0) > 1e-12) return 1;
  std::printf("fit: dome cond(A) %.2f; ring refused: %s\n", dome.condition_number,
              ring.problem.c_str());
  return 0;
}
