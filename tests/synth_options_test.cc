// Tests of the synth stage's options: bad options throw and write nothing; presets and light
// layouts.
#include <cmath>
#include <fstream>
#include <string>

#include <gtest/gtest.h>

#include "ptmkit/core/error.h"
#include "ptmkit/core/light_set.h"
#include "ptmkit/synth/synth.h"
#include "synth_test_util.h"
#include "test_util.h"

namespace fs = std::filesystem;

namespace ptmkit::synth {
namespace {

using test::small_options;

// A ring's elevation in degrees through double trigonometry (~1e-14), with room.
constexpr double kDegreesTol = 1e-9;
// A unit direction normalised in double (~1e-16 a component), with room.
constexpr double kUnitTol = 1e-12;

// --- options -------------------------------------------------------------------------------

TEST(SynthOptions, BadOptionsThrow) {
  auto expect_error = [](SynthOptions o, const std::string& fragment) {
    try {
      validate(o);
      (void)resolve_lights(o);
      ADD_FAILURE() << "no error for " << fragment;
    } catch (const Error& e) {
      EXPECT_NE(std::string(e.what()).find(fragment), std::string::npos) << e.what();
    }
  };
  SynthOptions o;
  o.width = 7;
  expect_error(o, "too small");
  o = {};
  o.light_dirs = {Eigen::Vector3d(1.0, 0.0, -0.1)};
  expect_error(o, "below the horizon");
  o = {};
  o.lights = "";
  expect_error(o, "no lights");
  o = {};
  o.lights = "dome48";
  expect_error(o, "unknown light layout");
  o = {};
  o.lights = "rings:95:4";
  expect_error(o, "");
  o = {};
  o.sensor.bits = 12;
  expect_error(o, "bit depth 12");
  o = {};
  o.sensor.bits = 32;
  expect_error(o, "png");
  o = {};
  o.sensor.file_type = FileType::kJpeg;
  o.sensor.bits = 16;
  expect_error(o, "jpg");
  o = {};
  o.sensor.noise_sigma_grey = -1.0;
  expect_error(o, "noise");
  o = {};
  o.sensor.exposure = 0.0;
  expect_error(o, "exposure");
  o = {};
  o.material.exponent = std::nan("");
  expect_error(o, "exponent");
  o = {};
  o.preset = "shiny";
  expect_error(o, "unknown preset");
  EXPECT_THROW((void)preset_options("shiny"), Error);
  EXPECT_THROW((void)parse_file_type("bmp"), Error);
  EXPECT_THROW((void)parse_scene_kind("sphere"), Error);
}

TEST(SynthOptions, BadOptionsWriteNothing) {
  ptmkit::test::ScratchDir dir;
  SynthOptions o = small_options();
  o.sensor.bits = 12;
  EXPECT_THROW((void)render_capture(o, dir / "out"), Error);
  EXPECT_FALSE(fs::exists(dir / "out"));
  o = small_options();
  o.lights = (dir / "missing.lp").string();
  EXPECT_THROW((void)render_capture(o, dir / "out"), Error);
  EXPECT_FALSE(fs::exists(dir / "out"));
}

TEST(SynthOptions, PresetsAndLightLayouts) {
  EXPECT_EQ(preset_options("matte").material.ks, 0.0);
  EXPECT_EQ(preset_options("glossy").material.ks, 0.8);
  EXPECT_EQ(preset_options("glossy").material.exponent, 100.0);
  EXPECT_EQ(preset_options("tall").relief.relief_height_frac,
            2.0 * preset_options("default").relief.relief_height_frac);
  EXPECT_EQ(preset_options("ambient").material.ambient, 0.1);
  EXPECT_EQ(preset_options("polynomial").sensor.file_type, FileType::kExr);
  SynthOptions o;
  EXPECT_EQ(resolve_lights(o).size(), 49u);
  o.lights = "icosa";
  EXPECT_EQ(resolve_lights(o).size(), 40u);
  o.lights = "rings:45:8,80:3:10";
  const auto dirs = resolve_lights(o);
  ASSERT_EQ(dirs.size(), 11u);
  EXPECT_NEAR(elevation_deg(dirs[0]), 45.0, kDegreesTol);

  ptmkit::test::ScratchDir dir;
  std::ofstream(dir / "l.lp") << "2\na.png 1 0 1\nb.png 0 1 1\n";
  o.lights = (dir / "l.lp").string();
  const auto from_lp = resolve_lights(o);
  ASSERT_EQ(from_lp.size(), 2u);
  EXPECT_NEAR(from_lp[1].y(), std::sqrt(0.5), kUnitTol);
}

}  // namespace
}  // namespace ptmkit::synth
