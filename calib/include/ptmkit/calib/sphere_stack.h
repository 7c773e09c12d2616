// Sphere calibration of real photographs, streamed: the spheres found from the evidence of
// the whole stack, the light's highlight told apart from the scene's reflections, and the
// rig refined (sphere_refine.h). The photographs are read twice in bands of rows and never
// held decoded: memory is a small analysis copy of each image plus a few full-size planes.
//
// Evidence, from one streamed pass:
//   per image   an analysis copy of its luma, each pixel the maximum of a block of
//               `scale` x `scale` photo pixels (highlights survive the reduction); scale is
//               the smallest integer that brings the longest side to analysis_max_side_px
//   per pixel   over the stack: maximum, mean, median and lower quartile (the last two on
//               the analysis copy); what stays still (the sphere, its base, the scene and its
//               reflections) is in the median, what moves with the light is not; the lower
//               quartile also leaves out a glow that covers part of the sphere in up to three
//               quarters of the images (a glass ball's refracted hot spot under high lights),
//               and its rim is taken where it is the sharper
//   moving spots  per image, the connected spots brighter than the median by a margin
// Sphere candidates: circles (OpenCV Hough gradient) on contrast-stretched composites (max,
// mean, median, the reference photo), each refined on the rim's edge, then scored:
//   rim     fraction of rays from the centre that cross an edge at the circle's radius
//           (the best composite's; rays outside the frame or hidden below do not count)
//   track   fraction of the images whose brightest moving spot inside the circle is compact
//           and lies at its own place: a mirror sphere shows each light at a different point
//           of one circle; a coin, dish or lens glints at the same few places or lights up
//           as a whole, so its track is short
//   geometry  1 - 2 x the share of those spots (the ones bright enough to be a light's
//           reflection, and clipped where three quarters of the track's bright spots are: an
//           unclipped one beside clipped reflections is a glass ball's refracted glow) that
//           the circle reflects to below the sample plane, at least 0: a
//           sphere on the plane reflects every light from above it, and a circle inside the
//           outline (the horizon mirrored in a chrome ball in a lit room, at 0.7 of its
//           radius) puts the low lights below it
//   score   min(1, rim / 0.3) x track x geometry: a rim on a third of the rays counts as a
//           full rim; neither a rim alone (a coin) nor a track alone (any circle drawn around
//           the highlights) makes a sphere
// The `sphere_count` best non-overlapping candidates with score >= min_score are taken; for
// two or three spheres, of the ten best the set with the highest sum of scores times
// (1 + agreement) / 2, agreement = its worst pair's share of common images whose spots reflect
// lights within 20 degrees of each other (pinhole; 30 orthographic): a dish's or coin's moving
// glint does not reflect the lights as the spheres do, while near lights only lower it;
// otherwise SphereSearchError lists every candidate and its evidence, and nothing is written.
//
// The highlight of a light on a sphere: the moving spots in the circle (the image minus the
// stack's median, so a reflected window or lamp, which is in every image, cancels), the
// brightest taken, then located in the photograph at full resolution. Where the exposure
// varies from image to image (a camera on automatic exposure, a flash whose output varies:
// StackCalibration::exposure_gains), the median is first scaled in linear light by the
// image's exposure, measured from what the spheres mirror of the room:
//   unsaturated  centroid of the brightness above the median within the spot
//   saturated    the clipped core (its holes filled) without its flare streaks and bloom: the
//                pixels at least half the core's inscribed radius from the clipped region's
//                edge, grown back by that radius inside it (a morphological opening), their
//                centroid
// Brightness above the median is measured in linear light (sRGB samples linearised). A small
// core (at most 20 pixels) is then moved to the centre about which its halo, clipped pixels
// left out, is most nearly point-symmetric (a larger clipped core too, where that centre lies
// more than 0.3 px from its edge's: a background brighter on one side moves the edge); a core
// far larger than its sphere's median core (a mirror's disc merged with the clipped scene beside
// it) is cut back to a disc of the median's size. Two moving spots in the circle (a glass ball's
// surface reflection and its refracted hot spot) are reported
// (StackCalibration::two_spot_images); with two or more spheres the spot whose direction agrees
// with the other spheres' is taken (a refracted spot does not obey mirror geometry;
// SphereLight::spot_rank says which), with one sphere the brightest unless it proves unusable on
// a glass sphere (SphereMaterial). On a glass sphere of at least 88 px radius, a spot over three
// times the size of its reflections (the most common size of its clipped spots, from at least
// three images) or unclipped where they clip is the hot spot's glow, and one under an eighth of
// it a piece of flare: neither is ever taken, and an image left with neither is flagged, its
// reflection hidden. Such spots count for no candidate's geometry either, and a glass-like
// candidate of that size takes the outermost rim the stack's maximum shows within 9% outside
// it (SphereCandidate::glass_outline).
#pragma once

