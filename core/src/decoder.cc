#include "decoder.h"

#include <algorithm>
#include <vector>

#include <array>
#include <cmath>
#include <cstdio>
#include <fstream>

#include "ptmkit/core/error.h"

namespace fs = std::filesystem;

namespace ptmkit {

std::string_view orientation_name(int orientation) {
  switch (orientation) {
    case 1:
      return "normal";
    case 2:
      return "mirrored left-right";
    case 3:
      return "rotated 180";
    case 4:
      return "mirrored top-bottom";
    case 5:
      return "transposed (mirrored along the main diagonal)";
    case 6:
      return "rotated 90 clockwise to display";
    case 7:
      return "transversed (mirrored along the anti-diagonal)";
    case 8:
      return "rotated 90 counter-clockwise to display";
    default:
      return "unknown";
  }
}

namespace internal {

void check_dimensions(const fs::path& path, long long width, long long height, long long channels) {
  if (width <= 0 || height <= 0 || channels <= 0) {
    throw Error(where(path) + ": image has no pixels (declared " + std::to_string(width) + "x" +
                std::to_string(height) + ", " + std::to_string(channels) + " channels)");
  }
  if (width > kMaxImageSidePx || height > kMaxImageSidePx) {
    throw Error(where(path) + ": declared size " + std::to_string(width) + "x" +
                std::to_string(height) + " exceeds the largest side accepted (" +
                std::to_string(kMaxImageSidePx) + " px)");
  }
  if (width * height > kMaxImagePixels) {
    throw Error(where(path) + ": declared size " + std::to_string(width) + "x" +
                std::to_string(height) + " exceeds the largest image accepted (" +
                std::to_string(kMaxImagePixels) + " pixels)");
  }
  if (channels > 64) {
    throw Error(where(path) + ": declares " + std::to_string(channels) +
                " channels (at most 64 are read)");
  }
}

void damaged_data(const fs::path& path, const DecodeSettings& settings, const std::string& warning,
                  bool* already_warned) {
  if (!settings.allow_damaged) {
    throw Error(where(path) + ": damaged image data: " + excerpt(warning) +
                " (--allow-damaged-images accepts such files with a warning)");
  }
  if (!*already_warned) {
    std::fprintf(stderr, "warning: %s: damaged image data accepted: %s\n", where(path).c_str(),
                 excerpt(warning).c_str());
    *already_warned = true;
  }
}

ImageInfo info_from_header(const Header& h) {
  ImageInfo info;
  const bool swap = h.orientation >= 5 && h.orientation <= 8;
  info.width = swap ? h.height : h.width;
  info.height = swap ? h.width : h.height;
  info.channels = h.channels;
  info.format = h.format;
  info.orientation = h.orientation;
  info.focal_px = h.focal_px;
  info.focal_evidence = h.focal_evidence;
  if (h.has_colour_metadata) {
    info.colour_space = h.colour_space;
    info.colour_from_metadata = true;
    info.colour_evidence = h.colour_evidence;
  } else if (h.format == PixelFormat::kU8) {
    info.colour_space = ColourSpace::kSRGB;
    info.colour_evidence = "8-bit, no colour metadata: sRGB";
  } else {
    info.colour_space = ColourSpace::kLinear;
    info.colour_evidence = std::string(h.format == PixelFormat::kU16 ? "16-bit" : "float") +
                           ", no colour metadata: linear";
  }
  return info;
}

ExifFacts parse_exif(const unsigned char* data, std::size_t size) {
  ExifFacts facts;
  if (size < 8) return facts;
  bool little = false;
  if (data[0] == 'I' && data[1] == 'I') {
    little = true;
  } else if (!(data[0] == 'M' && data[1] == 'M')) {
    return facts;
  }
  const auto u16 = [&](std::size_t at) -> unsigned {
    if (at + 2 > size) return 0;
    return little ? data[at] | (data[at + 1] << 8) : (data[at] << 8) | data[at + 1];
  };
  const auto u32 = [&](std::size_t at) -> std::size_t {
    if (at + 4 > size) return 0;
    const std::uint32_t v = little ? data[at] | (data[at + 1] << 8) | (data[at + 2] << 16) |
                                         (static_cast<std::uint32_t>(data[at + 3]) << 24)
                                   : (static_cast<std::uint32_t>(data[at]) << 24) |
                                         (data[at + 1] << 16) | (data[at + 2] << 8) | data[at + 3];
    return v;
  };
  if (u16(2) != 42) return facts;
  // Walks one IFD; returns the EXIF sub-IFD's offset (0 if none).
  const auto walk = [&](std::size_t ifd, bool top) -> std::size_t {
    if (ifd < 8 || ifd + 2 > size) return 0;
    const unsigned entries = u16(ifd);
    std::size_t sub = 0;
    for (unsigned e = 0; e < entries && e < 1000; ++e) {
      const std::size_t at = ifd + 2 + 12 * static_cast<std::size_t>(e);
      if (at + 12 > size) break;
      const unsigned tag = u16(at);
      const unsigned type = u16(at + 2);
      const std::size_t count = u32(at + 4);
      // An integer held in the entry (SHORT, or LONG), or -1.
      const auto integer = [&]() -> long {
        if (count != 1) return -1;
        if (type == 3) return static_cast<long>(u16(at + 8));
        if (type == 4) return static_cast<long>(u32(at + 8));
        return -1;
      };
      // An unsigned RATIONAL (stored at an offset), or 0 when malformed.
      const auto rational = [&]() -> double {
        if (type != 5 || count != 1) return 0.0;
        const std::size_t off = u32(at + 8);
        if (off < 8 || off + 8 > size) return 0.0;
        const double num = static_cast<double>(u32(off)), den = static_cast<double>(u32(off + 4));
        return den > 0.0 ? num / den : 0.0;
      };
      if (top && tag == 0x0112 && type == 3) {
        const unsigned v = u16(at + 8);
        if (v >= 1 && v <= 8) facts.orientation = static_cast<int>(v);
      } else if (top && tag == 0x8769) {
        sub = u32(at + 8);
      } else if (top) {
        continue;
      } else if (tag == 0xA001 && type == 3) {
        facts.colour_space_tag = static_cast<int>(u16(at + 8));
      } else if (tag == 0x920A) {
        facts.focal_mm = rational();
      } else if (tag == 0xA20E) {
        facts.focal_plane_x_res = rational();
      } else if (tag == 0xA210 && integer() >= 0) {
        facts.focal_plane_unit = static_cast<int>(integer());
      } else if (tag == 0xA002 && integer() >= 0) {
        facts.pixel_x_dimension = integer();
      } else if (tag == 0xA405 && integer() >= 0) {
        facts.focal_35mm = static_cast<double>(integer());
      }
    }
    return sub;
  };
  const std::size_t sub = walk(u32(4), true);
  if (sub != 0 && sub != u32(4)) walk(sub, false);
  return facts;
}

double exif_focal_px(const ExifFacts& exif, int stored_width, int stored_height,
                     std::string* evidence) {
  char text[160];
  if (exif.focal_mm > 0.0 && exif.focal_plane_x_res > 0.0 && stored_width > 0) {
    double unit_mm = 0.0;
    switch (exif.focal_plane_unit) {
      case 2:
        unit_mm = 25.4;
        break;
      case 3:
        unit_mm = 10.0;
        break;
      case 4:
        unit_mm = 1.0;
        break;
      case 5:
        unit_mm = 0.001;
        break;
      default:
        break;
    }
    if (unit_mm > 0.0) {
      // The pitch is the recorded width's; a smaller stored copy has larger pixels.
      double px_per_mm = exif.focal_plane_x_res / unit_mm;
      if (exif.pixel_x_dimension > 0) {
        px_per_mm *=
            static_cast<double>(stored_width) / static_cast<double>(exif.pixel_x_dimension);
      }
      const double sensor_mm = stored_width / px_per_mm;
      if (sensor_mm >= 1.0 && sensor_mm <= 100.0) {
        std::snprintf(text, sizeof text,
                      "EXIF FocalLength %.4g mm, FocalPlaneXResolution (sensor %.2f mm wide)",
                      exif.focal_mm, sensor_mm);
        if (evidence != nullptr) *evidence = text;
        return exif.focal_mm * px_per_mm;
      }
    }
  }
  if (exif.focal_35mm > 0.0 && stored_width > 0 && stored_height > 0) {
    const double diagonal_px =
        std::hypot(static_cast<double>(stored_width), static_cast<double>(stored_height));
    std::snprintf(text, sizeof text, "EXIF FocalLengthIn35mmFilm %.0f mm (over the diagonal)",
                  exif.focal_35mm);
    if (evidence != nullptr) *evidence = text;
    return exif.focal_35mm * diagonal_px / std::hypot(36.0, 24.0);
  }
  return 0.0;
}

std::unique_ptr<Decoder> open_decoder(const fs::path& path, const DecodeSettings& settings) {
  std::error_code ec;
  const auto status = fs::status(path, ec);
  if (ec || !fs::exists(status)) throw Error(where(path) + ": image file not found");
  if (!fs::is_regular_file(status)) {
    throw Error(where(path) + ": not a regular file (images are read from regular files only)");
  }
  const std::uintmax_t bytes = fs::file_size(path, ec);
  if (ec) throw Error(where(path) + ": cannot read image: " + ec.message());
  std::array<unsigned char, 8> magic{};
  {
    std::ifstream in(path, std::ios::binary);
    if (!in) throw Error(where(path) + ": cannot open image file");
    in.read(reinterpret_cast<char*>(magic.data()), magic.size());
  }
  if (bytes < 8) {
    throw Error(where(path) + ": not an image (" + std::to_string(bytes) + " bytes)");
  }
  // A start-of-image marker is a JPEG to libjpeg, whatever follows (it skips stray bytes
  // before the next marker with a warning), so such a file gets the bounded decoder: handed to
  // OpenImageIO, its header alone could make libjpeg allocate gigabytes.
  if (magic[0] == 0xFF && magic[1] == 0xD8) {
    if (auto d = open_jpeg(path, bytes, settings)) return d;
    return open_oiio(path, settings);  // CMYK and YCCK
  }
  static constexpr std::array<unsigned char, 8> kPng{0x89, 'P', 'N', 'G', '\r', '\n', 0x1A, '\n'};
  if (magic == kPng) return open_png(path, bytes, settings);
  const bool tiff = (magic[0] == 'I' && magic[1] == 'I' && magic[2] == 42 && magic[3] == 0) ||
                    (magic[0] == 'M' && magic[1] == 'M' && magic[2] == 0 && magic[3] == 42);
  if (tiff) {
    if (auto d = open_tiff(path, bytes, settings)) return d;
  }
  if (magic[0] == 0x76 && magic[1] == 0x2F && magic[2] == 0x31 && magic[3] == 0x01) {
    check_exr_header(path, bytes);
  }
  return open_oiio(path, settings);
}

void Decoder::skip_rows(int rows) {
  std::vector<unsigned char> scratch(row_bytes() * static_cast<std::size_t>(std::min(rows, 64)));
  while (rows > 0) {
    const int n = std::min(rows, 64);
    read_rows(n, scratch.data());
    rows -= n;
  }
}

}  // namespace internal
}  // namespace ptmkit
