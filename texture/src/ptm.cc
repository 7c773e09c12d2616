#include "ptmkit/texture/ptm.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <cctype>
#include <charconv>
#include <cmath>
#include <fstream>
#include <limits>
#include <stdexcept>
#include <system_error>

#include "ptm_internal.h"
#include "ptmkit/core/atomic_file.h"
#include "ptmkit/core/colour.h"
#include "ptmkit/core/error.h"
#include "ptmkit/core/light_layout.h"
#include "ptmkit/core/limits.h"
#include "ptmkit/texture/formats.h"

namespace fs = std::filesystem;

namespace ptmkit::texture {

std::string_view to_string(PtmVersion version) {
  return version == PtmVersion::k1_1 ? "PTM_1.1" : "PTM_1.2";
}

std::string_view to_string(PtmFormat format) {
  return format == PtmFormat::kRGB ? "PTM_FORMAT_RGB" : "PTM_FORMAT_LRGB";
}

std::string_view format_name(PtmFormat format, PtmCompression compression) {
  if (compression == PtmCompression::kJpeg) {
    return format == PtmFormat::kRGB ? "PTM_FORMAT_JPEG_RGB" : "PTM_FORMAT_JPEG_LRGB";
  }
  return to_string(format);
}

int PtmInfo::bytes_per_texel() const { return internal::bytes_per_texel(format); }

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

// ---------------------------------------------------------------------------------------------
// PtmFile

namespace internal {

std::size_t coeff_offset(const PtmFile& f, int x, int y, int plane, int term) {
  const std::size_t stored_row = static_cast<std::size_t>(f.height - 1 - y);
  const std::size_t pixel = stored_row * f.width + x;
  if (f.version == PtmVersion::k1_1) return pixel * 9 + term;
  return static_cast<std::size_t>(plane) * f.texels() * kPtmTerms + pixel * kPtmTerms + term;
}

std::size_t rgb_offset(const PtmFile& f, int x, int y, int channel) {
  const std::size_t stored_row = static_cast<std::size_t>(f.height - 1 - y);
  const std::size_t pixel = stored_row * f.width + x;
  if (f.version == PtmVersion::k1_1) return pixel * 9 + kPtmTerms + channel;
  return f.texels() * kPtmTerms + pixel * 3 + channel;
}

void file_relit(const PtmFile& f, int x, int y, double lu, double lv, float rgb[3]) {
  const auto basis = ptm_basis(lu, lv);
  const auto& q = f.quantisation;
  auto poly = [&](int plane) {
    double v = 0.0;
    for (int i = 0; i < kPtmTerms; ++i) {
      v += static_cast<double>(q.scales[i]) *
           (f.data[coeff_offset(f, x, y, plane, i)] - q.biases[i]) * basis[i];
    }
    return v;  // file units
  };
  if (f.format == PtmFormat::kRGB) {
    for (int c = 0; c < 3; ++c) rgb[c] = static_cast<float>(poly(c) / 255.0);
  } else {
    const double l = poly(0) / 255.0;
    for (int c = 0; c < 3; ++c) {
      rgb[c] = static_cast<float>(l * f.data[rgb_offset(f, x, y, c)] / 255.0);
    }
  }
}

void file_polynomials(ColourModel model, const float* a, const float* colour, float* polys,
                      std::uint8_t* rgb) {
  switch (model) {
    case ColourModel::kRGB:
      std::copy_n(a, 3 * kPtmTerms, polys);
      break;
    case ColourModel::kLRGB:
      std::copy_n(a, kPtmTerms, polys);
      for (int c = 0; c < 3; ++c) rgb[c] = colour_byte(colour[c]);
      break;
    case ColourModel::kYCC: {
      // Linear in (y, cb, cr): a0..a4 carry no chroma, a5 carries all of it.
      for (int i = 0; i < kPtmTerms; ++i) {
        const bool constant = i == kPtmTerms - 1;
        double r = 0, g = 0, b = 0;
        from_ycbcr({a[i], constant ? colour[0] : 0.0, constant ? colour[1] : 0.0}, &r, &g, &b);
        polys[i] = static_cast<float>(r);
        polys[kPtmTerms + i] = static_cast<float>(g);
        polys[2 * kPtmTerms + i] = static_cast<float>(b);
      }
      break;
    }
  }
}

}  // namespace internal

using internal::coeff_offset;
using internal::rgb_offset;

std::uint8_t PtmFile::coeff_byte(int x, int y, int plane, int term) const {
  return data[coeff_offset(*this, x, y, plane, term)];
}

std::uint8_t PtmFile::rgb_byte(int x, int y, int channel) const {
  return data[rgb_offset(*this, x, y, channel)];
}

double PtmFile::coefficient(int x, int y, int plane, int term) const {
  return static_cast<double>(quantisation.scales[term]) *
         (coeff_byte(x, y, plane, term) - quantisation.biases[term]);
}

std::string PtmFile::canonical_header() const {
  std::string h;
  h += to_string(version);
  h += '\n';
  h += format_name(format, compression);
  h += '\n';
  h += std::to_string(width) + '\n' + std::to_string(height) + '\n';
  for (int i = 0; i < kPtmTerms; ++i) {
    char buf[64];
    // Shortest text that reads back to the same float: rewrites are bit-exact.
    const auto r = std::to_chars(buf, buf + sizeof buf, quantisation.scales[i]);
    h.append(buf, r.ptr);
    h += i + 1 < kPtmTerms ? ' ' : '\n';
  }
  for (int i = 0; i < kPtmTerms; ++i) {
    h += std::to_string(quantisation.biases[i]);
    h += i + 1 < kPtmTerms ? ' ' : '\n';
  }
  return h;
}

// ---------------------------------------------------------------------------------------------
// Header parsing

namespace {

constexpr std::size_t kMaxTokenChars = 64;

bool is_space(std::uint8_t c) {
  return c == ' ' || c == '\t' || c == '\r' || c == '\n' || c == '\v' || c == '\f';
}

// Printable rendering of a header item for messages (binary junk becomes '?').
std::string printable(std::string_view s) {
  std::string out;
  for (const char c : s.substr(0, 32)) {
    out += std::isprint(static_cast<unsigned char>(c)) != 0 ? c : '?';
  }
  if (s.size() > 32) out += "...";
  return out;
}

class HeaderTokens {
 public:
  HeaderTokens(const std::uint8_t* data, std::size_t size, const fs::path& path)
      : data_(data), size_(size), path_(path) {}