#include <filesystem>
#include <optional>
#include <string>
#include <vector>

#include "ptmkit/calib/sphere.h"
#include "ptmkit/calib/sphere_refine.h"
#include "ptmkit/core/error.h"
#include "ptmkit/core/image.h"

namespace ptmkit::calib {

// A search box in photo pixels (top-left corner, width, height).
struct PixelBox {
  int x = 0, y = 0, width = 0, height = 0;
};

struct SphereSearchOptions {
  // Search boxes, one per sphere (a sphere is taken in each); empty = the whole frame.
  std::vector<PixelBox> rois;
  // Radius range in photo pixels; 0 = from 1/40 of the shorter side to the longer side.
  double min_radius_px = 0.0;
  double max_radius_px = 0.0;
  // A photo of the scene in room light (same size): its rim adds evidence.
  std::optional<std::filesystem::path> reference;
  // A candidate below this score (0..1) is refused.
  double min_score = 0.5;
  // The analysis copy's longest side, pixels.
  int analysis_max_side_px = 1280;
};

// What the spheres are, for choosing between two moving spots on one sphere.
enum class SphereMaterial {
  // Glass where at least a quarter of the images (kGlassTwoSpotShare) show a second spot of at
  // least half the first's lift across the sphere's centre from it (where a glass ball's
  // refracted hot spot lies), mirror otherwise; the decision is reported.
  kAuto,
  // Chrome, black glossy: one reflection of each light. When the spot taken proves unusable
  // the light has none; another spot is never taken in its place on a single sphere.
  kMirror,
  // A surface reflection and a refracted hot spot: when the spot taken proves unusable (not
  // compact, or reflecting to below the plane) and a comparable second spot is usable, the
  // second is taken (still doubtful).
  kGlass,
};
[[nodiscard]] const char* to_string(SphereMaterial m);

// The share of images with two spots across the centre from which kAuto decides glass.
inline constexpr double kGlassTwoSpotShare = 0.25;

struct StackCalibrationOptions {
  // The rig (spheres given or their count, camera, refinement, highlight thresholds).
  RigOptions rig;
  SphereSearchOptions search;
  SphereMaterial material = SphereMaterial::kAuto;
  // Spheres found (not given), two or more, a pinhole camera (a focal length; without one the
  // orthographic model itself makes off-centre spheres disagree): when they disagree about
  // more than kMostLightsDisagree of the usable lights under the model taken (distant, or
  // near from the evidence), they are most likely not the capture's spheres and
  // the search is made again, refining circles closer to where they were proposed and
  // choosing the spheres by how closely their lights agree (StackCalibration::search_note says
  // so); where those disagree too, SphereSearchError is thrown with the first search's
  // candidates. true: the first search's lights are kept (flagged as outliers).
  bool allow_disagreement = false;
};
// See StackCalibrationOptions::allow_disagreement.
inline constexpr double kMostLightsDisagree = 0.75;

struct SphereCandidate {
  Circle circle;           // photo pixels
  double rim = 0.0;        // 0..1
  double track = 0.0;      // 0..1
  double score = 0.0;      // 0..1
  int moving_spots = 0;    // images with a compact moving spot inside
  int distinct_spots = 0;  // of those, at their own place
  // Images with a spot bright enough to be a light's reflection, those the circle reflects
  // to below the sample plane (light_spots_px), and the share of score they leave (geometry
  // above).
  int light_spots = 0;
  int below_plane_spots = 0;
  double geometry = 1.0;  // 0..1
  bool chosen = false;
  // Glass-like (a quarter of the images show a second comparable spot across the centre) and
  // its circle taken from the outermost rim, in the stack's maximum: the full-resolution rim
  // is then not looked for more than 1% inside it (a glass ball's median shows the room's
  // refracted images ending inside the limb).
  bool glass_outline = false;
  std::string note;  // why refused, or where it came from
  // Per image, the brightest moving spot inside (photo pixels), if compact.
  std::vector<std::optional<Eigen::Vector2d>> spots_px;
  // Per image, the moving spots inside bright enough to be a light's reflection (photo
  // pixels): light_spots counts the images with one, below_plane_spots those whose every
  // such spot the circle reflects to below the sample plane.
  std::vector<std::vector<Eigen::Vector2d>> light_spots_px;
};

struct StackCalibration {
  RigReport rig;
  std::vector<SphereCandidate> candidates;  // best first; empty when the circles were given
  int two_spot_images = 0;  // images with a second moving spot of half the first's peak
  // The material the second spots were treated as (kMirror or kGlass), and why.
  SphereMaterial material = SphereMaterial::kMirror;
  std::string material_note;
  // Empty, or how the spheres were told apart when those first chosen disagreed about most
  // lights (a second search, made only then: see allow_disagreement).
  std::string search_note;
  // Per image, its exposure as a multiple of the stack's, where the exposure was found to
  // vary (empty where it does not). Measured on the spheres' discs, from the pixels the
  // stack's median shows bright (0.1-0.8 of full scale, linear) and that follow one gain per
  // image in at least 80% of the images (the room's lamps and windows mirrored): the median
  // of their ratios image / median, in linear light; 1 for an image whose light lifts them
  // too unevenly to tell (their lower quartile more than 7.5% below their median, or more
  // than half of them clipped). The exposure varies where the gains' median distance from 1
  // exceeds 3% (steady renders: at most 2.3%).
  std::vector<double> exposure_gains;
  // Per image, its shift against the stack's median (photo pixels, x right, y down), where
  // the camera was found to have moved between shots (empty where it did not): measured by
  // Gauss-Newton on the median's steepest 2% of edges at the analysis size (with the image's
  // exposure as a third unknown), weighted against what the light changes; the camera moved
  // where the shifts' median length exceeds 0.1 analysis pixels. The moving spots are then
  // measured against the median's maximum over each pixel's 3 x 3 neighbourhood (else every
  // shifted bright edge is a spot). Where the median length exceeds 0.2 analysis pixels
  // (image_shifts_undone), each highlight is also taken back into the stack's frame by its
  // image's shift (SphereLight::highlight_px) before its direction is computed; below that,
  // what the lights change can pass for shifts.
  std::vector<Eigen::Vector2d> image_shifts_px;
  bool image_shifts_undone = false;
  int analysis_scale = 1;
  int width = 0, height = 0;
  // The camera the highlights were turned into directions with (focal_px 0: orthographic),
  // and where its focal length came from.
  SphereCamera camera;
  [[nodiscard]] std::string to_json() const;
};

// Thrown when the evidence is too weak to name the spheres: carries the candidates.
class SphereSearchError : public Error {
 public:
  SphereSearchError(const std::string& message, std::vector<SphereCandidate> candidates)
      : Error(message), candidates_(std::move(candidates)) {}
  [[nodiscard]] const std::vector<SphereCandidate>& candidates() const { return candidates_; }

 private:
  std::vector<SphereCandidate> candidates_;
};

// Streams the photographs (all of one size). Throws ptmkit::Error naming a bad file or
// option (a file named as a mask whose pixels have two levels is refused as a photograph,
// pointing to the mask hint), SphereSearchError when the spheres cannot be told.
[[nodiscard]] StackCalibration calibrate_sphere_stack(
    const std::vector<std::filesystem::path>& files, const StackCalibrationOptions& options);

// The same from images in memory (tests); `names` label them.
[[nodiscard]] StackCalibration calibrate_sphere_stack(
    const std::vector<Image>& images, const std::vector<std::filesystem::path>& names,
    const StackCalibrationOptions& options);

// The candidates drawn on an image (chosen: green, refused: red, each with its score).
[[nodiscard]] Image candidates_overlay(const Image& image,
                                       const std::vector<SphereCandidate>& candidates,
                                       double scale = 1.0);

// An image reduced by an integer factor (block mean) so that its longest side is at most
// max_side_px (0 = unchanged); `scale` receives the factor applied (output = input * scale).
[[nodiscard]] Image downscale_for_overlay(const Image& image, int max_side_px, double* scale);

}  // namespace ptmkit::calib
