// Reading relight / OpenLIME web folders: image and deep-zoom layouts give the same
// coefficients, LRGB is colour times luminance, HSH folders read as HSH maps (and convert to
// .rti), and malformed folders are clear errors.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <string>
#include <utility>
#include <vector>

#include <nlohmann/json.hpp>

#include "formats_test_util.h"
#include "ptmkit/core/error.h"
#include "ptmkit/core/image_io.h"
#include "ptmkit/texture/convert.h"
#include "ptmkit/texture/rti.h"
#include "ptmkit/texture/texture_file.h"
#include "ptmkit/texture/web_folder.h"
#include "test_util.h"

namespace fs = std::filesystem;

namespace ptmkit::texture {
namespace {

using test::read_text;
using test::ScratchDir;
using test::smooth_planes;
using test::write_text;
using test::write_web_folder;

// JPEG at quality 100 with chroma subsampling on smooth planes: a few levels at most.
constexpr double kMaxJpegPlaneGrey = 4.0;
// Coefficients (byte - bias) x scale of magnitude up to ~1.5 held in float32 (rounding ~1e-7),
// with room: the same bytes read through another layout or reader.
constexpr double kCoeffFloatTol = 1e-5;
// LRGB colour x luminance evaluated in float32 against double: a hundredth of a grey level.
constexpr double kLrgbEvaluationGrey = 0.01;
// Half a step of the .rti's 8-bit range, which is wider.
constexpr double kRtiHalfStep = 0.8 * 2.0 / 255.0;

TEST(WebFolder, PtmRgbImageAndDeepzoomReadTheSameCoefficients) {
  ScratchDir dir;
  const int w = 40, h = 27;
  const std::vector<Image> planes = smooth_planes(6, w, h, test::test_seed());
  std::vector<double> scale(18), bias(18);
  for (int k = 0; k < 18; ++k) {
    scale[k] = 0.5 + 0.05 * k;
    bias[k] = k % 2 ? 0.4 : -0.1;
  }
  write_web_folder(dir / "image", "ptm", "rgb", planes, scale, bias, false);
  write_web_folder(dir / "dz", "ptm", "rgb", planes, scale, bias, true);
  const WebTexture a = read_web_folder(dir / "image");
  const WebTexture b = read_web_folder(dir / "dz" / "info.json");
  EXPECT_EQ(a.info.layout, "image");
  EXPECT_EQ(b.info.layout, "deepzoom");
  ASSERT_FALSE(a.is_hsh);
  ASSERT_EQ(a.ptm.model, ColourModel::kRGB);
  // Web basis order 1, u, v, u^2, uv, v^2 against .ptm order u^2, v^2, uv, u, v, 1.
  const int web_of[6] = {3, 5, 4, 1, 2, 0};
  double worst_a = 0, worst_b = 0;
  for (int y = 0; y < h; ++y) {
    for (int x = 0; x < w; ++x) {
      for (int c = 0; c < 3; ++c) {
        for (int t = 0; t < 6; ++t) {
          const int k = 3 * web_of[t] + c;
          const double byte = planes[static_cast<std::size_t>(k / 3)].at(x, y, k % 3);
          const double expect = (byte - bias[k]) * scale[k];
          const double got = a.ptm.texel_coeffs(x, y)[c * 6 + t];
          worst_a = std::max(worst_a, std::abs(got - expect) / scale[k]);
        }
      }
    }
  }
  EXPECT_LE(worst_a * 255.0, kMaxJpegPlaneGrey);
  // Deep zoom: against the level-3 tiles decoded by the image library and placed by the
  // descriptor's rule (tile (i, j) starts at i * 16 - 1 except on the first row and column;
  // the grey checkerboard makes a one-pixel misplacement 38 levels out).
  for (int k = 0; k < 18; ++k) {
    const int j = k / 3;
    for (int ty = 0; ty * 16 < h; ++ty) {
      for (int tx = 0; tx * 16 < w; ++tx) {
        const Image tile = read_image(dir / "dz" / ("plane_" + std::to_string(j) + "_files") / "3" /
                                      (std::to_string(tx) + "_" + std::to_string(ty) + ".jpg"));
        const int ox = tx > 0 ? 1 : 0, oy = ty > 0 ? 1 : 0;
        for (int y = ty * 16; y < std::min(h, ty * 16 + 16); ++y) {
          for (int x = tx * 16; x < std::min(w, tx * 16 + 16); ++x) {
            const double byte = tile.at(x - tx * 16 + ox, y - ty * 16 + oy, k % 3);
            const double expect = (byte - bias[k]) * scale[k];
            const int c = k % 3;
            const int t = static_cast<int>(std::find(web_of, web_of + 6, j) - web_of);
            worst_b = std::max(worst_b, std::abs(b.ptm.texel_coeffs(x, y)[c * 6 + t] - expect));
          }
        }
      }
    }
  }
  EXPECT_LE(worst_b, kCoeffFloatTol);
}

TEST(WebFolder, LrgbIsColourTimesLuminance) {
  ScratchDir dir;
  const int w = 20, h = 12;
  const std::vector<Image> planes = smooth_planes(3, w, h, test::test_seed());
  std::vector<double> scale(9, 1.0), bias(9, 0.0);
  for (int k = 3; k < 9; ++k) {
    scale[k] = 1.5;
    bias[k] = 0.3;
  }
  write_web_folder(dir / "l", "ptm", "lrgb", planes, scale, bias, false);
  const WebTexture t = read_web_folder(dir / "l");
  ASSERT_EQ(t.ptm.model, ColourModel::kLRGB);
  // Independent: read the JPEGs back, evaluate colour * sum(coef * basis) at one light.
  std::vector<Image> decoded;
  for (int j = 0; j < 3; ++j)
    decoded.push_back(read_image(dir / "l" / ("plane_" + std::to_string(j) + ".jpg")));
  const double u = 0.3, v = -0.2;
  const double basis[6] = {1, u, v, u * u, u * v, v * v};
  double worst = 0;
  for (int y = 0; y < h; ++y) {
    for (int x = 0; x < w; ++x) {
      double l = 0;
      for (int k = 0; k < 6; ++k) {
        const int p = 3 + k;
        l += basis[k] * (decoded[static_cast<std::size_t>(p / 3)].at(x, y, p % 3) - bias[p]) *
             scale[p];
      }
      float rgb[3];
      t.ptm.evaluate(x, y, u, v, rgb);
      for (int c = 0; c < 3; ++c) {
        worst = std::max(worst, std::abs(rgb[c] - decoded[0].at(x, y, c) * l));
      }
    }
  }
  EXPECT_LE(worst * 255.0, kLrgbEvaluationGrey);
}

TEST(WebFolder, HshFolderReadsAsAnHshMapAndConvertsToRti) {
  ScratchDir dir;
  const int w = 18, h = 10;
  const std::vector<Image> planes = smooth_planes(9, w, h, test::test_seed());
  std::vector<double> scale(27, 0.8), bias(27, 0.5);
  write_web_folder(dir / "hsh", "hsh", "rgb", planes, scale, bias, false);
  const WebTexture t = read_web_folder(dir / "hsh");
  ASSERT_TRUE(t.is_hsh);
  ASSERT_EQ(t.hsh.terms(), 9);
  std::vector<Image> decoded;
  for (int j = 0; j < 9; ++j)
    decoded.push_back(read_image(dir / "hsh" / ("plane_" + std::to_string(j) + ".jpg")));
  for (int c = 0; c < 3; ++c) {
    for (int k = 0; k < 9; ++k) {
      const double expect = (decoded[static_cast<std::size_t>(k)].at(4, 7, c) - 0.5) * 0.8;
      EXPECT_NEAR(t.hsh.texel_coeffs(4, 7)[c * 9 + k], expect, kCoeffFloatTol);
    }
  }
  ConvertOptions o;
  const ConvertReport r = convert_to_rti(dir / "hsh", dir / "out.rti", o);
  EXPECT_EQ(r.from, "web folder hsh rgb image");
  const CoefficientMap back = read_rti(dir / "out.rti");
  double worst = 0;
  for (std::size_t i = 0; i < back.coeffs.size(); ++i) {
    worst = std::max(worst, static_cast<double>(std::abs(back.coeffs[i] - t.hsh.coeffs[i])));
  }
  EXPECT_LE(worst, kRtiHalfStep);
  EXPECT_THROW((void)convert_to_ptm(dir / "hsh", dir / "x.ptm", o), Error);
  EXPECT_FALSE(fs::exists(dir / "x.ptm"));
}

TEST(WebFolder, MalformedFoldersAreClearErrors) {
  ScratchDir dir;
  const std::vector<Image> planes = smooth_planes(6, 20, 10, 1);
  std::vector<double> scale(18, 1.0), bias(18, 0.0);
  write_web_folder(dir / "ok", "ptm", "rgb", planes, scale, bias, false);
  // A missing plane, a plane of the wrong size, a corrupt plane, short scale arrays, bad JSON.
  fs::copy(dir / "ok", dir / "missing", fs::copy_options::recursive);
  fs::remove(dir / "missing" / "plane_4.jpg");
  fs::copy(dir / "ok", dir / "size", fs::copy_options::recursive);
  write_image(dir / "size" / "plane_2.jpg", planes[0].view().crop(0, 0, 10, 10));
  fs::copy(dir / "ok", dir / "corrupt", fs::copy_options::recursive);
  {
    std::string b = read_text(dir / "corrupt" / "plane_1.jpg");
    write_text(dir / "corrupt" / "plane_1.jpg", b.substr(0, b.size() / 2));
  }
  fs::copy(dir / "ok", dir / "short", fs::copy_options::recursive);
  {
    nlohmann::json j = nlohmann::json::parse(read_text(dir / "ok" / "info.json"));
    j["materials"][0]["scale"] = std::vector<double>(17, 1.0);
    write_text(dir / "short" / "info.json", j.dump());
  }
  fs::copy(dir / "ok", dir / "json", fs::copy_options::recursive);
  write_text(dir / "json" / "info.json", "{\"width\": 20,");
  const std::vector<std::pair<std::string, std::string>> cases = {
      {"missing", "plane_4.jpg: missing"}, {"size", "10 x 10 JPEG where 20 x 10"},
      {"corrupt", "plane_1.jpg"},          {"short", "must list 18 numbers"},
      {"json", "not valid JSON"},
  };
  for (const auto& [name, expect] : cases) {
    try {
      (void)read_texture(dir / name);
      ADD_FAILURE() << name << " was accepted";
    } catch (const Error& e) {
      EXPECT_NE(std::string(e.what()).find(expect), std::string::npos) << e.what();
    }
  }
}

}  // namespace
}  // namespace ptmkit::texture
