#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <numbers>
#include <string>
#include <vector>

#include <opencv2/imgproc.hpp>

#include "sphere_stack_detail.h"

namespace ptmkit::calib::stack_detail {

// ---- Candidates. ---------------------------------------------------------------------------

OutlinePlane::OutlinePlane(const SphereCamera& camera, int width, int height, int points_scale)
    : focal_px(camera.focal_px > 0.0 ? camera.focal_px : 0.0),
      principal_px(principal_point(camera, width, height)),
      scale(points_scale) {}

Eigen::Vector2d OutlinePlane::to(const Eigen::Vector2d& p) const {
  if (identity()) return p;
  const Eigen::Vector2d v = (photo_px(p, scale) - principal_px) / focal_px;
  const Eigen::Vector3d d = Eigen::Vector3d(v.x(), v.y(), 1.0).normalized();
  return small_px(principal_px + 2.0 * focal_px * d.head<2>() / (1.0 + d.z()), scale);
}

Eigen::Vector2d OutlinePlane::from(const Eigen::Vector2d& q) const {
  if (identity()) return q;
  const Eigen::Vector2d u = (photo_px(q, scale) - principal_px) / (2.0 * focal_px);
  // The ray (2 u, 1 - |u|^2) / (1 + |u|^2); the image plane at z = 1.
  const double z = std::max(1e-9, 1.0 - u.squaredNorm());
  return small_px(principal_px + focal_px * 2.0 * u / z, scale);
}

Circle OutlinePlane::to(const Circle& c) const {
  if (identity()) return c;
  Circle q;
  q.centre_px = to(c.centre_px);
  double sum = 0.0;
  for (int k = 0; k < 8; ++k) {
    const double a = 2.0 * std::numbers::pi * k / 8.0;
    sum += (to(c.centre_px + c.radius_px * Eigen::Vector2d(std::cos(a), std::sin(a))) - q.centre_px)
               .norm();
  }
  q.radius_px = sum / 8.0;
  return q;
}

Circle OutlinePlane::from(const Circle& q) const {
  if (identity()) return q;
  std::vector<cv::Point2f> ring;
  for (int k = 0; k < 72; ++k) {
    const double a = 2.0 * std::numbers::pi * k / 72.0;
    const Eigen::Vector2d p =
        from(q.centre_px + q.radius_px * Eigen::Vector2d(std::cos(a), std::sin(a)));
    ring.emplace_back(static_cast<float>(p.x()), static_cast<float>(p.y()));
  }
  Circle c;
  // Centred on the ring's mean for float precision.
  cv::Point2f mean(0.f, 0.f);
  for (const cv::Point2f& p : ring) mean += p * (1.0f / 72.0f);
  for (cv::Point2f& p : ring) p -= mean;
  const cv::RotatedRect e = cv::fitEllipse(ring);
  c.centre_px = {mean.x + e.center.x, mean.y + e.center.y};
  c.radius_px = 0.5 * std::sqrt(static_cast<double>(e.size.width) * e.size.height);
  for (const Eigen::Vector2d& p : q.outline_px) c.outline_px.push_back(from(p));
  return c;
}

bool edge_on_ray(const cv::Mat& f, const Eigen::Vector2d& c, const Eigen::Vector2d& dir, double t0,
                 double t1, double step, double* t) {
  std::vector<double> prof;
  ray_profile(f, c, dir, t0, t1, step, &prof);
  double best = 0.0;
  std::size_t bi = 0;
  for (std::size_t i = 1; i + 1 < prof.size(); ++i) {
    const double g = std::abs(prof[i + 1] - prof[i - 1]) / (2.0 * step);
    if (g > best) {
      best = g;
      bi = i;
    }
  }
  if (best < 2.0) return false;
  double off = 0.0;
  if (bi >= 2 && bi + 2 < prof.size()) {
    const double gm = std::abs(prof[bi] - prof[bi - 2]), gp = std::abs(prof[bi + 2] - prof[bi]);
    const double g0 = 2.0 * step * best;
    const double den = gm - 2.0 * g0 + gp;
    if (std::abs(den) > 1e-12) off = std::clamp(0.5 * (gm - gp) / den, -0.5, 0.5);
  }
  *t = t0 + (static_cast<double>(bi) + off) * step;
  return true;
}

// Per ray from the centre (360 rays), the strongest edge between (1 - band) r and
// (1 + band) r: edge_on_ray. Rays leaving the frame give none; `inside` counts the others.
// Profiles are sampled at r / 200, between 0.35 and 1 px: a parabola through samples further
// apart than the blurred edge is wide misplaces it (a sphere of radius 720 px sampled every
// 3.6 px: 0.5-1.0 px off, every pixel: 0.13-0.24).
std::vector<Eigen::Vector2d> ray_edges(const cv::Mat& f, const Eigen::Vector2d& c, double r,
                                       int* inside, double band) {
  constexpr int kRays = 360;
  std::vector<Eigen::Vector2d> out;
  *inside = 0;
  const double step = std::clamp(r / 200.0, 0.35, 1.0);
  for (int k = 0; k < kRays; ++k) {
    const double a = 2.0 * std::numbers::pi * k / kRays;
    const Eigen::Vector2d dir(std::cos(a), std::sin(a));
    const Eigen::Vector2d near = c + 1.02 * r * dir;
    if (near.x() < 1 || near.y() < 1 || near.x() > f.cols - 2 || near.y() > f.rows - 2) continue;
    ++*inside;
    double t = 0.0;
    if (edge_on_ray(f, c, dir, (1.0 - band) * r, (1.0 + band) * r, step, &t)) {
      out.push_back(c + t * dir);
    }
  }
  return out;
}

// A circle through the edge points that most of them support: circles through three points
// (a fixed pseudo-random sequence, so runs agree), the one with most points within a pixel,
// refitted to those within max(1 px, 1% r). `rim` = supporting points / 360. The choice
// counts within a pixel whatever the radius: on a large sphere 1% of r admits edges a
// pixel or two inside the outline (a reflection along the limb), and a circle threading
// those with the outline's arcs outnumbers the outline alone (a 180 px sphere in a dark
// room: 4.1 px off with 1% of r, 0.9 px with a pixel).
Circle consensus_circle(const std::vector<Eigen::Vector2d>& pts, const Circle& rough, double* rim,
                        double choose_tol_px) {
  *rim = 0.0;
  if (pts.size() < 8) return rough;
  std::uint64_t state = 0x9E3779B97F4A7C15ull;
  auto next = [&](std::size_t n) {
    state = state * 6364136223846793005ull + 1442695040888963407ull;
    return static_cast<std::size_t>((state >> 33) % n);
  };
  bool choosing = true;
  auto count = [&](const Circle& c, std::vector<Eigen::Vector2d>* in) {
    const double tol =
        choosing && choose_tol_px > 0.0 ? choose_tol_px : std::max(1.0, 0.01 * c.radius_px);
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
  choosing = false;
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
Composite make_composite(std::string name, const cv::Mat& plane, bool logarithm = true) {
  Composite c{std::move(name), stretch(plane, CV_8U, logarithm), stretch(plane, CV_32F, logarithm)};
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

// The edges of what stays still around `c` (analysis pixels), on the stack's spread
// (ray_edges). Where the images' exposure varies (disc_gains over the circle's disc) a still
// mirror varies with it, and the spread is measured again around the circle with each image's
// gain taken out: with the exposure varying by up to 1 EV a chrome ball lying on the cloth in a
// lit room showed no still disc, and a circle 12 px off was taken (lights 32 degrees off). Not on
// a glass-like circle (glass_from_spots): glass shows the lit scene behind it and is not still;
// with the gains taken out, a glass marble's disc in a lit room proposed its outline with a
// better rim than the ring inside it, and the concentric-rims rule then took an edge 4% outside
// (lights 0.30 to 3.4 degrees off on average).
std::vector<Eigen::Vector2d> still_edges(const Evidence& ev, const Composite& spread,
                                         const Circle& c, double min_peak, int* inside) {
  const std::vector<double> gains = disc_gains(ev, c.centre_px, c.radius_px);
  if (!exposure_varies(gains)) return ray_edges(spread.smooth, c.centre_px, c.radius_px, inside);
  std::vector<std::vector<Spot>> spots_of(static_cast<std::size_t>(ev.n));
  for (int i = 0; i < ev.n; ++i) {
    spots_of[static_cast<std::size_t>(i)] = moving_spots(
        ev, i, c.centre_px, 0.97 * c.radius_px, min_peak, gains[static_cast<std::size_t>(i)]);
  }
  if (glass_from_spots(across_spot_images(spots_of, c.centre_px), ev.n)) {
    return ray_edges(spread.smooth, c.centre_px, c.radius_px, inside);
  }
  // Room for ray_edges' band (0.3 r), the 1 px smoothing and its frame test (1.02 r).
  const double half = 1.4 * c.radius_px + 4.0;
  const cv::Rect box = cv::Rect(static_cast<int>(std::floor(c.centre_px.x() - half)),
                                static_cast<int>(std::floor(c.centre_px.y() - half)),
                                static_cast<int>(std::ceil(2.0 * half)) + 1,
                                static_cast<int>(std::ceil(2.0 * half)) + 1) &
                       cv::Rect(0, 0, ev.sw, ev.sh);
  if (box.width < 8 || box.height < 8)
    return ray_edges(spread.smooth, c.centre_px, c.radius_px, inside);
  const Composite local = make_composite(spread.name, spread_in_box(ev, box, gains), false);
  const Eigen::Vector2d tl(box.x, box.y);
  std::vector<Eigen::Vector2d> e = ray_edges(local.smooth, c.centre_px - tl, c.radius_px, inside);
  for (Eigen::Vector2d& p : e) p += tl;
  return e;
}

struct Scored {
  SphereCandidate cand;     // circle in analysis pixels until the end
  std::vector<Spot> first;  // per image: the brightest moving spot inside (area 0: none)
};

int below_plane_spots(const SphereCandidate& cand, const Circle& circle_photo,
                      const SphereCamera& camera, const Evidence& ev, int spots_scale) {
  const double min_z = -std::sin(kBelowPlaneSlackDeg * std::numbers::pi / 180.0);
  int n = 0;
  for (const std::vector<Eigen::Vector2d>& spots : cand.light_spots_px) {
    if (spots.empty()) continue;
    const bool all_below = std::all_of(spots.begin(), spots.end(), [&](const Eigen::Vector2d& p) {
      return reflect_highlight(circle_photo, camera, photo_px(p, spots_scale), ev.w, ev.h).z() <
             min_z;
    });
    if (all_below) ++n;
  }
  return n;
}

// Proposals grown outward from a circle that puts lights below the sample plane (see
// find_candidates): steps of kGrowStep, each refined within a band that reaches just short of
// the circle it grew from, at most kMaxGrowSteps of them (1.08^8 = 1.85); and one jump to the
// outline a mirrored horizon implies (1 / sin 45 degrees), refined within kHorizonBand. A
// grown proposal whose refinement moves its centre by more than kGrownMaxShift of its radius
// has left the sphere (the mirrored horizon's circle lies up to 0.08 r off the outline's
// centre under the pinhole).
constexpr double kGrowStep = 1.08;
constexpr int kMaxGrowSteps = 8;
constexpr double kHorizonGrow = 1.41;
constexpr double kHorizonBand = 0.12;
constexpr double kGrownMaxShift = 0.1;
// A proposal refined on the stack's spread (Evidence::small_spread) proposes the still disc it
// finds where that disc's rim shows on at least this share of the rays.
constexpr double kStillDiscRim = 0.5;
// ... and refines it within this share of its radius: the still disc ends within a few tenths
// of a pixel of the outline, while a chrome ball in a lit room shows the edge between the room
// and the cloth it mirrors 0.94 of the radius in, sharper in the median than the outline.
constexpr double kStillDiscBand = 0.04;

// What an image whose light the circle reflects to below the plane costs the score, in
// multiples of its share of the images. The spheres' own outlines on the photographic renders
// (dark and lit rooms) reflect none below, but a glass ball under lights near the camera's
// axis can show only its refracted hot spot's glow in an image (1 of 10 reflected below);
// the horizon mirrored in a chrome ball reflects 3 of 8 below, 8 of 22.
constexpr double kBelowPlaneCost = 2.0;

// Where at least this share of the track's spots are clipped, the sphere clips its lights'
// reflections, and an unclipped spot is not one: on a glass ball it is the refracted hot
// spot's glow, which appears on the side away from the light, at the limb for a light whose
// own reflection the base hides (a 180 px glass ball: such glows lift it by 0.31-0.71 where
// its reflections clip, and its outline reflected them to below the plane in 2 of 9 images).
constexpr double kClippedTrackShare = 0.75;

// A moving spot is compact, a light's reflection rather than a broad change of the scene,
// within this share of the disc (a chrome ball's highlight blooms)...
constexpr double kCompactSpotShare = 0.1;
// ... or where it is a clipped spot of the sphere's one bloom size: an overexposed mirror
// shows every light as a clipped disc of bloom of one size (a chrome ball at three times the
// presets' exposure: 550-650 pixels above half their lift, 10-12% of the disc, in all 22
// images). The brightest spots of at least kBloomImages of the images are clipped and within
// kBloomSpread of their median size, itself under kBloomMaxShare of the disc; then a clipped
// spot within that spread is compact. A glass marble's refracted glow, clipped too, varies
// with the light (90-1700 pixels under lights 20-84 degrees up) and does not qualify.
constexpr double kBloomImages = 0.75;
constexpr double kBloomSpread = 1.25;
constexpr double kBloomMaxShare = 0.15;

struct BloomSize {
  double median = 0.0;  // analysis pixels; 0: no bloom size
  bool holds(const Spot& s) const {
    return median > 0.0 && s.peak >= kSpotClip && s.area <= kBloomSpread * median &&
           s.area * kBloomSpread >= median;
  }
};

BloomSize bloom_size(const std::vector<std::vector<Spot>>& spots_of, double disc) {
  std::vector<double> sizes;
  for (const std::vector<Spot>& spots : spots_of) {
    if (!spots.empty() && spots.front().peak >= kSpotClip) sizes.push_back(spots.front().area);
  }
  const double n = static_cast<double>(spots_of.size());
  if (sizes.empty() || static_cast<double>(sizes.size()) < kBloomImages * n) return {};
  std::sort(sizes.begin(), sizes.end());
  const double median = sizes[sizes.size() / 2];
  if (median > kBloomMaxShare * disc) return {};
  const auto within = std::count_if(sizes.begin(), sizes.end(), [&](double a) {
    return a <= kBloomSpread * median && a * kBloomSpread >= median;
  });
  if (static_cast<double>(within) < kBloomImages * n) return {};
  return {median};
}

// `rim_band`: the rim is the share of rays whose strongest edge within this share of the
// radius lies on the circle (the band the circle was refined in: a grown outline keeps its
// own support beside the sharper circle inside it that it grew from). `glass_spots`: whether
// the spots judge it glass (glass_from_spots), at any size.
SphereCandidate score_candidate(const Evidence& ev, const std::vector<Composite>& comps,
                                const Circle& c, double min_peak, const SphereCamera& camera,
                                double rim_band, bool* glass_spots = nullptr) {
  SphereCandidate out;
  out.circle = c;
  for (const Composite& comp : comps) {
    int inside = 0;
    const std::vector<Eigen::Vector2d> e =
        ray_edges(comp.smooth, c.centre_px, c.radius_px, &inside, rim_band);
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
  std::vector<double> lifts;  // per place: its spot's lift in linear light
  std::vector<double> peaks;  // per place: its spot's peak
  std::vector<std::vector<Spot>> spots_of(static_cast<std::size_t>(ev.n));
  out.spots_px.assign(static_cast<std::size_t>(ev.n), std::nullopt);
  // Where the exposure varies (disc_gains), a spot is what rises above the median at the
  // image's exposure, as for the highlights: against the median itself the whole mirror rises
  // in a brighter image, and its brightest part (a window mirrored by the limb) was taken for
  // a light's reflection below the plane, costing the outline its geometry.
  const std::vector<double> gains = disc_gains(ev, c.centre_px, 0.97 * c.radius_px);
  for (int i = 0; i < ev.n; ++i) {
    spots_of[static_cast<std::size_t>(i)] = moving_spots(
        ev, i, c.centre_px, 0.97 * c.radius_px, min_peak, gains[static_cast<std::size_t>(i)]);
  }
  const BloomSize bloom = bloom_size(spots_of, disc);
  // Glass-like: a quarter of the images show two comparable spots across the centre. On a
  // large one the glow, told by size against its reflections, is no light's reflection.
  const int across = across_spot_images(spots_of, c.centre_px);
  const bool glass = glass_from_spots(across, ev.n);
  const bool large = c.radius_px * ev.scale >= kGlowRuleMinRadiusPx;
  if (glass_spots != nullptr) *glass_spots = glass;
  // 0: unknown (not glass, small, or no common reflection size).
  const double reflection_area =
      glass && large ? reflection_spot_area(spots_of).value_or(0.0) : 0.0;
  const auto compact = [&](const Spot& s) {
    return s.area <= std::max(kCompactSpotShare * disc, 4.0) || bloom.holds(s);
  };
  for (int i = 0; i < ev.n; ++i) {
    const std::vector<Spot>& spots = spots_of[static_cast<std::size_t>(i)];
    if (spots.empty()) continue;
    const Spot& s = spots.front();
    if (!compact(s)) continue;
    places.push_back(s.centre_small);
    lifts.push_back(s.lift_linear);
    peaks.push_back(s.peak);
    out.spots_px[static_cast<std::size_t>(i)] = s.centre_small;
  }
  out.moving_spots = static_cast<int>(places.size());
  // The spots bright enough to be a light's reflection (kLightLiftShare of the upper quartile
  // of the track's lifts), and the images whose every such spot the circle reflects to below
  // the sample plane (on glass the brightest can be the refracted hot spot, across the
  // centre from the reflection).
  out.light_spots_px.assign(static_cast<std::size_t>(ev.n), {});
  if (!lifts.empty()) {
    const double light_lift = highlight_lift(lifts);
    int bright_places = 0, clipped_places = 0;
    for (std::size_t k = 0; k < lifts.size(); ++k) {
      if (lifts[k] < kLightLiftShare * light_lift) continue;
      ++bright_places;
      if (peaks[k] >= kSpotClip) ++clipped_places;
    }
    const bool clipped_track = static_cast<double>(clipped_places) >=
                               kClippedTrackShare * static_cast<double>(bright_places);
    for (std::size_t i = 0; i < spots_of.size(); ++i) {
      for (const Spot& sp : spots_of[i]) {
        if (sp.lift_linear >= kLightLiftShare * light_lift && compact(sp) &&
            (!clipped_track || sp.peak >= kSpotClip) &&
            !(reflection_area > 0.0 && not_a_reflection(sp, reflection_area))) {
          out.light_spots_px[i].push_back(sp.centre_small);
        }
      }
      if (!out.light_spots_px[i].empty()) ++out.light_spots;
    }
    out.below_plane_spots = below_plane_spots(out, to_photo(c, ev.scale), camera, ev, ev.scale);
  }
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
  // A light's reflection put below the sample plane says the circle is too small: on a
  // mirror sphere in a lit room the reflected horizon is a sharper circle than the outline,
  // at 0.7 of its radius, and the low lights' highlights lie between the two (chrome
  // spheres in a lit room: 8 of 22 lights below the plane of that circle, none of the
  // outline's). Each such image costs kBelowPlaneCost times its share.
  out.geometry =
      out.light_spots > 0
          ? std::max(0.0, 1.0 - kBelowPlaneCost * out.below_plane_spots / out.light_spots)
          : 1.0;
  out.score = std::min(1.0, out.rim / 0.3) * out.track * out.geometry;
  return out;
}

// A glass ball shows the room refracted and reflected inside its outline, and in a dark room
// the stack's median holds only those images, whose edges end a few pixels inside the limb (a
// 180 px ball: 1-12 px); the stack's maximum, where the glow of the refracted light fills the
// ball image after image, ends at the outline. Where a candidate is glass-like (a quarter of
// the images show a second comparable spot across its centre), its rim is also looked for in
// the maximum from kGlassOutlineGrow times its radius within kGlassOutlineBand, and a larger
// concentric circle found there on 30% of the rays, scoring no less, is taken.
constexpr double kGlassOutlineGrow = 1.03;
constexpr double kGlassOutlineBand = 0.06;

// Two circles whose centres and radii each differ by less than `tol` of the larger radius.
bool same_circle(const Circle& a, const Circle& b, double tol) {
  return (a.centre_px - b.centre_px).norm() < tol * std::max(a.radius_px, b.radius_px) &&
         std::abs(a.radius_px - b.radius_px) < tol * std::max(a.radius_px, b.radius_px);
}

std::string describe(const SphereCandidate& c) {
  char geometry[128] = "";
  if (c.below_plane_spots > 0) {
    std::snprintf(geometry, sizeof(geometry),
                  "; geometry %.2f: %d of %d lights reflected to below the sample plane",
                  c.geometry, c.below_plane_spots, c.light_spots);
  }
  char buf[384];
  std::snprintf(buf, sizeof(buf),
                "(%.1f, %.1f) r %.1f px: score %.2f (rim %.2f, track %.2f: %d images with a "
                "moving spot inside, %d at their own place%s)%s%s",
                c.circle.centre_px.x(), c.circle.centre_px.y(), c.circle.radius_px, c.score, c.rim,
                c.track, c.moving_spots, c.distinct_spots, geometry, c.note.empty() ? "" : "; ",
                c.note.c_str());
  return buf;
}

Circle to_photo(const Circle& small, int scale) {
  Circle c;
  c.centre_px = photo_px(small.centre_px, scale);
  c.radius_px = small.radius_px * scale;
  for (const auto& p : small.outline_px) c.outline_px.push_back(photo_px(p, scale));
  return c;
}

std::vector<SphereCandidate> find_candidates(const Evidence& ev, const SphereSearchOptions& opt,
                                             double min_peak, int count, const SphereCamera& camera,
                                             std::vector<Circle>* chosen_photo,
                                             bool second_search) {
  std::vector<Composite> comps;
  comps.push_back(make_composite("stack's maximum", ev.small_max));
  comps.push_back(make_composite("stack's mean", ev.small_mean));
  comps.push_back(make_composite("stack's median", ev.small_median));
  if (!ev.reference.empty()) {
    cv::Mat r;
    cv::resize(ev.reference, r, cv::Size(ev.sw, ev.sh), 0, 0, cv::INTER_AREA);
    comps.push_back(make_composite("reference photo", r));
  }
  // What changes from light to light only proposes circles (kStillDiscRim): its rim is the
  // still mirror's, not an edge of the scene, so it neither refines nor scores them.
  const Composite spread = make_composite("stack's spread", ev.small_spread, false);
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
  std::vector<double> refined_rim;  // per candidate: its refinement's rim support
  std::vector<bool> refined_still;  // per candidate: refined from a still disc
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
    // The proposals: Hough's, then those grown outward from them (appended while the queue is
    // walked, so it is indexed, not iterated).
    struct Proposal {
      Circle rough;
      int generation = 0;          // how many steps outward it was grown (0: Hough's)
      double band = 0.3;           // the share of its radius its refinement looks within
      double parent_radius = 0.0;  // grown: the radius it grew from
      bool narrow = false;         // refined within a narrower band (kStillDiscBand, kSlideShare)
      bool still = false;          // a still disc's (kStillDiscRim)
    };
    std::vector<Proposal> queue;
    queue.reserve(2 * raw.size());
    for (const Circle& c : raw) queue.push_back(Proposal{c});
    // Each proposal also refined on what changes from light to light: where that finds the
    // still disc's rim on enough rays, the disc is proposed, to be refined close to it.
    for (const Circle& c : raw) {
      int inside = 0;
      const std::vector<Eigen::Vector2d> e = still_edges(ev, spread, c, min_peak, &inside);
      if (inside < 90) continue;
      double rim = 0.0;
      const Circle still = consensus_circle(e, c, &rim);
      if (rim < kStillDiscRim) continue;
      Proposal p{still};
      p.band = kStillDiscBand;
      p.narrow = true;
      p.still = true;
      queue.push_back(p);
    }
    for (std::size_t pi = 0; pi < queue.size(); ++pi) {
      const Proposal prop = queue[pi];
      const Circle& rough = prop.rough;
      const double band = prop.band;
      // Grown proposals come after Hough's: where a candidate that counts as a sphere and keeps
      // every light above the plane already surrounds the circle this one grew from, the walk
      // has its end.
      if (prop.generation > 0) {
        const bool enclosed = std::any_of(all.begin(), all.end(), [&](const SphereCandidate& o) {
          return o.below_plane_spots == 0 && o.score >= opt.min_score &&
                 o.circle.radius_px > prop.parent_radius &&
                 (o.circle.centre_px - rough.centre_px).norm() <
                     kGrownMaxShift * o.circle.radius_px;
        });
        if (enclosed) continue;
      }
      // Refined on the stretched composites' edge. What stays still (the median, the
      // reference photo) comes first: the maximum and mean also hold the moving highlights'
      // flares. The first with a rim on 30% of the rays is kept, else the best. Rays cast
      // from a centre far off cross the rim obliquely and meet other edges first, so the
      // refinement is repeated from its own result while the rim support grows.
      Circle best = rough;
      double best_rim = -1.0;
      Circle from = rough;
      for (int round = 0; round < 4; ++round) {
        Circle round_best = from;
        double round_rim = -1.0;
        for (const std::size_t k :
             {std::size_t{2}, std::size_t{3}, std::size_t{1}, std::size_t{0}}) {
          if (k >= comps.size()) continue;
          int inside = 0;
          const std::vector<Eigen::Vector2d> e =
              ray_edges(comps[k].smooth, from.centre_px, from.radius_px, &inside, band);
          if (inside < 90) continue;
          double rim = 0.0;
          const Circle c = consensus_circle(e, from, &rim);
          if (rim > round_rim) {
            round_rim = rim;
            round_best = c;
          }
          if (rim >= 0.3) break;
        }
        if (round_rim <= best_rim) break;
        const double moved = (round_best.centre_px - from.centre_px).norm() +
                             std::abs(round_best.radius_px - from.radius_px);
        best = round_best;
        best_rim = round_rim;
        if (moved < 0.5) break;
        from = round_best;
      }
      if (second_search && !prop.narrow && prop.generation == 0 &&
          std::abs(best.radius_px - rough.radius_px) > kSlideShare * rough.radius_px) {
        Proposal narrow = prop;
        narrow.band = kSlideShare;
        narrow.narrow = true;
        queue.push_back(narrow);
      }
      if (best.radius_px < 0.8 * min_r || best.radius_px > 1.25 * max_r) continue;
      // A grown proposal stands for an outline concentric with the circle it grew from.
      if (prop.generation > 0 &&
          (best.centre_px - rough.centre_px).norm() > kGrownMaxShift * rough.radius_px) {
        continue;
      }
      bool across = false;
      SphereCandidate scored = score_candidate(ev, comps, best, min_peak, camera, band, &across);
      // A large glass ball's outline: see kGlassOutlineBand.
      if (across && best.radius_px * ev.scale >= kGlowRuleMinRadiusPx) {
        int inside = 0;
        const std::vector<Eigen::Vector2d> e =
            ray_edges(comps[0].smooth, best.centre_px, kGlassOutlineGrow * best.radius_px, &inside,
                      kGlassOutlineBand);
        double rim = 0.0;
        Circle grown = best;
        grown.radius_px *= kGlassOutlineGrow;
        const Circle outer = inside >= 90 ? consensus_circle(e, grown, &rim) : best;
        if (rim >= 0.3 && outer.radius_px > best.radius_px &&
            (outer.centre_px - best.centre_px).norm() < kGrownMaxShift * best.radius_px) {
          SphereCandidate o =
              score_candidate(ev, comps, outer, min_peak, camera, kGlassOutlineBand);
          if (o.score >= scored.score) {
            o.note += "; the outermost rim (in the stack's maximum)";
            o.glass_outline = true;
            scored = std::move(o);
            best = outer;
          }
        }
      }
      // A circle that reflects a light to below the plane is too small for the sphere: the
      // outline is looked for further out. A sphere shows circles concentric with its outline
      // inside it (the horizon mirrored at 0.7 of the radius, the base or cup mirrored near
      // the limb), which in a lit room can be sharper than the outline and are all Hough
      // proposes, so the search walks outward from edge to edge (kGrowStep) and stops at the
      // first circle that keeps every light above the plane; a base or cup around the sphere
      // lies beyond it. The horizon's own ratio (kHorizonGrow) is tried as one jump. Only
      // circles whose rim and track would make them a sphere are grown.
      const bool would_count = std::min(1.0, scored.rim / 0.3) * scored.track >= opt.min_score;
      // A step that found no edge beyond the circle it grew from ends its walk.
      const bool moved_out = prop.generation == 0 || best.radius_px > 1.02 * prop.parent_radius;
      if (scored.below_plane_spots > 0 && would_count && moved_out &&
          prop.generation < kMaxGrowSteps) {
        const auto grow = [&](double factor, double grown_band) {
          Circle q;
          q.centre_px = best.centre_px;
          q.radius_px = best.radius_px * factor;
          // Proposals refined to the same circle grow the same way: once is enough.
          for (const Proposal& o : queue) {
            if (o.generation > 0 && (o.rough.centre_px - q.centre_px).norm() < 0.5 &&
                std::abs(o.rough.radius_px - q.radius_px) < 0.5) {
              return;
            }
          }
          queue.push_back(Proposal{q, prop.generation + 1, grown_band, best.radius_px});
        };
        grow(kGrowStep, kGrowStep - 1.0 - 0.02);
        if (prop.generation == 0) grow(kHorizonGrow, kHorizonBand);
      }
      // Of two proposals that refine to about the same circle, the one that keeps more lights
      // above the sample plane stays, else the better supported. Glass is not still (it shows
      // the lit scene behind it), and a still disc's rim, supported within its narrower band,
      // does not outweigh another's there: on marbles in a lit room such discs ended on an
      // edge 0.3% outside the outline (seed 3: lights 0.31 to 0.37 degrees mean).
      const auto dup = std::find_if(all.begin(), all.end(), [&](const SphereCandidate& o) {
        return same_circle(o.circle, best, 0.15);
      });
      if (dup != all.end()) {
        const auto j = static_cast<std::size_t>(dup - all.begin());
        const bool by_rim = !across || prop.still == refined_still[j];
        if (scored.geometry > dup->geometry ||
            (scored.geometry == dup->geometry &&
             (by_rim ? best_rim > refined_rim[j] : refined_still[j]))) {
          *dup = std::move(scored);
          refined_rim[j] = best_rim;
          refined_still[j] = prop.still;
        }
        continue;
      }
      all.push_back(std::move(scored));
      refined_rim.push_back(best_rim);
      refined_still.push_back(prop.still);
      region_of.push_back(static_cast<int>(g));
    }
  }
  std::vector<std::size_t> order(all.size());
  for (std::size_t k = 0; k < order.size(); ++k) order[k] = k;
  // The score saturates (a full track and a third of the rim score 1): among equals, the
  // better rim first.
  std::stable_sort(order.begin(), order.end(), [&](std::size_t a, std::size_t b) {
    if (all[a].score != all[b].score) return all[a].score > all[b].score;
    return all[a].rim > all[b].rim;
  });
  std::vector<SphereCandidate> sorted;
  std::vector<int> sorted_region;
  for (std::size_t k : order) {
    sorted.push_back(all[k]);
    sorted_region.push_back(region_of[k]);
  }
  for (SphereCandidate& c : sorted) {
    c.circle = to_photo(c.circle, ev.scale);
    for (auto& p : c.spots_px) {
      if (p) *p = photo_px(*p, ev.scale);
    }
    for (auto& spots : c.light_spots_px) {
      for (Eigen::Vector2d& p : spots) p = photo_px(p, ev.scale);
    }
  }
  auto overlap = [](const SphereCandidate& a, const SphereCandidate& b) {
    return (a.circle.centre_px - b.circle.centre_px).norm() <
           a.circle.radius_px + b.circle.radius_px;
  };
  // Agreement of two candidates: the share of their common images whose spots reflect the
  // same light (within the tolerance), 0 with fewer than 3 common images.
  const double tol_deg =
      second_search ? (camera.focal_px > 0.0 ? kStrictAgreementDeg : kStrictAgreementOrthoDeg)
                    : (camera.focal_px > 0.0 ? 20.0 : 30.0);
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
        // are seen along different directions by spheres far apart. The second search weighs
        // all of it (kSlideShare).
        const double value = second_search ? sum * worst : sum * (0.5 + 0.5 * worst);
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

}  // namespace ptmkit::calib::stack_detail
