// ptmkit calibrate dome: light files from dome geometry.
#include <cstdio>
#include <limits>
#include <memory>

#include <algorithm>
#include <array>

#include "commands.h"
#include "flags.h"
#include "ptmkit/calib/camera.h"
#include "ptmkit/calib/dome.h"
#include "ptmkit/calib/sphere.h"
#include "ptmkit/calib/sphere_refine.h"
#include "ptmkit/calib/sphere_stack.h"
#include "ptmkit/core/atomic_file.h"
#include "ptmkit/core/error.h"
#include "ptmkit/core/image_io.h"
#include "ptmkit/core/light_set.h"
#include "ptmkit/core/plane.h"
#include "ptmkit/core/stack_reader.h"

namespace ptmkit::app {

namespace {

struct DomeArgs {
  calib::DomeOptions options;
  std::string output;
  std::string json;
};

void run_dome(const DomeArgs& args) {
  const LightSet lights = calib::dome_light_set(args.options);
  write_lp(args.output, lights);
  if (!args.json.empty()) write_light_json(args.json, lights);
  double min_el = 90.0, max_el = 0.0;
  for (const auto& l : lights.lights) {
    min_el = std::min(min_el, elevation_deg(l.direction));
    max_el = std::max(max_el, elevation_deg(l.direction));
  }
  std::printf("calibrate dome: %zu lights, elevations %.1f..%.1f degrees%s -> %s%s%s\n",
              lights.size(), min_el, max_el,
              lights.lights.front().position_mm ? ", with positions" : "", args.output.c_str(),
              args.json.empty() ? "" : " and ", args.json.c_str());
}

struct SphereArgs {
  std::vector<std::string> images;
  std::string output;
  std::string report;
  std::vector<std::string> spheres;
  int sphere_count = 1;
  double sphere_radius_mm = 0.0;
  std::string plane;
  std::string json;
  bool drop_outliers = false;
  bool no_refine = false;
  bool distant_lights = false;
  bool allow_disagreement = false;
  double outlier_px = 1.5;
  std::string mask;
  std::string principal;
  std::string camera;
  double focal_mm = 0.0;
  double sensor_width_mm = 0.0;
  std::string overlays;
  std::string plot;
  std::vector<int> drop;
  std::vector<std::string> rois;
  std::string radius_range;
  std::string reference;
  double min_score = 0.5;
  std::string sphere_material = "auto";
  bool no_exif_focal = false;
  bool focal_px_given = false;  // --focal-px on the command line (even 0: orthographic)
  bool overlay_full_size = false;
  int overlay_max_side = 1600;
  calib::SphereOptions options;
};

// Overlays one image at a time (never the whole stack), downscaled unless asked otherwise.
void write_overlays(const SphereArgs& args, const std::vector<std::filesystem::path>& files,
                    const calib::RigReport& report) {
  ensure_directory(args.overlays);
  const int max_side = args.overlay_full_size ? 0 : args.overlay_max_side;
  for (std::size_t i = 0; i < files.size(); ++i) {
    double scale = 1.0;
    Image overlay = calib::downscale_for_overlay(read_image(files[i]), max_side, &scale);
    int row = 0;
    for (const calib::SphereReport& s : report.spheres) {
      overlay = calib::sphere_overlay(overlay, s, i, scale, row++);
    }
    const auto name = files[i].stem().string() + ".overlay.png";
    write_image(std::filesystem::path(args.overlays) / name, overlay.view());
  }
}

void run_sphere(const SphereArgs& args) {
  calib::RigOptions options;
  options.detection = args.options;
  options.sphere_count = args.sphere_count;
  options.sphere_radius_mm = args.sphere_radius_mm;
  options.refine = !args.no_refine;
  options.near_from_evidence = !args.distant_lights;
  options.outlier_px = args.outlier_px;
  if (!args.spheres.empty() && !args.mask.empty()) {
    throw Error("give the sphere either by --sphere or by --mask, not both");
  }
  for (const std::string& text : args.spheres) {
    const Eigen::Vector3d v = parse_vector3(text, "--sphere");
    calib::Circle c;
    c.centre_px = {v[0], v[1]};
    c.radius_px = v[2];
    options.spheres.push_back(c);
  }
  if (!args.mask.empty()) {
    options.spheres.push_back(calib::circle_from_mask(read_image(args.mask).view()));
  }
  if (!args.plane.empty()) options.plane = read_plane_json(args.plane);
  std::vector<std::filesystem::path> files(args.images.begin(), args.images.end());
  const ImageInfo first = probe_image(files.front());
  calib::CameraSource camera;
  camera.camera_json = args.camera;
  camera.focal_mm = args.focal_mm;
  camera.sensor_width_mm = args.sensor_width_mm;
  camera.focal_px = options.detection.camera.focal_px;
  if (!args.no_exif_focal && !args.focal_px_given && args.camera.empty() &&
      !(args.focal_mm > 0.0)) {
    const calib::PhotoFocal exif = calib::focal_from_exif(files);
    camera.exif_focal_px = exif.focal_px;
    camera.exif_note = exif.note;
  }
  if (!args.principal.empty()) camera.principal_px = parse_vector2(args.principal, "--principal");
  try {
    options.detection.camera = calib::resolve_sphere_camera(camera, first.width, first.height);
  } catch (const Error& e) {
    throw Error(std::string(e.what()) +
                " (--camera, --focal-mm with --sensor-width-mm, --focal-px)");
  }
  calib::StackCalibrationOptions stack_options;
  stack_options.rig = options;
  for (const std::string& r : args.rois) {
    const std::array<int, 4> box = parse_box(r, "--roi");
    stack_options.search.rois.push_back({box[0], box[1], box[2], box[3]});
  }
  if (!args.radius_range.empty()) {
    const Eigen::Vector2d range = parse_vector2(args.radius_range, "--radius-range");
    const double lo = range.x(), hi = range.y();
    if (!(lo >= 0.0 && hi >= lo && hi > 0.0)) {
      throw Error("--radius-range " + args.radius_range +
                  ": expected MIN,MAX in pixels with 0 <= MIN <= MAX");
    }
    stack_options.search.min_radius_px = lo;
    stack_options.search.max_radius_px = hi;
  }
  if (!args.reference.empty()) stack_options.search.reference = args.reference;
  stack_options.search.min_score = args.min_score;
  stack_options.allow_disagreement = args.allow_disagreement;
  stack_options.material = args.sphere_material == "mirror"  ? calib::SphereMaterial::kMirror
                           : args.sphere_material == "glass" ? calib::SphereMaterial::kGlass
                                                             : calib::SphereMaterial::kAuto;
  if (!options.spheres.empty() && (!args.rois.empty() || !args.radius_range.empty())) {
    throw Error("--roi and --radius-range help the search: not with --sphere or --mask");
  }
  calib::StackCalibration result;
  try {
    result = calib::calibrate_sphere_stack(files, stack_options);
  } catch (const calib::SphereSearchError& e) {
    // What was considered, drawn on the first photo, so the user can see it and give a hint.
    const std::filesystem::path shown =
        args.overlays.empty()
            ? std::filesystem::path(args.output).replace_extension(".candidates.png")
            : std::filesystem::path(args.overlays) / "candidates.png";
    if (!args.overlays.empty()) ensure_directory(args.overlays);
    double scale = 1.0;
    const Image img = calib::downscale_for_overlay(
        read_image(files.front()), args.overlay_full_size ? 0 : args.overlay_max_side, &scale);
    {
      // The diagnostic is the point of this failure: it is kept although the command fails.
      const OutputTransaction::Immediate keep;
      write_image(shown, calib::candidates_overlay(img, e.candidates(), scale).view());
    }
    throw Error(std::string(e.what()) + "\nthe candidates are drawn in " + shown.string() +
                "; no light file written");
  }
  calib::RigReport& report = result.rig;
  calib::drop_rig_lights(args.drop, &report);
  const int dropped = args.drop_outliers ? calib::drop_outliers(&report) : 0;
  const LightSet lights = calib::rig_light_set(report);
  if (lights.empty()) {
    // The report says why each light was dropped: it is kept although the command fails.
    std::string why = "no image has a usable highlight on the sphere";
    if (!args.report.empty()) {
      const OutputTransaction::Immediate keep;
      write_file_atomic(args.report, result.to_json() + "\n");
      why += " (the flags of every light are in " + args.report + ")";
    } else {
      why += " (--report FILE lists the flags of every light)";
    }
    for (const calib::SphereReport& sphere : report.spheres) {
      for (const calib::SphereLight& light : sphere.lights) {
        if (!light.flag.empty()) {
          why += "\nfirst flag: " + light.image.filename().string() + ": " + light.flag;
          break;
        }
      }
    }
    throw Error(why);
  }
  write_lp(args.output, lights);
  if (!args.json.empty()) write_light_json(args.json, lights);
  if (!args.report.empty()) write_file_atomic(args.report, result.to_json() + "\n");
  if (!args.overlays.empty()) write_overlays(args, files, report);
  if (!args.plot.empty()) {
    // The plot shows the rig's lights: the first sphere's report with the rig's results.
    calib::SphereReport shown = report.spheres.front();
    for (std::size_t i = 0; i < shown.lights.size(); ++i) {
      shown.lights[i].found = report.lights[i].found;
      shown.lights[i].flag = report.lights[i].flag;
      shown.lights[i].direction = report.lights[i].direction;
    }
    write_image(args.plot, calib::light_polar_plot(shown).view());
  }
  for (const calib::SphereReport& s : report.spheres) {
    // The chosen candidate nearest the sphere: the full-resolution polish moves a circle a
    // little, a small one by more than a tenth of its radius.
    double score = 0.0, nearest = std::numeric_limits<double>::infinity();
    for (const auto& c : result.candidates) {
      const double d = (c.circle.centre_px - s.sphere.centre_px).norm();
      if (c.chosen && d < nearest) {
        nearest = d;
        score = c.score;
      }
    }
    std::printf("calibrate sphere: sphere at (%.2f, %.2f) radius %.2f px (%s",
                s.sphere.centre_px.x(), s.sphere.centre_px.y(), s.sphere.radius_px,
                s.sphere_detected ? "found" : "given");
    if (s.sphere_detected) std::printf(", score %.2f", score);
    std::printf(")\n");
  }
  if (!result.search_note.empty()) std::printf("  %s\n", result.search_note.c_str());
  if (!result.exposure_gains.empty()) {
    const auto [lo, hi] =
        std::minmax_element(result.exposure_gains.begin(), result.exposure_gains.end());
    std::printf(
        "  the exposure varies from image to image: %.2f-%.2f times the stack's (measured from "
        "what the spheres mirror; a camera on automatic exposure, or a flash whose output "
        "varies); the highlights were measured against it (exposure_gains in the report)\n",
        *lo, *hi);
  }
  if (!result.image_shifts_px.empty()) {
    std::vector<double> len;
    for (const Eigen::Vector2d& d : result.image_shifts_px) len.push_back(d.norm());
    std::sort(len.begin(), len.end());
    std::printf(
        "  the camera moved between shots: images shifted by about %.2f px at most (median %.2f) "
        "against the stack; spots were measured against the median's 3 x 3 maximum%s "
        "(image_shifts_px in the report)\n",
        len.back(), len[len.size() / 2],
        result.image_shifts_undone
            ? " and each highlight taken back by its image's shift"
            : "; shifts this small are not told from what the lights change, and were not "
              "undone");
  }
  if (result.two_spot_images > 0) {
    std::printf("  %d of %zu images show two moving spots on a sphere; treated as %s (%s)\n",
                result.two_spot_images, files.size(), calib::to_string(result.material),
                result.material_note.c_str());
  }
  if (result.camera.focal_px > 0.0) {
    std::printf("calibrate sphere: camera focal length %.1f px, from %s\n", result.camera.focal_px,
                result.camera.focal_source.c_str());
  } else {
    std::printf("calibrate sphere: camera focal length %s\n", result.camera.focal_source.c_str());
  }
  std::printf("calibrate sphere: %s model%s; %d of %zu lights usable, %d outliers%s -> %s%s%s\n",
              report.model.c_str(), report.refined ? ", refined" : "", report.usable(),
              report.lights.size(), report.outliers(), dropped > 0 ? " (dropped)" : "",
              args.output.c_str(), args.json.empty() ? "" : " and ", args.json.c_str());
  if (!report.model_note.empty()) std::printf("  %s\n", report.model_note.c_str());
  if (report.near) {
    std::printf("  light %s: origin at %s\n", report.near_scale_free ? "directions" : "positions",
                report.origin.c_str());
  }
  if (!report.near && report.spheres.size() >= 2 && report.most_lights_outliers()) {
    std::printf(
        "  most lights disagree between the spheres: near lights? (give --sphere-radius-mm "
        "and --focal-px to triangulate their positions)\n");
  }
  for (const auto& l : report.lights) {
    if (!l.found) {
      std::printf("  flagged %s: %s\n", l.image.filename().string().c_str(), l.flag.c_str());
    } else if (l.outlier) {
      std::printf("  outlier %s (residual %.2f px, confidence %.2f): %s\n",
                  l.image.filename().string().c_str(), l.residual_px, l.confidence, l.flag.c_str());
    }
  }
}

}  // namespace

void add_calibrate_command(CLI::App& root) {
  CLI::App* cmd = root.add_subcommand(
      "calibrate", "Calibrate a capture rig: light directions (and positions) of the lights.");
  cmd->require_subcommand(1);

  auto dome = std::make_shared<DomeArgs>();
  CLI::App* d = cmd->add_subcommand(
      "dome",
      "Write a light file from dome geometry: a standard layout (icosa: the seed paper's 40 "
      "lights; geodesic:F; dome49; rings:ELEV:COUNT[:AZIMUTH],...) or a dome description "
      "(.json with radius_mm, yaw_deg and a layout or per-light directions / positions).");
  d->add_option("--layout", dome->options.layout, "Layout spec or dome description .json")
      ->capture_default_str();
  d->add_option("-o,--output", dome->output, "Light file to write (.lp)")->required();
  d->add_option("--names", dome->options.name_pattern,
                "Image names, printf-style with the 1-based light index")
      ->capture_default_str();
  d->add_option("--radius", dome->options.radius_mm,
                "Dome radius in mm (0 = distant lights); gives every light a position")
      ->capture_default_str()
      ->check(CLI::NonNegativeNumber);
  d->add_option("--yaw", dome->options.yaw_deg,
                "Rotation of the dome about the camera axis, degrees counter-clockwise")
      ->capture_default_str();
  d->add_option("--json", dome->json,
                "Also write every light as JSON (directions, positions in mm, intensity)");
  d->callback([dome] { run_dome(*dome); });

  auto sphere = std::make_shared<SphereArgs>();
  CLI::App* sp = cmd->add_subcommand(
      "sphere",
      "Light directions from the highlight on a mirror or black glossy sphere in each photo. "
      "The sphere is found automatically, or given by --sphere or --mask. Images without a "
      "usable highlight are flagged and left out of the light file, never guessed.");
  sp->add_option("images", sphere->images, "The photographs, one per light")->required();
  sp->add_option("-o,--output", sphere->output, "Light file to write (.lp)")->required();
  sp->add_option("--report", sphere->report,
                 "JSON report: the model, each sphere (detected and refined) with every "
                 "light's highlight, blob shape, residual and confidence; per light the "
                 "direction (position), residual, confidence and flags");
  sp->add_option("--sphere", sphere->spheres,
                 "A sphere's circle cx,cy,r in pixels from the image's top-left pixel centre; "
                 "once per sphere")
      ->expected(1)
      ->allow_extra_args(false)
      ->multi_option_policy(CLI::MultiOptionPolicy::TakeAll);
  sp->add_option("--spheres", sphere->sphere_count,
                 "How many spheres to find when no --sphere is given")
      ->capture_default_str()
      ->check(CLI::PositiveNumber);
  sp->add_option("--sphere-radius-mm", sphere->sphere_radius_mm,
                 "The spheres' real radius in mm: with --focal-px and 2+ spheres, light "
                 "positions are triangulated (near lights; write them with --json)")
      ->check(CLI::NonNegativeNumber);
  sp->add_option("--plane", sphere->plane,
                 "Sample plane (.json with a pose): light positions relative to its centre "
                 "(default origin: the optical axis at the spheres' mean depth)");
  sp->add_option("--json", sphere->json,
                 "Also write every light as JSON (directions, positions in mm)");
  sp->add_flag("--allow-disagreement", sphere->allow_disagreement,
               "Write the lights even where two or more spheres found, with a focal length, "
               "disagree about more than three quarters of them (by default the search is made "
               "once more, outlines kept near their proposals and spheres chosen by a 5-degree "
               "agreement, and if those disagree too it is an error listing the candidates: such "
               "spheres are most likely not the capture's)");
  sp->add_flag("--distant-lights", sphere->distant_lights,
               "Keep the distant-light model even where the spheres disagree. By default, with "
               "a focal length, 2+ spheres and neither --sphere-radius-mm nor --plane, near "
               "lights are taken where most lights disagree between the spheres as distant "
               "ones and near ones explain them (directions from the origin; the report says "
               "why)");
  sp->add_flag("--no-refine", sphere->no_refine,
               "Skip the joint refinement (per-sphere reflections, linear triangulation)");
  sp->add_option("--outlier-px", sphere->outlier_px,
                 "A highlight residual above this (pixels) flags the light as an outlier")
      ->capture_default_str()
      ->check(CLI::PositiveNumber);
  sp->add_flag("--drop-outliers", sphere->drop_outliers,
               "Leave the lights flagged as outliers out of the light file");
  sp->add_option("--mask", sphere->mask, "A mask image of the sphere (pixels > 0.5)");
  CLI::Option* focal_px =
      sp->add_option("--focal-px", sphere->options.camera.focal_px,
                     "Focal length in pixels for the perspective model (0 = orthographic). "
                     "Default: the photographs' EXIF focal length (FocalLength with the "
                     "sensor's FocalPlaneXResolution, else FocalLengthIn35mmFilm), when every "
                     "photograph gives the same; else orthographic")
          ->check(CLI::NonNegativeNumber);
  sp->add_flag("--no-exif-focal", sphere->no_exif_focal,
               "Ignore the photographs' EXIF focal length (orthographic camera unless "
               "--focal-px, --focal-mm or --camera says otherwise)");
  sp->add_option("--camera", sphere->camera,
                 "Intrinsics (.json from `ptmkit calibrate camera`): focal length and principal "
                 "point for the perspective model");
  sp->add_option("--focal-mm", sphere->focal_mm,
                 "Lens focal length in mm (with --sensor-width-mm) for the perspective model")
      ->check(CLI::PositiveNumber);
  sp->add_option("--sensor-width-mm", sphere->sensor_width_mm,
                 "Sensor width in mm (the photographs' full width), for --focal-mm")
      ->check(CLI::PositiveNumber);
  sp->add_option("--principal", sphere->principal,
                 "Principal point x,y in pixels (default: the image centre)");
  sp->add_option("--blob-fraction", sphere->options.blob_fraction,
                 "Highlight blob: pixels at or above this fraction of the peak")
      ->capture_default_str();
  sp->add_option("--min-peak", sphere->options.min_peak,
                 "A peak below this (full scale 1) is no highlight")
      ->capture_default_str();
  sp->add_option("--drop", sphere->drop,
                 "Leave these lights out (0-based indices, as in the report), e.g. --drop 3,7")
      ->delimiter(',');
  sp->add_option("--overlays", sphere->overlays,
                 "Folder for one overlay PNG per image: the sphere and the highlight found "
                 "(green used, orange outlier, red flagged)");
  sp->add_option("--plot", sphere->plot, "Polar plot (PNG) of the light directions");
  sp->add_option("--roi", sphere->rois,
                 "Search box x,y,w,h in pixels for a sphere (repeat once per sphere): a sphere "
                 "is taken in each box")
      ->expected(1)
      ->allow_extra_args(false)
      ->multi_option_policy(CLI::MultiOptionPolicy::TakeAll);
  sp->add_option("--radius-range", sphere->radius_range,
                 "Search only spheres of radius MIN,MAX pixels");
  sp->add_option("--reference", sphere->reference,
                 "A photo of the scene in room light (same size): its sphere rims help the "
                 "search");
  sp->add_option("--min-score", sphere->min_score,
                 "A found sphere needs at least this evidence score (0..1; see the report's "
                 "candidates)")
      ->capture_default_str()
      ->check(CLI::Range(0.0, 1.0));
  sp->add_option("--sphere-material", sphere->sphere_material,
                 "What the spheres are, for two moving spots on one sphere: mirror (chrome, "
                 "black glossy: one reflection per light; an unusable spot leaves the light "
                 "without one), glass (a surface reflection and a refracted hot spot: when the "
                 "spot taken is unusable a comparable usable second one is taken, doubtful), "
                 "auto (glass when a quarter of the images show a second spot across the "
                 "sphere's centre from the first; reported)")
      ->capture_default_str()
      ->check(CLI::IsMember({"auto", "mirror", "glass"}));
  sp->add_flag("--overlay-full-size", sphere->overlay_full_size,
               "Overlays at the photographs' size (default: longest side --overlay-max-side)");
  sp->add_option("--overlay-max-side", sphere->overlay_max_side,
                 "Downscaled overlays' longest side, pixels")
      ->capture_default_str()
      ->check(CLI::Range(64, 100000));
  sp->callback([sphere, focal_px] {
    sphere->focal_px_given = focal_px->count() > 0;
    run_sphere(*sphere);
  });
  add_calibrate_board_commands(cmd);
}

}  // namespace ptmkit::app
