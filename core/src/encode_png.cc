#include <cerrno>
#include <csetjmp>
#include <cstdio>
#include <cstring>
#include <string>

#include <png.h>

#include "encoder.h"
#include "ptmkit/core/error.h"

namespace fs = std::filesystem;

namespace ptmkit::internal {

namespace {

struct PngWriteMessages {
  char error[256] = {};
};

[[noreturn]] void on_error(png_structp png, png_const_charp msg) {
  auto* m = static_cast<PngWriteMessages*>(png_get_error_ptr(png));
  std::snprintf(m->error, sizeof(m->error), "%s", msg);
  png_longjmp(png, 1);
}

void on_warning(png_structp, png_const_charp) {}

// The libpng calls, behind one setjmp (no C++ object with a destructor lives in this frame).
bool encode(png_structp png, png_infop info, std::FILE* file, int width, int height, int channels,
            bool sixteen_bit, const unsigned char* pixels, ColourSpace colour) {
  if (setjmp(png_jmpbuf(png)) != 0) return false;
  png_init_io(png, file);
  const int type = channels == 1   ? PNG_COLOR_TYPE_GRAY
                   : channels == 2 ? PNG_COLOR_TYPE_GRAY_ALPHA
                   : channels == 3 ? PNG_COLOR_TYPE_RGB
                                   : PNG_COLOR_TYPE_RGB_ALPHA;
  png_set_IHDR(png, info, static_cast<png_uint_32>(width), static_cast<png_uint_32>(height),
               sixteen_bit ? 16 : 8, type, PNG_INTERLACE_NONE, PNG_COMPRESSION_TYPE_DEFAULT,
               PNG_FILTER_TYPE_DEFAULT);
  if (colour == ColourSpace::kSRGB) {
    png_set_sRGB(png, info, PNG_sRGB_INTENT_PERCEPTUAL);
  } else {
    png_set_gAMA_fixed(png, info, PNG_FP_1);
  }
  png_write_info(png, info);
  if (sixteen_bit) png_set_swap(png);
  const std::size_t stride =
      static_cast<std::size_t>(width) * static_cast<std::size_t>(channels) * (sixteen_bit ? 2 : 1);
  for (int y = 0; y < height; ++y) {
    png_write_row(png, pixels + stride * static_cast<std::size_t>(y));
  }
  png_write_end(png, nullptr);
  return true;
}

}  // namespace

void write_png(const fs::path& target, const fs::path& path, int width, int height, int channels,
               bool sixteen_bit, const void* pixels, ColourSpace colour) {
  if (channels < 1 || channels > 4) {
    throw Error(where(target) + ": PNG holds 1 to 4 channels, not " + std::to_string(channels));
  }
  std::FILE* file = std::fopen(path.c_str(), "wb");
  if (file == nullptr) {
    throw Error(where(target) + ": cannot open for writing: " + std::strerror(errno));
  }
  PngWriteMessages messages;
  png_structp png = png_create_write_struct(PNG_LIBPNG_VER_STRING, &messages, on_error, on_warning);
  png_infop info = png != nullptr ? png_create_info_struct(png) : nullptr;
  bool ok = info != nullptr && encode(png, info, file, width, height, channels, sixteen_bit,
                                      static_cast<const unsigned char*>(pixels), colour);
  png_destroy_write_struct(&png, &info);
  std::string why = ok ? "" : (messages.error[0] != '\0' ? messages.error : "encoder failed");
  // Buffered bytes reach the file system only here: a full disk shows in the flush or close.
  if (std::fflush(file) != 0 || std::ferror(file) != 0) {
    if (ok) why = std::strerror(errno);
    ok = false;
  }
  if (std::fclose(file) != 0) {
    if (ok) why = std::strerror(errno);
    ok = false;
  }
  if (!ok) throw Error(where(target) + ": write failed: " + why);
}

}  // namespace ptmkit::internal
