// The outline of a glossy sphere located on its limb's profile (sphere_stack_detail.h,
// LimbProfileModel).
#include <algorithm>
#include <cmath>
#include <limits>

#include <Eigen/Dense>

#include "sphere_stack_detail.h"

namespace ptmkit::calib::stack_detail {

namespace {

// The blurs tried (pixels, Gaussian sigma): from the pixel's own footprint (a box of one pixel
// is about 0.3) to a soft lens.
constexpr double kLimbSigmasPx[] = {0.3, 0.45, 0.6, 0.8, 1.0};
// The tables' reach and resolution in u (pixels inside the outline).
constexpr double kTableReachPx = 10.0;
constexpr double kTableStepPx = 1.0 / 64.0;
// The outline's offsets tried, pixels, before the parabola.
constexpr double kOffsetStepPx = 0.05;

// 1 - F(theta) / (1 - F0) by Schlick's approximation at u pixels inside the outline of a
// sphere of radius r: the share of the sphere's own light that the mirror leaves, 0 at the
// outline, where the reflection is total. Independent of F0, so one shape fits black glass,
// chrome and a glass marble.
double limb_shape(double u, double r) {
  if (u <= 0.0) return 0.0;
  const double rho = std::max(0.0, 1.0 - u / r);
  const double cos_t = std::sqrt(std::max(0.0, 1.0 - rho * rho));
  return 1.0 - std::pow(1.0 - cos_t, 5);
}

}  // namespace

LimbProfileModel::LimbProfileModel(double radius_px) {
  const int n = static_cast<int>(std::lround(2.0 * kTableReachPx / kTableStepPx)) + 1;
  // The blur's Gaussian weights on evenly spaced nodes over +-4 sigma.
  constexpr int kNodes = 161;
  std::vector<double> z(kNodes), w(kNodes);
  double wsum = 0.0;
  for (int k = 0; k < kNodes; ++k) {
    z[static_cast<std::size_t>(k)] = -4.0 + 8.0 * k / (kNodes - 1);
    w[static_cast<std::size_t>(k)] =
        std::exp(-0.5 * z[static_cast<std::size_t>(k)] * z[static_cast<std::size_t>(k)]);
    wsum += w[static_cast<std::size_t>(k)];
  }
  for (double& x : w) x /= wsum;
  for (const double sigma : kLimbSigmasPx) {
    Table t;
    t.step.resize(static_cast<std::size_t>(n));
    t.limb.resize(static_cast<std::size_t>(n));
    for (int i = 0; i < n; ++i) {
      const double u = -kTableReachPx + i * kTableStepPx;
      double h = 0.0, g = 0.0;
      for (int k = 0; k < kNodes; ++k) {
        const double v = u + sigma * z[static_cast<std::size_t>(k)];
        if (v > 0.0) h += w[static_cast<std::size_t>(k)];
        g += w[static_cast<std::size_t>(k)] * limb_shape(v, radius_px);
      }
      t.step[static_cast<std::size_t>(i)] = h;
      t.limb[static_cast<std::size_t>(i)] = g;
    }
    tables_.push_back(std::move(t));
  }
}

double LimbProfileModel::Table::at(const std::vector<double>& f, double u) {
  const double x = (std::clamp(u, -kTableReachPx, kTableReachPx) + kTableReachPx) / kTableStepPx;
  const auto i = std::min(static_cast<std::size_t>(x), f.size() - 2);
  const double a = x - static_cast<double>(i);
  return (1.0 - a) * f[i] + a * f[i + 1];
}

LimbProfileModel::Fit LimbProfileModel::fit(const std::vector<double>& prof, double t0, double step,
                                            double lo, double hi) const {
  Fit best;
  const std::size_t n = prof.size();
  if (n < 8 || !(hi > lo)) return best;
  // The sums that do not depend on the outline's place (t centred for conditioning).
  const double tc = t0 + 0.5 * step * static_cast<double>(n - 1);
  double st = 0.0, stt = 0.0, sy = 0.0, sty = 0.0, syy = 0.0;
  for (std::size_t i = 0; i < n; ++i) {
    const double t = t0 + step * static_cast<double>(i) - tc, y = prof[i];
    st += t;
    stt += t * t;
    sy += y;
    sty += t * y;
    syy += y * y;
  }
  // Residual sum of squares of level + slope * t + c * basis(R - t), and the c found.
  const auto sse_at = [&](const std::vector<double>& basis, double r_px, double* c) {
    double sb = 0.0, sbb = 0.0, stb = 0.0, sby = 0.0;
    for (std::size_t i = 0; i < n; ++i) {
      const double t = t0 + step * static_cast<double>(i);
      const double b = Table::at(basis, r_px - t);
      sb += b;
      sbb += b * b;
      stb += (t - tc) * b;
      sby += b * prof[i];
    }
    Eigen::Matrix3d m;
    m << static_cast<double>(n), st, sb, st, stt, stb, sb, stb, sbb;
    const Eigen::Vector3d rhs(sy, sty, sby);
    const Eigen::LDLT<Eigen::Matrix3d> ldlt(m);
    if (ldlt.info() != Eigen::Success || !(std::abs(ldlt.vectorD().minCoeff()) > 1e-12)) {
      return std::numeric_limits<double>::infinity();
    }
    const Eigen::Vector3d x = ldlt.solve(rhs);
    *c = x[2];
    return std::max(0.0, syy - x.dot(rhs));
  };
  // The best place of one basis over the offsets, refined by a parabola through its SSE.
  const auto place = [&](const std::vector<double>& basis, double* r_px, double* sse, double* c) {
    const int k_n = static_cast<int>(std::floor((hi - lo) / kOffsetStepPx)) + 1;
    std::vector<double> e(static_cast<std::size_t>(k_n));
    int bk = -1;
    double cb = 0.0;
    for (int k = 0; k < k_n; ++k) {
      double ck = 0.0;
      e[static_cast<std::size_t>(k)] = sse_at(basis, lo + k * kOffsetStepPx, &ck);
      if (bk < 0 || e[static_cast<std::size_t>(k)] < e[static_cast<std::size_t>(bk)]) {
        bk = k;
        cb = ck;
      }
    }
    double off = 0.0;
    if (bk > 0 && bk + 1 < k_n) {
      const double em = e[static_cast<std::size_t>(bk - 1)], e0 = e[static_cast<std::size_t>(bk)],
                   ep = e[static_cast<std::size_t>(bk + 1)];
      const double den = em - 2.0 * e0 + ep;
      if (den > 1e-300) off = std::clamp(0.5 * (em - ep) / den, -0.5, 0.5);
    }
    *r_px = lo + (bk + off) * kOffsetStepPx;
    *sse = e[static_cast<std::size_t>(bk)];
    *c = cb;
  };
  for (const Table& t : tables_) {
    double r = 0.0, e = 0.0, c = 0.0;
    place(t.limb, &r, &e, &c);
    if (e < best.limb_sse) {
      best.limb_sse = e;
      best.limb_px = r;
      const double t_last = t0 + step * static_cast<double>(n - 1);
      best.limb_amplitude =
          std::abs(c) * std::abs(Table::at(t.limb, r - t0) - Table::at(t.limb, r - t_last));
      best.limb_rms = std::sqrt(e / static_cast<double>(n));
    }
    place(t.step, &r, &e, &c);
    if (e < best.step_sse) {
      best.step_sse = e;
      best.step_px = r;
    }
  }
  best.valid = std::isfinite(best.limb_sse) && std::isfinite(best.step_sse);
  return best;
}

}  // namespace ptmkit::calib::stack_detail
