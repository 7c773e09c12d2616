// AprilTag boards: the JSON description (core/board.h) and rendered boards (synth/board.h)
// checked against the detector (calib/apriltag.h).
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "ptmkit/calib/apriltag.h"
#include "ptmkit/core/board.h"
#include "ptmkit/core/error.h"
#include "ptmkit/core/plane.h"
#include "ptmkit/synth/board.h"
#include "test_util.h"
#include "tolerances.h"

namespace fs = std::filesystem;

namespace ptmkit {
namespace {

using test::kDoubleRoundoff;

// The detector's common shift (mean of detected minus true corners): measured (0.001, -0.004)
// px on the pinhole render, (-0.005, -0.084) px on the orthographic one.
constexpr double kDetectorShiftTolPx = 0.15;
// Corner RMS after removing the shift: measured 0.067 px (pinhole), 0.231 px (orthographic).
constexpr double kCornerRmsTolPx = 0.25;
// Worst corner after removing the shift, pinhole render: measured 0.231 px.
constexpr double kCornerWorstTolPx = 0.6;
// Scale from the tags' edges: the detector's ~0.1 px outward bias per corner is 0.3% of a
// 54 px edge (measured 0.25%).
constexpr double kEdgeScaleRelTol = 0.005;

void write_text(const fs::path& p, const std::string& text) {
  std::ofstream out(p);
  out << text;
}

// The error message of read_board_json on this text; empty when it reads.
std::string board_error(const fs::path& p, const std::string& text) {
  write_text(p, text);
  try {
    (void)read_board_json(p);
  } catch (const Error& e) {
    return e.what();
  }
  return {};
}

TEST(CalibBoard, SampleGridReadsAndRoundTrips) {
  const TagBoard board = read_board_json(test::source_dir() / "data/boards/tag36h11-6x4.json");
  ASSERT_EQ(board.tags.size(), 24u);
  EXPECT_EQ(board.family, "tag36h11");
  EXPECT_DOUBLE_EQ(board.tag_size_mm, 20.0);
  // Grid centred on the origin, ids row by row from the top-left, y up.
  EXPECT_NEAR(board.tags[0].centre_mm().x(), -75.0, kDoubleRoundoff);
  EXPECT_NEAR(board.tags[0].centre_mm().y(), 45.0, kDoubleRoundoff);
  EXPECT_NEAR(board.tags[23].centre_mm().x(), 75.0, kDoubleRoundoff);
  EXPECT_NEAR(board.tags[23].centre_mm().y(), -45.0, kDoubleRoundoff);
  EXPECT_NEAR(board.tags[1].centre_mm().x() - board.tags[0].centre_mm().x(), 30.0, kDoubleRoundoff);
  // Bottom-left corner first, counter-clockwise.
  EXPECT_NEAR(board.tags[0].corners_mm[0].x(), -85.0, kDoubleRoundoff);
  EXPECT_NEAR(board.tags[0].corners_mm[0].y(), 35.0, kDoubleRoundoff);
  EXPECT_NEAR(board.tags[0].corners_mm[2].x(), -65.0, kDoubleRoundoff);
  EXPECT_NEAR(board.tags[0].corners_mm[2].y(), 55.0, kDoubleRoundoff);
  EXPECT_NEAR(board.paper_min_mm.x(), -95.0, kDoubleRoundoff);
  EXPECT_NEAR(board.paper_max_mm.y(), 65.0, kDoubleRoundoff);

  test::ScratchDir dir;
  write_board_json(dir / "b.json", board);
  const TagBoard back = read_board_json(dir / "b.json");
  ASSERT_EQ(back.tags.size(), board.tags.size());
  for (std::size_t i = 0; i < board.tags.size(); ++i) {
    EXPECT_EQ(back.tags[i].id, board.tags[i].id);
    for (std::size_t k = 0; k < 4; ++k) {
      EXPECT_EQ(back.tags[i].corners_mm[k], board.tags[i].corners_mm[k]);
    }
  }
  EXPECT_EQ(back.paper_min_mm, board.paper_min_mm);
  EXPECT_EQ(back.paper_max_mm, board.paper_max_mm);
  EXPECT_EQ(back.find(7)->id, 7);
  EXPECT_EQ(back.find(24), nullptr);
}

TEST(CalibBoard, ExplicitTagsAndErrorsNameTheFile) {
  test::ScratchDir dir;
  const fs::path p = dir / "board.json";
  EXPECT_EQ(board_error(p, R"({"tag_size_mm": 10, "tags": [
      {"id": 3, "centre_mm": [0, 0]},
      {"id": 1, "corners_mm": [[20, -5], [30, -5], [30, 5], [20, 5]]}]})"),
            "");
  const TagBoard b = read_board_json(p);
  ASSERT_EQ(b.tags.size(), 2u);
  EXPECT_EQ(b.tags[0].id, 1);  // sorted by id
  EXPECT_EQ(b.family, "tag36h11");

