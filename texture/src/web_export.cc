// Export to the relight/OpenLIME web folder (texture/web_export.h).
#include "ptmkit/texture/web_export.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
// clang-format off
#include <cstdio>  // jpeglib.h needs FILE and size_t declared first
#include <jpeglib.h>
// clang-format on

#include <algorithm>
#include <array>
#include <cmath>
#include <csetjmp>
#include <cstdint>
#include <fstream>
#include <functional>
#include <limits>
#include <nlohmann/json.hpp>
#include <random>
#include <sstream>

#include "ptmkit/core/atomic_file.h"
#include "ptmkit/core/colour.h"
#include "ptmkit/core/error.h"
#include "ptmkit/core/image_io.h"

namespace fs = std::filesystem;

namespace ptmkit::texture {

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

// The one place the texture maps are read: what a map is in the web format's terms, and a
// function that fills one row of texels with every plane's coefficient (normalised units).
struct PlaneSource {
  std::string type;        // "ptm" or "hsh"
  std::string colorspace;  // "rgb" or "lrgb"
  int width = 0, height = 0;
  int planes = 0;
  // Planes holding a colour in 0..1, written with scale 1 and bias 0 (lrgb's plane_0).
  int fixed_unit_planes = 0;
  // out: width * planes floats, [x][plane].
  std::function<void(int y, float* out)> fill_row;
};

// The web order of the PTM terms (1, u, v, u^2, uv, v^2) as indices into the .ptm's a0..a5
// (u^2, v^2, uv, u, v, 1).
constexpr std::array<int, kPtmTerms> kWebFromPtm = {5, 3, 4, 0, 2, 1};

PlaneSource planes_of(const CoefficientMap& map) {
  PlaneSource s;
  s.type = "ptm";
  s.width = map.width;
  s.height = map.height;
  const std::size_t texels = static_cast<std::size_t>(map.width) * map.height;
  if (map.width <= 0 || map.height <= 0 ||
      map.coeffs.size() != texels * map.polynomials() * kPtmTerms ||
      map.colour.size() != texels * map.colours()) {
    throw Error("web export: the coefficient map is empty or its buffers do not match its size");
  }
  switch (map.model) {
    case ColourModel::kRGB:
      s.colorspace = "rgb";
      s.planes = 18;
      s.fill_row = [&map](int y, float* out) {
        for (int x = 0; x < map.width; ++x, out += 18) {
          const float* a = map.texel_coeffs(x, y);
          for (int j = 0; j < kPtmTerms; ++j) {
            for (int c = 0; c < 3; ++c) out[3 * j + c] = a[c * kPtmTerms + kWebFromPtm[j]];
          }
        }
      };
      break;
    case ColourModel::kLRGB:
      s.colorspace = "lrgb";
      s.planes = 9;
      s.fixed_unit_planes = 3;
      s.fill_row = [&map](int y, float* out) {
        for (int x = 0; x < map.width; ++x, out += 9) {
          const float* a = map.texel_coeffs(x, y);
          const float* col = map.texel_colour(x, y);
          for (int c = 0; c < 3; ++c) out[c] = col[c];
          for (int j = 0; j < kPtmTerms; ++j) out[3 + j] = a[kWebFromPtm[j]];
        }
      };
      break;
    case ColourModel::kYCC:
      // rgb = from_ycbcr(Y(l), cb, cr) is linear in (Y, cb, cr): each channel is a polynomial
      // whose terms are from_ycbcr of (a_k, 0, 0), the constant term's of (a5, cb, cr).
      s.colorspace = "rgb";
      s.planes = 18;
      s.fill_row = [&map](int y, float* out) {
        for (int x = 0; x < map.width; ++x, out += 18) {
          const float* a = map.texel_coeffs(x, y);
          const float* col = map.texel_colour(x, y);
          for (int j = 0; j < kPtmTerms; ++j) {
            const int k = kWebFromPtm[j];
            const bool constant = k == 5;
            double rgb[3];
            from_ycbcr({a[k], constant ? col[0] : 0.0, constant ? col[1] : 0.0}, &rgb[0], &rgb[1],
                       &rgb[2]);
            for (int c = 0; c < 3; ++c) out[3 * j + c] = static_cast<float>(rgb[c]);
          }
        }
      };
      break;
  }
  return s;
}

// An HSH map (the rgb layout .rti holds).
PlaneSource hsh_planes_of(const CoefficientMap& map) {
  PlaneSource s;
  s.type = "hsh";
  s.colorspace = "rgb";
  s.width = map.width;
  s.height = map.height;
  const int t = map.terms();
  if (map.model != ColourModel::kRGB) {
    throw Error("web export: an HSH map is exported in the rgb layout, not " +
                std::string(to_string(map.model)));
  }
  if (map.width <= 0 || map.height <= 0 ||
      map.coeffs.size() != map.texels() * 3 * static_cast<std::size_t>(t)) {
    throw Error("web export: the HSH map is empty or its buffer does not match its size");
  }
  s.planes = 3 * t;
  s.fill_row = [&map, t](int y, float* out) {
    for (int x = 0; x < map.width; ++x, out += 3 * t) {
      const float* c = map.texel_coeffs(x, y);
      for (int j = 0; j < t; ++j) {
        for (int k = 0; k < 3; ++k) out[3 * j + k] = c[k * t + j];
      }
    }
  };
  return s;
}

// Per-plane range over every texel (exact minimum and maximum, see docs/WEB.md for why not a
// quantile); throws on a non-finite coefficient.
void plane_ranges(const PlaneSource& src, std::vector<double>* lo, std::vector<double>* hi) {
  const int p = src.planes;
  std::vector<std::vector<double>> row_lo(src.height), row_hi(src.height);
  std::vector<int> bad_row(src.height, -1);
  tbb::parallel_for(tbb::blocked_range<int>(0, src.height), [&](const tbb::blocked_range<int>& r) {
    std::vector<float> buf(static_cast<std::size_t>(src.width) * p);
    for (int y = r.begin(); y < r.end(); ++y) {
      src.fill_row(y, buf.data());
      std::vector<double> l(p, std::numeric_limits<double>::infinity());
      std::vector<double> h(p, -std::numeric_limits<double>::infinity());
      for (int x = 0; x < src.width; ++x) {
        for (int k = 0; k < p; ++k) {
          const float v = buf[static_cast<std::size_t>(x) * p + k];
          if (!std::isfinite(v)) {
            bad_row[y] = x;
            break;
          }
          l[k] = std::min(l[k], static_cast<double>(v));
          h[k] = std::max(h[k], static_cast<double>(v));
        }
      }
      row_lo[y] = std::move(l);
      row_hi[y] = std::move(h);
    }
  });
  lo->assign(p, std::numeric_limits<double>::infinity());
  hi->assign(p, -std::numeric_limits<double>::infinity());
  for (int y = 0; y < src.height; ++y) {
    if (bad_row[y] >= 0) {
      throw Error("web export: texel (" + std::to_string(bad_row[y]) + ", " + std::to_string(y) +
                  ") has a non-finite coefficient");
    }
    for (int k = 0; k < p; ++k) {
      (*lo)[k] = std::min((*lo)[k], row_lo[y][k]);
      (*hi)[k] = std::max((*hi)[k], row_hi[y][k]);
    }
  }
}

// --- JPEG through libjpeg ---------------------------------------------------------------

struct JpegErrorManager {
  jpeg_error_mgr pub;
  std::jmp_buf jump;
  char message[JMSG_LENGTH_MAX];
};

void jpeg_error_exit(j_common_ptr cinfo) {
  auto* err = reinterpret_cast<JpegErrorManager*>(cinfo->err);
  (*cinfo->err->format_message)(cinfo, err->message);
  std::longjmp(err->jump, 1);
}

// Encodes interleaved 8-bit RGB. `ycbcr`: the ordinary colour transform; otherwise the
// components are stored as R, G, B (Adobe marker, no transform). No chroma subsampling.
std::vector<unsigned char> encode_jpeg(const unsigned char* rgb, int width, int height, int quality,
                                       bool ycbcr) {
  jpeg_compress_struct cinfo{};
  JpegErrorManager err{};
  cinfo.err = jpeg_std_error(&err.pub);
  err.pub.error_exit = jpeg_error_exit;
  unsigned char* mem = nullptr;
  unsigned long mem_size = 0;  // NOLINT(runtime/int): libjpeg's type
  if (setjmp(err.jump)) {
    jpeg_destroy_compress(&cinfo);
    std::free(mem);
    throw Error(std::string("JPEG encoding failed: ") + err.message);
  }
  jpeg_create_compress(&cinfo);
  jpeg_mem_dest(&cinfo, &mem, &mem_size);
  cinfo.image_width = static_cast<JDIMENSION>(width);
  cinfo.image_height = static_cast<JDIMENSION>(height);
  cinfo.input_components = 3;
  cinfo.in_color_space = JCS_RGB;
  jpeg_set_defaults(&cinfo);
  jpeg_set_colorspace(&cinfo, ycbcr ? JCS_YCbCr : JCS_RGB);
  for (int c = 0; c < 3; ++c) {
    cinfo.comp_info[c].h_samp_factor = 1;
    cinfo.comp_info[c].v_samp_factor = 1;
  }
  jpeg_set_quality(&cinfo, quality, TRUE);
  cinfo.optimize_coding = TRUE;
  cinfo.dct_method = JDCT_ISLOW;
  jpeg_start_compress(&cinfo, TRUE);
  const std::size_t stride = static_cast<std::size_t>(width) * 3;
  while (cinfo.next_scanline < cinfo.image_height) {
    JSAMPROW row = const_cast<JSAMPROW>(rgb + cinfo.next_scanline * stride);
    jpeg_write_scanlines(&cinfo, &row, 1);
  }
  jpeg_finish_compress(&cinfo);
  jpeg_destroy_compress(&cinfo);
  std::vector<unsigned char> out(mem, mem + mem_size);
  std::free(mem);
  return out;
}

// Decodes to interleaved RGB (for measuring what the coding lost).
std::vector<unsigned char> decode_jpeg(const std::vector<unsigned char>& data, int width,
                                       int height) {
  jpeg_decompress_struct cinfo{};
  JpegErrorManager err{};
  // Declared before setjmp: a longjmp back here must not skip an object's construction.
  std::vector<unsigned char> out;
  cinfo.err = jpeg_std_error(&err.pub);
  err.pub.error_exit = jpeg_error_exit;
  if (setjmp(err.jump)) {
    jpeg_destroy_decompress(&cinfo);
    throw Error(std::string("JPEG decoding failed: ") + err.message);
  }
  jpeg_create_decompress(&cinfo);
  jpeg_mem_src(&cinfo, data.data(), static_cast<unsigned long>(data.size()));  // NOLINT
  jpeg_read_header(&cinfo, TRUE);
  cinfo.out_color_space = JCS_RGB;
  cinfo.dct_method = JDCT_ISLOW;
  jpeg_start_decompress(&cinfo);
  if (static_cast<int>(cinfo.output_width) != width ||
      static_cast<int>(cinfo.output_height) != height || cinfo.output_components != 3) {
    jpeg_destroy_decompress(&cinfo);
    throw Error("JPEG decoding: unexpected size");
  }
  out.resize(static_cast<std::size_t>(width) * height * 3);
  while (cinfo.output_scanline < cinfo.output_height) {
    JSAMPROW row = out.data() + static_cast<std::size_t>(cinfo.output_scanline) * width * 3;
    jpeg_read_scanlines(&cinfo, &row, 1);
  }
  jpeg_finish_decompress(&cinfo);
  jpeg_destroy_decompress(&cinfo);
  return out;
}

// --- the folder ------------------------------------------------------------------------

// A temporary folder beside the target, removed unless committed. The files written into it
// must exist at once, even inside the command's OutputTransaction: renaming the folder is
// what commits them.
class TempFolder {
 public:
  explicit TempFolder(const fs::path& target) : target_(target) {
    const fs::path parent = target.has_parent_path() ? target.parent_path() : fs::path(".");
    std::random_device rd;
    for (int attempt = 0; attempt < 100; ++attempt) {
      std::ostringstream name;
      name << "." << target.filename().string() << ".tmp-" << std::hex << rd();
      const fs::path p = parent / name.str();
      std::error_code ec;
      if (fs::create_directory(p, ec)) {
        path_ = p;
        return;
      }
      if (ec && ec != std::errc::file_exists) {
        throw Error(where(parent) + ": cannot create a temporary folder: " + ec.message());
      }
    }
    throw Error(where(parent) + ": cannot create a temporary folder");
  }
  ~TempFolder() {
    if (!path_.empty()) {
      std::error_code ec;
      fs::remove_all(path_, ec);
    }
  }
  TempFolder(const TempFolder&) = delete;
  TempFolder& operator=(const TempFolder&) = delete;
  [[nodiscard]] const fs::path& path() const { return path_; }

