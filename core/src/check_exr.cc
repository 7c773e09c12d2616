// Bounds an OpenEXR file's header before OpenEXR reads it. OpenEXR trusts what the header
// declares: a string attribute declaring 2 GB in a 1 kB file is allocated before a byte of it is
// read, and the chunk offset table is sized from the data window. Both are checked here against
// the file's size, and the data window against the limits every image meets.
#include <algorithm>
#include <array>
#include <cstdint>
#include <fstream>
#include <string>
#include <utility>
#include <vector>

#include "decoder.h"
#include "ptmkit/core/error.h"

namespace fs = std::filesystem;

namespace ptmkit::internal {
namespace {

constexpr std::uint32_t kTiledFlag = 0x200;
constexpr std::uint32_t kLongNamesFlag = 0x400;
constexpr std::uint32_t kDeepFlag = 0x800;
constexpr std::uint32_t kMultipartFlag = 0x1000;

// Scan lines per chunk for each compression (the OpenEXR file layout's table); -1: unknown.
int lines_per_chunk(int compression) {
  static constexpr std::array<int, 10> kLines{1, 1, 1, 16, 32, 16, 32, 32, 32, 256};
  return compression >= 0 && compression < static_cast<int>(kLines.size()) ? kLines[compression]
                                                                           : -1;
}

// The size of OpenEXR's fixed-size attribute types, -1 for the others.
int fixed_size(const std::string& type) {
  static const std::array<std::pair<const char*, int>, 24> kSizes{{{"box2i", 16},
                                                                   {"box2f", 16},
                                                                   {"compression", 1},
                                                                   {"lineOrder", 1},
                                                                   {"envmap", 1},
                                                                   {"deepImageState", 1},
                                                                   {"int", 4},
                                                                   {"float", 4},
                                                                   {"double", 8},
                                                                   {"v2i", 8},
                                                                   {"v2f", 8},
                                                                   {"v2d", 16},
                                                                   {"v3i", 12},
                                                                   {"v3f", 12},
                                                                   {"v3d", 24},
                                                                   {"m33f", 36},
                                                                   {"m33d", 72},
                                                                   {"m44f", 64},
                                                                   {"m44d", 128},
                                                                   {"rational", 8},
                                                                   {"timecode", 8},
                                                                   {"keycode", 28},
                                                                   {"chromaticities", 32},
                                                                   {"tiledesc", 9}}};
  for (const auto& [name, size] : kSizes) {
    if (type == name) return size;
  }
  return -1;
}

struct Part {
  bool has_window = false;
  std::int32_t xmin = 0, ymin = 0, xmax = 0, ymax = 0;
  int compression = 0;
  bool has_tiles = false;
  std::uint32_t tile_x = 0, tile_y = 0;
  std::string type;          // "scanlineimage", "tiledimage", "deepscanline", "deeptile"
  std::int64_t chunks = -1;  // the chunkCount attribute (multi-part files), -1 if absent
};

class HeaderReader {
 public:
  HeaderReader(const fs::path& path, std::uintmax_t bytes)
      : path_(path), bytes_(bytes), in_(path, std::ios::binary) {
    if (!in_) throw Error(where(path) + ": cannot open image file");
  }

  [[noreturn]] void fail(const std::string& what) const {
    throw Error(where(path_) + ": malformed OpenEXR header: " + what);
  }

  std::uintmax_t position() const { return pos_; }

  void read(void* out, std::size_t n) {
    if (n > bytes_ - pos_) fail("it ends inside the header (" + std::to_string(bytes_) + " bytes)");
    in_.read(static_cast<char*>(out), static_cast<std::streamsize>(n));
    if (!in_) fail("cannot read it");
    pos_ += n;
  }
  std::uint32_t u32() {
    std::array<unsigned char, 4> b{};
    read(b.data(), b.size());
    return static_cast<std::uint32_t>(b[0]) | static_cast<std::uint32_t>(b[1]) << 8 |
           static_cast<std::uint32_t>(b[2]) << 16 | static_cast<std::uint32_t>(b[3]) << 24;
  }
  std::int32_t i32() { return static_cast<std::int32_t>(u32()); }
  // A NUL-terminated name of at most `max_chars` characters.
  std::string name(std::size_t max_chars, const char* what) {
    std::string s;
    for (;;) {
      char c = 0;
      read(&c, 1);
      if (c == '\0') return s;
      if (s.size() == max_chars) {
        fail(std::string(what) + " longer than " + std::to_string(max_chars) + " characters");
      }
      s.push_back(c);
    }
  }
  void skip(std::uintmax_t n) {
    if (n > bytes_ - pos_) fail("it ends inside the header (" + std::to_string(bytes_) + " bytes)");
    in_.seekg(static_cast<std::streamoff>(n), std::ios::cur);
    if (!in_) fail("cannot read it");
    pos_ += n;
  }

