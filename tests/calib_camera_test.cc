// Camera calibration and sample-plane geometry from rendered AprilTag boards
// (calib/camera.h, synth/board.h), and `ptmkit calibrate camera` / `calibrate plane`.
#include <cmath>
#include <cstdio>
#include <fstream>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "ptmkit/calib/camera.h"
#include "ptmkit/core/board.h"
#include "ptmkit/core/error.h"
#include "ptmkit/core/image_io.h"
#include "ptmkit/core/plane.h"
#include "ptmkit/synth/board.h"
#include "test_util.h"
#include "tolerances.h"

namespace fs = std::filesystem;

namespace ptmkit::calib {
namespace {

constexpr double kPi = 3.14159265358979323846;

// Focal length within 0.5%: the requirement (docs/TARGETS.md). Measured 0.034% from 8 views
// (k3 fixed), 0.038% (k3 free), 0.08% from 5 views on the command line.
constexpr double kFocalTargetPercent = 0.5;
// Principal point, 8 views: measured 0.54 px (cx) and 0.06 px (cy) off.
constexpr double kPrincipalPointTolPx = 1.0;
// Reprojection RMS with noise sigma 1 grey level: measured 0.083 px over 8 views, 0.069 px for
// the tilted board's plane.
constexpr double kReprojectionRmsTolPx = 0.2;
// Reprojection RMS of any one of the 8 views: measured worst 0.139 px.
constexpr double kViewRmsTolPx = 0.3;
// The tilted board's tilt and normal: measured 0.000 and 0.0005 degrees off.
constexpr double kPlaneAngleTolDeg = 0.2;
// The plane's origin in the camera frame (560 mm away): measured 0.005 mm off.
constexpr double kPlaneOriginTolMm = 1.0;
// Corners mapped through the homography to board mm: measured worst 0.070 mm (0.19 px at
// 0.37 mm/px).
constexpr double kPlaneCornerTolMm = 0.1;
// View 1's tilt from a 5-view command-line calibration: measured 0.012 degrees off.
constexpr double kCliTiltTolDeg = 0.5;

// The camera of these tests: f ~1500 px, mild barrel distortion, a little decentring.
synth::PinholeCamera true_camera() {
  synth::PinholeCamera c;
  c.width_px = 640;
  c.height_px = 480;
  c.fx = 1500.0;
  c.fy = 1492.0;
  c.cx = 324.3;
  c.cy = 236.8;
  c.k1 = -0.12;
  c.k2 = 0.25;
  c.p1 = 4e-4;
  c.p2 = -3e-4;
  return c;
}

TagBoard test_board() {
  return read_board_json(test::source_dir() / "data/boards/tag36h11-6x4.json");
}

// Eight views from different directions (tilt 15..35 degrees about different axes), the
// board filling most of the frame; rendered once per process (noise sigma 1 grey level).
const std::vector<Image>& views() {
  static const std::vector<Image> images = [] {
    const TagBoard board = test_board();
    const synth::PinholeCamera cam = true_camera();
    struct V {
      double distance, tilt, axis, roll, dx, dy;
    };
    const V vs[] = {{520, 25, 0, 0, 0, 0},    {540, 30, 90, 4, 10, -5}, {500, 20, 45, -6, -8, 6},
                    {560, 35, 135, 3, 5, 8},  {520, 28, 200, 0, 0, 0},  {540, 32, 270, -3, -6, -4},
                    {510, 15, 315, 8, 12, 4}, {600, 35, 20, 0, -10, 0}};
    std::vector<Image> out;
    for (std::size_t i = 0; i < std::size(vs); ++i) {
      synth::BoardPose pose =
          synth::facing_pose(vs[i].distance, vs[i].tilt, vs[i].axis, vs[i].roll);
      pose.board_origin_in_camera_mm += Eigen::Vector3d(vs[i].dx, vs[i].dy, 0.0);
      synth::BoardRenderOptions ro;
      ro.noise_sigma = 1.0;
      ro.seed = 100 + i;
      out.push_back(synth::render_board(board, cam, pose, ro));
    }
    return out;
  }();
  return images;
}

TEST(CalibCamera, RecoversTheFocalLengthFromEightViews) {
  PTMKIT_RELEASE_BUILD_ONLY();
  const TagBoard board = test_board();
  const synth::PinholeCamera truth = true_camera();
  const CameraReport report = calibrate_camera(views(), {}, board);
  ASSERT_EQ(report.views_used, 8);
  const CameraIntrinsics& c = report.camera;
  const double fx_err = 100.0 * (c.fx - truth.fx) / truth.fx;
  const double fy_err = 100.0 * (c.fy - truth.fy) / truth.fy;
  std::printf(
      "calibrate (k3 fixed): fx %.2f (%+.3f%%) fy %.2f (%+.3f%%) cx %.2f cy %.2f k1 %.4f k2 "
      "%.4f p1 %.5f p2 %.5f; rms %.3f px over %d corners\n",
      c.fx, fx_err, c.fy, fy_err, c.cx, c.cy, c.k1, c.k2, c.p1, c.p2, report.rms_px,
      report.corners_used);
  EXPECT_LT(std::abs(fx_err), kFocalTargetPercent);
  EXPECT_LT(std::abs(fy_err), kFocalTargetPercent);
  EXPECT_NEAR(c.cx, truth.cx, kPrincipalPointTolPx);
  EXPECT_NEAR(c.cy, truth.cy, kPrincipalPointTolPx);
  EXPECT_LT(report.rms_px, kReprojectionRmsTolPx);
  EXPECT_EQ(c.k3, 0.0);
  for (const auto& v : report.views) {
    EXPECT_TRUE(v.used);
    EXPECT_EQ(v.tags_used, v.tags_detected);
    EXPECT_LT(v.rms_px, kViewRmsTolPx);
  }
}

// With k3 free the same views give no better focal length and a meaningless k3 (the truth is
// 0): the sixth-order term is not identifiable from a board that stays off the image
// corners, which is why CameraCalibrationOptions::fix_k3 defaults to true.
TEST(CalibCamera, FreeK3GivesNoBetterFocalLength) {
  PTMKIT_RELEASE_BUILD_ONLY();
  const synth::PinholeCamera truth = true_camera();
  CameraCalibrationOptions free_k3;
  free_k3.fix_k3 = false;
  const CameraReport f = calibrate_camera(views(), {}, test_board(), free_k3);
  const double fx_err = 100.0 * (f.camera.fx - truth.fx) / truth.fx;
  const double fy_err = 100.0 * (f.camera.fy - truth.fy) / truth.fy;
  std::printf("calibrate (k3 free): fx %+.3f%% fy %+.3f%% k1 %.4f k2 %.4f k3 %.4f rms %.3f px\n",
              fx_err, fy_err, f.camera.k1, f.camera.k2, f.camera.k3, f.rms_px);
  EXPECT_LT(std::abs(fx_err), kFocalTargetPercent);
  EXPECT_LT(std::abs(fy_err), kFocalTargetPercent);
  EXPECT_NE(f.camera.k3, 0.0);
}

TEST(CalibCamera, TooFewViewsOrTagsAreErrorsWithReasons) {
  const TagBoard board = test_board();
  const std::vector<Image> two(views().begin(), views().begin() + 2);
  EXPECT_THROW((void)calibrate_camera(two, {}, board), Error);
  // A blank view is rejected with a reason, and three usable views remain: 4 in all.
  std::vector<Image> some(views().begin(), views().begin() + 3);
  some.emplace_back(640, 480, 1, ColourSpace::kLinear, 0.5f);
  const CameraReport r = calibrate_camera(some, {"a.png", "b.png", "c.png", "blank.png"}, board);
  EXPECT_EQ(r.views_used, 3);
  EXPECT_FALSE(r.views[3].used);
  EXPECT_EQ(r.views[3].image, "blank.png");
  EXPECT_NE(r.views[3].reason.find("fewer than 4"), std::string::npos) << r.views[3].reason;
  some.pop_back();
  some.pop_back();
  some.emplace_back(640, 480, 1, ColourSpace::kLinear, 0.5f);
  try {
    (void)calibrate_camera(some, {"a.png", "b.png", "blank.png"}, board);
    ADD_FAILURE() << "no error for 2 usable views";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("blank.png"), std::string::npos) << e.what();
  }
  some.emplace_back(320, 240, 1);
  EXPECT_THROW((void)calibrate_camera(some, {}, board), Error);  // mixed sizes
}

TEST(CalibCamera, CameraJsonRoundTripsAndErrorsNameTheFile) {
  test::ScratchDir dir;
  CameraIntrinsics c;
  c.width_px = 640;
  c.height_px = 480;
  c.fx = 1501.25;
  c.fy = 1499.5;
  c.cx = 320.1;
  c.cy = 239.9;
  c.k1 = -0.1;
  c.p2 = 1e-4;
  c.rms_px = 0.07;
  write_camera_json(dir / "cam.json", c);
  const CameraIntrinsics b = read_camera_json(dir / "cam.json");
  EXPECT_EQ(b.fx, c.fx);
  EXPECT_EQ(b.fy, c.fy);
  EXPECT_EQ(b.cx, c.cx);
  EXPECT_EQ(b.k1, c.k1);
  EXPECT_EQ(b.p2, c.p2);
  EXPECT_EQ(b.rms_px, c.rms_px);
  EXPECT_EQ(b.width_px, 640);
  {
    std::ofstream out(dir / "bad.json");
    out << R"({"width_px": 640, "height_px": 480, "fx": -5, "fy": 1, "cx": 0, "cy": 0})";
  }
  try {
    (void)read_camera_json(dir / "bad.json");
    ADD_FAILURE() << "no error";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("bad.json"), std::string::npos) << e.what();
  }
  EXPECT_THROW((void)read_camera_json(dir / "none.json"), Error);
  // A size that is no int (a fraction, or a number JSON can only give as a double: converting
  // 4.8e70 to int is undefined) is an error naming the file and the key, in the camera and in
  // the sample-plane file alike.
  for (const char* size : {"4.8e70", "480.5", "3000000000", "\"480\""}) {
    std::ofstream(dir / "huge.json") << R"({"width_px": 640, "height_px": )" << size
                                     << R"(, "fx": 800, "fy": 800, "cx": 320, "cy": 240})";
    for (int reader = 0; reader < 2; ++reader) {
      try {
        if (reader == 0) {
          (void)read_camera_json(dir / "huge.json");
        } else {
          (void)read_plane_json(dir / "huge.json");
        }
        ADD_FAILURE() << "no error for height_px " << size;
      } catch (const Error& e) {
        const std::string what = e.what();
        EXPECT_NE(what.find("huge.json"), std::string::npos) << what;
        EXPECT_NE(what.find("height_px"), std::string::npos) << what;
      }
    }
  }
}