  // Next whitespace-separated item; `what` names it for the error message.
  std::string_view next(const char* what) {
    while (pos_ < size_ && is_space(data_[pos_])) {
      if (data_[pos_] == '\n') ++line_;
      ++pos_;
    }
    if (pos_ >= size_) {
      throw Error(where(path_, line_) + ": the header ends before the " + what);
    }
    token_line_ = line_;
    const std::size_t start = pos_;
    while (pos_ < size_ && !is_space(data_[pos_])) {
      if (pos_ - start >= kMaxTokenChars) {
        throw Error(where(path_, line_) + ": header item too long where the " + what +
                    " was expected (is this a PTM file?)");
      }
      ++pos_;
    }
    return {reinterpret_cast<const char*>(data_ + start), pos_ - start};
  }

  // After the last item: optional spaces, then exactly one line end (LF or CRLF). The binary
  // block starts right after it, so nothing more may be skipped (its first byte may be a
  // space or a newline).
  std::size_t end_of_header() {
    while (pos_ < size_ && (data_[pos_] == ' ' || data_[pos_] == '\t')) ++pos_;
    if (pos_ < size_ && data_[pos_] == '\r') ++pos_;
    if (pos_ >= size_ || data_[pos_] != '\n') {
      throw Error(where(path_, line_) +
                  ": the header's last line (the biases) is not followed by a line end");
    }
    return pos_ + 1;
  }

  [[nodiscard]] int line() const { return token_line_; }
  [[nodiscard]] std::string at() const { return where(path_, token_line_); }

