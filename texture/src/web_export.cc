// Export to the relight/OpenLIME web folder (texture/web_export.h): the names, and the folder
// (checks, plane files or deep-zoom pyramids, normals, info.json) built aside and renamed in.
#include "ptmkit/texture/web_export.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <fstream>
#include <nlohmann/json.hpp>
#include <sstream>

#include "ptmkit/core/atomic_file.h"
#include "ptmkit/core/error.h"
#include "ptmkit/core/image_io.h"
#include "web_export_detail.h"

namespace fs = std::filesystem;

namespace ptmkit::texture {

using internal::decode_jpeg;
using internal::encode_jpeg;
using internal::half;
using internal::hsh_planes_of;
using internal::Level;
using internal::plane_ranges;
using internal::planes_of;
using internal::PlaneSource;
using internal::quantise_region;
using internal::Quantiser;

std::string to_string(WebLayout layout) {
  return layout == WebLayout::kDeepZoom ? "deepzoom" : "image";
}

WebLayout parse_web_layout(const std::string& name) {
  if (name == "image") return WebLayout::kImage;
  if (name == "deepzoom") return WebLayout::kDeepZoom;
  throw Error("web layout '" + name + "': expected image or deepzoom");
}

std::string to_string(WebJpegColour colour) {
  switch (colour) {
    case WebJpegColour::kYCbCr:
      return "ycbcr";
    case WebJpegColour::kNone:
      return "none";
    case WebJpegColour::kAuto:
      break;
  }
  return "auto";
}

WebJpegColour parse_web_jpeg_colour(const std::string& name) {
  if (name == "auto") return WebJpegColour::kAuto;
  if (name == "ycbcr") return WebJpegColour::kYCbCr;
  if (name == "none") return WebJpegColour::kNone;
  throw Error("JPEG colour transform '" + name + "': expected auto, ycbcr or none");
}

int web_deepzoom_levels(int width, int height, int tile_size_px) {
  const double ratio = static_cast<double>(std::max(width, height)) / tile_size_px;
  if (ratio <= 1.0) return 1;
  return static_cast<int>(std::ceil(std::log2(ratio))) + 1;
}

std::string WebExportReport::brief() const {
  std::ostringstream s;
  s << type << " " << colorspace << ", " << width << " x " << height << ", " << planes
    << " planes in " << jpegs << " JPEGs";
  if (levels > 1) s << ", " << levels << " deep-zoom levels";
  s << ", " << files << " files, " << bytes / 1024 << " KiB";
  s.setf(std::ios::fixed);
  s.precision(2);
  s << "; JPEG error per plane byte: mean " << jpeg_mean_abs_byte << ", max " << jpeg_max_abs_byte;
  if (normals) s << "; normals.png";
  return s.str();
}

namespace {

// --- the folder ------------------------------------------------------------------------

struct Writer {
  fs::path root;
  std::size_t files = 0;
  std::size_t bytes = 0;
  void write(const fs::path& rel, std::string_view data) {
    const fs::path p = root / rel;
    std::ofstream f(p, std::ios::binary);
    f.write(data.data(), static_cast<std::streamsize>(data.size()));
    f.close();
    if (!f) throw Error(where(p) + ": write failed");
    ++files;
    bytes += data.size();
  }
};

std::string number_text(double v) {
  std::ostringstream s;
  s.precision(9);
  s << v;
  return s.str();
}

WebExportReport export_planes(const PlaneSource& src, const fs::path& dir,
                              const WebExportOptions& options) {
  if (dir.empty()) throw Error("web export: no output folder given");
  if (options.quality < 1 || options.quality > 100) {
    throw Error("web export: JPEG quality " + std::to_string(options.quality) +
                " is outside 1..100");
  }
  if (options.tile_size_px < 16 || options.tile_size_px > 4096) {
    throw Error("web export: tile size " + std::to_string(options.tile_size_px) +
                " px is outside 16..4096");
  }
  if (!std::isfinite(options.pixel_size_mm) || options.pixel_size_mm < 0.0) {
    throw Error("web export: pixel size must be a finite number >= 0 (0 = unknown)");
  }
  std::error_code ec;
  if (fs::exists(dir, ec)) {
    if (!fs::is_directory(dir, ec)) throw Error(where(dir) + ": exists and is not a folder");
    const bool empty = fs::is_empty(dir, ec);
    const bool is_export = fs::exists(dir / "info.json", ec);
    if (!empty && !is_export) {
      throw Error(where(dir) +
                  ": exists and does not hold a web export (no info.json); not replaced");
    }
    if (!empty && !options.overwrite) throw Error(where(dir) + ": exists");
  }
  const fs::path parent = dir.has_parent_path() ? dir.parent_path() : fs::path(".");
  if (!fs::is_directory(parent, ec)) ensure_directory(parent);

  // Normals first: a bad normal map fails before any work.
  Image normals;
  if (!options.normals.empty()) {
    normals = read_normal_map(options.normals);
    if (normals.width() != src.width || normals.height() != src.height || normals.channels() < 3) {
      throw Error(where(options.normals) + ": normal map is " + std::to_string(normals.width()) +
                  " x " + std::to_string(normals.height()) + " with " +
                  std::to_string(normals.channels()) + " channels; the texture is " +
                  std::to_string(src.width) + " x " + std::to_string(src.height) +
                  " (3 channels needed)");
    }
  }

  WebExportReport report;
  report.dir = dir;
  report.type = src.type;
  report.colorspace = src.colorspace;
  report.width = src.width;
  report.height = src.height;
  report.planes = src.planes;
  report.jpegs = (src.planes + 2) / 3;
  const bool deepzoom = options.layout == WebLayout::kDeepZoom;
  report.levels = deepzoom ? web_deepzoom_levels(src.width, src.height, options.tile_size_px) : 1;

  std::vector<double> lo, hi;
  plane_ranges(src, &lo, &hi);
  report.scale.resize(src.planes);
  report.bias.resize(src.planes);
  std::vector<double> qlo(src.planes), qinv(src.planes);
  for (int k = 0; k < src.planes; ++k) {
    if (k < src.fixed_unit_planes) {
      // A colour: stored as its 8-bit value (scale 1, bias 0), as the format's readers expect.
      qlo[k] = 0.0;
      qinv[k] = 1.0;
      report.scale[k] = 1.0;
      report.bias[k] = 0.0;
      if (lo[k] < 0.0 || hi[k] > 1.0) {
        throw Error("web export: the lrgb colour leaves 0..1 (" + number_text(lo[k]) + " .. " +
                    number_text(hi[k]) + ")");
      }
      continue;
    }
    const double range = hi[k] - lo[k];
    if (range > 0.0) {
      qlo[k] = lo[k];
      qinv[k] = 1.0 / range;
      report.scale[k] = range;
      report.bias[k] = -lo[k] / range;
    } else {
      // A constant plane: every byte 0 decodes to (0 - bias) * 1 = lo.
      qlo[k] = lo[k];
      qinv[k] = 0.0;
      report.scale[k] = 1.0;
      report.bias[k] = -lo[k];
    }
    report.max_quantisation_error =
        std::max(report.max_quantisation_error, 0.5 * report.scale[k] / 255.0);
  }

  StagedFolder temp(dir, ".web");
  Writer out{temp.path()};
  const bool ycbcr = options.jpeg_colour == WebJpegColour::kAuto
                         ? src.colorspace == "rgb"
                         : options.jpeg_colour == WebJpegColour::kYCbCr;
  double err_sum = 0.0;
  std::size_t err_count = 0;
  std::vector<float> row_buf(static_cast<std::size_t>(src.width) * src.planes);

  for (int j = 0; j < report.jpegs; ++j) {
    // This JPEG's three planes at full size (a missing third plane stays 0).
    Level full;
    full.width = src.width;
    full.height = src.height;
    full.v.assign(static_cast<std::size_t>(src.width) * src.height * 3, 0.0f);
    tbb::parallel_for(
        tbb::blocked_range<int>(0, src.height), [&](const tbb::blocked_range<int>& r) {
          std::vector<float> buf(static_cast<std::size_t>(src.width) * src.planes);
          for (int y = r.begin(); y < r.end(); ++y) {
            src.fill_row(y, buf.data());
            float* o = full.v.data() + static_cast<std::size_t>(y) * src.width * 3;
            for (int x = 0; x < src.width; ++x) {
              for (int c = 0; c < 3 && 3 * j + c < src.planes; ++c) {
                o[3 * x + c] = buf[static_cast<std::size_t>(x) * src.planes + 3 * j + c];
              }
            }
          }
        });
    Quantiser q;
    for (int c = 0; c < 3; ++c) {
      const int k = 3 * j + c;
      q.lo[c] = k < src.planes ? qlo[k] : 0.0;
      q.inv_range[c] = k < src.planes ? qinv[k] : 0.0;
    }
    const std::string name = "plane_" + std::to_string(j);

    // What the JPEG coding lost, on the full-size plane (decoded here with libjpeg).
    auto measure = [&](const std::vector<unsigned char>& bytes_in,
                       const std::vector<unsigned char>& jpeg, int w, int h) {
      const std::vector<unsigned char> back = decode_jpeg(jpeg, w, h);
      for (std::size_t i = 0; i < back.size(); ++i) {
        if (3 * j + static_cast<int>(i % 3) >= src.planes) continue;
        const double d = std::abs(static_cast<int>(back[i]) - static_cast<int>(bytes_in[i]));
        report.jpeg_max_abs_byte = std::max(report.jpeg_max_abs_byte, d);
        err_sum += d;
        ++err_count;
      }
    };

    if (!deepzoom) {
      const auto bytes_in = quantise_region(full, q, 0, 0, full.width, full.height);
      const auto jpeg =
          encode_jpeg(bytes_in.data(), full.width, full.height, options.quality, ycbcr);
      measure(bytes_in, jpeg, full.width, full.height);
      out.write(name + ".jpg",
                std::string_view(reinterpret_cast<const char*>(jpeg.data()), jpeg.size()));
      continue;
    }
    const int ts = options.tile_size_px;
    constexpr int kOverlap = 1;
    std::ostringstream dzi;
    dzi << "<?xml version=\"1.0\" encoding=\"UTF-8\"?>\n"
        << "<Image xmlns=\"http://schemas.microsoft.com/deepzoom/2008\" Format=\"jpg\" "
        << "Overlap=\"" << kOverlap << "\" TileSize=\"" << ts << "\">\n"
        << "  <Size Width=\"" << src.width << "\" Height=\"" << src.height << "\"/>\n"
        << "</Image>\n";
    out.write(name + ".dzi", dzi.str());
    const fs::path files = name + "_files";
    ensure_directory(out.root / files);
    Level level = std::move(full);
    for (int l = report.levels - 1; l >= 0; --l) {
      if (l != report.levels - 1) level = half(level);
      const fs::path ldir = files / std::to_string(l);
      ensure_directory(out.root / ldir);
      const int nx = (level.width + ts - 1) / ts;
      const int ny = (level.height + ts - 1) / ts;
      for (int ty = 0; ty < ny; ++ty) {
        for (int tx = 0; tx < nx; ++tx) {
          // The tile's pixels plus kOverlap on each inner side (seamless linear filtering).
          const int x0 = std::max(0, tx * ts - kOverlap), y0 = std::max(0, ty * ts - kOverlap);
          const int w = std::min((tx + 1) * ts + kOverlap, level.width) - x0;
          const int h = std::min((ty + 1) * ts + kOverlap, level.height) - y0;
          const auto bytes_in = quantise_region(level, q, x0, y0, w, h);
          const auto jpeg = encode_jpeg(bytes_in.data(), w, h, options.quality, ycbcr);
          if (l == report.levels - 1) measure(bytes_in, jpeg, w, h);
          out.write(ldir / (std::to_string(tx) + "_" + std::to_string(ty) + ".jpg"),
                    std::string_view(reinterpret_cast<const char*>(jpeg.data()), jpeg.size()));
        }
      }
    }
  }
  report.jpeg_mean_abs_byte = err_count ? err_sum / static_cast<double>(err_count) : 0.0;

  if (!normals.empty()) {
    Image enc(src.width, src.height, 3, ColourSpace::kSRGB);
    for (int y = 0; y < src.height; ++y) {
      const float* n = normals.row(y);
      float* o = enc.row(y);
      for (int x = 0; x < src.width; ++x) {
        for (int c = 0; c < 3; ++c) {
          const float v = n[static_cast<std::size_t>(x) * normals.channels() + c];
          if (!std::isfinite(v)) {
            throw Error(where(options.normals) + ": non-finite normal at (" + std::to_string(x) +
                        ", " + std::to_string(y) + ")");
          }
          o[3 * x + c] = std::clamp(0.5f * (v + 1.0f), 0.0f, 1.0f);
        }
      }
    }
    write_image(out.root / "normals.png", enc.view(), {.format = PixelFormat::kU8});
    ++out.files;
    out.bytes += fs::file_size(out.root / "normals.png");
    report.normals = true;
  }

  nlohmann::ordered_json info;
  info["width"] = src.width;
  info["height"] = src.height;
  info["format"] = "jpg";
  info["type"] = src.type;
  info["colorspace"] = src.colorspace;
  info["nplanes"] = src.planes;
  info["quality"] = options.quality;
  if (options.pixel_size_mm > 0.0) info["pixelSizeInMM"] = options.pixel_size_mm;
  info["materials"] = nlohmann::ordered_json::array(
      {nlohmann::ordered_json{{"scale", report.scale}, {"bias", report.bias}}});
  nlohmann::ordered_json own;
  own["layout"] = to_string(options.layout);
  if (deepzoom) {
    own["tilesize"] = options.tile_size_px;
    own["levels"] = report.levels;
  }
  own["normals"] = report.normals;
  info["ptmkit"] = own;
  out.write("info.json", info.dump(1) + "\n");
  if (options.viewer) {
    for (const auto& f : web_viewer_files()) out.write(f.name, f.contents);
  }
  report.files = out.files;
  report.bytes = out.bytes;
  temp.commit();
  return report;
}

}  // namespace

WebExportReport export_web(const CoefficientMap& map, const fs::path& dir,
                           const WebExportOptions& options) {
  return export_planes(map.basis == Basis::kPtm ? planes_of(map) : hsh_planes_of(map), dir,
                       options);
}

}  // namespace ptmkit::texture
