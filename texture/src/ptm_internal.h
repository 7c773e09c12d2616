// Shared by the .ptm writers (whole map and streaming): byte layout, the map-to-file
// polynomial conversion, and the encoder with its error report, written once over a "source"
// of texels so both writers quantise identically.
#pragma once

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <filesystem>
#include <limits>
#include <string>
#include <vector>

#include "ptmkit/core/holdout.h"
#include "ptmkit/core/light_layout.h"
#include "ptmkit/texture/ptm.h"

namespace ptmkit::texture::internal {

inline int bytes_per_texel(PtmFormat format) { return format == PtmFormat::kRGB ? 18 : 9; }

// The JPEG part of a PTM_FORMAT_JPEG_* header (ptm.h), N = jpeg_planes(format) entries each.
struct JpegPtmHeader {
  int quality = 0;
  std::vector<int> transforms, motion_x, motion_y, order, reference;
  std::vector<std::size_t> stream_bytes, side_bytes;
  // Bytes of the binary block: every stream and its side information.
  [[nodiscard]] std::size_t data_bytes() const {
    std::size_t n = 0;
    for (std::size_t i = 0; i < stream_bytes.size(); ++i) n += stream_bytes[i] + side_bytes[i];
    return n;
  }
};
inline int jpeg_planes(PtmFormat format) { return format == PtmFormat::kRGB ? 18 : 9; }

// Decodes the streams at `data` (`size` bytes: exactly the binary block) into the uncompressed
// PTM 1.2 layout. Errors name `path` and the plane.
std::vector<std::uint8_t> decode_jpeg_planes(const std::uint8_t* data, std::size_t size,
                                             const JpegPtmHeader& header, PtmFormat format,
                                             int width, int height,
                                             const std::filesystem::path& path);
// Encodes the uncompressed layout of `file` (version 1.2) as JPEG planes at `quality`: the
// header lines after the biases (with their line ends) and the binary block.
void encode_jpeg_planes(const PtmFile& file, int quality, std::string* header_tail,
                        std::vector<std::uint8_t>* block);
inline int planes(PtmFormat format) { return format == PtmFormat::kRGB ? 3 : 1; }

// std::round (halves away from zero) for |t| < 2^62, inline: the libm call was a measurable
// part of writing a 12-megapixel file. t - trunc(t) is exact, so the result is std::round's.
inline double round_half_away(double t) {
  const auto f = static_cast<double>(static_cast<long long>(t));
  const double d = t - f;
  return d >= 0.5 ? f + 1.0 : d <= -0.5 ? f - 1.0 : f;
}

// round(255 * v) clamped to 0..255.
inline std::uint8_t colour_byte(float v) {
  double b = 255.0 * static_cast<double>(v);
  b = b >= 0.0 ? b : 0.0;  // negative or NaN
  b = b <= 255.0 ? b : 255.0;
  // 255 times a float is exact in a double, so b + 0.5 is too, and truncating it rounds
  // halves up as std::round does for b >= 0. Branch-free, so loops over it vectorise.
  return static_cast<std::uint8_t>(static_cast<int>(b + 0.5));
}

// File coefficient (0..255 units) to byte: round(c / s + b) clamped to 0..255.
inline std::uint8_t quantise(double c, float scale, int bias) {
  // Round c / s rather than c / s + b: identical for integer b, and exact for c = 0.
  const double t = c / static_cast<double>(scale);
  if (!(t > -512.0)) return 0;  // far below the byte range, or NaN
  if (t > 512.0) return 255;
  const double v = round_half_away(t) + bias;
  if (!(v >= 0.0)) return 0;
  return static_cast<std::uint8_t>(std::min(v, 255.0));
}

std::size_t coeff_offset(const PtmFile& f, int x, int y, int plane, int term);
std::size_t rgb_offset(const PtmFile& f, int x, int y, int channel);
// The file's value at (x, y) lit from (lu, lv), normalised units, unclamped.
void file_relit(const PtmFile& f, int x, int y, double lu, double lv, float rgb[3]);
// A map texel as file polynomials in normalised units: `polys` gets planes * 6 values (3
// planes for kRGB and kYCC, 1 for kLRGB), `rgb` the colour bytes for kLRGB.
void file_polynomials(ColourModel model, const float* coeffs, const float* colour, float* polys,
                      std::uint8_t* rgb);
PtmFormat format_for(ColourModel model);

// Per coefficient index, min and max of the file polynomials (normalised units) over every
// texel and plane. A non-finite value makes that index's bounds NaN.
template <class Source>
void coefficient_range(const Source& source, int width, int height, PtmFormat format,
                       std::array<double, kPtmTerms>* lo, std::array<double, kPtmTerms>* hi) {
  const int np = planes(format);
  std::vector<std::array<double, kPtmTerms>> row_lo(height), row_hi(height);
  tbb::parallel_for(tbb::blocked_range<int>(0, height), [&](const tbb::blocked_range<int>& r) {
    for (int y = r.begin(); y < r.end(); ++y) {
      auto& l = row_lo[y];
      auto& h = row_hi[y];
      l.fill(std::numeric_limits<double>::infinity());
      h.fill(-std::numeric_limits<double>::infinity());
      float polys[3 * kPtmTerms] = {};
      std::uint8_t rgb[3];
      for (int x = 0; x < width; ++x) {
        source.texel(x, y, polys, rgb);
        for (int p = 0; p < np; ++p) {
          for (int i = 0; i < kPtmTerms; ++i) {
            const double v = polys[p * kPtmTerms + i];
            if (!std::isfinite(v)) {
              l[i] = h[i] = std::numeric_limits<double>::quiet_NaN();
            } else if (!std::isnan(l[i])) {
              l[i] = std::min(l[i], v);
              h[i] = std::max(h[i], v);
            }
          }
        }
      }
    }
  });
  lo->fill(std::numeric_limits<double>::infinity());
  hi->fill(-std::numeric_limits<double>::infinity());
  for (int y = 0; y < height; ++y) {
    for (int i = 0; i < kPtmTerms; ++i) {
      if (std::isnan(row_lo[y][i]) || std::isnan((*lo)[i])) {
        (*lo)[i] = (*hi)[i] = std::numeric_limits<double>::quiet_NaN();
      } else {
        (*lo)[i] = std::min((*lo)[i], row_lo[y][i]);
        (*hi)[i] = std::max((*hi)[i], row_hi[y][i]);
      }
    }
  }
}

// Texel stride of the relit-error sample: every stride-th texel in row-major order (0: none).
inline std::size_t relit_sample_stride(std::size_t texels, const PtmWriteOptions& options) {
  if (options.report_max_texels == 0) return 0;
  return std::max<std::size_t>(
      1, (texels + options.report_max_texels - 1) / options.report_max_texels);
}

// Relit error of the file (file_value(x, y, lu, lv, rgb)) against `source` (see
// PtmWriteReport), over every relit_sample_stride-th texel.
template <class Source, class FileValue>
void relit_error(const Source& source, const FileValue& file_value, int width, std::size_t texels,
                 const PtmWriteOptions& options, PtmWriteReport* report) {
  report->relit_mean_abs_grey = report->relit_max_abs_grey = 0.0;
  report->relit_psnr_db = std::numeric_limits<double>::infinity();
  report->relit_samples = 0;
  if (options.report_max_texels == 0) return;
  std::vector<Eigen::Vector3d> lights =
      options.report_lights.empty() ? geodesic_dome(2) : options.report_lights;
  std::vector<std::array<double, 2>> luv;
  for (const auto& l : lights) {
    const double n = l.norm();
    if (!std::isfinite(n) || n == 0.0 || l.z() <= 0.0) continue;
    luv.push_back({l.x() / n, l.y() / n});
  }
  if (luv.empty()) return;
  const std::size_t stride = relit_sample_stride(texels, options);
  const std::size_t samples = (texels + stride - 1) / stride;
  constexpr std::size_t kChunk = 4096;
  const std::size_t chunks = (samples + kChunk - 1) / kChunk;
  struct Sums {
    double abs = 0.0, sq = 0.0, max = 0.0;
    std::size_t n = 0;
  };
  std::vector<Sums> sums(chunks);
  tbb::parallel_for(std::size_t{0}, chunks, [&](std::size_t c) {
    Sums s;
    const std::size_t end = std::min(samples, (c + 1) * kChunk);
    for (std::size_t k = c * kChunk; k < end; ++k) {
      const std::size_t t = k * stride;
      const int x = static_cast<int>(t % static_cast<std::size_t>(width));
      const int y = static_cast<int>(t / static_cast<std::size_t>(width));
      for (const auto& l : luv) {
        float a[3], b[3];
        source.relit(x, y, l[0], l[1], a);
        file_value(x, y, l[0], l[1], b);
        for (int ch = 0; ch < 3; ++ch) {
          const double d = std::abs(std::clamp(static_cast<double>(a[ch]), 0.0, 1.0) -
                                    std::clamp(static_cast<double>(b[ch]), 0.0, 1.0));
          s.abs += d;
          s.sq += d * d;
          s.max = std::max(s.max, d);
          ++s.n;
        }
      }
    }
    sums[c] = s;
  });
  Sums total;
  for (const Sums& s : sums) {
    total.abs += s.abs;
    total.sq += s.sq;
    total.max = std::max(total.max, s.max);
    total.n += s.n;
  }
  if (total.n == 0) return;
  report->relit_samples = total.n;
  report->relit_mean_abs_grey = 255.0 * total.abs / static_cast<double>(total.n);
  report->relit_max_abs_grey = 255.0 * total.max;
  const double mse = total.sq / static_cast<double>(total.n);
  report->relit_psnr_db = psnr_db(mse);
}

// Quantises every texel of `source` with `q` into a PTM 1.2 file; fills `report` (optional).
template <class Source>
PtmFile encode(const Source& source, int width, int height, PtmFormat format,
               const PtmQuantisation& q, const PtmWriteOptions& options, PtmWriteReport* report) {
  PtmFile f;
  f.version = PtmVersion::k1_2;
  f.format = format;
  f.width = width;
  f.height = height;
  f.quantisation = q;
  f.data.resize(f.texels() * static_cast<std::size_t>(bytes_per_texel(format)));
  const int np = planes(format);
  std::vector<double> row_max(height, 0.0), row_sq(height, 0.0);
  tbb::parallel_for(tbb::blocked_range<int>(0, height), [&](const tbb::blocked_range<int>& r) {
    for (int y = r.begin(); y < r.end(); ++y) {
      double mx = 0.0, sq = 0.0;
      float polys[3 * kPtmTerms] = {};
      std::uint8_t rgb[3] = {0, 0, 0};
      for (int x = 0; x < width; ++x) {
        source.texel(x, y, polys, rgb);
        for (int p = 0; p < np; ++p) {
          for (int i = 0; i < kPtmTerms; ++i) {
            const double c = 255.0 * static_cast<double>(polys[p * kPtmTerms + i]);
            const std::uint8_t byte = quantise(c, q.scales[i], q.biases[i]);
            f.data[coeff_offset(f, x, y, p, i)] = byte;
            const double e =
                std::abs(static_cast<double>(q.scales[i]) * (byte - q.biases[i]) - c) / 255.0;
            mx = std::max(mx, e);
            sq += e * e;
          }
        }
        if (format == PtmFormat::kLRGB) {
          for (int ch = 0; ch < 3; ++ch) f.data[rgb_offset(f, x, y, ch)] = rgb[ch];
        }
      }
      row_max[y] = mx;
      row_sq[y] = sq;
    }
  });
  if (report != nullptr) {
    report->format = format;
    report->quantisation = q;
    double mx = 0.0, sq = 0.0;
    for (int y = 0; y < height; ++y) {
      mx = std::max(mx, row_max[y]);
      sq += row_sq[y];
    }
    report->max_coeff_error = mx;
    report->rms_coeff_error = std::sqrt(sq / static_cast<double>(f.texels() * np * kPtmTerms));
    const auto file_value = [&f](int x, int y, double lu, double lv, float out[3]) {
      file_relit(f, x, y, lu, lv, out);
    };
    relit_error(source, file_value, f.width, f.texels(), options, report);
  }
  return f;
}

}  // namespace ptmkit::texture::internal