  const std::string name = p.string();
  const auto expect_error = [&](const std::string& text, const std::string& what) {
    const std::string err = board_error(p, text);
    EXPECT_NE(err.find(name), std::string::npos) << err;
    EXPECT_NE(err.find(what), std::string::npos) << "'" << err << "' lacks '" << what << "'";
  };
  expect_error(R"({"tag_size_mm": 10, "tags": [{"id": 1, "centre_mm": [0, 0]},
      {"id": 1, "centre_mm": [30, 0]}]})",
               "duplicate tag 1");
  expect_error(R"({"tag_size_mm": 0, "grid": {"cols": 2, "rows": 2, "spacing_mm": 30}})",
               "tag_size_mm");
  expect_error(R"({"tag_size_mm": -3, "tags": [{"id": 1, "centre_mm": [0, 0]}]})", "tag_size_mm");
  expect_error(R"({"tag_size_mm": 20, "grid": {"cols": 2, "rows": 2, "spacing_mm": 10}})",
               "spacing_mm");
  expect_error(R"({"tag_size_mm": 10, "tags": [
      {"id": 1, "corners_mm": [[0, 0], [0, 10], [10, 10], [10, 0]]}]})",
               "counter-clockwise");
  expect_error(R"({"tag_size_mm": 10, "tags": [
      {"id": 1, "corners_mm": [[0, 0], [20, 0], [20, 20], [0, 20]]}]})",
               "tag_size_mm says 10");
  expect_error(R"({"tag_size_mm": 10, "tags": [], "grid": {}})", "either");
  expect_error(R"({"tag_size_mm": 10, "tags": [{"id": -1, "centre_mm": [0, 0]}]})", ">= 0");
  expect_error(R"({"tag_size_mm": 10, "tags": [{"id": 1, "centre_mm": [0]}]})", "centre_mm");
  expect_error(R"({"tag_size_mm": 10,)", "not valid JSON");
  expect_error(R"({"tag_size_mm": 10, "tags": [{"id": 1, "centre_mm": [0, 0]}],
      "paper_mm": [0, 0, 1, 1]})",
               "outside the paper");
  EXPECT_THROW((void)read_board_json(dir / "missing.json"), Error);
}

// detect_tags converts the apriltag library's pixel convention (centres at +0.5) to ours
// (centres at integers): no common shift is left between detected and true corners. The tests
// measure the shift, and the corners after removing it.
constexpr double kDetectorOffsetPx = 0.0;

// Detected minus true corner positions (pixels): the mean (common shift) and what remains.
struct CornerErrors {
  Eigen::Vector2d shift_px = Eigen::Vector2d::Zero();
  double rms_px = 0.0;    // after removing the shift
  double worst_px = 0.0;  // after removing the shift
};

CornerErrors corner_errors(const std::vector<Eigen::Vector2d>& errors) {
  CornerErrors out;
  for (const auto& e : errors) out.shift_px += e / static_cast<double>(errors.size());
  for (const auto& e : errors) {
    const double d = (e - out.shift_px).norm();
    out.rms_px += d * d / static_cast<double>(errors.size());
    out.worst_px = std::max(out.worst_px, d);
  }
  out.rms_px = std::sqrt(out.rms_px);
  return out;
}

// Projected board corners vs detections: same ids, same order, sub-pixel agreement.
TEST(CalibBoard, RenderedBoardIsDetectedWhereItWasPut) {
  const TagBoard board = grid_board("tag36h11", 20.0, 6, 4, 30.0);
  synth::PinholeCamera cam;  // 640x480, f 1000 px
  cam.k1 = -0.1;
  cam.k2 = 0.05;
  const synth::BoardPose pose = synth::facing_pose(420.0, 20.0, 30.0, 5.0);
  synth::BoardRenderOptions ro;
  ro.noise_sigma = 1.0;
  const Image img = synth::render_board(board, cam, pose, ro);
  const auto project = [&](const Eigen::Vector2d& c) {
    return cam.project(pose.camera_from_board * Eigen::Vector3d(c.x(), c.y(), 0.0) +
                       pose.board_origin_in_camera_mm);
  };
  int in_view = 0;
  for (const auto& t : board.tags) {
    bool inside = true;
    for (const auto& c : t.corners_mm) {
      const Eigen::Vector2d px = project(c);
      inside = inside && px.x() > 0 && px.y() > 0 && px.x() < 639 && px.y() < 479;
    }
    in_view += inside ? 1 : 0;
  }
  EXPECT_EQ(in_view, 24);
  const auto found = calib::detect_tags(img.view());
  ASSERT_EQ(found.size(), 24u);
  std::vector<Eigen::Vector2d> errors;
  for (const auto& d : found) {
    const BoardTag* t = board.find(d.id);
    ASSERT_NE(t, nullptr);
    for (std::size_t k = 0; k < 4; ++k)
      errors.push_back(d.corners_px[k] - project(t->corners_mm[k]));
  }
  const CornerErrors e = corner_errors(errors);
  std::printf(
      "pinhole render: 24 tags; detector shift (%.3f, %.3f) px; after it rms %.3f px, "
      "worst %.3f px\n",
      e.shift_px.x(), e.shift_px.y(), e.rms_px, e.worst_px);
  EXPECT_NEAR(e.shift_px.x(), kDetectorOffsetPx, kDetectorShiftTolPx);
  EXPECT_NEAR(e.shift_px.y(), kDetectorOffsetPx, kDetectorShiftTolPx);
  EXPECT_LT(e.rms_px, kCornerRmsTolPx);
  EXPECT_LT(e.worst_px, kCornerWorstTolPx);
}

