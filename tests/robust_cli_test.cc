// `ptmkit fit` robust outputs: per-sample label dump and albedo.
#include <cmath>
#include <filesystem>
#include <string>

#include <gtest/gtest.h>

#include "ptmkit/core/image_io.h"
#include "ptmkit/synth/synth.h"
#include "test_util.h"

namespace fs = std::filesystem;

namespace ptmkit {
namespace {

using test::list_files;
using test::run_ptmkit;
using test::ScratchDir;

// The relief's albedo is 0.3-0.9 per channel (synth.h); the Lambertian estimate from the
// inliers lands within 0.05 of that range, up to noise and model error ...
constexpr float kAlbedoLow = 0.25f;
constexpr float kAlbedoHigh = 0.95f;
// ... at nine texels in ten or more (measured 1023 of 1024).
constexpr int kInRangeTenths = 9;

TEST(RobustCli, WritesLabelDumpAndAlbedo) {
  ScratchDir dir;
  synth::SynthOptions o = synth::preset_options("default");
  o.width = 32;
  o.height = 32;
  const auto cap = synth::render_capture(o, dir / "cap");
  const fs::path labels = dir / "labels";
  const auto r = run_ptmkit({"fit", cap.lp_file.string(), "-o", (dir / "out.ptm").string(),
                             "--solver", "robust", "--labels", labels.string(), "--albedo",
                             (dir / "albedo.exr").string()});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const auto files = list_files(labels);
  ASSERT_EQ(files.size(), 49u);
  EXPECT_EQ(files.front(), "image_001.png");
  // Codes are 0/1/2 and, on a relief with cast shadows and highlights, some of each occur
  // across the lights.
  int counts[3] = {0, 0, 0};
  for (const auto& f : files) {
    const Image lab = read_image(labels / f);
    ASSERT_EQ(lab.channels(), 1);
    for (int y = 0; y < lab.height(); ++y) {
      for (int x = 0; x < lab.width(); ++x) {
        const int code = static_cast<int>(std::lround(lab.at(x, y, 0) * 255.0f));
        ASSERT_GE(code, 0);
        ASSERT_LE(code, 2);
        ++counts[code];
      }
    }
  }
  EXPECT_GT(counts[0], counts[1] + counts[2]);
  EXPECT_GT(counts[1], 0);
  EXPECT_GT(counts[2], 0);
  const Image albedo = read_image(dir / "albedo.exr");
  ASSERT_EQ(albedo.channels(), 3);
  int in_range = 0;
  for (int y = 0; y < albedo.height(); ++y)
    for (int x = 0; x < albedo.width(); ++x)
      in_range += albedo.at(x, y, 1) > kAlbedoLow && albedo.at(x, y, 1) < kAlbedoHigh ? 1 : 0;
  EXPECT_GT(in_range, 32 * 32 * kInRangeTenths / 10);
}

TEST(RobustCli, LabelsMustBeAFolder) {
  ScratchDir dir;
  synth::SynthOptions o = synth::preset_options("default");
  o.width = 16;
  o.height = 16;
  o.lights = "rings:30:6,60:4";
  const auto cap = synth::render_capture(o, dir / "cap");
  const auto r = run_ptmkit({"fit", cap.lp_file.string(), "-o", (dir / "out.ptm").string(),
                             "--labels", cap.lp_file.string()});
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_NE(r.err.find("must be a folder"), std::string::npos) << r.err;
  EXPECT_FALSE(fs::exists(dir / "out.ptm"));
}

}  // namespace
}  // namespace ptmkit
