#include "ptmkit/calib/sphere_stack.h"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <functional>
#include <numbers>

#include <tbb/parallel_for.h>
#include <nlohmann/json.hpp>
#include <opencv2/imgproc.hpp>

#include "ptmkit/core/colour.h"
#include "ptmkit/core/image_io.h"
#include "ptmkit/core/stack_reader.h"
#include "sphere_detail.h"

namespace ptmkit::calib {

namespace {

namespace fs = std::filesystem;

// ---- Sources: the stack in bands of rows, from files or from memory. -----------------------

class Source {
 public:
  virtual ~Source() = default;
  [[nodiscard]] virtual int width() const = 0;
  [[nodiscard]] virtual int height() const = 0;
  [[nodiscard]] virtual int count() const = 0;
  // Calls fn with every band, top to bottom.
  virtual void scan(const std::function<void(const StackBand&)>& fn) const = 0;
};

class FileSource : public Source {
 public:
  explicit FileSource(std::vector<fs::path> files) : files_(std::move(files)) {
    StackReader probe(files_);
    w_ = probe.width();
    h_ = probe.height();
  }
  int width() const override { return w_; }
  int height() const override { return h_; }
  int count() const override { return static_cast<int>(files_.size()); }
  void scan(const std::function<void(const StackBand&)>& fn) const override {
    StackReader reader(files_);
    StackBand band;
    while (reader.read_band(16, &band, BandStorage::kNative8)) fn(band);
  }

 private:
  std::vector<fs::path> files_;
  int w_ = 0, h_ = 0;
};

class MemorySource : public Source {
 public:
  explicit MemorySource(const std::vector<Image>& images) : images_(images) {}
  int width() const override { return images_[0].width(); }
  int height() const override { return images_[0].height(); }
  int count() const override { return static_cast<int>(images_.size()); }
  void scan(const std::function<void(const StackBand&)>& fn) const override {
    StackBand band;
    const int w = width(), h = height(), c = images_[0].channels();
    for (int y0 = 0; y0 < h; y0 += 64) {
      band.y0 = y0;
      band.rows = std::min(64, h - y0);
      band.width = w;
      band.channels = c;
      band.images = count();
      band.is_u8 = false;
      band.samples.resize(static_cast<std::size_t>(band.images) * band.image_stride());
      for (int i = 0; i < band.images; ++i) {
        std::copy_n(images_[static_cast<std::size_t>(i)].row(y0), band.image_stride(),
                    band.image(i));
      }
      fn(band);
    }
  }

