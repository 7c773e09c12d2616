// Real sample files (../shared/data/real-files; skipped when absent) relit against an
// evaluation written here from the formats' descriptions: a JPEG LRGB .ptm and an OpenLIME
// PTM folder.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <sstream>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "formats_test_util.h"
#include "ptmkit/core/image_io.h"
#include "ptmkit/texture/ptm.h"
#include "ptmkit/texture/relight.h"
#include "ptmkit/texture/texture_file.h"
#include "test_util.h"

namespace fs = std::filesystem;

namespace ptmkit::texture {
namespace {

using test::read_text;
using test::ScratchDir;
using test::write_text;

// The reader's float32 map relit against the evaluation here in double: rounding keeps them
// within one grey level anywhere and a hundredth of one on average (a misread plane or
// reference is tens of levels out).
constexpr double kMaxRelitGrey = 1.0;
constexpr double kMeanRelitGrey = 0.01;

std::vector<std::string> words(const std::string& line) {
  std::istringstream in(line);
  std::vector<std::string> out;
  std::string w;
  while (in >> w) out.push_back(w);
  return out;
}

TEST(RealFiles, JpegLrgbTabletRelitWithinOneGreyLevel) {
  const auto root = test::shared_data("real-files");
  if (!root || !fs::exists(*root / "tablet1.ptm")) {
    GTEST_SKIP() << "../shared/data/real-files/tablet1.ptm is absent";
  }
  const fs::path path = *root / "tablet1.ptm";
  const std::string file = read_text(path);
  // Header: one item list per line in this file.
  std::vector<std::string> lines;
  std::size_t pos = 0;
  for (int i = 0; i < 14; ++i) {
    const std::size_t end = file.find('\n', pos);
    lines.push_back(file.substr(pos, end - pos));
    pos = end + 1;
  }
  ASSERT_EQ(lines[1], "PTM_FORMAT_JPEG_LRGB");
  const int w = std::stoi(lines[2]), h = std::stoi(lines[3]);
  std::vector<double> scale, bias;
  for (const auto& s : words(lines[4])) scale.push_back(std::stod(s));
  for (const auto& s : words(lines[5])) bias.push_back(std::stod(s));
  std::vector<int> transform, order, ref;
  std::vector<std::size_t> size, side;
  for (const auto& s : words(lines[7])) transform.push_back(std::stoi(s));
  for (const auto& s : words(lines[10])) order.push_back(std::stoi(s));
  for (const auto& s : words(lines[11])) ref.push_back(std::stoi(s));
  for (const auto& s : words(lines[12])) size.push_back(std::stoul(s));
  for (const auto& s : words(lines[13])) side.push_back(std::stoul(s));
  // Each stream decoded by the image library into its own plane (JPEG rows bottom-up).
  ScratchDir dir;
  std::vector<std::vector<int>> plane(9);
  for (int k = 0; k < 9; ++k) {
    // Built with append: GCC 12 warns falsely (-Wrestrict) on "literal" + std::string.
    const fs::path jp = dir / std::string("p").append(std::to_string(k)).append(".jpg");
    write_text(jp, file.substr(pos, size[k]));
    pos += size[k] + side[k];
    ASSERT_EQ(side[k], 0u);  // this file has none
    const Image im = read_image(jp);
    for (int y = 0; y < h; ++y)
      for (int x = 0; x < w; ++x)
        plane[k].push_back(static_cast<int>(std::lround(im.at(x, y, 0) * 255.0)));
  }
  for (int rank = 0; rank < 9; ++rank) {
    const int k = static_cast<int>(std::find(order.begin(), order.end(), rank) - order.begin());
    if (ref[k] < 0) continue;
    for (std::size_t i = 0; i < plane[k].size(); ++i) {
      const int r = transform[k] & 1 ? 255 - plane[ref[k]][i] : plane[ref[k]][i];
      int v = plane[k][i] + r - 128;
      if (v < 0) v += 256;
      plane[k][i] = std::min(v, 255);
    }
  }
  const CoefficientMap map = read_ptm(path);
  for (const Eigen::Vector3d& light : {Eigen::Vector3d(0, 0, 1), Eigen::Vector3d(0.6, 0.2, 0.77),
                                       Eigen::Vector3d(-0.5, -0.5, 0.6)}) {
    const Eigen::Vector3d l = light.normalized();
    const Image relit = relight(map, l);
    double sum = 0, worst = 0;
    for (int y = 0; y < h; ++y) {
      for (int x = 0; x < w; ++x) {
        const std::size_t i = static_cast<std::size_t>(h - 1 - y) * w + x;  // stored row
        const double b[6] = {l.x() * l.x(), l.y() * l.y(), l.x() * l.y(), l.x(), l.y(), 1.0};
        double lum = 0;
        for (int t = 0; t < 6; ++t) lum += scale[t] * (plane[t][i] - bias[t]) * b[t];
        for (int c = 0; c < 3; ++c) {
          const double expect = std::clamp(lum / 255.0 * plane[6 + c][i] / 255.0, 0.0, 1.0);
          const double d = std::abs(expect - relit.at(x, y, c)) * 255.0;
          sum += d;
          worst = std::max(worst, d);
        }
      }
    }
    EXPECT_LE(worst, kMaxRelitGrey);
    EXPECT_LE(sum / (3.0 * w * h), kMeanRelitGrey);
  }
}

TEST(RealFiles, OpenlimePtmFolderRelitWithinOneGreyLevel) {
  const auto root = test::shared_data("real-files");
  if (!root || !fs::exists(*root / "openlime-ptm" / "info.json")) {
    GTEST_SKIP() << "../shared/data/real-files/openlime-ptm is absent";
  }
  const fs::path folder = *root / "openlime-ptm";
  const nlohmann::json j = nlohmann::json::parse(read_text(folder / "info.json"));
  ASSERT_EQ(j["type"], "ptm");
  ASSERT_EQ(j["colorspace"], "rgb");
  const std::vector<double> scale = j["materials"][0]["scale"];
  const std::vector<double> bias = j["materials"][0]["bias"];
  std::vector<Image> jpegs;
  for (int k = 0; k < 6; ++k)
    jpegs.push_back(read_image(folder / ("plane_" + std::to_string(k) + ".jpg")));
  const LoadedTexture tex = read_texture(folder);
  ASSERT_FALSE(tex.is_hsh);
  const int w = jpegs[0].width(), h = jpegs[0].height();
  for (const Eigen::Vector3d& light : {Eigen::Vector3d(0, 0, 1), Eigen::Vector3d(0.5, 0.3, 0.81),
                                       Eigen::Vector3d(-0.7, 0.1, 0.7)}) {
    const Eigen::Vector3d l = light.normalized();
    const Image relit = relight(tex.ptm, l);
    const double basis[6] = {1, l.x(), l.y(), l.x() * l.x(), l.x() * l.y(), l.y() * l.y()};
    double sum = 0, worst = 0;
    for (int y = 0; y < h; ++y) {
      for (int x = 0; x < w; ++x) {
        for (int c = 0; c < 3; ++c) {
          double v = 0;
          for (int t = 0; t < 6; ++t) {
            const int k = 3 * t + c;
            v += basis[t] * (jpegs[static_cast<std::size_t>(t)].at(x, y, c) - bias[k]) * scale[k];
          }
          const double d = std::abs(std::clamp(v, 0.0, 1.0) - relit.at(x, y, c)) * 255.0;
          sum += d;
          worst = std::max(worst, d);
        }
      }
    }
    EXPECT_LE(worst, kMaxRelitGrey);
    EXPECT_LE(sum / (3.0 * w * h), kMeanRelitGrey);
  }
}

}  // namespace
}  // namespace ptmkit::texture
