// Tests of the synth stage's capture folders: byte-identical whatever the threads, the
// documented truth of the default preset, the polynomial preset's coefficients, JPEG without
// truth.
#include <algorithm>
#include <chrono>
#include <cmath>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include "ptmkit/core/image_io.h"
#include "ptmkit/core/light_set.h"
#include "ptmkit/core/parallel.h"
#include "ptmkit/synth/synth.h"
#include "synth_test_util.h"
#include "test_util.h"
#include "tolerances.h"

namespace fs = std::filesystem;

namespace ptmkit::synth {
namespace {

using test::kFloatRoundoff;
using test::small_options;

std::string read_bytes(const fs::path& p) {
  std::ifstream in(p, std::ios::binary);
  std::stringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

std::vector<fs::path> all_files(const fs::path& dir) {
  std::vector<fs::path> files;
  for (const auto& e : fs::recursive_directory_iterator(dir)) {
    if (e.is_regular_file()) files.push_back(fs::relative(e.path(), dir));
  }
  std::sort(files.begin(), files.end());
  return files;
}

// --- capture folders -----------------------------------------------------------------------

TEST(SynthCapture, ByteIdenticalWhateverTheThreadCountAndOnReRuns) {
  ptmkit::test::ScratchDir dir;
  SynthOptions o = small_options("default", 48);
  o.lights = "rings:25:5,60:3";
  {
    ThreadLimit limit(1);
    (void)render_capture(o, dir / "one");
  }
  {
    ThreadLimit limit(2);
    (void)render_capture(o, dir / "two");
    (void)render_capture(o, dir / "two");  // re-run over the same folder
  }
  const auto files = all_files(dir / "one");
  ASSERT_EQ(files, all_files(dir / "two"));
  ASSERT_GT(files.size(), 8u * 3u);
  for (const auto& f : files) {
    EXPECT_EQ(read_bytes(dir / "one" / f), read_bytes(dir / "two" / f)) << f;
  }
}

TEST(SynthCapture, DefaultPresetWritesTheDocumentedTruth) {
  ptmkit::test::ScratchDir dir;
  const SynthOptions o = preset_options("default");  // the full 256x256, 49 lights
  const auto start = std::chrono::steady_clock::now();
  const SynthReport report = render_capture(o, dir.path());
  const double seconds =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  RecordProperty("default_preset_seconds", std::to_string(seconds));
  EXPECT_EQ(report.images, 49);

  const LightSet lights = read_lp(dir / "lights.lp");
  ASSERT_EQ(lights.size(), 49u);
  EXPECT_EQ(lights.lights[0].image.filename(), "image_001.png");
  for (const auto& name :
       {"normals.exr", "normals.png", "albedo.exr", "albedo.png", "height.exr"}) {
    EXPECT_TRUE(fs::exists(dir.path() / "truth" / name)) << name;
  }
  const ImageInfo image = probe_image(dir / "image_049.png");
  EXPECT_EQ(image.width, 256);
  EXPECT_EQ(image.channels, 3);
  EXPECT_EQ(image.format, PixelFormat::kU8);
  EXPECT_EQ(image.colour_space, ColourSpace::kLinear);
  const ImageInfo labels = probe_image(dir.path() / "truth" / "labels" / "image_049.png");
  EXPECT_EQ(labels.channels, 1);
  EXPECT_EQ(labels.format, PixelFormat::kU8);
  EXPECT_EQ(probe_image(dir.path() / "truth" / "normals.png").format, PixelFormat::kU16);
  EXPECT_EQ(probe_image(dir.path() / "truth" / "diffuse" / "image_049.png").format,
            PixelFormat::kU8);

  // Files hold what the in-memory renderer gives.
  const Scene s = build_scene(o);
  const auto dirs = resolve_lights(o);
  const RenderedLight r = render_light(s, o, dirs[10], 10);
  const Image read = read_image(dir / "image_011.png");
  const Image read_diffuse = read_image(dir.path() / "truth" / "diffuse" / "image_011.png");
  const Image read_labels = read_image(dir.path() / "truth" / "labels" / "image_011.png");
  ASSERT_EQ(read.size(), r.observed.size());
  for (std::size_t i = 0; i < read.size(); ++i) {
    ASSERT_NEAR(read.data()[i], r.observed.data()[i], kFloatRoundoff);
    ASSERT_NEAR(read_diffuse.data()[i], r.diffuse.data()[i], kFloatRoundoff);
  }
  for (std::size_t i = 0; i < r.labels.size(); ++i) {
    ASSERT_EQ(std::lround(read_labels.data()[i] * 255.0f), r.labels[i]);
  }
  const Image normals = read_image(dir.path() / "truth" / "normals.exr");
  ASSERT_EQ(normals.channels(), 3);
  EXPECT_EQ(normals.at(17, 33, 2), s.normals.at(17, 33, 2));
  const Image height = read_image(dir.path() / "truth" / "height.exr");
  EXPECT_EQ(height.channels(), 1);
  EXPECT_EQ(height.at(100, 50, 0), s.height_at(100, 50));

  std::ifstream in(dir / "truth.json");
  const nlohmann::json j = nlohmann::json::parse(in);
  EXPECT_EQ(j["scene"], "relief");
  EXPECT_EQ(j["preset"], "default");
  EXPECT_EQ(j["seed"], o.seed);
  EXPECT_EQ(j["width"], 256);
  EXPECT_EQ(j["material"]["ks"], 0.3);
  EXPECT_EQ(j["material"]["exponent"], 40.0);
  EXPECT_EQ(j["sensor"]["bits"], 8);
  EXPECT_EQ(j["sensor"]["noise_sigma_grey"], 1.0);
  EXPECT_EQ(j["lights"]["count"], 49);
  ASSERT_EQ(j["images"].size(), 49u);
  EXPECT_EQ(j["images"][0]["file"], "image_001.png");
  EXPECT_EQ(j["images"][0]["labels"], "truth/labels/image_001.png");
  EXPECT_TRUE(j["labels"].contains("1"));
  EXPECT_TRUE(j["labels"].contains("2"));
}

TEST(SynthCapture, PolynomialPresetWritesItsCoefficients) {
  ptmkit::test::ScratchDir dir;
  SynthOptions o = small_options("polynomial", 24);
  o.lights = "rings:30:6,70:4";
  (void)render_capture(o, dir.path());
  const Image coeffs = read_image(dir.path() / "truth" / "coefficients.exr");
  ASSERT_EQ(coeffs.channels(), 18);
  const Scene s = build_scene(o);
  for (int y = 0; y < 24; y += 5) {
    for (int x = 0; x < 24; x += 5) {
      for (int k = 0; k < 18; ++k) {
        ASSERT_EQ(coeffs.at(x, y, k), s.coefficients.texel_coeffs(x, y)[k]);
      }
    }
  }
  const LightSet lights = read_lp(dir / "lights.lp");
  ASSERT_EQ(lights.size(), 10u);
  const Image img = read_image(lights.lights[3].image);
  EXPECT_EQ(lights.lights[3].image.extension(), ".exr");
  double rgb[3];
  const Eigen::Vector3d l = lights.lights[3].direction;
  evaluate_polynomial(s, 7, 9, l.x(), l.y(), rgb);
  // The .lp stores 9 significant digits of the direction: well inside float32 rounding.
  for (int c = 0; c < 3; ++c) EXPECT_NEAR(img.at(7, 9, c), rgb[c], kFloatRoundoff);
  EXPECT_FALSE(fs::exists(dir.path() / "truth" / "normals.exr"));
}

TEST(SynthCapture, JpegWithoutTruth) {
  ptmkit::test::ScratchDir dir;
  SynthOptions o = small_options("default", 40);
  o.sensor.file_type = FileType::kJpeg;
  o.cast_shadows = false;
  o.write_truth = false;
  o.lights = "rings:40:3";
  const SynthReport report = render_capture(o, dir.path());
  EXPECT_EQ(report.files.size(), 4u);
  EXPECT_EQ(
      ptmkit::test::list_files(dir.path()),
      (std::vector<std::string>{"image_001.jpg", "image_002.jpg", "image_003.jpg", "lights.lp"}));
}

}  // namespace
}  // namespace ptmkit::synth
