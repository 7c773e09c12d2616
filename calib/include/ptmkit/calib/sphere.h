// Light directions from highlights on a specular sphere (mirror or black glossy) seen in the
// photographs of a capture.
//
// Per image: the highlight is the brightest compact blob on the sphere, located to sub-pixel
// by an intensity-weighted centroid (all saturated pixels equally when the peak clips). The
// sphere normal there, and the view ray, give the light by reflection: L = 2 (n.v) n - v.
// Orthographic model: v = toward the camera everywhere. Pinhole model (focal length known):
// v = back along the pixel's ray, and the normal from intersecting that ray with the sphere,
// which matters off-axis (a sphere 6 mm off-axis on the sensor tilts the view by 7 degrees
// with a 50 mm lens).
//
// Frames: pixels x right, y down, origin at the centre of the top-left pixel. Light
// directions in the light frame: x right, y toward the image top, z toward the camera.
#pragma once

#include <filesystem>
#include <optional>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "ptmkit/core/image.h"
#include "ptmkit/core/light_set.h"

namespace ptmkit::calib {

struct Circle {
  Eigen::Vector2d centre_px{0.0, 0.0};
  double radius_px = 0.0;
  // Sub-pixel points of the sphere's outline when it was measured (mask or detection); the
  // pinhole model fits the tangent cone to them, since an off-axis sphere's outline is an
  // ellipse, not this circle. Empty for a circle given by hand (then sampled on the circle).
  std::vector<Eigen::Vector2d> outline_px;
};

// The circle of a sphere mask (pixels > 0.5 are the sphere): a geometric least-squares fit
// to the sub-pixel boundary between inside and outside pixels. Throws ptmkit::Error when the
// mask has no usable region.
[[nodiscard]] Circle circle_from_mask(ConstImageViewF mask);

// Finds the most prominent sphere in a capture: the per-pixel maximum over the stack (the
// sphere's body and rim show in it), circle detection (OpenCV Hough), then a geometric fit
// to sub-pixel edge points sampled along rays from the centre. Throws ptmkit::Error when
// nothing circular is found (the message suggests --sphere or --mask).
[[nodiscard]] Circle find_sphere(const std::vector<Image>& images);

// The same for a rig of `count` spheres: the `count` strongest circles that do not overlap,
// each refined as above, ordered left to right (then top to bottom). Throws ptmkit::Error
// when fewer are found (the message suggests --sphere, once per sphere).
[[nodiscard]] std::vector<Circle> find_spheres(const std::vector<Image>& images, int count);

struct SphereCamera {
  // Focal length in pixels; 0 = orthographic camera.
  double focal_px = 0.0;
  // Principal point in pixels; nullopt = the image centre.
  std::optional<Eigen::Vector2d> principal_px;
  // Where focal_px came from, for reports ("--focal-px", "camera file ...", "EXIF ...");
  // empty: not said.
  std::string focal_source;
};

struct SphereOptions {
  // Known sphere circle (overrides detection); otherwise found by find_sphere.
  std::optional<Circle> sphere;
  SphereCamera camera;
  // Highlight blob: pixels at or above this fraction of the peak, connected to it.
  double blob_fraction = 0.7;
  // A peak below this (full scale 1) is no highlight: the light is flagged, not guessed.
  double min_peak = 0.2;
  // A blob larger than this fraction of the sphere's area is not a compact highlight.
  double max_blob_area_fraction = 0.02;
  // Only this fraction of the radius is searched (the rim reflects the scene at grazing).
  double search_radius_fraction = 0.97;

