// The photo scene: geometry, materials, the room, and the truth (photo.h).
#include "ptmkit/synth/photo.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <numbers>
#include <string>

#include <Eigen/Eigenvalues>

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include "hash.h"
#include "optics.h"
#include "photo_internal.h"
#include "ptmkit/core/error.h"
#include "render.h"

namespace ptmkit::synth {

namespace {

constexpr double kPi = std::numbers::pi;
constexpr double kDeg = kPi / 180.0;
constexpr double kInf = std::numeric_limits<double>::infinity();
constexpr double kEps = 1e-6;
constexpr double kGlassIndex = 1.5;
constexpr double kCameraBodyRadiusMm = 45.0;
// Glass scatters the light it transmits over a wider cone (bubbles, striae, the ball not
// being a perfect lens): the disc seen through it is this many times wider, as bright in
// total.
constexpr double kGlassBlur = 3.0;

using V3 = Eigen::Vector3d;
using V2 = Eigen::Vector2d;
using Rgb = Eigen::Array3d;

void require(bool ok, const std::string& message) {
  if (!ok) throw Error("synth photo: " + message);
}

double smoothstep(double e0, double e1, double x) {
  const double t = std::clamp((x - e0) / (e1 - e0), 0.0, 1.0);
  return t * t * (3.0 - 2.0 * t);
}

}  // namespace

std::string_view to_string(SphereMaterial m) {
  switch (m) {
    case SphereMaterial::kBlackGlossy:
      return "black-glossy";
    case SphereMaterial::kChrome:
      return "chrome";
    case SphereMaterial::kGlass:
      return "glass";
  }
  return "black-glossy";
}

SphereMaterial parse_sphere_material(std::string_view name) {
  if (name == "black-glossy" || name == "black") return SphereMaterial::kBlackGlossy;
  if (name == "chrome") return SphereMaterial::kChrome;
  if (name == "glass") return SphereMaterial::kGlass;
  throw Error("synth: unknown sphere material '" + std::string(name) +
              "' (expected black-glossy, chrome or glass)");
}

std::string_view to_string(PhotoEnvironment e) {
  return e == PhotoEnvironment::kDark ? "dark" : "lit";
}

PhotoEnvironment parse_environment(std::string_view name) {
  if (name == "dark") return PhotoEnvironment::kDark;
  if (name == "lit") return PhotoEnvironment::kLit;
  throw Error("synth: unknown environment '" + std::string(name) + "' (expected dark or lit)");
}

std::string_view to_string(Distractor d) {
  switch (d) {
    case Distractor::kNone:
      return "none";
    case Distractor::kCoin:
      return "coin";
    case Distractor::kDish:
      return "dish";
  }
  return "none";
}

Distractor parse_distractor(std::string_view name) {
  if (name == "none") return Distractor::kNone;
  if (name == "coin") return Distractor::kCoin;
  if (name == "dish") return Distractor::kDish;
  throw Error("synth: unknown distractor '" + std::string(name) +
              "' (expected coin, dish or none)");
}

std::vector<std::string> photo_preset_names() {
  return {"photo-dome", "photo-glass", "photo-chrome", "photo-large-sphere"};
}

bool is_photo_preset(std::string_view name) {
  const auto names = photo_preset_names();
  return std::find(names.begin(), names.end(), name) != names.end();
}

PhotoOptions photo_preset_options(std::string_view name) {
  PhotoOptions o;
  o.preset = std::string(name);
  // Top-down dome: ground 400 mm away, 3.2 px per mm there.
  auto dome_spheres = [&](double radius_mm, SphereMaterial m, double stand_frac) {
    // Each sphere rests in a cup of radius base_radius_frac * r on a stand stand_frac * r
    // tall.
    const double rise =
        radius_mm * (stand_frac + std::sqrt(1.0 - o.base_radius_frac * o.base_radius_frac));
    o.spheres = {PhotoSphere{V3(-80.0, -20.0, o.camera_height_mm - rise), radius_mm, m},
                 PhotoSphere{V3(80.0, -20.0, o.camera_height_mm - rise), radius_mm, m}};
  };
  if (name == "photo-dome") {
    dome_spheres(12.5, SphereMaterial::kBlackGlossy, 0.4);
    return o;
  }
  if (name == "photo-glass") {
    // Marbles lying on the cloth: the cloth under and beside them, where their caustic falls,
    // is seen through them.
    o.sphere_bases = false;
    o.spheres = {
        PhotoSphere{V3(-75.0, -20.0, o.camera_height_mm - 9.0), 9.0, SphereMaterial::kGlass},
        PhotoSphere{V3(75.0, -20.0, o.camera_height_mm - 9.0), 9.0, SphereMaterial::kGlass}};
    return o;
  }
  if (name == "photo-chrome") {
    dome_spheres(12.5, SphereMaterial::kChrome, 0.4);
    o.distractor = Distractor::kDish;
    o.distractor_radius_mm = 17.0;
    return o;
  }
  if (name == "photo-large-sphere") {
    o.view = PhotoView::kSide;
    o.focal_px = 760.0;
    o.base_outer_frac = o.base_radius_frac;
    o.object = false;
    o.distractor = Distractor::kNone;
    o.windows = 3;
    o.lamps = 3;
    o.ground_albedo = 0.06;
    // Centre at pixel (300, 150): the top of the outline leaves the frame, the cup hides the
    // bottom.
    const double z = 650.0;
    o.spheres = {PhotoSphere{V3((300.0 - 319.5) / 760.0 * z, (150.0 - 179.5) / 760.0 * z, z), 150.0,
                             SphereMaterial::kBlackGlossy}};
    o.lights = "rings:65:4:45,45:4:0,28:4:22.5";
    o.artefacts.flare_spokes = 8;
    o.artefacts.flare_strength = 0.5;
    o.artefacts.flare_length_frac = 0.04;
    return o;
  }
  throw Error("synth: unknown photo preset '" + std::string(name) +
              "' (expected photo-dome, photo-glass, photo-chrome or photo-large-sphere)");
}

void resize_photo(int width, int height, PhotoOptions* o) {
  require(width >= 32 && height >= 32, "image size " + std::to_string(width) + "x" +
                                           std::to_string(height) +
                                           " is too small (at least 32x32)");
  const double scale = static_cast<double>(width) / o->width;
  const double aspect_old = static_cast<double>(o->width) / o->height;
  const double aspect_new = static_cast<double>(width) / height;
  require(std::abs(aspect_new / aspect_old - 1.0) < 0.01,
          "a photo preset keeps its aspect ratio: " + std::to_string(width) + "x" +
              std::to_string(height) + " differs from " + std::to_string(o->width) + "x" +
              std::to_string(o->height) + " by more than 1%");
  o->focal_px *= scale;
  if (o->principal_px) {
    *o->principal_px = (*o->principal_px + V2(0.5, 0.5)) * scale - V2(0.5, 0.5);
  }
  o->width = width;
  o->height = height;
}

void validate(const PhotoOptions& o) {
  require(o.preset == "custom" || is_photo_preset(o.preset), "unknown preset '" + o.preset + "'");
  require(o.width >= 32 && o.height >= 32, "image size " + std::to_string(o.width) + "x" +
                                               std::to_string(o.height) +
                                               " is too small (at least 32x32)");
  require(o.width <= 20000 && o.height <= 20000 && static_cast<double>(o.width) * o.height <= 100e6,
          "image size too large (at most 20000 a side and 100 megapixels)");
  require(std::isfinite(o.focal_px) && o.focal_px > 0.0, "focal length must be > 0 pixels");
  if (o.principal_px) require(o.principal_px->allFinite(), "principal point must be finite");
  require(std::isfinite(o.camera_height_mm) && o.camera_height_mm > 0.0,
          "camera height must be > 0 mm");
  require(!o.spheres.empty() && o.spheres.size() <= 4, "1 to 4 spheres");
  for (std::size_t i = 0; i < o.spheres.size(); ++i) {
    const PhotoSphere& s = o.spheres[i];
    require(s.centre_mm.allFinite() && std::isfinite(s.radius_mm) && s.radius_mm > 0.0,
            "sphere " + std::to_string(i + 1) + " has a non-finite centre or radius <= 0");
    require(s.centre_mm.z() > s.radius_mm + kCameraBodyRadiusMm,
            "sphere " + std::to_string(i + 1) + " must lie in front of the camera");
    if (o.view == PhotoView::kTopDown) {
      require(s.centre_mm.z() + s.radius_mm <= o.camera_height_mm + 1e-9,
              "sphere " + std::to_string(i + 1) + " reaches below the ground");
    }
    for (std::size_t j = 0; j < i; ++j) {
      require((s.centre_mm - o.spheres[j].centre_mm).norm() > s.radius_mm + o.spheres[j].radius_mm,
              "spheres " + std::to_string(j + 1) + " and " + std::to_string(i + 1) + " overlap");
    }
  }
  require(
      std::isfinite(o.base_radius_frac) && o.base_radius_frac > 0.05 && o.base_radius_frac < 0.95,
      "base radius fraction must be in (0.05, 0.95)");
  require(std::isfinite(o.base_outer_frac) && o.base_outer_frac >= 0.0 && o.base_outer_frac <= 3.0,
          "base outer radius fraction must be in [0, 3]");
  require(std::isfinite(o.object_size_mm) && o.object_size_mm > 0.0, "object size must be > 0");
  require(o.distractor_offset_mm.allFinite() && std::isfinite(o.distractor_radius_mm) &&
              o.distractor_radius_mm > 0.0,
          "distractor position must be finite and its radius > 0");
  require(o.windows >= 0 && o.windows <= 8 && o.lamps >= 0 && o.lamps <= 8,
          "windows and lamps: 0..8 each");
  require(std::isfinite(o.ground_albedo) && o.ground_albedo >= 0.0 && o.ground_albedo <= 1.0,
          "ground albedo must be in [0, 1]");
  require(
      std::isfinite(o.light_radius_deg) && o.light_radius_deg > 0.01 && o.light_radius_deg < 20.0,
      "light radius must be in (0.01, 20) degrees");
  require(std::isfinite(o.light_irradiance) && o.light_irradiance > 0.0,
          "light irradiance must be > 0");
  const PhotoArtefacts& a = o.artefacts;
  require(a.flare_spokes >= 2 && a.flare_spokes <= 16 && a.flare_spokes % 2 == 0,
          "flare spokes must be even, 2..16");
  require(std::isfinite(a.flare_strength) && a.flare_strength >= 0.0 && a.flare_strength <= 1.0,
          "flare strength must be in [0, 1]");
  require(
      std::isfinite(a.flare_length_frac) && a.flare_length_frac > 0.0 && a.flare_length_frac <= 1.0,
      "flare length must be in (0, 1] of the diagonal");
  require(std::isfinite(a.flare_angle_deg), "flare angle must be finite");
  require(std::isfinite(a.bloom_strength) && a.bloom_strength >= 0.0 && a.bloom_strength <= 1.0,
          "bloom strength must be in [0, 1]");
  require(
      std::isfinite(a.bloom_sigma_frac) && a.bloom_sigma_frac > 0.0 && a.bloom_sigma_frac <= 0.2,
      "bloom sigma must be in (0, 0.2] of the diagonal");
  require(std::isfinite(a.vignetting_corner_loss) && a.vignetting_corner_loss >= 0.0 &&
              a.vignetting_corner_loss < 1.0,
          "vignetting corner loss must be in [0, 1)");
  require(std::isfinite(a.read_noise_grey) && a.read_noise_grey >= 0.0 &&
              std::isfinite(a.shot_full_well) && a.shot_full_well > 0.0,
          "noise: read noise >= 0 grey levels and full well > 0");
  require(std::isfinite(a.exposure_jitter_ev) && a.exposure_jitter_ev >= 0.0 &&
              a.exposure_jitter_ev <= 4.0,
          "exposure jitter must be in [0, 4] EV");
  require(std::isfinite(a.shake_px) && a.shake_px >= 0.0 && a.shake_px <= 20.0,
          "shake must be in [0, 20] pixels");
  require(std::isfinite(o.exposure) && o.exposure > 0.0, "exposure must be > 0");
  require(o.bits == 8 || o.bits == 16, "photo output is 8 or 16 bits");
  require(o.file_type != FileType::kExr, "photo output is png, tif or jpg");
  if (o.file_type == FileType::kJpeg) {
    require(o.bits == 8, "jpg output is 8 bits only");
    require(o.jpeg_quality >= 1 && o.jpeg_quality <= 100, "jpeg quality must be 1..100");
  }
  require(std::isfinite(o.exif_sensor_width_mm) && o.exif_sensor_width_mm >= 0.0,
          "the EXIF sensor width must be >= 0 mm");
  require(o.supersample >= 1 && o.supersample <= 16, "supersample must be 1..16");
  require(!o.light_dirs.empty() || !o.lights.empty(), "no lights");
}

std::vector<Eigen::Vector3d> resolve_lights(const PhotoOptions& o) {
  SynthOptions s;
  s.lights = o.lights;
  s.light_dirs = o.light_dirs;
  return resolve_lights(s);
}

SphereOutline sphere_outline(const V3& c, double r, double f, const V2& pp) {
  // Rays (X, Y, 1) tangent to the sphere: (ray . c)^2 = |ray|^2 (|c|^2 - r^2), a conic in the
  // normalised image coordinates (X, Y).
  const double k = c.squaredNorm() - r * r;
  const Eigen::Matrix3d q = c * c.transpose() - k * Eigen::Matrix3d::Identity();
  const double a = q(0, 0), b = 2.0 * q(0, 1), cc = q(1, 1), d = 2.0 * q(0, 2), e = 2.0 * q(1, 2),
               ff = q(2, 2);
  Eigen::Matrix2d m;
  m << 2.0 * a, b, b, 2.0 * cc;
  const V2 x0 = m.inverse() * V2(-d, -e);
  const double f0 = ff + 0.5 * (d * x0.x() + e * x0.y());
  Eigen::Matrix2d s;
  s << a, 0.5 * b, 0.5 * b, cc;
  Eigen::SelfAdjointEigenSolver<Eigen::Matrix2d> eig(s);
  // Ellipse: (x - x0)^T S (x - x0) = -f0; semi-axis i is sqrt(-f0 / lambda_i).
  const double ax0 = f * std::sqrt(-f0 / eig.eigenvalues()(0));
  const double ax1 = f * std::sqrt(-f0 / eig.eigenvalues()(1));
  const int major = ax0 >= ax1 ? 0 : 1;
  SphereOutline out;
  out.centre_px = pp + f * x0;
  out.semi_major_px = std::max(ax0, ax1);
  out.semi_minor_px = std::min(ax0, ax1);
  out.radius_px = 0.5 * (out.semi_major_px + out.semi_minor_px);
  const V2 axis = eig.eigenvectors().col(major);
  out.angle_deg = std::atan2(axis.y(), axis.x()) / kDeg;
  if (out.angle_deg < 0.0) out.angle_deg += 180.0;
  if (out.angle_deg >= 180.0) out.angle_deg -= 180.0;
  out.centre_projection_px = pp + f * V2(c.x() / c.z(), c.y() / c.z());
  return out;
}

std::optional<V2> mirror_highlight_px(const V3& c, double r, const V3& light_dir, double f,
                                      const V2& pp) {
  const V3 l = V3(light_dir.x(), -light_dir.y(), -light_dir.z()).normalized();
  const V3 e1 = (-c).normalized();
  V3 perp = l - l.dot(e1) * e1;
  const double beta = std::atan2(perp.norm(), l.dot(e1));
  if (beta > kPi - 1e-6) return std::nullopt;
  V3 n = e1;
  if (perp.norm() > 1e-12) {
    const V3 e2 = perp.normalized();
    auto normal = [&](double t) { return V3(std::cos(t) * e1 + std::sin(t) * e2); };
    auto g = [&](double t) {
      const V3 nn = normal(t);
      const V3 v = (-(c + r * nn)).normalized();
      return std::acos(std::clamp(nn.dot(v), -1.0, 1.0)) -
             std::acos(std::clamp(nn.dot(l), -1.0, 1.0));
    };
    double lo = 0.0, hi = beta;
    for (int it = 0; it < 100; ++it) {
      const double mid = 0.5 * (lo + hi);
      (g(mid) < 0.0 ? lo : hi) = mid;
    }
    n = normal(0.5 * (lo + hi));
  }
  const V3 p = c + r * n;
  if (n.dot((-p).normalized()) <= 1e-6) return std::nullopt;
  return pp + f * V2(p.x() / p.z(), p.y() / p.z());
}

namespace detail {

PhotoScene::PhotoScene(const PhotoOptions& options) : o(options) {
  validate(o);
  light_dirs = resolve_lights(o);
  pp = o.principal_px ? *o.principal_px : V2(0.5 * (o.width - 1), 0.5 * (o.height - 1));
  if (o.view == PhotoView::kTopDown) {
    up = V3(0.0, 0.0, -1.0);
    ground_origin = V3(0.0, 0.0, o.camera_height_mm);
    g1 = V3(1.0, 0.0, 0.0);
    g2 = V3(0.0, 1.0, 0.0);
    a1 = V3(1.0, 0.0, 0.0);
    a2 = V3(0.0, 1.0, 0.0);
  } else {
    // The floor below the lowest sphere's base (or the sphere itself).
    double floor_y = -kInf;
    for (const PhotoSphere& s : o.spheres) {
      const double rb = o.base_radius_frac * s.radius_mm;
      const double drop = o.sphere_bases
                              ? std::sqrt(s.radius_mm * s.radius_mm - rb * rb) + 2.0 * s.radius_mm
                              : s.radius_mm;
      floor_y = std::max(floor_y, s.centre_mm.y() + drop);
    }
    up = V3(0.0, -1.0, 0.0);
    ground_origin = V3(0.0, floor_y, o.spheres.front().centre_mm.z());
    g1 = V3(1.0, 0.0, 0.0);
    g2 = V3(0.0, 0.0, -1.0);
    a1 = V3(1.0, 0.0, 0.0);
    a2 = V3(0.0, 0.0, 1.0);
  }
  ground_offset = up.dot(ground_origin);
  for (const PhotoSphere& s : o.spheres) {
    Base b;
    b.radius_mm = o.base_radius_frac * s.radius_mm;
    b.outer_radius_mm = std::max(b.radius_mm, o.base_outer_frac * s.radius_mm);
    b.rim_mm = s.centre_mm - up * std::sqrt(s.radius_mm * s.radius_mm - b.radius_mm * b.radius_mm);
    b.length_mm = up.dot(b.rim_mm) - ground_offset;
    b.on = o.sphere_bases && b.length_mm > 0.0;
    bases.push_back(b);
  }
  // The room: windows and lamps at seeded places.
  detail::Stream room(o.seed, 0x726f6f6dull);
  for (int i = 0; i < o.windows; ++i) {
    Window w;
    w.azimuth = (i + room.uniform(0.15, 0.85)) * 2.0 * kPi / std::max(o.windows, 1);
    w.elevation = room.uniform(12.0, 40.0) * kDeg;
    w.half_width = room.uniform(9.0, 15.0) * kDeg;
    w.half_height = room.uniform(8.0, 13.0) * kDeg;
    windows.push_back(w);
  }
  for (int i = 0; i < o.lamps; ++i) {
    Lamp l;
    const double az = (i + room.uniform(0.0, 1.0)) * 2.0 * kPi / std::max(o.lamps, 1) + 0.7;
    const double el = room.uniform(25.0, 70.0) * kDeg;
    l.dir =
        (std::cos(el) * (std::cos(az) * a1 + std::sin(az) * a2) + std::sin(el) * up).normalized();
    l.cos_radius = std::cos(room.uniform(1.5, 3.0) * kDeg);
    lamps.push_back(l);
  }
  const bool dark = o.environment == PhotoEnvironment::kDark;
  ambient = dark ? 0.03 : 0.35;
  light_cos_radius = std::cos(o.light_radius_deg * kDeg);
  const double solid = 2.0 * kPi * (1.0 - light_cos_radius);
  light_radiance = o.light_irradiance / solid;
  glass_cos_radius = std::cos(kGlassBlur * o.light_radius_deg * kDeg);
  glass_radiance = o.light_irradiance / (2.0 * kPi * (1.0 - glass_cos_radius));
  // The object: synth's relief as a texture at about the pixel scale.
  if (o.object && o.view == PhotoView::kTopDown) {
    const double px_per_mm = o.focal_px / o.camera_height_mm;
    const int n = std::clamp(static_cast<int>(std::lround(o.object_size_mm * px_per_mm)), 16, 4096);
    relief_options.preset = "custom";
    relief_options.width = relief_options.height = n;
    relief_options.seed = o.seed;
    relief_options.relief = o.relief;
    relief_options.material = o.object_material;
    relief_options.sensor.bits = 32;
    relief_options.sensor.file_type = FileType::kExr;
    relief_options.sensor.noise_sigma_grey = 0.0;
    relief_options.sensor.srgb = false;
    relief_options.write_truth = false;
    relief = build_scene(relief_options);
    has_object = true;
  }
  build_truth();
  build_static_refine();
}

Rgb PhotoScene::environment(const V3& w) const {
  const double s = w.dot(up);
  const bool dark = o.environment == PhotoEnvironment::kDark;
  if (s < 0.0) {
    // Below the horizon beyond the scene: the floor far away.
    return Rgb(1.0, 0.95, 0.9) * (dark ? 0.002 : 0.05);
  }
  const double el = std::asin(std::clamp(s, -1.0, 1.0));
  const double az = std::atan2(w.dot(a2), w.dot(a1));
  Rgb c = dark ? Rgb(0.004, 0.004, 0.005) * (1.0 + s) : Rgb(0.11, 0.105, 0.095) * (1.0 + 0.6 * s);
  for (const Window& win : windows) {
    double da = std::remainder(az - win.azimuth, 2.0 * kPi);
    const double de = el - win.elevation;
    if (std::abs(da) < win.half_width && std::abs(de) < win.half_height) {
      // Glazing bars: a cross and a frame.
      const double bx = std::abs(da) / win.half_width, by = std::abs(de) / win.half_height;
      if (bx < 0.04 || by < 0.05 || bx > 0.94 || by > 0.92) {
        c = Rgb(0.01, 0.01, 0.01);
      } else {
        c = (dark ? 1.6 : 3.5) * Rgb(0.85, 0.92, 1.0) * (1.0 - 0.3 * (de / win.half_height));
      }
    }
  }
  for (const Lamp& lamp : lamps) {
    const double cd = w.dot(lamp.dir);
    if (cd > lamp.cos_radius) c = Rgb(1.0, 0.82, 0.55) * 18.0;
  }
  return c;
}

double PhotoScene::light_term(const V3& w, const V3& l, bool through_glass) const {
  const double cd = w.dot(l);
  const double cr = through_glass ? glass_cos_radius : light_cos_radius;
  if (cd < cr - (1.0 - cr)) return 0.0;
  // A disc with a soft edge: full inside 0.8 of the radius, none beyond 1.2 (in angle squared,
  // 1 - cos is proportional to the angle squared).
  const double t = (1.0 - cd) / (1.0 - cr);
  const double profile = 1.0 - smoothstep(0.64, 1.44, t);
  return profile * (through_glass ? glass_radiance : light_radiance);
}

Hit PhotoScene::intersect(const V3& origin, const V3& d, bool camera_body, int skip_sphere) const {
  Hit h;
  for (std::size_t i = 0; i < o.spheres.size(); ++i) {
    if (static_cast<int>(i) == skip_sphere) continue;
    const double t =
        intersect_sphere(origin, d, o.spheres[i].centre_mm, o.spheres[i].radius_mm, kEps);
    if (t < h.t) {
      h.t = t;
      h.kind = HitKind::kSphere;
      h.index = static_cast<int>(i);
    }
  }
  const V3 down = -up;
  for (std::size_t i = 0; i < bases.size(); ++i) {
    const Base& b = bases[i];
    if (!b.on) continue;
    const V3 w = origin - b.rim_mm;
    const V3 dp = d - d.dot(down) * down;
    const V3 wp = w - w.dot(down) * down;
    const double qa = dp.squaredNorm();
    if (qa < 1e-18) continue;
    const double qb = dp.dot(wp);
    const double qc = wp.squaredNorm() - b.outer_radius_mm * b.outer_radius_mm;
    const double disc = qb * qb - qa * qc;
    if (disc > 0.0) {
      const double sq = std::sqrt(disc);
      for (double t : {(-qb - sq) / qa, (-qb + sq) / qa}) {
        if (t <= kEps || t >= h.t) continue;
        const double along = (w + t * d).dot(down);
        if (along < 0.0 || along > b.length_mm) continue;
        h.t = t;
        h.kind = HitKind::kBase;
        h.index = static_cast<int>(i);
        break;
      }
    }
    // The flat top at the rim, between the cup and the side.
    const double dd = d.dot(down);
    if (b.outer_radius_mm > b.radius_mm && std::abs(dd) > 1e-12) {
      const double t = -w.dot(down) / dd;
      if (t > kEps && t < h.t) {
        const double r2 = (w + t * d).squaredNorm();
        if (r2 >= b.radius_mm * b.radius_mm && r2 <= b.outer_radius_mm * b.outer_radius_mm) {
          h.t = t;
          h.kind = HitKind::kBase;
          h.index = static_cast<int>(i);
        }
      }
    }
  }
  const double denom = up.dot(d);
  if (std::abs(denom) > 1e-12) {
    const double t = (ground_offset - up.dot(origin)) / denom;
    if (t > kEps && t < h.t) {
      h.t = t;
      h.kind = HitKind::kGround;
      h.index = -1;
    }
  }
  if (camera_body) {
    const double t = intersect_sphere(origin, d, V3::Zero(), kCameraBodyRadiusMm, kEps);
    if (t < h.t) {
      h.t = t;
      h.kind = HitKind::kCamera;
      h.index = -1;
    }
  }
  if (h.kind != HitKind::kNone) h.point = origin + h.t * d;
  return h;
}

// Fraction of the light reaching point p (0: behind a sphere or a base), soft over the
// light's angular size.
double PhotoScene::light_visibility(const V3& p, const V3& l, int skip_sphere) const {
  double vis = 1.0;
  const double tan_r = std::tan(o.light_radius_deg * kDeg);
  for (std::size_t i = 0; i < o.spheres.size(); ++i) {
    if (static_cast<int>(i) == skip_sphere) continue;
    const V3 oc = o.spheres[i].centre_mm - p;
    const double t = oc.dot(l);
    if (t <= 0.0) continue;
    const double miss = (oc - t * l).norm() - o.spheres[i].radius_mm;
    const double pen = std::max(t * tan_r, 1e-3);
    vis *= smoothstep(-pen, pen, miss);
  }
  if (vis > 0.0) {
    const Hit h = intersect(p, l, false, skip_sphere);
    if (h.kind == HitKind::kBase) vis = 0.0;
  }
  return vis;
}

// Irradiance the glass spheres focus onto ground point p (their caustics).
double PhotoScene::caustic(const V3& p, const V3& l) const {
  double sum = 0.0;
  const double cos_ground = l.dot(up);
  if (cos_ground <= 0.0) return 0.0;
  for (const PhotoSphere& s : o.spheres) {
    if (s.material != SphereMaterial::kGlass) continue;
    const double r = s.radius_mm;
    const V3 w = p - s.centre_mm;
    const double dist = -w.dot(l);  // distance behind the centre along the light's travel
    if (dist < r) continue;
    const double off = (w + dist * l).norm();
    // Paraxial focus of a ball lens, n r / (2 (n - 1)) from the centre; beyond it the cone
    // widens again; spherical aberration keeps the waist finite.
    const double focus = kGlassIndex * r / (2.0 * (kGlassIndex - 1.0));
    const double rho = std::max(r * std::abs(dist - focus) / focus, 0.06 * r);
    const double sigma = 0.5 * rho;
    const double transmitted = 0.85;
    sum += o.light_irradiance * transmitted * cos_ground * r * r / (2.0 * sigma * sigma) *
           std::exp(-off * off / (2.0 * sigma * sigma));
  }
  return sum;
}

}  // namespace detail

}  // namespace ptmkit::synth
