// The photo renderer's public face: PhotoRenderer and the capture folder with its truth.
#include <algorithm>
#include <chrono>
#include <cmath>
#include <string>

#include <tbb/parallel_for.h>
#include <nlohmann/json.hpp>

#include "optics.h"
#include "photo_internal.h"
#include "ptmkit/core/atomic_file.h"
#include "ptmkit/core/error.h"
#include "ptmkit/core/image_io.h"
#include "ptmkit/core/light_set.h"

namespace fs = std::filesystem;

namespace ptmkit::synth {

struct PhotoRenderer::Impl {
  explicit Impl(const PhotoOptions& o) : scene(o) {}
  detail::PhotoScene scene;
};

double exposure_factor(const PhotoOptions& options, int index) {
  return detail::exposure_jitter(options, index);
}

Eigen::Vector2d shake_offset_px(const PhotoOptions& options, int index) {
  return detail::shake_offset(options, index);
}

ShakeError shake_error(const PhotoOptions& options,
                       const std::vector<Eigen::Vector2d>& measured_px) {
  const std::size_t n = measured_px.size();
  if (n == 0) throw Error("synth photo: no measured shifts to compare with the render's");
  Eigen::Vector2d mean_found = Eigen::Vector2d::Zero(), mean_true = Eigen::Vector2d::Zero();
  for (std::size_t i = 0; i < n; ++i) {
    mean_found += measured_px[i] / static_cast<double>(n);
    mean_true += shake_offset_px(options, static_cast<int>(i)) / static_cast<double>(n);
  }
  ShakeError e;
  double sq = 0.0;
  for (std::size_t i = 0; i < n; ++i) {
    const double d = ((measured_px[i] - mean_found) -
                      (shake_offset_px(options, static_cast<int>(i)) - mean_true))
                         .norm();
    sq += d * d / static_cast<double>(n);
    e.worst_px = std::max(e.worst_px, d);
  }
  e.rms_px = std::sqrt(sq);
  return e;
}

PhotoRenderer::PhotoRenderer(const PhotoOptions& options) : impl_(new Impl(options)) {}
PhotoRenderer::~PhotoRenderer() { delete impl_; }

const PhotoOptions& PhotoRenderer::options() const { return impl_->scene.o; }
const PhotoTruth& PhotoRenderer::truth() const { return impl_->scene.truth; }

Image PhotoRenderer::render_radiance(int index) const {
  const auto& s = impl_->scene;
  if (index < 0 || index >= static_cast<int>(s.light_dirs.size())) {
    throw Error("synth photo: light index " + std::to_string(index) + " out of range");
  }
  Image img = s.trace(s.light_state(index));
  detail::apply_shake(detail::shake_offset(s.o, index), &img);
  detail::apply_lens(s.o, &img);
  return img;
}

Image PhotoRenderer::render(int index) const {
  return detail::apply_sensor(impl_->scene.o, render_radiance(index), index);
}

Image PhotoRenderer::sphere_mask(int k) const {
  const auto& s = impl_->scene;
  if (k < 0 || k >= static_cast<int>(s.o.spheres.size())) {
    throw Error("synth photo: sphere index " + std::to_string(k) + " out of range");
  }
  Image mask(s.o.width, s.o.height, 1, ColourSpace::kLinear);
  tbb::parallel_for(0, s.o.height, [&](int y) {
    for (int x = 0; x < s.o.width; ++x) {
      const detail::Hit h = s.intersect(Eigen::Vector3d::Zero(),
                                        detail::pinhole_ray(x, y, s.o.focal_px, s.pp), false, -1);
      mask.at(x, y, 0) = h.kind == detail::HitKind::kSphere && h.index == k ? 1.0f : 0.0f;
    }
  });
  return mask;
}

namespace {

std::string image_name(int index, int count, FileType type) {
  const int digits = std::max(3, static_cast<int>(std::to_string(count).size()));
  std::string number = std::to_string(index + 1);
  number.insert(0, static_cast<std::size_t>(digits) - number.size(), '0');
  return "image_" + number + "." + std::string(extension(type));
}

nlohmann::json xy(const Eigen::Vector2d& v) { return {v.x(), v.y()}; }
nlohmann::json xyz(const Eigen::Vector3d& v) { return {v.x(), v.y(), v.z()}; }

}  // namespace

PhotoReport render_photo_capture(const PhotoOptions& options, const fs::path& out_dir) {
  const auto start = std::chrono::steady_clock::now();
  const PhotoRenderer renderer(options);  // validates
  if (out_dir.empty()) throw Error("synth: no output folder given");
  if (fs::exists(out_dir) && !fs::is_directory(out_dir)) {
    throw Error("synth: " + where(out_dir) + " exists and is not a folder");
  }
  const PhotoOptions& o = renderer.options();
  const PhotoTruth& truth = renderer.truth();
  const int n = static_cast<int>(truth.light_dirs.size());
  PhotoReport report;
  report.folder = out_dir;
  report.width = o.width;
  report.height = o.height;
  ensure_directory(out_dir);
  ensure_directory(out_dir / "truth");

  ImageWriteOptions image_opts{o.bits == 16 ? PixelFormat::kU16 : PixelFormat::kU8, o.jpeg_quality};
  if (o.file_type == FileType::kJpeg && o.exif_sensor_width_mm > 0.0) {
    image_opts.exif_camera = ImageWriteOptions::ExifCamera{
        o.focal_px * o.exif_sensor_width_mm / o.width, o.exif_sensor_width_mm};
  }
  auto one = [&](int i) {
    const Image img = renderer.render(i);
    write_image(out_dir / image_name(i, n, o.file_type), img.view(), image_opts);
  };
  // Small captures: several images at once; large ones one at a time (each render is itself
  // parallel), so memory stays at a few images.
  if (static_cast<double>(o.width) * o.height <= 4e6) {
    tbb::parallel_for(0, n, one);
  } else {
    for (int i = 0; i < n; ++i) one(i);
  }
  for (int i = 0; i < n; ++i) report.files.push_back(out_dir / image_name(i, n, o.file_type));
  for (int k = 0; k < static_cast<int>(o.spheres.size()); ++k) {
    const fs::path p = out_dir / "truth" / ("sphere_" + std::to_string(k + 1) + ".png");
    write_image(p, renderer.sphere_mask(k).view());
    report.files.push_back(p);
  }

  LightSet lights;
  nlohmann::json images = nlohmann::json::array();
  for (int i = 0; i < n; ++i) {
    const Eigen::Vector3d& d = truth.light_dirs[static_cast<std::size_t>(i)];
    Light l;
    l.image = out_dir / image_name(i, n, o.file_type);
    l.direction = d;
    lights.lights.push_back(l);
    nlohmann::json im = {{"file", image_name(i, n, o.file_type)},
                         {"light_dir", xyz(d)},
                         {"elevation_deg", elevation_deg(d)}};
    // The image's own exposure and shift, where they vary (the circles and highlights of
    // truth.json are the unshifted ones: add shake_px to place them in this image).
    if (o.artefacts.exposure_jitter_ev > 0.0) im["exposure_factor"] = detail::exposure_jitter(o, i);
    if (o.artefacts.shake_px > 0.0) {
      const Eigen::Vector2d s = detail::shake_offset(o, i);
      im["shake_px"] = {s.x(), s.y()};
    }
    images.push_back(std::move(im));
  }
  report.lp_file = out_dir / "lights.lp";
  write_lp(report.lp_file, lights);
  report.files.push_back(report.lp_file);

  nlohmann::json j;
  j["generator"] = "ptmkit synth";
  j["kind"] = "photo";
  j["preset"] = o.preset;
  j["seed"] = o.seed;
  j["width"] = o.width;
  j["height"] = o.height;
  j["camera"] = {
      {"model", "pinhole"},
      {"focal_px", o.focal_px},
      {"principal_px", xy(truth.principal_px)},
      {"view", o.view == PhotoView::kTopDown ? "top-down" : "side"},
      {"frame",
       "camera frame: x right, y down, z forward, mm, camera at the origin; pixel centres at "
       "integer coordinates, origin at the centre of the top-left pixel"}};
  j["spheres"] = nlohmann::json::array();
  for (std::size_t k = 0; k < truth.spheres.size(); ++k) {
    const PhotoSphereTruth& t = truth.spheres[k];
    nlohmann::json s;
    s["material"] = std::string(to_string(t.sphere.material));
    s["centre_mm"] = xyz(t.sphere.centre_mm);
    s["radius_mm"] = t.sphere.radius_mm;
    s["circle"] = {{"centre_px", xy(t.outline.centre_px)}, {"radius_px", t.outline.radius_px}};
    s["ellipse"] = {{"centre_px", xy(t.outline.centre_px)},
                    {"semi_major_px", t.outline.semi_major_px},
                    {"semi_minor_px", t.outline.semi_minor_px},
                    {"angle_deg", t.outline.angle_deg}};
    s["centre_projection_px"] = xy(t.outline.centre_projection_px);
    s["outline_inside_frame"] = t.outline_inside_frame;
    s["outline_visible"] = t.outline_visible;
    if (o.sphere_bases) {
      const double rb = o.base_radius_frac * t.sphere.radius_mm;
      s["base"] = {{"radius_mm", rb},
                   {"outer_radius_mm", std::max(rb, o.base_outer_frac * t.sphere.radius_mm)},
                   {"top_mm", std::sqrt(t.sphere.radius_mm * t.sphere.radius_mm - rb * rb)}};
    } else {
      s["base"] = nullptr;
    }
    s["mask"] = "truth/sphere_" + std::to_string(k + 1) + ".png";
    nlohmann::json hl = nlohmann::json::array();
    for (const auto& h : t.highlight_px) hl.push_back(h ? xy(*h) : nlohmann::json(nullptr));
    s["highlight_px"] = hl;
    j["spheres"].push_back(s);
  }
  j["circle_definition"] =
      "centre of the sphere's projected outline (an ellipse under the pinhole camera) and the "
      "mean of its semi-axes";
  if (o.distractor != Distractor::kNone) {
    j["distractor"] = {{"kind", std::string(to_string(o.distractor))},
                       {"centre_px", xy(truth.distractor_centre_px)},
                       {"radius_px", truth.distractor_radius_px},
                       {"offset_mm", xy(o.distractor_offset_mm)},
                       {"radius_mm", o.distractor_radius_mm}};
  } else {
    j["distractor"] = {{"kind", "none"}};
  }
  j["object"] = o.object && o.view == PhotoView::kTopDown;
  j["environment"] = {{"kind", std::string(to_string(o.environment))},
                      {"windows", o.windows},
                      {"lamps", o.lamps},
                      {"reflect_scene", o.reflect_scene}};
  j["lights"] = {
      {"count", n},
      {"file", "lights.lp"},
      {"frame", "light frame: x to the image's right, y to its top, z toward the camera"},
      {"light_radius_deg", o.light_radius_deg},
      {"light_irradiance", o.light_irradiance}};
  j["images"] = images;
  const PhotoArtefacts& a = o.artefacts;
  j["artefacts"] = {
      {"flare",
       {{"on", a.flare},
        {"spokes", a.flare_spokes},
        {"strength", a.flare_strength},
        {"length_frac", a.flare_length_frac},
        {"angle_deg", a.flare_angle_deg}}},
      {"bloom",
       {{"on", a.bloom}, {"strength", a.bloom_strength}, {"sigma_frac", a.bloom_sigma_frac}}},
      {"vignetting", {{"on", a.vignetting}, {"corner_loss", a.vignetting_corner_loss}}},
      {"noise",
       {{"on", a.noise}, {"read_grey", a.read_noise_grey}, {"shot_full_well", a.shot_full_well}}},
      {"exposure_jitter_ev", a.exposure_jitter_ev},
      {"shake_px", a.shake_px}};
  j["sensor"] = {
      {"exposure", o.exposure},
      {"colour_space", o.srgb ? "srgb" : "linear"},
      {"format", std::string(extension(o.file_type))},
      {"bits", o.bits},
      {"jpeg_quality",
       o.file_type == FileType::kJpeg ? nlohmann::json(o.jpeg_quality) : nlohmann::json(nullptr)},
      {"exif", image_opts.exif_camera
                   ? nlohmann::json{{"focal_mm", image_opts.exif_camera->focal_mm},
                                    {"sensor_width_mm", image_opts.exif_camera->sensor_width_mm}}
                   : nlohmann::json(nullptr)}};
  write_file_atomic(out_dir / "truth.json", j.dump(2) + "\n");
  report.files.push_back(out_dir / "truth.json");
  report.images = n;
  report.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  return report;
}

}  // namespace ptmkit::synth
