// ptmkit calibrate camera / plane: camera intrinsics and the sample plane from photographs of
// an AprilTag board.
#include <cstdio>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "commands.h"
#include "flags.h"
#include "ptmkit/calib/apriltag.h"
#include "ptmkit/calib/camera.h"
#include "ptmkit/core/atomic_file.h"
#include "ptmkit/core/board.h"
#include "ptmkit/core/error.h"
#include "ptmkit/core/image_io.h"
#include "ptmkit/core/plane.h"

namespace ptmkit::app {

namespace {

struct CameraArgs {
  std::string board;
  std::vector<std::string> images;
  std::string output;
  std::string report;
  std::string family;
  bool free_k3 = false;
  calib::CameraCalibrationOptions options;
};

void run_camera(const CameraArgs& args) {
  const TagBoard board = read_board_json(args.board);
  calib::CameraCalibrationOptions options = args.options;
  if (!args.family.empty()) options.family = calib::parse_tag_family(args.family);
  options.fix_k3 = !args.free_k3;
  std::vector<std::filesystem::path> files(args.images.begin(), args.images.end());
  const calib::CameraReport report = calib::calibrate_camera(
      files.size(), [&](std::size_t i) { return read_image(files[i]); }, files, board, options);
  calib::write_camera_json(args.output, report.camera);
  if (!args.report.empty()) write_file_atomic(args.report, report.to_json() + "\n");
  const auto& c = report.camera;
  std::printf(
      "calibrate camera: %d of %zu views, %d corners; focal %.2f, %.2f px; principal point "
      "(%.2f, %.2f) px; k1 %.4f k2 %.4f p1 %.5f p2 %.5f k3 %.4f; rms %.3f px -> %s\n",
      report.views_used, report.views.size(), report.corners_used, c.fx, c.fy, c.cx, c.cy, c.k1,
      c.k2, c.p1, c.p2, c.k3, report.rms_px, args.output.c_str());
  for (const auto& v : report.views) {
    if (!v.used) std::printf("  rejected %s: %s\n", v.image.c_str(), v.reason.c_str());
  }
}

struct PlaneArgs {
  std::string board;
  std::string camera;
  std::string image;
  std::string output;
  std::string report;
  std::string family;
  std::string origin;
  calib::PlaneOptions options;
};

void run_plane(const PlaneArgs& args) {
  const TagBoard board = read_board_json(args.board);
  const calib::CameraIntrinsics camera = calib::read_camera_json(args.camera);
  calib::PlaneOptions options = args.options;
  if (!args.family.empty()) options.family = calib::parse_tag_family(args.family);
  if (!args.origin.empty()) {
    options.origin_mm = parse_vector2(args.origin, "--origin");
  }
  const Image image = read_image(args.image);
  calib::PlaneReport report;
  try {
    report = calib::estimate_plane(image, board, camera, options);
  } catch (const Error& e) {
    throw Error(args.image + ": " + e.what());
  }
  write_plane_json(args.output, report.plane);
  if (!args.report.empty()) write_file_atomic(args.report, report.to_json() + "\n");
  const auto& t = report.plane.pose->plane_origin_in_camera_mm;
  std::printf(
      "calibrate plane: %d tags, %d corners; plane origin at (%.2f, %.2f, %.2f) mm in the "
      "camera frame, distance %.2f mm; tilt %.2f degrees; %.4f mm/px; rms %.3f px -> %s\n",
      report.tags_used, report.corners_used, t.x(), t.y(), t.z(), report.distance_mm,
      report.tilt_deg, report.plane.mean_mm_per_px(), report.rms_px, args.output.c_str());
}

}  // namespace

void add_calibrate_board_commands(CLI::App* calibrate) {
  auto cam = std::make_shared<CameraArgs>();
  CLI::App* c = calibrate->add_subcommand(
      "camera",
      "Camera intrinsics (focal lengths, principal point, Brown-Conrady distortion) from "
      "photographs of an AprilTag board seen from several directions (3 or more usable "
      "views; a view with fewer tags than --min-tags is rejected and listed).");
  c->add_option("images", cam->images, "Photographs of the board")->required();
  c->add_option("--board", cam->board, "Board description (.json, see data/boards/)")->required();
  c->add_option("-o,--output", cam->output, "Camera file to write (.json)")->required();
  c->add_option("--report", cam->report,
                "JSON report: per view tags found and used, reprojection rms, board pose");
  c->add_option("--family", cam->family, "Tag family (default: the board's)");
  c->add_flag("--free-k3", cam->free_k3,
              "Estimate k3 too (default: k3 = 0, better conditioned for mild distortion)");
  c->add_option("--min-tags", cam->options.min_tags_per_view,
                "Views with fewer board tags are rejected")
      ->capture_default_str()
      ->check(CLI::PositiveNumber);
  c->callback([cam] { run_camera(*cam); });

  auto plane = std::make_shared<PlaneArgs>();
  CLI::App* p = calibrate->add_subcommand(
      "plane",
      "The sample plane from one photograph of an AprilTag board lying on it: board pose, "
      "pixel-to-plane-mm homography (for undistorted pixels), tilt of the camera.");
  p->add_option("image", plane->image, "Photograph of the board on the sample plane")->required();
  p->add_option("--board", plane->board, "Board description (.json)")->required();
  p->add_option("--camera", plane->camera, "Camera file from `calibrate camera` (.json)")
      ->required();
  p->add_option("-o,--output", plane->output, "Sample-plane file to write (.json)")->required();
  p->add_option("--report", plane->report, "JSON report: tags used, pose, tilt, rms");
  p->add_option("--family", plane->family, "Tag family (default: the board's)");
  p->add_option("--origin", plane->origin,
                "The plane origin (sample-plane centre) x,y in board mm (default 0,0)");
  p->callback([plane] { run_plane(*plane); });
}

}  // namespace ptmkit::app
