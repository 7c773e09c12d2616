// PNG through libpng: palettes and sub-byte grey expanded to 8 bits, transparency to an alpha
// channel, 16-bit samples in the machine's byte order (as OpenImageIO's PNG reader gives them).
#include <csetjmp>
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <string>
#include <vector>

#include <png.h>

#include "decoder.h"
#include "ptmkit/core/error.h"

namespace fs = std::filesystem;

namespace ptmkit::internal {

namespace {

struct PngMessages {
  char error[256] = {};
  char warning[256] = {};
  int warnings = 0;
};

[[noreturn]] void on_error(png_structp png, png_const_charp msg) {
  auto* m = static_cast<PngMessages*>(png_get_error_ptr(png));
  std::snprintf(m->error, sizeof(m->error), "%s", msg);
  png_longjmp(png, 1);
}

// libpng's warnings are mostly about ancillary chunks (an sRGB profile it knows to be
// slightly off, an unknown chunk); the image data is intact, so they are not errors.
void on_warning(png_structp png, png_const_charp msg) {
  auto* m = static_cast<PngMessages*>(png_get_error_ptr(png));
  if (m->warnings++ == 0) std::snprintf(m->warning, sizeof(m->warning), "%s", msg);
}

class PngDecoder final : public Decoder {
 public:
  PngDecoder(fs::path path, const DecodeSettings& settings)
      : path_(std::move(path)), settings_(settings) {}
  ~PngDecoder() override {
    if (png_ != nullptr) png_destroy_read_struct(&png_, &info_, nullptr);
    if (file_ != nullptr) std::fclose(file_);
  }
  PngDecoder(const PngDecoder&) = delete;
  PngDecoder& operator=(const PngDecoder&) = delete;

  void open(std::uintmax_t file_bytes) {
    file_ = std::fopen(path_.c_str(), "rb");
    if (file_ == nullptr) throw Error(where(path_) + ": cannot open image file");
    check_chunk_lengths(file_bytes);
    png_ = png_create_read_struct(PNG_LIBPNG_VER_STRING, &messages_, on_error, on_warning);
    if (png_ == nullptr) throw Error(where(path_) + ": cannot start the PNG reader");
    info_ = png_create_info_struct(png_);
    if (info_ == nullptr) throw Error(where(path_) + ": cannot start the PNG reader");
    // Checksum errors in the image data are damage: an error, or accepted on request.
    if (settings_.allow_damaged) {
      png_set_crc_action(png_, PNG_CRC_WARN_USE, PNG_CRC_WARN_USE);
    }
    // libpng's own limits are tighter than ours for width; ours bound both.
    png_set_user_limits(png_, static_cast<png_uint_32>(kMaxImageSidePx),
                        static_cast<png_uint_32>(kMaxImageSidePx));
    // Decompressed ancillary chunks (zTXt, iTXt, iCCP) need no more than 16 MiB.
    png_set_chunk_malloc_max(png_, static_cast<png_alloc_size_t>(16u << 20));
    if (!read_info()) fail("not a readable PNG");
    const png_uint_32 w = png_get_image_width(png_, info_);
    const png_uint_32 h = png_get_image_height(png_, info_);
    const int colour_type = png_get_color_type(png_, info_);
    const int depth = png_get_bit_depth(png_, info_);
    const int file_channels = png_get_channels(png_, info_);
    check_dimensions(path_, w, h, file_channels);
    // zlib compresses at most about 1032:1; image data beyond that cannot be in the file.
    const std::uintmax_t raw =
        static_cast<std::uintmax_t>(h) *
        (1 + (static_cast<std::uintmax_t>(w) * file_channels * depth + 7) / 8);
    if (raw > 1040 * file_bytes + (1u << 16)) {
      throw Error(where(path_) + ": declares " + std::to_string(w) + "x" + std::to_string(h) +
                  " pixels but its " + std::to_string(file_bytes) +
                  " bytes cannot hold that many even at zlib's highest ratio");
    }
    png_set_expand(png_);  // palette -> RGB, grey < 8 bits -> 8, tRNS -> alpha
    if (depth == 16) png_set_swap(png_);
    interlaced_ = png_get_interlace_type(png_, info_) != PNG_INTERLACE_NONE;
    if (interlaced_) png_set_interlace_handling(png_);
    if (!update_info()) fail("cannot read PNG header");
    header_.width = static_cast<int>(w);
    header_.height = static_cast<int>(h);
    header_.channels = png_get_channels(png_, info_);
    header_.format = depth == 16 ? PixelFormat::kU16 : PixelFormat::kU8;
    header_.codec = "png";
    (void)colour_type;
    if (png_get_valid(png_, info_, PNG_INFO_sRGB) != 0) {
      set_colour(ColourSpace::kSRGB, "PNG sRGB chunk");
    } else if (png_get_valid(png_, info_, PNG_INFO_iCCP) != 0) {
      set_colour(ColourSpace::kSRGB, "PNG ICC profile (taken as sRGB-like encoded)");
    } else if (png_fixed_point g = 0; png_get_gAMA_fixed(png_, info_, &g) != 0 && g > 0) {
      // gAMA holds the encoding exponent x 100000: 100000 is linear, 45455 is the usual 1/2.2.
      if (g > 90000) {
        set_colour(ColourSpace::kLinear, "PNG gAMA 1.0");
      } else {
        set_colour(ColourSpace::kSRGB, "PNG gAMA " + std::to_string(g / 100000.0).substr(0, 6));
      }
    }
#ifdef PNG_eXIf_SUPPORTED
    png_bytep exif = nullptr;
    png_uint_32 exif_bytes = 0;
    if (png_get_eXIf_1(png_, info_, &exif_bytes, &exif) != 0 && exif != nullptr) {
      const ExifFacts facts = parse_exif(exif, exif_bytes);
      header_.orientation = facts.orientation;
      header_.focal_px =
          exif_focal_px(facts, header_.width, header_.height, &header_.focal_evidence);
    }
#endif
  }

