// A rig of one or more specular spheres, refined as a whole: sphere geometry and every light
// from all highlights and outline points together (Ceres, robust loss), each light with a
// residual in pixels, a confidence and flags; with two or more spheres of known size and a
// pinhole camera, light positions (near lights) by triangulation.
//
// Models (the camera never moves, so there is no gauge freedom):
//   orthographic, distant lights   per sphere its circle (cx, cy, r in pixels); per light a
//                                  unit direction. Highlight of L: the point whose normal is
//                                  the bisector of L and the view direction.
//   pinhole, distant lights        per sphere its centre in the camera frame in units of its
//                                  radius (radius 1); per light a unit direction.
//   pinhole, near lights           per sphere its centre in millimetres (radius given in mm);
//                                  per light its position in millimetres. Needs 2+ spheres:
//                                  one sphere gives a light's direction, not its distance.
// Residuals, in pixels: each highlight's predicted minus measured position; each outline
// point's distance to the predicted outline (pinhole: the angle between its ray and the
// tangent cone, times the focal length: pixels near the principal point). Huber loss on all.
//
// What a residual can tell. A distant light seen on one sphere has 2 unknowns and 2
// measurements: its highlight residual is zero by construction, whatever the highlight. It
// becomes a check only with redundancy: 2+ spheres (a distant light must be seen along the
// same direction on each; a near light, 3 unknowns, 2 per sphere). For every sphere count the
// highlight itself is also checked: its shape against the shape a small light should have
// there, and a second candidate of similar brightness elsewhere on the sphere.
//
// Confidence of a light on a sphere (0..1), the product of:
//   residual   1 / (1 + (residual_px / outlier_px)^2)
//   shape      expected / measured elongation, or its inverse, whichever is <= 1; elongation
//              = sqrt((major^2 + 0.25) / (minor^2 + 0.25)) (0.5 px in quadrature, so that
//              pixel-sized blobs count as round); expected: the same with minor = major *
//              cos^2(theta), theta the angle between the sphere normal and the view ray there
//              (a small round light's reflection is foreshortened so, across the radius)
//   ambiguity  1 - second_peak / peak (0 when a second candidate is as bright)
//   strength   (peak - min_peak) / min_peak, at most 1
// A rig light's confidence is the lowest over the spheres that see it.
//
// Outliers (flagged, `outlier` true, still used unless dropped): residual above outlier_px,
// elongation off by more than max_shape_ratio either way, or a second candidate of at least
// ambiguous_fraction of the peak.
#pragma once

#include <filesystem>
#include <optional>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "ptmkit/calib/sphere.h"
#include "ptmkit/core/image.h"
#include "ptmkit/core/light_set.h"
#include "ptmkit/core/plane.h"

namespace ptmkit::calib {

struct RigOptions {
  // Highlight detection and the camera (detection.sphere is ignored: see spheres).
  SphereOptions detection;
  // The spheres' circles; empty = find sphere_count of them (find_spheres).
  std::vector<Circle> spheres;
  int sphere_count = 1;
  // The spheres' real radius in millimetres. With a pinhole camera and 2+ spheres: near
  // lights, positions triangulated. 0 = distant lights (directions only), unless the
  // evidence asks for near ones (near_from_evidence).
  double sphere_radius_mm = 0.0;
  // With a pinhole camera, 2+ spheres, no sphere radius and no sample plane: where most
  // lights are outliers as distant lights (the spheres see them along different directions:
  // a dome whose lights are near), near lights are tried with distances in units of the
  // sphere radius, and taken where they leave at most a quarter of the lights outliers and
  // at most half as many as the distant model. Directions are then from the light frame's
  // origin; positions are not reported (their scale needs sphere_radius_mm). A light seen on
  // one sphere only keeps its direction from that sphere, flagged.
  bool near_from_evidence = true;
  // The sample plane (optional; pinhole only; needs its pose and the images' size): light
  // frame and origin from it. Without it
  // the light frame is the camera's turned to face it (x right, y up the image, z toward the
  // camera) with its origin on the optical axis at the spheres' mean depth.
  std::optional<SamplePlane> plane;
  // Ceres refinement (false: per-sphere reflections averaged, positions by linear
  // triangulation; residuals still reported).
  bool refine = true;
  // Huber loss scale in pixels (about the highlight locator's noise).
  double loss_scale_px = 0.5;
  // Flags (see above).
  double outlier_px = 1.5;
  double max_shape_ratio = 2.5;
  double ambiguous_fraction = 0.6;
  int max_iterations = 200;

