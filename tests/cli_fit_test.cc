// End-to-end tests of `ptmkit fit` through the binary: outputs, reports, determinism, and
// bad inputs (non-zero exit, a message naming the problem, no output file).
#include <fstream>
#include <random>

#include <gmock/gmock.h>
#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include "ptmkit/calib/dome.h"
#include "ptmkit/core/image_io.h"
#include "ptmkit/core/light_layout.h"
#include "ptmkit/core/light_set.h"
#include "ptmkit/texture/ptm.h"
#include "test_util.h"
#include "tolerances.h"

namespace fs = std::filesystem;
using ::testing::HasSubstr;

namespace ptmkit {
namespace {

std::string slurp(const fs::path& p) {
  std::ifstream f(p, std::ios::binary);
  return {std::istreambuf_iterator<char>(f), {}};
}

// A small capture: a smooth Lambertian-like texture under `dirs`, 8-bit PNG.
LightSet write_capture(const fs::path& dir, const std::vector<Eigen::Vector3d>& dirs, int w = 24,
                       int h = 16) {
  LightSet set;
  for (std::size_t i = 0; i < dirs.size(); ++i) {
    Image img(w, h, 3, ColourSpace::kSRGB);
    for (int y = 0; y < h; ++y)
      for (int x = 0; x < w; ++x) {
        const Eigen::Vector3d n =
            Eigen::Vector3d(0.3 * std::sin(0.2 * x), 0.3 * std::cos(0.3 * y), 1.0).normalized();
        const double shade = std::max(0.0, n.dot(dirs[i]));
        for (int c = 0; c < 3; ++c) img.at(x, y, c) = static_cast<float>(shade * (0.5 + 0.15 * c));
      }
    Light l;
    l.image = dir / ("img_" + std::to_string(i) + ".png");
    l.direction = dirs[i];
    write_image(l.image, img.view());
    set.lights.push_back(l);
  }
  write_lp(dir / "lights.lp", set);
  return set;
}

TEST(CliFit, FitsWritesAReportAndIsDeterministicAcrossThreads) {
  test::ScratchDir dir;
  write_capture(dir.path(), calib::layout_directions("dome49"));
  const auto r1 =
      test::run_ptmkit({"fit", (dir / "lights.lp").string(), "-o", (dir / "one.ptm").string(),
                        "--threads", "1", "--report", (dir / "fit.json").string()});
  ASSERT_EQ(r1.exit_code, 0) << r1.err;
  EXPECT_THAT(r1.out, HasSubstr("49 lights"));
  const auto r2 =
      test::run_ptmkit({"fit", (dir / "lights.lp").string(), "-o", (dir / "two.ptm").string(),
                        "--threads", "2", "--band-rows", "3"});
  ASSERT_EQ(r2.exit_code, 0) << r2.err;
  EXPECT_EQ(slurp(dir / "one.ptm"), slurp(dir / "two.ptm"));
  const auto report = nlohmann::json::parse(slurp(dir / "fit.json"));
  EXPECT_EQ(report["lights"], 49);
  EXPECT_NEAR(report["design"]["condition_number"].get<double>(), test::kDome49Condition,
              test::kDome49ConditionTol);
  EXPECT_GT(report["residuals_grey"]["rms"].get<double>(), 0.0);
  const texture::PtmInfo info = texture::read_ptm_info(dir / "one.ptm");
  EXPECT_EQ(info.width, 24);
  EXPECT_EQ(info.height, 16);
  EXPECT_EQ(info.format, texture::PtmFormat::kRGB);
  for (const char* format : {"lrgb", "ycc"}) {
    const auto r =
        test::run_ptmkit({"fit", (dir / "lights.lp").string(), "-o",
                          (dir / (std::string(format) + ".ptm")).string(), "--format", format});
    EXPECT_EQ(r.exit_code, 0) << r.err;
  }
  EXPECT_EQ(texture::read_ptm_info(dir / "lrgb.ptm").format, texture::PtmFormat::kLRGB);
}

struct BadCase {
  std::string name;
  std::string expected_message;
};

// Runs fit on dir/lights.lp and expects exit 1, the message, and no output or temp file.
void expect_refusal(const test::ScratchDir& dir, const std::string& lp, const std::string& what) {
  const auto before = test::list_files(dir.path());
  const auto r = test::run_ptmkit({"fit", (dir / lp).string(), "-o", (dir / "out.ptm").string(),
                                   "--report", (dir / "out.json").string()});
  EXPECT_EQ(r.exit_code, 1) << lp;
  EXPECT_THAT(r.err, HasSubstr(what)) << lp;
  EXPECT_FALSE(fs::exists(dir / "out.ptm")) << lp;
  EXPECT_FALSE(fs::exists(dir / "out.json")) << lp;
  EXPECT_EQ(test::list_files(dir.path()), before) << "stray files after " << lp;
}

TEST(CliFit, BadInputsExitNonZeroNameTheProblemAndWriteNothing) {
  test::ScratchDir dir;
  const LightSet set = write_capture(dir.path(), calib::layout_directions("dome49"), 12, 8);
  auto write_variant = [&](const std::string& name, LightSet s) { write_lp(dir / name, s); };

  LightSet missing = set;
  missing.lights[5].image = dir / "no_such_image.png";
  write_variant("missing.lp", missing);
  expect_refusal(dir, "missing.lp", "no_such_image.png");

  write_image(dir / "small.png", Image(11, 8, 3).view());
  LightSet mismatch = set;
  mismatch.lights[3].image = dir / "small.png";
  write_variant("mismatch.lp", mismatch);
  expect_refusal(dir, "mismatch.lp", "small.png");

  LightSet few = set;
  few.lights.resize(5);
  write_variant("few.lp", few);
  expect_refusal(dir, "few.lp", "at least 6 lights");

  LightSet ring = set;
  ring.lights.resize(12);
  const auto ring_dirs = ring_layout(parse_rings("35:12"));
  for (int i = 0; i < 12; ++i) ring.lights[i].direction = ring_dirs[i];
  write_variant("ring.lp", ring);
  expect_refusal(dir, "ring.lp", "same elevation");

  {
    std::ofstream f(dir / "nan.lp");
    f << "2\nimg_0.png 0 0 1\nimg_1.png 0.2 nan 0.9\n";
  }
  expect_refusal(dir, "nan.lp", "nan.lp:3");
  expect_refusal(dir, "absent.lp", "absent.lp");

  {
    std::ofstream f(dir / "corrupt.png");
    f << "\x89PNG\r\n\x1a\n garbage";
  }
  LightSet corrupt = set;
  corrupt.lights[9].image = dir / "corrupt.png";
  write_variant("corrupt.lp", corrupt);
  expect_refusal(dir, "corrupt.lp", "corrupt.png");

  // A bad command line is exit code 2.
  EXPECT_EQ(test::run_ptmkit({"fit"}).exit_code, 2);
  EXPECT_EQ(test::run_ptmkit({"fit", (dir / "lights.lp").string(), "-o", (dir / "x.ptm").string(),
                              "--format", "cmyk"})
                .exit_code,
            2);
}

TEST(CliFit, RidgeFitsASingleRingWhenAsked) {
  test::ScratchDir dir;
  write_capture(dir.path(), ring_layout(parse_rings("35:12")), 8, 8);
  const auto r =
      test::run_ptmkit({"fit", (dir / "lights.lp").string(), "-o", (dir / "ring.ptm").string(),
                        "--ridge", "1e-3", "--report", (dir / "r.json").string()});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const auto report = nlohmann::json::parse(slurp(dir / "r.json"));
  EXPECT_TRUE(report["design"]["regularised"].get<bool>());
  EXPECT_TRUE(report["design"]["single_ring"].get<bool>());
}

// A capture with no more lights than a robust texel keeps (12, as photometric-stereo sets
// have) cannot reject a sample: the command says so and names the flag; --min-inliers lowers
// the floor, and a floor below the polynomial's 6 terms is refused as a bad command line.
TEST(CliFit, RobustSolverSaysWhenTooFewLightsLeaveNothingToReject) {
  test::ScratchDir dir;
  write_capture(dir.path(), ring_layout(parse_rings("30:6,60:6")), 8, 8);
  const auto lp = (dir / "lights.lp").string();
  const auto r = test::run_ptmkit(
      {"fit", lp, "-o", (dir / "a.ptm").string(), "--solver", "robust", "--threads", "1"});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_NE(r.out.find("12 lights and at least 12 inliers"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("--min-inliers"), std::string::npos) << r.out;
  const auto lowered = test::run_ptmkit({"fit", lp, "-o", (dir / "b.ptm").string(), "--solver",
                                         "robust", "--min-inliers", "8", "--threads", "1",
                                         "--report", (dir / "b.json").string()});
  ASSERT_EQ(lowered.exit_code, 0) << lowered.err;
  EXPECT_EQ(lowered.out.find("nothing to reject"), std::string::npos) << lowered.out;
  // The report says which thresholds were in force: 8-bit files keep the floor of 2 grey levels.
  const auto report = nlohmann::json::parse(slurp(dir / "b.json"));
  EXPECT_EQ(report["robust_options"]["min_inliers"].get<int>(), 8);
  EXPECT_DOUBLE_EQ(report["robust_options"]["min_scale_grey"].get<double>(), 2.0);
  const auto plain = test::run_ptmkit({"fit", lp, "-o", (dir / "c.ptm").string()});
  ASSERT_EQ(plain.exit_code, 0) << plain.err;
  EXPECT_EQ(plain.out.find("nothing to reject"), std::string::npos) << plain.out;
  const auto bad = test::run_ptmkit(
      {"fit", lp, "-o", (dir / "d.ptm").string(), "--solver", "robust", "--min-inliers", "5"});
  EXPECT_EQ(bad.exit_code, 2);
  EXPECT_NE(bad.err.find("--min-inliers"), std::string::npos) << bad.err;
  EXPECT_FALSE(fs::exists(dir / "d.ptm"));
}

}  // namespace
}  // namespace ptmkit
