// Synthetic capture sets with known ground truth.
//
// A scene is rendered under a set of lights by an orthographic camera looking straight down
// (view direction +z, one pixel per texel), in the light frame of light_set.h: x to the
// image's right, y to the image's top, z toward the camera. Lights are distant (one direction
// for every texel, the default) or near: point lights on a dome of finite radius centred on
// the sample-plane centre (SynthOptions::dome_radius_mm), so every texel sees each light from
// its own direction and, optionally, with inverse-square fall-off. Two scenes:
//
//  - Relief: a height field (smooth bumps, a few long narrow grooves and "crumpled" fractal
//    noise, heights in pixels) with a colour albedo texture, shaded with Lambertian diffuse,
//    white Blinn-Phong specular, an optional ambient term and cast shadows. Its truth is the
//    diffuse-only image, per-sample outlier labels, normals, albedo and the height field.
//  - Polynomial world: every texel's RGB is exactly a known biquadratic in (lu, lv) (the
//    light direction's x and y), so a least-squares fit must recover it to float precision.
//
// A sensor model turns radiance into file values: exposure, optional sRGB encoding, additive
// Gaussian noise, quantisation and clipping at full scale. Everything random is a counter-based
// hash of (seed, what, where): results are byte-identical whatever the thread count.
//
// Output folder written by render_capture():
//   lights.lp                      count line, then `image_NNN.ext x y z` (names relative)
//   image_001.ext ...              the observed photographs
//   truth/diffuse/image_001.ext    diffuse + ambient only: no cast shadow, no specular, no
//                                  noise; same sensor encoding, bit depth and file type
//   truth/labels/image_001.png     8-bit single channel, codes below (kLabel*)
//   truth.json                     scene kind, preset, seed, size, material, sensor, lights,
//                                  images, label codes, truth files, dome radius, mm per pixel
// Near lights only (dome_radius_mm > 0):
//   lights.json                    every light's image, direction, position_mm and intensity
//                                  (the light JSON, core/light_set.h; `fit --lights-json`)
//   plane.json                     the sample plane (core/plane.h): orthographic_plane of the
//                                  image size and mm_per_px
// Relief only:
//   truth/normals.exr              float xyz unit normals, light frame
//   truth/normals.png              16-bit, (n + 1) / 2, R,G,B = x,y,z
//   truth/albedo.exr, albedo.png   linear per-channel diffuse albedo (png: 16-bit)
//   truth/height.exr               height in pixels, one channel
// Polynomial world only:
//   truth/coefficients.exr         18 float channels: channel 6 c + k is term a_k (order of
//                                  coefficients.h) of colour c (0 = R, 1 = G, 2 = B), named
//                                  c00_R_a0 ... c17_B_a5 (EXR sorts channels by name; these
//                                  names keep the order through any reader)
// (The polynomial world has no geometry: its diffuse truth equals its images and every
// label is kLabelInlier.)
#pragma once

#include <cstdint>
#include <filesystem>
#include <string>
#include <string_view>
#include <vector>

#include <Eigen/Core>

#include "ptmkit/core/coefficients.h"
#include "ptmkit/core/image.h"
#include "ptmkit/core/light_set.h"
#include "ptmkit/core/sample_label.h"

