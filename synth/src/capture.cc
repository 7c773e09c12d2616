// Options, presets, light layouts and the capture folder.
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <string>
#include <vector>

#include <tbb/parallel_for.h>
#include <nlohmann/json.hpp>

#include "coefficients_exr.h"
#include "ptmkit/core/atomic_file.h"
#include "ptmkit/core/error.h"
#include "ptmkit/core/image_io.h"
#include "ptmkit/core/light_layout.h"
#include "ptmkit/core/light_set.h"
#include "ptmkit/core/limits.h"
#include "ptmkit/core/plane.h"
#include "ptmkit/synth/synth.h"
#include "render.h"

namespace fs = std::filesystem;

namespace ptmkit::synth {

namespace {

constexpr const char* kDome49 = "10:18,30:12,50:10,70:8,90:1";
constexpr int kMaxSide = 65536;
constexpr double kMaxPixels = 400e6;
constexpr double kGroupBudgetBytes = 256e6;

bool finite(double v) { return std::isfinite(v); }

void require(bool ok, const std::string& message) {
  if (!ok) throw Error("synth: " + message);
}

std::string join(const std::vector<std::string>& names) {
  std::string s;
  for (const auto& n : names) s += (s.empty() ? "" : ", ") + n;
  return s;
}

PixelFormat pixel_format(int bits) {
  return bits == 8 ? PixelFormat::kU8 : bits == 16 ? PixelFormat::kU16 : PixelFormat::kF32;
}

std::string image_name(int index, int count, FileType type) {
  const int digits = std::max(3, static_cast<int>(std::to_string(count).size()));
  std::string number = std::to_string(index + 1);
  number.insert(0, static_cast<std::size_t>(digits) - number.size(), '0');
  return "image_" + number + "." + std::string(extension(type));
}

std::string label_name(const std::string& image) {
  return fs::path(image).replace_extension(".png").string();
}

}  // namespace

std::string_view to_string(SceneKind kind) {
  return kind == SceneKind::kRelief ? "relief" : "polynomial";
}

SceneKind parse_scene_kind(std::string_view name) {
  if (name == "relief") return SceneKind::kRelief;
  if (name == "polynomial") return SceneKind::kPolynomial;
  throw Error("synth: unknown scene '" + std::string(name) + "' (expected relief or polynomial)");
}

std::string_view to_string(FileType type) { return extension(type); }

std::string_view extension(FileType type) {
  switch (type) {
    case FileType::kPng:
      return "png";
    case FileType::kTiff:
      return "tif";
    case FileType::kExr:
      return "exr";
    case FileType::kJpeg:
      return "jpg";
  }
  return "png";
}

FileType parse_file_type(std::string_view name) {
  if (name == "png") return FileType::kPng;
  if (name == "tif" || name == "tiff") return FileType::kTiff;
  if (name == "exr") return FileType::kExr;
  if (name == "jpg" || name == "jpeg") return FileType::kJpeg;
  throw Error("synth: unknown output format '" + std::string(name) +
              "' (expected png, tif, exr or jpg)");
}

std::vector<std::string> preset_names() {
  return {"default", "matte", "glossy", "tall", "ambient", "polynomial"};
}

SynthOptions preset_options(std::string_view name) {
  SynthOptions o;  // the defaults are the `default` preset
  o.preset = std::string(name);
  if (name == "default") return o;
  if (name == "matte") {
    o.material.ks = 0.0;
  } else if (name == "glossy") {
    o.material.ks = 0.8;
    o.material.exponent = 100.0;
  } else if (name == "tall") {
    o.relief.relief_height_frac = 0.20;
  } else if (name == "ambient") {
    // Brightest diffuse value albedo_max * (1 + ambient) * exposure stays at 0.9 of full scale.
    o.material.ambient = 0.1;
    o.sensor.exposure = 1.0 / 1.1;
  } else if (name == "polynomial") {
    o.scene = SceneKind::kPolynomial;
    o.width = 64;
    o.height = 64;
    o.material.ks = 0.0;
    o.cast_shadows = false;
    o.sensor.bits = 32;
    o.sensor.file_type = FileType::kExr;
    o.sensor.noise_sigma_grey = 0.0;
  } else {
    throw Error("synth: unknown preset '" + std::string(name) + "' (expected one of " +
                join(preset_names()) + ")");
  }
  return o;
}

void validate(const SynthOptions& o) {
  const auto names = preset_names();
  require(o.preset == "custom" || std::find(names.begin(), names.end(), o.preset) != names.end(),
          "unknown preset '" + o.preset + "' (expected one of " + join(names) + ", or custom)");
  require(o.width >= 8 && o.height >= 8, "image size " + std::to_string(o.width) + "x" +
                                             std::to_string(o.height) +
                                             " is too small (at least 8x8)");
  require(o.width <= kMaxSide && o.height <= kMaxSide &&
              static_cast<double>(o.width) * o.height <= kMaxPixels,
          "image size " + std::to_string(o.width) + "x" + std::to_string(o.height) +
              " is too large (at most 65536 a side and 400 megapixels)");
  require(finite(o.relief.relief_height_frac) && o.relief.relief_height_frac >= 0.0,
          "relief height fraction must be a finite number >= 0");
  require(o.relief.bumps >= 0 && o.relief.grooves >= 0, "bump and groove counts must be >= 0");
  require(finite(o.relief.crumple) && o.relief.crumple >= 0.0, "crumple must be finite and >= 0");
  require(finite(o.material.ks) && o.material.ks >= 0.0, "ks must be finite and >= 0");
  require(finite(o.material.exponent) && o.material.exponent > 0.0,
          "specular exponent must be finite and > 0");
  require(finite(o.material.ambient) && o.material.ambient >= 0.0,
          "ambient must be finite and >= 0");
  require(finite(o.sensor.exposure) && o.sensor.exposure > 0.0, "exposure must be finite and > 0");
  require(finite(o.sensor.noise_sigma_grey) && o.sensor.noise_sigma_grey >= 0.0,
          "noise sigma must be finite and >= 0 grey levels");
  require(finite(o.highlight_threshold_grey) && o.highlight_threshold_grey >= 0.0,
          "highlight threshold must be finite and >= 0 grey levels");
  const int bits = o.sensor.bits;
  require(bits == 8 || bits == 16 || bits == 32,
          "bit depth " + std::to_string(bits) + " is not supported (expected 8, 16 or 32)");
  const std::string type(extension(o.sensor.file_type));
  switch (o.sensor.file_type) {
    case FileType::kPng:
      require(bits != 32, "png output is 8 or 16 bits, not 32 (use exr or tif for float)");
      break;
    case FileType::kJpeg:
      require(bits == 8, "jpg output is 8 bits only");
      require(o.sensor.jpeg_quality >= 1 && o.sensor.jpeg_quality <= 100,
              "jpeg quality must be 1..100");
      break;
    case FileType::kExr:
      require(bits == 32, "exr output is 32-bit float (use --bits 32)");
      break;
    case FileType::kTiff:
      break;
  }
  for (std::size_t i = 0; i < o.light_dirs.size(); ++i) {
    const Eigen::Vector3d& d = o.light_dirs[i];
    require(d.allFinite() && d.norm() > 0.0,
            "light " + std::to_string(i + 1) + " has a zero or non-finite direction");
    require(d.z() > 0.0, "light " + std::to_string(i + 1) + " is below the horizon (z <= 0)");
  }
  require(!o.light_dirs.empty() || !o.lights.empty(), "no lights");
  require(finite(o.mm_per_px) && o.mm_per_px > 0.0, "mm per pixel must be finite and > 0");
  require(finite(o.dome_radius_mm) && o.dome_radius_mm >= 0.0,
          "dome radius must be finite and >= 0 mm (0 = distant lights)");
}

std::vector<Eigen::Vector3d> resolve_lights(const SynthOptions& o) {
  std::vector<Eigen::Vector3d> dirs;
  if (!o.light_dirs.empty()) {
    dirs = o.light_dirs;
  } else if (o.lights == "icosa") {
    dirs = geodesic_dome(2);
  } else if (o.lights == "dome49") {
    dirs = ring_layout(parse_rings(kDome49));
  } else if (o.lights.rfind("rings:", 0) == 0) {
    dirs = ring_layout(parse_rings(std::string_view(o.lights).substr(6)));
  } else if (fs::path(o.lights).extension() == ".lp") {
    dirs = read_lp(o.lights).directions();
  } else {
    throw Error("synth: unknown light layout '" + excerpt(o.lights) +
                "' (expected icosa, dome49, rings:ELEV:COUNT[:AZ],... or an .lp file)");
  }
  require(!dirs.empty(), "no lights in '" + o.lights + "'");
  for (std::size_t i = 0; i < dirs.size(); ++i) {
    require(dirs[i].allFinite() && dirs[i].norm() > 0.0,
            "light " + std::to_string(i + 1) + " has a zero or non-finite direction");
    require(dirs[i].z() > 0.0, "light " + std::to_string(i + 1) + " is below the horizon");
    dirs[i].normalize();
  }
  return dirs;
}

SynthReport render_capture(const SynthOptions& o, const fs::path& out_dir) {
  const auto start = std::chrono::steady_clock::now();
  validate(o);
  const std::vector<Eigen::Vector3d> dirs = resolve_lights(o);
  require(!out_dir.empty(), "no output folder given");
  require(!fs::exists(out_dir) || fs::is_directory(out_dir),
          where(out_dir) + " exists and is not a folder");

  const Scene scene = build_scene(o);
  const bool relief = scene.kind == SceneKind::kRelief;
  const int n = static_cast<int>(dirs.size());
  const bool near = o.dome_radius_mm > 0.0;
  if (near) {
    // A light at or below the relief's top would light some texels from below the horizon.
    const double top_mm = scene.max_height_px * o.mm_per_px;
    for (int i = 0; i < n; ++i) {
      const double z = o.dome_radius_mm * dirs[static_cast<std::size_t>(i)].z();
      if (!(z > top_mm)) {
        char msg[200];
        std::snprintf(msg, sizeof(msg),
                      "light %d is %.3g mm above the plane at dome radius %.3g mm, not above "
                      "the relief's top (%.3g mm): raise the radius or lower the relief",
                      i + 1, z, o.dome_radius_mm, top_mm);
        throw Error(std::string("synth: ") + msg);
      }
    }
  }
  const ImageWriteOptions image_opts{pixel_format(o.sensor.bits), o.sensor.jpeg_quality};
  ImageWriteOptions u16;
  u16.format = PixelFormat::kU16;
  ImageWriteOptions f32;
  f32.format = PixelFormat::kF32;
  ImageWriteOptions u8;

  SynthReport report;
  report.folder = out_dir;
  report.width = scene.width;
  report.height = scene.height;
  auto written = [&](const fs::path& p) { report.files.push_back(p); };

  // Committed as a whole: the images, lights.lp and truth reach the folder together once all
  // are written; a failure leaves the folder as it was.
  OutputTransaction outputs;
  ensure_directory(out_dir);
  const fs::path truth_dir = out_dir / "truth";
  nlohmann::json truth_files = nlohmann::json::object();
  if (o.write_truth) {
    ensure_directory(truth_dir / "diffuse");
    ensure_directory(truth_dir / "labels");
    if (relief) {
      write_normal_map(truth_dir / "normals.exr", scene.normals.view());
      written(truth_dir / "normals.exr");
      write_normal_map(truth_dir / "normals.png", scene.normals.view());
      written(truth_dir / "normals.png");
      write_image(truth_dir / "albedo.exr", scene.albedo.view(), f32);
      written(truth_dir / "albedo.exr");
      write_image(truth_dir / "albedo.png", scene.albedo.view(), u16);
      written(truth_dir / "albedo.png");
      Image height(scene.width, scene.height, 1, ColourSpace::kLinear);
      std::copy(scene.height_px.begin(), scene.height_px.end(), height.data());
      write_image(truth_dir / "height.exr", height.view(), f32);
      written(truth_dir / "height.exr");
      truth_files = {{"normals_exr", "truth/normals.exr"},
                     {"normals_png", "truth/normals.png"},
                     {"albedo_exr", "truth/albedo.exr"},
                     {"albedo_png", "truth/albedo.png"},
                     {"height_exr", "truth/height.exr"}};
    } else {
      detail::write_coefficients_exr(truth_dir / "coefficients.exr", scene.coefficients);
      written(truth_dir / "coefficients.exr");
      truth_files = {
          {"coefficients_exr", "truth/coefficients.exr"},
          {"coefficients_layout",
           "18 float channels named cNN_<colour>_a<k>; channel 6*c + k is term a_k of "
           "colour c (0 R, 1 G, 2 B); L = a0 lu^2 + a1 lv^2 + a2 lu lv + a3 lu + a4 lv + a5"}};
    }
  }

  // Lights are rendered and written in groups processed in parallel; a group holds as many
  // lights as fit kGroupBudgetBytes of image buffers (all 49 of a 256x256 capture, one of a
  // 12-megapixel capture), so large renders keep to the scene's maps plus about one image.
  // Each light's files depend on nothing but the light, so the files are identical whatever
  // the grouping or thread count.
  const double light_bytes = static_cast<double>(scene.width) * scene.height * 4.0 * 4.0;
  const int group = std::clamp(static_cast<int>(kGroupBudgetBytes / light_bytes), 1, n);
  std::vector<std::vector<fs::path>> light_files(static_cast<std::size_t>(n));
  auto process_light = [&](int i) {
    std::vector<fs::path>& files = light_files[static_cast<std::size_t>(i)];
    const std::string name = image_name(i, n, o.sensor.file_type);
    std::vector<std::uint8_t> shadow;
    if (relief && o.cast_shadows) shadow = cast_shadow_mask(scene, o, dirs[i]);
    const std::uint8_t* shadow_ptr = shadow.empty() ? nullptr : shadow.data();
    Image image;
    std::vector<std::uint8_t> labels;
    detail::render_into(scene, o, dirs[i], i, shadow_ptr, &image, nullptr,
                        o.write_truth ? &labels : nullptr);
    write_image(out_dir / name, image.view(), image_opts);
    files.push_back(out_dir / name);
    if (!o.write_truth) return;
    const std::string png = label_name(name);
    {
      Image label_image(scene.width, scene.height, 1, ColourSpace::kLinear);
      for (std::size_t t = 0; t < labels.size(); ++t) {
        label_image.data()[t] = static_cast<float>(labels[t]) / 255.0f;
      }
      write_image(truth_dir / "labels" / png, label_image.view(), u8);
      files.push_back(truth_dir / "labels" / png);
    }
    detail::render_into(scene, o, dirs[i], i, nullptr, nullptr, &image, nullptr);
    write_image(truth_dir / "diffuse" / name, image.view(), image_opts);
    files.push_back(truth_dir / "diffuse" / name);
  };
  for (int first = 0; first < n; first += group) {
    const int last = std::min(first + group, n);
    if (last - first == 1) {
      process_light(first);
    } else {
      tbb::parallel_for(first, last, process_light);
    }
  }
  for (const auto& files : light_files) {
    for (const auto& f : files) written(f);
  }

  LightSet light_set;
  nlohmann::json images = nlohmann::json::array();
  for (int i = 0; i < n; ++i) {
    const std::string name = image_name(i, n, o.sensor.file_type);
    nlohmann::json entry = {{"file", name},
                            {"light_dir", {dirs[i].x(), dirs[i].y(), dirs[i].z()}},
                            {"elevation_deg", elevation_deg(dirs[i])}};
    if (o.write_truth) {
      entry["diffuse"] = "truth/diffuse/" + name;
      entry["labels"] = "truth/labels/" + label_name(name);
    }
    Light light;
    light.image = out_dir / name;
    light.direction = dirs[i];
    if (near) {
      const Eigen::Vector3d p = o.dome_radius_mm * dirs[i];
      light.position_mm = p;
      entry["position_mm"] = {p.x(), p.y(), p.z()};
    }
    images.push_back(entry);
    light_set.lights.push_back(light);
  }
  report.lp_file = out_dir / "lights.lp";
  write_lp(report.lp_file, light_set);
  written(report.lp_file);
  report.images = n;
  if (near) {
    // The .lp holds only the nominal directions; positions go in lights.json (the light
    // JSON of core/light_set.h, read by `ptmkit fit --lights-json`), and the plane geometry
    // in plane.json.
    write_light_json(out_dir / "lights.json", light_set);
    written(out_dir / "lights.json");
    write_plane_json(out_dir / "plane.json",
                     orthographic_plane(scene.width, scene.height, o.mm_per_px));
    written(out_dir / "plane.json");
  }

  if (o.write_truth) {
    nlohmann::json j;
    j["generator"] = "ptmkit synth";
    j["scene"] = std::string(to_string(o.scene));
    j["preset"] = o.preset;
    j["seed"] = o.seed;
    j["width"] = o.width;
    j["height"] = o.height;
    j["camera"] = "orthographic, looking down -z (view direction +z), one pixel per texel";
    j["mm_per_px"] = o.mm_per_px;
    j["dome_radius_mm"] = o.dome_radius_mm;
    if (near) {
      j["near_lights"] = {
          {"model",
           "point lights at dome_radius_mm * direction (light frame, origin at the plane "
           "centre); texel (x, y) at (X, Y, height_px * mm_per_px), (X, Y) from plane.json; lit "
           "from normalise(position - texel)"},
          {"inverse_square_falloff", o.inverse_square_falloff},
          {"falloff", "(|position| / |position - texel|)^2, 1 at the plane centre"},
          {"lights_json", "lights.json"},
          {"plane_json", "plane.json"}};
    }
    j["frame"] = "light frame: x to the image's right, y to the image's top, z toward the camera";
    if (relief) {
      j["relief"] = {{"relief_height_frac", o.relief.relief_height_frac},
                     {"max_height_px", scene.max_height_px},
                     {"bumps", o.relief.bumps},
                     {"grooves", o.relief.grooves},
                     {"crumple", o.relief.crumple},
                     {"albedo_range", {0.3, 0.9}}};
      j["material"] = {{"model", "lambert + white blinn-phong + ambient*albedo"},
                       {"ks", o.material.ks},
                       {"exponent", o.material.exponent},
                       {"normalise_specular", o.material.normalise_specular},
                       {"ambient", o.material.ambient}};
      j["cast_shadows"] = o.cast_shadows;
    }
    j["sensor"] = {{"exposure", o.sensor.exposure},
                   {"colour_space", o.sensor.srgb ? "srgb" : "linear"},
                   {"noise_sigma_grey", o.sensor.noise_sigma_grey},
                   {"bits", o.sensor.bits},
                   {"format", std::string(extension(o.sensor.file_type))},
                   {"clipped_at_full_scale", o.sensor.bits != 32}};
    if (o.sensor.file_type == FileType::kJpeg) j["sensor"]["jpeg_quality"] = o.sensor.jpeg_quality;
    j["lights"] = {{"layout", o.light_dirs.empty() ? o.lights : "explicit"},
                   {"count", n},
                   {"file", "lights.lp"}};
    j["images"] = images;
    j["labels"] = {
        {"0", "inlier"},
        {"1", "shadow: attached (n.l <= 0) or cast by the height field"},
        {"2",
         "highlight: specular adds more than highlight_threshold_grey to some channel, or "
         "some channel exceeded full scale before clipping"},
        {"highlight_threshold_grey", o.highlight_threshold_grey}};
    j["truth"] = truth_files;
    const fs::path json_path = out_dir / "truth.json";
    write_file_atomic(json_path, j.dump(2) + "\n");
    written(json_path);
  }
  report.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  outputs.commit();
  return report;
}

}  // namespace ptmkit::synth
