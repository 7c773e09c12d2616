// Internal to calib: the streamed sphere search's passes (calib/src/sphere_stack.cc drives
// them): the stack as bands (files or memory), the evidence gathered in one pass over it,
// the spots that move from image to image, and the sphere candidates found from both.
#pragma once

#include <algorithm>
#include <cstdint>
#include <filesystem>
#include <functional>
#include <limits>
#include <optional>
#include <string>
#include <vector>

#include <Eigen/Core>
#include <opencv2/core.hpp>

#include "ptmkit/calib/sphere_stack.h"
#include "ptmkit/core/colour.h"
#include "ptmkit/core/image.h"
#include "ptmkit/core/stack_reader.h"
#include "sphere_detail.h"

namespace ptmkit::calib::stack_detail {

namespace fs = std::filesystem;
using detail::kth_smallest;
using detail::upper_median;

// ---- Sources: the stack in bands of rows, from files or from memory. -----------------------

class Source {
 public:
  virtual ~Source() = default;
  [[nodiscard]] virtual int width() const = 0;
  [[nodiscard]] virtual int height() const = 0;
  [[nodiscard]] virtual int count() const = 0;
  // How the samples are encoded (sRGB or linear).
  [[nodiscard]] virtual ColourSpace colour_space() const = 0;
  // Calls fn with every band, top to bottom.
  virtual void scan(const std::function<void(const StackBand&)>& fn) const = 0;
};

class FileSource : public Source {
 public:
  explicit FileSource(std::vector<fs::path> files) : files_(std::move(files)) {
    StackReader probe(files_);
    w_ = probe.width();
    h_ = probe.height();
    colour_space_ = probe.summary().colour_space;
  }
  int width() const override { return w_; }
  int height() const override { return h_; }
  int count() const override { return static_cast<int>(files_.size()); }
  ColourSpace colour_space() const override { return colour_space_; }
  void scan(const std::function<void(const StackBand&)>& fn) const override {
    StackReader reader(files_);
    StackBand band;
    while (reader.read_band(16, &band, BandStorage::kNative8)) fn(band);
  }

