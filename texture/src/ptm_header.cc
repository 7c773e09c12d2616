// The .ptm header text: parsing it (with the wording of errors for damaged or foreign files),
// and the canonical header a writer produces.
#include "ptm_header.h"

#include <cctype>
#include <charconv>
#include <string>
#include <string_view>
#include <system_error>
#include <vector>

#include "ptmkit/core/error.h"
#include "ptmkit/texture/formats.h"

namespace fs = std::filesystem;

namespace ptmkit::texture {

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

}  // namespace

namespace internal {

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
  } else if (format == "PTM_FORMAT_LUM") {
    // One luminance polynomial per texel and no colour: an LRGB file whose colour is white.
    h.format = PtmFormat::kLRGB;
    h.luminance_only = true;
  } else if (format == "PTM_FORMAT_JPEG_RGB") {
    h.format = PtmFormat::kRGB;
    h.compression = PtmCompression::kJpeg;
  } else if (format == "PTM_FORMAT_JPEG_LRGB") {
    h.format = PtmFormat::kLRGB;
    h.compression = PtmCompression::kJpeg;
  } else {
    // PTM 1.2 also names PTM_FORMAT_PTM_LUT, PTM_FORMAT_PTM_C_LUT and
    // PTM_FORMAT_JPEGLS_RGB/LRGB; anything else is not a format at all.
    const bool named = format.substr(0, 11) == "PTM_FORMAT_";
    throw Error(tokens.at() + ": " +
                unsupported_variant((named ? "format " : "unknown format '") + printable(format) +
                                    (named ? "" : "'")));
  }
  // PTM 1.1 has one layout: LRGB, interleaved.
  if (h.version == PtmVersion::k1_1 && (h.compression != PtmCompression::kNone ||
                                        h.format != PtmFormat::kLRGB || h.luminance_only)) {
    throw Error(tokens.at() + ": " + unsupported_variant("PTM_1.1 " + printable(format)));
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

}  // namespace internal

}  // namespace ptmkit::texture
