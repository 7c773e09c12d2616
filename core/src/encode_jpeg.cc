// JPEG output through libjpeg(-turbo) with its errors caught: libjpeg's default error handler
// ends the process (a full disk would kill a command mid-write, leaving its temporaries).
#include <algorithm>
#include <cerrno>
#include <cmath>
#include <csetjmp>
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <string>
#include <vector>

// jpeglib.h needs FILE and size_t declared first.
#include <jpeglib.h>

#include "encoder.h"
#include "ptmkit/core/error.h"

namespace ptmkit::internal {

namespace {

struct ErrorManager {
  jpeg_error_mgr base;
  std::jmp_buf jump;
  char message[JMSG_LENGTH_MAX];
};

[[noreturn]] void on_error(j_common_ptr cinfo) {
  auto* err = reinterpret_cast<ErrorManager*>(cinfo->err);
  (*cinfo->err->format_message)(cinfo, err->message);
  std::longjmp(err->jump, 1);
}

// Between setjmp and a possible longjmp: no C++ objects with destructors.
bool encode(jpeg_compress_struct* cinfo, ErrorManager* err, std::FILE* file, int width, int height,
            int channels, const unsigned char* pixels, int quality, const unsigned char* exif,
            unsigned exif_bytes) {
  if (setjmp(err->jump) != 0) return false;
  jpeg_create_compress(cinfo);
  jpeg_stdio_dest(cinfo, file);
  cinfo->image_width = static_cast<JDIMENSION>(width);
  cinfo->image_height = static_cast<JDIMENSION>(height);
  cinfo->input_components = channels;
  cinfo->in_color_space = channels == 1 ? JCS_GRAYSCALE : JCS_RGB;
  jpeg_set_defaults(cinfo);
  jpeg_set_quality(cinfo, quality, TRUE);
  jpeg_start_compress(cinfo, TRUE);
  if (exif_bytes > 0) jpeg_write_marker(cinfo, JPEG_APP0 + 1, exif, exif_bytes);
  const std::size_t stride = static_cast<std::size_t>(width) * static_cast<std::size_t>(channels);
  while (cinfo->next_scanline < cinfo->image_height) {
    auto* row =
        const_cast<JSAMPROW>(pixels + static_cast<std::size_t>(cinfo->next_scanline) * stride);
    jpeg_write_scanlines(cinfo, &row, 1);
  }
  jpeg_finish_compress(cinfo);
  return true;
}

}  // namespace

std::vector<unsigned char> exif_camera_block(double focal_mm, double sensor_width_mm, int width_px,
                                             int height_px) {
  std::vector<unsigned char> b;
  auto u16 = [&](unsigned v) {
    b.push_back(static_cast<unsigned char>(v & 0xFF));
    b.push_back(static_cast<unsigned char>((v >> 8) & 0xFF));
  };
  auto u32 = [&](std::uint32_t v) {
    for (int k = 0; k < 4; ++k) b.push_back(static_cast<unsigned char>((v >> (8 * k)) & 0xFF));
  };
  // Rationals to a thousandth.
  auto milli = [](double v) { return static_cast<std::uint32_t>(std::lround(v * 1000.0)); };
  const double px_per_cm = width_px / (0.1 * sensor_width_mm);
  const double equivalent_mm = focal_mm / sensor_width_mm * width_px * std::hypot(36.0, 24.0) /
                               std::hypot(static_cast<double>(width_px), height_px);
  // Layout: header (8), IFD0 at 8 (1 entry: 18 bytes), the EXIF IFD at 26 (5 entries: 66
  // bytes), then the two rationals' values at 92 and 100.
  constexpr std::uint32_t kExifIfd = 26, kValues = 92;
  b.reserve(108);
  u16(0x4949);  // "II": little-endian
  u16(42);
  u32(8);
  u16(1);
  u16(0x8769), u16(4), u32(1), u32(kExifIfd);
  u32(0);
  u16(5);                                     // entries in ascending tag order
  u16(0x920A), u16(5), u32(1), u32(kValues);  // FocalLength
  u16(0xA002), u16(4), u32(1), u32(static_cast<std::uint32_t>(width_px));  // PixelXDimension
  u16(0xA20E), u16(5), u32(1), u32(kValues + 8);                           // FocalPlaneXResolution
  u16(0xA210), u16(3), u32(1), u32(3);  // FocalPlaneResolutionUnit: cm
  u16(0xA405), u16(3), u32(1),
      u32(static_cast<std::uint32_t>(std::clamp(std::lround(equivalent_mm), 1L, 65535L)));
  u32(0);
  u32(milli(focal_mm)), u32(1000);
  u32(milli(px_per_cm)), u32(1000);
  return b;
}

void write_jpeg(const std::filesystem::path& target, const std::filesystem::path& path, int width,
                int height, int channels, const unsigned char* pixels, int quality,
                const std::vector<unsigned char>& exif) {
  if (channels != 1 && channels != 3) {
    throw Error(where(target) + ": JPEG holds grey or RGB, not " + std::to_string(channels) +
                " channels; use .png, .tif or .exr");
  }
  std::FILE* file = std::fopen(path.c_str(), "wb");
  if (file == nullptr) {
    throw Error(where(target) + ": cannot open for writing: " + std::strerror(errno));
  }
  jpeg_compress_struct cinfo{};
  ErrorManager err{};
  jpeg_std_error(&err.base);
  err.base.error_exit = on_error;
  cinfo.err = &err.base;
  // The segment: "Exif\0\0" and the block.
  std::vector<unsigned char> app1;
  if (!exif.empty()) {
    app1 = {'E', 'x', 'i', 'f', 0, 0};
    app1.insert(app1.end(), exif.begin(), exif.end());
  }
  const bool ok = encode(&cinfo, &err, file, width, height, channels, pixels, quality, app1.data(),
                         static_cast<unsigned>(app1.size()));
  jpeg_destroy_compress(&cinfo);
  // The flush and close are where a full disk shows for the last bytes.
  const bool closed = std::fclose(file) == 0;
  if (!ok) throw Error(where(target) + ": write failed: " + std::string(err.message));
  if (!closed) throw Error(where(target) + ": write failed: " + std::strerror(errno));
}

}  // namespace ptmkit::internal