 private:
  std::vector<fs::path> files_;
  int w_ = 0, h_ = 0;
  ColourSpace colour_space_ = ColourSpace::kSRGB;
};

class MemorySource : public Source {
 public:
  explicit MemorySource(const std::vector<Image>& images) : images_(images) {}
  int width() const override { return images_[0].width(); }
  int height() const override { return images_[0].height(); }
  int count() const override { return static_cast<int>(images_.size()); }
  ColourSpace colour_space() const override { return images_[0].colour_space(); }
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

inline float band_luma(const StackBand& b, int i, int row, int x) {
  if (b.channels >= 3) {
    return static_cast<float>(
        luma(b.sample(i, row, x, 0), b.sample(i, row, x, 1), b.sample(i, row, x, 2)));
  }
  return b.sample(i, row, x, 0);
}

// ---- Pass 1: the stack's evidence (sphere_stack_evidence.cc). --------------------------------

struct Evidence {
  int w = 0, h = 0, n = 0, scale = 1, sw = 0, sh = 0;
  std::vector<std::vector<std::uint16_t>> small;  // per image, block-max luma * 65535
  cv::Mat full_max, full_mean;                    // CV_32F, photo size
  cv::Mat small_max, small_median, small_mean;    // CV_32F, analysis size
  // Each image's shift against the stack's median (photo pixels; camera_shifts in
  // sphere_stack_evidence.cc), and whether the camera moved between shots: the shifts' median
  // length above kCameraMovedPx analysis pixels, and the shifts measured on the frame's left
  // and right halves alone no further apart than that (their distance's median over the
  // images, photo pixels: shift_halves_apart_px).
  std::vector<Eigen::Vector2d> shifts_px;
  double shift_halves_apart_px = 0.0;
  bool camera_moved = false;
  bool undo_shifts = false;  // the camera moved, by a median length above kShiftUndoPx
  // What a moving spot must rise above: the median, or where the camera moved its maximum
  // over each pixel's 3 x 3 neighbourhood. A camera that moved by a fraction of a pixel moves
  // every edge of the scene, and against the median itself each bright edge (a window
  // mirrored in the sphere) lifts like a spot in every image.
  cv::Mat small_median_max3;
  // At scale > 1: the per-pixel median over the images of each image's block mean (analysis
  // size; a block mean keeps an edge where it is, a block maximum moves it); else empty.
  cv::Mat small_block_median;
  // The per-pixel lower quartile over the images (of the block means at scale > 1, of the
  // pixels at scale 1), analysis size. Light only adds, so what glows under a few of the
  // lights (a glass ball's refracted hot spot under lights near the camera's axis, spread over
  // its limb) rises above it only where it glows in more than three quarters of the images.
  cv::Mat small_lower_quartile;
  // Per pixel, how much it changes from light to light: the spread between the upper and the
  // lower quartile over the images against their sum, in linear light (analysis size; of the
  // block maxima at scale > 1). A mirror shows the room as it is under every light and changes
  // only where a highlight or its flare passes; a matte surface (the cloth, a sphere's base or
  // cup) follows every light. In a lit room a chrome ball's limb mirrors the dark cloth it
  // shades and barely shows in the median, while here the still disc ends at it.
  cv::Mat small_spread;
  cv::Mat reference;  // CV_32F photo size, or empty
  bool srgb = true;   // the samples are sRGB-encoded (else linear)
  // Each analysis sample's value in linear light (to_linear), by its 16-bit code.
  std::vector<double> linear_of_code;
  [[nodiscard]] double linear_at(int i, int x, int y) const {
    return linear_of_code[small[static_cast<std::size_t>(i)]
                               [static_cast<std::size_t>(y) * sw + static_cast<std::size_t>(x)]];
  }
  [[nodiscard]] float at(int i, int x, int y) const {
    return static_cast<float>(small[static_cast<std::size_t>(i)][static_cast<std::size_t>(y) * sw +
                                                                 static_cast<std::size_t>(x)]) /
           65535.0f;
  }
};

// One pass over the stack: each image's block-maximum luma at the analysis size (longest side
// at most max_side), the photo-size maximum and mean, the analysis-size median and mean.
Evidence gather(const Source& src, int max_side);
// The luma of an image as a float plane.
cv::Mat luma_plane(const Image& img);
// Contrast-stretched 8-bit copy: log brightness between the 1st and 99.5th percentiles, so a
// black ball's faint rim on a black ground shows as well as a bright one.
cv::Mat stretch(const cv::Mat& f, int type, bool logarithm = true);

// ---- Moving spots (sphere_stack_evidence.cc). -------------------------------------------------

struct Spot {
  Eigen::Vector2d centre_small;  // analysis pixels, weighted by the light added (linear)
  double peak = 0.0;             // image luma at the spot's brightest pixel
  double lift = 0.0;             // brightest (image - median)
  double lift_linear = 0.0;      // the same in linear light
  int area = 0;                  // analysis pixels
  cv::Rect box;                  // analysis pixels
};

// A sample at or above this (full scale 1) is clipped.
constexpr double kSpotClip = 0.99;

// The camera moved between shots where the images' shifts against the median have a median
// length above this, analysis pixels: steady renders of 22 lights give 0.002-0.035 (the
// light's changes leave a little; with the exposure varying by +-1 EV 0.008-0.037), 8 lights
// at three times the exposure 0.09-0.11 and 22 at five times 0.15 (their discs of bloom),
// shaken by up to a quarter of a pixel 0.13-0.28 and by up to half a pixel 0.27-0.47. The
// halves of the frame tell the last two apart: a camera's shift moves both alike (the shifts
// measured on each half alone 0.4-0.65 times the shift apart), the bloom does not (2.2-6
// times).
constexpr double kCameraMovedPx = 0.1;
// The shifts are undone (each highlight taken back by its image's) only above this median
// length: below it what the light changes can pass for them (the 8 overexposed lights above:
// shifts of up to 1.1 px measured, 0.55 to 1.1 degrees mean if undone).
constexpr double kShiftUndoPx = 0.2;

// The spots of image i in a disc (analysis pixels) brighter than the median by more than
// max(0.05, half the brightest lift in the disc, six times the disc's noise in the image),
// and at least min_peak bright. `gain`: image i's exposure against the stack's (see
// exposure_gains); the median is scaled by it in linear light before it is subtracted.
std::vector<Spot> moving_spots(const Evidence& ev, int i, const Eigen::Vector2d& c, double r,
                               double min_peak, double gain = 1.0);

// The glass rules below hold only on spheres of at least this radius (photo pixels): on 42 px
// marbles the reflections and the glow are both a few dozen analysis pixels, and told apart by size
// the zenith light's reflection was refused and one marble's lights came out 31 degrees off on
// average.
inline constexpr double kGlowRuleMinRadiusPx = 88.0;
// A glass ball's reflections of one light source are one size, its refracted hot spot's glow
// varies with the light and is broader: a spot kGlowAreaRatio times the reflections' size
// (their analysis pixels above half the spot's lift) is glow, and so is an unclipped spot
// where the reflections clip; a clipped spot kFragmentAreaRatio times smaller is a piece of a
// flare's spoke or of the glow's edge. The reflections' size is the clipped spots' most common
// one: the area a with the most images holding a clipped spot within kReflectionAreaSpread of
// it (at least kReflectionAreaImages of them; else none is known and no spot is refused). On
// a 180 px glass ball: reflections 250-541 analysis pixels, clipped glow 1896-14070, unclipped
// glow 324-1281, clipped spoke pieces of 1-5 pixels at the limb. The glow's clipped core, the
// one the highlight was located on, was 196 pixels against the reflections' 37-85 (under
// kGlareCoreRatio) and gave a light 89 degrees off.
inline constexpr double kGlowAreaRatio = 3.0;
inline constexpr double kFragmentAreaRatio = 8.0;
inline constexpr double kReflectionAreaSpread = 1.5;
inline constexpr int kReflectionAreaImages = 3;

std::optional<double> reflection_spot_area(const std::vector<std::vector<Spot>>& spots_of);
// Whether `sp`, on glass whose reflections are `reflection_area` analysis pixels, is glow or a
// fragment (above), not the light's reflection.
bool not_a_reflection(const Spot& sp, double reflection_area);

// A second spot of at least half the first's lift (spots brightest first).
inline bool two_comparable_spots(const std::vector<Spot>& spots) {
  return spots.size() >= 2 && spots[1].lift >= 0.5 * spots[0].lift;
}
// Two comparable spots across the disc's centre `c` from each other: a glass ball's reflection
// and refracted hot spot.
inline bool spots_across(const std::vector<Spot>& spots, const Eigen::Vector2d& c) {
  return two_comparable_spots(spots) &&
         (spots[0].centre_small - c).dot(spots[1].centre_small - c) < 0.0;
}
// Images whose spots lie across the centre (spots_across).
int across_spot_images(const std::vector<std::vector<Spot>>& spots_of, const Eigen::Vector2d& c);
// Glass, judged from `across` of `n` images with spots across the centre (kGlassTwoSpotShare).
inline bool glass_from_spots(int across, int n) {
  return across > 0 && across >= kGlassTwoSpotShare * n;
}

// A sample in linear light: decoded where the samples are sRGB-encoded (clamped to 0..1).
inline double to_linear(double v, bool srgb) {
  return srgb ? srgb_to_linear(std::clamp(v, 0.0, 1.0)) : v;
}

// The stack's median value m as an image taken at `gain` times the stack's exposure shows it:
// scaled in linear light, clipped at full scale, encoded again.
inline float scaled_median(float m, double gain, bool srgb) {
  if (gain == 1.0) return m;
  const double v = std::min(1.0, gain * to_linear(m, srgb));
  return static_cast<float>(srgb ? linear_to_srgb(v) : v);
}

// Each image's exposure against the stack's, from what the spheres mirror of the room: the
// median, over the pixels of the discs (analysis pixels: centres `c`, radii `r`) that the
// stack's median shows bright but unclipped and that follow one gain per image, of the image's
// value over the median's, in linear light (the lower quartile for an image whose light lifts
// many of them, where the exposure varies). The room's lamps and windows and whatever they
// light stay as they are from light to light, so an image that shows them brighter or darker
// was exposed so (a camera on automatic exposure, a flash whose output varies). 1 for every
// image without enough such pixels (a dark room that mirrors nothing bright), and for an image
// where most of them clip.
std::vector<double> exposure_gains(const Evidence& ev, const std::vector<Eigen::Vector2d>& c,
                                   const std::vector<double>& r);

// The exposure varies from image to image where the median over the images of |ln gain|
// exceeds this (3%): steady renders' gains scatter by at most 2.3% about 1 (the light's own
// glow over what the spheres mirror, JPEG; 47 renders of the four presets, dark and lit).
// Smaller variations change the highlights by less than the steady scatter does.
inline constexpr double kExposureVaries = 0.03;
bool exposure_varies(const std::vector<double>& gains);
// exposure_gains over one disc (analysis pixels), where they vary and taking them out leaves
// the disc stiller: the lower quartile over the disc of its spread (Evidence::small_spread, the
// stillest quarter: what it mirrors of the room) at most kGainsStillerShare of the stack's;
// else all 1. A steady capture's gains measured over a disc that mirrors what the lights change
// (the lit cloth, the relief) vary too, by up to a factor 6, and leave a ball's disc no stiller
// (photo-dome in a lit room, seed 4: 0.96); a chrome ball's with the exposure varying by up to
// 1 EV came to 0.39-0.45.
inline constexpr double kGainsStillerShare = 0.7;
std::vector<double> disc_gains(const Evidence& ev, const Eigen::Vector2d& c, double r);
// Evidence::small_spread over `box` (analysis pixels) with each image's value divided by its
// gain (exposure_gains) first: under an exposure that varies a still mirror varies with it,
// and only with the gains taken out is it still again.
cv::Mat spread_in_box(const Evidence& ev, const cv::Rect& box, const std::vector<double>& gains);

// ---- Candidates (sphere_stack_candidates.cc). -------------------------------------------------

// A light is far brighter than anything it lights: its reflection lifts the sphere, in linear
// light, by at least this share of what the sphere's highlights lift it by (their upper
// quartile over the stack). A fainter spot is the lit scene mirrored in the sphere or noise on a
// bright static reflection, seen where the light's own reflection is hidden (behind the
// sphere, or under its base). On the photographic renders every highlight lifts by 0.92-1.0
// and the brightest such spot by at most 0.11.
inline constexpr double kLightLiftShare = 0.25;

// What a sphere's highlights lift it by, the reference of kLightLiftShare: the upper quartile
// (the 3 (n - 1) / 4-th smallest) of the lifts of its brightest spots; 0 for none.
inline double highlight_lift(std::vector<double> lifts) {
  if (lifts.empty()) return 0.0;
  return kth_smallest(lifts, 3 * (lifts.size() - 1) / 4);
}

// A light reflects off a sphere lying on the sample plane only from above the plane, so a
// circle that puts a light's reflection below it (by more than this elevation, degrees:
// noise on a light at the horizon) is not the sphere's outline.
inline constexpr double kBelowPlaneSlackDeg = 2.0;

// Where circles are fitted to a sphere's outline. A pinhole camera sees the outline as the cone
// of rays tangent to the sphere: an ellipse, stretched away from the principal point by about
// 1 / cos of the centre's angle off the axis (2% at 12 degrees: 3.4 px on a sphere of radius
// 170, and a circle fitted by consensus then follows one side). The stereographic projection of
// the rays maps every such cone to a circle: with a focal length, points are fitted there. The
// plane is scaled to the points' pixels at the principal point (2 f tan(angle / 2) from it);
// without a focal length it is the identity.
struct OutlinePlane {
  double focal_px = 0.0;                                   // photo pixels; 0: identity
  Eigen::Vector2d principal_px = Eigen::Vector2d::Zero();  // photo pixels
  int scale = 1;  // the points' pixels: photo pixel = scale p + (scale - 1) / 2

