// ptmkit calibrate dome: light files from dome geometry.
#include <cstdio>
#include <memory>

#include "commands.h"
#include "progress.h"
#include "ptmkit/calib/dome.h"
#include "ptmkit/calib/sphere.h"
#include "ptmkit/core/atomic_file.h"
#include "ptmkit/core/error.h"
#include "ptmkit/core/image_io.h"
#include "ptmkit/core/light_set.h"
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
  if (!args.json.empty()) calib::write_light_set_json(args.json, lights);
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
  std::string sphere;
  std::string mask;
  std::string principal;
  std::string overlays;
  std::string plot;
  std::vector<int> drop;
  calib::SphereOptions options;
};

void run_sphere(const SphereArgs& args) {
  calib::SphereOptions options = args.options;
  if (!args.sphere.empty() && !args.mask.empty()) {
    throw Error("give the sphere either by --sphere or by --mask, not both");
  }
  if (!args.sphere.empty()) {
    double v[3];
    parse_vector3(args.sphere, "--sphere", v);
    calib::Circle c;
    c.centre_px = {v[0], v[1]};
    c.radius_px = v[2];
    options.sphere = c;
  }
  if (!args.mask.empty()) options.sphere = calib::circle_from_mask(read_image(args.mask).view());
  if (!args.principal.empty()) {
    double v[3] = {0, 0, 0};
    parse_vector3(args.principal + ",0", "--principal", v);
    options.camera.principal_px = Eigen::Vector2d(v[0], v[1]);
  }
  std::vector<std::filesystem::path> files(args.images.begin(), args.images.end());
  const std::vector<Image> images = read_stack(files);
  calib::SphereReport report = calib::calibrate_sphere(images, files, options);
  calib::drop_lights(args.drop, &report);
  const LightSet lights = calib::sphere_light_set(report);
  if (lights.empty()) {
    throw Error("no image has a usable highlight on the sphere (see the flags with --report)");
  }
  write_lp(args.output, lights);
  if (!args.report.empty()) write_file_atomic(args.report, report.to_json() + "\n");
  if (!args.overlays.empty()) {
    ensure_directory(args.overlays);
    for (std::size_t i = 0; i < images.size(); ++i) {
      const auto name = files[i].stem().string() + ".overlay.png";
      write_image(std::filesystem::path(args.overlays) / name,
                  calib::sphere_overlay(images[i], report, i).view());
    }
  }
  if (!args.plot.empty()) write_image(args.plot, calib::light_polar_plot(report).view());
  std::printf(
      "calibrate sphere: sphere at (%.2f, %.2f) radius %.2f px (%s); %d of %zu lights "
      "usable -> %s\n",
      report.sphere.centre_px.x(), report.sphere.centre_px.y(), report.sphere.radius_px,
      report.sphere_detected ? "found" : "given", report.usable(), report.lights.size(),
      args.output.c_str());
  for (const auto& l : report.lights) {
    if (!l.found) {
      std::printf("  flagged %s: %s\n", l.image.filename().string().c_str(), l.flag.c_str());
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
                 "JSON report: sphere, and per light the highlight pixel, peak, blob size, "
                 "saturation, direction and flags");
  sp->add_option("--sphere", sphere->sphere,
                 "The sphere's circle cx,cy,r in pixels from the image's top-left pixel centre");
  sp->add_option("--mask", sphere->mask, "A mask image of the sphere (pixels > 0.5)");
  sp->add_option("--focal-px", sphere->options.camera.focal_px,
                 "Focal length in pixels for the perspective model (0 = orthographic)")
      ->capture_default_str()
      ->check(CLI::NonNegativeNumber);
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
                 "(green used, red flagged)");
  sp->add_option("--plot", sphere->plot, "Polar plot (PNG) of the light directions");
  sp->callback([sphere] { run_sphere(*sphere); });
}

}  // namespace ptmkit::app