 private:
  const std::uint8_t* data_;
  std::size_t size_;
  const fs::path& path_;
  std::size_t pos_ = 0;
  int line_ = 1;
  int token_line_ = 1;
};

template <class T>
bool parse_number(std::string_view s, T* value) {
  const auto r = std::from_chars(s.data(), s.data() + s.size(), *value);
  return r.ec == std::errc() && r.ptr == s.data() + s.size();
}

struct Header {
  PtmVersion version = PtmVersion::k1_2;
  PtmFormat format = PtmFormat::kRGB;
  PtmCompression compression = PtmCompression::kNone;
  int width = 0;
  int height = 0;
  PtmQuantisation quantisation;
  internal::JpegPtmHeader jpeg;
  std::size_t header_bytes = 0;
};

Header parse_header(const std::uint8_t* data, std::size_t size, const fs::path& path) {
  HeaderTokens tokens(data, size, path);
  Header h;
  if (size == 0) throw Error(where(path) + ": empty file, not a PTM file");
  const std::string_view magic = tokens.next("magic PTM_1.2");
  if (magic == "PTM_1.2") {
    h.version = PtmVersion::k1_2;
  } else if (magic == "PTM_1.1") {
    h.version = PtmVersion::k1_1;
  } else if (magic.substr(0, 4) == "PTM_") {
    throw Error(tokens.at() + ": unsupported PTM version '" + printable(magic) +
                "' (supported: PTM_1.2, and PTM_1.1 with PTM_FORMAT_LRGB)");
  } else {
    throw Error(where(path) + ": not a PTM file (it does not start with PTM_1.2)");
  }

  const std::string_view format = tokens.next("format");
  if (format == "PTM_FORMAT_RGB") {
    h.format = PtmFormat::kRGB;
  } else if (format == "PTM_FORMAT_LRGB") {
    h.format = PtmFormat::kLRGB;
  } else if (format == "PTM_FORMAT_JPEG_RGB") {
    h.format = PtmFormat::kRGB;
    h.compression = PtmCompression::kJpeg;
  } else if (format == "PTM_FORMAT_JPEG_LRGB") {
    h.format = PtmFormat::kLRGB;
    h.compression = PtmCompression::kJpeg;
  } else {
    // PTM 1.2 names PTM_FORMAT_LUM, PTM_FORMAT_PTM_LUT, PTM_FORMAT_PTM_C_LUT and
    // PTM_FORMAT_JPEGLS_RGB/LRGB; anything else is not a format at all.
    const bool named = format.substr(0, 11) == "PTM_FORMAT_";
    throw Error(tokens.at() + ": " +
                unsupported_variant((named ? "format " : "unknown format '") + printable(format) +
                                    (named ? "" : "'")));
  }
  if (h.version == PtmVersion::k1_1 && h.compression != PtmCompression::kNone) {
    throw Error(tokens.at() + ": " + unsupported_variant("PTM_1.1 " + printable(format)));
  }
  if (h.version == PtmVersion::k1_1 && h.format != PtmFormat::kLRGB) {
    throw Error(tokens.at() + ": " +
                unsupported_variant("PTM_1.1 " + std::string(to_string(h.format))));
  }

  auto dimension = [&](const char* what) {
    const std::string_view t = tokens.next(what);
    long long v = 0;
    if (!parse_number(t, &v) || v <= 0) {
      throw Error(tokens.at() + ": " + what + " '" + printable(t) + "' is not a positive integer");
    }
    if (v > kMaxPtmSide) {
      throw Error(tokens.at() + ": " + what + " " + std::string(t) + " is absurd (at most " +
                  std::to_string(kMaxPtmSide) + ")");
    }
    return static_cast<int>(v);
  };
  h.width = dimension("width");
  h.height = dimension("height");
  if (static_cast<std::size_t>(h.width) * static_cast<std::size_t>(h.height) > kMaxPtmTexels) {
    throw Error(tokens.at() + ": size " + std::to_string(h.width) + " x " +
                std::to_string(h.height) + " is absurd");
  }

  for (int i = 0; i < kPtmTerms; ++i) {
    const std::string what = "scale " + std::to_string(i);
    const std::string_view t = tokens.next(what.c_str());
    float s = 0.0f;
    if (!parse_number(t, &s)) {
      throw Error(tokens.at() + ": " + what + " '" + printable(t) + "' is not a number");
    }
    if (!std::isfinite(s) || s == 0.0f) {
      throw Error(tokens.at() + ": " + what + " is " + std::string(t) +
                  "; scales must be finite and non-zero");
    }
    h.quantisation.scales[i] = s;
  }
  for (int i = 0; i < kPtmTerms; ++i) {
    const std::string what = "bias " + std::to_string(i);
    const std::string_view t = tokens.next(what.c_str());
    // Any integer: negative biases exist in the wild (see ptm.h).
    int b = 0;
    if (!parse_number(t, &b) || b < -kMaxPtmBias || b > kMaxPtmBias) {
      throw Error(tokens.at() + ": " + what + " '" + printable(t) + "' is not an integer in -" +
                  std::to_string(kMaxPtmBias) + ".." + std::to_string(kMaxPtmBias));
    }
    h.quantisation.biases[i] = b;
  }
  if (h.compression == PtmCompression::kJpeg) {
    const int n = internal::jpeg_planes(h.format);
    auto integers = [&](const char* what, std::vector<int>* out, int lo, int hi) {
      out->resize(static_cast<std::size_t>(n));
      for (int k = 0; k < n; ++k) {
        const std::string label = std::string(what) + " " + std::to_string(k);
        const std::string_view t = tokens.next(label.c_str());
        int v = 0;
        if (!parse_number(t, &v) || v < lo || v > hi) {
          throw Error(tokens.at() + ": " + label + " '" + printable(t) + "' is not an integer in " +
                      std::to_string(lo) + ".." + std::to_string(hi));
        }
        (*out)[static_cast<std::size_t>(k)] = v;
      }
    };
    auto sizes = [&](const char* what, std::vector<std::size_t>* out) {
      out->resize(static_cast<std::size_t>(n));
      for (int k = 0; k < n; ++k) {
        const std::string label = std::string(what) + " " + std::to_string(k);
        const std::string_view t = tokens.next(label.c_str());
        unsigned long long v = 0;
        if (!parse_number(t, &v) || v > (1ULL << 40)) {
          throw Error(tokens.at() + ": " + label + " '" + printable(t) + "' is not a byte count");
        }
        (*out)[static_cast<std::size_t>(k)] = static_cast<std::size_t>(v);
      }
    };
    {
      const std::string_view t = tokens.next("compression parameter");
      if (!parse_number(t, &h.jpeg.quality)) {
        throw Error(tokens.at() + ": compression parameter '" + printable(t) +
                    "' is not an integer");
      }
    }
    integers("transform", &h.jpeg.transforms, 0, 3);
    integers("motion vector x", &h.jpeg.motion_x, -kMaxPtmSide, kMaxPtmSide);
    integers("motion vector y", &h.jpeg.motion_y, -kMaxPtmSide, kMaxPtmSide);
    integers("plane order", &h.jpeg.order, 0, n - 1);
    integers("reference plane", &h.jpeg.reference, -1, n - 1);
    sizes("JPEG stream size", &h.jpeg.stream_bytes);
    sizes("side information size", &h.jpeg.side_bytes);
  }
  h.header_bytes = tokens.end_of_header();
  return h;
}

std::size_t data_bytes(const Header& h) {
  if (h.compression == PtmCompression::kJpeg) return h.jpeg.data_bytes();
  return static_cast<std::size_t>(h.width) * static_cast<std::size_t>(h.height) *
         static_cast<std::size_t>(internal::bytes_per_texel(h.format));
}

std::size_t data_bytes(PtmFormat format, int width, int height) {
  return static_cast<std::size_t>(width) * static_cast<std::size_t>(height) *
         static_cast<std::size_t>(internal::bytes_per_texel(format));
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
  if (present < expected) {
    throw Error(where(path) + ": binary data truncated: " + std::to_string(h.width) + " x " +
                std::to_string(h.height) + " " + std::string(format_name(h.format, h.compression)) +
                " needs " + std::to_string(expected) + " bytes after the header, found " +
                std::to_string(present));
  }
  if (present > expected) {
    // Not tolerated: a header line too many or a wrong declared size shifts every texel.
    throw Error(where(path) + ": " + std::to_string(present - expected) +
                " bytes after the binary block: " + std::to_string(h.width) + " x " +
                std::to_string(h.height) + " " + std::string(to_string(h.format)) + " needs " +
                std::to_string(expected) +
                " (a damaged file, or a header that does not describe the data)");
  }
  PtmFile f;
  f.version = h.version;
  f.format = h.format;
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
  f.header.assign(bytes.begin(), data_begin);
  // Reuse the read buffer for the data block: no second full-size copy.
  bytes.erase(data_end, bytes.end());
  bytes.erase(bytes.begin(), bytes.begin() + static_cast<std::ptrdiff_t>(h.header_bytes));
  f.data = std::move(bytes);
  return f;
}

void write_ptm_file(const fs::path& path, const PtmFile& file) {
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
          h.format == file.format && h.compression == PtmCompression::kNone &&
          h.width == file.width && h.height == file.height && h.quantisation == file.quantisation) {
        header = file.header;
      }
    } catch (const Error&) {
      // Stale or foreign text: the canonical header is written instead.
    }
  }
  AtomicOutput out(path);
  {
    std::ofstream f(out.temp_path(), std::ios::binary | std::ios::trunc);
    if (!f) throw Error(where(path) + ": cannot open for writing");
    f.write(header.data(), static_cast<std::streamsize>(header.size()));
    const std::vector<std::uint8_t>& block =
        file.compression == PtmCompression::kJpeg ? jpeg_block : file.data;
    f.write(reinterpret_cast<const char*>(block.data()),
            static_cast<std::streamsize>(block.size()));
    f.write(reinterpret_cast<const char*>(file.trailing.data()),
            static_cast<std::streamsize>(file.trailing.size()));
    f.flush();
    if (!f) throw Error(where(path) + ": write failed (disk full?)");
  }
  out.commit();
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
  write_ptm_file(path, file);
  report.path = path;
  report.file_bytes = file.canonical_header().size() + file.data.size();
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
  s.file_bytes_per_texel = internal::bytes_per_texel(file.format);
  const int floats = file.format == PtmFormat::kRGB ? 3 * kPtmTerms : kPtmTerms + 3;
  s.map_bytes_per_texel = floats * static_cast<int>(sizeof(float));
  return s;
}

}  // namespace ptmkit::texture