  OutlinePlane() = default;
  OutlinePlane(const SphereCamera& camera, int width, int height, int points_scale);
  [[nodiscard]] bool identity() const { return !(focal_px > 0.0); }
  [[nodiscard]] Eigen::Vector2d to(const Eigen::Vector2d& p) const;
  [[nodiscard]] Eigen::Vector2d from(const Eigen::Vector2d& q) const;
  // A circle in the points' pixels (an outline's centre and mean radius) to the plane, near
  // enough to start a fit from (its outline points are not mapped).
  [[nodiscard]] Circle to(const Circle& c) const;
  // A circle fitted in the plane back to the points' pixels: the outline ellipse's centre and
  // the geometric mean of its semi-axes; its outline points mapped back.
  [[nodiscard]] Circle from(const Circle& q) const;
};

// Analysis pixel k covers photo pixels k s .. k s + s - 1: its centre is photo pixel
// k s + (s - 1) / 2. A point from the analysis size to photo pixels, and back.
inline Eigen::Vector2d photo_px(const Eigen::Vector2d& small, double scale) {
  return small * scale + Eigen::Vector2d::Constant(0.5 * (scale - 1));
}
inline Eigen::Vector2d small_px(const Eigen::Vector2d& photo, double scale) {
  return (photo - Eigen::Vector2d::Constant(0.5 * (scale - 1))) / scale;
}
// An analysis-size circle (and its outline points) in photo pixels.
Circle to_photo(const Circle& small, int scale);

// A CV_32F plane at p by bilinear interpolation; p within [0, cols - 1) x [0, rows - 1).
inline double sample_bilinear(const cv::Mat& f, const Eigen::Vector2d& p) {
  const int x0 = static_cast<int>(p.x()), y0 = static_cast<int>(p.y());
  const double fx = p.x() - x0, fy = p.y() - y0;
  const float* r0 = f.ptr<float>(y0);
  const float* r1 = f.ptr<float>(std::min(y0 + 1, f.rows - 1));
  const int x1 = std::min(x0 + 1, f.cols - 1);
  return (1 - fy) * ((1 - fx) * r0[x0] + fx * r0[x1]) + fy * ((1 - fx) * r1[x0] + fx * r1[x1]);
}

// The profile of `f` along a ray, c + t dir for t = t0, t0 + step, ... <= t1, bilinear, ending
// where the ray leaves the frame: what the rim searches find their edges on.
inline void ray_profile(const cv::Mat& f, const Eigen::Vector2d& c, const Eigen::Vector2d& dir,
                        double t0, double t1, double step, std::vector<double>* prof) {
  prof->clear();
  for (double t = t0; t <= t1; t += step) {
    const Eigen::Vector2d p = c + t * dir;
    if (p.x() < 0 || p.y() < 0 || p.x() > f.cols - 1.001 || p.y() > f.rows - 1.001) break;
    prof->push_back(sample_bilinear(f, p));
  }
}

// The strongest edge on the ray c + t dir, t0 <= t <= t1, of the smoothed composite `f`: the
// largest radial derivative, at least 2 grey levels a pixel, to a sub-sample by a parabola;
// profiles sampled every `step` pixels. False where there is none.
bool edge_on_ray(const cv::Mat& f, const Eigen::Vector2d& c, const Eigen::Vector2d& dir, double t0,
                 double t1, double step, double* t);
// A glossy sphere's limb along a ray, in linear light. Toward the outline the mirror's
// reflectance rises to 1 (Fresnel) and what it mirrors there is what lies just beyond the
// limb, so the sphere's brightness meets the background's without a step: the profile is
// that of the background minus the sphere's own contrast times 1 - (1 - cos theta)^5
// (Schlick), which climbs like the square root of the distance inside the outline. In a lit
// room a black ball against a lit wall brightens over its last 3-4 pixels at a radius of
// 180 px, and the steepest point of that climb lies 0.5-0.8 px inside the outline. The model:
// level + slope * t + c * limb_sigma(R - t), beside the plain blurred step
// (level + slope * t + c * step_sigma(R - t)), each fitted by least squares for every outline
// R on a 0.05 px grid (refined by a parabola) and every blur sigma of a short list; the
// better fit of each and its place are returned.
class LimbProfileModel {
 public:
  explicit LimbProfileModel(double radius_px);
  struct Fit {
    bool valid = false;
    double limb_px = 0.0, limb_sse = std::numeric_limits<double>::infinity();
    // The limb model's climb over the window (its contrast times its shape's range there) and
    // its rms residual: how clearly the ray shows a limb at all.
    double limb_amplitude = 0.0, limb_rms = 0.0;
    double step_px = 0.0, step_sse = std::numeric_limits<double>::infinity();
  };
  // prof[i] sampled at t0 + i step (linear light), the outline sought within [lo, hi] (the same
  // units as t).
  [[nodiscard]] Fit fit(const std::vector<double>& prof, double t0, double step, double lo,
                        double hi) const;

