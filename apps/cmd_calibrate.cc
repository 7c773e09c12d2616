// ptmkit calibrate dome: light files from dome geometry.
#include <cstdio>
#include <memory>

#include "commands.h"
#include "ptmkit/calib/dome.h"
#include "ptmkit/core/error.h"
#include "ptmkit/core/light_set.h"

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
  d->add_option("--layout", dome->options.layout,
                "Layout spec or dome description .json")
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
}

}  // namespace ptmkit::app
