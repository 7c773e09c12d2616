// JPEG output through libjpeg(-turbo) with its errors caught: libjpeg's default error handler
// ends the process (a full disk would kill a command mid-write, leaving its temporaries).
#include <cerrno>
#include <csetjmp>
#include <cstdio>
#include <cstring>
#include <string>

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
            int channels, const unsigned char* pixels, int quality) {
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

void write_jpeg(const std::filesystem::path& target, const std::filesystem::path& path, int width,
                int height, int channels, const unsigned char* pixels, int quality) {
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
  const bool ok = encode(&cinfo, &err, file, width, height, channels, pixels, quality);
  jpeg_destroy_compress(&cinfo);
  // The flush and close are where a full disk shows for the last bytes.
  const bool closed = std::fclose(file) == 0;
  if (!ok) throw Error(where(target) + ": write failed: " + std::string(err.message));
  if (!closed) throw Error(where(target) + ": write failed: " + std::strerror(errno));
}

}  // namespace ptmkit::internal
