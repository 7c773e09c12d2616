// Light files from dome geometry: layouts, radius and positions, yaw, dome descriptions, CLI.
#include <fstream>

#include <gmock/gmock.h>
#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include "ptmkit/calib/dome.h"
#include "ptmkit/core/error.h"
#include "ptmkit/core/light_set.h"
#include "test_util.h"
#include "tolerances.h"

namespace fs = std::filesystem;
using ::testing::HasSubstr;

namespace ptmkit::calib {
namespace {

using test::kDoubleRoundoff;
using test::kDoubleSolveRoundoff;

void write_text(const fs::path& p, const std::string& s) {
  std::ofstream f(p);
  f << s;
}

TEST(CalibDome, LayoutsRadiusAndYaw) {
  DomeOptions o;
  o.layout = "icosa";
  EXPECT_EQ(dome_light_set(o).size(), 40u);
  o.layout = "dome49";
  const LightSet flat = dome_light_set(o);
  ASSERT_EQ(flat.size(), 49u);
  EXPECT_FALSE(flat.lights[0].position_mm.has_value());
  EXPECT_EQ(flat.lights[0].image, fs::path("image_001.png"));
  o.radius_mm = 500.0;
  o.yaw_deg = 90.0;
  const LightSet near = dome_light_set(o);
  for (std::size_t i = 0; i < near.size(); ++i) {
    ASSERT_TRUE(near.lights[i].position_mm.has_value());
    EXPECT_NEAR((*near.lights[i].position_mm - 500.0 * near.lights[i].direction).norm(), 0.0,
                kDoubleSolveRoundoff);
    // Yaw 90: (x, y) -> (-y, x), elevation unchanged.
    EXPECT_NEAR(near.lights[i].direction.x(), -flat.lights[i].direction.y(), kDoubleRoundoff);
    EXPECT_NEAR(near.lights[i].direction.y(), flat.lights[i].direction.x(), kDoubleRoundoff);
    EXPECT_NEAR(near.lights[i].direction.z(), flat.lights[i].direction.z(), kDoubleRoundoff);
  }
  o.layout = "rings:30:6:15";
  o.radius_mm = 0.0;
  o.yaw_deg = 0.0;
  EXPECT_NEAR(elevation_deg(dome_light_set(o).lights[0].direction), 30.0, kDoubleSolveRoundoff);
  o.layout = "pentagon";
  EXPECT_THROW((void)dome_light_set(o), Error);
  o.layout = "icosa";
  o.name_pattern = "fixed.png";
  EXPECT_THROW((void)dome_light_set(o), Error);
}

TEST(CalibDome, DescriptionFilesWithDirectionsOrPositions) {
  test::ScratchDir dir;
  write_text(dir / "dome.json", R"({"radius_mm": 400, "yaw_deg": 0, "lights": [
      {"image": "a.jpg", "position_mm": [0, 0, 400]},
      {"image": "b.jpg", "position_mm": [300, 0, 300], "intensity": 0.9},
      {"direction": [0, 1, 1]}]})");
  const LightSet set = read_dome_json(dir / "dome.json");
  ASSERT_EQ(set.size(), 3u);
  EXPECT_EQ(set.lights[0].image, dir.path() / "a.jpg");
  EXPECT_NEAR(set.lights[1].direction.x(), std::sqrt(0.5), kDoubleRoundoff);
  EXPECT_NEAR(set.lights[1].position_mm->x(), 300.0, kDoubleRoundoff);
  EXPECT_DOUBLE_EQ(set.lights[1].intensity, 0.9);
  EXPECT_NEAR(set.lights[2].position_mm->y(), 400.0 * std::sqrt(0.5), kDoubleSolveRoundoff);
  EXPECT_EQ(set.lights[2].image, fs::path("image_003.png"));

  write_text(dir / "layout.json", R"({"layout": "icosa", "radius_mm": 250})");
  EXPECT_EQ(read_dome_json(dir / "layout.json").size(), 40u);

