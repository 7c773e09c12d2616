#include "ptmkit/calib/sphere_stack.h"

#include <algorithm>
#include <array>
#include <cctype>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <functional>
#include <limits>
#include <numbers>
#include <optional>
#include <utility>

#include <tbb/parallel_for.h>
#include <Eigen/Dense>
#include <nlohmann/json.hpp>
#include <opencv2/imgproc.hpp>

#include "ptmkit/core/colour.h"
#include "ptmkit/core/image_io.h"
#include "ptmkit/core/stack_reader.h"
#include "sphere_detail.h"

#include "sphere_stack_detail.h"

namespace ptmkit::calib {

namespace {

using namespace stack_detail;  // NOLINT: the passes of this one search
using detail::bilinear_at;
using detail::upper_median;

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
  // The clipped region reaches pixels clipped in the stack's median too: a static
  // reflection (a window, a lamp) clipped in every image, merged with the light's core.
  bool touches_static = false;
  // The core was cut to a disc placed by the region's shape alone (cut_to_disc's `by_shape`)
  // and its halo's symmetry did not settle near it: nothing located the light.
  bool cut_unsupported = false;
  // What placed the highlight beyond the clipped core's centroid: a disc cut from a merged
  // region (cut_to_disc), and the halo's symmetry settling near it (symmetric_centre; measured
  // on small or saturated cores and on discs touching a static reflection).
  bool disc_cut = false;
  bool halo_settled = false;
  // On glass: the spot is many times the sphere's usual core (kGlareCoreRatio), the glow of
  // the refracted hot spot rather than the light's reflection.
  double glare_ratio = 0.0;
  // A clipped core cut from nothing: the radius (px) of the circle fitted to its edge, found
  // as cut_to_disc finds a disc's (0: not measured). See kFreeArcMinDeg.
  double edge_radius_px = 0.0;
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

// A highlight's halo is taken to ride on a ramp (a linear background) where allowing for one
// leaves at most this share of the asymmetry (mean squared residual) of the plain symmetric
// fit. On the photographic renders, the reflections on glass that the glare of the hot spot
// moves by a pixel or more (lights 75-84 degrees up) leave 0.01-0.03 of it; of the other
// highlights, none that the slope would move by more than 0.1 px leaves under 0.15.
constexpr double kRampAsymmetryShare = 0.1;

// Point symmetry of a highlight's halo about c, up to a background of slope g: the residual
// of pixel p is L(p) - L(2c - p) - 2 g.(p - c), which vanishes for a halo symmetric about c on
// a linear background g.x + k.
struct Symmetry {
  Eigen::Vector2d centre;
  Eigen::Vector2d slope = Eigen::Vector2d::Zero();
  double sum_sq = 0.0;  // of the residuals at the pixels used
  int used = 0;
  bool ok = false;
};

// The Gauss-Newton step of the first N unknowns from the normal equations; false where they
// are singular (a flat window: no slope to find).
template <int N>
bool normal_step(const Eigen::Matrix4d& jtj, const Eigen::Vector4d& jtr, Eigen::Vector4d* step) {
  const Eigen::Matrix<double, N, N> a = jtj.topLeftCorner<N, N>();
  const Eigen::FullPivLU<Eigen::Matrix<double, N, N>> lu(a);
  if (lu.rank() < N || std::abs(a.determinant()) < 1e-12) return false;
  step->setZero();
  step->head<N>() = -lu.solve(jtr.head<N>());
  return true;
}

// Gauss-Newton on the residuals above over `pts`, for the centre alone or (with_slope) the
// centre and the slope; the centre moves at most half a pixel a step (the linearisation
// holds that far) and at most `max_shift` from `start` (else not ok).
Symmetry fit_symmetry(const cv::Mat& lift, const std::vector<Eigen::Vector2d>& pts,
                      const Eigen::Vector2d& start, double max_shift, bool with_slope,
                      const std::function<bool(int, int)>& inside_win) {
  Symmetry s;
  s.centre = start;
  bool settled = false;
  for (int it = 0; it <= 20; ++it) {
    Eigen::Matrix4d jtj = Eigen::Matrix4d::Zero();
    Eigen::Vector4d jtr = Eigen::Vector4d::Zero();
    double sum_sq = 0.0;
    int used = 0;
    for (const Eigen::Vector2d& p : pts) {
      const Eigen::Vector2d q = 2.0 * s.centre - p;
      if (!inside_win(static_cast<int>(std::lround(q.x())), static_cast<int>(std::lround(q.y())))) {
        continue;
      }
      double vp = 0, vq = 0, xm = 0, xp = 0, ym = 0, yp = 0;
      if (!bilinear_at(lift, p.x(), p.y(), &vp) || !bilinear_at(lift, q.x(), q.y(), &vq) ||
          !bilinear_at(lift, q.x() - 0.5, q.y(), &xm) ||
          !bilinear_at(lift, q.x() + 0.5, q.y(), &xp) ||
          !bilinear_at(lift, q.x(), q.y() - 0.5, &ym) ||
          !bilinear_at(lift, q.x(), q.y() + 0.5, &yp)) {
        continue;
      }
      Eigen::Vector4d j;
      j.head<2>() = -2.0 * Eigen::Vector2d(xp - xm, yp - ym) + 2.0 * s.slope;  // d r / d c
      j.tail<2>() = -2.0 * (p - s.centre);                                     // d r / d g
      const double res = vp - vq - 2.0 * s.slope.dot(p - s.centre);
      jtj += j * j.transpose();
      jtr += j * res;
      sum_sq += res * res;
      ++used;
    }
    s.sum_sq = sum_sq;
    s.used = used;
    if (used < 12) return s;
    if (settled || it == 20) break;  // the residuals above are the final centre's
    Eigen::Vector4d step;
    if (!(with_slope ? normal_step<4>(jtj, jtr, &step) : normal_step<2>(jtj, jtr, &step))) {
      return s;
    }
    s.centre += step.head<2>().cwiseMax(-0.5).cwiseMin(0.5);
    s.slope += step.tail<2>();
    if ((s.centre - start).norm() > max_shift) return s;
    settled = step.head<2>().norm() < 1e-4;  // one more pass for the final residuals
  }
  s.ok = true;
  return s;
}

// The centre about which the highlight's brightness (above the stack's median) is most nearly
// point-symmetric, over the pixels within `radius` of the start. A light's highlight on a
// sphere is symmetric about its centre to first order, and so are its bloom and its flare
// (the spokes come in opposite pairs), so every pixel of the halo takes part, not only the
// core's edge: the clipped core alone pins the centre to about 0.15 px, the halo's slopes to
// a fraction of that. Pixels clipped on both sides cancel. A highlight on a sloping
// background (the glare of a glass ball's refracted hot spot beside it, under a light near
// the camera's axis) is symmetric only once the slope is allowed for, and the plain fit
// follows the slope by a pixel or more; but the slope's two unknowns also absorb any
// asymmetry of the halo itself (the lit scene mirrored around it), so it is taken only where
// it leaves at most kRampAsymmetryShare of the plain fit's residual. Returns the start when
// the fit does not settle within `max_shift` (`settled` false).
Eigen::Vector2d symmetric_centre(const cv::Mat& lift, const Eigen::Vector2d& start_win,
                                 double radius, double max_shift,
                                 const std::function<bool(int, int)>& inside_win,
                                 bool* settled = nullptr) {
  if (settled != nullptr) *settled = false;
  std::vector<Eigen::Vector2d> pts;
  const int r = static_cast<int>(std::ceil(radius));
  const int cx = static_cast<int>(std::lround(start_win.x()));
  const int cy = static_cast<int>(std::lround(start_win.y()));
  for (int y = cy - r; y <= cy + r; ++y) {
    for (int x = cx - r; x <= cx + r; ++x) {
      if (x < 0 || y < 0 || x >= lift.cols || y >= lift.rows) continue;
      if ((Eigen::Vector2d(x, y) - start_win).norm() > radius || !inside_win(x, y)) continue;
      pts.emplace_back(x, y);
    }
  }
  if (pts.size() < 12) return start_win;
  const Symmetry plain = fit_symmetry(lift, pts, start_win, max_shift, false, inside_win);
  if (!plain.ok) return start_win;
  if (settled != nullptr) *settled = true;
  const Symmetry sloped = fit_symmetry(lift, pts, plain.centre, max_shift, true, inside_win);
  if (!sloped.ok || (sloped.centre - start_win).norm() > max_shift) return plain.centre;
  const bool ramp = sloped.sum_sq / sloped.used < kRampAsymmetryShare * plain.sum_sq / plain.used;
  return ramp ? sloped.centre : plain.centre;
}

// Highlights whose core (saturated) or spot (above half the peak) has at most this many
// pixels are refined by symmetric_centre.
constexpr int kSmallCorePixels = 20;

// A larger clipped core's edge and its halo's symmetry disagreeing by more than this (pixels):
// the background has moved the edge, and the halo's centre is taken. With the edge on the
// level set of the light's lift (level_centre) the background moves it less, and 0.4 rather
// than 0.3 leaves it more often where the halo is the one moved (the lit scene mirrored around
// the light): photo-chrome in a lit room, seeds 2 and 3, means 0.316 / 0.347 to 0.305 / 0.285
// degrees, at 2560 x 1440 0.205 / 0.187 to 0.194 / 0.172; every dark-room figure unchanged.
constexpr double kEdgeVsHaloPx = 0.4;

// A disc cut from a merged region (cut_to_disc) and its settled halo apart by more than this
// many core radii, and at least this many pixels: the arc errs by a fraction of a pixel where
// it is short, so this far apart it was cut where the light's image is not round at all.
// Over 291 such highlights (photo-chrome dark and lit, 640 x 360 and 2560 x 1440, lit at
// +-1 EV): their midpoint's worst error 2.38 px to 0.76 px, the mean 0.119 to 0.113 px.
constexpr double kDiscVsHaloCoreRadii = 0.4;
constexpr double kDiscVsHaloPx = 2.0;

// A second spot replaces the brightest only when the spheres' directions then agree better by
// this much (sum of pairwise angles, degrees).
constexpr double kSpotAgreementMarginDeg = 3.0;

// The full-resolution circle is chosen by the rim points within this distance (see
// consensus_circle).
constexpr double kRimChoiceTolPx = 1.0;

// The full-resolution rim is looked for within this share of the candidate's radius (the
// candidate is already within a few percent of the outline). Further in, other circles
// concentric with the outline can be sharper: the horizon mirrored in a chrome ball in a lit
// room lies at 0.7 of its radius, and a refinement reaching it took it (28% too small).
constexpr double kRimRefineBand = 0.12;

// Edges concentric with a sphere's outline lie inside it more often than outside: a mirror or
// glossy ball shows its surroundings mirrored at the limb (the cup or cloth beside it at about
// 0.9 r), and a glass marble in a lit room a sharp ring at 0.91 r where its limb stops
// mirroring the lit floor and starts mirroring the floor it shades (the stack's median shows
// that ring on more rays than the faint outline outside it). So where a composite shows a rim
// of its own outside the rim taken (more than kConcentricRimGap further out, within
// kRimRefineBand) on at least kConcentricRimMin of the rays, keeping the candidate's lights
// above the sample plane, the outer is the outline. On the photographic renders (640 x 360 and
// 2560 x 1440, seeds 1-3, dark and lit rooms) only glass in a lit room shows such a rim (the
// mean: 0.64-1.00 of the rays); the edge of the glow and caustics around glass in a dark room
// reaches 0.50 (1280 x 720, 12 lights, four 80 degrees up), and a cup or a shadow around the
// other presets' spheres lies beyond the band (1.15-1.18 r) or on at most 0.4.
constexpr double kConcentricRimMin = 0.6;
// See SphereCandidate::glass_outline.
constexpr double kGlassOutlineSlack = 0.01;
constexpr double kConcentricRimGap = 0.03;

// How sharp a composite shows a rim: the share of rays whose edge lies within this many of its
// pixels of the circle fitted (rim_circle's `tight`).
constexpr double kTightRimPx = 0.5;

// At scale > 1, a photo-size rim circle supported by kBlockMedianRimMargin fewer rays than the
// one on the median of the block means is taken to be moved by what moves in the stack (glass
// at 2560 x 1440: 0.70-0.77 of the rays against 0.88-1.00 on the median; radius 0.11-0.16% off
// against 0.00-0.04%), and the median's is taken. Where the photo-size rim is as well
// supported (a large black sphere in a dark room: 0.34-0.42 against 0.34-0.46, the median's a
// pixel or more inside), its resolution wins.
constexpr double kBlockMedianRimMargin = 0.1;

// polish_rim: the band either side of the rim and the profiles' step along the rays, the
// smoothing, the least share of the rim's edge points the polished circle keeps, and how far it
// may move (photo pixels).
constexpr double kPolishBandPx = 2.0;
constexpr double kPolishStepPx = 0.25;
constexpr double kPolishSigmaPx = 0.7;
constexpr double kPolishSupport = 0.9;
constexpr double kPolishMaxMovePx = 1.0;
// The limb's profile (LimbProfileModel) is fitted from kLimbInsidePx inside the rim to
// kLimbOutsidePx outside it.
constexpr double kLimbInsidePx = 3.5;
constexpr double kLimbOutsidePx = 3.0;
// The limb's climb to half the sphere's contrast spans 0.0085 of the radius (Schlick: cos theta
// 0.13): under a pixel's blur below about 90 px, where the limb is hard to tell from a step, the
// steepest point is kept. On the 42 px spheres of the 640 x 360 renders (seeds 1-3) the limb's
// model gave circles 0.01-0.12% off in a dark room against 0.00-0.06% (glass seed 1's lights
// 0.20 to 0.23 degrees mean), and took lit-room chrome from 0.28-0.31 to 0.24-0.25.
constexpr double kLimbMinRadiusPx = 88.0;
// The limb's climb over its window must stand this many times above the fit's rms residual,
// and the limb's model leave at most kLimbEvidence of the step's residual. Under read noise of 6
// grey levels in a dark room neither model is clearly the better; the large sphere's lights
// (seeds 1-3, mean degrees) were 0.46 / 0.12 / 0.21 by the steepest point, 0.46 / 0.25 / 0.23
// with the limb taken wherever it fitted better, 0.43 / 0.13 / 0.26 with kLimbEvidence.
constexpr double kLimbMinContrast = 10.0;
constexpr double kLimbEvidence = 0.5;

// A sphere whose clipped cores have at least this many pixels (median over the images) shows
// the light as a disc: a core kMergedCoreRatio times as large is cut back to it (cut_to_disc).
constexpr int kMergedCoreMinPixels = 12;
constexpr double kMergedCoreRatio = 1.25;
// Where the exposure varies: a core is compared with the cores of the images whose gain is
// at least this share of its own.
constexpr double kMergedCoreGain = 0.9;
// On glass, a spot (its clipped core, or where it is not clipped its pixels above half its
// peak) this many times the sphere's median clipped core, and at least kGlareCoreMinPixels, is
// the refracted hot spot's glow, not the light's reflection, which is the same small disc in
// every image (on the photographic renders the reflections' cores are 5-8 pixels and such
// glow 150-200).
constexpr double kGlareCoreRatio = 8.0;
constexpr int kGlareCoreMinPixels = 40;

// A saturated core is compact, whatever DetectOptions::max_blob_area_fraction says, up to
// kUsualCoreSlack times the sphere's usual clipped core (its median over the images), and
// never beyond kMaxUsualCoreFraction of the sphere's area. An overexposed mirror sphere shows
// every light as a large clipped disc of bloom (a chrome ball at three times the presets'
// exposure: 300-390 pixels, 6-7% of its area), one size in every image: refusing them all
// as "not compact" left no light, while a reflection of the scene clipped beside one light
// is as large only in that image.
constexpr double kUsualCoreSlack = 1.5;
constexpr double kMaxUsualCoreFraction = 0.15;
// On glass, how many more clipped components of a spot's window are tried when the one taken
// reflects to below the sample plane.
constexpr int kGlassRetries = 3;

// A disc cut from a merged region keeps the arc of the light's edge that the reflection beside
// it does not hide, on a chrome sphere often a third to two thirds of the circle. A circle
// fitted freely to so short an arc trades its radius for its centre (photo-chrome at 640 x 360:
// radii 4.36-4.91 px where the sphere's whole cores measure 4.50-4.59, centres up to 0.6 px
// off). Where the arc spans less than kFreeArcMinDeg degrees, the centre is fitted with the
// radius of the sphere's whole cores instead: the median of their edge circles, from at least
// kEdgeRadiusMinCores of them. A nearly whole arc keeps its own radius: on a large sphere the
// light's image grows toward the limb (photo-large-sphere in a lit room: a 316-degree arc
// fitted 8.0 px against the median 7.05, and its light 0.12 to 0.33 degrees with the median).
// The short arc's own circle must agree with that radius within kShortArcRadiusAgreement of
// it: the light's image is then the usual disc, partly hidden. On photo-chrome (seeds 1-12 in
// a dark room, 1-5 in a lit one) and photo-large-sphere in a lit room (seeds 1-6), 146 short
// arcs, the free radii lie within -5% to +14% of the whole cores'. On photo-large-sphere under
// lights near the camera's axis, where the camera's reflection and the pedestal hide part of a
// light's image, three arcs fitted +21% to +29%; held to the whole cores' radius those lights'
// highlights went 3-4 px off (1.3-2.6 px with their own circle).
constexpr double kFreeArcMinDeg = 300.0;
constexpr int kEdgeRadiusMinCores = 3;
constexpr double kShortArcRadiusAgreement = 0.17;

// The angle (degrees) the points cover as seen from `centre`: 360 less the widest gap.
double arc_span_deg(const std::vector<Eigen::Vector2d>& points, const Eigen::Vector2d& centre) {
  if (points.empty()) return 0.0;
  std::vector<double> angles;
  angles.reserve(points.size());
  for (const Eigen::Vector2d& p : points) {
    angles.push_back(std::atan2(p.y() - centre.y(), p.x() - centre.x()));
  }
  std::sort(angles.begin(), angles.end());
  double gap = angles.front() + 2.0 * std::numbers::pi - angles.back();
  for (std::size_t i = 1; i < angles.size(); ++i) gap = std::max(gap, angles[i] - angles[i - 1]);
  return (2.0 * std::numbers::pi - gap) * 180.0 / std::numbers::pi;
}

// A pixel of `mask` (CV_8U) set and 4-adjacent to one unset or to the mask's border.
bool on_mask_edge(const cv::Mat& mask, int x, int y) {
  return mask.at<std::uint8_t>(y, x) &&
         (x == 0 || y == 0 || x + 1 == mask.cols || y + 1 == mask.rows ||
          !mask.at<std::uint8_t>(y, x - 1) || !mask.at<std::uint8_t>(y, x + 1) ||
          !mask.at<std::uint8_t>(y - 1, x) || !mask.at<std::uint8_t>(y + 1, x));
}

// A clipped region's boundary pixel `b` as a point of its edge: the last clipped pixel along its
// ray from `centre`, so the edge lies beyond its centre by half a pixel plus how far the next
// pixel out climbs toward the clip (`climb`, 0..1). Also that next pixel; none where it leaves
// the window (cols x rows).
struct EdgePoint {
  Eigen::Vector2d px;
  cv::Point next;
};
std::optional<EdgePoint> edge_point(const Eigen::Vector2d& b, const Eigen::Vector2d& centre,
                                    int cols, int rows,
                                    const std::function<double(int, int)>& climb) {
  const Eigen::Vector2d n = (b - centre).normalized();
  const int ox = static_cast<int>(std::lround(b.x() + n.x()));
  const int oy = static_cast<int>(std::lround(b.y() + n.y()));
  if (ox < 0 || oy < 0 || ox >= cols || oy >= rows) return {};
  return EdgePoint{b + (0.5 + climb(ox, oy)) * n, {ox, oy}};
}

// A clipped region much larger than the sphere's usual core: the light's image merged with
// something else clipped beside it (on a mirror sphere, the lit scene mirrored next to the
// light, or a static reflection clipped in every image). The light's image is a disc of the
// usual radius `r`: the disc, lying inside the region, on whose circle most of the region's
// boundary pixels lie; the region is cut to it (plus a pixel and a half), so the core's
// centroid sees the disc alone, the cut side weighted as a clipped edge (mirrored from the
// opposite side). `light_edge` (window pixels) tells the boundary pixels that can be the
// light's edge, `climb` how far a pixel climbs from the median toward the clip (0..1);
// `merged` says the region is known to hold more than the light (else a region not much larger
// than the disc is left as it is). `edge_r` (0: none known) is the radius of the sphere's whole
// cores' edges, fixed for a short arc that agrees with it (kFreeArcMinDeg). `by_shape`: the disc
// cut has none of the light's edge on its circle, so it was placed by the region's shape alone (the
// most pixels inside), which in a window that holds the light is anywhere.
std::optional<Eigen::Vector2d> cut_to_disc(cv::Mat* region, double r,
                                           const std::function<bool(int, int)>& light_edge,
                                           const std::function<double(int, int)>& climb,
                                           bool merged, double edge_r, bool* by_shape) {
  *by_shape = false;
  const cv::Mat& m = *region;
  std::vector<Eigen::Vector2d> boundary, inner;
  for (int y = 0; y < m.rows; ++y) {
    for (int x = 0; x < m.cols; ++x) {
      if (!m.at<std::uint8_t>(y, x)) continue;
      inner.emplace_back(x, y);
      if (on_mask_edge(m, x, y) && light_edge(x, y)) boundary.emplace_back(x, y);
    }
  }
  const double disc_area = std::numbers::pi * r * r;
  if (!merged && static_cast<double>(inner.size()) < kMergedCoreRatio * disc_area) return {};
  double best_score = -1.0;
  int best_on = 0;
  Eigen::Vector2d best_c(0.0, 0.0);
  for (const Eigen::Vector2d& p : inner) {
    for (const double dy : {0.0, 0.5}) {
      for (const double dx : {0.0, 0.5}) {
        const Eigen::Vector2d c = p + Eigen::Vector2d(dx, dy);
        // Mostly inside the region.
        int in = 0, all = 0;
        const int rr = static_cast<int>(std::ceil(r));
        for (int y = static_cast<int>(c.y()) - rr; y <= static_cast<int>(c.y()) + rr + 1; ++y) {
          for (int x = static_cast<int>(c.x()) - rr; x <= static_cast<int>(c.x()) + rr + 1; ++x) {
            if ((Eigen::Vector2d(x, y) - c).norm() > r - 0.5) continue;
            ++all;
            if (x >= 0 && y >= 0 && x < m.cols && y < m.rows && m.at<std::uint8_t>(y, x)) ++in;
          }
        }
        if (all == 0 || in < 0.9 * all) continue;
        int on = 0;
        for (const Eigen::Vector2d& b : boundary) {
          if (std::abs((b - c).norm() - r) < 0.75) ++on;
        }
        const double score = on + 0.01 * in;
        if (score > best_score) {
          best_score = score;
          best_on = on;
          best_c = c;
        }
      }
    }
  }
  if (best_score < 0.0) return {};
  *by_shape = best_on == 0;
  for (const Eigen::Vector2d& p : inner) {
    if ((p - best_c).norm() > r + 1.5) {
      region->at<std::uint8_t>(static_cast<int>(p.y()), static_cast<int>(p.x())) = 0;
    }
  }
  // The centre to a fraction of a pixel: a circle fitted (fit_circle) to the boundary pixels
  // on the disc's circle; the merged side has none there.
  std::vector<Eigen::Vector2d> arc;
  for (const Eigen::Vector2d& b : boundary) {
    if (std::abs((b - best_c).norm() - r) < 1.0) arc.push_back(b);
  }
  if (arc.size() < 8) return {};
  // The arc on the edge (edge_point), not on its pixels' centres: the short arc of a light
  // mostly hidden by a reflection is otherwise fitted on pixel centres (photo-chrome seed 2's
  // worst highlights 0.42 to 0.29-0.32 px).
  for (Eigen::Vector2d& b : arc) {
    if (const auto e = edge_point(b, best_c, m.cols, m.rows, climb)) b = e->px;
  }
  Circle fitted;
  try {
    fitted = detail::fit_circle(arc);
  } catch (const Error&) {
    return {};
  }
  if ((fitted.centre_px - best_c).norm() > 1.5) return {};
  if (edge_r > 0.0 && arc_span_deg(arc, fitted.centre_px) < kFreeArcMinDeg &&
      std::abs(fitted.radius_px - edge_r) <= kShortArcRadiusAgreement * edge_r) {
    const Eigen::Vector2d c = detail::fit_circle_centre(arc, edge_r, fitted.centre_px);
    if ((c - best_c).norm() <= 1.5) return c;
  }
  return fitted.centre_px;
}

// Sets the pixels of `mask` (CV_8U, 0 or 255) that it encloses: those of the background not
// 4-connected to the mask's border.
void fill_holes(cv::Mat* mask) {
  cv::Mat background = *mask == 0;
  cv::Mat labels;
  const int k = cv::connectedComponents(background, labels, 4, CV_32S);
  std::vector<char> outside(static_cast<std::size_t>(k), 0);
  for (int y = 0; y < labels.rows; ++y) {
    for (int x = 0; x < labels.cols; ++x) {
      if (y == 0 || x == 0 || y + 1 == labels.rows || x + 1 == labels.cols) {
        outside[static_cast<std::size_t>(labels.at<int>(y, x))] = 1;
      }
    }
  }
  for (int y = 0; y < labels.rows; ++y) {
    for (int x = 0; x < labels.cols; ++x) {
      const int j = labels.at<int>(y, x);
      if (background.at<std::uint8_t>(y, x) && !outside[static_cast<std::size_t>(j)]) {
        mask->at<std::uint8_t>(y, x) = 255;
      }
    }
  }
}

// A glossy sphere's outline seen against darker surroundings (a dark room) and against
// brighter ones (a floor, a cloth): against the darker, its limb mirrors the dark room at
// grazing incidence and fades into the background, so the steepest edge lies up to a pixel or
// more inside the outline; against the brighter, the edge is the outline. Where the rim points
// against brighter surroundings suffice (a sixth of the rays, in at least three 30-degree
// sectors), the circle is refitted to them alone (photo-large-sphere: 0.6-1.2 px off with
// every rim point, 0.1 px with these). `f` is the composite the points were found on.
void rim_against_brighter(const cv::Mat& f, const OutlinePlane& op, Circle* circle) {
  constexpr double kProbePx = 1.5;  // either side of the edge, along the ray
  std::vector<Eigen::Vector2d> brighter_out;
  int brighter_in = 0;
  std::array<int, 12> sectors{};
  for (const Eigen::Vector2d& p : circle->outline_px) {
    const Eigen::Vector2d d = (p - circle->centre_px).normalized();
    double in = 0.0, out = 0.0;
    const Eigen::Vector2d pi = p - kProbePx * d, po = p + kProbePx * d;
    if (!bilinear_at(f, pi.x(), pi.y(), &in) || !bilinear_at(f, po.x(), po.y(), &out)) continue;
    if (out > in) {
      brighter_out.push_back(p);
      const double a = std::atan2(d.y(), d.x()) + std::numbers::pi;  // 0 .. 2 pi
      ++sectors[static_cast<std::size_t>(std::min(11.0, std::floor(a / (std::numbers::pi / 6))))];
    } else {
      ++brighter_in;
    }
  }
  const auto covered = std::count_if(sectors.begin(), sectors.end(), [](int n) { return n >= 3; });
  if (brighter_in == 0 || brighter_out.size() < 60 || covered < 3) return;
  Circle q;
  try {
    std::vector<Eigen::Vector2d> in_plane;
    for (const Eigen::Vector2d& p : brighter_out) in_plane.push_back(op.to(p));
    q = op.from(detail::fit_circle(in_plane));
  } catch (const Error&) {
    return;
  }
  const double r = circle->radius_px;
  if ((q.centre_px - circle->centre_px).norm() > 0.02 * r || std::abs(q.radius_px - r) > 0.02 * r) {
    return;
  }
  q.outline_px = std::move(brighter_out);
  *circle = std::move(q);
}

// The light's brightness above the median, in linear light where the samples are sRGB-encoded:
// light adds to what the sphere shows in linear light, so an encoded lift over a bright
// background (a window mirrored beside the highlight) is compressed and a halo spanning it
// looks lopsided.
cv::Mat linear_lift(const cv::Mat& l, const cv::Mat& base, bool srgb) {
  if (!srgb) return l - base;
  cv::Mat lift(l.rows, l.cols, CV_32F);
  for (int y = 0; y < l.rows; ++y) {
    for (int x = 0; x < l.cols; ++x) {
      lift.at<float>(y, x) = static_cast<float>(to_linear(l.at<float>(y, x), true) -
                                                to_linear(base.at<float>(y, x), true));
    }
  }
  return lift;
}

// A clipped core's centre from the level set of the light's own lift rather than from the
// clip. The clip is reached where the light and the background together reach it, so a
// background brighter on one side moves the clipped region's edge that way; the lift above
// the stack's median, in linear light, is the light's alone and symmetric about it whatever
// lies behind. The level is the least room to the clip over the core's surroundings (within
// `core_r` + 3 px of `start`, window pixels), so a clipped pixel is certainly above it; each
// pixel counts by its soft membership, 0 at kLevelRampFrom of the level and below, 1 at the
// level and above (a clipped pixel), and the centre is the centroid of that membership. Below the
// ramp lies the halo, where the lit scene mirrored around the light lifts too and is not symmetric.
// Nothing where the surroundings leave less than half the clip level (a reflection bright in
// the median beside the light: the halo's symmetry decides there) or reach the window's or
// the sphere's edge. photo-chrome's highlights, 640 x 360, from the mirror highlights on
// average: in a lit room 0.11-0.13 px by the clip's edge, 0.05-0.10 px on the level set; in a
// dark room 0.088 to 0.069 px (seeds 1-8). The ramp from 0.75 of the level: from 0.5 or 0.9
// the lit room's lights (true circles given) were 0.01-0.06 degrees worse on average.
constexpr double kLevelRampFrom = 0.75;
std::optional<Eigen::Vector2d> level_centre(const cv::Mat& l, const cv::Mat& base,
                                            const std::function<bool(int, int)>& inside_win,
                                            const Eigen::Vector2d& start, double core_r,
                                            double clip_level, double clip_value, bool srgb) {
  const double reach = core_r + 3.0;
  const int r = static_cast<int>(std::ceil(reach));
  const int cx = static_cast<int>(std::lround(start.x()));
  const int cy = static_cast<int>(std::lround(start.y()));
  double level = clip_level;
  for (int y = cy - r; y <= cy + r; ++y) {
    for (int x = cx - r; x <= cx + r; ++x) {
      if ((Eigen::Vector2d(x, y) - start).norm() > reach) continue;
      if (x < 0 || y < 0 || x >= l.cols || y >= l.rows || !inside_win(x, y)) return {};
      level = std::min(level, clip_level - to_linear(base.at<float>(y, x), srgb));
    }
  }
  if (!(level > 0.5 * clip_level)) return {};
  double sw = 0.0, sx = 0.0, sy = 0.0;
  for (int y = cy - r; y <= cy + r; ++y) {
    for (int x = cx - r; x <= cx + r; ++x) {
      if ((Eigen::Vector2d(x, y) - start).norm() > reach) continue;
      double w = 1.0;
      if (l.at<float>(y, x) < clip_value) {
        const double lift =
            to_linear(l.at<float>(y, x), srgb) - to_linear(base.at<float>(y, x), srgb);
        w = std::clamp((lift / level - kLevelRampFrom) / (1.0 - kLevelRampFrom), 0.0, 1.0);
      }
      sw += w;
      sx += w * x;
      sy += w * y;
    }
  }
  if (!(sw > 0.0)) return {};
  return Eigen::Vector2d(sx / sw, sy / sw);
}

// The highlight in a window (photo pixels), `base` the stack's median there (same size),
// `inside` tells photo pixels on the sphere's searched disc, `srgb` that the samples are
// sRGB-encoded.
Located locate(const Window& win, const cv::Mat& base, const std::function<bool(int, int)>& inside,
               bool srgb, double core_radius_hint = 0.0, double compact_max_pixels = 0.0,
               const std::vector<Eigen::Vector2d>& skip_px = {}, double edge_r = 0.0) {
  Located out;
  std::optional<Eigen::Vector2d> disc_centre;  // window pixels, see cut_to_disc
  bool cut_by_shape = false;
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
    // Pixels clipped in the stack's median as well: a static reflection, not the light's.
    auto static_clip = [&](int x, int y) { return base.at<float>(y, x) >= 0.9 * top; };
    // Bright in the median (at least half the clip): a reflection there (a window, a lamp) can
    // be lifted to the clip by the light's glow, so such pixels are no evidence of the light's
    // core or its edge.
    auto bright_in_median = [&](int x, int y) { return base.at<float>(y, x) >= 0.5 * top; };
    // The light's clipped component is the thickest (a streak may be longer, never thicker):
    // the largest inscribed radius, then the larger area. Thickness counts the pixels that
    // are dark in the median (below half the clip): a static reflection clipped in every
    // image is no light's core, however thick, nor is a bright one (a lamp mirrored beside
    // the light) that only the light's glow lifts to the clip.
    cv::Mat moving = clipped.clone();
    for (int y = 0; y < l.rows; ++y) {
      for (int x = 0; x < l.cols; ++x) {
        if (bright_in_median(x, y)) moving.at<std::uint8_t>(y, x) = 0;
      }
    }
    cv::Mat cpad, cdist;
    cv::copyMakeBorder(moving, cpad, 1, 1, 1, 1, cv::BORDER_CONSTANT, cv::Scalar(0));
    cv::distanceTransform(cpad, cdist, cv::DIST_L2, cv::DIST_MASK_PRECISE);
    std::vector<int> area(static_cast<std::size_t>(k), 0);
    std::vector<float> depth(static_cast<std::size_t>(k), 0.0f);
    std::vector<Eigen::Vector2d> sum(static_cast<std::size_t>(k), Eigen::Vector2d::Zero());
    for (int y = 0; y < l.rows; ++y) {
      for (int x = 0; x < l.cols; ++x) {
        const auto j = static_cast<std::size_t>(labels.at<int>(y, x));
        ++area[j];
        depth[j] = std::max(depth[j], cdist.at<float>(y + 1, x + 1));
        sum[j] += Eigen::Vector2d(x + win.rect.x, y + win.rect.y);
      }
    }
    // Components already tried (a highlight taken there proved unusable): their centre within
    // a core's radius (at least 3 px) of a skipped point.
    auto skipped = [&](std::size_t j) {
      const Eigen::Vector2d c = sum[j] / std::max(1, area[j]);
      const double reach = std::max(3.0, std::sqrt(area[j] / std::numbers::pi));
      return std::any_of(skip_px.begin(), skip_px.end(),
                         [&](const Eigen::Vector2d& p) { return (p - c).norm() <= reach; });
    };
    // Given compact_max_pixels (glass), a component larger than a compact highlight can be is
    // passed over while a compact one is left: a glass ball's refracted hot spot is a broad
    // clipped area, and under a light near the camera's axis the surface reflection, a small
    // clipped dot, lies beside it or in its glow.
    auto compact = [&](std::size_t j) {
      return compact_max_pixels <= 0.0 || area[j] <= compact_max_pixels;
    };
    int best = 0;
    for (int j = 1; j < k; ++j) {
      const auto jj = static_cast<std::size_t>(j), bb = static_cast<std::size_t>(best);
      if (skipped(jj)) continue;
      const bool better = best == 0 || (compact(jj) && !compact(bb)) ||
                          (compact(jj) == compact(bb) &&
                           (depth[jj] > depth[bb] + 0.25f ||
                            (std::abs(depth[jj] - depth[bb]) <= 0.25f && area[jj] > area[bb])));
      if (better) best = j;
    }
    cv::Mat region = labels == best;
    // JPEG's noise leaves pixels of a clipped core a few levels below the clip; the opening
    // below would take a hole at the core's edge for a dent and cut the row around it (a
    // chrome core's centre 0.4-0.5 px off). Holes (unclipped pixels the core encloses) are
    // filled first.
    fill_holes(&region);
    for (int y = 0; y < l.rows && !out.touches_static; ++y) {
      for (int x = 0; x < l.cols; ++x) {
        if (region.at<std::uint8_t>(y, x) && static_clip(x, y)) {
          out.touches_static = true;
          break;
        }
      }
    }
    // How far a pixel's brightness climbs from the median toward the clip level, 0..1, in
    // linear light where the samples are sRGB-encoded (see linear_lift).
    const double clip_level = to_linear(0.98 * top, srgb);
    auto edge_weight = [&](int x, int y) {
      const double b = to_linear(base.at<float>(y, x), srgb);
      const double v = to_linear(l.at<float>(y, x), srgb) - b;
      const double room = clip_level - b;
      // Where the median itself is (nearly) clipped, the image says nothing of the light.
      return room > 1e-3 ? std::clamp(v / room, 0.0, 1.0) : 0.0;
    };
    if (core_radius_hint > 0.0) {
      // Only a boundary pixel dark in the median is the light's edge: where the median is
      // bright the pixel belongs to a reflection beside the light (a window, a lamp) which
      // the light's glow has lifted to the clip. Beside a static clipped reflection, only
      // one with an unclipped neighbour lit above the median (the light's halo) as well.
      auto light_edge = [&](int x, int y) {
        if (bright_in_median(x, y)) return false;
        if (!out.touches_static) return true;
        constexpr int kDx[4] = {1, -1, 0, 0}, kDy[4] = {0, 0, 1, -1};
        for (int d = 0; d < 4; ++d) {
          const int nx = x + kDx[d], ny = y + kDy[d];
          if (nx < 0 || ny < 0 || nx >= l.cols || ny >= l.rows || region.at<std::uint8_t>(ny, nx))
            continue;
          const double b = base.at<float>(ny, nx);
          if (l.at<float>(ny, nx) - b >= 0.25 * (top - b) && !static_clip(nx, ny)) return true;
        }
        return false;
      };
      disc_centre = cut_to_disc(&region, core_radius_hint, light_edge, edge_weight,
                                out.touches_static, edge_r, &cut_by_shape);
    }
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
    if (core_radius_hint <= 0.0 && !out.touches_static) {
      // The whole core's edge, placed as cut_to_disc places an arc's (edge_point), where the
      // next pixel out has left the clipped region.
      std::vector<Eigen::Vector2d> edge;
      for (int y = 0; y < l.rows; ++y) {
        for (int x = 0; x < l.cols; ++x) {
          if (!on_mask_edge(core, x, y)) continue;
          const auto e = edge_point({x, y}, c0, l.cols, l.rows, edge_weight);
          if (e && !region.at<std::uint8_t>(e->next)) edge.push_back(e->px);
        }
      }
      if (edge.size() >= 8) {
        try {
          out.edge_radius_px = detail::fit_circle(edge).radius_px;
        } catch (const Error&) {
          // Collinear or too few points: no radius from this core.
        }
      }
    }
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
    const cv::Mat spot_lift = linear_lift(l, base, srgb);
    for (int y = 0; y < l.rows; ++y) {
      for (int x = 0; x < l.cols; ++x) {
        if (!spot.at<std::uint8_t>(y, x) || !inside(x + win.rect.x, y + win.rect.y)) continue;
        const double v = spot_lift.at<float>(y, x);
        samples.emplace_back(x + win.rect.x, y + win.rect.y, std::max(0.0, v));
      }
    }
  }
  shape(samples, &out);
  if (out.ok && out.saturated && !disc_centre && !out.touches_static &&
      out.pixels > kSmallCorePixels) {
    // A larger core's edge, on the level set of the light's lift (level_centre), its window
    // centred on it (three passes settle it).
    const double core_r = std::sqrt(out.pixels / std::numbers::pi);
    Eigen::Vector2d c(out.px.x() - win.rect.x, out.px.y() - win.rect.y);
    const auto inside_win = [&](int x, int y) { return inside(x + win.rect.x, y + win.rect.y); };
    for (int it = 0; it < 3; ++it) {
      const auto lc = level_centre(l, base, inside_win, c, core_r, to_linear(0.98 * top, srgb),
                                   static_cast<float>(0.98 * top), srgb);
      if (!lc) break;
      c = *lc;
      if (it == 2) out.px = {c.x() + win.rect.x, c.y() + win.rect.y};
    }
  }
  if (out.ok && disc_centre) {
    out.disc_cut = true;
    out.px = {disc_centre->x() + win.rect.x, disc_centre->y() + win.rect.y};
  }
  if (out.ok &&
      (disc_centre ? out.touches_static : out.pixels <= kSmallCorePixels || out.saturated)) {
    // A core of a few pixels has too few edge pixels to pin its centre (about 0.15 px on the
    // photographic renders); its halo's symmetry pins it to about 0.04 px. A larger core (a
    // mirror sphere's image of the light, a flat disc with a sharp edge) is located well by
    // its edge, to a few hundredths of a pixel, and its surroundings (the lit scene mirrored
    // around it) are not symmetric; but the clip is reached where the light and the
    // background together reach it, so a background much brighter on one side moves the edge
    // there: where the halo's centre of symmetry is more than kEdgeVsHaloPx from the edge's
    // centre, the halo's is taken (photo-chrome's worst light 0.78-1.45 to 0.50-0.67 degrees
    // on seeds 1 and 3). The symmetry is measured on the lift in linear light, without
    // clipped pixels (their lift is cut short by the clip, the more so over a bright
    // background): photo-dome's worst light error 0.62-1.43 to 0.18-0.27 degrees. Where the
    // core touches a reflection clipped in the median (the light falling on a mirrored
    // window), the pixels bright in the median are left out too: the light's glow lifts
    // them to the clip unevenly (the window's blurred edges, JPEG's ringing there), and only
    // the halo over the dark surroundings tells where the light is (lit chrome at 2560 x
    // 1440, two lights on a window: 2.1-4.5 px off to 0.2-0.5 px). A disc cut from such a
    // reflection (cut_to_disc) has both: its arc errs where it is short, the halo where the
    // dark around the light is mostly on one side, and neither error predicts the other, so
    // where the halo settles the two are averaged (photo-chrome at 640 x 360 in a dark room,
    // seeds 1-16: mean light error 0.198 to 0.183 degrees, worst 0.72 to 0.56; the halo alone
    // 0.205 and 0.96).
    const cv::Mat lift = linear_lift(l, base, srgb);
    const double core_r = std::sqrt(std::max(1, out.pixels) / std::numbers::pi);
    const double radius = std::max(4.0, 2.0 * core_r + 2.0);
    const Eigen::Vector2d start(out.px.x() - win.rect.x, out.px.y() - win.rect.y);
    const auto measured = [&](int x, int y) {
      return x >= 0 && y >= 0 && x < l.cols && y < l.rows &&
             inside(x + win.rect.x, y + win.rect.y) &&
             !(out.saturated && l.at<float>(y, x) >= 0.98 * top) &&
             !(out.touches_static && base.at<float>(y, x) >= 0.5 * top);
    };
    bool settled = false;
    const Eigen::Vector2d c =
        symmetric_centre(lift, start, radius, std::max(1.0, core_r), measured, &settled);
    out.cut_unsupported = cut_by_shape && !settled;
    out.halo_settled = settled;
    const Eigen::Vector2d halo(c.x() + win.rect.x, c.y() + win.rect.y);
    if (disc_centre) {
      // Far apart (kDiscVsHaloPx), the arc was cut where the light's image is not round
      // (lit chrome at +-1 EV: a disc 4.6 px off, its halo 0.8): the halo alone is taken.
      if (settled) {
        const bool apart =
            (halo - out.px).norm() > std::max(kDiscVsHaloPx, kDiscVsHaloCoreRadii * core_r);
        out.px = apart ? halo : Eigen::Vector2d(0.5 * (out.px + halo));
      }
    } else if (out.pixels <= kSmallCorePixels || (halo - out.px).norm() > kEdgeVsHaloPx) {
      out.px = halo;
    }
  }
  return out;
}

// A composite contrast-stretched (of the logarithm if asked) and smoothed by a 1 px Gaussian:
// what rim_circle and outer_rim look for edges on.
cv::Mat smoothed(const cv::Mat& plane, bool logarithm) {
  cv::Mat f = stretch(plane, CV_32F, logarithm);
  cv::GaussianBlur(f, f, cv::Size(0, 0), 1.0);
  return f;
}

// The rim circle near `around` on a composite prepared by smoothed(): the consensus of the
// strongest edges on 360 rays, refitted to the points against brighter surroundings where both
// kinds are present; circles are fitted in `op` (the outline under the camera: OutlinePlane).
// `rim`: the share of rays supporting it; `tight`: the share whose edge lies within kTightRimPx of
// it (how sharp a rim the plane shows).
Circle rim_circle(const cv::Mat& f, const Circle& around, const OutlinePlane& op, double* rim,
                  double* tight = nullptr) {
  int inside = 0;
  auto e = ray_edges(f, around.centre_px, around.radius_px, &inside, kRimRefineBand);
  for (Eigen::Vector2d& p : e) p = op.to(p);
  Circle r = op.from(consensus_circle(e, op.to(around), rim, kRimChoiceTolPx));
  rim_against_brighter(f, op, &r);
  if (tight != nullptr) {
    // In the outline plane, whose units are the plane's pixels.
    const Circle q = op.to(r);
    int n = 0;
    for (const Eigen::Vector2d& p : e) {
      if (std::abs((p - q.centre_px).norm() - q.radius_px) <= kTightRimPx) ++n;
    }
    *tight = n / 360.0;
  }
  return r;
}

// A rim outside `inner` on a composite prepared by smoothed() (linear): per ray, the strongest edge
// between inner's radius plus max(2 px, kConcentricRimGap r) and (1 + kRimRefineBand) r that is an
// edge of its own (the gradient falls below half its height between it and inner's rim, so inner's
// blurred flank is not taken), and the circle those edges agree on; `rim`: the share of rays
// supporting it.
Circle outer_rim(const cv::Mat& f, const Circle& inner, const OutlinePlane& op, double* rim) {
  constexpr int kRays = 360;
  const double r0 = inner.radius_px;
  const double step = std::clamp(r0 / 200.0, 0.35, 1.0);
  const double t_min = r0 + std::max(2.0, kConcentricRimGap * r0);
  std::vector<Eigen::Vector2d> pts;
  std::vector<double> prof, g;
  for (int k = 0; k < kRays; ++k) {
    const double a = 2.0 * std::numbers::pi * k / kRays;
    const Eigen::Vector2d dir(std::cos(a), std::sin(a));
    ray_profile(f, inner.centre_px, dir, r0, (1.0 + kRimRefineBand) * r0, step, &prof);
    if (prof.size() < 5) continue;
    g.assign(prof.size(), 0.0);
    for (std::size_t i = 1; i + 1 < prof.size(); ++i) {
      g[i] = std::abs(prof[i + 1] - prof[i - 1]) / (2.0 * step);
    }
    const auto first = static_cast<std::size_t>(std::ceil((t_min - r0) / step));
    double best = 0.0;
    std::size_t bi = 0;
    double valley = g[1];
    for (std::size_t i = 2; i + 1 < g.size(); ++i) {
      valley = std::min(valley, g[i - 1]);
      if (i < first || g[i] < 2.0 || g[i] < g[i - 1] || g[i] < g[i + 1]) continue;
      if (valley > 0.5 * g[i] || g[i] <= best) continue;
      best = g[i];
      bi = i;
    }
    if (bi > 0) {
      pts.push_back(
          op.to(Eigen::Vector2d(inner.centre_px + (r0 + static_cast<double>(bi) * step) * dir)));
    }
  }
  Circle around = inner;
  around.radius_px *= 1.0 + 0.5 * kRimRefineBand;
  return op.from(consensus_circle(pts, op.to(around), rim, kRimChoiceTolPx));
}

// The rim taken, located once more on the photo-size composite it was found on, free of what
// served to find it but moves where it lies (rim_circle):
// - on the rays of the edge points that supported it, from the circle's own centre, within
//   kPolishBandPx of it: the search's rays start from the candidate's centre, a pixel or two
//   off, and cross the edge obliquely;
// - in linear light: a pixel integrates radiance, so a blurred edge in linear light keeps its
//   place, while the sRGB encoding stretches a dark side's structure (the dark band inside a
//   black ball's limb, where it mirrors the cloth it shades) and moves the steepest point;
// - stretched between the band's own 1st and 99th percentiles and not clipped: the search's
//   stretch clips the frame's darkest hundredth, often a black ball's inside, and a flattened
//   inner side moves the steepest point outward;
// - smoothed by kPolishSigmaPx, not 1 px: smoothing moves an edge with a darker band inside
//   and a brighter skirt outside toward the skirt.
// - on a sphere whose limb's climb is resolved (kLimbMinRadiusPx), by the limb's own profile
//   where that explains the ray better than a step (LimbProfileModel): a black ball against a
//   lit wall brightens over its last pixels as its reflectance rises to 1, and the steepest
//   point of that climb lies 0.5-0.8 px inside the outline (photo-large-sphere in a lit room,
//   seeds 1-3: circles 0.25-0.39% small, lights 0.33-0.48 degrees mean; on the limb 0.06-0.09%,
//   0.10-0.11 degrees). `limb_rays_out` gets the rays so located where the polished circle is
//   returned (0 otherwise).
// The polished circle replaces the rim's where it keeps kPolishSupport of the edge points and
// lies within kPolishMaxMovePx. On the photographic renders (640 x 360, seeds 1-3), black
// glossy balls lying on the cloth: light means 0.55-0.63 to 0.29-0.36 degrees in a dark room;
// the other presets' means move by -0.22 to +0.06 (docs/CALIBRATION.md).
Circle polish_rim(const cv::Mat& plane, const Circle& rim, const OutlinePlane& op, bool srgb,
                  int* limb_rays_out) {
  if (limb_rays_out != nullptr) *limb_rays_out = 0;
  if (rim.outline_px.size() < 8) return rim;
  // The region the rays and the smoothing reach.
  const double reach = rim.radius_px + kPolishBandPx + 3.0 * kPolishSigmaPx + 2.0;
  const int x0 = std::max(0, static_cast<int>(std::floor(rim.centre_px.x() - reach)));
  const int y0 = std::max(0, static_cast<int>(std::floor(rim.centre_px.y() - reach)));
  const int x1 = std::min(plane.cols, static_cast<int>(std::ceil(rim.centre_px.x() + reach)) + 1);
  const int y1 = std::min(plane.rows, static_cast<int>(std::ceil(rim.centre_px.y() + reach)) + 1);
  if (x1 - x0 < 8 || y1 - y0 < 8) return rim;
  const Eigen::Vector2d at(x0, y0);
  cv::Mat f(y1 - y0, x1 - x0, CV_32F);
  for (int y = 0; y < f.rows; ++y) {
    const float* in = plane.ptr<float>(y0 + y) + x0;
    float* out = f.ptr<float>(y);
    for (int x = 0; x < f.cols; ++x) out[x] = static_cast<float>(to_linear(in[x], srgb));
  }
  const Eigen::Vector2d centre = rim.centre_px - at;
  const auto in_region = [&](const Eigen::Vector2d& p) {
    return p.x() >= 0.0 && p.y() >= 0.0 && p.x() <= f.cols - 1.001 && p.y() <= f.rows - 1.001;
  };
  // The band's levels: every half pixel along every tenth ray.
  std::vector<float> levels;
  for (int k = 0; k < 360; k += 10) {
    const double a = 2.0 * std::numbers::pi * k / 360.0;
    const Eigen::Vector2d dir(std::cos(a), std::sin(a));
    for (double t = -kPolishBandPx; t <= kPolishBandPx; t += 0.5) {
      const Eigen::Vector2d p = centre + (rim.radius_px + t) * dir;
      if (in_region(p)) levels.push_back(static_cast<float>(sample_bilinear(f, p)));
    }
  }
  if (levels.size() < 20) return rim;
  std::sort(levels.begin(), levels.end());
  const float lo = levels[levels.size() / 100], hi = levels[levels.size() * 99 / 100];
  if (!(hi - lo > 1e-6f)) return rim;
  const cv::Mat lin = f.clone();  // linear light, for the limb's profile
  f.convertTo(f, CV_32F, 255.0 / (hi - lo), -255.0 * lo / (hi - lo));
  cv::GaussianBlur(f, f, cv::Size(0, 0), kPolishSigmaPx);
  std::vector<Eigen::Vector2d> pts;
  const double t0 = rim.radius_px - kPolishBandPx, t1 = rim.radius_px + kPolishBandPx;
  // Only where the limb's climb spans more than the blur (kLimbMinRadiusPx).
  std::optional<LimbProfileModel> limb;
  if (rim.radius_px >= kLimbMinRadiusPx) limb.emplace(rim.radius_px);
  const double l0 = rim.radius_px - kLimbInsidePx, l1 = rim.radius_px + kLimbOutsidePx;
  int limb_rays = 0;
  std::vector<double> prof;
  for (const Eigen::Vector2d& q : rim.outline_px) {
    const Eigen::Vector2d d = q - rim.centre_px;
    if (!(d.norm() > 0.0)) continue;
    const Eigen::Vector2d dir = d.normalized();
    double t = 0.0;
    bool found = in_region(centre + t0 * dir) && in_region(centre + t1 * dir) &&
                 edge_on_ray(f, centre, dir, t0, t1, kPolishStepPx, &t);
    if (limb && in_region(centre + l0 * dir) && in_region(centre + l1 * dir)) {
      ray_profile(lin, centre, dir, l0, l1 + 1e-9, kPolishStepPx, &prof);
      const LimbProfileModel::Fit fit = limb->fit(prof, l0, kPolishStepPx, t0, t1);
      // Where the ray shows a climb well above the fit's residual: the limb's outline where its
      // model is clearly the better; elsewhere the steepest point as before, or the step's
      // place on a ray whose edge is too faint for the stretched composite.
      if (fit.valid && fit.limb_amplitude > kLimbMinContrast * fit.limb_rms) {
        if (fit.limb_sse < kLimbEvidence * fit.step_sse) {
          t = fit.limb_px;
          found = true;
          ++limb_rays;
        } else if (!found) {
          t = fit.step_px;
          found = true;
        }
      }
    }
    if (found) pts.push_back(op.to(rim.centre_px + t * dir));
  }
  double share = 0.0;
  const Circle r = op.from(consensus_circle(pts, op.to(rim), &share, kRimChoiceTolPx));
  if (static_cast<double>(r.outline_px.size()) <
      kPolishSupport * static_cast<double>(rim.outline_px.size())) {
    return rim;
  }
  if ((r.centre_px - rim.centre_px).norm() > kPolishMaxMovePx ||
      std::abs(r.radius_px - rim.radius_px) > kPolishMaxMovePx) {
    return rim;
  }
  if (limb_rays_out != nullptr) *limb_rays_out = limb_rays;
  return r;
}

struct Want {
  int image = 0;
  int sphere = 0;
  cv::Rect rect;  // photo pixels
  // The other of two comparable spots, tried only when the one taken proves unusable.
  int alternate_rank = -1;
};

// The spheres found disagree about most lights (kMostLightsDisagree): what run() throws, for
// run_searches() to try the second search.
class Disagreement : public SphereSearchError {
 public:
  using SphereSearchError::SphereSearchError;
};

// The options checked and the stack's evidence gathered (one pass over the photographs), with
// the reference photo if one is given: what both searches read.
Evidence prepare(const Source& src, const std::vector<fs::path>& names,
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
  Evidence ev = gather(src, so.analysis_max_side_px);
  if (so.reference) {
    const Image ref = read_image(*so.reference);
    if (ref.width() != ev.w || ref.height() != ev.h) {
      throw Error(where(*so.reference) + ": the reference photo's size differs from the images'");
    }
    ev.reference = luma_plane(ref);
  }
  return ev;
}

// One search on the evidence: the spheres (found, or given), then their highlights in windows
// of the photographs (a second pass over them). `second_search`: see run_searches.
StackCalibration run(const Source& src, const std::vector<fs::path>& names,
                     const StackCalibrationOptions& options, const Evidence& ev,
                     bool second_search) {
  const RigOptions& rig = options.rig;
  const SphereSearchOptions& so = options.search;
  StackCalibration out;
  out.camera = rig.detection.camera;
  out.analysis_scale = ev.scale;
  if (ev.camera_moved) out.image_shifts_px = ev.shifts_px;
  out.image_shifts_undone = ev.undo_shifts;
  out.width = ev.w;
  out.height = ev.h;
  const SphereOptions& det = rig.detection;
  std::vector<Circle> circles = rig.spheres;
  const bool detected = circles.empty();
  if (detected) {
    std::vector<Circle> small;
    out.candidates =
        find_candidates(ev, so, det.min_peak, rig.sphere_count, det.camera, &small, second_search);
    // Full-resolution rim: the consensus circle on the photo-size composite where the rim
    // shows best (at scale 1 the analysis already was at full resolution).
    // Still composites first (the median exists at photo size only at scale 1).
    std::vector<std::pair<std::string, const cv::Mat*>> planes;
    if (ev.scale == 1) planes.emplace_back("stack's median", &ev.small_median);
    if (!ev.reference.empty()) planes.emplace_back("reference photo", &ev.reference);
    planes.emplace_back("stack's mean", &ev.full_mean);
    planes.emplace_back("stack's maximum", &ev.full_max);
    const OutlinePlane photo_plane(det.camera, ev.w, ev.h, 1);
    const OutlinePlane small_plane(det.camera, ev.w, ev.h, ev.scale);
    std::vector<SphereCandidate*> chosen;
    for (SphereCandidate& cand : out.candidates) {
      if (cand.chosen) chosen.push_back(&cand);
    }
    for (std::size_t ci = 0; ci < small.size(); ++ci) {
      const Circle& c = small[ci];
      SphereCandidate& cand = *chosen.at(ci);
      // A rim circle stands for the candidate when its centre and radius each lie within 5% of
      // the radius (plus an analysis pixel) of the candidate's, and it reflects no more of the
      // candidate's light spots to below the sample plane (an edge inside the outline, such as
      // the horizon mirrored in a chrome ball, lies within 5% on a large sphere's lit rim).
      const auto keeps_lights_above = [&](const Circle& r) {
        return below_plane_spots(cand, r, det.camera, ev, 1) <= cand.below_plane_spots;
      };
      // A glass ball's outline found in the maximum (SphereCandidate::glass_outline): the
      // median's edges inside it are the room seen through the glass.
      const auto outside_glass_floor = [&](const Circle& r) {
        return !cand.glass_outline || r.radius_px >= (1.0 - kGlassOutlineSlack) * c.radius_px;
      };
      const auto near_candidate = [&](const Circle& r) {
        const double tol = 0.05 * c.radius_px + ev.scale;
        return (r.centre_px - c.centre_px).norm() < tol &&
               std::abs(r.radius_px - c.radius_px) < tol && keeps_lights_above(r) &&
               outside_glass_floor(r);
      };
      Circle best = c;
      double best_rim = 0.0, best_tight = 0.0;
      // The photo-size composite `best` was measured on, if it was (polish_rim).
      const cv::Mat* best_plane = nullptr;
      // Of the composites' rims the best supported (on equal support the first: what holds
      // still). Linear brightness first: the logarithm shows a faint rim but moves a clear
      // one's steepest point toward its dark side, so it is tried only where no composite
      // shows a rim on 0.3 of the rays. Where a dark cup, the spheres' shadows or the dark
      // room border part of the limb in the median, the edge taken there lies off the
      // outline, and the maximum or the mean, where the lights lit those surroundings, show
      // the rim on more rays (photo-dome under 18 lights, 10 of them 75-84 degrees up: rims
      // on 0.63-0.65 of the rays in the median, 0.92-0.93 in the maximum; circles 0.17-0.32
      // px off against 0.03-0.06 px).
      for (const bool logarithm : {false, true}) {
        for (const auto& [name, plane] : planes) {
          double rim = 0.0, tight = 0.0;
          const Circle r = rim_circle(smoothed(*plane, logarithm), c, photo_plane, &rim, &tight);
          if (rim > best_rim && near_candidate(r)) {
            best_rim = rim;
            best_tight = tight;
            best = r;
            best_plane = plane;
          }
        }
        if (best_rim >= 0.3) break;
      }
      // The rims of the analysis-size still composites: the first of linear and logarithmic
      // brightness supported by 0.3 of the rays (the lower quartile's also near the
      // candidate: where the sphere's shadows darken its surroundings in a quarter of the
      // images, it can show another circle).
      Circle cs;
      cs.centre_px = small_px(c.centre_px, ev.scale);
      cs.radius_px = c.radius_px / ev.scale;
      struct StillRim {
        Circle circle;
        double rim = 0.0, tight = 0.0;
        bool found = false;
      };
      auto still_rim = [&](const cv::Mat& plane, const OutlinePlane& op, bool must_be_near) {
        StillRim sr;
        for (const bool logarithm : {false, true}) {
          const Circle r = rim_circle(smoothed(plane, logarithm), cs, op, &sr.rim, &sr.tight);
          if (sr.rim < 0.3) continue;
          sr.circle = to_photo(r, ev.scale);
          sr.found = must_be_near ? near_candidate(sr.circle)
                                  : keeps_lights_above(sr.circle) && outside_glass_floor(sr.circle);
          break;
        }
        return sr;
      };
      // Under lights near the camera's axis a glass ball's refracted hot spot glows over its
      // limb, and with few lights that glow is in the median of the images too, blurring the
      // rim there into a ramp (rings:15:3,40:3,65:2,80:4 at 1280 x 720: 0.66-0.69 px off on
      // one marble). The lower quartile keeps the rim sharp where the glow does not cover it
      // in most images; it is taken where more rays' edges lie within kTightRimPx of its
      // circle than of the one chosen above (at scale 1, the best-supported composite's; at
      // scale > 1, the block median's, below).
      const StillRim lower = still_rim(ev.small_lower_quartile, small_plane, true);
      if (ev.scale == 1) {
        if (lower.found && lower.tight > best_tight) {
          best = lower.circle;
          best_plane = &ev.small_lower_quartile;  // at scale 1, photo size
        }
      } else {
        // At scale > 1 the photo-size composites hold what moves (a glass ball's caustics
        // and refracted hot spots beside its limb, flares): the rim is measured on the
        // median of the block means too (or their lower quartile, as above), at the
        // analysis size, and taken where clearly more rays support it
        // (kBlockMedianRimMargin; glass at 1600 x 900: 0.4 to 0.02-0.03 px off).
        StillRim still = still_rim(ev.small_block_median, small_plane, false);
        if (lower.found && (!still.found || lower.tight > still.tight)) still = lower;
        if (still.found && still.rim > best_rim + kBlockMedianRimMargin) {
          best = still.circle;
          best_plane = nullptr;
        }
      }
      // Of two concentric rims, the outer (kConcentricRimMin): looked for outside the rim taken
      // and outside the candidate's circle (the rim taken can mix the ring and the outline,
      // off the centre of both).
      {
        const Circle inner = best;
        double outer_best = 0.0;
        for (const auto& [name, plane] : planes) {
          const cv::Mat f = smoothed(*plane, false);  // once per composite, for both circles
          for (const Circle& from : {inner, c}) {
            double rim = 0.0;
            const Circle r = outer_rim(f, from, photo_plane, &rim);
            if (rim >= kConcentricRimMin && rim > outer_best &&
                (r.centre_px - from.centre_px).norm() < 0.05 * from.radius_px &&
                r.radius_px > (1.0 + kConcentricRimGap) * from.radius_px &&
                r.radius_px > (1.0 + kConcentricRimGap) * inner.radius_px &&
                keeps_lights_above(r)) {
              outer_best = rim;
              best = r;
              best_plane = plane;
            }
          }
        }
        if (outer_best > 0.0) {
          char buf[160];
          std::snprintf(buf, sizeof(buf),
                        "; outline at r %.1f px, outside a concentric rim at r %.1f px",
                        best.radius_px, inner.radius_px);
          cand.note += buf;
        }
      }
      // Only rims measured at photo size are polished: a block plane (scale > 1) averages the
      // encoded samples across each block, mixing an edge's two sides after encoding, which
      // decoding does not undo (glass at 640 x 360 analysed at scale 2: circles 0.01-0.08%
      // off on the block median, 0.16-0.50% once polished there).
      if (best_plane != nullptr) {
        int limb_rays = 0;
        const Circle polished = polish_rim(*best_plane, best, photo_plane, ev.srgb, &limb_rays);
        if (limb_rays > 0) {
          char buf[160];
          std::snprintf(buf, sizeof(buf), "; outline on the limb's profile on %d of %zu rays",
                        limb_rays, best.outline_px.size());
          cand.note += buf;
        }
        best = polished;
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
  std::vector<std::vector<std::vector<Spot>>> spots_of(
      k_spheres, std::vector<std::vector<Spot>>(static_cast<std::size_t>(ev.n)));
  std::vector<double> gains;
  {
    std::vector<Eigen::Vector2d> cs;
    std::vector<double> rs;
    for (const Circle& c : circles) {
      cs.push_back(small_px(c.centre_px, s));
      rs.push_back(det.search_radius_fraction * c.radius_px / s);
    }
    gains = exposure_gains(ev, cs, rs);
    // A steady capture's gains scatter a little about 1: below kExposureVaries the exposure
    // is taken as steady and the median left as it is.
    if (!exposure_varies(gains)) {
      std::fill(gains.begin(), gains.end(), 1.0);
    } else {
      out.exposure_gains = gains;
    }
  }
  for (std::size_t k = 0; k < k_spheres; ++k) {
    const Circle& c = circles[k];
    reports[k].sphere = c;
    reports[k].sphere_detected = detected;
    reports[k].lights.resize(static_cast<std::size_t>(ev.n));
    const Eigen::Vector2d cs = small_px(c.centre_px, s);
    const double rs = det.search_radius_fraction * c.radius_px / s;
    for (int i = 0; i < ev.n; ++i) {
      reports[k].lights[static_cast<std::size_t>(i)].image = names[static_cast<std::size_t>(i)];
      spots_of[k][static_cast<std::size_t>(i)] =
          moving_spots(ev, i, cs, rs, det.min_peak, gains[static_cast<std::size_t>(i)]);
    }
  }
  // Spots too faint to be a light's reflection (kLightLiftShare) are dropped; an image left
  // without one says so.
  std::vector<std::vector<double>> faint_lift(
      k_spheres, std::vector<double>(static_cast<std::size_t>(ev.n), 0.0));
  std::vector<double> light_lift(k_spheres, 0.0);
  for (std::size_t k = 0; k < k_spheres; ++k) {
    std::vector<double> brightest;
    for (const std::vector<Spot>& spots : spots_of[k]) {
      double b = 0.0;
      for (const Spot& sp : spots) b = std::max(b, sp.lift_linear);
      if (!spots.empty()) brightest.push_back(b);
    }
    if (brightest.empty()) continue;
    light_lift[k] = highlight_lift(std::move(brightest));
    for (std::size_t ii = 0; ii < spots_of[k].size(); ++ii) {
      std::vector<Spot>& spots = spots_of[k][ii];
      for (const Spot& sp : spots) faint_lift[k][ii] = std::max(faint_lift[k][ii], sp.lift_linear);
      std::erase_if(
          spots, [&](const Spot& sp) { return sp.lift_linear < kLightLiftShare * light_lift[k]; });
    }
  }
  // Which spot is the light's reflection: the brightest (a saturated one: the larger), unless
  // with two or more spheres a second spot of comparable lift gives a direction that agrees
  // with the other spheres' far better. A glass ball's refracted hot spot (the light it
  // focuses, seen through it) can be larger than its reflection and does not obey mirror
  // geometry; the reflections on every sphere agree on one distant light.
  // Sphere k shows two comparable spots in image ii.
  auto two_spots = [&](std::size_t k, std::size_t ii) {
    return two_comparable_spots(spots_of[k][ii]);
  };
  std::vector<std::vector<int>> rank(k_spheres, std::vector<int>(static_cast<std::size_t>(ev.n)));
  // Per image: the choice agrees across spheres better than every other by the margin.
  std::vector<char> settled(static_cast<std::size_t>(ev.n), 0);
  if (k_spheres >= 2 && k_spheres <= 4) {
    for (int i = 0; i < ev.n; ++i) {
      const auto ii = static_cast<std::size_t>(i);
      std::vector<int> choices(k_spheres, 1);
      bool ambiguous = false;
      for (std::size_t k = 0; k < k_spheres; ++k) {
        if (spots_of[k][ii].empty()) choices[k] = 0;
        if (two_spots(k, ii)) {
          choices[k] = 2;
          ambiguous = true;
        }
      }
      if (!ambiguous) continue;
      // Each sphere's direction for its first and second spot, once.
      std::vector<std::array<Eigen::Vector3d, 2>> dir(k_spheres);
      for (std::size_t k = 0; k < k_spheres; ++k) {
        for (int r = 0; r < choices[k]; ++r) {
          const Eigen::Vector2d px =
              photo_px(spots_of[k][ii][static_cast<std::size_t>(r)].centre_small, s);
          dir[k][static_cast<std::size_t>(r)] =
              reflect_highlight(circles[k], det.camera, px, ev.w, ev.h);
        }
      }
      // Every combination (at most 2^4), scored by the sum of pairwise angles (degrees).
      auto cost = [&](const std::vector<int>& pick) {
        double sum = 0.0;
        for (std::size_t a = 0; a < k_spheres; ++a) {
          for (std::size_t b = a + 1; b < k_spheres; ++b) {
            if (choices[a] == 0 || choices[b] == 0) continue;
            const double c = dir[a][static_cast<std::size_t>(pick[a])].dot(
                dir[b][static_cast<std::size_t>(pick[b])]);
            sum += std::acos(std::clamp(c, -1.0, 1.0)) * 180.0 / std::numbers::pi;
          }
        }
        return sum;
      };
      std::vector<int> pick(k_spheres, 0);
      const double brightest = cost(pick);
      double best_cost = brightest;
      int best = 0;  // bit k: sphere k's rank
      const int combos = 1 << k_spheres;
      std::vector<std::pair<int, double>> costs;  // valid combinations (bit k: sphere k's rank)
      costs.emplace_back(0, brightest);
      for (int m = 1; m < combos; ++m) {
        bool valid = true;
        for (std::size_t k = 0; k < k_spheres; ++k) {
          pick[k] = (m >> k) & 1;
          if (pick[k] >= std::max(1, choices[k])) valid = false;
        }
        if (!valid) continue;
        const double c = cost(pick);
        costs.emplace_back(m, c);
        if (c < best_cost) {
          best_cost = c;
          best = m;
        }
      }
      // The spots' coarse positions (analysis pixels) give directions to a degree or two; a
      // refracted spot is tens of degrees off.
      int chosen = 0;
      double chosen_cost = brightest;
      if (best_cost < brightest - kSpotAgreementMarginDeg) {
        for (std::size_t k = 0; k < k_spheres; ++k) rank[k][ii] = (best >> k) & 1;
        chosen = best;
        chosen_cost = best_cost;
      }
      int seen = 0;
      for (std::size_t k = 0; k < k_spheres; ++k) seen += choices[k] > 0 ? 1 : 0;
      bool clear = seen >= 2;
      for (const auto& [m, c] : costs) {
        if (m != chosen && c < chosen_cost + kSpotAgreementMarginDeg) clear = false;
      }
      settled[ii] = clear ? 1 : 0;
    }
  }
  // A glass ball's refracted hot spot lies across the centre from its surface reflection (the
  // ball focuses the light on its far side); a second spot beside the first (a flare's spoke,
  // a reflection of the lit scene) says nothing of glass.
  int across = 0;
  for (int i = 0; i < ev.n; ++i) {
    bool two = false, opposite = false;
    for (std::size_t k = 0; k < k_spheres; ++k) {
      const auto ii = static_cast<std::size_t>(i);
      if (!two_spots(k, ii)) continue;
      two = true;
      if (spots_across(spots_of[k][ii], small_px(circles[k].centre_px, s))) opposite = true;
    }
    out.two_spot_images += two ? 1 : 0;
    across += opposite ? 1 : 0;
  }
  if (options.material == SphereMaterial::kAuto) {
    const bool glass = glass_from_spots(across, ev.n);
    out.material = glass ? SphereMaterial::kGlass : SphereMaterial::kMirror;
    out.material_note = "decided from the stack: " + std::to_string(across) + " of " +
                        std::to_string(ev.n) +
                        " images show a second comparable spot across the sphere's centre (" +
                        (glass ? "at least" : "fewer than") + " a quarter)";
  } else {
    out.material = options.material;
    out.material_note = "given (--sphere-material)";
  }
  // On glass, the refracted hot spot's glow told from the light's reflection by its size
  // (reflection_spot_area, not_a_reflection): where no spot of an image is left, its reflection
  // is hidden.
  std::vector<std::vector<char>> glow_only(k_spheres,
                                           std::vector<char>(static_cast<std::size_t>(ev.n), 0));
  if (out.material == SphereMaterial::kGlass) {
    for (std::size_t k = 0; k < k_spheres; ++k) {
      if (circles[k].radius_px < kGlowRuleMinRadiusPx) continue;
      const std::optional<double> area = reflection_spot_area(spots_of[k]);
      if (!area) continue;
      for (int i = 0; i < ev.n; ++i) {
        const auto ii = static_cast<std::size_t>(i);
        std::vector<Spot>& spots = spots_of[k][ii];
        if (spots.empty() || settled[ii]) continue;
        const auto glow = [&](const Spot& sp) { return not_a_reflection(sp, *area); };
        const Spot taken = spots[static_cast<std::size_t>(rank[k][ii])];
        const bool taken_glow = glow(taken);
        std::erase_if(spots, glow);
        if (spots.empty()) {
          glow_only[k][ii] = 1;
          continue;
        }
        // The spot taken keeps its place among the rest; a glow taken gives it to the brightest
        // reflection.
        int r = 0;
        if (!taken_glow) {
          for (std::size_t q = 0; q < spots.size(); ++q) {
            if (spots[q].centre_small == taken.centre_small) r = static_cast<int>(q);
          }
        }
        rank[k][ii] = r;
      }
    }
  }
  for (std::size_t k = 0; k < k_spheres; ++k) {
    for (int i = 0; i < ev.n; ++i) {
      const auto ii = static_cast<std::size_t>(i);
      SphereLight& light = reports[k].lights[ii];
      const std::vector<Spot>& spots = spots_of[k][ii];
      if (glow_only[k][ii]) {
        light.flag =
            "no highlight on the sphere: only the refracted hot spot's glow (broader than the "
            "sphere's reflections, or unclipped where they clip) or pieces of flare; the light's "
            "reflection is hidden";
        continue;
      }
      if (spots.empty()) {
        if (faint_lift[k][ii] > 0.0) {
          char why[200];
          std::snprintf(why, sizeof why,
                        "no highlight on the sphere: its brightest spot lifts it by %.3f (linear "
                        "light), under a quarter of what its highlights do (%.3f): the lit scene "
                        "mirrored, or noise; the light's reflection is hidden",
                        faint_lift[k][ii], light_lift[k]);
          light.flag = why;
        } else {
          light.flag = "no highlight on the sphere: nothing brighter than in the other images";
        }
        continue;
      }
      const int r = rank[k][ii];
      const Spot& sp = spots[static_cast<std::size_t>(r)];
      light.spot_rank = r;
      // On glass a second spot is expected: once the spheres settle which spot is the
      // reflection, it leaves no doubt.
      if (two_spots(k, ii) && !(out.material == SphereMaterial::kGlass && settled[ii])) {
        light.second_peak = spots[r == 0 ? 1 : 0].peak;
      }
      const int margin = static_cast<int>(std::ceil(std::max(6.0, 2.0 * s)));
      auto window_of = [&](const Spot& spot) {
        cv::Rect box(static_cast<int>(spot.box.x * s) - margin,
                     static_cast<int>(spot.box.y * s) - margin,
                     static_cast<int>(spot.box.width * s) + 2 * margin,
                     static_cast<int>(spot.box.height * s) + 2 * margin);
        return box & cv::Rect(0, 0, ev.w, ev.h);
      };
      wants.push_back({i, static_cast<int>(k), window_of(sp), -1});
      if (out.material == SphereMaterial::kGlass && two_spots(k, ii)) {
        const int other = r == 0 ? 1 : 0;
        wants.push_back(
            {i, static_cast<int>(k), window_of(spots[static_cast<std::size_t>(other)]), other});
      }
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
  const bool srgb = src.colour_space() == ColourSpace::kSRGB;
  const double sphere_area_factor = det.max_blob_area_fraction * std::numbers::pi;
  auto inside_of = [&](std::size_t q) {
    const Circle& c = circles[static_cast<std::size_t>(wants[q].sphere)];
    const double search_r = det.search_radius_fraction * c.radius_px;
    return [c, search_r](int x, int y) {
      return (Eigen::Vector2d(x, y) - c.centre_px).squaredNorm() <= search_r * search_r;
    };
  };
  // The stack's median under each window (analysis resolution, nearest).
  std::vector<cv::Mat> bases(wants.size());
  std::vector<Located> located(wants.size());
  for (std::size_t q = 0; q < wants.size(); ++q) {
    const Want& wt = wants[q];
    cv::Mat& base = bases[q];
    base.create(wt.rect.height, wt.rect.width, CV_32F);
    for (int y = 0; y < wt.rect.height; ++y) {
      for (int x = 0; x < wt.rect.width; ++x) {
        const int sx = std::min(ev.sw - 1, (x + wt.rect.x) / ev.scale);
        const int sy = std::min(ev.sh - 1, (y + wt.rect.y) / ev.scale);
        base.at<float>(y, x) = scaled_median(ev.small_median.at<float>(sy, sx),
                                             gains[static_cast<std::size_t>(wt.image)], ev.srgb);
      }
    }
    const Circle& c = circles[static_cast<std::size_t>(wt.sphere)];
    located[q] = locate(windows[q], base, inside_of(q), srgb, 0.0,
                        out.material == SphereMaterial::kGlass
                            ? sphere_area_factor * c.radius_px * c.radius_px
                            : 0.0);
  }
  // A sphere's clipped cores are the light's image, of one size in every image (a mirror's
  // disc): a core far larger than the sphere's median has merged with something clipped
  // beside it and is cut back to a disc of the median's radius (cut_to_disc).
  std::vector<double> usual_core(k_spheres, 0.0);  // per sphere: the median clipped core
  for (std::size_t k = 0; k < k_spheres; ++k) {
    std::vector<int> sizes;
    for (std::size_t q = 0; q < wants.size(); ++q) {
      if (static_cast<std::size_t>(wants[q].sphere) == k && wants[q].alternate_rank < 0 &&
          located[q].ok && located[q].saturated) {
        sizes.push_back(located[q].pixels);
      }
    }
    if (sizes.size() < 3) continue;
    const double median = upper_median(sizes);
    usual_core[k] = median;
    if (out.material == SphereMaterial::kGlass) {
      for (std::size_t q = 0; q < wants.size(); ++q) {
        Located& loc = located[q];
        if (static_cast<std::size_t>(wants[q].sphere) != k || !loc.ok) continue;
        if (loc.pixels >= kGlareCoreMinPixels && loc.pixels > kGlareCoreRatio * median) {
          loc.glare_ratio = loc.pixels / median;
        }
      }
    }
    if (median < kMergedCoreMinPixels) continue;  // small cores: no disc to fit
    std::vector<double> radii;
    for (std::size_t q = 0; q < wants.size(); ++q) {
      if (static_cast<std::size_t>(wants[q].sphere) == k && wants[q].alternate_rank < 0 &&
          located[q].ok && located[q].edge_radius_px > 0.0 &&
          located[q].pixels < kMergedCoreRatio * median) {
        radii.push_back(located[q].edge_radius_px);
      }
    }
    double edge_r = 0.0;  // see kFreeArcMinDeg
    if (radii.size() >= static_cast<std::size_t>(kEdgeRadiusMinCores)) {
      edge_r = upper_median(radii);
    }
    // Where the exposure varies, a more exposed image clips more of the light's lobe and
    // flare: its core is measured against the cores of the images exposed at least about as
    // much (kMergedCoreGain of its gain; none with fewer than three such, but where it touches
    // a clipped reflection). Against the stack's median, the lights of the most exposed
    // images were cut to a disc off their centre (a large sphere's star flare at 1.6 times:
    // 3 degrees off).
    auto reference_core = [&](std::size_t q) {
      if (out.exposure_gains.empty()) return median;
      const double g = gains[static_cast<std::size_t>(wants[q].image)];
      std::vector<int> alike;
      for (std::size_t o = 0; o < wants.size(); ++o) {
        if (static_cast<std::size_t>(wants[o].sphere) == k && wants[o].alternate_rank < 0 &&
            located[o].ok && located[o].saturated &&
            gains[static_cast<std::size_t>(wants[o].image)] >= kMergedCoreGain * g) {
          alike.push_back(located[o].pixels);
        }
      }
      if (alike.size() < 3) return std::numeric_limits<double>::infinity();
      return static_cast<double>(upper_median(alike));
    };
    for (std::size_t q = 0; q < wants.size(); ++q) {
      if (static_cast<std::size_t>(wants[q].sphere) != k || !located[q].ok ||
          !located[q].saturated ||
          (located[q].pixels < kMergedCoreRatio * reference_core(q) &&
           !located[q].touches_static)) {
        continue;
      }
      // On a mirror sphere, unless nothing located the light in the disc cut (a light wholly
      // inside a window mirrored in the sphere, a disc placed by the window's shape): the
      // whole region's halo, found first, stands. On glass the clipped region beside the
      // reflection is the refracted hot spot's glow, whose halo is no light's: the cut stands.
      Located cut = locate(windows[q], bases[q], inside_of(q), srgb,
                           std::sqrt(median / std::numbers::pi), 0.0, {}, edge_r);
      // A cut that found no disc and whose halo did not settle is the clipped region's
      // centroid, pulled toward what the light merged with: where the whole region's halo
      // settled, its centre stands, with the cut's core as the light's (lit chrome, +-1 EV:
      // lights on a mirrored window 1.5-2.4 px off by the centroid).
      if (out.material != SphereMaterial::kGlass && !cut.disc_cut && !cut.halo_settled &&
          located[q].halo_settled) {
        cut.px = located[q].px;
        cut.halo_settled = true;
      }
      if (!cut.cut_unsupported || out.material == SphereMaterial::kGlass) located[q] = cut;
    }
  }
  // The light from a located spot: unusable (flagged) when there is no highlight, the core is
  // not compact or the reflected direction points below the sample plane.
  auto evaluate = [&](std::size_t q, SphereLight* out_light) {
    const Want& wt = wants[q];
    const Circle& c = circles[static_cast<std::size_t>(wt.sphere)];
    SphereLight& light = *out_light;
    const Located& loc = located[q];
    light.peak = loc.peak;
    light.saturated = loc.saturated;
    light.blob_pixels = loc.pixels;
    light.blob_major_px = loc.major;
    light.blob_minor_px = loc.minor;
    light.blob_angle_deg = loc.angle_deg;
    if (!loc.ok || loc.peak < det.min_peak) {
      light.flag =
          "no highlight on the sphere (peak " + std::to_string(loc.peak).substr(0, 5) + ")";
      return;
    }
    light.highlight_px = loc.px;
    // Where the camera moved, the sphere in this image lies shifted from the circle found on
    // the stack: the highlight is taken back into the stack's frame (at half a pixel of shake
    // on 42 px spheres: lights 0.86-1.34 degrees off on average to 0.29-0.52).
    if (ev.undo_shifts) light.highlight_px -= ev.shifts_px[static_cast<std::size_t>(wt.image)];
    const double disc_area = std::numbers::pi * c.radius_px * c.radius_px;
    const double compact_pixels = std::max(
        sphere_area_factor * c.radius_px * c.radius_px,
        loc.saturated ? std::min(kUsualCoreSlack * usual_core[static_cast<std::size_t>(wt.sphere)],
                                 kMaxUsualCoreFraction * disc_area)
                      : 0.0);
    if (loc.pixels > compact_pixels) {
      light.flag = "highlight core covers " + std::to_string(loc.pixels) +
                   " pixels: not a compact highlight (a reflection of the scene?)";
      return;
    }
    if (loc.glare_ratio > 0.0) {
      char why[200];
      std::snprintf(why, sizeof why,
                    "the spot covers %d pixels, %.0f times the sphere's usual clipped core: the "
                    "glow of the refracted hot spot, not the light's reflection",
                    loc.pixels, loc.glare_ratio);
      light.flag = why;
      return;
    }
    light.direction = reflect_highlight(c, det.camera, light.highlight_px, ev.w, ev.h);
    light.found = light.direction.z() > 0.0;
    if (!light.found) light.flag = "reflected direction is below the sample plane";
  };
  for (std::size_t q = 0; q < wants.size(); ++q) {
    if (wants[q].alternate_rank >= 0) continue;
    SphereLight& light = reports[static_cast<std::size_t>(wants[q].sphere)]
                             .lights[static_cast<std::size_t>(wants[q].image)];
    evaluate(q, &light);
  }
  // Two comparable spots and the one taken unusable (a glass ball's refracted hot spot is
  // larger than a compact highlight, or reflects to below the plane): the other is taken when
  // it is usable. It stays doubtful (second_peak), and spot_rank says which was taken.
  for (std::size_t q = 0; q < wants.size(); ++q) {
    if (wants[q].alternate_rank < 0) continue;
    SphereLight& light = reports[static_cast<std::size_t>(wants[q].sphere)]
                             .lights[static_cast<std::size_t>(wants[q].image)];
    if (light.found) continue;
    SphereLight other = light;
    other.flag.clear();
    evaluate(q, &other);
    if (!other.found) continue;
    other.second_peak = light.peak;
    other.spot_rank = wants[q].alternate_rank;
    light = other;
  }
  // On glass a compact piece of the hot spot's glow, at its edge, can reflect to below the
  // plane while the reflection, a smaller dot in the same spot's window, is left. Where no
  // sphere has the light, the next clipped components of the window are tried (at most
  // kGlassRetries), the light taken from the first usable one; it stays doubtful
  // (second_peak: the component passed over). Where another sphere has it, the light is
  // theirs: a piece of the glow that happens to reflect above the plane would only pull it.
  auto seen_elsewhere = [&](const Want& w) {
    for (std::size_t k = 0; k < k_spheres; ++k) {
      if (static_cast<int>(k) != w.sphere &&
          reports[k].lights[static_cast<std::size_t>(w.image)].found) {
        return true;
      }
    }
    return false;
  };
  for (std::size_t q = 0; q < wants.size(); ++q) {
    if (wants[q].alternate_rank >= 0) continue;
    SphereLight& light = reports[static_cast<std::size_t>(wants[q].sphere)]
                             .lights[static_cast<std::size_t>(wants[q].image)];
    if (out.material != SphereMaterial::kGlass || light.found || !located[q].ok ||
        !located[q].saturated || seen_elsewhere(wants[q])) {
      continue;
    }
    const Circle& c = circles[static_cast<std::size_t>(wants[q].sphere)];
    std::vector<Eigen::Vector2d> skip{located[q].px};
    const Located first = located[q];
    for (int t = 0; t < kGlassRetries && !light.found; ++t) {
      located[q] = locate(windows[q], bases[q], inside_of(q), srgb, 0.0,
                          sphere_area_factor * c.radius_px * c.radius_px, skip);
      if (!located[q].ok || !located[q].saturated ||
          std::any_of(skip.begin(), skip.end(),
                      [&](const Eigen::Vector2d& p) { return (p - located[q].px).norm() < 1.0; })) {
        break;
      }
      SphereLight other = light;
      other.flag.clear();
      evaluate(q, &other);
      if (other.found) {
        other.second_peak = first.peak;
        light = other;
        break;
      }
      skip.push_back(located[q].px);
    }
    if (!light.found) located[q] = first;
  }
  out.rig = refine_rig(std::move(reports), names, ev.w, ev.h, rig);
  const int usable = out.rig.usable(), outliers = out.rig.outliers();
  // Only where the camera is known: without a focal length the orthographic model itself
  // makes spheres away from the image centre disagree.
  if (detected && k_spheres >= 2 && out.camera.focal_px > 0.0 && !options.allow_disagreement &&
      usable >= 4 && outliers > kMostLightsDisagree * usable) {
    std::string msg = "the spheres found disagree about " + std::to_string(outliers) + " of " +
                      std::to_string(usable) + " lights (" + out.rig.model +
                      " model): they are most likely not the capture's spheres; candidates:";
    const std::size_t show = std::min<std::size_t>(out.candidates.size(), 8);
    for (std::size_t k = 0; k < show; ++k) msg += "\n  " + describe(out.candidates[k]);
    msg +=
        "\nhelp the search with --roi x,y,w,h (a box per sphere), --radius-range MIN,MAX, "
        "--reference IMG, or give --sphere cx,cy,r; or keep these with --allow-disagreement";
    throw Disagreement(msg, out.candidates);
  }
  return out;
}

// run(), and where the spheres it found disagree about most lights, run() again with the
// second search (kSlideShare) on the same evidence: only the highlights' windows are read
// again. Where the second search refuses too (its spheres disagree, or too few are found), the
// first refusal stands.
StackCalibration run_searches(const Source& src, const std::vector<fs::path>& names,
                              const StackCalibrationOptions& options) {
  const Evidence ev = prepare(src, names, options);
  std::string first_message;
  std::vector<SphereCandidate> first_candidates;
  try {
    return run(src, names, options, ev, false);
  } catch (const Disagreement& first) {
    first_message = first.what();
    first_candidates = first.candidates();
  }
  try {
    StackCalibration out = run(src, names, options, ev, true);
    out.search_note =
        "the spheres first chosen disagreed about most lights; these are from a second search "
        "that also refines circles within " +
        std::to_string(static_cast<int>(kSlideShare * 100.0 + 0.5)) +
        "% of their radius and chooses the spheres whose lights agree";
    return out;
  } catch (const SphereSearchError&) {
    // Disagreeing again, or too few spheres with a narrower choice: the first refusal says more.
    throw SphereSearchError(first_message, std::move(first_candidates));
  }
}

}  // namespace

namespace {

// A mask beside the photographs (`chrome.mask.png` next to `chrome.0.png`, ...) is easily
// caught by a shell pattern; taken for a photograph it looks like a light filling the
// sphere and spoils the search. A file named as a mask whose samples are black or white
// (within 2% of either end) but for at most 1% of them - a saved mask's anti-aliased or
// compressed edge - and white somewhere is refused with what to do instead.
void refuse_masks_among_photos(const std::vector<fs::path>& files) {
  for (const fs::path& f : files) {
    std::string stem = f.stem().string();
    std::transform(stem.begin(), stem.end(), stem.begin(),
                   [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
    if (stem.find("mask") == std::string::npos) continue;
    const Image img = read_image(f);
    std::size_t white = 0;
    std::size_t between = 0;
    for (std::size_t i = 0; i < img.size(); ++i) {
      const float v = img.data()[i];
      white += v > 0.98f ? 1 : 0;
      between += v >= 0.02f && v <= 0.98f ? 1 : 0;
    }
    if (white > 0 && between * 100 <= img.size()) {
      throw Error(f.string() +
                  ": a mask (named so, black and white), not a photograph: give it with "
                  "--mask, or leave it out of the images");
    }
  }
}

}  // namespace

StackCalibration calibrate_sphere_stack(const std::vector<fs::path>& files,
                                        const StackCalibrationOptions& options) {
  if (files.empty()) throw Error("sphere: no images");
  refuse_masks_among_photos(files);
  const FileSource src(files);
  return run_searches(src, files, options);
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
  return run_searches(src, names, options);
}

const char* to_string(SphereMaterial m) {
  switch (m) {
    case SphereMaterial::kAuto:
      return "auto";
    case SphereMaterial::kMirror:
      return "mirror";
    case SphereMaterial::kGlass:
      return "glass";
  }
  return "auto";
}

std::string StackCalibration::to_json() const {
  nlohmann::json j = nlohmann::json::parse(rig.to_json());
  j["analysis_scale"] = analysis_scale;
  j["two_spot_images"] = two_spot_images;
  j["material"] = to_string(material);
  j["material_note"] = material_note;
  j["search_note"] = search_note;
  j["exposure_gains"] = exposure_gains;
  j["image_shifts_undone"] = image_shifts_undone;
  j["image_shifts_px"] = nlohmann::json::array();
  for (const Eigen::Vector2d& d : image_shifts_px) j["image_shifts_px"].push_back({d.x(), d.y()});
  j["focal_px"] = camera.focal_px;
  j["focal_source"] = camera.focal_source;
  j["candidates"] = nlohmann::json::array();
  for (const SphereCandidate& c : candidates) {
    j["candidates"].push_back({{"centre_px", {c.circle.centre_px.x(), c.circle.centre_px.y()}},
                               {"radius_px", c.circle.radius_px},
                               {"score", c.score},
                               {"rim", c.rim},
                               {"track", c.track},
                               {"moving_spots", c.moving_spots},
                               {"distinct_spots", c.distinct_spots},
                               {"light_spots", c.light_spots},
                               {"below_plane_spots", c.below_plane_spots},
                               {"geometry", c.geometry},
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
  return detail::from_bgr8(m);
}

}  // namespace ptmkit::calib
