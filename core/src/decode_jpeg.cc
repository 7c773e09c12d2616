// JPEG through libjpeg(-turbo)'s own API: the library's default decoding (accurate integer
// IDCT, fancy upsampling), which is what OpenImageIO's JPEG reader uses, so the decoded bytes
// are the ones OpenImageIO gave (checked by a test where OpenImageIO is available).
#include <csetjmp>
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <string>

#include <jpeglib.h>

#include "decoder.h"
#include "ptmkit/core/error.h"
#include "ptmkit/core/limits.h"

namespace fs = std::filesystem;

namespace ptmkit::internal {

namespace {

struct JpegErrors {
  jpeg_error_mgr pub;
  std::jmp_buf jump;
  char error[JMSG_LENGTH_MAX];
  char warning[JMSG_LENGTH_MAX];
  int warnings = 0;
};

// Scans one progressive JPEG may have. Each scan walks the whole coefficient buffer, so a
// small file of many near-empty scans costs time out of all proportion to its size. Libjpeg's
// standard progression has 10 scans; libjpeg-turbo's own tools offer a cut-off like this one.
constexpr int kMaxJpegScans = 500;

struct JpegProgress {
  jpeg_progress_mgr pub;
  JpegErrors* errors = nullptr;
  // Where damaged data is an error, decoding stops at the first warning: a JPEG of several
  // scans is otherwise read to its end (libjpeg completes a cut-short file with empty scans)
  // before jpeg_start_decompress returns and the warning can be seen.
  bool stop_at_warning = false;
  bool stopped_at_warning = false;
};

void on_progress(j_common_ptr cinfo) {
  auto* p = reinterpret_cast<JpegProgress*>(cinfo->progress);
  if (p->stop_at_warning && p->errors->warnings > 0) {
    p->stopped_at_warning = true;
    std::longjmp(p->errors->jump, 1);
  }
  const int scan = reinterpret_cast<j_decompress_ptr>(cinfo)->input_scan_number;
  if (scan > kMaxJpegScans) {
    std::snprintf(p->errors->error, sizeof(p->errors->error),
                  "more than %d scans (a standard progressive JPEG has 10)", kMaxJpegScans);
    std::longjmp(p->errors->jump, 1);
  }
}

[[noreturn]] void on_error(j_common_ptr cinfo) {
  auto* e = reinterpret_cast<JpegErrors*>(cinfo->err);
  cinfo->err->format_message(cinfo, e->error);
  std::longjmp(e->jump, 1);
}

// Level -1 is a warning (damaged data the library repaired); others are trace messages.
void on_message(j_common_ptr cinfo, int level) {
  if (level >= 0) return;
  auto* e = reinterpret_cast<JpegErrors*>(cinfo->err);
  if (e->warnings++ == 0) cinfo->err->format_message(cinfo, e->warning);
}

class JpegDecoder final : public Decoder {
 public:
  JpegDecoder(fs::path path, const DecodeSettings& settings)
      : path_(std::move(path)), settings_(settings) {
    std::memset(&cinfo_, 0, sizeof(cinfo_));
  }
  ~JpegDecoder() override {
    if (created_) jpeg_destroy_decompress(&cinfo_);
    if (file_ != nullptr) std::fclose(file_);
  }
  JpegDecoder(const JpegDecoder&) = delete;
  JpegDecoder& operator=(const JpegDecoder&) = delete;

  // A file shorter than the fewest bytes its declared pixels can be coded in is refused before
  // decoding: libjpeg would otherwise decode it to its declared size, filling what is missing.
  void require_bytes(std::uintmax_t file_bytes, std::uintmax_t needed) const {
    if (file_bytes >= needed) return;
    throw Error(where(path_) + ": declares " + std::to_string(cinfo_.image_width) + "x" +
                std::to_string(cinfo_.image_height) + " pixels but its " +
                std::to_string(file_bytes) + " bytes cannot hold that many (at least " +
                std::to_string(needed) + " needed)");
  }