 private:
  const std::vector<Image>& images_;
};

float band_luma(const StackBand& b, int i, int row, int x) {
  if (b.channels >= 3) {
    return static_cast<float>(
        luma(b.sample(i, row, x, 0), b.sample(i, row, x, 1), b.sample(i, row, x, 2)));
  }
  return b.sample(i, row, x, 0);
}

// ---- Pass 1: the stack's evidence. ---------------------------------------------------------

struct Evidence {
  int w = 0, h = 0, n = 0, scale = 1, sw = 0, sh = 0;
  std::vector<std::vector<std::uint16_t>> small;  // per image, block-max luma * 65535
  cv::Mat full_max, full_mean;                    // CV_32F, photo size
  cv::Mat small_max, small_median, small_mean;    // CV_32F, analysis size
  cv::Mat reference;                              // CV_32F photo size, or empty
  [[nodiscard]] float at(int i, int x, int y) const {
    return static_cast<float>(small[static_cast<std::size_t>(i)][static_cast<std::size_t>(y) * sw +
                                                                 static_cast<std::size_t>(x)]) /
           65535.0f;
  }
};

Evidence gather(const Source& src, int max_side) {
  Evidence ev;
  ev.w = src.width();
  ev.h = src.height();
  ev.n = src.count();
  ev.scale = std::max(1, (std::max(ev.w, ev.h) + max_side - 1) / max_side);
  ev.sw = (ev.w + ev.scale - 1) / ev.scale;
  ev.sh = (ev.h + ev.scale - 1) / ev.scale;
  ev.small.assign(static_cast<std::size_t>(ev.n),
                  std::vector<std::uint16_t>(static_cast<std::size_t>(ev.sw) * ev.sh, 0));
  ev.full_max = cv::Mat(ev.h, ev.w, CV_32F, cv::Scalar(0.0f));
  ev.full_mean = cv::Mat(ev.h, ev.w, CV_32F, cv::Scalar(0.0f));
  const float inv_n = 1.0f / static_cast<float>(ev.n);
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
        for (int x = 0; x < band.width; ++x) {
          const float v = band_luma(band, i, r, x);
          const auto q = static_cast<std::uint16_t>(std::lround(std::clamp(v, 0.0f, 1.0f) * 65535));
          std::uint16_t& sv = small[x / ev.scale];
          sv = std::max(sv, q);
        }
      }
    });
  });
  ev.small_max = cv::Mat(ev.sh, ev.sw, CV_32F);
  ev.small_median = cv::Mat(ev.sh, ev.sw, CV_32F);
  tbb::parallel_for(0, ev.sh, [&](int y) {
    std::vector<float> v(static_cast<std::size_t>(ev.n));
    for (int x = 0; x < ev.sw; ++x) {
      for (int i = 0; i < ev.n; ++i) v[static_cast<std::size_t>(i)] = ev.at(i, x, y);
      ev.small_max.at<float>(y, x) = *std::max_element(v.begin(), v.end());
      std::nth_element(v.begin(), v.begin() + ev.n / 2, v.end());
      ev.small_median.at<float>(y, x) = v[static_cast<std::size_t>(ev.n / 2)];
    }
  });
  cv::resize(ev.full_mean, ev.small_mean, cv::Size(ev.sw, ev.sh), 0, 0, cv::INTER_AREA);
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
cv::Mat stretch(const cv::Mat& f, int type, bool logarithm = true) {
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

// ---- Moving spots. -------------------------------------------------------------------------

struct Spot {
  Eigen::Vector2d centre_small;  // analysis pixels, weighted by brightness above the median
  double peak = 0.0;             // image luma at the spot's brightest pixel
  double lift = 0.0;             // brightest (image - median)
  int area = 0;                  // analysis pixels
  cv::Rect box;                  // analysis pixels
};

// The spots of image i in a disc (analysis pixels) brighter than the median by more than
// max(0.05, half the brightest lift in the disc), and at least min_peak bright.
std::vector<Spot> moving_spots(const Evidence& ev, int i, const Eigen::Vector2d& c, double r,
                               double min_peak) {
  const int x0 = std::max(0, static_cast<int>(std::floor(c.x() - r)));
  const int y0 = std::max(0, static_cast<int>(std::floor(c.y() - r)));
  const int x1 = std::min(ev.sw - 1, static_cast<int>(std::ceil(c.x() + r)));
  const int y1 = std::min(ev.sh - 1, static_cast<int>(std::ceil(c.y() + r)));
  if (x1 < x0 || y1 < y0) return {};
  cv::Mat lift(y1 - y0 + 1, x1 - x0 + 1, CV_32F, cv::Scalar(0.0f));
  float best = 0.0f;
  for (int y = y0; y <= y1; ++y) {
    for (int x = x0; x <= x1; ++x) {
      if ((Eigen::Vector2d(x, y) - c).squaredNorm() > r * r) continue;
      const float v = ev.at(i, x, y);
      if (v < min_peak) continue;
      const float d = v - ev.small_median.at<float>(y, x);
      lift.at<float>(y - y0, x - x0) = d;
      best = std::max(best, d);
    }
  }
  const float thr = std::max(0.05f, 0.5f * best);
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

// ---- Candidates. ---------------------------------------------------------------------------

// Per ray from the centre (360 rays), the strongest edge between 0.7 r and 1.3 r: the
// largest radial derivative of the smoothed composite, at least 2 grey levels a pixel, to a
// sub-sample by a parabola. Rays leaving the frame give none; `inside` counts the others.
std::vector<Eigen::Vector2d> ray_edges(const cv::Mat& f, const Eigen::Vector2d& c, double r,
                                       int* inside) {
  constexpr int kRays = 360;
  std::vector<Eigen::Vector2d> out;
  *inside = 0;
  const double step = std::max(0.35, r / 200.0);
  std::vector<double> prof;
  for (int k = 0; k < kRays; ++k) {
    const double a = 2.0 * std::numbers::pi * k / kRays;
    const Eigen::Vector2d dir(std::cos(a), std::sin(a));
    const Eigen::Vector2d near = c + 1.02 * r * dir;
    if (near.x() < 1 || near.y() < 1 || near.x() > f.cols - 2 || near.y() > f.rows - 2) continue;
    ++*inside;
    prof.clear();
    const double t0 = 0.7 * r;
    for (double t = t0; t <= 1.3 * r; t += step) {
      const Eigen::Vector2d p = c + t * dir;
      if (p.x() < 0 || p.y() < 0 || p.x() > f.cols - 1.001 || p.y() > f.rows - 1.001) break;
      const int x0 = static_cast<int>(p.x()), y0 = static_cast<int>(p.y());
      const double fx = p.x() - x0, fy = p.y() - y0;
      const float* r0 = f.ptr<float>(y0);
      const float* r1 = f.ptr<float>(std::min(y0 + 1, f.rows - 1));
      const int x1 = std::min(x0 + 1, f.cols - 1);
      prof.push_back((1 - fy) * ((1 - fx) * r0[x0] + fx * r0[x1]) +
                     fy * ((1 - fx) * r1[x0] + fx * r1[x1]));
    }
    double best = 0.0;
    std::size_t bi = 0;
    for (std::size_t i = 1; i + 1 < prof.size(); ++i) {
      const double g = std::abs(prof[i + 1] - prof[i - 1]) / (2.0 * step);
      if (g > best) {
        best = g;
        bi = i;
      }
    }
    if (best < 2.0) continue;
    double off = 0.0;
    if (bi >= 2 && bi + 2 < prof.size()) {
      const double gm = std::abs(prof[bi] - prof[bi - 2]), gp = std::abs(prof[bi + 2] - prof[bi]);
      const double g0 = 2.0 * step * best;
      const double den = gm - 2.0 * g0 + gp;
      if (std::abs(den) > 1e-12) off = std::clamp(0.5 * (gm - gp) / den, -0.5, 0.5);
    }
    out.push_back(c + (t0 + (static_cast<double>(bi) + off) * step) * dir);
  }
  return out;
}

// A circle through the edge points that most of them support: circles through three points
// (a fixed pseudo-random sequence, so runs agree), the one with most points within
// max(1 px, 1% r), refitted to those. `rim` = supporting points / 360.
Circle consensus_circle(const std::vector<Eigen::Vector2d>& pts, const Circle& rough, double* rim) {
  *rim = 0.0;
  if (pts.size() < 8) return rough;
  std::uint64_t state = 0x9E3779B97F4A7C15ull;
  auto next = [&](std::size_t n) {
    state = state * 6364136223846793005ull + 1442695040888963407ull;
    return static_cast<std::size_t>((state >> 33) % n);
  };
  auto count = [&](const Circle& c, std::vector<Eigen::Vector2d>* in) {
    const double tol = std::max(1.0, 0.01 * c.radius_px);
    int n = 0;
    for (const auto& p : pts) {
      if (std::abs((p - c.centre_px).norm() - c.radius_px) <= tol) {
        ++n;
        if (in != nullptr) in->push_back(p);
      }
    }
    return n;
  };
  Circle best = rough;
  int best_n = count(rough, nullptr);
  for (int it = 0; it < 400; ++it) {
    const Eigen::Vector2d& a = pts[next(pts.size())];
    const Eigen::Vector2d& b = pts[next(pts.size())];
    const Eigen::Vector2d& c = pts[next(pts.size())];
    // Circumcentre.
    const double d =
        2.0 * (a.x() * (b.y() - c.y()) + b.x() * (c.y() - a.y()) + c.x() * (a.y() - b.y()));
    if (std::abs(d) < 1e-9) continue;
    const double a2 = a.squaredNorm(), b2 = b.squaredNorm(), c2 = c.squaredNorm();
    Circle k;
    k.centre_px = {(a2 * (b.y() - c.y()) + b2 * (c.y() - a.y()) + c2 * (a.y() - b.y())) / d,
                   (a2 * (c.x() - b.x()) + b2 * (a.x() - c.x()) + c2 * (b.x() - a.x())) / d};
    k.radius_px = (a - k.centre_px).norm();
    if (k.radius_px < 0.75 * rough.radius_px || k.radius_px > 1.3 * rough.radius_px) continue;
    if ((k.centre_px - rough.centre_px).norm() > 0.3 * rough.radius_px) continue;
    const int n = count(k, nullptr);
    if (n > best_n) {
      best_n = n;
      best = k;
    }
  }
  for (int round = 0; round < 2; ++round) {
    std::vector<Eigen::Vector2d> in;
    count(best, &in);
    if (in.size() < 8) break;
    try {
      best = detail::fit_circle(in);
    } catch (const Error&) {
      break;
    }
  }
  std::vector<Eigen::Vector2d> in;
  *rim = count(best, &in) / 360.0;
  best.outline_px = std::move(in);
  return best;
}

struct Composite {
  std::string name;
  cv::Mat small8;  // analysis size, stretched
  cv::Mat smooth;  // the same, CV_32F grey levels, Gaussian sigma 1
};

// The 8-bit copy finds circles (Hough); the rim is measured on the unquantised one.
Composite make_composite(std::string name, const cv::Mat& plane) {
  Composite c{std::move(name), stretch(plane, CV_8U), stretch(plane, CV_32F)};
  cv::GaussianBlur(c.smooth, c.smooth, cv::Size(0, 0), 1.0);
  return c;
}

void add_hough(const cv::Mat& img8, double min_r, double max_r, const cv::Point& offset,
               std::vector<Circle>* out) {
  cv::Mat blur;
  cv::GaussianBlur(img8, blur, cv::Size(5, 5), 1.5);
  const int lo = std::max(3, static_cast<int>(std::floor(min_r)));
  const int hi = std::max(lo + 1, static_cast<int>(std::ceil(max_r)));
  std::vector<cv::Vec3f> circles;
  cv::HoughCircles(blur, circles, cv::HOUGH_GRADIENT, 1.0, std::max(4.0, 0.5 * min_r), 80.0, 18.0,
                   lo, hi);
  for (std::size_t k = 0; k < std::min<std::size_t>(circles.size(), 12); ++k) {
    Circle c;
    c.centre_px = {static_cast<double>(circles[k][0]) + offset.x,
                   static_cast<double>(circles[k][1]) + offset.y};
    c.radius_px = circles[k][2];
    out->push_back(c);
  }
}

struct Scored {
  SphereCandidate cand;     // circle in analysis pixels until the end
  std::vector<Spot> first;  // per image: the brightest moving spot inside (area 0: none)
};

SphereCandidate score_candidate(const Evidence& ev, const std::vector<Composite>& comps,
                                const Circle& c, double min_peak) {
  SphereCandidate out;
  out.circle = c;
  for (const Composite& comp : comps) {
    int inside = 0;
    const std::vector<Eigen::Vector2d> e =
        ray_edges(comp.smooth, c.centre_px, c.radius_px, &inside);
    double rim = 0.0;
    if (inside >= 90) {
      const double tol = std::max(1.0, 0.01 * c.radius_px);
      for (const auto& p : e) {
        if (std::abs((p - c.centre_px).norm() - c.radius_px) <= tol) rim += 1.0 / 360.0;
      }
    }
    if (rim > out.rim) {
      out.rim = rim;
      out.note = "rim in the " + comp.name;
    }
  }
  // The track: per image the brightest moving spot inside, compact; distinct places.
  const double disc = std::numbers::pi * c.radius_px * c.radius_px;
  std::vector<Eigen::Vector2d> places;
  out.spots_px.assign(static_cast<std::size_t>(ev.n), std::nullopt);
  for (int i = 0; i < ev.n; ++i) {
    const std::vector<Spot> spots = moving_spots(ev, i, c.centre_px, 0.97 * c.radius_px, min_peak);
    if (spots.empty()) continue;
    const Spot& s = spots.front();
    if (s.area > std::max(0.1 * disc, 4.0)) continue;
    places.push_back(s.centre_small);
    out.spots_px[static_cast<std::size_t>(i)] = s.centre_small;
  }
  out.moving_spots = static_cast<int>(places.size());
  // A place is distinct when no other image's spot is within 1.5 analysis pixels (or 2% of
  // the radius) of it.
  const double near = std::max(1.5, 0.02 * c.radius_px);
  for (std::size_t a = 0; a < places.size(); ++a) {
    bool alone = true;
    for (std::size_t b = 0; b < places.size() && alone; ++b) {
      if (a != b && (places[a] - places[b]).norm() < near) alone = false;
    }
    if (alone) ++out.distinct_spots;
  }
  out.track = static_cast<double>(out.distinct_spots) / ev.n;
  // A circle needs a rim (a third of the rays make it a full one) and a track: either alone
  // is no sphere (a coin has a rim, any circle around the highlights has their track).
  out.score = std::min(1.0, out.rim / 0.3) * out.track;
  return out;
}

bool same_circle(const Circle& a, const Circle& b) {
  return (a.centre_px - b.centre_px).norm() < 0.15 * std::max(a.radius_px, b.radius_px) &&
         std::abs(a.radius_px - b.radius_px) < 0.15 * std::max(a.radius_px, b.radius_px);
}

std::string describe(const SphereCandidate& c) {
  char buf[256];
  std::snprintf(buf, sizeof(buf),
                "(%.1f, %.1f) r %.1f px: score %.2f (rim %.2f, track %.2f: %d images with a "
                "moving spot inside, %d at their own place)%s%s",
                c.circle.centre_px.x(), c.circle.centre_px.y(), c.circle.radius_px, c.score, c.rim,
                c.track, c.moving_spots, c.distinct_spots, c.note.empty() ? "" : "; ",
                c.note.c_str());
  return buf;
}

Circle to_photo(const Circle& small, int scale) {
  Circle c;
  const double s = scale;
  // Analysis pixel k covers photo pixels k*s .. k*s+s-1: its centre is at k*s + (s-1)/2.
  c.centre_px = small.centre_px * s + Eigen::Vector2d::Constant(0.5 * (s - 1));
  c.radius_px = small.radius_px * s;
  for (const auto& p : small.outline_px) {
    c.outline_px.push_back(p * s + Eigen::Vector2d::Constant(0.5 * (s - 1)));
  }
  return c;
}

std::vector<SphereCandidate> find_candidates(const Evidence& ev, const SphereSearchOptions& opt,
                                             double min_peak, int count, const SphereCamera& camera,
                                             std::vector<Circle>* chosen_photo) {
  std::vector<Composite> comps;
  comps.push_back(make_composite("stack's maximum", ev.small_max));
  comps.push_back(make_composite("stack's mean", ev.small_mean));
  comps.push_back(make_composite("stack's median", ev.small_median));
  if (!ev.reference.empty()) {
    cv::Mat r;
    cv::resize(ev.reference, r, cv::Size(ev.sw, ev.sh), 0, 0, cv::INTER_AREA);
    comps.push_back(make_composite("reference photo", r));
  }
  const double s = ev.scale;
  const int short_side = std::min(ev.sw, ev.sh), long_side = std::max(ev.sw, ev.sh);
  const double min_r =
      opt.min_radius_px > 0.0 ? opt.min_radius_px / s : std::max(5.0, short_side / 40.0);
  const double max_r = opt.max_radius_px > 0.0 ? opt.max_radius_px / s : 0.75 * long_side;
  // Search regions: the boxes, or the frame.
  std::vector<cv::Rect> regions;
  for (const PixelBox& b : opt.rois) {
    cv::Rect r(static_cast<int>(std::floor(b.x / s)), static_cast<int>(std::floor(b.y / s)),
               static_cast<int>(std::ceil(b.width / s)), static_cast<int>(std::ceil(b.height / s)));
    r &= cv::Rect(0, 0, ev.sw, ev.sh);
    if (r.width < 8 || r.height < 8) throw Error("--roi: the box is outside the images or tiny");
    regions.push_back(r);
  }
  const bool boxes = !regions.empty();
  if (!boxes) regions.emplace_back(0, 0, ev.sw, ev.sh);
  std::vector<SphereCandidate> all;
  std::vector<int> region_of;
  for (std::size_t g = 0; g < regions.size(); ++g) {
    const cv::Rect& reg = regions[g];
    std::vector<Circle> raw;
    const double hi = std::min(max_r, boxes ? 0.5 * std::max(reg.width, reg.height) : max_r);
    // Radius bands of a factor 2.5 each: Hough's accumulator favours small circles otherwise.
    for (double lo = min_r; lo < hi; lo *= 2.5) {
      for (const Composite& comp : comps) {
        add_hough(comp.small8(reg), lo, std::min(hi, lo * 2.5), reg.tl(), &raw);
      }
    }
    for (const Circle& rough : raw) {
      // Refined on the stretched composites' edge. What stays still (the median, the
      // reference photo) comes first: the maximum and mean also hold the moving highlights'
      // flares. The first with a rim on 30% of the rays is kept, else the best.
      Circle best = rough;
      double best_rim = -1.0;
      for (const std::size_t k : {std::size_t{2}, std::size_t{3}, std::size_t{1}, std::size_t{0}}) {
        if (k >= comps.size()) continue;
        int inside = 0;
        const std::vector<Eigen::Vector2d> e =
            ray_edges(comps[k].smooth, rough.centre_px, rough.radius_px, &inside);
        if (inside < 90) continue;
        double rim = 0.0;
        const Circle c = consensus_circle(e, rough, &rim);
        if (rim > best_rim) {
          best_rim = rim;
          best = c;
        }
        if (rim >= 0.3) break;
      }
      if (best.radius_px < 0.8 * min_r || best.radius_px > 1.25 * max_r) continue;
      const bool dup = std::any_of(all.begin(), all.end(), [&](const SphereCandidate& o) {
        return same_circle(o.circle, best);
      });
      if (dup) continue;
      all.push_back(score_candidate(ev, comps, best, min_peak));
      region_of.push_back(static_cast<int>(g));
    }
  }
  std::vector<std::size_t> order(all.size());
  for (std::size_t k = 0; k < order.size(); ++k) order[k] = k;
  std::stable_sort(order.begin(), order.end(),
                   [&](std::size_t a, std::size_t b) { return all[a].score > all[b].score; });
  std::vector<SphereCandidate> sorted;
  std::vector<int> sorted_region;
  for (std::size_t k : order) {
    sorted.push_back(all[k]);
    sorted_region.push_back(region_of[k]);
  }
  for (SphereCandidate& c : sorted) {
    c.circle = to_photo(c.circle, ev.scale);
    for (auto& p : c.spots_px) {
      if (p) *p = *p * ev.scale + Eigen::Vector2d::Constant(0.5 * (ev.scale - 1));
    }
  }
  auto overlap = [](const SphereCandidate& a, const SphereCandidate& b) {
    return (a.circle.centre_px - b.circle.centre_px).norm() <
           a.circle.radius_px + b.circle.radius_px;
  };
  // Agreement of two candidates: the share of their common images whose spots reflect the
  // same light (within the tolerance), 0 with fewer than 3 common images.
  const double tol_deg = camera.focal_px > 0.0 ? 20.0 : 30.0;
  auto agree = [&](const SphereCandidate& a, const SphereCandidate& b) {
    int common = 0, same = 0;
    for (std::size_t i = 0; i < a.spots_px.size(); ++i) {
      if (!a.spots_px[i] || !b.spots_px[i]) continue;
      ++common;
      const Eigen::Vector3d la = reflect_highlight(a.circle, camera, *a.spots_px[i], ev.w, ev.h);
      const Eigen::Vector3d lb = reflect_highlight(b.circle, camera, *b.spots_px[i], ev.w, ev.h);
      const double ang = std::acos(std::clamp(la.dot(lb), -1.0, 1.0)) * 180.0 / std::numbers::pi;
      if (ang <= tol_deg) ++same;
    }
    return common >= 3 ? static_cast<double>(same) / common : 0.0;
  };
  // Take: one per box, or the `count` best that do not overlap (for two or three spheres, the
  // best agreeing set).
  const int want = boxes ? static_cast<int>(regions.size()) : count;
  std::vector<bool> region_done(regions.size(), false);
  int taken = 0;
  if (!boxes && (want == 2 || want == 3)) {
    std::vector<std::size_t> pool;
    for (std::size_t k = 0; k < sorted.size() && pool.size() < 10; ++k) {
      if (sorted[k].score >= opt.min_score) pool.push_back(k);
    }
    double best_value = 0.0;
    std::vector<std::size_t> best_set;
    std::vector<std::size_t> set;
    const std::function<void(std::size_t)> search = [&](std::size_t from) {
      if (static_cast<int>(set.size()) == want) {
        double worst = 1.0, sum = 0.0;
        for (std::size_t x = 0; x < set.size(); ++x) {
          sum += sorted[set[x]].score;
          for (std::size_t y = x + 1; y < set.size(); ++y) {
            worst = std::min(worst, agree(sorted[set[x]], sorted[set[y]]));
          }
        }
        // Agreement weighs the choice but refuses nothing alone: near lights (a small dome)
        // are seen along different directions by spheres far apart.
        const double value = sum * (0.5 + 0.5 * worst);
        if (value > best_value) {
          best_value = value;
          best_set = set;
        }
        return;
      }
      for (std::size_t q = from; q < pool.size(); ++q) {
        const bool clash = std::any_of(set.begin(), set.end(), [&](std::size_t k) {
          return overlap(sorted[k], sorted[pool[q]]);
        });
        if (clash) continue;
        set.push_back(pool[q]);
        search(q + 1);
        set.pop_back();
      }
    };
    search(0);
    for (std::size_t k : best_set) sorted[k].chosen = true;
    taken = static_cast<int>(best_set.size());
    if (taken < want) {
      for (std::size_t k : pool) sorted[k].note += "; no set of spheres whose highlights agree";
    } else {
      for (std::size_t k : pool) {
        if (!sorted[k].chosen) sorted[k].note += "; its spots disagree with the spheres taken";
      }
    }
  } else {
    for (std::size_t k = 0; k < sorted.size() && taken < want; ++k) {
      SphereCandidate& c = sorted[k];
      if (c.score < opt.min_score) break;
      if (boxes && region_done[static_cast<std::size_t>(sorted_region[k])]) continue;
      const bool overlaps =
          std::any_of(sorted.begin(), sorted.begin() + static_cast<std::ptrdiff_t>(k),
                      [&](const SphereCandidate& o) { return o.chosen && overlap(o, c); });
      if (overlaps) continue;
      c.chosen = true;
      if (boxes) region_done[static_cast<std::size_t>(sorted_region[k])] = true;
      ++taken;
    }
  }
  for (SphereCandidate& c : sorted) {
    if (!c.chosen) {
      c.note +=
          c.score < opt.min_score ? "; refused: weak evidence" : "; refused: overlaps a better one";
      if (c.track < 0.3 && c.rim >= 0.5)
        c.note += " (round, but its bright spots do not move like a sphere's)";
    }
  }
  if (taken < want) {
    std::string msg =
        "found " + std::to_string(taken) + " of " + std::to_string(want) +
        " spheres with enough evidence (score >= " + std::to_string(opt.min_score).substr(0, 4) +
        "); candidates:";
    const std::size_t show = std::min<std::size_t>(sorted.size(), 8);
    for (std::size_t k = 0; k < show; ++k) msg += "\n  " + describe(sorted[k]);
    if (sorted.empty()) msg += " none";
    msg +=
        "\nhelp the search with --roi x,y,w,h (a box per sphere), --radius-range MIN,MAX, "
        "--reference IMG (a photo in room light), or give --sphere cx,cy,r";
    throw SphereSearchError(msg, sorted);
  }
  for (const SphereCandidate& c : sorted) {
    if (c.chosen) chosen_photo->push_back(c.circle);
  }
  return sorted;
}

// ---- Highlights at full resolution. --------------------------------------------------------

struct Window {
  cv::Rect rect;  // photo pixels
  cv::Mat luma;   // CV_32F
};

struct Located {
  Eigen::Vector2d px{0.0, 0.0};
  double peak = 0.0;
  bool saturated = false;
  int pixels = 0;  // the core's (saturated) or the spot's pixels
  double major = 0.0, minor = 0.0, angle_deg = 0.0;
  bool ok = false;
};

void shape(const std::vector<Eigen::Vector3d>& samples, Located* out) {
  double sw = 0.0, sx = 0.0, sy = 0.0;
  for (const auto& q : samples) {
    sw += q.z();
    sx += q.z() * q.x();
    sy += q.z() * q.y();
  }
  if (!(sw > 0.0)) return;
  out->px = {sx / sw, sy / sw};
  Eigen::Matrix2d m = Eigen::Matrix2d::Zero();
  for (const auto& q : samples) {
    const Eigen::Vector2d d = q.head<2>() - out->px;
    m += q.z() * d * d.transpose();
  }
  m /= sw;
  const double tr = m.trace(), det = m(0, 0) * m(1, 1) - m(0, 1) * m(1, 0);
  const double disc = std::sqrt(std::max(0.0, 0.25 * tr * tr - det));
  out->major = std::sqrt(std::max(0.0, 0.5 * tr + disc));
  out->minor = std::sqrt(std::max(0.0, 0.5 * tr - disc));
  out->angle_deg = -0.5 * std::atan2(2.0 * m(0, 1), m(0, 0) - m(1, 1)) * 180.0 / std::numbers::pi;
  out->ok = true;
}

// The highlight in a window (photo pixels), `base` the stack's median there (same size),
// `inside` tells photo pixels on the sphere's searched disc.
Located locate(const Window& win, const cv::Mat& base,
               const std::function<bool(int, int)>& inside) {
  Located out;
  const cv::Mat& l = win.luma;
  double peak = 0.0;
  cv::Point at(-1, -1);
  for (int y = 0; y < l.rows; ++y) {
    for (int x = 0; x < l.cols; ++x) {
      if (!inside(x + win.rect.x, y + win.rect.y)) continue;
      const double v = l.at<float>(y, x) - base.at<float>(y, x);
      if (v > peak) {
        peak = v;
        at = {x, y};
      }
    }
  }
  if (at.x < 0) return out;
  double top = 0.0;
  for (int y = 0; y < l.rows; ++y) {
    for (int x = 0; x < l.cols; ++x) {
      if (inside(x + win.rect.x, y + win.rect.y)) top = std::max(top, double(l.at<float>(y, x)));
    }
  }
  out.peak = top;
  out.saturated = top >= 0.98;
  std::vector<Eigen::Vector3d> samples;
  if (out.saturated) {
    // Clipped region around the brightest pixel; its core: an opening by half the core's
    // inscribed radius removes streaks thinner than the core.
    cv::Mat clipped(l.rows, l.cols, CV_8U, cv::Scalar(0));
    for (int y = 0; y < l.rows; ++y) {
      for (int x = 0; x < l.cols; ++x) {
        if (l.at<float>(y, x) >= 0.98 * top && inside(x + win.rect.x, y + win.rect.y)) {
          clipped.at<std::uint8_t>(y, x) = 255;
        }
      }
    }
    cv::Mat labels;
    const int k = cv::connectedComponents(clipped, labels, 8, CV_32S);
    // The light's clipped component is the thickest (a streak may be longer, never thicker):
    // the largest inscribed radius, then the larger area.
    cv::Mat cpad, cdist;
    cv::copyMakeBorder(clipped, cpad, 1, 1, 1, 1, cv::BORDER_CONSTANT, cv::Scalar(0));
    cv::distanceTransform(cpad, cdist, cv::DIST_L2, cv::DIST_MASK_PRECISE);
    std::vector<int> area(static_cast<std::size_t>(k), 0);
    std::vector<float> depth(static_cast<std::size_t>(k), 0.0f);
    for (int y = 0; y < l.rows; ++y) {
      for (int x = 0; x < l.cols; ++x) {
        const auto j = static_cast<std::size_t>(labels.at<int>(y, x));
        ++area[j];
        depth[j] = std::max(depth[j], cdist.at<float>(y + 1, x + 1));
      }
    }
    int best = 0;
    for (int j = 1; j < k; ++j) {
      const auto jj = static_cast<std::size_t>(j), bb = static_cast<std::size_t>(best);
      if (best == 0 || depth[jj] > depth[bb] + 0.25f ||
          (std::abs(depth[jj] - depth[bb]) <= 0.25f && area[jj] > area[bb])) {
        best = j;
      }
    }
    cv::Mat region = labels == best;
    cv::Mat padded;
    cv::copyMakeBorder(region, padded, 1, 1, 1, 1, cv::BORDER_CONSTANT, cv::Scalar(0));
    cv::Mat dist;
    cv::distanceTransform(padded, dist, cv::DIST_L2, cv::DIST_MASK_PRECISE);
    double dmax = 0.0;
    cv::minMaxLoc(dist, nullptr, &dmax);
    cv::Point deep;
    cv::minMaxLoc(dist, nullptr, nullptr, nullptr, &deep);
    // Opening by half the core's inscribed radius (at least 1 px: a 3 x 3 disc removes
    // streaks one pixel wide); a core smaller than that is the disc of its inscribed radius
    // (plus a pixel) around its deepest point.
    const int rad = std::max(1, static_cast<int>(std::floor(0.5 * dmax)));
    const cv::Mat kernel =
        cv::getStructuringElement(cv::MORPH_ELLIPSE, cv::Size(2 * rad + 1, 2 * rad + 1));
    cv::Mat opened;
    cv::morphologyEx(padded, opened, cv::MORPH_OPEN, kernel);
    cv::Mat ol;
    cv::connectedComponents(opened, ol, 8, CV_32S);
    const int keep = ol.at<int>(deep);
    cv::Mat core;
    if (keep > 0) {
      const cv::Mat kept = ol == keep;
      core = kept(cv::Rect(1, 1, l.cols, l.rows)).clone();
    } else {
      core = cv::Mat(l.rows, l.cols, CV_8U, cv::Scalar(0));
      cv::circle(core, deep - cv::Point(1, 1), static_cast<int>(std::ceil(dmax)) + 1,
                 cv::Scalar(255), cv::FILLED);
      core &= region;
    }
    // Edge pixels weigh by how far the brightness climbs toward the clip level, so the
    // centroid moves smoothly rather than pixel by pixel. An edge pixel that is clipped (the
    // root of a streak) says nothing of the core's edge there: it takes the weight of the
    // pixel opposite it across the core, as a round core would have.
    cv::Mat grown;
    cv::dilate(core, grown, cv::Mat());
    const cv::Moments mo = cv::moments(core, true);
    const Eigen::Vector2d c0 = mo.m00 > 0.0 ? Eigen::Vector2d(mo.m10 / mo.m00, mo.m01 / mo.m00)
                                            : Eigen::Vector2d(deep.x - 1, deep.y - 1);
    auto edge_weight = [&](int x, int y) {
      const double v = l.at<float>(y, x) - base.at<float>(y, x);
      return std::clamp(v / (0.98 * top - base.at<float>(y, x)), 0.0, 1.0);
    };
    for (int y = 0; y < l.rows; ++y) {
      for (int x = 0; x < l.cols; ++x) {
        if (core.at<std::uint8_t>(y, x)) {
          samples.emplace_back(x + win.rect.x, y + win.rect.y, 1.0);
          ++out.pixels;
        } else if (grown.at<std::uint8_t>(y, x)) {
          double wgt = 0.0;
          if (region.at<std::uint8_t>(y, x) == 0) {
            wgt = edge_weight(x, y);
          } else {
            const int ox = static_cast<int>(std::lround(2.0 * c0.x() - x));
            const int oy = static_cast<int>(std::lround(2.0 * c0.y() - y));
            const bool ok = ox >= 0 && oy >= 0 && ox < l.cols && oy < l.rows &&
                            !core.at<std::uint8_t>(oy, ox) && !region.at<std::uint8_t>(oy, ox);
            wgt = ok ? edge_weight(ox, oy) : 0.5;
          }
          samples.emplace_back(x + win.rect.x, y + win.rect.y, wgt);
        }
      }
    }
  } else {
    // The spot: pixels above half the peak lift connected to the brightest, grown by two
    // pixels; weights are the brightness above the median.
    cv::Mat above(l.rows, l.cols, CV_8U, cv::Scalar(0));
    for (int y = 0; y < l.rows; ++y) {
      for (int x = 0; x < l.cols; ++x) {
        if (inside(x + win.rect.x, y + win.rect.y) &&
            l.at<float>(y, x) - base.at<float>(y, x) >= 0.5 * peak) {
          above.at<std::uint8_t>(y, x) = 255;
        }
      }
    }
    cv::Mat labels;
    cv::connectedComponents(above, labels, 8, CV_32S);
    cv::Mat spot = labels == labels.at<int>(at);
    out.pixels = cv::countNonZero(spot);
    cv::dilate(spot, spot, cv::getStructuringElement(cv::MORPH_RECT, cv::Size(5, 5)));
    for (int y = 0; y < l.rows; ++y) {
      for (int x = 0; x < l.cols; ++x) {
        if (!spot.at<std::uint8_t>(y, x) || !inside(x + win.rect.x, y + win.rect.y)) continue;
        const double v = l.at<float>(y, x) - base.at<float>(y, x);
        samples.emplace_back(x + win.rect.x, y + win.rect.y, std::max(0.0, v));
      }
    }
  }
  shape(samples, &out);
  return out;
}

struct Want {
  int image = 0;
  int sphere = 0;
  cv::Rect rect;  // photo pixels
};

StackCalibration run(const Source& src, const std::vector<fs::path>& names,
                     const StackCalibrationOptions& options) {
  const RigOptions& rig = options.rig;
  if (const auto err = rig.validate(); !err.empty()) throw Error("sphere: " + err);
  if (src.count() < 1) throw Error("sphere: no images");
  if (names.size() != static_cast<std::size_t>(src.count())) throw Error("sphere: names differ");
  const SphereSearchOptions& so = options.search;
  if (so.min_radius_px < 0.0 || so.max_radius_px < 0.0 ||
      (so.max_radius_px > 0.0 && so.min_radius_px > so.max_radius_px)) {
    throw Error("--radius-range: needs 0 <= MIN <= MAX pixels");
  }
  for (const PixelBox& b : so.rois) {
    if (b.width <= 0 || b.height <= 0) throw Error("--roi: width and height must be positive");
  }
  if (so.analysis_max_side_px < 64) throw Error("sphere: the analysis size must be >= 64 pixels");
  StackCalibration out;
  Evidence ev = gather(src, so.analysis_max_side_px);
  out.analysis_scale = ev.scale;
  out.width = ev.w;
  out.height = ev.h;
  if (so.reference) {
    const Image ref = read_image(*so.reference);
    if (ref.width() != ev.w || ref.height() != ev.h) {
      throw Error(where(*so.reference) + ": the reference photo's size differs from the images'");
    }
    ev.reference = luma_plane(ref);
  }
  const SphereOptions& det = rig.detection;
  std::vector<Circle> circles = rig.spheres;
  const bool detected = circles.empty();
  if (detected) {
    std::vector<Circle> small;
    out.candidates = find_candidates(ev, so, det.min_peak, rig.sphere_count, det.camera, &small);
    // Full-resolution rim: the consensus circle on the photo-size composite where the rim
    // shows best (at scale 1 the analysis already was at full resolution).
    // Still composites first (the median exists at photo size only at scale 1).
    std::vector<std::pair<std::string, const cv::Mat*>> planes;
    if (ev.scale == 1) planes.emplace_back("stack's median", &ev.small_median);
    if (!ev.reference.empty()) planes.emplace_back("reference photo", &ev.reference);
    planes.emplace_back("stack's mean", &ev.full_mean);
    planes.emplace_back("stack's maximum", &ev.full_max);
    for (const Circle& c : small) {
      Circle best = c;
      double best_rim = 0.0;
      // Linear brightness first: the logarithm shows a faint rim but moves a clear one's
      // steepest point toward its dark side.
      bool done = false;
      for (const bool logarithm : {false, true}) {
        for (const auto& [name, plane] : planes) {
          cv::Mat f = stretch(*plane, CV_32F, logarithm);
          cv::GaussianBlur(f, f, cv::Size(0, 0), 1.0);
          int inside = 0;
          const auto e = ray_edges(f, c.centre_px, c.radius_px, &inside);
          double rim = 0.0;
          const Circle r = consensus_circle(e, c, &rim);
          if (rim > best_rim &&
              (r.centre_px - c.centre_px).norm() < 0.05 * c.radius_px + ev.scale &&
              std::abs(r.radius_px - c.radius_px) < 0.05 * c.radius_px + ev.scale) {
            best_rim = rim;
            best = r;
          }
          if (rim >= 0.3) {
            done = true;
            break;
          }
        }
        if (done) break;
      }
      circles.push_back(best);
    }
    std::sort(circles.begin(), circles.end(), [](const Circle& a, const Circle& b) {
      if (std::abs(a.centre_px.x() - b.centre_px.x()) > 0.5 * std::min(a.radius_px, b.radius_px)) {
        return a.centre_px.x() < b.centre_px.x();
      }
      return a.centre_px.y() < b.centre_px.y();
    });
  }
  // Highlights: the spots on the analysis copy, then windows of the photographs.
  const double s = ev.scale;
  const std::size_t k_spheres = circles.size();
  std::vector<SphereReport> reports(k_spheres);
  std::vector<Want> wants;
  std::vector<std::vector<Spot>> first(k_spheres,
                                       std::vector<Spot>(static_cast<std::size_t>(ev.n)));
  for (std::size_t k = 0; k < k_spheres; ++k) {
    const Circle& c = circles[k];
    reports[k].sphere = c;
    reports[k].sphere_detected = detected;
    reports[k].lights.resize(static_cast<std::size_t>(ev.n));
    const Eigen::Vector2d cs = (c.centre_px - Eigen::Vector2d::Constant(0.5 * (s - 1))) / s;
    const double rs = det.search_radius_fraction * c.radius_px / s;
    for (int i = 0; i < ev.n; ++i) {
      SphereLight& light = reports[k].lights[static_cast<std::size_t>(i)];
      light.image = names[static_cast<std::size_t>(i)];
      const std::vector<Spot> spots = moving_spots(ev, i, cs, rs, det.min_peak);
      if (spots.empty()) {
        light.flag = "no highlight on the sphere: nothing brighter than in the other images";
        continue;
      }
      const Spot& sp = spots.front();
      first[k][static_cast<std::size_t>(i)] = sp;
      if (spots.size() >= 2 && spots[1].lift >= 0.5 * sp.lift) {
        light.second_peak = spots[1].peak;
        ++out.two_spot_images;
      }
      const int margin = static_cast<int>(std::ceil(std::max(6.0, 2.0 * s)));
      cv::Rect r(static_cast<int>(sp.box.x * s) - margin, static_cast<int>(sp.box.y * s) - margin,
                 static_cast<int>(sp.box.width * s) + 2 * margin,
                 static_cast<int>(sp.box.height * s) + 2 * margin);
      r &= cv::Rect(0, 0, ev.w, ev.h);
      wants.push_back({i, static_cast<int>(k), r});
    }
  }
  // Windows: straight from the analysis copy at scale 1, else a second streamed pass.
  std::vector<Window> windows(wants.size());
  for (std::size_t q = 0; q < wants.size(); ++q) {
    windows[q].rect = wants[q].rect;
    windows[q].luma = cv::Mat(wants[q].rect.height, wants[q].rect.width, CV_32F, cv::Scalar(0.0f));
  }
  if (ev.scale == 1) {
    for (std::size_t q = 0; q < wants.size(); ++q) {
      const cv::Rect& r = wants[q].rect;
      for (int y = 0; y < r.height; ++y) {
        for (int x = 0; x < r.width; ++x) {
          windows[q].luma.at<float>(y, x) = ev.at(wants[q].image, x + r.x, y + r.y);
        }
      }
    }
  } else if (!wants.empty()) {
    src.scan([&](const StackBand& band) {
      tbb::parallel_for(std::size_t{0}, wants.size(), [&](std::size_t q) {
        const cv::Rect& r = wants[q].rect;
        const int y0 = std::max(r.y, band.y0), y1 = std::min(r.y + r.height, band.y0 + band.rows);
        for (int y = y0; y < y1; ++y) {
          for (int x = r.x; x < r.x + r.width; ++x) {
            windows[q].luma.at<float>(y - r.y, x - r.x) =
                band_luma(band, wants[q].image, y - band.y0, x);
          }
        }
      });
    });
  }
  const double sphere_area_factor = det.max_blob_area_fraction * std::numbers::pi;
  for (std::size_t q = 0; q < wants.size(); ++q) {
    const Want& wt = wants[q];
    const Circle& c = circles[static_cast<std::size_t>(wt.sphere)];
    SphereLight& light =
        reports[static_cast<std::size_t>(wt.sphere)].lights[static_cast<std::size_t>(wt.image)];
    const double search_r = det.search_radius_fraction * c.radius_px;
    auto inside = [&](int x, int y) {
      return (Eigen::Vector2d(x, y) - c.centre_px).squaredNorm() <= search_r * search_r;
    };
    // The stack's median under the window (analysis resolution, nearest).
    cv::Mat base(wt.rect.height, wt.rect.width, CV_32F);
    for (int y = 0; y < wt.rect.height; ++y) {
      for (int x = 0; x < wt.rect.width; ++x) {
        const int sx = std::min(ev.sw - 1, (x + wt.rect.x) / ev.scale);
        const int sy = std::min(ev.sh - 1, (y + wt.rect.y) / ev.scale);
        base.at<float>(y, x) = ev.small_median.at<float>(sy, sx);
      }
    }
    const Located loc = locate(windows[q], base, inside);
    light.peak = loc.peak;
    light.saturated = loc.saturated;
    light.blob_pixels = loc.pixels;
    light.blob_major_px = loc.major;
    light.blob_minor_px = loc.minor;
    light.blob_angle_deg = loc.angle_deg;
    if (!loc.ok || loc.peak < det.min_peak) {
      light.flag =
          "no highlight on the sphere (peak " + std::to_string(loc.peak).substr(0, 5) + ")";
      continue;
    }
    light.highlight_px = loc.px;
    if (loc.pixels > sphere_area_factor * c.radius_px * c.radius_px) {
      light.flag = "highlight core covers " + std::to_string(loc.pixels) +
                   " pixels: not a compact highlight (a reflection of the scene?)";
      continue;
    }
    light.direction = reflect_highlight(c, det.camera, light.highlight_px, ev.w, ev.h);
    light.found = light.direction.z() > 0.0;
    if (!light.found) light.flag = "reflected direction is below the sample plane";
  }
  out.rig = refine_rig(std::move(reports), names, ev.w, ev.h, rig);
  return out;
}

}  // namespace

StackCalibration calibrate_sphere_stack(const std::vector<fs::path>& files,
                                        const StackCalibrationOptions& options) {
  if (files.empty()) throw Error("sphere: no images");
  const FileSource src(files);
  return run(src, files, options);
}

StackCalibration calibrate_sphere_stack(const std::vector<Image>& images,
                                        const std::vector<fs::path>& names,
                                        const StackCalibrationOptions& options) {
  if (images.empty()) throw Error("sphere: no images");
  for (std::size_t i = 0; i < images.size(); ++i) {
    if (images[i].width() != images[0].width() || images[i].height() != images[0].height() ||
        images[i].channels() != images[0].channels()) {
      throw Error(where(names.at(i)) + ": image size differs from the first image's");
    }
  }
  const MemorySource src(images);
  return run(src, names, options);
}

std::string StackCalibration::to_json() const {
  nlohmann::json j = nlohmann::json::parse(rig.to_json());
  j["analysis_scale"] = analysis_scale;
  j["two_spot_images"] = two_spot_images;
  j["candidates"] = nlohmann::json::array();
  for (const SphereCandidate& c : candidates) {
    j["candidates"].push_back({{"centre_px", {c.circle.centre_px.x(), c.circle.centre_px.y()}},
                               {"radius_px", c.circle.radius_px},
                               {"score", c.score},
                               {"rim", c.rim},
                               {"track", c.track},
                               {"moving_spots", c.moving_spots},
                               {"distinct_spots", c.distinct_spots},
                               {"chosen", c.chosen},
                               {"note", c.note}});
  }
  return j.dump(2);
}

Image downscale_for_overlay(const Image& image, int max_side_px, double* scale) {
  const int f =
      max_side_px > 0
          ? std::max(1, (std::max(image.width(), image.height()) + max_side_px - 1) / max_side_px)
          : 1;
  if (scale != nullptr) *scale = 1.0 / f;
  if (f == 1) return image;
  const int w = image.width() / f, h = image.height() / f, ch = image.channels();
  Image out(w, h, ch, image.colour_space());
  for (int y = 0; y < h; ++y) {
    for (int x = 0; x < w; ++x) {
      for (int c = 0; c < ch; ++c) {
        double sum = 0.0;
        for (int dy = 0; dy < f; ++dy) {
          for (int dx = 0; dx < f; ++dx) sum += image.at(x * f + dx, y * f + dy, c);
        }
        out.at(x, y, c) = static_cast<float>(sum / (f * f));
      }
    }
  }
  return out;
}

Image candidates_overlay(const Image& image, const std::vector<SphereCandidate>& candidates,
                         double scale) {
  cv::Mat m(image.height(), image.width(), CV_8UC3);
  for (int y = 0; y < image.height(); ++y) {
    auto* row = m.ptr<cv::Vec3b>(y);
    for (int x = 0; x < image.width(); ++x) {
      for (int c = 0; c < 3; ++c) {
        // Brightened (square root) so that a dark scene's spheres show.
        const float v = image.at(x, y, image.channels() >= 3 ? 2 - c : 0);
        row[x][c] =
            static_cast<unsigned char>(std::lround(std::sqrt(std::clamp(v, 0.0f, 1.0f)) * 255.0f));
      }
    }
  }
  for (std::size_t k = 0; k < candidates.size(); ++k) {
    const SphereCandidate& c = candidates[k];
    const cv::Scalar colour = c.chosen ? cv::Scalar(0, 220, 0) : cv::Scalar(0, 0, 255);
    const cv::Point p(static_cast<int>(std::lround(c.circle.centre_px.x() * scale)),
                      static_cast<int>(std::lround(c.circle.centre_px.y() * scale)));
    cv::circle(m, p, std::max(1, static_cast<int>(std::lround(c.circle.radius_px * scale))), colour,
               1, cv::LINE_AA);
    char buf[64];
    std::snprintf(buf, sizeof(buf), "%zu: %.2f", k, c.score);
    cv::putText(m, buf, p + cv::Point(4, -4), cv::FONT_HERSHEY_SIMPLEX, 0.4, colour, 1,
                cv::LINE_AA);
  }
  Image out(m.cols, m.rows, 3, ColourSpace::kSRGB);
  for (int y = 0; y < m.rows; ++y) {
    const auto* row = m.ptr<cv::Vec3b>(y);
    for (int x = 0; x < m.cols; ++x) {
      for (int c = 0; c < 3; ++c) out.at(x, y, c) = static_cast<float>(row[x][2 - c]) / 255.0f;
    }
  }
  return out;
}

}  // namespace ptmkit::calib
