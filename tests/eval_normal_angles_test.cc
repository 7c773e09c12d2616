// Normal-map error gathered band by band in fixed memory (eval/truth.h NormalAngles): the
// mean exact, the median within a histogram bin of the exact median, the same whatever the
// banding, masks and zero normals skipped.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <random>
#include <vector>

#include "ptmkit/core/image.h"
#include "ptmkit/eval/truth.h"

namespace ptmkit::eval {
namespace {

// Normals tilted from +z by angles spread over 0..60 degrees, at random azimuths.
Image tilted(int w, int h, std::vector<double>* angles_deg, unsigned seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> tilt(0.0, 60.0), azimuth(0.0, 2.0 * M_PI);
  Image img(w, h, 3);
  for (int y = 0; y < h; ++y) {
    for (int x = 0; x < w; ++x) {
      const double t = tilt(rng) * M_PI / 180.0, a = azimuth(rng);
      img.at(x, y, 0) = static_cast<float>(std::sin(t) * std::cos(a));
      img.at(x, y, 1) = static_cast<float>(std::sin(t) * std::sin(a));
      img.at(x, y, 2) = static_cast<float>(std::cos(t));
    }
  }
  // The angles as the accumulator computes them (from the float normals), in texel order.
  for (int y = 0; y < h; ++y) {
    for (int x = 0; x < w; ++x) {
      const double z = img.at(x, y, 2);
      const double n = std::sqrt(img.at(x, y, 0) * double(img.at(x, y, 0)) +
                                 img.at(x, y, 1) * double(img.at(x, y, 1)) + z * z);
      angles_deg->push_back(std::acos(std::clamp(z / n, -1.0, 1.0)) * 180.0 / M_PI);
    }
  }
  return img;
}

Image rows_of(const Image& img, int y0, int rows) {
  Image out(img.width(), rows, img.channels());
  for (int y = 0; y < rows; ++y) {
    for (int x = 0; x < img.width(); ++x) {
      for (int c = 0; c < img.channels(); ++c) out.at(x, y, c) = img.at(x, y0 + y, c);
    }
  }
  return out;
}

TEST(NormalAngles, MeanExactMedianWithinABinWhateverTheBanding) {
  const int w = 37, h = 29;
  std::vector<double> angles;
  const Image est = tilted(w, h, &angles, 7);
  Image up(w, h, 3);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) up.at(x, y, 2) = 1.0f;

  const NormalError whole = normal_error(est, up);
  double sum = 0.0;
  for (double a : angles) sum += a;
  std::vector<double> sorted = angles;
  std::nth_element(sorted.begin(), sorted.begin() + static_cast<std::ptrdiff_t>(sorted.size() / 2),
                   sorted.end());
  const double exact_median = sorted[sorted.size() / 2];
  EXPECT_EQ(whole.texels, angles.size());
  EXPECT_NEAR(whole.mean_deg, sum / static_cast<double>(angles.size()), 1e-9);
  EXPECT_LE(std::abs(whole.median_deg - exact_median), NormalAngles::kBinDeg);

  // Bands of 5 rows (the last shorter) give the same figures, bit for bit.
  NormalAngles banded;
  for (int y0 = 0; y0 < h; y0 += 5) {
    const int rows = std::min(5, h - y0);
    banded.add(rows_of(est, y0, rows), rows_of(up, y0, rows), nullptr);
  }
  const NormalError b = banded.result();
  EXPECT_EQ(b.texels, whole.texels);
  EXPECT_EQ(b.mean_deg, whole.mean_deg);
  EXPECT_EQ(b.median_deg, whole.median_deg);

  // A mask, and a zero normal, leave texels out.
  Image mask(w, h, 1);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) mask.at(x, y, 0) = x < 10 ? 1.0f : 0.0f;
  Image holes = est;
  for (int c = 0; c < 3; ++c) holes.at(0, 0, c) = 0.0f;
  EXPECT_EQ(normal_error(holes, up, &mask).texels, static_cast<std::uint64_t>(10 * h - 1));
}

}  // namespace
}  // namespace ptmkit::eval
