// The web export (texture/web_export.h): the folder's layout, info.json, the plane order and
// its scale and bias (read back here with OpenImageIO's JPEG reader, an independent decoder),
// the deep-zoom pyramid, atomicity and the errors; and the `export web` / `view` commands.
#include "ptmkit/texture/web_export.h"

#include <gtest/gtest.h>

#include <cmath>
#include <fstream>
#include <nlohmann/json.hpp>

#include "ptmkit/core/error.h"
#include "ptmkit/core/image_io.h"
#include "ptmkit/texture/ptm.h"
#include "test_util.h"
#include "tolerances.h"

namespace fs = std::filesystem;
using ptmkit::test::run_ptmkit;
using ptmkit::test::ScratchDir;

namespace ptmkit::texture {
namespace {

using test::kFloatRoundoff;
using test::kHalf8BitStep;

// A flat plane's 8-bit code after JPEG at quality 100, in levels: the texel that differs shares
// the 8x8 block of the texels read and rings into it by up to a level.
constexpr double kJpegQ100Levels = 1.0;
// A YCC map's planes summed at one light: these planes are flat, and a flat 8 x 8 block is
// its DC term alone, stored exactly at quality 100 (quantiser 1), so each plane comes back
// unchanged; half a level of the sum allows for its rounding (measured exact).
constexpr double kYccPlaneSumTol = 0.5 / 255.0;
// A deep-zoom tile of a varying plane at the default JPEG quality, in levels of the plane's
// scale: measured worst 5.6.
constexpr double kDeepZoomTileLevels = 12.0;

nlohmann::json read_json(const fs::path& p) {
  std::ifstream f(p);
  return nlohmann::json::parse(f);
}

// Plane k of a folder's image layout at texel (x, y), decoded with the format's formula.
double plane_value(const fs::path& dir, const nlohmann::json& info, int k, int x, int y) {
  const Image img = read_image(dir / ("plane_" + std::to_string(k / 3) + ".jpg"));
  const double byte = std::round(img.at(x, y, k % 3) * 255.0);
  const double scale = info["materials"][0]["scale"][k];
  const double bias = info["materials"][0]["bias"][k];
  return (byte / 255.0 - bias) * scale;
}

// An RGB map whose every coefficient is a distinct constant: each plane is flat, so JPEG
// codes it exactly and the plane order can be read back exactly.
CoefficientMap distinct_constant_map(ColourModel model) {
  CoefficientMap m(20, 12, model);
  for (int y = 0; y < m.height; ++y) {
    for (int x = 0; x < m.width; ++x) {
      float* a = m.texel_coeffs(x, y);
      for (int p = 0; p < m.polynomials(); ++p) {
        for (int t = 0; t < kPtmTerms; ++t)
          a[p * kPtmTerms + t] = 0.1f * static_cast<float>(t) + 0.01f * static_cast<float>(p);
      }
      float* c = m.texel_colour(x, y);
      for (int i = 0; i < m.colours(); ++i) c[i] = 0.2f + 0.3f * static_cast<float>(i);
    }
  }
  // One texel differs in every coefficient, so every plane has a range (min < max).
  float* a = m.texel_coeffs(0, 0);
  for (int i = 0; i < m.polynomials() * kPtmTerms; ++i) a[i] -= 0.5f;
  return m;
}

TEST(WebExport, DeepZoomLevelCountIsOpenLimes) {
  EXPECT_EQ(web_deepzoom_levels(256, 256, 256), 1);
  EXPECT_EQ(web_deepzoom_levels(100, 40, 256), 1);
  EXPECT_EQ(web_deepzoom_levels(257, 10, 256), 2);
  EXPECT_EQ(web_deepzoom_levels(1024, 1024, 256), 3);
  // Just above tile * 2^k: ceil(log2(1025 / 256)) + 1 = 4 (floor-halving to one tile gives 4
  // levels too but from a 1x1 start would count differently).
  EXPECT_EQ(web_deepzoom_levels(1025, 300, 256), 4);
  EXPECT_EQ(web_deepzoom_levels(300, 200, 64), 4);
}

TEST(WebExport, RgbPlanesInTheFormatsOrderWithScaleAndBias) {
  ScratchDir tmp;
  const CoefficientMap m = distinct_constant_map(ColourModel::kRGB);
  WebExportOptions o;
  o.quality = 100;
  o.pixel_size_mm = 0.02;
  const WebExportReport r = export_web(m, tmp / "out", o);
  EXPECT_EQ(r.planes, 18);
  EXPECT_EQ(r.jpegs, 6);
  const nlohmann::json info = read_json(tmp / "out" / "info.json");
  EXPECT_EQ(info["type"], "ptm");
  EXPECT_EQ(info["colorspace"], "rgb");
  EXPECT_EQ(info["nplanes"], 18);
  EXPECT_EQ(info["format"], "jpg");
  EXPECT_EQ(info["width"], 20);
  EXPECT_EQ(info["height"], 12);
  EXPECT_DOUBLE_EQ(info["pixelSizeInMM"].get<double>(), 0.02);
  ASSERT_EQ(info["materials"][0]["scale"].size(), 18u);
  for (const char* f : {"index.html", "viewer.js", "viewer.css", "plane_5.jpg"}) {
    EXPECT_TRUE(fs::exists(tmp / "out" / f)) << f;
  }
  EXPECT_FALSE(fs::exists(tmp / "out" / "plane_6.jpg"));
  // Web term j is the .ptm's a[{5, 3, 4, 0, 2, 1}[j]]; JPEG j holds it for R, G, B.
  const int ptm_index[6] = {5, 3, 4, 0, 2, 1};
  for (int j = 0; j < 6; ++j) {
    for (int c = 0; c < 3; ++c) {
      const double want = m.texel_coeffs(5, 7)[c * kPtmTerms + ptm_index[j]];
      const double scale = info["materials"][0]["scale"][3 * j + c];
      EXPECT_NEAR(plane_value(tmp / "out", info, 3 * j + c, 5, 7), want,
                  kJpegQ100Levels * scale / 255.0 + kFloatRoundoff)
          << "term " << j << " channel " << c;
    }
  }
}

TEST(WebExport, LrgbColourPlaneHasUnitScaleAndLuminanceTermsFollow) {
  ScratchDir tmp;
  const CoefficientMap m = distinct_constant_map(ColourModel::kLRGB);
  WebExportOptions o;
  o.quality = 100;
  const WebExportReport r = export_web(m, tmp / "out", o);
  EXPECT_EQ(r.planes, 9);
  const nlohmann::json info = read_json(tmp / "out" / "info.json");
  EXPECT_EQ(info["colorspace"], "lrgb");
  for (int c = 0; c < 3; ++c) {
    EXPECT_EQ(info["materials"][0]["scale"][c], 1.0);
    EXPECT_EQ(info["materials"][0]["bias"][c], 0.0);
    EXPECT_NEAR(plane_value(tmp / "out", info, c, 3, 3), m.texel_colour(3, 3)[c],
                kHalf8BitStep + kFloatRoundoff);
  }
  const int ptm_index[6] = {5, 3, 4, 0, 2, 1};
  for (int j = 0; j < 6; ++j) {
    const double scale = info["materials"][0]["scale"][3 + j];
    EXPECT_NEAR(plane_value(tmp / "out", info, 3 + j, 3, 3), m.texel_coeffs(3, 3)[ptm_index[j]],
                kJpegQ100Levels * scale / 255.0 + kFloatRoundoff);
  }
}

TEST(WebExport, YccMapIsExportedAsRgbWithTheSameColours) {
  ScratchDir tmp;
  const CoefficientMap m = distinct_constant_map(ColourModel::kYCC);
  WebExportOptions o;
  o.quality = 100;
  o.jpeg_colour = WebJpegColour::kNone;
  export_web(m, tmp / "out", o);
  const nlohmann::json info = read_json(tmp / "out" / "info.json");
  EXPECT_EQ(info["colorspace"], "rgb");
  // Evaluate both at one light: the polynomial of the planes equals the YCC evaluation.
  const double u = 0.3, v = -0.2;
  const double web_basis[6] = {1, u, v, u * u, u * v, v * v};
  float want[3];
  m.evaluate(4, 4, u, v, want);
  for (int c = 0; c < 3; ++c) {
    double got = 0;
    for (int j = 0; j < 6; ++j)
      got += web_basis[j] * plane_value(tmp / "out", info, 3 * j + c, 4, 4);
    EXPECT_NEAR(got, want[c], kYccPlaneSumTol) << "channel " << c;
  }
}

TEST(WebExport, HshPlanesAndDeepZoomPyramid) {
  ScratchDir tmp;
  CoefficientMap m({150, 70, Basis::kHsh3, ColourModel::kRGB, ColourSpace::kSRGB});
  for (std::size_t i = 0; i < m.coeffs.size(); ++i)
    m.coeffs[i] = static_cast<float>(std::sin(0.37 * static_cast<double>(i)));
  WebExportOptions o;
  o.layout = WebLayout::kDeepZoom;
  o.tile_size_px = 32;
  const WebExportReport r = export_web(m, tmp / "dz", o);
  EXPECT_EQ(r.planes, 27);
  EXPECT_EQ(r.jpegs, 9);
  const int levels = web_deepzoom_levels(150, 70, 32);  // ceil(log2(150 / 32)) + 1 = 4
  EXPECT_EQ(levels, 4);
  EXPECT_EQ(r.levels, levels);
  const nlohmann::json info = read_json(tmp / "dz" / "info.json");
  EXPECT_EQ(info["type"], "hsh");
  EXPECT_EQ(info["nplanes"], 27);
  EXPECT_EQ(info["ptmkit"]["layout"], "deepzoom");
  for (int j = 0; j < 9; ++j) {
    const fs::path files = tmp / "dz" / ("plane_" + std::to_string(j) + "_files");
    EXPECT_TRUE(fs::exists(tmp / "dz" / ("plane_" + std::to_string(j) + ".dzi")));
    for (int l = 0; l < levels; ++l) {
      // Level sizes halve with floor from the full size; tiles of 32 plus one pixel of overlap
      // on each inner side.
      const int lw = 150 >> (levels - 1 - l), lh = 70 >> (levels - 1 - l);
      const int nx = (lw + 31) / 32, ny = (lh + 31) / 32;
      EXPECT_EQ(ptmkit::test::list_files(files / std::to_string(l)).size(),
                static_cast<std::size_t>(nx * ny))
          << "plane " << j << " level " << l;
      if (j != 0) continue;
      for (int ty = 0; ty < ny; ++ty) {
        for (int tx = 0; tx < nx; ++tx) {
          const ImageInfo t = probe_image(files / std::to_string(l) /
                                          (std::to_string(tx) + "_" + std::to_string(ty) + ".jpg"));
          const int x0 = std::max(0, tx * 32 - 1), x1 = std::min((tx + 1) * 32 + 1, lw);
          const int y0 = std::max(0, ty * 32 - 1), y1 = std::min((ty + 1) * 32 + 1, lh);
          EXPECT_EQ(t.width, x1 - x0) << "level " << l << " tile " << tx << "_" << ty;
          EXPECT_EQ(t.height, y1 - y0) << "level " << l << " tile " << tx << "_" << ty;
        }
      }
    }
    EXPECT_FALSE(fs::exists(files / std::to_string(levels)));
  }
  // Finest level, tile (1, 1): its pixel (1, 1) (after the overlap) is texel (32, 32).
  const Image tile = read_image(tmp / "dz" / "plane_2_files" / "3" / "1_1.jpg");
  for (int c = 0; c < 3; ++c) {
    const int k = 6 + c;  // JPEG 2 holds HSH term 2 of R, G, B
    const double scale = info["materials"][0]["scale"][k], bias = info["materials"][0]["bias"][k];
    const double got = (std::round(tile.at(1, 1, c) * 255.0) / 255.0 - bias) * scale;
    EXPECT_NEAR(got, m.texel_coeffs(32, 32)[c * 9 + 2], kDeepZoomTileLevels / 255.0 * scale) << c;
  }
}

TEST(WebExport, FailuresLeaveNothingAndOtherFoldersAreNotReplaced) {
  ScratchDir tmp;
  CoefficientMap m = distinct_constant_map(ColourModel::kRGB);
  // A folder that is not an export is refused and left as it was.
  fs::create_directories(tmp / "mine");
  std::ofstream(tmp / "mine" / "notes.txt") << "keep";
  EXPECT_THROW((void)export_web(m, tmp / "mine"), Error);
  EXPECT_TRUE(fs::exists(tmp / "mine" / "notes.txt"));
  // A normal map of the wrong size: no folder, no temporary folder.
  Image n(5, 5, 3, ColourSpace::kLinear, 0.0f);
  write_image(tmp / "n.exr", n.view(), {.format = PixelFormat::kF32});
  WebExportOptions o;
  o.normals = tmp / "n.exr";
  EXPECT_THROW((void)export_web(m, tmp / "out", o), Error);
  // A non-finite coefficient.
  m.texel_coeffs(3, 3)[2] = std::nanf("");
  EXPECT_THROW((void)export_web(m, tmp / "out"), Error);
  EXPECT_FALSE(fs::exists(tmp / "out"));
  for (const auto& entry : fs::directory_iterator(tmp.path())) {
    EXPECT_EQ(entry.path().filename().string().find(".tmp-"), std::string::npos) << entry.path();
  }
  // Bad options.
  WebExportOptions bad;
  bad.quality = 0;
  m.texel_coeffs(3, 3)[2] = 0.0f;
  EXPECT_THROW((void)export_web(m, tmp / "out", bad), Error);
  bad = {};
  bad.tile_size_px = 4;
  EXPECT_THROW((void)export_web(m, tmp / "out", bad), Error);
}

TEST(WebExport, AnEarlierExportIsReplacedWhole) {
  ScratchDir tmp;
  const CoefficientMap m = distinct_constant_map(ColourModel::kRGB);
  WebExportOptions dz;
  dz.layout = WebLayout::kDeepZoom;
  dz.tile_size_px = 16;
  export_web(m, tmp / "out", dz);
  EXPECT_TRUE(fs::exists(tmp / "out" / "plane_0.dzi"));
  export_web(m, tmp / "out");
  EXPECT_FALSE(fs::exists(tmp / "out" / "plane_0.dzi"));
  EXPECT_FALSE(fs::exists(tmp / "out" / "plane_0_files"));
  EXPECT_TRUE(fs::exists(tmp / "out" / "plane_0.jpg"));
}

TEST(WebExport, NormalsAreWrittenAsEncodedPng) {
  ScratchDir tmp;
  const CoefficientMap m = distinct_constant_map(ColourModel::kRGB);
  Image n(m.width, m.height, 3, ColourSpace::kLinear, 0.0f);
  for (int y = 0; y < n.height(); ++y) {
    for (int x = 0; x < n.width(); ++x) {
      n.at(x, y, 0) = 0.6f;
      n.at(x, y, 1) = -0.48f;
      n.at(x, y, 2) = 0.64f;
    }
  }
  write_normal_map(tmp / "n.exr", n.view());
  WebExportOptions o;
  o.normals = tmp / "n.exr";
  const WebExportReport r = export_web(m, tmp / "out", o);
  EXPECT_TRUE(r.normals);
  const Image back = read_image(tmp / "out" / "normals.png");
  EXPECT_NEAR(back.at(7, 3, 0), 0.8, kHalf8BitStep + kFloatRoundoff);
  EXPECT_NEAR(back.at(7, 3, 1), 0.26, kHalf8BitStep + kFloatRoundoff);
  EXPECT_NEAR(back.at(7, 3, 2), 0.82, kHalf8BitStep + kFloatRoundoff);
  EXPECT_TRUE(read_json(tmp / "out" / "info.json")["ptmkit"]["normals"].get<bool>());
}

TEST(WebExportCli, ExportWebAndItsErrors) {
  ScratchDir tmp;
  const CoefficientMap m = distinct_constant_map(ColourModel::kLRGB);
  write_ptm(tmp / "t.ptm", m);
  auto r = run_ptmkit({"export", "web", (tmp / "t.ptm").string(), "-o", (tmp / "w").string(),
                       "--layout", "deepzoom", "--tile-size", "16"});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_NE(r.out.find("ptm lrgb"), std::string::npos) << r.out;
  EXPECT_TRUE(fs::exists(tmp / "w" / "plane_2.dzi"));
  r = run_ptmkit({"export", "web", (tmp / "missing.ptm").string(), "-o", (tmp / "x").string()});
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_NE(r.err.find("missing.ptm"), std::string::npos) << r.err;
  EXPECT_FALSE(fs::exists(tmp / "x"));
  r = run_ptmkit({"export", "web", (tmp / "t.ptm").string(), "-o", (tmp / "x").string(), "--layout",
                  "tarzoom"});
  EXPECT_EQ(r.exit_code, 2);
  r = run_ptmkit({"view", (tmp / "t.ptm").string(), "--port", "0", "--exit-after-seconds", "0.5"});
  EXPECT_EQ(r.exit_code, 0) << r.err;
  EXPECT_NE(r.out.find("http://127.0.0.1:"), std::string::npos) << r.out;
  r = run_ptmkit({"view", tmp.path().string(), "--port", "0", "--exit-after-seconds", "0.5"});
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_NE(r.err.find("info.json"), std::string::npos) << r.err;
}

}  // namespace
}  // namespace ptmkit::texture