  // One header: attributes up to the empty name. Returns false when the header is empty (the
  // end of a multi-part file's header list).
  bool part(std::size_t max_name, Part* out) {
    bool any = false;
    for (;;) {
      const std::string attr = name(max_name, "an attribute name");
      if (attr.empty()) return any;
      any = true;
      const std::string type = name(max_name, "an attribute type");
      const std::int32_t size = i32();
      if (size < 0 || static_cast<std::uintmax_t>(size) > bytes_ - pos_) {
        fail("attribute '" + excerpt(attr) + "' declares " + std::to_string(size) +
             " bytes, but the file has " + std::to_string(bytes_ - pos_) + " left");
      }
      // OpenEXR reads these types by their content, not by the declared size: a size that
      // disagrees with the content would put its reading and this walk out of step.
      if (const int fixed = fixed_size(type); fixed >= 0 && size != fixed) {
        fail("attribute '" + excerpt(attr) + "' of type " + excerpt(type) + " declares " +
             std::to_string(size) + " bytes; that type has " + std::to_string(fixed));
      }
      if (type == "chlist") {
        channel_list(attr, static_cast<std::uint32_t>(size), max_name);
      } else if (type == "preview") {
        if (size < 8) fail("preview attribute '" + excerpt(attr) + "' shorter than its header");
        const std::uint64_t w = u32();
        const std::uint64_t h = u32();
        if (w * h * 4 != static_cast<std::uint64_t>(size) - 8) {
          fail("preview attribute '" + excerpt(attr) + "' declares " + std::to_string(w) + "x" +
               std::to_string(h) + " pixels in " + std::to_string(size) + " bytes");
        }
        skip(static_cast<std::uintmax_t>(size) - 8);
      } else if (attr == "dataWindow" && type == "box2i") {
        out->has_window = true;
        out->xmin = i32();
        out->ymin = i32();
        out->xmax = i32();
        out->ymax = i32();
      } else if (attr == "compression" && type == "compression") {
        unsigned char c = 0;
        read(&c, 1);
        out->compression = c;
      } else if (attr == "tiles" && type == "tiledesc") {
        out->has_tiles = true;
        out->tile_x = u32();
        out->tile_y = u32();
        skip(1);
      } else if (attr == "type" && type == "string") {
        out->type.resize(static_cast<std::size_t>(size));
        read(out->type.data(), out->type.size());
      } else if (attr == "chunkCount" && type == "int") {
        out->chunks = i32();
      } else {
        skip(static_cast<std::uintmax_t>(size));
      }
    }
  }

  // A channel list: (name, 16 bytes of type, linearity, sampling) per channel, then an empty
  // name, exactly filling `size` bytes.
  void channel_list(const std::string& attr, std::uint32_t size, std::size_t max_name) {
    const std::uintmax_t end = pos_ + size;
    for (int channels = 0;; ++channels) {
      if (pos_ >= end) fail("channel list '" + excerpt(attr) + "' runs past its declared size");
      const std::string channel = name(max_name, "a channel name");
      if (channel.empty()) break;
      if (channels == 1024) fail("more than 1024 channels");
      skip(16);
    }
    if (pos_ != end) fail("channel list '" + excerpt(attr) + "' does not fill its declared size");
  }

 private:
  fs::path path_;
  std::uintmax_t bytes_;
  std::ifstream in_;
  std::uintmax_t pos_ = 0;
};

std::uint64_t ceil_div(std::uint64_t a, std::uint64_t b) { return (a + b - 1) / b; }

}  // namespace

void check_exr_header(const fs::path& path, std::uintmax_t bytes) {
  HeaderReader r(path, bytes);
  r.skip(4);  // the magic number, checked by the caller
  const std::uint32_t version = r.u32();
  if ((version & 0xFF) != 2) {
    r.fail("version " + std::to_string(version & 0xFF) + " (only version 2 exists)");
  }
  const std::size_t max_name = (version & kLongNamesFlag) != 0 ? 255 : 31;
  const bool multipart = (version & kMultipartFlag) != 0;
  std::vector<Part> parts;
  for (;;) {
    Part p;
    if (!r.part(max_name, &p)) break;
    parts.push_back(p);
    if (!multipart) break;
    if (parts.size() > 10000) r.fail("more than 10000 parts");
  }
  if (parts.empty()) r.fail("no header");
  if ((version & kDeepFlag) != 0 || parts[0].type.rfind("deep", 0) == 0) {
    throw Error(where(path) +
                ": a deep OpenEXR image (a varying number of samples per pixel) "
                "is not a photograph ptmkit can fit");
  }
  // Every part's chunk offset table follows the headers, 8 bytes per chunk.
  std::uint64_t table_bytes = 0;
  for (const Part& p : parts) {
    if (!p.has_window) r.fail("no dataWindow attribute");
    const long long width = static_cast<long long>(p.xmax) - p.xmin + 1;
    const long long height = static_cast<long long>(p.ymax) - p.ymin + 1;
    check_dimensions(path, width, height, 1);
    std::uint64_t chunks = 0;
    const bool tiled =
        p.has_tiles && (multipart ? p.type == "tiledimage" : (version & kTiledFlag) != 0);
    if (tiled) {
      if (p.tile_x == 0 || p.tile_y == 0) r.fail("a tile size of zero");
      // The full-resolution level alone; mip and rip levels only add chunks.
      chunks = ceil_div(static_cast<std::uint64_t>(width), p.tile_x) *
               ceil_div(static_cast<std::uint64_t>(height), p.tile_y);
    } else {
      const int lines = lines_per_chunk(p.compression);
      if (lines < 0) r.fail("unknown compression " + std::to_string(p.compression));
      chunks = ceil_div(static_cast<std::uint64_t>(height), static_cast<std::uint64_t>(lines));
    }
    if (p.chunks >= 0)
      chunks = std::max<std::uint64_t>(chunks, static_cast<std::uint64_t>(p.chunks));
    table_bytes += chunks * 8;
  }
  // Each chunk also holds at least its offset's worth of data; the table alone must fit.
  if (table_bytes > bytes - r.position()) {
    throw Error(where(path) + ": the OpenEXR header declares " + std::to_string(table_bytes / 8) +
                " chunks, which this " + std::to_string(bytes) +
                "-byte file cannot hold (truncated or damaged)");
  }
}

}  // namespace ptmkit::internal
