// Writing .ptm files (ptm.h): the choice of scales and biases, a PtmFile to disk, and a
// CoefficientMap through the encoder shared with the streaming writer (ptm_internal.h).
#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <limits>
#include <string>
#include <vector>

#include "ptm_header.h"
#include "ptm_internal.h"
#include "ptmkit/core/atomic_file.h"
#include "ptmkit/core/error.h"
#include "ptmkit/core/limits.h"
#include "ptmkit/texture/ptm.h"

namespace fs = std::filesystem;

namespace ptmkit::texture {

using internal::Header;
using internal::parse_header;

// ---------------------------------------------------------------------------------------------
// Quantisation

PtmQuantisation choose_quantisation(const std::array<double, kPtmTerms>& lo,
                                    const std::array<double, kPtmTerms>& hi, bool integer_scales) {
  PtmQuantisation q;
  for (int i = 0; i < kPtmTerms; ++i) {
    const double l = std::min(lo[i], 0.0);
    const double h = std::max(hi[i], 0.0);
    if (!(h - l > 0.0)) {
      q.scales[i] = 1.0f;
      q.biases[i] = 0;
      continue;
    }
    if (integer_scales) {
      // The smallest whole scale s with an integer bias b reaching both ends:
      // b >= -l / s and 255 - b >= h / s.
      for (double s = std::max(1.0, std::ceil((h - l) / 255.0));; s += 1.0) {
        const double b = std::ceil(-l / s - 1e-9);
        if (b + std::ceil(h / s - 1e-9) <= 255.0) {
          q.scales[i] = static_cast<float>(s);
          q.biases[i] = static_cast<int>(b);
          break;
        }
      }
      continue;
    }
    const double ideal = -l / (h - l) * 255.0;
    double best_scale = std::numeric_limits<double>::infinity();
    int best_bias = 0;
    for (const double candidate : {std::floor(ideal), std::ceil(ideal)}) {
      const int b = std::clamp(static_cast<int>(candidate), 0, 255);
      double s = 0.0;
      if (h > 0.0) s = b == 255 ? std::numeric_limits<double>::infinity() : h / (255 - b);
      if (l < 0.0) s = std::max(s, b == 0 ? std::numeric_limits<double>::infinity() : -l / b);
      if (s < best_scale) {
        best_scale = s;
        best_bias = b;
      }
    }
    // The written scale is a float: round up so both ends stay reachable.
    float s = static_cast<float>(best_scale);
    if (static_cast<double>(s) < best_scale)
      s = std::nextafter(s, std::numeric_limits<float>::max());
    q.scales[i] = std::max(s, 1e-30f);
    q.biases[i] = best_bias;
  }
  return q;
}

namespace {

std::size_t data_bytes(PtmFormat format, int width, int height) {
  return static_cast<std::size_t>(width) * static_cast<std::size_t>(height) *
         static_cast<std::size_t>(internal::bytes_per_texel(format));
}

}  // namespace

std::size_t write_ptm_file(const fs::path& path, const PtmFile& file) {
  if (file.width <= 0 || file.height <= 0 || file.width > kMaxPtmSide ||
      file.height > kMaxPtmSide) {
    throw Error(where(path) + ": cannot write a " + std::to_string(file.width) + " x " +
                std::to_string(file.height) + " PTM");
  }
  if (file.version == PtmVersion::k1_1 && file.format != PtmFormat::kLRGB) {
    throw Error(where(path) + ": PTM_1.1 can only be written as PTM_FORMAT_LRGB");
  }
  if (file.version == PtmVersion::k1_1 && file.compression != PtmCompression::kNone) {
    throw Error(where(path) + ": PTM_1.1 has no JPEG variant");
  }
  if (file.compression == PtmCompression::kJpeg &&
      (file.compression_parameter < 1 || file.compression_parameter > 100)) {
    throw Error(where(path) + ": JPEG quality " + std::to_string(file.compression_parameter) +
                " is not in 1..100");
  }
  for (int i = 0; i < kPtmTerms; ++i) {
    const float s = file.quantisation.scales[i];
    const int b = file.quantisation.biases[i];
    if (!std::isfinite(s) || s == 0.0f || b < -kMaxPtmBias || b > kMaxPtmBias) {
      throw Error(where(path) + ": invalid scale or bias for coefficient " + std::to_string(i));
    }
  }
  const std::size_t expected = data_bytes(file.format, file.width, file.height);
  if (file.data.size() != expected) {
    throw Error(where(path) + ": the data block has " + std::to_string(file.data.size()) +
                " bytes; the header implies " + std::to_string(expected));
  }
  std::string header = file.canonical_header();
  std::vector<std::uint8_t> jpeg_block;
  if (file.compression == PtmCompression::kJpeg) {
    std::string tail;
    internal::encode_jpeg_planes(file, file.compression_parameter, &tail, &jpeg_block);
    header += tail;
  } else if (!file.header.empty()) {
    // Keep the header as read if it still describes these fields exactly.
    try {
      const auto* raw = reinterpret_cast<const std::uint8_t*>(file.header.data());
      const Header h = parse_header(raw, file.header.size(), path);
      if (h.header_bytes == file.header.size() && h.version == file.version &&
          h.format == file.format && !h.luminance_only && h.compression == PtmCompression::kNone &&
          h.width == file.width && h.height == file.height && h.quantisation == file.quantisation) {
        header = file.header;
      }
    } catch (const Error&) {
      // Stale or foreign text: the canonical header is written instead.
    }
  }
  const std::vector<std::uint8_t>& block =
      file.compression == PtmCompression::kJpeg ? jpeg_block : file.data;
  const std::size_t block_bytes = block.size();
  AtomicOutput out(path);
  {
    std::ofstream f(out.temp_path(), std::ios::binary | std::ios::trunc);
    if (!f) throw Error(where(path) + ": cannot open for writing");
    f.write(header.data(), static_cast<std::streamsize>(header.size()));
    f.write(reinterpret_cast<const char*>(block.data()),
            static_cast<std::streamsize>(block.size()));
    f.write(reinterpret_cast<const char*>(file.trailing.data()),
            static_cast<std::streamsize>(file.trailing.size()));
    f.flush();
    if (!f) throw Error(where(path) + ": write failed (disk full?)");
  }
  out.commit();
  return header.size() + block_bytes + file.trailing.size();
}

// ---------------------------------------------------------------------------------------------
// Encoding a map

namespace {

// Reads texels of a CoefficientMap as file polynomials.
class MapSource {
 public:
  explicit MapSource(const CoefficientMap& map) : map_(map) {}
  void texel(int x, int y, float* polys, std::uint8_t* rgb) const {
    internal::file_polynomials(map_.model, map_.texel_coeffs(x, y),
                               map_.colours() > 0 ? map_.texel_colour(x, y) : nullptr, polys, rgb);
  }
  void relit(int x, int y, double lu, double lv, float rgb[3]) const {
    map_.evaluate(x, y, lu, lv, rgb);
  }