CameraIntrinsics intrinsics_of(const synth::PinholeCamera& s) {
  CameraIntrinsics c;
  c.width_px = s.width_px;
  c.height_px = s.height_px;
  c.fx = s.fx;
  c.fy = s.fy;
  c.cx = s.cx;
  c.cy = s.cy;
  c.k1 = s.k1;
  c.k2 = s.k2;
  c.p1 = s.p1;
  c.p2 = s.p2;
  c.k3 = s.k3;
  return c;
}

TEST(CalibCamera, PlanePoseOfATiltedBoard) {
  const TagBoard board = test_board();
  const synth::PinholeCamera cam = true_camera();
  const double tilt = 30.0;
  synth::BoardPose pose = synth::facing_pose(560.0, tilt, 60.0, 10.0);
  synth::BoardRenderOptions ro;
  ro.noise_sigma = 1.0;
  const Image img = synth::render_board(board, cam, pose, ro);
  PlaneOptions options;
  options.origin_mm = {15.0, -15.0};
  const PlaneReport r = estimate_plane(img, board, intrinsics_of(cam), options);
  ASSERT_TRUE(r.plane.pose.has_value());
  const Eigen::Vector3d n_true = pose.camera_from_board.col(2);
  const Eigen::Vector3d n = r.plane.pose->camera_from_plane.col(2);
  const double normal_err_deg = std::acos(std::min(1.0, n.dot(n_true))) * 180.0 / kPi;
  // The plane origin: board point origin_mm.
  const Eigen::Vector3d origin_true =
      pose.camera_from_board * Eigen::Vector3d(15.0, -15.0, 0.0) + pose.board_origin_in_camera_mm;
  const double origin_err = (r.plane.pose->plane_origin_in_camera_mm - origin_true).norm();
  // Corners through the homography (undistorted with the intrinsics) vs board mm.
  const auto found = detect_tags(img.view());
  std::vector<Eigen::Vector2d> px;
  std::vector<Eigen::Vector2d> mm;
  for (const auto& d : found) {
    for (std::size_t k = 0; k < 4; ++k) {
      px.push_back(d.corners_px[k]);
      mm.push_back(board.find(d.id)->corners_mm[k] - Eigen::Vector2d(15.0, -15.0));
    }
  }
  const auto ideal = intrinsics_of(cam).undistort(px);
  double worst_mm = 0.0, sum2 = 0.0;
  for (std::size_t i = 0; i < ideal.size(); ++i) {
    const double e = (r.plane.plane_mm(ideal[i]) - mm[i]).norm();
    worst_mm = std::max(worst_mm, e);
    sum2 += e * e;
  }
  std::printf(
      "plane: %d tags, tilt %.3f deg (true %.1f), normal error %.4f deg, origin error %.3f mm, "
      "corners rms %.4f mm worst %.4f mm (%.4f mm/px), reprojection rms %.3f px\n",
      r.tags_used, r.tilt_deg, tilt, normal_err_deg, origin_err,
      std::sqrt(sum2 / static_cast<double>(ideal.size())), worst_mm, r.plane.mean_mm_per_px(),
      r.rms_px);
  EXPECT_EQ(r.tags_used, 24);
  EXPECT_NEAR(r.tilt_deg, tilt, kPlaneAngleTolDeg);
  EXPECT_LT(normal_err_deg, kPlaneAngleTolDeg);
  EXPECT_LT(origin_err, kPlaneOriginTolMm);
  EXPECT_LT(worst_mm, kPlaneCornerTolMm);
  EXPECT_LT(r.rms_px, kReprojectionRmsTolPx);

  // The plane file reads back (read_plane_json validates the rotation and homography).
  test::ScratchDir dir;
  write_plane_json(dir / "plane.json", r.plane);
  const SamplePlane back = read_plane_json(dir / "plane.json");
  EXPECT_NEAR((back.plane_mm(ideal[0]) - r.plane.plane_mm(ideal[0])).norm(), 0.0,
              test::kDoubleSolveRoundoff);

  // The wrong image size and a board-free image are errors.
  CameraIntrinsics other = intrinsics_of(cam);
  other.width_px = 800;
  EXPECT_THROW((void)estimate_plane(img, board, other), Error);
  EXPECT_THROW((void)estimate_plane(Image(640, 480, 1, ColourSpace::kLinear, 0.5f), board,
                                    intrinsics_of(cam)),
               Error);
}