  [[nodiscard]] std::string validate() const;  // empty if valid
};

struct SphereLight {
  std::filesystem::path image;
  bool found = false;  // false: no usable highlight (see flag)
  std::string flag;    // why the light is unusable or doubtful; empty when fine
  // Where the light's reflection lies (photo pixels). Where the camera moved between shots
  // and the shifts were undone (StackCalibration::image_shifts_undone) it is placed in the
  // stack's frame, where the circle was found: the position in the photograph less the
  // image's shift.
  Eigen::Vector2d highlight_px{0.0, 0.0};
  double peak = 0.0;  // brightest value in the blob, full scale 1
  int blob_pixels = 0;
  bool saturated = false;
  Eigen::Vector3d direction{0.0, 0.0, 1.0};  // light frame, unit
  // Shape of the highlight: standard deviations (pixels) of its brightness along its major
  // and minor axes, and the major axis' angle (degrees from image x, counter-clockwise as
  // seen, i.e. toward the image top). From the same weights as the sub-pixel position.
  double blob_major_px = 0.0;
  double blob_minor_px = 0.0;
  double blob_angle_deg = 0.0;
  // The brightest pixel on the sphere away from the highlight (beyond its blob by at least
  // 3 pixels and its own size), full scale 1: a second candidate of similar brightness
  // makes the highlight ambiguous (a reflection of the scene, a second light).
  double second_peak = 0.0;
  // Which moving spot was taken (calibrate_sphere_stack): 0, the brightest (a saturated one:
  // the larger); 1, the second, because its direction agrees with the other spheres' and the
  // brightest's does not, or because the brightest is unusable (not compact, or reflecting
  // to below the sample plane) and the second is not (a glass ball's refracted hot spot).
  // second_peak is then the brightest's peak.
  int spot_rank = 0;
  // Filled by the rig refinement (sphere_refine.h); 0 / false before it.
  double residual_px = 0.0;  // predicted minus measured highlight, pixels
  double confidence = 0.0;   // 0..1, see sphere_refine.h
  bool outlier = false;      // doubtful: `flag` says why; still used unless dropped
};

struct SphereReport {
  Circle sphere;
  bool sphere_detected = false;  // true when found automatically, false when given
  std::vector<SphereLight> lights;
  [[nodiscard]] int usable() const;
  [[nodiscard]] std::string to_json() const;
};

// The light direction for a highlight at `highlight_px` on `sphere` seen by `camera`.
[[nodiscard]] Eigen::Vector3d reflect_highlight(const Circle& sphere, const SphereCamera& camera,
                                                const Eigen::Vector2d& highlight_px, int width,
                                                int height);

// The sphere's centre in the camera frame (x right, y down, z forward) in units of its
// radius, for a pinhole camera: the cone tangent to the sphere fitted to the outline's rays
// (sampled on the circle when it has no outline), with one round of 3-sigma trimming.
[[nodiscard]] Eigen::Vector3d sphere_centre_in_camera(const Circle& sphere,
                                                      const SphereCamera& camera, int width,
                                                      int height);

// The principal point: the camera's, or the image centre.
[[nodiscard]] Eigen::Vector2d principal_point(const SphereCamera& camera, int width, int height);

// Calibrates from in-memory images (same size), one light each.
[[nodiscard]] SphereReport calibrate_sphere(const std::vector<Image>& images,
                                            const std::vector<std::filesystem::path>& names,
                                            const SphereOptions& options);

// The usable lights as a light set (images and directions); flagged ones are left out.
[[nodiscard]] LightSet sphere_light_set(const SphereReport& report);

// Marks lights as dropped by the user (0-based indices into report->lights); an index out of
// range throws ptmkit::Error.
void drop_lights(const std::vector<int>& indices, SphereReport* report);

// What was detected, to be looked at: the image with the sphere's circle and centre and the
// highlight (green: used, orange: used but an outlier, red: flagged, with the reason) and
// its confidence, RGB, full scale 1. `scale`: the image's size over the photographs' (a
// downscaled overlay); `text_row`: which line of the caption (one per sphere).
[[nodiscard]] Image sphere_overlay(const Image& image, const SphereReport& report,
                                   std::size_t light_index, double scale = 1.0, int text_row = 0);

// A polar plot of the usable lights (azimuth around, elevation from the rim (0 degrees) to
// the centre (90)), each labelled with its index; flagged lights listed in red. Square, RGB.
[[nodiscard]] Image light_polar_plot(const SphereReport& report, int size_px = 600);

}  // namespace ptmkit::calib