TEST(CalibBoard, PartlyVisibleBoardDetectsTheTagsInView) {
  const TagBoard board = grid_board("tag36h11", 20.0, 6, 4, 30.0);
  synth::PinholeCamera cam;
  cam.width_px = 320;
  cam.height_px = 240;
  cam.cx = 159.5;
  cam.cy = 119.5;
  // Shift the board right so the left columns fall outside the image.
  synth::BoardPose pose = synth::facing_pose(500.0);
  pose.board_origin_in_camera_mm.x() = 60.0;
  const Image img = synth::render_board(board, cam, pose);
  int in_view = 0;
  for (const auto& t : board.tags) {
    bool inside = true;
    for (const auto& c : t.corners_mm) {
      const Eigen::Vector2d px =
          cam.project(pose.camera_from_board * Eigen::Vector3d(c.x(), c.y(), 0) +
                      pose.board_origin_in_camera_mm);
      // A quiet zone of one cell (2.5 mm = 5 px) is needed around the black square.
      inside = inside && px.x() > 5 && px.y() > 5 && px.x() < 314 && px.y() < 234;
    }
    in_view += inside ? 1 : 0;
  }
  const auto found = calib::detect_tags(img.view());
  EXPECT_GT(in_view, 0);
  EXPECT_LT(in_view, 24);
  EXPECT_EQ(static_cast<int>(found.size()), in_view);
}

TEST(CalibBoard, OrthographicRenderHasTheRequestedScale) {
  // Off-grid: the grid centre is not on a pixel centre or edge.
  const TagBoard board = grid_board("tag36h11", 20.0, 6, 4, 30.0, 0, {0.123, -0.377});
  const double mm_per_px = 0.37;
  const Image img = synth::render_board_orthographic(board, 600, 420, mm_per_px);
  const SamplePlane plane = orthographic_plane(600, 420, mm_per_px);
  const auto found = calib::detect_tags(img.view());
  ASSERT_EQ(found.size(), 24u);
  std::vector<Eigen::Vector2d> errors;
  double edge_sum_px = 0.0;
  for (const auto& d : found) {
    const BoardTag* t = board.find(d.id);
    ASSERT_NE(t, nullptr);
    for (std::size_t k = 0; k < 4; ++k) {
      const Eigen::Vector2d mm = plane.plane_mm(d.corners_px[k]) - t->corners_mm[k];
      errors.emplace_back(mm.x() / mm_per_px, -mm.y() / mm_per_px);  // image y is down
      edge_sum_px += (d.corners_px[(k + 1) % 4] - d.corners_px[k]).norm();
    }
  }
  const double measured = 20.0 / (edge_sum_px / (4.0 * 24.0));
  const CornerErrors e = corner_errors(errors);
  std::printf(
      "orthographic: measured %.5f mm/px (asked %.5f); detector shift (%.3f, %.3f) px; "
      "after it rms %.3f px, worst %.3f px\n",
      measured, mm_per_px, e.shift_px.x(), e.shift_px.y(), e.rms_px, e.worst_px);
  EXPECT_NEAR(measured, mm_per_px, kEdgeScaleRelTol * mm_per_px);
  EXPECT_NEAR(e.shift_px.x(), kDetectorOffsetPx, kDetectorShiftTolPx);
  EXPECT_NEAR(e.shift_px.y(), kDetectorOffsetPx, kDetectorShiftTolPx);
  EXPECT_LT(e.rms_px, kCornerRmsTolPx);
  EXPECT_NEAR(plane.mean_mm_per_px(), mm_per_px, kDoubleRoundoff);
}

TEST(CalibBoard, RendererRejectsBadInput) {
  TagBoard board = grid_board("tag36h11", 20.0, 2, 2, 30.0);
  synth::PinholeCamera cam;
  EXPECT_THROW((void)synth::render_board(board, cam, synth::facing_pose(300.0), {0}), Error);
  cam.fx = 0.0;
  EXPECT_THROW((void)synth::render_board(board, cam, synth::facing_pose(300.0)), Error);
  board.family = "qr";
  EXPECT_THROW((void)synth::render_board_orthographic(board, 64, 64, 1.0), Error);
  board = grid_board("tag16h5", 20.0, 6, 6, 30.0);  // 36 tags, 30 codes
  EXPECT_THROW((void)synth::render_board_orthographic(board, 64, 64, 1.0), Error);
}

}  // namespace
}  // namespace ptmkit
