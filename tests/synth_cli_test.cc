// End-to-end tests of `ptmkit synth`.
#include <algorithm>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include "ptmkit/core/image_io.h"
#include "ptmkit/core/light_set.h"
#include "test_util.h"

namespace fs = std::filesystem;
using ptmkit::test::list_files;
using ptmkit::test::run_ptmkit;
using ptmkit::test::ScratchDir;

namespace {

std::string read_bytes(const fs::path& p) {
  std::ifstream in(p, std::ios::binary);
  std::stringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

TEST(SynthCli, WritesTheFolderAndSummarises) {
  ScratchDir dir;
  const fs::path out = dir / "cap";
  const auto r = run_ptmkit(
      {"synth", "--out", out.string(), "--size", "32", "--lights", "rings:40:5", "--seed", "7"});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_NE(r.out.find("wrote 5 images"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find(out.string()), std::string::npos) << r.out;
  EXPECT_EQ(list_files(out), (std::vector<std::string>{
                                 "image_001.png", "image_002.png", "image_003.png", "image_004.png",
                                 "image_005.png", "lights.lp", "truth.json"}));
  EXPECT_EQ(list_files(out / "truth" / "labels").size(), 5u);
  EXPECT_EQ(list_files(out / "truth" / "diffuse").size(), 5u);
  EXPECT_EQ(ptmkit::read_lp(out / "lights.lp").size(), 5u);
  std::ifstream in(out / "truth.json");
  const auto j = nlohmann::json::parse(in);
  EXPECT_EQ(j["seed"], 7);
  EXPECT_EQ(j["width"], 32);
}

TEST(SynthCli, FlagsOverrideThePreset) {
  ScratchDir dir;
  const fs::path out = dir / "cap";
  const auto r =
      run_ptmkit({"synth",      "--out",        out.string(), "--preset",   "glossy",
                  "--width",    "40",           "--height",   "24",         "--lights",
                  "rings:50:2", "--bits",       "16",         "--srgb",     "--noise",
                  "0",          "--ks",         "0.5",        "--exponent", "20",
                  "--ambient",  "0.05",         "--exposure", "0.8",        "--height-frac",
                  "0.05",       "--no-shadows", "--format",   "tif"});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const auto info = ptmkit::probe_image(out / "image_002.tif");
  EXPECT_EQ(info.width, 40);
  EXPECT_EQ(info.height, 24);
  EXPECT_EQ(info.format, ptmkit::PixelFormat::kU16);
  std::ifstream in(out / "truth.json");
  const auto j = nlohmann::json::parse(in);
  EXPECT_EQ(j["preset"], "glossy");
  EXPECT_EQ(j["material"]["ks"], 0.5);
  EXPECT_EQ(j["material"]["exponent"], 20.0);
  EXPECT_EQ(j["material"]["ambient"], 0.05);
  EXPECT_EQ(j["sensor"]["exposure"], 0.8);
  EXPECT_EQ(j["sensor"]["colour_space"], "srgb");
  EXPECT_EQ(j["sensor"]["noise_sigma_grey"], 0.0);
  EXPECT_EQ(j["relief"]["relief_height_frac"], 0.05);
  EXPECT_EQ(j["cast_shadows"], false);
}

TEST(SynthCli, PolynomialSceneAndFormatPicksTheDepth) {
  ScratchDir dir;
  const auto r = run_ptmkit({"synth", "--out", (dir / "p").string(), "--preset", "polynomial",
                             "--size", "16", "--lights", "icosa"});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_TRUE(fs::exists(dir / "p" / "truth" / "coefficients.exr"));
  EXPECT_EQ(ptmkit::read_lp(dir / "p" / "lights.lp").size(), 40u);
  const auto r2 = run_ptmkit({"synth", "--out", (dir / "e").string(), "--size", "16", "--format",
                              "exr", "--lights", "rings:30:2"});
  ASSERT_EQ(r2.exit_code, 0) << r2.err;
  EXPECT_EQ(ptmkit::probe_image(dir / "e" / "image_001.exr").format, ptmkit::PixelFormat::kF32);
}

TEST(SynthCli, SameFilesWhateverTheThreadCount) {
  ScratchDir dir;
  for (const std::string threads : {"1", "2"}) {
    const auto r = run_ptmkit({"synth", "--out", (dir / ("t" + threads)).string(), "--size", "40",
                               "--lights", "rings:20:3,60:2", "--threads", threads});
    ASSERT_EQ(r.exit_code, 0) << r.err;
  }
  const auto files = list_files(dir / "t1");
  ASSERT_EQ(files, list_files(dir / "t2"));
  for (const auto& f : files) {
    EXPECT_EQ(read_bytes(dir / "t1" / f), read_bytes(dir / "t2" / f)) << f;
  }
  for (const auto& f : list_files(dir / "t1" / "truth" / "labels")) {
    EXPECT_EQ(read_bytes(dir / "t1" / "truth" / "labels" / f),
              read_bytes(dir / "t2" / "truth" / "labels" / f));
  }
}

TEST(SynthCli, BadFlagsFailAndWriteNothing) {
  ScratchDir dir;
  const fs::path out = dir / "cap";
  const std::vector<std::vector<std::string>> bad = {
      {"--size", "4"},
      {"--bits", "12"},
      {"--preset", "shiny"},
      {"--lights", (dir / "missing.lp").string()},
      {"--lights", "rings:100:3"},
      {"--format", "jpg", "--bits", "16"},
      {"--noise", "-2"},
      {"--size", "abc"},
  };
  for (const auto& extra : bad) {
    std::vector<std::string> args = {"synth", "--out", out.string()};
    args.insert(args.end(), extra.begin(), extra.end());
    const auto r = run_ptmkit(args);
    EXPECT_NE(r.exit_code, 0) << extra[0] << " " << extra[1];
    EXPECT_FALSE(r.err.empty()) << extra[0];
    EXPECT_FALSE(fs::exists(out)) << extra[0] << " " << extra[1];
  }
  const auto missing_out = run_ptmkit({"synth", "--size", "16"});
  EXPECT_NE(missing_out.exit_code, 0);
}

TEST(SynthCli, HelpDescribesEveryFlag) {
  const auto r = run_ptmkit({"synth", "--help"});
  ASSERT_EQ(r.exit_code, 0);
  for (const auto* flag :
       {"--out", "--preset", "--scene", "--size", "--width", "--height", "--lights", "--seed",
        "--bits", "--format", "--srgb", "--noise", "--exposure", "--ks", "--exponent", "--ambient",
        "--height-frac", "--no-shadows"}) {
    EXPECT_NE(r.out.find(flag), std::string::npos) << flag;
  }
}

}  // namespace
