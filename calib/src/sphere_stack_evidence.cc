#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>
#include <numbers>
#include <vector>

#include <tbb/parallel_for.h>
#include <Eigen/Dense>
#include <opencv2/imgproc.hpp>

#include "sphere_stack_detail.h"

namespace ptmkit::calib::stack_detail {

namespace {

// The share of the median's pixels, its steepest edges, that the shifts are measured on.
constexpr double kShiftEdgeShare = 0.02;
// Evidence::small_spread's floor in linear light (about 25 grey levels of sRGB): below it the
// sensor's noise and the JPEG's would pass for change.
constexpr double kSpreadFloor = 0.01;
// The quartiles of Evidence::small_spread among n sorted values.
std::ptrdiff_t spread_low(int n) { return n / 4; }
std::ptrdiff_t spread_high(int n) { return 3 * (n - 1) / 4; }
double spread_of(double hi, double lo) { return (hi - lo) / (hi + lo + kSpreadFloor); }

// The spread of one analysis pixel over the images with each image's value divided by its gain
// (`v`: scratch of ev.n values).
double spread_without_gains(const Evidence& ev, int x, int y, const std::vector<double>& gains,
                            std::vector<double>* v) {
  const std::ptrdiff_t q1 = spread_low(ev.n), q3 = spread_high(ev.n);
  for (int i = 0; i < ev.n; ++i) {
    (*v)[static_cast<std::size_t>(i)] = ev.linear_at(i, x, y) / gains[static_cast<std::size_t>(i)];
  }
  std::nth_element(v->begin(), v->begin() + q3, v->end());
  const double hi = (*v)[static_cast<std::size_t>(q3)];
  std::nth_element(v->begin(), v->begin() + q1, v->begin() + q3);
  return spread_of(hi, (*v)[static_cast<std::size_t>(q1)]);
}
constexpr int kShiftIterations = 10;

struct CameraShifts {
  std::vector<Eigen::Vector2d> shifts;  // per image, analysis pixels
  // Per image: how far apart the shifts measured on the frame's left and right halves alone
  // are (analysis pixels; 0 where a half has too few edges).
  std::vector<double> halves_apart;
};

// Each image's shift against the stack's median (analysis pixels), by Gauss-Newton on the
// median's strongest edges (the kShiftEdgeShare of its pixels with the steepest gradient):
// image(p) = a median(p - d) (a: the image's exposure against the stack's), each step
// weighted by Tukey's biweight of the residual at twice
// its robust scale, so what the light changes (a highlight, a shading edge) weighs little
// against the edges that stay (the spheres' rims, the windows they mirror, the bases). The
// same on each half of the frame gives CameraShifts::halves_apart.
CameraShifts camera_shifts(const Evidence& ev) {
  CameraShifts cs;
  std::vector<Eigen::Vector2d>& out = cs.shifts;
  out.assign(static_cast<std::size_t>(ev.n), Eigen::Vector2d::Zero());
  cs.halves_apart.assign(static_cast<std::size_t>(ev.n), 0.0);
  const cv::Mat& m = ev.small_median;
  if (m.cols < 8 || m.rows < 8 || ev.n < 3) return cs;
  cv::Mat gx, gy, mag;
  cv::Sobel(m, gx, CV_32F, 1, 0, 3, 1.0 / 8.0);
  cv::Sobel(m, gy, CV_32F, 0, 1, 3, 1.0 / 8.0);
  cv::magnitude(gx, gy, mag);
  std::vector<float> sorted;
  for (int y = 2; y < m.rows - 2; ++y) {
    for (int x = 2; x < m.cols - 2; ++x) sorted.push_back(mag.at<float>(y, x));
  }
  const float thr =
      std::max(kth_smallest(sorted, static_cast<std::size_t>((1.0 - kShiftEdgeShare) *
                                                             static_cast<double>(sorted.size()))),
               1e-4f);
  std::vector<cv::Point> pts;
  for (int y = 2; y < m.rows - 2; ++y) {
    for (int x = 2; x < m.cols - 2; ++x) {
      if (mag.at<float>(y, x) >= thr) pts.emplace_back(x, y);
    }
  }
  if (pts.size() < 50) return cs;
  // Bilinear sample of a plane at (x, y), inside the frame by construction (|d| is capped).
  auto sample = [](const cv::Mat& f, double x, double y) {
    const int x0 = static_cast<int>(std::floor(x)), y0 = static_cast<int>(std::floor(y));
    const double fx = x - x0, fy = y - y0;
    const float* r0 = f.ptr<float>(y0);
    const float* r1 = f.ptr<float>(y0 + 1);
    return (1 - fy) * ((1 - fx) * r0[x0] + fx * r0[x0 + 1]) +
           fy * ((1 - fx) * r1[x0] + fx * r1[x0 + 1]);
  };
  auto estimate = [&](int i, const std::vector<cv::Point>& use) {
    // The image's exposure may differ from the stack's: image(p) = a median(p - d), a free.
    Eigen::Vector2d d = Eigen::Vector2d::Zero();
    double a = 1.0;
    std::vector<double> res(use.size()), absr(use.size());
    for (int it = 0; it < kShiftIterations; ++it) {
      for (std::size_t j = 0; j < use.size(); ++j) {
        res[j] = ev.at(i, use[j].x, use[j].y) - a * sample(m, use[j].x - d.x(), use[j].y - d.y());
        absr[j] = std::abs(res[j]);
      }
      const double c = 2.0 * std::max(1e-3, 1.4826 * upper_median(absr));
      Eigen::Matrix3d h = Eigen::Matrix3d::Zero();
      Eigen::Vector3d b = Eigen::Vector3d::Zero();
      for (std::size_t j = 0; j < use.size(); ++j) {
        const double u = res[j] / c;
        if (std::abs(u) >= 1.0) continue;
        const double w = (1.0 - u * u) * (1.0 - u * u);
        const double px = use[j].x - d.x(), py = use[j].y - d.y();
        // d res / d (dx, dy, a).
        const Eigen::Vector3d g(a * sample(gx, px, py), a * sample(gy, px, py), -sample(m, px, py));
        h += w * g * g.transpose();
        b += w * g * res[j];
      }
      if (std::abs(h.determinant()) < 1e-15) break;
      const Eigen::Vector3d step = -h.ldlt().solve(b);
      d += step.head<2>();
      a = std::clamp(a + step.z(), 1.0 / 16.0, 16.0);
      // A shift beyond a pixel and a half is no camera shake the analysis copy can follow.
      if (d.norm() > 1.5) d *= 1.5 / d.norm();
      if (step.head<2>().norm() < 1e-3 && std::abs(step.z()) < 1e-4) break;
    }
    return d;
  };
  std::vector<cv::Point> left, right;
  for (const cv::Point& p : pts) (p.x < m.cols / 2 ? left : right).push_back(p);
  tbb::parallel_for(0, ev.n, [&](int i) {
    const auto k = static_cast<std::size_t>(i);
    out[k] = estimate(i, pts);
    if (left.size() >= 50 && right.size() >= 50) {
      cs.halves_apart[k] = (estimate(i, left) - estimate(i, right)).norm();
    }
  });
  return cs;
}

}  // namespace

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
  ev.linear_of_code.resize(65536);
  for (std::size_t q = 0; q < ev.linear_of_code.size(); ++q) {
    ev.linear_of_code[q] = to_linear(static_cast<float>(q) / 65535.0f, ev.srgb);
  }
  ev.small_max = cv::Mat(ev.sh, ev.sw, CV_32F);
  ev.small_median = cv::Mat(ev.sh, ev.sw, CV_32F);
  ev.small_lower_quartile = cv::Mat(ev.sh, ev.sw, CV_32F);
  ev.small_spread = cv::Mat(ev.sh, ev.sw, CV_32F);
  tbb::parallel_for(0, ev.sh, [&](int y) {
    std::vector<float> v(static_cast<std::size_t>(ev.n));
    // After the median's partition the quartiles lie in its halves.
    const std::ptrdiff_t mid = ev.n / 2, q1 = spread_low(ev.n), q3 = spread_high(ev.n);
    for (int x = 0; x < ev.sw; ++x) {
      for (int i = 0; i < ev.n; ++i) v[static_cast<std::size_t>(i)] = ev.at(i, x, y);
      ev.small_max.at<float>(y, x) = *std::max_element(v.begin(), v.end());
      std::nth_element(v.begin(), v.begin() + mid, v.end());
      ev.small_median.at<float>(y, x) = v[static_cast<std::size_t>(mid)];
      if (q3 > mid) {
        std::nth_element(v.begin() + mid + 1, v.begin() + q3, v.end());
      } else if (q3 < mid) {
        std::nth_element(v.begin(), v.begin() + q3, v.begin() + mid);
      }
      const double hi = to_linear(v[static_cast<std::size_t>(q3)], ev.srgb);
      if (q1 < mid) std::nth_element(v.begin(), v.begin() + q1, v.begin() + mid);
      const float lower = v[static_cast<std::size_t>(q1)];
      const double lo = to_linear(lower, ev.srgb);
      ev.small_spread.at<float>(y, x) = static_cast<float>(spread_of(hi, lo));
      if (ev.scale == 1) ev.small_lower_quartile.at<float>(y, x) = lower;
    }
  });
  CameraShifts cs = camera_shifts(ev);
  ev.shifts_px = std::move(cs.shifts);
  std::vector<double> moved;
  for (const Eigen::Vector2d& d : ev.shifts_px) moved.push_back(d.norm());
  if (!moved.empty()) {
    const double typical = upper_median(moved);
    ev.shift_halves_apart_px = upper_median(cs.halves_apart) * ev.scale;
    // A camera that moved moves the whole frame alike; what the lights change does not.
    ev.camera_moved = typical > kCameraMovedPx && ev.shift_halves_apart_px <= typical * ev.scale;
    ev.undo_shifts = ev.camera_moved && typical > kShiftUndoPx;
  }
  if (ev.camera_moved) {
    cv::dilate(ev.small_median, ev.small_median_max3, cv::Mat());
  } else {
    ev.small_median_max3 = ev.small_median;
  }
  for (Eigen::Vector2d& d : ev.shifts_px) d *= ev.scale;
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
                               double min_peak, double gain) {
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
      const float d = v - scaled_median(ev.small_median.at<float>(y, x), gain, ev.srgb);
      if (have_prev) steps.push_back(std::abs(d - prev));
      prev = d;
      have_prev = true;
      if (v < min_peak) continue;
      const float lifted = v - scaled_median(ev.small_median_max3.at<float>(y, x), gain, ev.srgb);
      lift.at<float>(y - y0, x - x0) = lifted;
      best = std::max(best, lifted);
    }
  }
  float noise = 0.0f;
  if (!steps.empty()) {
    noise = 1.4826f * upper_median(steps) / std::numbers::sqrt2_v<float>;
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
      s.lift = std::max(s.lift, d);
      const double v = ev.at(i, x + x0, y + y0);
      const double m = scaled_median(ev.small_median_max3.at<float>(y + y0, x + x0), gain, ev.srgb);
      const double d_linear = to_linear(v, ev.srgb) - to_linear(m, ev.srgb);
      s.lift_linear = std::max(s.lift_linear, d_linear);
      // Weighted by the light added, in linear light: the encoded lift is largest where the
      // room is dark, and a highlight's bloom over a mirror's dark limb outweighed its clipped
      // core on the bright room mirrored beside it (5 px toward the limb on a 42 px ball).
      const double wgt = std::max(d_linear, 0.0) + 1e-6;
      sw[static_cast<std::size_t>(l - 1)] += wgt;
      sx[static_cast<std::size_t>(l - 1)] += wgt * (x + x0);
      sy[static_cast<std::size_t>(l - 1)] += wgt * (y + y0);
      s.peak = std::max(s.peak, v);
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

// A median this bright (linear) and no brighter counts toward the gain: well above the dark
// room and its noise, and unclipped in most images whatever their exposure.
constexpr double kGainMinLinear = 0.1;
constexpr double kGainMaxLinear = 0.8;
// Where too few such pixels follow one gain per image, from this bright: a chrome ball in a lit
// room mirrors the lamps and windows clipped and the room's walls darker (lit chrome at +-1 EV,
// seeds 3 and 5: 14 and 0-4 such pixels from 0.1, 52 from this on seed 3). Not from the first:
// in a dark room the lit cloth a black ball mirrors changes with each light coherently enough
// to pass for the exposure.
constexpr double kGainDimMinLinear = 0.02;
// ... and there the exposure counts as varying only where the gains' median |ln gain| exceeds
// this (10%): from 0.02 the mirrored cloth of a steady black ball in a dark room gave 5.7%
// (photo-dome seed 2, gains 0.89-1.38); an exposure varying by up to 1 EV gives about 35%.
constexpr double kDimExposureVaries = 0.1;
// Fewest such pixels over the discs for a gain to be measured, and the most taken.
constexpr int kGainMinPixels = 20;
// How many times the pixels that follow the gains are chosen again, from the gains measured
// on those chosen before.
constexpr int kGainReselections = 2;
// The fewest pixels where the gains are chosen again (disc_gains).
constexpr int kGainReselectMinPixels = 10;
constexpr std::size_t kGainMaxPixels = 20000;
// A pixel follows the first gains where its ratio lies within this share of an image's gain
// in at least kGainSteadyShare of the images (the light's own reflection and its glow pass
// over a few of them).
constexpr double kGainFollow = 0.15;
constexpr double kGainSteadyShare = 0.8;

namespace {

// exposure_gains from the pixels whose median lies in [min_linear, kGainMaxLinear]; nullopt
// where fewer than `min_pixels` follow one gain per image. `reselections`: how many times the
// pixels that follow are chosen again.
std::optional<std::vector<double>> gains_from(const Evidence& ev,
                                              const std::vector<Eigen::Vector2d>& c,
                                              const std::vector<double>& r, double min_linear,
                                              int min_pixels, int reselections) {
  std::vector<double> gains(static_cast<std::size_t>(ev.n), 1.0);
  // The pixels, once: median in the band, inside a disc.
  std::vector<cv::Point> px;
  std::vector<double> m_lin;
  for (std::size_t k = 0; k < c.size(); ++k) {
    const int x0 = std::max(0, static_cast<int>(std::floor(c[k].x() - r[k])));
    const int y0 = std::max(0, static_cast<int>(std::floor(c[k].y() - r[k])));
    const int x1 = std::min(ev.sw - 1, static_cast<int>(std::ceil(c[k].x() + r[k])));
    const int y1 = std::min(ev.sh - 1, static_cast<int>(std::ceil(c[k].y() + r[k])));
    for (int y = y0; y <= y1; ++y) {
      for (int x = x0; x <= x1; ++x) {
        if ((Eigen::Vector2d(x, y) - c[k]).squaredNorm() > r[k] * r[k]) continue;
        const double m = to_linear(ev.small_median.at<float>(y, x), ev.srgb);
        if (m < min_linear || m > kGainMaxLinear) continue;
        px.emplace_back(x, y);
        m_lin.push_back(m);
      }
    }
  }
  if (static_cast<int>(px.size()) < min_pixels) return std::nullopt;
  // A sphere filling a lit frame has hundreds of thousands: every k-th is as good a sample and
  // keeps the ratios below (one per pixel and image) small.
  if (px.size() > kGainMaxPixels) {
    const std::size_t step = (px.size() + kGainMaxPixels - 1) / kGainMaxPixels;
    std::size_t kept = 0;
    for (std::size_t j = 0; j < px.size(); j += step, ++kept) {
      px[kept] = px[j];
      m_lin[kept] = m_lin[j];
    }
    px.resize(kept);
    m_lin.resize(kept);
  }
  // Each pixel's ratio image / median per image; a clipped sample says only that the ratio is
  // at least its own, and ranks above every unclipped one (which a median needs and no more).
  const std::size_t np = px.size(), ni = static_cast<std::size_t>(ev.n);
  std::vector<double> ratio(np * ni);
  tbb::parallel_for(std::size_t{0}, ni, [&](std::size_t i) {
    for (std::size_t j = 0; j < np; ++j) {
      const double v = ev.at(static_cast<int>(i), px[j].x, px[j].y);
      ratio[i * np + j] = v >= kSpotClip
                              ? std::numeric_limits<double>::infinity()
                              : ev.linear_at(static_cast<int>(i), px[j].x, px[j].y) / m_lin[j];
    }
  });
  auto median_of = [](std::vector<double> v) { return upper_median(v); };
  // First, over every such pixel; then over the pixels that follow those gains in most
  // images: what the room shows. A glass ball's refracted glow is bright in the median too,
  // but it comes and goes with the lights (under a light near the camera's axis it covers
  // half the ball, clipped), and taken with the rest it made such an image's gain 16.
  std::vector<double> first(ni, 1.0);
  for (std::size_t i = 0; i < ni; ++i) {
    first[i] = median_of({ratio.begin() + static_cast<std::ptrdiff_t>(i * np),
                          ratio.begin() + static_cast<std::ptrdiff_t>((i + 1) * np)});
  }
  std::vector<std::size_t> steady;
  auto select_steady = [&](const std::vector<double>& g) {
    steady.clear();
    for (std::size_t j = 0; j < np; ++j) {
      std::size_t follow = 0;
      for (std::size_t i = 0; i < ni; ++i) {
        if (std::isfinite(g[i]) && std::abs(ratio[i * np + j] - g[i]) <= kGainFollow * g[i]) {
          ++follow;
        }
      }
      if (static_cast<double>(follow) >= kGainSteadyShare * static_cast<double>(ni)) {
        steady.push_back(j);
      }
    }
  };
  select_steady(first);
  // The first gains lean toward what the capture's light changes where that is most of the
  // discs (a chrome ball in a lit room mirrors the lit cloth and cup over most of its disc):
  // measured again on the pixels that follow them, and the pixels that follow those taken,
  // the room's share grows (lit chrome at +-1 EV: 14 such pixels of 2217, then 52).
  for (int it = 0; it < reselections && static_cast<int>(steady.size()) >= min_pixels; ++it) {
    std::vector<double> again(ni, 1.0);
    for (std::size_t i = 0; i < ni; ++i) {
      std::vector<double> v;
      v.reserve(steady.size());
      for (std::size_t j : steady) v.push_back(ratio[i * np + j]);
      again[i] = median_of(std::move(v));
    }
    select_steady(again);
  }
  if (static_cast<int>(steady.size()) < min_pixels) return std::nullopt;
  // The median of their ratios, where they agree: the lower quartile within half kGainFollow
  // of it (the upper half may clip in a brighter image). Where the image's light lifts many
  // of them (a glass ball glowing whole under a light by the camera's axis: the ratios
  // spread, or more than half clip) the image gives no measure and keeps 1. (Their lower
  // quartile taken there instead was lifted itself where most were: a chrome sphere's image
  // at 0.96 times the stack's exposure measured 1.53.) But over what a sphere mirrors light
  // only adds, so that quartile bounds the gain from above: where the other images show an
  // exposure that varies and it lies below 1, the gain is taken at the bound, the value
  // nearest 1 that it allows (one lit chrome ball at +-1 EV, seed 4: three images at
  // 0.53-0.75 times the render's exposure were kept at 1, 1.6-2.3 times their gain, and
  // measure from 4% over to 14% under it; the lights 1.26 to 0.96 degrees off on average).
  // Where the exposure is steady the bound is not taken: over a region that is no mirror
  // (a candidate around the object) the light also darkens, and the bounds made a steady
  // capture's exposure vary (glass marbles hidden by their glow: 0.25-1.09).
  std::vector<double> bound(ni, std::numeric_limits<double>::infinity());
  for (std::size_t i = 0; i < ni; ++i) {
    std::vector<double> v;
    v.reserve(steady.size());
    for (std::size_t j : steady) v.push_back(ratio[i * np + j]);
    std::sort(v.begin(), v.end());
    const double q1 = v[v.size() / 4], mid = v[v.size() / 2];
    if (std::isfinite(mid) && mid - q1 <= 0.5 * kGainFollow * mid) {
      gains[i] = std::clamp(mid, 1.0 / 16.0, 16.0);
    } else if (q1 < 1.0) {
      bound[i] = std::max(q1, 1.0 / 16.0);
    }
  }
  if (exposure_varies(gains)) {
    for (std::size_t i = 0; i < ni; ++i) gains[i] = std::min(gains[i], bound[i]);
  }
  return gains;
}

}  // namespace

std::vector<double> exposure_gains(const Evidence& ev, const std::vector<Eigen::Vector2d>& c,
                                   const std::vector<double>& r) {
  if (auto g = gains_from(ev, c, r, kGainMinLinear, kGainMinPixels, 0)) return *g;
  return std::vector<double>(static_cast<std::size_t>(ev.n), 1.0);
}

namespace {

// exposure_gains where they decide how a disc is searched: the pixels chosen again, from fewer
// (kGainReselectMinPixels), and where too few follow, from the dim ones too.
std::vector<double> thorough_gains(const Evidence& ev, const Eigen::Vector2d& c, double r) {
  if (auto g =
          gains_from(ev, {c}, {r}, kGainMinLinear, kGainReselectMinPixels, kGainReselections)) {
    return *g;
  }
  std::vector<double> steady(static_cast<std::size_t>(ev.n), 1.0);
  const std::optional<std::vector<double>> dim =
      gains_from(ev, {c}, {r}, kGainDimMinLinear, kGainReselectMinPixels, kGainReselections);
  if (!dim) return steady;
  // The dim pixels vary by more than kDimExposureVaries with an exposure that varies.
  std::vector<double> off;
  for (double g : *dim) off.push_back(std::abs(std::log(g)));
  return upper_median(off) > kDimExposureVaries ? *dim : steady;
}

}  // namespace

cv::Mat spread_in_box(const Evidence& ev, const cv::Rect& box, const std::vector<double>& gains) {
  cv::Mat out(box.height, box.width, CV_32F);
  tbb::parallel_for(0, box.height, [&](int r) {
    std::vector<double> v(static_cast<std::size_t>(ev.n));
    for (int x = 0; x < box.width; ++x) {
      out.at<float>(r, x) =
          static_cast<float>(spread_without_gains(ev, box.x + x, box.y + r, gains, &v));
    }
  });
  return out;
}

std::vector<double> disc_gains(const Evidence& ev, const Eigen::Vector2d& c, double r) {
  std::vector<double> gains = thorough_gains(ev, c, r);
  const std::vector<double> steady(gains.size(), 1.0);
  if (!exposure_varies(gains)) return steady;
  // The spread inside the disc, as the stack shows it and with the gains taken out, on every
  // k-th pixel (at most about 2000).
  const int x0 = std::max(0, static_cast<int>(std::floor(c.x() - r)));
  const int y0 = std::max(0, static_cast<int>(std::floor(c.y() - r)));
  const int x1 = std::min(ev.sw - 1, static_cast<int>(std::ceil(c.x() + r)));
  const int y1 = std::min(ev.sh - 1, static_cast<int>(std::ceil(c.y() + r)));
  const double area = std::numbers::pi * r * r;
  const int step = std::max(1, static_cast<int>(std::sqrt(area / 2000.0)));
  std::vector<double> raw, taken_out, v(static_cast<std::size_t>(ev.n));
  for (int y = y0; y <= y1; y += step) {
    for (int x = x0; x <= x1; x += step) {
      if ((Eigen::Vector2d(x, y) - c).squaredNorm() > r * r) continue;
      raw.push_back(ev.small_spread.at<float>(y, x));
      taken_out.push_back(spread_without_gains(ev, x, y, gains, &v));
    }
  }
  if (raw.empty()) return steady;
  // The stillest quarter: what the disc mirrors of the room.
  const auto quarter = [](std::vector<double>& a) {
    std::nth_element(a.begin(), a.begin() + static_cast<std::ptrdiff_t>(a.size() / 4), a.end());
    return a[a.size() / 4];
  };
  return quarter(taken_out) < kGainsStillerShare * quarter(raw) ? gains : steady;
}

bool exposure_varies(const std::vector<double>& gains) {
  std::vector<double> off;
  for (double g : gains) off.push_back(std::abs(std::log(g)));
  return !off.empty() && upper_median(off) > kExposureVaries;
}

std::optional<double> reflection_spot_area(const std::vector<std::vector<Spot>>& spots_of) {
  std::vector<double> areas;
  for (const std::vector<Spot>& spots : spots_of) {
    for (const Spot& sp : spots) {
      if (sp.peak >= kSpotClip) areas.push_back(sp.area);
    }
  }
  std::sort(areas.begin(), areas.end());
  int best_images = 0;
  double best_area = 0.0;
  for (double a : areas) {
    int images = 0;
    for (const std::vector<Spot>& spots : spots_of) {
      images += std::any_of(spots.begin(), spots.end(),
                            [&](const Spot& sp) {
                              return sp.peak >= kSpotClip && sp.area <= kReflectionAreaSpread * a &&
                                     sp.area * kReflectionAreaSpread >= a;
                            })
                    ? 1
                    : 0;
    }
    if (images > best_images) {
      best_images = images;
      best_area = a;
    }
  }
  if (best_images < kReflectionAreaImages) return std::nullopt;
  return best_area;
}

bool not_a_reflection(const Spot& sp, double reflection_area) {
  return sp.peak < kSpotClip || sp.area > kGlowAreaRatio * reflection_area ||
         sp.area * kFragmentAreaRatio < reflection_area;
}

int across_spot_images(const std::vector<std::vector<Spot>>& spots_of, const Eigen::Vector2d& c) {
  int across = 0;
  for (const std::vector<Spot>& spots : spots_of) across += spots_across(spots, c) ? 1 : 0;
  return across;
}

}  // namespace ptmkit::calib::stack_detail