TEST(CalibCamera, CliCalibratesCameraAndPlane) {
  test::ScratchDir dir;
  const fs::path board = test::source_dir() / "data/boards/tag36h11-6x4.json";
  std::vector<std::string> args = {"calibrate", "camera", "--board", board.string()};
  for (std::size_t i = 0; i < 5; ++i) {  // five views keep the test short
    char name[32];
    std::snprintf(name, sizeof name, "view_%02zu.png", i + 1);
    write_image(dir / name, views()[i].view());
    args.push_back((dir / name).string());
  }
  args.insert(args.end(), {"-o", (dir / "camera.json").string(), "--report",
                           (dir / "camera_report.json").string()});
  const auto r = test::run_ptmkit(args);
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_NE(r.out.find("calibrate camera: 5 of 5 views"), std::string::npos) << r.out;
  const CameraIntrinsics c = read_camera_json(dir / "camera.json");
  EXPECT_NEAR(c.fx, true_camera().fx, kFocalTargetPercent / 100.0 * true_camera().fx);
  EXPECT_TRUE(fs::exists(dir / "camera_report.json"));

  const auto p = test::run_ptmkit({"calibrate", "plane", "--board", board.string(), "--camera",
                                   (dir / "camera.json").string(), (dir / "view_01.png").string(),
                                   "-o", (dir / "plane.json").string(), "--origin", "30,0"});
  ASSERT_EQ(p.exit_code, 0) << p.err;
  EXPECT_NE(p.out.find("tilt"), std::string::npos) << p.out;
  const SamplePlane plane = read_plane_json(dir / "plane.json");
  EXPECT_EQ(plane.width_px, 640);
  ASSERT_TRUE(plane.pose.has_value());
  // View 1: 25 degrees about board x.
  EXPECT_NEAR(std::acos(-plane.pose->camera_from_plane(2, 2)) * 180.0 / kPi, 25.0, kCliTiltTolDeg);

  // Errors: a missing image, a missing camera file; exit 1, nothing written.
  const auto e1 =
      test::run_ptmkit({"calibrate", "camera", "--board", board.string(),
                        (dir / "view_01.png").string(), (dir / "nope.png").string(),
                        (dir / "view_02.png").string(), "-o", (dir / "cam2.json").string()});
  EXPECT_EQ(e1.exit_code, 1);
  EXPECT_NE(e1.err.find("nope.png"), std::string::npos) << e1.err;
  EXPECT_FALSE(fs::exists(dir / "cam2.json"));
  const auto e2 = test::run_ptmkit({"calibrate", "plane", "--board", board.string(), "--camera",
                                    (dir / "nocam.json").string(), (dir / "view_01.png").string(),
                                    "-o", (dir / "plane2.json").string()});
  EXPECT_EQ(e2.exit_code, 1);
  EXPECT_NE(e2.err.find("nocam.json"), std::string::npos) << e2.err;
  EXPECT_FALSE(fs::exists(dir / "plane2.json"));
  // Too few views: exit 1, no output.
  const auto e3 = test::run_ptmkit({"calibrate", "camera", "--board", board.string(),
                                    (dir / "view_01.png").string(), (dir / "view_02.png").string(),
                                    "-o", (dir / "cam3.json").string()});
  EXPECT_EQ(e3.exit_code, 1);
  EXPECT_NE(e3.err.find("at least 3"), std::string::npos) << e3.err;
  EXPECT_FALSE(fs::exists(dir / "cam3.json"));
}

}  // namespace
}  // namespace ptmkit::calib