  void read_rows(int rows, void* out) override {
    auto* dst = static_cast<unsigned char*>(out);
    const std::size_t stride = row_bytes();
    if (interlaced_) {
      // Interlaced images arrive in passes over the whole image: decoded whole, once.
      if (whole_.empty()) {
        whole_.resize(stride * static_cast<std::size_t>(header_.height));
        if (!read_all()) fail("cannot decode");
      }
      std::memcpy(dst, whole_.data() + stride * static_cast<std::size_t>(next_row_),
                  stride * static_cast<std::size_t>(rows));
      next_row_ += rows;
      return;
    }
    for (int r = 0; r < rows; ++r) {
      if (!read_row(dst + stride * static_cast<std::size_t>(r))) fail("cannot decode");
    }
    next_row_ += rows;
    if (messages_.warnings > 0 && settings_.allow_damaged &&
        std::strstr(messages_.warning, "CRC")) {
      damaged_data(path_, settings_, messages_.warning, &warned_);
    }
  }

  // libpng allocates (and clears) an ancillary chunk - text, an ICC profile - at the length
  // its header declares before reading it: a 339-byte file declaring a 1.6 GB tEXt chunk cost
  // 1.6 GB. Every chunk before the image data is walked first and must lie inside the file.
  // The image data (IDAT) is streamed, so a cut-short file still reaches libpng, which
  // reports it as damaged.
  void check_chunk_lengths(std::uintmax_t file_bytes) const {
    std::FILE* f = file_;
    std::uintmax_t pos = 8;
    std::string problem;
    while (pos + 8 <= file_bytes && std::fseek(f, static_cast<long>(pos), SEEK_SET) == 0) {
      unsigned char h[8];
      if (std::fread(h, 1, 8, f) != 8) break;
      const std::uint32_t length = static_cast<std::uint32_t>(h[0]) << 24 |
                                   static_cast<std::uint32_t>(h[1]) << 16 |
                                   static_cast<std::uint32_t>(h[2]) << 8 | h[3];
      const std::string type(reinterpret_cast<const char*>(h + 4), 4);
      if (type == "IDAT" || type == "IEND") break;
      if (length > file_bytes - pos - 8 || file_bytes - pos - 8 - length < 4) {
        problem = "its " + excerpt(type) + " chunk declares " + std::to_string(length) +
                  " bytes but the file has " + std::to_string(file_bytes - pos - 8) + " left";
        break;
      }
      pos += 12 + static_cast<std::uintmax_t>(length);
    }
    if (!problem.empty()) throw Error(where(path_) + ": not a readable PNG: " + problem);
    if (std::fseek(f, 0, SEEK_SET) != 0) throw Error(where(path_) + ": cannot read image file");
  }

 private:
  void set_colour(ColourSpace space, std::string evidence) {
    header_.has_colour_metadata = true;
    header_.colour_space = space;
    header_.colour_evidence = std::move(evidence);
  }
  bool read_info() {
    if (setjmp(png_jmpbuf(png_)) != 0) return false;
    png_init_io(png_, file_);
    png_read_info(png_, info_);
    return true;
  }
  bool update_info() {
    if (setjmp(png_jmpbuf(png_)) != 0) return false;
    png_read_update_info(png_, info_);
    return true;
  }
  bool read_row(unsigned char* row) {
    if (setjmp(png_jmpbuf(png_)) != 0) return false;
    png_read_row(png_, row, nullptr);
    return true;
  }
  bool read_all() {
    if (setjmp(png_jmpbuf(png_)) != 0) return false;
    const std::size_t stride = row_bytes();
    const int passes = png_set_interlace_handling(png_);
    for (int p = 0; p < passes; ++p) {
      for (int y = 0; y < header_.height; ++y) {
        png_read_row(png_, whole_.data() + stride * static_cast<std::size_t>(y), nullptr);
      }
    }
    return true;
  }
  [[noreturn]] void fail(const char* what) {
    std::string why = messages_.error;
    // libpng's words for data that ends early.
    if (why.find("Read Error") != std::string::npos ||
        why.find("Not enough") != std::string::npos) {
      why += " (the file is truncated)";
    }
    throw Error(where(path_) + ": " + what + ": " + excerpt(why));
  }

  fs::path path_;
  DecodeSettings settings_;
  PngMessages messages_;
  png_structp png_ = nullptr;
  png_infop info_ = nullptr;
  std::FILE* file_ = nullptr;
  bool interlaced_ = false;
  bool warned_ = false;
  int next_row_ = 0;
  std::vector<unsigned char> whole_;
};

}  // namespace

std::unique_ptr<Decoder> open_png(const fs::path& path, std::uintmax_t file_bytes,
                                  const DecodeSettings& settings) {
  auto d = std::make_unique<PngDecoder>(path, settings);
  d->open(file_bytes);
  return d;
}

}  // namespace ptmkit::internal
