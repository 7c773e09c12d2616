// Rendered captures as a photographer takes them: calibration spheres (black glossy, chrome,
// glass) on bases beside the object, or one large sphere filling the frame; a lit or dark room
// with windows and lamps reflected in the spheres; a coin or dish that is round but no mirror
// sphere; and the camera's artefacts (flare streaks and bloom around saturated highlights,
// vignetting, noise, sRGB JPEG). Every artefact can be switched off (PhotoOptions).
//
// Geometry. A pinhole camera at the origin of the camera frame (x right, y down, z forward;
// millimetres) with focal length focal_px and principal point principal_px; pixel (x, y) has
// its centre at integer coordinates, origin at the centre of the top-left pixel, and looks
// along ((x - cx) / f, (y - cy) / f, 1). Two views:
//  - kTopDown (a dome or copy stand): the ground (a cloth or table) is the plane z =
//    camera_height_mm, facing the camera; the object (synth.h's relief, as a texture) lies on
//    it at the image centre, the spheres beside it, each resting in a cup-shaped base.
//  - kSide (a large sphere in a room): the camera looks horizontally; the floor is the plane
//    y = floor below the sphere, the room (environment) is seen behind it; the sphere stands
//    in a cup on a pedestal whose rim hides the bottom of its outline.
// Lights are distant: unit directions in the light frame of light_set.h (x to the image's
// right, y to its top, z toward the camera), each a small disc of light_radius_deg seen in
// mirrors, giving irradiance light_irradiance on a surface facing it.
//
// Materials. Chrome: a mirror of reflectance 0.8 (rising toward 1 at grazing). Black glossy:
// a dark diffuse body (albedo 0.02) under a dielectric mirror of Schlick reflectance F0 =
// 0.05. Glass: the same surface reflection, plus the light refracted through the ball (index
// 1.5): rays are traced through the glass (one internal reflection), and the light the ball
// focuses onto the ground (its caustic, on the far side from the light) is seen beside and
// through the ball: a hot spot that does not obey mirror geometry. The coin is a flat metal
// disc (silver ring, brass centre, bevelled rim, a low relief) and the dish a shallow glazed
// bowl: their specular bits move with the light, but not as a sphere's reflection does.
//
// What the images show is static except for the light: windows, lamps, the room and the
// scene reflected in the spheres are lit by the room only, so their reflections are the same
// in every image; the light's highlight, its direct shading and shadows move.
//
// Sensor and lens, in this order: radiance (1 = full scale at exposure 1; times the image's
// exposure jitter) -> the image's shake (a sub-pixel shift) -> vignetting ->
// flare (star-shaped streaks: each saturated pixel's excess above full scale spread along
// flare_spokes spokes) -> bloom (a Gaussian halo of the excess) -> noise (shot + read) ->
// clipping at full scale -> sRGB encoding (or linear) -> quantisation -> file (JPEG at
// jpeg_quality, or PNG/TIFF). All randomness is a hash of (seed, image, pixel): results are
// byte-identical for any thread count.
//
// Truth (written by render_photo_capture beside the images):
//   lights.lp           the true light directions (light frame), `image_NNN.jpg x y z`
//   truth.json          schema below
//   truth/sphere_K.png  8-bit mask of sphere K's visible pixels (K = 1, 2, ...; 255 where
//                       the pixel's centre sees the sphere, cut by the frame and the base)
// truth.json:
//   generator, kind ("photo"), preset, seed, width, height
//   camera: model "pinhole", focal_px, principal_px [x, y], view ("top-down" | "side"),
//           frame (text)
//   spheres: per sphere, in the order of PhotoOptions::spheres (the presets: left to right):
//     material ("black-glossy" | "chrome" | "glass"), centre_mm [x,y,z], radius_mm (camera
//     frame), circle {centre_px [x,y], radius_px} (see below), ellipse {centre_px, semi_major_px,
//     semi_minor_px, angle_deg (major axis from image x toward image y)},
//     centre_projection_px (where the sphere's centre projects; differs from the outline's
//     centre off-axis), outline_inside_frame (fraction of the outline inside the image),
//     outline_visible (fraction inside the image and not hidden by the base or another
//     object), base {radius_mm (the cup holding the sphere), outer_radius_mm, top_mm (the rim's
//     distance below the centre)} or null,
//     mask ("truth/sphere_K.png"), highlight_px per image ([x, y] where mirror geometry puts
//     the light's reflection, or null when it is hidden or outside the frame)
//   "circle" is what a detector should report for a sphere: the centre of its projected
//   outline (an ellipse under a pinhole camera: the cone tangent to the sphere cut by the
//   image plane) and the mean of the ellipse's semi-axes as radius. A circle fitted to the
//   outline lands there to a few thousandths of a pixel at these ellipticities.
//   circle_definition: the sentence above, in words
//   distractor: {kind ("coin" | "dish" | "none"), centre_px, radius_px (its outline's circle),
//               offset_mm (on the ground from the point under the image centre: x right, y
//               down), radius_mm}; only kind when none
//   object: whether the relief is on the ground
//   environment: {kind ("dark" | "lit"), windows, lamps, reflect_scene}
//   lights: {count, file, frame, light_radius_deg, light_irradiance}; images: per image
//           {file, light_dir [x,y,z] (light frame), elevation_deg, exposure_factor (with
//           exposure jitter), shake_px [dx, dy] (with shake: add it to the circles and
//           highlights above to place them in this image)}
//   artefacts: {flare {on, spokes, strength, length_frac, angle_deg}, bloom {on, sigma_frac,
//               strength}, vignetting {on, corner_loss}, noise {on, read_grey, shot_full_well},
//               exposure_jitter_ev, shake_px}
//   sensor: {exposure, colour_space ("srgb" | "linear"), format, bits, jpeg_quality,
//            exif {focal_mm, sensor_width_mm} (JPEG with an EXIF block) or null}
#pragma once