  auto expect_error = [&](const std::string& name, const std::string& text,
                          const std::string& what) {
    write_text(dir / name, text);
    try {
      (void)read_dome_json(dir / name);
      FAIL() << name;
    } catch (const Error& e) {
      EXPECT_THAT(e.what(), HasSubstr(name));
      EXPECT_THAT(e.what(), HasSubstr(what));
    }
  };
  expect_error("both.json", R"({"layout": "icosa", "lights": []})", "either");
  expect_error("below.json", R"({"lights": [{"direction": [1, 0, -0.1]}]})", "light 1");
  expect_error("broken.json", R"({"lights": [)", "not valid JSON");
  expect_error("vec.json", R"({"lights": [{"direction": [1, 0]}]})", "three numbers");
  expect_error("neither.json", R"({"lights": [{"image": "x.jpg"}]})", "direction or position");
  expect_error("radius.json", R"({"layout": "icosa", "radius_mm": -1})", "radius");
}

TEST(CalibDome, CommandWritesTheLightFileAndJsonOrNothing) {
  test::ScratchDir dir;
  const auto ok = test::run_ptmkit({"calibrate", "dome", "--layout", "dome49", "--radius", "500",
                                    "-o", (dir / "dome.lp").string(), "--json",
                                    (dir / "dome.json").string(), "--names", "IMG_%04d.JPG"});
  ASSERT_EQ(ok.exit_code, 0) << ok.err;
  const LightSet lp = read_lp(dir / "dome.lp");
  EXPECT_EQ(lp.size(), 49u);
  EXPECT_EQ(lp.lights[0].image, dir.path() / "IMG_0001.JPG");
  std::ifstream f(dir / "dome.json");
  const auto j = nlohmann::json::parse(f);
  EXPECT_EQ(j["lights"].size(), 49u);
  // The zenith light.
  EXPECT_NEAR(j["lights"][48]["position_mm"][2].get<double>(), 500.0, kDoubleSolveRoundoff);

  const auto bad = test::run_ptmkit(
      {"calibrate", "dome", "--layout", "rings:30:12,95:3", "-o", (dir / "bad.lp").string()});
  EXPECT_EQ(bad.exit_code, 1);
  EXPECT_THAT(bad.err, HasSubstr("elevation"));
  EXPECT_FALSE(fs::exists(dir / "bad.lp"));
  EXPECT_EQ(test::run_ptmkit({"calibrate"}).exit_code, 2);
}

TEST(CalibDome, JsonWrittenWithPositionsReadsBack) {
  test::ScratchDir dir;
  DomeOptions o;
  o.layout = "dome49";
  o.radius_mm = 450.0;
  const LightSet written = dome_light_set(o);
  write_light_json(dir / "lights.json", written);
  const LightSet read = read_dome_json(dir / "lights.json");
  ASSERT_EQ(read.size(), written.size());
  for (std::size_t i = 0; i < read.size(); ++i) {
    ASSERT_TRUE(read.lights[i].position_mm.has_value());
    EXPECT_LT((*read.lights[i].position_mm - *written.lights[i].position_mm).norm(),
              kDoubleSolveRoundoff);
    EXPECT_LT((read.lights[i].direction - written.lights[i].direction).norm(), kDoubleRoundoff);
  }
  // A direction that does not point at the position is refused.
  std::ofstream(dir / "bad.json")
      << R"({"lights": [{"image": "a.png", "direction": [0, 0, 1], "position_mm": [300, 0, 300]}]})";
  try {
    (void)read_dome_json(dir / "bad.json");
    ADD_FAILURE() << "accepted a direction that disagrees with the position";
  } catch (const Error& e) {
    EXPECT_THAT(e.what(), HasSubstr("bad.json"));
    EXPECT_THAT(e.what(), HasSubstr("does not point at position_mm"));
  }
}

}  // namespace
}  // namespace ptmkit::calib
