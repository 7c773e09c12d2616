// Helpers shared by the format tests (formats_*_test.cc): whole files as text, raw PTM 1.2
// files of random bytes, and relight / OpenLIME web folders of smooth plane images.
#pragma once

#include <algorithm>
#include <cstdint>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <random>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "ptmkit/core/image.h"
#include "ptmkit/core/image_io.h"
#include "ptmkit/texture/ptm.h"

namespace ptmkit::test {

inline std::string read_text(const std::filesystem::path& p) {
  std::ifstream in(p, std::ios::binary);
  return {std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
}

inline void write_text(const std::filesystem::path& p, const std::string& s) {
  std::ofstream out(p, std::ios::binary);
  out << s;
}

// A raw PTM 1.2 file with random bytes.
inline texture::PtmFile random_file(texture::PtmFormat format, int w, int h, std::uint64_t seed) {
  texture::PtmFile f;
  f.format = format;
  f.width = w;
  f.height = h;
  f.quantisation.scales = {1.5f, 1.25f, 1.0f, 0.75f, 0.5f, 2.0f};
  f.quantisation.biases = {128, 120, 100, 127, 127, 0};
  f.data.resize(f.texels() * static_cast<std::size_t>(format == texture::PtmFormat::kRGB ? 18 : 9));
  std::mt19937_64 rng(seed);
  // Smooth content (JPEG keeps it closely), plus a little noise.
  for (std::size_t i = 0; i < f.data.size(); ++i) {
    const double t = static_cast<double>(i % 977) / 977.0;
    f.data[i] = static_cast<std::uint8_t>(
        std::clamp(60.0 + 120.0 * t + static_cast<double>(rng() % 5), 0.0, 255.0));
  }
  return f;
}

// Writes plane images (nplanes / 3 JPEGs of w x h) as an `image` or `deepzoom` folder.
inline void write_web_folder(const std::filesystem::path& folder, const std::string& type,
                             const std::string& colorspace, const std::vector<Image>& jpegs,
                             const std::vector<double>& scale, const std::vector<double>& bias,
                             bool deepzoom, int tile = 16, int overlap = 1) {
  std::filesystem::create_directories(folder);
  const int w = jpegs[0].width(), h = jpegs[0].height();
  nlohmann::json j = {{"width", w},
                      {"height", h},
                      {"format", "jpg"},
                      {"type", type},
                      {"colorspace", colorspace},
                      {"nplanes", 3 * jpegs.size()},
                      {"quality", 100}};
  j["materials"] = {{{"scale", scale}, {"bias", bias}}};
  write_text(folder / "info.json", j.dump());
  ImageWriteOptions q;
  q.jpeg_quality = 100;
  for (std::size_t k = 0; k < jpegs.size(); ++k) {
    const std::string name = "plane_" + std::to_string(k);
    if (!deepzoom) {
      write_image(folder / (name + ".jpg"), jpegs[k].view(), q);
      continue;
    }
    write_text(folder / (name + ".dzi"),
               "<?xml version=\"1.0\" encoding=\"UTF-8\"?>\n<Image TileSize=\"" +
                   std::to_string(tile) + "\" Overlap=\"" + std::to_string(overlap) +
                   "\" Format=\"jpg\" xmlns=\"http://schemas.microsoft.com/deepzoom/2008\">"
                   "<Size Width=\"" +
                   std::to_string(w) + "\" Height=\"" + std::to_string(h) + "\"/></Image>\n");
    // Full resolution at level 3; a decoy lower level 1 that must not be used.
    for (const int level : {1, 3}) {
      const std::filesystem::path dirl = folder / (name + "_files") / std::to_string(level);
      std::filesystem::create_directories(dirl);
      if (level == 1) {
        write_image(dirl / "0_0.jpg", jpegs[k].view().crop(0, 0, 4, 4), q);
        continue;
      }
      const int cols = (w + tile - 1) / tile, rows = (h + tile - 1) / tile;
      for (int ty = 0; ty < rows; ++ty) {
        for (int tx = 0; tx < cols; ++tx) {
          const int x0 = std::max(0, tx * tile - overlap), y0 = std::max(0, ty * tile - overlap);
          const int x1 = std::min(w, (tx + 1) * tile + overlap);
          const int y1 = std::min(h, (ty + 1) * tile + overlap);
          write_image(dirl / (std::to_string(tx) + "_" + std::to_string(ty) + ".jpg"),
                      jpegs[k].view().crop(x0, y0, x1 - x0, y1 - y0), q);
        }
      }
    }
  }
}

// Plane images of smooth random-ish content (JPEG keeps it within a level or two).
inline std::vector<Image> smooth_planes(int count, int w, int h, std::uint64_t seed) {
  std::vector<Image> out;
  std::mt19937_64 rng(seed);
  for (int k = 0; k < count; ++k) {
    Image im(w, h, 3, ColourSpace::kSRGB);
    double f[3][3];
    for (auto& row : f)
      for (double& v : row) v = static_cast<double>(rng() % 1000) / 1000.0;
    for (int y = 0; y < h; ++y) {
      for (int x = 0; x < w; ++x) {
        for (int c = 0; c < 3; ++c) {
          im.at(x, y, c) = static_cast<float>(0.2 + 0.3 * f[c][0] + 0.25 * f[c][1] * x / w +
                                              0.2 * f[c][2] * y / h);
        }
      }
    }
    out.push_back(std::move(im));
  }
  return out;
}

}  // namespace ptmkit::test