#include <cstdint>
#include <filesystem>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include <Eigen/Core>

#include "ptmkit/core/image.h"
#include "ptmkit/synth/synth.h"

namespace ptmkit::synth {

enum class SphereMaterial { kBlackGlossy, kChrome, kGlass };
[[nodiscard]] std::string_view to_string(SphereMaterial m);
// "black-glossy" (or "black"), "chrome", "glass"; throws ptmkit::Error otherwise.
[[nodiscard]] SphereMaterial parse_sphere_material(std::string_view name);

enum class PhotoView { kTopDown, kSide };
enum class PhotoEnvironment { kDark, kLit };
[[nodiscard]] std::string_view to_string(PhotoEnvironment e);
// "dark" or "lit"; throws ptmkit::Error otherwise.
[[nodiscard]] PhotoEnvironment parse_environment(std::string_view name);

enum class Distractor { kNone, kCoin, kDish };
[[nodiscard]] std::string_view to_string(Distractor d);
// "none", "coin" or "dish"; throws ptmkit::Error otherwise.
[[nodiscard]] Distractor parse_distractor(std::string_view name);

// A sphere in the camera frame, millimetres.
struct PhotoSphere {
  Eigen::Vector3d centre_mm{0.0, 0.0, 400.0};
  double radius_mm = 12.5;
  SphereMaterial material = SphereMaterial::kBlackGlossy;
};

// Lens and sensor artefacts, each with an on/off switch (defaults: all on).
struct PhotoArtefacts {
  bool flare = true;
  int flare_spokes = 6;             // even, 2..16: streaks in opposite pairs
  double flare_angle_deg = 15.0;    // first spoke's angle from image x
  double flare_strength = 0.02;     // fraction of the saturated excess spread into the streaks
  double flare_length_frac = 0.06;  // e-folding length of a streak, fraction of the diagonal
  bool bloom = true;
  double bloom_strength = 0.05;    // fraction of the excess spread into the halo
  double bloom_sigma_frac = 0.01;  // halo's Gaussian sigma, fraction of the image diagonal
  bool vignetting = true;
  // Brightness lost in the image corners (0.35: corners at 65%); the centre (10% of the
  // half-diagonal) is untouched.
  double vignetting_corner_loss = 0.35;
  bool noise = true;
  double read_noise_grey = 1.0;  // read noise sigma, grey levels of 8 bits (linear)
  // Shot noise: electrons at full scale (variance = value / full_well, full scale 1).
  double shot_full_well = 4000.0;
  // Exposure that differs from image to image (a camera left on automatic exposure, a flash
  // whose output varies): each image's radiance times 2^(u x exposure_jitter_ev), u uniform in
  // [-1, 1] per image. 0: every image alike (the default).
  double exposure_jitter_ev = 0.0;
  // A camera that moves between shots (a tripod knocked, mirror slap): each image's optical
  // image shifted by a vector uniform in a disc of this radius, pixels, before the lens
  // artefacts. truth.json keeps the unshifted circles and records each image's shift. 0: none.
  double shake_px = 0.0;
};

struct PhotoOptions {
  // Name recorded in truth.json: one of photo_preset_names(), or "custom".
  std::string preset = "photo-dome";
  int width = 640;   // pixels, >= 32
  int height = 360;  // pixels, >= 32
  std::uint64_t seed = 1;
  PhotoView view = PhotoView::kTopDown;
  // Pinhole focal length in pixels (> 0) and principal point (nullopt: the image centre,
  // ((width - 1) / 2, (height - 1) / 2)).
  double focal_px = 1280.0;
  std::optional<Eigen::Vector2d> principal_px;
  // kTopDown: the ground's distance from the camera; kSide: the floor's distance below the
  // optical axis is taken from the spheres and bases.
  double camera_height_mm = 400.0;
  std::vector<PhotoSphere> spheres;
  // Every sphere rests in a cup-shaped base (a cylinder along "down" whose rim holds the
  // sphere): base_radius_frac of the sphere's radius, standing on the ground (kTopDown; its
  // height is the gap between the sphere and the ground) or on the floor (kSide).
  bool sphere_bases = true;
  double base_radius_frac = 0.6;
  // The base's outer radius (fraction of the sphere's): wider than the sphere, a stand whose
  // flat top (at the cup's rim) rings the sphere as seen from above; at most the cup's
  // radius, a pedestal under it.
  double base_outer_frac = 1.2;
  // The relief object on the ground at the image centre (kTopDown only), a square of this
  // side; its texture resolution follows the pixel scale.
  bool object = true;
  double object_size_mm = 90.0;
  ReliefOptions relief;
  MaterialOptions object_material;
  Distractor distractor = Distractor::kCoin;
  // Where the distractor lies on the ground (mm from the image centre's ground point, x right,
  // y down) and its radius.
  Eigen::Vector2d distractor_offset_mm{-80.0, 30.0};
  double distractor_radius_mm = 12.0;
  PhotoEnvironment environment = PhotoEnvironment::kDark;
  int windows = 2;  // bright rectangles in the room (0..8)
  int lamps = 2;    // small bright discs in the room (0..8)
  // Sphere reflections show the scene (ground, object, bases, other spheres, the camera)
  // before the room; off: the room only.
  bool reflect_scene = true;
  double ground_albedo = 0.04;  // the cloth (dark by default)
  // Lights: as SynthOptions::lights ("dome49", "icosa", "rings:SPEC", an .lp file), or
  // explicit directions (light frame, z > 0).
  std::string lights = "rings:15:8,40:8,65:6";
  std::vector<Eigen::Vector3d> light_dirs;
  double light_radius_deg = 0.6;
  double light_irradiance = 0.9;
  PhotoArtefacts artefacts;
  // Sensor: exposure multiplies the radiance; sRGB encoding; file type and bit depth as in
  // SensorOptions (JPEG: 8 bits).
  double exposure = 1.0;
  bool srgb = true;
  FileType file_type = FileType::kJpeg;
  int bits = 8;
  int jpeg_quality = 92;
  // JPEG files carry an EXIF block as a camera's do (FocalLength, the sensor's pixel pitch,
  // the 35 mm equivalent) for focal_px on a sensor this wide (mm; 23.5: APS-C); 0: none.
  double exif_sensor_width_mm = 23.5;
  // Sub-samples per pixel side on edges and highlights (the rest: one sample at the centre).
  int supersample = 4;
};

// photo-dome, photo-large-sphere, photo-glass, photo-chrome.
[[nodiscard]] std::vector<std::string> photo_preset_names();
[[nodiscard]] bool is_photo_preset(std::string_view name);
// The options of a named preset; throws ptmkit::Error naming the known presets otherwise.
//   photo-dome:         top-down, 640x360 (16:9 like 4608x2592), focal 1280 px at 400 mm:
//                       the relief (90 mm) between two black glossy spheres (radius 12.5 mm,
//                       70 mm left and right) in cups, a coin below the object, dark cloth,
//                       dark room with 2 windows and 2 lamps, 22 lights (rings 15/40/65
//                       degrees), every artefact on, sRGB JPEG quality 92.
//   photo-glass:        photo-dome with glass marbles (radius 9 mm, 75 mm left and right)
//                       lying on the cloth (no bases), and a coin.
//   photo-chrome:       photo-dome with chrome spheres and a dish instead of the coin.
//   photo-large-sphere: side view, one black glossy sphere (radius 150 mm, 650 mm away,
//                       focal 760 px: radius about 180 px in a 640x360 frame, cut by the
//                       top edge) in a cup on a pedestal, dark room with 3 windows and 3
//                       lamps reflected, 12 lights 20-60 degrees from the view axis, strong
//                       8-spoke star flares.
[[nodiscard]] PhotoOptions photo_preset_options(std::string_view name);

// Scales a preset's image size (and its focal length) to width x height keeping the scene:
// the focal length scales with the width, the height must keep the aspect within 1%.
void resize_photo(int width, int height, PhotoOptions* options);

// Throws ptmkit::Error with a clear message for invalid options.
void validate(const PhotoOptions& options);

// The light directions of `options` (light_dirs, else the `lights` spec), unit, light frame.
[[nodiscard]] std::vector<Eigen::Vector3d> resolve_lights(const PhotoOptions& options);

struct SphereOutline {
  Eigen::Vector2d centre_px{0.0, 0.0};  // the outline's centre (the ellipse's)
  double radius_px = 0.0;               // (semi_major + semi_minor) / 2
  double semi_major_px = 0.0;
  double semi_minor_px = 0.0;
  double angle_deg = 0.0;                          // major axis, from image x toward image y
  Eigen::Vector2d centre_projection_px{0.0, 0.0};  // the sphere centre's projection
};

// The projected outline of a sphere (camera frame, mm) under a pinhole camera.
[[nodiscard]] SphereOutline sphere_outline(const Eigen::Vector3d& centre_mm, double radius_mm,
                                           double focal_px, const Eigen::Vector2d& principal_px);

// Where a mirror sphere reflects a distant light toward a pinhole camera at the origin: the
// surface point whose normal bisects the directions to the camera and to the light, in
// pixels. `light_dir` is in the light frame. nullopt when the light is behind the sphere as
// seen from the camera (no reflection reaches the camera).
[[nodiscard]] std::optional<Eigen::Vector2d> mirror_highlight_px(
    const Eigen::Vector3d& centre_mm, double radius_mm, const Eigen::Vector3d& light_dir,
    double focal_px, const Eigen::Vector2d& principal_px);

struct PhotoSphereTruth {
  PhotoSphere sphere;
  SphereOutline outline;
  double outline_inside_frame = 1.0;
  double outline_visible = 1.0;
  // Per light: the mirror highlight, or nullopt when hidden (by the base, another sphere, the
  // frame) or absent.
  std::vector<std::optional<Eigen::Vector2d>> highlight_px;
};

struct PhotoTruth {
  std::vector<PhotoSphereTruth> spheres;  // in the order of PhotoOptions::spheres
  std::vector<Eigen::Vector3d> light_dirs;
  Eigen::Vector2d principal_px{0.0, 0.0};
  // The distractor's outline (zero radius when none).
  Eigen::Vector2d distractor_centre_px{0.0, 0.0};
  double distractor_radius_px = 0.0;
};

// Image `index`'s exposure as a multiple of options.exposure (2^u, u uniform in
// [-exposure_jitter_ev, exposure_jitter_ev]; 1 without jitter) and its shake (the shift of its
// optical image, pixels, within a disc of shake_px; zero without), as the renders apply and
// truth.json records them: pure functions of the seed and the index.
[[nodiscard]] double exposure_factor(const PhotoOptions& options, int index);
[[nodiscard]] Eigen::Vector2d shake_offset_px(const PhotoOptions& options, int index);

// How far shifts measured per image (photo pixels, one per light, in order) lie from the
// renders' shake_offset_px, each set taken about its own mean (shifts measured against a
// stack's median are known up to a common offset): rms and worst, pixels. Throws
// ptmkit::Error when there are none.
struct ShakeError {
  double rms_px = 0.0;
  double worst_px = 0.0;
};
[[nodiscard]] ShakeError shake_error(const PhotoOptions& options,
                                     const std::vector<Eigen::Vector2d>& measured_px);

// A photo capture in memory: the scene built once, then any light rendered.
class PhotoRenderer {
 public:
  // Validates the options and builds the scene (the relief, the room, the truth).
  explicit PhotoRenderer(const PhotoOptions& options);
  ~PhotoRenderer();
  PhotoRenderer(const PhotoRenderer&) = delete;
  PhotoRenderer& operator=(const PhotoRenderer&) = delete;

