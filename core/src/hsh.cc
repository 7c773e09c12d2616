#include "ptmkit/core/hsh.h"

#include <algorithm>
#include <cmath>
#include <numbers>

namespace ptmkit {

namespace {
constexpr double kPi = std::numbers::pi;
// The .rti viewers' clamp of theta (core/hsh.h).
constexpr double kThetaMargin = 0.04;
}  // namespace

void hsh_basis(int terms, const Eigen::Vector3d& dir, double* out) {
  const double norm = dir.norm();
  const Eigen::Vector3d d = dir / norm;
  const double theta = std::min(std::acos(std::clamp(d.z(), -1.0, 1.0)), kPi / 2 - kThetaMargin);
  const double phi = std::atan2(d.y(), d.x());
  const double c = std::cos(theta);
  const double c2 = c * c;
  const double s = std::sqrt(std::max(0.0, c - c2));
  out[0] = 1.0 / std::sqrt(2.0 * kPi);
  out[1] = std::sqrt(6.0 / kPi) * std::cos(phi) * s;
  out[2] = std::sqrt(3.0 / (2.0 * kPi)) * (2.0 * c - 1.0);
  out[3] = std::sqrt(6.0 / kPi) * std::sin(phi) * s;
  if (terms <= 4) return;
  const double k30 = std::sqrt(30.0 / kPi);
  out[4] = k30 * std::cos(2.0 * phi) * (c2 - c);
  out[5] = k30 * std::cos(phi) * (2.0 * c - 1.0) * s;
  out[6] = std::sqrt(5.0 / (2.0 * kPi)) * (6.0 * c2 - 6.0 * c + 1.0);
  out[7] = k30 * std::sin(phi) * (2.0 * c - 1.0) * s;
  out[8] = k30 * std::sin(2.0 * phi) * (c2 - c);
  if (terms <= 9) return;
  const double s3 = s * s * s;
  const double k35 = 2.0 * std::sqrt(35.0 / kPi);
  const double k210 = std::sqrt(210.0 / kPi);
  const double k21 = 2.0 * std::sqrt(21.0 / kPi);
  const double q = 5.0 * c2 - 5.0 * c + 1.0;
  out[9] = k35 * std::cos(3.0 * phi) * s3;
  out[10] = k210 * std::cos(2.0 * phi) * (2.0 * c - 1.0) * (c2 - c);
  out[11] = k21 * std::cos(phi) * s * q;
  out[12] = std::sqrt(7.0 / (2.0 * kPi)) * (20.0 * c2 * c - 30.0 * c2 + 12.0 * c - 1.0);
  out[13] = k21 * std::sin(phi) * s * q;
  out[14] = k210 * std::sin(2.0 * phi) * (2.0 * c - 1.0) * (c2 - c);
  out[15] = k35 * std::sin(3.0 * phi) * s3;
}

}  // namespace ptmkit
