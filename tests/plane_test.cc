// Sample-plane geometry: the orthographic plane, JSON round trip and malformed files.
#include <fstream>

#include <gmock/gmock.h>
#include <gtest/gtest.h>
#include <Eigen/Geometry>

#include "ptmkit/core/error.h"
#include "ptmkit/core/plane.h"
#include "test_util.h"

namespace ptmkit {
namespace {

TEST(SamplePlane, OrthographicMapsTheImageCentreToTheOriginAndUpToPlusY) {
  const SamplePlane p = orthographic_plane(201, 101, 0.5);
  EXPECT_TRUE(p.plane_mm(100, 50).isApprox(Eigen::Vector2d(0, 0)));
  EXPECT_TRUE(p.plane_mm(200, 50).isApprox(Eigen::Vector2d(50, 0)));
  EXPECT_TRUE(p.plane_mm(100, 0).isApprox(Eigen::Vector2d(0, 25)));  // image top = plane +y
  EXPECT_DOUBLE_EQ(p.mean_mm_per_px(), 0.5);
  EXPECT_THROW((void)orthographic_plane(0, 10, 1.0), Error);
  EXPECT_THROW((void)orthographic_plane(10, 10, -1.0), Error);
}

TEST(SamplePlane, JsonRoundTripKeepsHomographyAndPose) {
  test::ScratchDir dir;
  SamplePlane p = orthographic_plane(64, 48, 0.25);
  p.pixel_to_plane_mm(2, 0) = 1e-4;  // projective
  PlanePose pose;
  pose.camera_from_plane = Eigen::Matrix3d(
      Eigen::AngleAxisd(0.3, Eigen::Vector3d(1, 2, 3).normalized()).toRotationMatrix());
  pose.plane_origin_in_camera_mm = {1, -2, 600};
  p.pose = pose;
  write_plane_json(dir / "plane.json", p);
  const SamplePlane q = read_plane_json(dir / "plane.json");
  EXPECT_EQ(q.width_px, 64);
  EXPECT_EQ(q.height_px, 48);
  EXPECT_TRUE(q.pixel_to_plane_mm.isApprox(p.pixel_to_plane_mm, 1e-12));
  ASSERT_TRUE(q.pose.has_value());
  EXPECT_TRUE(q.pose->camera_from_plane.isApprox(pose.camera_from_plane, 1e-12));
  EXPECT_TRUE(q.pose->plane_origin_in_camera_mm.isApprox(pose.plane_origin_in_camera_mm));
}

TEST(SamplePlane, MalformedFilesAreErrorsNamingTheFile) {
  test::ScratchDir dir;
  const auto expect_error = [&](const std::string& text, const std::string& what) {
    const auto path = dir / "bad.json";
    std::ofstream(path) << text;
    try {
      (void)read_plane_json(path);
      ADD_FAILURE() << "accepted: " << text;
    } catch (const Error& e) {
      EXPECT_THAT(e.what(), ::testing::HasSubstr("bad.json"));
      EXPECT_THAT(e.what(), ::testing::HasSubstr(what));
    }
  };
  const std::string h = R"("pixel_to_plane_mm": [[1,0,0],[0,1,0],[0,0,1]])";
  expect_error("{", "not valid JSON");
  expect_error(R"({"width_px": 0, "height_px": 4, )" + h + "}", "positive");
  expect_error(R"({"width_px": 4, "height_px": 4})", "pixel_to_plane_mm");
  expect_error(R"({"width_px": 4, "height_px": 4, "pixel_to_plane_mm": [[1,0,0],[0,1,0]]})",
               "3 rows");
  expect_error(R"({"width_px": 4, "height_px": 4, "pixel_to_plane_mm": [[1,0,0],[2,0,0],[0,0,1]]})",
               "singular");
  expect_error(R"({"width_px": 4, "height_px": 4, )" + h +
                   R"(, "camera_from_plane": [[2,0,0],[0,1,0],[0,0,1]],
                   "plane_origin_in_camera_mm": [0,0,1]})",
               "not a rotation");
  EXPECT_THROW((void)read_plane_json(dir / "missing.json"), Error);
}

}  // namespace
}  // namespace ptmkit
