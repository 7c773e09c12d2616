// Lambertian photometric stereo of one texel (FitOutputs::normals and albedo): the unit
// normal and per-channel albedo that best explain the texel's weighted samples as
// albedo * max(0, l . n), with l each sample's unit light direction.
//
// A template over how the directions are stored (the shared design's N x 3, or a texel's own
// under near lights) so either is read as it is, without a copy.
#pragma once

#include <algorithm>
#include <cstddef>
#include <vector>

#include <Eigen/Cholesky>
#include <Eigen/Core>

#include "ptmkit/core/colour.h"

namespace ptmkit::fit::internal {

// dirs: N x 3 unit light directions (rows). s: the texel's samples, s[i * ch + k] (ch 1 or 3).
// value: the labelling values (luma, or the grey value). weights: 0 = rejected sample.
// sRGB-encoded samples (srgb) are linearised first: Lambert's law holds for radiance, not for
// the encoded values the polynomial is fitted to. Where the system is singular or the normal
// would point away from the camera, the normal is (0, 0, 1). Grey input gives three equal
// albedos.
template <class Dirs>
void lambertian_stereo(const Dirs& dirs, int n, int ch, bool srgb, const std::vector<double>& s,
                       const double* value, const double* weights, float normal[3],
                       float albedo[3]) {
  // value_i = l_i . g with g = albedo * normal, over the inlier samples. Samples at or below
  // zero carry no direction (attached shadow).
  Eigen::Matrix3d m = Eigen::Matrix3d::Zero();
  Eigen::Vector3d rhs = Eigen::Vector3d::Zero();
  for (int i = 0; i < n; ++i) {
    const double w = weights[i];
    if (w <= 0.0) continue;
    const Eigen::Vector3d l = Eigen::Vector3d(dirs.row(i).transpose());
    m.noalias() += w * l * l.transpose();
    rhs += (w * (srgb ? srgb_to_linear(value[i]) : value[i])) * l;
  }
  Eigen::Vector3d nrm(0.0, 0.0, 1.0);
  const Eigen::LDLT<Eigen::Matrix3d> ldlt(m);
  if (ldlt.info() == Eigen::Success && ldlt.isPositive()) {
    const Eigen::Vector3d g = ldlt.solve(rhs);
    if (g.allFinite() && g.norm() > 1e-12 && g.z() > 0.0) nrm = g.normalized();
  }
  double num[3] = {0.0, 0.0, 0.0};
  double den = 0.0;
  for (int i = 0; i < n; ++i) {
    const double w = weights[i];
    if (w <= 0.0) continue;
    const double shade = std::max(0.0, dirs.row(i).dot(nrm));
    den += w * shade * shade;
    for (int k = 0; k < 3; ++k) {
      const double v = s[static_cast<std::size_t>(i * ch + (ch == 3 ? k : 0))];
      num[k] += w * shade * (srgb ? srgb_to_linear(v) : v);
    }
  }
  for (int k = 0; k < 3; ++k) {
    normal[k] = static_cast<float>(nrm(k));
    albedo[k] = den > 1e-20 ? static_cast<float>(num[k] / den) : 0.0f;
  }
}

}  // namespace ptmkit::fit::internal