  // Returns false for colour models the direct path does not convert (CMYK, YCCK).
  bool open(std::uintmax_t file_bytes) {
    file_ = std::fopen(path_.c_str(), "rb");
    if (file_ == nullptr) throw Error(where(path_) + ": cannot open image file");
    cinfo_.err = jpeg_std_error(&errors_.pub);
    errors_.pub.error_exit = on_error;
    errors_.pub.emit_message = on_message;
    progress_.pub.progress_monitor = on_progress;
    progress_.errors = &errors_;
    progress_.stop_at_warning = !settings_.allow_damaged;
    if (!start()) fail("cannot read JPEG header");
    check_dimensions(path_, cinfo_.image_width, cinfo_.image_height, cinfo_.num_components);
    // A progressive Huffman-coded JPEG codes every block of a component in that component's
    // first DC scan, in at least one bit.
    if (cinfo_.progressive_mode && !cinfo_.arith_code) {
      const jpeg_component_info& c = cinfo_.comp_info[0];
      const std::uintmax_t blocks =
          static_cast<std::uintmax_t>(c.width_in_blocks) * c.height_in_blocks;
      require_bytes(file_bytes, blocks / 8);
    }
    // A JPEG of several scans (progressive, or components in separate scans) is decoded into
    // a buffer of every coefficient of the image before the first row comes out: 128 bytes
    // per 8x8 block of each component, which libjpeg allocates in jpeg_start_decompress.
    if (jpeg_has_multiple_scans(&cinfo_)) {
      std::uint64_t bytes = 0;
      for (int k = 0; k < cinfo_.num_components; ++k) {
        const jpeg_component_info& c = cinfo_.comp_info[k];
        const std::uint64_t across =
            (c.width_in_blocks + c.h_samp_factor - 1ULL) / c.h_samp_factor * c.h_samp_factor;
        const std::uint64_t down =
            (c.height_in_blocks + c.v_samp_factor - 1ULL) / c.v_samp_factor * c.v_samp_factor;
        bytes += across * down * sizeof(JBLOCK);
      }
      check_allocation(path_, bytes,
                       "the coefficients of this " + std::to_string(cinfo_.image_width) + "x" +
                           std::to_string(cinfo_.image_height) +
                           " JPEG of several scans (decoded whole before its first row)");
    }
    // A Huffman-coded sequential JPEG spends at least 2 bits (a DC code and an end-of-block
    // code) on each 8x8 luminance block; a file too short for that declares more than it holds.
    if (!cinfo_.progressive_mode && !cinfo_.arith_code) {
      const std::uintmax_t blocks =
          ((cinfo_.image_width + 7ULL) / 8) * ((cinfo_.image_height + 7ULL) / 8);
      require_bytes(file_bytes, blocks / 4);
    }
    if (cinfo_.jpeg_color_space == JCS_CMYK || cinfo_.jpeg_color_space == JCS_YCCK) return false;
    if (cinfo_.num_components != 1 && cinfo_.num_components != 3) return false;
    header_.width = static_cast<int>(cinfo_.image_width);
    header_.height = static_cast<int>(cinfo_.image_height);
    header_.channels = cinfo_.num_components == 1 ? 1 : 3;
    header_.format = PixelFormat::kU8;
    header_.codec = "jpeg";
    bool exif_seen = false;
    for (jpeg_saved_marker_ptr m = cinfo_.marker_list; m != nullptr; m = m->next) {
      // The first EXIF segment is the image's (a file has one; later ones are ignored).
      if (m->marker == JPEG_APP0 + 1 && m->data_length > 6 && !exif_seen &&
          std::memcmp(m->data, "Exif\0\0", 6) == 0) {
        exif_seen = true;
        const ExifFacts exif = parse_exif(m->data + 6, m->data_length - 6);
        header_.orientation = exif.orientation;
        header_.focal_px =
            exif_focal_px(exif, header_.width, header_.height, &header_.focal_evidence);
        if (exif.colour_space_tag == 1 && !header_.has_colour_metadata) {
          header_.has_colour_metadata = true;
          header_.colour_space = ColourSpace::kSRGB;
          header_.colour_evidence = "EXIF ColorSpace sRGB";
        }
      } else if (m->marker == JPEG_APP0 + 2 && m->data_length > 12 &&
                 std::memcmp(m->data, "ICC_PROFILE", 12) == 0) {
        header_.has_colour_metadata = true;
        header_.colour_space = ColourSpace::kSRGB;
        header_.colour_evidence = "ICC profile (taken as sRGB-like encoded)";
      }
    }
    cinfo_.out_color_space = header_.channels == 1 ? JCS_GRAYSCALE : JCS_RGB;
    if (!begin_decompress()) fail("cannot start decoding");
    check_warnings();
    return true;
  }