namespace ptmkit::synth {

// Per-sample outlier labels (truth/labels/*.png values): the codes of core/sample_label.h.
inline constexpr std::uint8_t kLabelInlier = label_code(SampleLabel::kInlier);
// Shadowed: the texel faces away from the light (attached shadow, n.l <= 0) or the height
// field blocks the light (cast shadow).
inline constexpr std::uint8_t kLabelShadow = label_code(SampleLabel::kShadow);
// Highlight: the specular term raises some channel by more than
// SynthOptions::highlight_threshold_grey grey levels of the output encoding, or some channel
// exceeded full scale before clipping (integer outputs).
inline constexpr std::uint8_t kLabelHighlight = label_code(SampleLabel::kHighlight);

enum class SceneKind { kRelief, kPolynomial };
[[nodiscard]] std::string_view to_string(SceneKind kind);
// "relief" or "polynomial"; throws ptmkit::Error otherwise.
[[nodiscard]] SceneKind parse_scene_kind(std::string_view name);

enum class FileType { kPng, kTiff, kExr, kJpeg };
[[nodiscard]] std::string_view to_string(FileType type);
// The extension without the dot: png, tif, exr, jpg.
[[nodiscard]] std::string_view extension(FileType type);
// "png", "tif"/"tiff", "exr", "jpg"/"jpeg"; throws ptmkit::Error otherwise.
[[nodiscard]] FileType parse_file_type(std::string_view name);

// Shape of the relief. All sizes scale with the image width, so a larger render shows the
// same scene at a finer sampling.
struct ReliefOptions {
  // Highest point above the lowest, as a fraction of the width (0.10: 25.6 px at 256 wide).
  double relief_height_frac = 0.10;
  int bumps = 24;   // smooth Gaussian blobs (a few are dimples)
  int grooves = 2;  // long narrow channels cut across the surface
  // Amplitude of the fractal value noise relative to the bumps' (0 = smooth).
  double crumple = 0.2;
};

struct MaterialOptions {
  double ks = 0.3;         // white Blinn-Phong specular weight, ks * max(0, n.h)^exponent
  double exponent = 40.0;  // Blinn-Phong exponent (> 0)
  // Multiply the specular lobe by (exponent + 8) / (8 pi), so its energy stays roughly fixed
  // as the exponent changes (off by default: ks is then the peak value).
  bool normalise_specular = false;
  double ambient = 0.0;  // ambient term ambient * albedo, added with every light
};

struct SensorOptions {
  // File value = exposure * radiance before encoding (1 = an albedo-1 surface facing the
  // light is full scale).
  double exposure = 1.0;
  bool srgb = false;  // encode with the sRGB curve (otherwise linear values)
  // Standard deviation of additive Gaussian noise, in grey levels of the output bit depth
  // (for 32-bit float output one grey level is 1/255). Added after encoding.
  double noise_sigma_grey = 1.0;
  int bits = 8;  // 8 or 16 (png, tif; jpg is 8 only) or 32 (float: exr, tif)
  FileType file_type = FileType::kPng;
  int jpeg_quality = 95;
};

struct SynthOptions {
  // Name recorded in truth.json: one of preset_names(), or "custom". The options' values are
  // what is rendered: to start from a preset, call preset_options() and change fields.
  std::string preset = "default";
  SceneKind scene = SceneKind::kRelief;
  int width = 256;   // pixels, >= 8
  int height = 256;  // pixels, >= 8
  std::uint64_t seed = 1;
  ReliefOptions relief;
  MaterialOptions material;
  SensorOptions sensor;
  bool cast_shadows = true;
  // "icosa" (geodesic dome of frequency 2: the seed paper's 40 lights), "dome49" (rings
  // 10:18,30:12,50:10,70:8,90:1), "rings:SPEC" (light_layout.h's parse_rings), or an .lp file
  // (its directions). Ignored when light_dirs is non-empty.
  std::string lights = "dome49";
  // Explicit unit light directions (light frame, z > 0); used instead of `lights` if set.
  std::vector<Eigen::Vector3d> light_dirs;
  // Grey levels (of the output encoding; 1/255 for float output) of specular that make a
  // sample a highlight (kLabelHighlight).
  double highlight_threshold_grey = 4.0;
  // Write truth/ and truth.json (off for plain benchmark captures).
  bool write_truth = true;
  // Scene scale: millimetres per pixel on the sample plane (0.5: a 256 px render spans 128
  // mm). Heights scale with it (a height of h px is h * mm_per_px mm). Only near lights use it.
  double mm_per_px = 0.5;
  // Near lights: dome radius in millimetres; 0 (default) = distant lights. Light i sits at
  // position_mm = dome_radius_mm * direction_i (light frame, origin at the plane centre) and
  // texel (x, y) at p = (X, Y, height * mm_per_px), (X, Y) = orthographic_plane's plane_mm(x,
  // y); it is lit from normalise(position - p), shading, specular, cast shadows and the truth
  // alike. Every light must be higher than the relief's top.
  double dome_radius_mm = 0.0;
  // Near lights: scale each light's radiance by (|position| / |position - p|)^2, the
  // inverse-square fall-off relative to the plane centre (1 there).
  bool inverse_square_falloff = true;
};

// Preset names: default, matte, glossy, tall, ambient, polynomial.
[[nodiscard]] std::vector<std::string> preset_names();
// The options of a named preset (documented in the .cc and in --help); throws ptmkit::Error
// naming the known presets for an unknown name.
//   default:    256x256 relief, height 10% of the width, albedo 0.3-0.9, dome49 lights,
//               Lambertian + Blinn-Phong ks 0.3 exponent 40, cast shadows, linear 8-bit PNG,
//               noise sigma 1 grey level, exposure 1 (brightest diffuse value about 0.9).
//   matte:      default with ks 0.
//   glossy:     default with ks 0.8, exponent 100.
//   tall:       default with the relief twice as high (20%).
//   ambient:    default plus ambient 0.1 x albedo, exposure 1/1.1 (same brightest diffuse).
//   polynomial: the polynomial world, 64x64, dome49, 32-bit float EXR, no noise.
[[nodiscard]] SynthOptions preset_options(std::string_view name);

// Throws ptmkit::Error with a clear message for invalid options (sizes, bit depth and file
// type, negative or non-finite values, light directions below the horizon, no lights).
void validate(const SynthOptions& options);

// The light directions of `options` (light_dirs, else the `lights` spec); validated.
[[nodiscard]] std::vector<Eigen::Vector3d> resolve_lights(const SynthOptions& options);

// A scene in memory. Maps are row-major, top row first, (x, y) in pixels.
struct Scene {
  SceneKind kind = SceneKind::kRelief;
  int width = 0;
  int height = 0;
  // Relief only (empty for the polynomial world):
  std::vector<float> height_px;  // height above the lowest point, pixels
  float max_height_px = 0.0f;
  Image normals;  // 3 channels, unit normals, light frame
  Image albedo;   // 3 channels, linear, each in [0.3, 0.9]
  // Polynomial world only: the truth, ColourModel::kRGB, colour space linear.
  CoefficientMap coefficients;