  // Moves the folder into place. An existing target (checked by the caller to be an export)
  // is renamed aside first and removed once the new folder is in place.
  void commit() {
    std::error_code ec;
    fs::path old;
    if (fs::exists(target_, ec)) {
      old = path_;
      old += ".old";
      fs::rename(target_, old, ec);
      if (ec) throw Error(where(target_) + ": cannot replace the existing export: " + ec.message());
    }
    fs::rename(path_, target_, ec);
    if (ec) {
      std::error_code ec2;
      if (!old.empty()) fs::rename(old, target_, ec2);
      throw Error(where(target_) + ": cannot move the export into place: " + ec.message());
    }
    path_.clear();
    if (!old.empty()) fs::remove_all(old, ec);
  }

 private:
  OutputTransaction::Immediate immediate_;
  fs::path target_;
  fs::path path_;
};

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

// One JPEG's three planes at one pyramid level, floats [y][x][3].
struct Level {
  int width = 0, height = 0;
  std::vector<float> v;
};

Level half(const Level& src) {
  Level d;
  d.width = src.width / 2;
  d.height = src.height / 2;
  d.v.resize(static_cast<std::size_t>(d.width) * d.height * 3);
  tbb::parallel_for(tbb::blocked_range<int>(0, d.height), [&](const tbb::blocked_range<int>& r) {
    for (int y = r.begin(); y < r.end(); ++y) {
      const float* a = src.v.data() + static_cast<std::size_t>(2 * y) * src.width * 3;
      const float* b = a + static_cast<std::size_t>(src.width) * 3;
      float* o = d.v.data() + static_cast<std::size_t>(y) * d.width * 3;
      for (int x = 0; x < d.width; ++x) {
        for (int c = 0; c < 3; ++c) {
          const std::size_t i = static_cast<std::size_t>(2 * x) * 3 + c;
          o[3 * x + c] = 0.25f * (a[i] + a[i + 3] + b[i] + b[i + 3]);
        }
      }
    }
  });
  return d;
}

// 8-bit plane value of a coefficient: round((v - min) / (max - min) * 255).
struct Quantiser {
  std::array<double, 3> lo{}, inv_range{};
  [[nodiscard]] unsigned char byte(int c, float v) const {
    const double q = (v - lo[c]) * inv_range[c] * 255.0;
    return static_cast<unsigned char>(std::clamp(std::lround(q), 0L, 255L));
  }
};

std::vector<unsigned char> quantise_region(const Level& l, const Quantiser& q, int x0, int y0,
                                           int w, int h) {
  std::vector<unsigned char> out(static_cast<std::size_t>(w) * h * 3);
  for (int y = 0; y < h; ++y) {
    const float* row = l.v.data() + (static_cast<std::size_t>(y0 + y) * l.width + x0) * 3;
    unsigned char* o = out.data() + static_cast<std::size_t>(y) * w * 3;
    for (int i = 0; i < w * 3; ++i) o[i] = q.byte(i % 3, row[i]);
  }
  return out;
}

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

  TempFolder temp(dir);
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