  [[nodiscard]] const PhotoOptions& options() const;
  [[nodiscard]] const PhotoTruth& truth() const;
  // The photograph under light `index` (of truth().light_dirs), 3 channels, values as the
  // file will hold them before JPEG compression (quantised for 8/16 bits), colour space sRGB
  // or linear as options().srgb.
  [[nodiscard]] Image render(int index) const;
  // The same before the sensor: linear radiance after vignetting, flare and bloom, without
  // noise, clipping or encoding (exposure applied; 1 = full scale).
  [[nodiscard]] Image render_radiance(int index) const;
  // Sphere k's visibility mask (1 channel, 1 where a pixel's centre sees the sphere, else 0).
  [[nodiscard]] Image sphere_mask(int k) const;

 private:
  struct Impl;
  Impl* impl_;
};

struct PhotoReport {
  std::filesystem::path folder;
  std::filesystem::path lp_file;
  int images = 0;
  int width = 0;
  int height = 0;
  std::vector<std::filesystem::path> files;
  double seconds = 0.0;
};

// Renders every light and writes the folder described at the top of this header (images in
// parallel; every file atomic; nothing written if the options are invalid).
[[nodiscard]] PhotoReport render_photo_capture(const PhotoOptions& options,
                                               const std::filesystem::path& out_dir);

}  // namespace ptmkit::synth