  [[nodiscard]] float height_at(int x, int y) const {
    return height_px[static_cast<std::size_t>(y) * width + x];
  }
};

// Builds the scene described by `options` (validated first).
[[nodiscard]] Scene build_scene(const SynthOptions& options);

// A relief scene from a given height field (pixels, row-major, top row first) and a uniform
// albedo: normals by central differences (one-sided at the border).
[[nodiscard]] Scene scene_from_height(int width, int height, std::vector<float> height_px,
                                      double albedo = 0.5);

// The polynomial world's value at texel (x, y) for light (lu, lv), in double precision from
// the stored float coefficients: rgb[c] = sum_k a_k(c) basis_k(lu, lv).
void evaluate_polynomial(const Scene& scene, int x, int y, double lu, double lv, double rgb[3]);

// Cast shadows of a relief for one light: 1 where the height field blocks the light, else 0.
// Marches from each texel toward the light in steps of about 0.5 px with bilinear height
// lookups, stopping at the image border or once the ray is above the highest point.
[[nodiscard]] std::vector<std::uint8_t> cast_shadow_mask(const Scene& scene,
                                                         const Eigen::Vector3d& light_dir);
// The same for the light of `options` with nominal direction `light_dir`: with near lights
// (options.dome_radius_mm > 0) each texel marches toward the light's position.
[[nodiscard]] std::vector<std::uint8_t> cast_shadow_mask(const Scene& scene,
                                                         const SynthOptions& options,
                                                         const Eigen::Vector3d& light_dir);

// The unit direction from texel (x, y) toward the light of nominal direction `light_dir`, and
// (when `falloff` is non-null) its relative intensity there: `light_dir` itself and 1 for
// distant lights; for near lights see SynthOptions::dome_radius_mm.
[[nodiscard]] Eigen::Vector3d texel_light_dir(const Scene& scene, const SynthOptions& options,
                                              const Eigen::Vector3d& light_dir, int x, int y,
                                              double* falloff = nullptr);

// One light rendered in memory: what the sensor records, and the truth.
struct RenderedLight {
  Image observed;                    // sensor values (quantised for integer bit depths), 3 channels
  Image diffuse;                     // diffuse + ambient truth through the same sensor, no noise
  std::vector<std::uint8_t> labels;  // kLabel* per texel, row-major
};

// Renders light `light_dir` (unit, z > 0; the nominal direction of a near light) as image
// number `image_index` (the index seeds the noise). The images' colour space is kSRGB when
// options.sensor.srgb, else kLinear.
[[nodiscard]] RenderedLight render_light(const Scene& scene, const SynthOptions& options,
                                         const Eigen::Vector3d& light_dir, int image_index);

struct SynthReport {
  std::filesystem::path folder;
  std::filesystem::path lp_file;
  int images = 0;
  int width = 0;
  int height = 0;
  std::vector<std::filesystem::path> files;  // every file written, in order
  double seconds = 0.0;
};

// Validates, builds the scene and writes the folder described at the top of this header.
// Lights are rendered and written in parallel groups that fit a 256 MB buffer budget (all
// lights of a small capture at once; one at a time at 12 megapixels, so memory stays at the
// scene's maps plus about one image). Every file is written atomically and depends only on
// the options, never on the thread count; nothing is written if the options or the light
// layout are invalid.
[[nodiscard]] SynthReport render_capture(const SynthOptions& options,
                                         const std::filesystem::path& out_dir);

}  // namespace ptmkit::synth
