// The `relight` and `info` subcommands, end to end through the ptmkit binary.
#include <gtest/gtest.h>

#include <cmath>
#include <fstream>
#include <nlohmann/json.hpp>
#include <string>

#include "ptmkit/core/image_io.h"
#include "ptmkit/core/light_set.h"
#include "ptmkit/texture/ptm.h"
#include "ptmkit/texture/relight.h"
#include "test_util.h"
#include "tolerances.h"

namespace fs = std::filesystem;

namespace ptmkit::texture {
namespace {

using test::kFloatRoundoff;
using test::kHalf16BitStep;

// A .ptm (8-bit scale and bias) relit and saved as 8-bit against the float map: a few tenths
// of a grey level (measured 54.8 dB); 45 dB is 1.4 grey levels RMS.
constexpr double kQuantisedRelightPsnrDb = 45.0;

CoefficientMap cli_map(int w, int h) {
  CoefficientMap map(w, h, ColourModel::kRGB);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x)
      for (int p = 0; p < 3; ++p) {
        float* c = map.texel_coeffs(x, y) + p * kPtmTerms;
        c[0] = -0.1f;
        c[3] = 0.3f * static_cast<float>(x) / static_cast<float>(w);
        c[4] = 0.2f * static_cast<float>(y) / static_cast<float>(h) - 0.1f;
        c[5] = 0.4f + 0.1f * static_cast<float>(p);
      }
  return map;
}

TEST(TextureCli, InfoTextAndJson) {
  test::ScratchDir dir;
  const fs::path ptm = dir / "m.ptm";
  write_ptm(ptm, cli_map(12, 9));
  const auto text = test::run_ptmkit({"info", ptm.string()});
  ASSERT_EQ(text.exit_code, 0) << text.err;
  EXPECT_NE(text.out.find("PTM_FORMAT_RGB"), std::string::npos) << text.out;
  EXPECT_NE(text.out.find("12 x 9"), std::string::npos) << text.out;
  const auto json = test::run_ptmkit({"info", ptm.string(), "--json"});
  ASSERT_EQ(json.exit_code, 0) << json.err;
  const auto j = nlohmann::json::parse(json.out);
  EXPECT_EQ(j["width"], 12);
  EXPECT_EQ(j["height"], 9);
  EXPECT_EQ(j["scales"].size(), 6u);
  EXPECT_EQ(j["file_bytes_per_texel"], 18);
}

TEST(TextureCli, RelightOneLightMatchesTheLibrary) {
  test::ScratchDir dir;
  const fs::path ptm = dir / "m.ptm", png = dir / "lit.png";
  write_ptm(ptm, cli_map(16, 10));
  const auto r = test::run_ptmkit(
      {"relight", ptm.string(), "--light", "0.3,-0.2,0.9", "-o", png.string(), "--bits", "16"});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const Image got = read_image(png);
  const Image want = relight(read_ptm(ptm), {0.3, -0.2, 0.9});
  ASSERT_EQ(got.width(), 16);
  ASSERT_EQ(got.channels(), 3);
  double worst = 0.0;
  for (std::size_t k = 0; k < got.size(); ++k) {
    worst = std::max(worst, std::abs(static_cast<double>(got.data()[k] - want.data()[k])));
  }
  EXPECT_LE(worst, kHalf16BitStep + kFloatRoundoff);
}

TEST(TextureCli, RelightBelowHorizonIsBlackWithAWarning) {
  test::ScratchDir dir;
  const fs::path ptm = dir / "m.ptm", png = dir / "black.png";
  write_ptm(ptm, cli_map(8, 8));
  const auto r =
      test::run_ptmkit({"relight", ptm.string(), "--light", "1,0,-0.5", "-o", png.string()});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_NE(r.err.find("horizon"), std::string::npos) << r.err;
  const Image img = read_image(png);
  for (std::size_t k = 0; k < img.size(); ++k) EXPECT_EQ(img.data()[k], 0.0f);
}

TEST(TextureCli, RelightLightSetWritesImagesAndReport) {
  test::ScratchDir dir;
  const CoefficientMap map = cli_map(20, 12);
  const fs::path ptm = dir / "m.ptm";
  write_ptm(ptm, map);
  LightSet set;
  const Eigen::Vector3d dirs[2] = {Eigen::Vector3d(0, 0, 1), Eigen::Vector3d(0.4, 0.3, 0.866)};
  for (int i = 0; i < 2; ++i) {
    Light l;
    l.image = dir / "photos" / ("img" + std::to_string(i) + ".png");
    l.direction = dirs[i].normalized();
    set.lights.push_back(l);
  }
  fs::create_directories(dir / "photos");
  write_image(set.lights[0].image, relight(map, dirs[0]).view());  // only the first exists
  write_lp(dir / "photos" / "test.lp", set);
  const fs::path out = dir / "relit", report = dir / "report.json";
  const auto r =
      test::run_ptmkit({"relight", ptm.string(), "--lights", (dir / "photos" / "test.lp").string(),
                        "--out-dir", out.string(), "--report", report.string()});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_NE(r.out.find("mean PSNR"), std::string::npos) << r.out;
  EXPECT_EQ(test::list_files(out), (std::vector<std::string>{"img0.png", "img1.png"}));
  std::ifstream in(report);
  const auto j = nlohmann::json::parse(in);
  EXPECT_EQ(j["compared"], 1);
  EXPECT_EQ(j["lights"].size(), 2u);
  EXPECT_GT(j["mean_psnr_db"].get<double>(), kQuantisedRelightPsnrDb);
}

TEST(TextureCli, BadInputsExitOneNameTheFileAndLeaveNoOutput) {
  test::ScratchDir dir;
  const fs::path good = dir / "good.ptm", truncated = dir / "trunc.ptm";
  write_ptm(good, cli_map(6, 6));
  {
    const PtmFile f = read_ptm_file(good);
    std::ofstream o(truncated, std::ios::binary);
    o << f.canonical_header();
    o.write(reinterpret_cast<const char*>(f.data.data()), 10);
  }
  const fs::path out = dir / "out.png";
  struct Case {
    std::vector<std::string> args;
    std::string mentions;
  };
  const std::vector<Case> cases = {
      {{"relight", (dir / "missing.ptm").string(), "--light", "0,0,1", "-o", out.string()},
       (dir / "missing.ptm").string()},
      {{"relight", truncated.string(), "--light", "0,0,1", "-o", out.string()}, truncated.string()},
      {{"relight", good.string(), "--light", "nan,0,1", "-o", out.string()}, "--light"},
      {{"relight", good.string(), "--light", "0,0,0", "-o", out.string()}, "--light"},
      {{"relight", good.string(), "--light", "0,1", "-o", out.string()}, "--light"},
      {{"relight", good.string(), "--lights", (dir / "none.lp").string(), "--out-dir",
        (dir / "outdir").string()},
       (dir / "none.lp").string()},
      {{"info", truncated.string()}, truncated.string()},
      {{"info", (dir / "missing.ptm").string()}, (dir / "missing.ptm").string()},
  };
  for (const auto& c : cases) {
    SCOPED_TRACE(c.args[0] + " " + c.args[1] + " " + (c.args.size() > 3 ? c.args[3] : ""));
    const auto r = test::run_ptmkit(c.args);
    EXPECT_EQ(r.exit_code, 1) << r.err;
    EXPECT_NE(r.err.find(c.mentions), std::string::npos) << r.err;
  }
  EXPECT_EQ(test::list_files(dir.path()), (std::vector<std::string>{"good.ptm", "trunc.ptm"}));
  EXPECT_FALSE(fs::exists(dir / "outdir"));
}

}  // namespace
}  // namespace ptmkit::texture
