#include "ptmkit/eval/ssim.h"

#include <cmath>
#include <cstddef>

namespace ptmkit::eval {

namespace {

// Separable Gaussian blur (sigma 1.5, radius 5) with weights renormalised at the border.
std::vector<double> blur(const std::vector<double>& in, int w, int h) {
  constexpr int kRadius = 5;
  constexpr double kSigma = 1.5;
  double k[2 * kRadius + 1];
  for (int i = -kRadius; i <= kRadius; ++i)
    k[i + kRadius] = std::exp(-0.5 * i * i / (kSigma * kSigma));
  std::vector<double> tmp(in.size()), out(in.size());
  for (int y = 0; y < h; ++y) {
    for (int x = 0; x < w; ++x) {
      double s = 0.0, ws = 0.0;
      for (int d = -kRadius; d <= kRadius; ++d) {
        const int xx = x + d;
        if (xx < 0 || xx >= w) continue;
        s += k[d + kRadius] * in[static_cast<std::size_t>(y) * w + xx];
        ws += k[d + kRadius];
      }
      tmp[static_cast<std::size_t>(y) * w + x] = s / ws;
    }
  }
  for (int y = 0; y < h; ++y) {
    for (int x = 0; x < w; ++x) {
      double s = 0.0, ws = 0.0;
      for (int d = -kRadius; d <= kRadius; ++d) {
        const int yy = y + d;
        if (yy < 0 || yy >= h) continue;
        s += k[d + kRadius] * tmp[static_cast<std::size_t>(yy) * w + x];
        ws += k[d + kRadius];
      }
      out[static_cast<std::size_t>(y) * w + x] = s / ws;
    }
  }
  return out;
}

}  // namespace

double mean_ssim(const std::vector<double>& a, const std::vector<double>& b, int w, int h) {
  return a.empty() ? 0.0 : ssim_sum(a, b, w, h, 0, h) / static_cast<double>(a.size());
}

double ssim_sum(const std::vector<double>& a, const std::vector<double>& b, int w, int h,
                int first_row, int last_row) {
  constexpr double kC1 = 0.01 * 0.01;
  constexpr double kC2 = 0.03 * 0.03;
  std::vector<double> aa(a.size()), bb(a.size()), ab(a.size());
  for (std::size_t i = 0; i < a.size(); ++i) {
    aa[i] = a[i] * a[i];
    bb[i] = b[i] * b[i];
    ab[i] = a[i] * b[i];
  }
  const auto ma = blur(a, w, h), mb = blur(b, w, h);
  const auto saa = blur(aa, w, h), sbb = blur(bb, w, h), sab = blur(ab, w, h);
  double sum = 0.0;
  const std::size_t end = static_cast<std::size_t>(last_row) * static_cast<std::size_t>(w);
  for (std::size_t i = static_cast<std::size_t>(first_row) * static_cast<std::size_t>(w); i < end;
       ++i) {
    const double va = saa[i] - ma[i] * ma[i];
    const double vb = sbb[i] - mb[i] * mb[i];
    const double cov = sab[i] - ma[i] * mb[i];
    sum += ((2 * ma[i] * mb[i] + kC1) * (2 * cov + kC2)) /
           ((ma[i] * ma[i] + mb[i] * mb[i] + kC1) * (va + vb + kC2));
  }
  return sum;
}

}  // namespace ptmkit::eval