 private:
  struct Table {
    std::vector<double> step, limb;  // on u = R - t, from -reach by 1/64 px
    static double at(const std::vector<double>& f, double u);
  };
  std::vector<Table> tables_;
};

// Per ray from the centre (360 rays), the strongest edge between (1 - band) r and
// (1 + band) r of the smoothed composite `f`; `inside` counts the rays that stay in the frame.
std::vector<Eigen::Vector2d> ray_edges(const cv::Mat& f, const Eigen::Vector2d& c, double r,
                                       int* inside, double band = 0.3);
// The circle the rim points agree on, near `rough`; `rim` gets the share of rays that agree
// (within max(1 px, 1% r)). With `choose_tol_px` > 0 the circle is chosen by the points within
// that distance instead.
Circle consensus_circle(const std::vector<Eigen::Vector2d>& pts, const Circle& rough, double* rim,
                        double choose_tol_px = 0.0);
// The second search, made only when the spheres the first chose disagree about most lights
// (StackCalibrationOptions::allow_disagreement). A proposal whose refinement slid onto an edge
// more than kSlideShare of its radius away (a base's or cup's rim around a sphere whose own
// outline shows on few rays) is also refined within that share of its own radius; and two or
// three spheres are chosen by the share of their lights that agree within
// kStrictAgreementDeg (kStrictAgreementOrthoDeg without a focal length), all of the value
// weighted by it, instead of the first search's wide tolerance, which only weighs the choice
// (near lights in a small dome are seen along different directions by spheres far apart).
inline constexpr double kSlideShare = 0.08;
inline constexpr double kStrictAgreementDeg = 5.0;
inline constexpr double kStrictAgreementOrthoDeg = 8.0;

// The sphere candidates of the stack, scored, best first; `chosen_photo` gets the `count`
// chosen circles in photo pixels. `second_search`: see kSlideShare.
std::vector<SphereCandidate> find_candidates(const Evidence& ev, const SphereSearchOptions& opt,
                                             double min_peak, int count, const SphereCamera& camera,
                                             std::vector<Circle>* chosen_photo,
                                             bool second_search = false);
// How many of the candidate's images with light spots (SphereCandidate::light_spots_px)
// `circle_photo` (photo pixels) reflects to below the sample plane, every spot of the image;
// the spots are in pixels of `spots_scale` (the analysis scale while candidates are scored, 1
// once find_candidates has returned them).
int below_plane_spots(const SphereCandidate& cand, const Circle& circle_photo,
                      const SphereCamera& camera, const Evidence& ev, int spots_scale);
// One line on a candidate: circle, score and its parts, why chosen or refused.
std::string describe(const SphereCandidate& c);

}  // namespace ptmkit::calib::stack_detail
