// Reading .ptm files (ptm.h): the file's bytes and their checks, PtmInfo and PtmFile, the
// decoding into a CoefficientMap, and the summary.
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <array>
#include <cstdint>
#include <fstream>
#include <limits>
#include <string>
#include <system_error>
#include <vector>

#include "ptm_header.h"
#include "ptm_internal.h"
#include "ptmkit/core/error.h"
#include "ptmkit/core/limits.h"
#include "ptmkit/texture/ptm.h"

namespace fs = std::filesystem;

namespace ptmkit::texture {

using internal::Header;
using internal::parse_header;

namespace {

std::size_t data_bytes(const Header& h) {
  if (h.compression == PtmCompression::kJpeg) return h.jpeg.data_bytes();
  const std::size_t texels = static_cast<std::size_t>(h.width) * static_cast<std::size_t>(h.height);
  if (h.luminance_only) return texels * kPtmTerms;
  return texels * static_cast<std::size_t>(internal::bytes_per_texel(h.format));
}

std::vector<std::uint8_t> read_bytes(const fs::path& path, std::size_t limit) {
  std::error_code ec;
  if (!fs::exists(path, ec)) throw Error(where(path) + ": no such file");
  if (fs::is_directory(path, ec))
    throw Error(where(path) +
                ": is a folder without an info.json (not a web folder), expected a .ptm file");
  // Regular files only (a device never ends), read only if they fit in memory.
  const std::uintmax_t size =
      checked_input_size(path, std::numeric_limits<std::uintmax_t>::max(), ".ptm file");
  check_allocation(path, std::min<std::uintmax_t>(size, limit), "the file's bytes");
  std::ifstream in(path, std::ios::binary);
  if (!in) throw Error(where(path) + ": cannot open for reading");
  std::vector<std::uint8_t> bytes(static_cast<std::size_t>(std::min<std::uintmax_t>(size, limit)));
  in.read(reinterpret_cast<char*>(bytes.data()), static_cast<std::streamsize>(bytes.size()));
  if (in.gcount() != static_cast<std::streamsize>(bytes.size())) {
    throw Error(where(path) + ": read failed");
  }
  return bytes;
}

PtmInfo info_from(const Header& h, const fs::path& path, std::size_t file_bytes) {
  PtmInfo info;
  info.path = path;
  info.version = h.version;
  info.format = h.format;
  info.luminance_only = h.luminance_only;
  info.width = h.width;
  info.height = h.height;
  info.quantisation = h.quantisation;
  info.compression = h.compression;
  info.compression_parameter = h.jpeg.quality;
  info.header_bytes = h.header_bytes;
  info.data_bytes = data_bytes(h);
  info.file_bytes = file_bytes;
  const std::size_t used = info.header_bytes + info.data_bytes;
  info.trailing_bytes = file_bytes > used ? file_bytes - used : 0;
  return info;
}

}  // namespace

PtmInfo read_ptm_info(const fs::path& path) {
  // The header is short (16 items of at most 64 characters); 64 KiB is plenty.
  const std::vector<std::uint8_t> bytes = read_bytes(path, std::size_t{1} << 16);
  const Header h = parse_header(bytes.data(), bytes.size(), path);
  std::error_code ec;
  const std::size_t size = static_cast<std::size_t>(fs::file_size(path, ec));
  return info_from(h, path, size);
}

PtmFile read_ptm_file(const fs::path& path) {
  std::vector<std::uint8_t> bytes = read_bytes(path, std::numeric_limits<std::size_t>::max());
  const Header h = parse_header(bytes.data(), bytes.size(), path);
  // Declared sizes are checked against the file before anything of that size is allocated.
  const std::size_t expected = data_bytes(h);
  const std::size_t present = bytes.size() - h.header_bytes;
  const std::string name(info_from(h, path, bytes.size()).format_line());
  if (h.luminance_only && present > expected && present % h.texels() == 0 &&
      present / h.texels() > kPtmTerms && present / h.texels() <= kPtmTerms + 3) {
    // One description of the format puts 2 or 3 colour bytes a texel after the luminance
    // block, in an order no reader agrees on and no sample file settles: refused, not guessed.
    throw Error(where(path) + ": PTM_FORMAT_LUM with " +
                std::to_string(present / h.texels() - kPtmTerms) +
                " colour bytes a texel after the luminance block is not supported (the order of "
                "that block is not defined; supported: PTM_FORMAT_LUM with the luminance block "
                "alone, " +
                std::to_string(kPtmTerms) + " bytes a texel)");
  }
  if (present < expected) {
    throw Error(where(path) + ": binary data truncated: " + std::to_string(h.width) + " x " +
                std::to_string(h.height) + " " + name + " needs " + std::to_string(expected) +
                " bytes after the header, found " + std::to_string(present));
  }
  if (present > expected) {
    // Not tolerated: a header line too many or a wrong declared size shifts every texel.
    throw Error(where(path) + ": " + std::to_string(present - expected) +
                " bytes after the binary block: " + std::to_string(h.width) + " x " +
                std::to_string(h.height) + " " + name + " needs " + std::to_string(expected) +
                " (a damaged file, or a header that does not describe the data)");
  }
  PtmFile f;
  f.version = h.version;
  f.format = h.format;
  f.luminance_only = h.luminance_only;
  f.compression = h.compression;
  f.compression_parameter = h.jpeg.quality;
  f.width = h.width;
  f.height = h.height;
  f.quantisation = h.quantisation;
  const auto data_begin = bytes.begin() + static_cast<std::ptrdiff_t>(h.header_bytes);
  const auto data_end = data_begin + static_cast<std::ptrdiff_t>(expected);
  f.trailing.assign(data_end, bytes.end());
  if (h.compression == PtmCompression::kJpeg) {
    // The header describes streams that are not kept: a rewrite writes its own.
    f.data = internal::decode_jpeg_planes(bytes.data() + h.header_bytes, expected, h.jpeg, h.format,
                                          h.width, h.height, path);
    return f;
  }
  if (h.luminance_only) {
    // The LRGB layout: the luminance block as stored, then a white colour block. The header
    // is not kept (it says PTM_FORMAT_LUM): a rewrite is a PTM_FORMAT_LRGB file.
    f.data.reserve(h.texels() * internal::bytes_per_texel(PtmFormat::kLRGB));
    f.data.assign(data_begin, data_end);
    f.data.resize(h.texels() * internal::bytes_per_texel(PtmFormat::kLRGB), 255);
    return f;
  }
  f.header.assign(bytes.begin(), data_begin);
  // Reuse the read buffer for the data block: no second full-size copy.
  bytes.erase(data_end, bytes.end());
  bytes.erase(bytes.begin(), bytes.begin() + static_cast<std::ptrdiff_t>(h.header_bytes));
  f.data = std::move(bytes);
  return f;
}

// ---------------------------------------------------------------------------------------------
// Decoding

CoefficientMap decode_ptm(const PtmFile& file, ColourSpace colour_space) {
  const ColourModel model = file.format == PtmFormat::kRGB ? ColourModel::kRGB : ColourModel::kLRGB;
  CoefficientMap map(file.width, file.height, model, colour_space);
  const int planes = map.polynomials();
  tbb::parallel_for(tbb::blocked_range<int>(0, file.height), [&](const tbb::blocked_range<int>& r) {
    for (int y = r.begin(); y < r.end(); ++y) {
      for (int x = 0; x < file.width; ++x) {
        float* a = map.texel_coeffs(x, y);
        double factor = 1.0 / 255.0;
        if (model == ColourModel::kLRGB) {
          float* col = map.texel_colour(x, y);
          const int m =
              std::max({file.rgb_byte(x, y, 0), file.rgb_byte(x, y, 1), file.rgb_byte(x, y, 2)});
          for (int c = 0; c < 3; ++c) {
            col[c] =
                m > 0 ? static_cast<float>(static_cast<double>(file.rgb_byte(x, y, c)) / m) : 0.0f;
          }
          if (m > 0) factor = m / (255.0 * 255.0);
        }
        for (int p = 0; p < planes; ++p) {
          for (int i = 0; i < kPtmTerms; ++i) {
            a[p * kPtmTerms + i] = static_cast<float>(file.coefficient(x, y, p, i) * factor);
          }
        }
      }
    }
  });
  return map;
}

CoefficientMap read_ptm(const fs::path& path, ColourSpace colour_space) {
  return decode_ptm(read_ptm_file(path), colour_space);
}

PtmSummary summarise_ptm(const fs::path& path) {
  const PtmFile file = read_ptm_file(path);
  PtmSummary s;
  s.info = read_ptm_info(path);
  const auto& q = file.quantisation;
  std::array<int, kPtmTerms> bmin, bmax;
  bmin.fill(255);
  bmax.fill(0);
  const int planes = file.format == PtmFormat::kRGB ? 3 : 1;
  for (int y = 0; y < file.height; ++y) {
    for (int x = 0; x < file.width; ++x) {
      for (int p = 0; p < planes; ++p) {
        for (int i = 0; i < kPtmTerms; ++i) {
          const int b = file.coeff_byte(x, y, p, i);
          bmin[i] = std::min(bmin[i], b);
          bmax[i] = std::max(bmax[i], b);
        }
      }
    }
  }
  for (int i = 0; i < kPtmTerms; ++i) {
    const double sc = q.scales[i];
    const double a = sc * (bmin[i] - q.biases[i]), b = sc * (bmax[i] - q.biases[i]);
    s.coeff_min[i] = std::min(a, b);
    s.coeff_max[i] = std::max(a, b);
    const double ra = sc * (0 - q.biases[i]), rb = sc * (255 - q.biases[i]);
    s.representable_min[i] = std::min(ra, rb);
    s.representable_max[i] = std::max(ra, rb);
  }
  s.file_bytes_per_texel = s.info.bytes_per_texel();
  const int floats = file.format == PtmFormat::kRGB ? 3 * kPtmTerms : kPtmTerms + 3;
  s.map_bytes_per_texel = floats * static_cast<int>(sizeof(float));
  return s;
}

}  // namespace ptmkit::texture