 private:
  const CoefficientMap& map_;
};

}  // namespace

namespace internal {

PtmFormat format_for(ColourModel model) {
  return model == ColourModel::kLRGB ? PtmFormat::kLRGB : PtmFormat::kRGB;
}

}  // namespace internal

PtmFile encode_ptm(const CoefficientMap& map, const PtmWriteOptions& options,
                   PtmWriteReport* report) {
  if (map.width <= 0 || map.height <= 0 || map.width > kMaxPtmSide || map.height > kMaxPtmSide) {
    throw Error("cannot encode a " + std::to_string(map.width) + " x " +
                std::to_string(map.height) + " map as PTM");
  }
  if (map.basis != Basis::kPtm) {
    throw Error("cannot encode a " + std::string(to_string(map.basis)) +
                " map as PTM (the format holds the ptm basis; write an .rti)");
  }
  const PtmFormat format = internal::format_for(map.model);
  const MapSource source(map);
  std::array<double, kPtmTerms> lo{}, hi{};
  internal::coefficient_range(source, map.width, map.height, format, &lo, &hi);
  for (int i = 0; i < kPtmTerms; ++i) {
    if (!std::isfinite(lo[i]) || !std::isfinite(hi[i])) {
      throw Error("the coefficient map holds NaN or infinite coefficients (a" + std::to_string(i) +
                  "); it cannot be written as PTM");
    }
    lo[i] *= 255.0;
    hi[i] *= 255.0;
  }
  const PtmQuantisation q = choose_quantisation(lo, hi, options.integer_scales);
  return internal::encode(source, map.width, map.height, format, q, options, report);
}

PtmWriteReport write_ptm(const fs::path& path, const CoefficientMap& map,
                         const PtmWriteOptions& options) {
  PtmWriteReport report;
  if (map.width > 0 && !map.coeffs.empty()) {
    check_coefficients(path, map.coeffs.data(), map.coeffs.size(), map.width,
                       polynomial_count(map.model) * kPtmTerms);
  }
  PtmFile file;
  try {
    file = encode_ptm(map, options, &report);
  } catch (const Error& e) {
    throw Error(where(path) + ": " + e.what());
  }
  report.path = path;
  report.file_bytes = write_ptm_file(path, file);
  return report;
}

std::string PtmWriteReport::brief() const {
  char buf[256];
  std::snprintf(buf, sizeof buf,
                "%s: max coefficient error %.3g, RMS %.3g; relit error mean %.3f, max %.3f "
                "grey levels, PSNR %.2f dB",
                std::string(to_string(format)).c_str(), max_coeff_error, rms_coeff_error,
                relit_mean_abs_grey, relit_max_abs_grey, relit_psnr_db);
  return buf;
}

}  // namespace ptmkit::texture