  void read_rows(int rows, void* out) override {
    auto* dst = static_cast<unsigned char*>(out);
    const std::size_t stride = row_bytes();
    for (int r = 0; r < rows; ++r) {
      if (cinfo_.output_scanline >= cinfo_.output_height) {
        throw Error(where(path_) + ": read past the last row");
      }
      if (!read_one(dst + stride * static_cast<std::size_t>(r))) fail("cannot decode");
    }
    check_warnings();
  }

  void skip_rows(int rows) override {
    if (rows <= 0) return;
    if (cinfo_.output_scanline + static_cast<JDIMENSION>(rows) > cinfo_.output_height) {
      throw Error(where(path_) + ": read past the last row");
    }
    // libjpeg-turbo entropy-decodes what it must and skips the inverse DCT, upsampling and
    // colour conversion of whole skipped rows; the rows after are decoded as they would be
    // after reading these (the MPI tests compare every byte of the result).
    if (!skip(static_cast<JDIMENSION>(rows))) fail("cannot decode");
    check_warnings();
  }

 private:
  // The count lives in the object, not in a local: a longjmp may clobber locals.
  bool skip(JDIMENSION rows) {
    skip_left_ = rows;
    if (setjmp(errors_.jump) != 0) return false;
    while (skip_left_ > 0) {
      const JDIMENSION done = jpeg_skip_scanlines(&cinfo_, skip_left_);
      if (done == 0) return false;
      skip_left_ -= done;
    }
    return true;
  }
  bool start() {
    if (setjmp(errors_.jump) != 0) return false;
    jpeg_create_decompress(&cinfo_);
    created_ = true;
    cinfo_.progress = &progress_.pub;
    jpeg_stdio_src(&cinfo_, file_);
    jpeg_save_markers(&cinfo_, JPEG_APP0 + 1, 0xFFFF);
    jpeg_save_markers(&cinfo_, JPEG_APP0 + 2, 0xFFFF);
    jpeg_read_header(&cinfo_, TRUE);
    return true;
  }
  bool begin_decompress() {
    if (setjmp(errors_.jump) != 0) return false;
    jpeg_start_decompress(&cinfo_);
    return true;
  }
  bool read_one(unsigned char* row) {
    if (setjmp(errors_.jump) != 0) return false;
    JSAMPROW rows[1] = {row};
    while (jpeg_read_scanlines(&cinfo_, rows, 1) != 1) {
      // The stdio source never suspends; a zero return would loop forever.
      return false;
    }
    return true;
  }
  [[noreturn]] void fail(const char* what) {
    // Stopped by on_progress at a warning: the error is the damaged data (check_warnings
    // throws, as damage is not allowed where decoding stops at it).
    if (progress_.stopped_at_warning) check_warnings();
    throw Error(where(path_) + ": " + what + ": " + excerpt(errors_.error));
  }
  void check_warnings() {
    if (errors_.warnings > 0) {
      std::string w = errors_.warning;
      if (errors_.warnings > 1) w += " (and " + std::to_string(errors_.warnings - 1) + " more)";
      errors_.warnings = 0;
      damaged_data(path_, settings_, w, &warned_);
    }
  }

  fs::path path_;
  DecodeSettings settings_;
  JDIMENSION skip_left_ = 0;
  jpeg_decompress_struct cinfo_;
  JpegErrors errors_{};
  JpegProgress progress_{};
  std::FILE* file_ = nullptr;
  bool created_ = false;
  bool warned_ = false;
};

}  // namespace

std::unique_ptr<Decoder> open_jpeg(const fs::path& path, std::uintmax_t file_bytes,
                                   const DecodeSettings& settings) {
  auto d = std::make_unique<JpegDecoder>(path, settings);
  if (!d->open(file_bytes)) return nullptr;
  return d;
}

}  // namespace ptmkit::internal