  [[nodiscard]] std::string validate() const;  // empty if valid
};

struct RigLight {
  std::filesystem::path image;
  bool found = false;    // a usable result (a highlight on enough spheres)
  bool outlier = false;  // doubtful, see flag; left in unless dropped
  std::string flag;      // why unusable or doubtful ("; "-separated); empty when fine
  int spheres_seen = 0;  // spheres with a usable highlight of this light
  Eigen::Vector3d direction{0.0, 0.0, 1.0};           // light frame, unit (near: from the origin)
  std::optional<Eigen::Vector3d> position_mm;         // light frame (near lights)
  std::optional<Eigen::Vector3d> position_camera_mm;  // camera frame (near lights)
  double residual_px = 0.0;  // RMS over the spheres of the highlight residual
  double confidence = 0.0;   // 0..1, see above
};

struct RigReport {
  // Per sphere: its circle as detected (or given) and every light's highlight on it, with
  // the per-sphere residual, confidence and outlier flag.
  std::vector<SphereReport> spheres;
  // Refined geometry: orthographic, the circles; pinhole, the centres in the camera frame
  // (mm for near lights, else units of the radius) before and after refinement.
  std::vector<Circle> refined_circles;
  std::vector<Eigen::Vector3d> centres_camera_initial;
  std::vector<Eigen::Vector3d> centres_camera;
  double outline_rms_px = 0.0;  // outline residual after refinement
  bool refined = false;
  bool near = false;
  // Near lights chosen from the evidence (near_from_evidence): distances in units of the
  // sphere radius, no positions; `model_note` says why.
  bool near_scale_free = false;
  std::string model_note;
  std::string model;   // "orthographic distant", "pinhole distant", "pinhole near"
  std::string origin;  // where the light frame's origin is
  int iterations = 0;
  std::vector<RigLight> lights;

  [[nodiscard]] int usable() const;
  [[nodiscard]] int outliers() const;
  // More than half of the usable lights are outliers: the spheres see most lights along
  // different directions (near lights taken as distant, or circles that are not spheres).
  [[nodiscard]] bool most_lights_outliers() const;
  [[nodiscard]] std::string to_json() const;
};

// Finds (or takes) the spheres, the highlights on each, and refines the rig.
[[nodiscard]] RigReport calibrate_rig(const std::vector<Image>& images,
                                      const std::vector<std::filesystem::path>& names,
                                      const RigOptions& options);

// The refinement alone, from highlights already measured: one report per sphere (its circle
// and one SphereLight per image, in the order of `names`), for images of w x h pixels.
// calibrate_rig measures them with calibrate_sphere; calibrate_sphere_stack (sphere_stack.h)
// streams the photographs instead.
[[nodiscard]] RigReport refine_rig(std::vector<SphereReport> spheres,
                                   const std::vector<std::filesystem::path>& names, int w, int h,
                                   const RigOptions& options);

// The usable lights (directions, and positions for near lights); flagged-unusable and
// dropped ones left out.
[[nodiscard]] LightSet rig_light_set(const RigReport& report);

// Marks lights as dropped (0-based indices; out of range throws ptmkit::Error), or every
// light flagged as an outlier.
void drop_rig_lights(const std::vector<int>& indices, RigReport* report);
int drop_outliers(RigReport* report);  // returns how many were dropped

}  // namespace ptmkit::calib
