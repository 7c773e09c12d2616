#include <algorithm>
#include <cmath>
#include <cstdint>
#include <numbers>
#include <vector>

#include <tbb/parallel_for.h>
#include <opencv2/imgproc.hpp>

#include "sphere_stack_detail.h"

namespace ptmkit::calib::stack_detail {

Evidence gather(const Source& src, int max_side) {
  Evidence ev;
  ev.w = src.width();
  ev.h = src.height();
  ev.n = src.count();
  ev.srgb = src.colour_space() == ColourSpace::kSRGB;
  ev.scale = std::max(1, (std::max(ev.w, ev.h) + max_side - 1) / max_side);
  ev.sw = (ev.w + ev.scale - 1) / ev.scale;
  ev.sh = (ev.h + ev.scale - 1) / ev.scale;
  ev.small.assign(static_cast<std::size_t>(ev.n),
                  std::vector<std::uint16_t>(static_cast<std::size_t>(ev.sw) * ev.sh, 0));
  ev.full_max = cv::Mat(ev.h, ev.w, CV_32F, cv::Scalar(0.0f));
  ev.full_mean = cv::Mat(ev.h, ev.w, CV_32F, cv::Scalar(0.0f));
  const float inv_n = 1.0f / static_cast<float>(ev.n);
  // Block sums of each image's luma (scale > 1): 65535 x luma, summed over the block.
  std::vector<std::vector<std::uint32_t>> block_sum;
  if (ev.scale > 1) {
    block_sum.assign(static_cast<std::size_t>(ev.n),
                     std::vector<std::uint32_t>(static_cast<std::size_t>(ev.sw) * ev.sh, 0));
  }
  src.scan([&](const StackBand& band) {
    // The photo-size planes by rows (each pixel's sum over the images in their order), the
    // analysis copies by image (each its own array): no two threads write one value, and any
    // thread count gives the same bits.
    tbb::parallel_for(0, band.rows, [&](int r) {
      const int y = band.y0 + r;
      float* mx = ev.full_max.ptr<float>(y);
      float* mean = ev.full_mean.ptr<float>(y);
      for (int i = 0; i < band.images; ++i) {
        for (int x = 0; x < band.width; ++x) {
          const float v = band_luma(band, i, r, x);
          mx[x] = std::max(mx[x], v);
          mean[x] += v * inv_n;
        }
      }
    });
    tbb::parallel_for(0, band.images, [&](int i) {
      for (int r = 0; r < band.rows; ++r) {
        const int y = band.y0 + r;
        std::uint16_t* small = ev.small[static_cast<std::size_t>(i)].data() +
                               static_cast<std::size_t>(y / ev.scale) * ev.sw;
        std::uint32_t* sum = block_sum.empty() ? nullptr
                                               : block_sum[static_cast<std::size_t>(i)].data() +
                                                     static_cast<std::size_t>(y / ev.scale) * ev.sw;
        for (int x = 0; x < band.width; ++x) {
          const float v = band_luma(band, i, r, x);
          // Rounded to nearest (v is clamped to 0..1, so adding a half truncates correctly).
          const auto q = static_cast<std::uint16_t>(std::clamp(v, 0.0f, 1.0f) * 65535.0f + 0.5f);
          std::uint16_t& sv = small[x / ev.scale];
          sv = std::max(sv, q);
          if (sum != nullptr) sum[x / ev.scale] += q;
        }
      }
    });
  });
  ev.small_max = cv::Mat(ev.sh, ev.sw, CV_32F);
  ev.small_median = cv::Mat(ev.sh, ev.sw, CV_32F);
  ev.small_lower_quartile = cv::Mat(ev.sh, ev.sw, CV_32F);
  tbb::parallel_for(0, ev.sh, [&](int y) {
    std::vector<float> v(static_cast<std::size_t>(ev.n));
    for (int x = 0; x < ev.sw; ++x) {
      for (int i = 0; i < ev.n; ++i) v[static_cast<std::size_t>(i)] = ev.at(i, x, y);
      ev.small_max.at<float>(y, x) = *std::max_element(v.begin(), v.end());
      std::nth_element(v.begin(), v.begin() + ev.n / 2, v.end());
      ev.small_median.at<float>(y, x) = v[static_cast<std::size_t>(ev.n / 2)];
      if (ev.scale == 1) {
        std::nth_element(v.begin(), v.begin() + ev.n / 4, v.begin() + ev.n / 2);
        ev.small_lower_quartile.at<float>(y, x) = v[static_cast<std::size_t>(ev.n / 4)];
      }
    }
  });
  cv::resize(ev.full_mean, ev.small_mean, cv::Size(ev.sw, ev.sh), 0, 0, cv::INTER_AREA);
  if (!block_sum.empty()) {
    ev.small_block_median = cv::Mat(ev.sh, ev.sw, CV_32F);
    tbb::parallel_for(0, ev.sh, [&](int y) {
      // Blocks on the last row and column may be cut by the frame.
      const int bh = std::min(ev.scale, ev.h - y * ev.scale);
      std::vector<float> v(static_cast<std::size_t>(ev.n));
      for (int x = 0; x < ev.sw; ++x) {
        const int bw = std::min(ev.scale, ev.w - x * ev.scale);
        const float per = 1.0f / (65535.0f * static_cast<float>(bw * bh));
        const std::size_t at = static_cast<std::size_t>(y) * ev.sw + static_cast<std::size_t>(x);
        for (int i = 0; i < ev.n; ++i) {
          v[static_cast<std::size_t>(i)] =
              static_cast<float>(block_sum[static_cast<std::size_t>(i)][at]) * per;
        }
        std::nth_element(v.begin(), v.begin() + ev.n / 2, v.end());
        ev.small_block_median.at<float>(y, x) = v[static_cast<std::size_t>(ev.n / 2)];
        std::nth_element(v.begin(), v.begin() + ev.n / 4, v.begin() + ev.n / 2);
        ev.small_lower_quartile.at<float>(y, x) = v[static_cast<std::size_t>(ev.n / 4)];
      }
    });
  }
  return ev;
}

cv::Mat luma_plane(const Image& img) {
  cv::Mat m(img.height(), img.width(), CV_32F);
  for (int y = 0; y < img.height(); ++y) {
    const float* p = img.row(y);
    float* out = m.ptr<float>(y);
    for (int x = 0; x < img.width(); ++x, p += img.channels()) {
      out[x] = img.channels() >= 3 ? static_cast<float>(luma(p[0], p[1], p[2])) : p[0];
    }
  }
  return m;
}

// Contrast-stretched 8-bit copy: log brightness between the 1st and 99.5th percentiles, so a
// black ball's faint rim on a black ground shows as well as a bright one.
cv::Mat stretch(const cv::Mat& f, int type, bool logarithm) {
  cv::Mat lg;
  if (logarithm) {
    cv::log(f + 1.0f / 255.0f, lg);
  } else {
    lg = f;
  }
  std::vector<float> v;
  v.reserve(f.total() / 7 + 1);
  for (int y = 0; y < lg.rows; y += 3) {
    const float* p = lg.ptr<float>(y);
    for (int x = y % 7; x < lg.cols; x += 7) v.push_back(p[x]);
  }
  std::sort(v.begin(), v.end());
  const float lo = v[v.size() / 100], hi = v[std::min(v.size() - 1, v.size() * 995 / 1000)];
  cv::Mat out;
  lg.convertTo(out, type, 255.0 / std::max(1e-3f, hi - lo), -255.0 * lo / std::max(1e-3f, hi - lo));
  if (type == CV_32F) cv::min(cv::max(out, 0.0), 255.0, out);
  return out;
}

// A spot must lift above the stack's median by kSpotNoiseLifts times the noise of the image
// over the disc, estimated from the steps of (image - median) between horizontal neighbours
// (median absolute step / sqrt 2, as a Gaussian sigma): what the light changes in the scene
// mirrored by the sphere is smooth over a pixel except at its edges, noise is not. (The
// spread of (image - median) itself is not noise: on a black ball at three times the
// presets' exposure the lit ground it mirrors changes with every light, and six times that
// spread left 2-8 of 22 lights without a spot.) Without the threshold a noisy dark room (a
// sensor's read noise of 6 grey levels: 0.056 in sRGB values on a black ball) lifts some
// pixel of any small disc by 0.2-0.28 in every image, and a 16 px circle that Hough drew in
// the noise had a moving spot at its own place in each: the track of a sphere. Six sigma is
// above the largest of a disc's noise samples (the largest of 10^5 Gaussian samples lies
// near 4.4 sigma) and far below a light's reflection.
constexpr double kSpotNoiseLifts = 6.0;

// The spots of image i in a disc (analysis pixels) brighter than the median by more than
// max(0.05, half the brightest lift in the disc, kSpotNoiseLifts times its noise), and at
// least min_peak bright.
std::vector<Spot> moving_spots(const Evidence& ev, int i, const Eigen::Vector2d& c, double r,
                               double min_peak) {
  const int x0 = std::max(0, static_cast<int>(std::floor(c.x() - r)));
  const int y0 = std::max(0, static_cast<int>(std::floor(c.y() - r)));
  const int x1 = std::min(ev.sw - 1, static_cast<int>(std::ceil(c.x() + r)));
  const int y1 = std::min(ev.sh - 1, static_cast<int>(std::ceil(c.y() + r)));
  if (x1 < x0 || y1 < y0) return {};
  cv::Mat lift(y1 - y0 + 1, x1 - x0 + 1, CV_32F, cv::Scalar(0.0f));
  float best = 0.0f;
  // |step of (image - median)| between horizontal neighbours inside the disc: the noise, as
  // the scene's own changes with the light are smooth over a pixel but at their edges.
  std::vector<float> steps;
  for (int y = y0; y <= y1; ++y) {
    float prev = 0.0f;
    bool have_prev = false;
    for (int x = x0; x <= x1; ++x) {
      if ((Eigen::Vector2d(x, y) - c).squaredNorm() > r * r) {
        have_prev = false;
        continue;
      }
      const float v = ev.at(i, x, y);
      const float d = v - ev.small_median.at<float>(y, x);
      if (have_prev) steps.push_back(std::abs(d - prev));
      prev = d;
      have_prev = true;
      if (v < min_peak) continue;
      lift.at<float>(y - y0, x - x0) = d;
      best = std::max(best, d);
    }
  }
  float noise = 0.0f;
  if (!steps.empty()) {
    auto mid = steps.begin() + static_cast<std::ptrdiff_t>(steps.size() / 2);
    std::nth_element(steps.begin(), mid, steps.end());
    noise = 1.4826f * *mid / std::numbers::sqrt2_v<float>;
  }
  const float thr = std::max({0.05f, 0.5f * best, static_cast<float>(kSpotNoiseLifts) * noise});
  if (best <= thr) return {};
  cv::Mat mask = lift > thr;
  cv::Mat labels, stats, centroids;
  const int k = cv::connectedComponentsWithStats(mask, labels, stats, centroids, 8, CV_32S);
  std::vector<Spot> spots(static_cast<std::size_t>(std::max(0, k - 1)));
  std::vector<double> sw(spots.size(), 0.0), sx(spots.size(), 0.0), sy(spots.size(), 0.0);
  for (int y = 0; y < labels.rows; ++y) {
    for (int x = 0; x < labels.cols; ++x) {
      const int l = labels.at<int>(y, x);
      if (l == 0) continue;
      Spot& s = spots[static_cast<std::size_t>(l - 1)];
      const double d = lift.at<float>(y, x);
      const double wgt = d - thr + 1e-6;
      sw[static_cast<std::size_t>(l - 1)] += wgt;
      sx[static_cast<std::size_t>(l - 1)] += wgt * (x + x0);
      sy[static_cast<std::size_t>(l - 1)] += wgt * (y + y0);
      s.lift = std::max(s.lift, d);
      const double v = ev.at(i, x + x0, y + y0);
      const double m = ev.small_median.at<float>(y + y0, x + x0);
      s.lift_linear = std::max(s.lift_linear, to_linear(v, ev.srgb) - to_linear(m, ev.srgb));
      s.peak = std::max(s.peak, static_cast<double>(ev.at(i, x + x0, y + y0)));
    }
  }
  for (int l = 1; l < k; ++l) {
    Spot& s = spots[static_cast<std::size_t>(l - 1)];
    s.centre_small = {sx[static_cast<std::size_t>(l - 1)] / sw[static_cast<std::size_t>(l - 1)],
                      sy[static_cast<std::size_t>(l - 1)] / sw[static_cast<std::size_t>(l - 1)]};
    s.area = stats.at<int>(l, cv::CC_STAT_AREA);
    s.box =
        cv::Rect(stats.at<int>(l, cv::CC_STAT_LEFT) + x0, stats.at<int>(l, cv::CC_STAT_TOP) + y0,
                 stats.at<int>(l, cv::CC_STAT_WIDTH), stats.at<int>(l, cv::CC_STAT_HEIGHT));
  }
  // Brightest first (a saturated spot: the larger first); ties by position, so the order is
  // the same on every run.
  std::sort(spots.begin(), spots.end(), [](const Spot& a, const Spot& b) {
    const double pa = std::min(a.peak, 0.995), pb = std::min(b.peak, 0.995);
    if (pa != pb) return pa > pb;
    if (a.area != b.area) return a.area > b.area;
    return a.centre_small.y() != b.centre_small.y() ? a.centre_small.y() < b.centre_small.y()
                                                    : a.centre_small.x() < b.centre_small.x();
  });
  return spots;
}

}  // namespace ptmkit::calib::stack_detail
