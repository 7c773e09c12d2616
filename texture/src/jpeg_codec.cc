#include "jpeg_codec.h"

#include <csetjmp>
#include <cstdio>
#include <cstdlib>
#include <cstring>

// jpeglib.h needs FILE and size_t declared first.
#include <jpeglib.h>

namespace ptmkit::texture::internal {

namespace {

struct ErrorManager {
  jpeg_error_mgr base;
  std::jmp_buf jump;
  char message[JMSG_LENGTH_MAX];
  bool warned;
};

[[noreturn]] void on_error(j_common_ptr cinfo) {
  auto* err = reinterpret_cast<ErrorManager*>(cinfo->err);
  (*cinfo->err->format_message)(cinfo, err->message);
  std::longjmp(err->jump, 1);
}

// Warnings (level -1) mean corrupt data that libjpeg would paper over: keep the first one.
void on_message(j_common_ptr cinfo, int level) {
  auto* err = reinterpret_cast<ErrorManager*>(cinfo->err);
  if (level < 0 && !err->warned) {
    err->warned = true;
    (*cinfo->err->format_message)(cinfo, err->message);
  }
}

void install(ErrorManager* err) {
  jpeg_std_error(&err->base);
  err->base.error_exit = on_error;
  err->base.emit_message = on_message;
  err->message[0] = '\0';
  err->warned = false;
}

// The parts that run between setjmp and a possible longjmp hold no C++ objects with
// destructors: the output vector is sized before, and only written through a raw pointer.
bool decode_into(jpeg_decompress_struct* cinfo, ErrorManager* err, const std::uint8_t* data,
                 std::size_t size, int components, int expect_width, int expect_height,
                 std::vector<std::uint8_t>* pixels, int* width, int* height, char* why,
                 std::size_t why_size) {
  if (setjmp(err->jump) != 0) return false;
  jpeg_create_decompress(cinfo);
  jpeg_mem_src(cinfo, data, static_cast<unsigned long>(size));
  jpeg_read_header(cinfo, TRUE);
  if (components == 1 && cinfo->num_components != 1) {
    std::snprintf(why, why_size, "a %d-component JPEG where a greyscale plane was expected",
                  cinfo->num_components);
    return false;
  }
  if (components == 3 && cinfo->num_components != 3) {
    std::snprintf(why, why_size, "a %d-component JPEG where a 3-component plane was expected",
                  cinfo->num_components);
    return false;
  }
  const auto w = static_cast<int>(cinfo->image_width);
  const auto h = static_cast<int>(cinfo->image_height);
  if ((expect_width > 0 && w != expect_width) || (expect_height > 0 && h != expect_height)) {
    std::snprintf(why, why_size, "a %d x %d JPEG where %d x %d was expected", w, h, expect_width,
                  expect_height);
    return false;
  }
  cinfo->out_color_space = components == 1 ? JCS_GRAYSCALE : JCS_RGB;
  *width = w;
  *height = h;
  pixels->resize(static_cast<std::size_t>(w) * static_cast<std::size_t>(h) *
                 static_cast<std::size_t>(components));
  std::uint8_t* out = pixels->data();
  jpeg_start_decompress(cinfo);
  const std::size_t stride = static_cast<std::size_t>(w) * static_cast<std::size_t>(components);
  while (cinfo->output_scanline < cinfo->output_height) {
    JSAMPROW row = out + static_cast<std::size_t>(cinfo->output_scanline) * stride;
    jpeg_read_scanlines(cinfo, &row, 1);
  }
  jpeg_finish_decompress(cinfo);
  return true;
}

bool encode_into(jpeg_compress_struct* cinfo, ErrorManager* err, const std::uint8_t* pixels,
                 int width, int height, int quality, unsigned char** buffer, unsigned long* size) {
  if (setjmp(err->jump) != 0) return false;
  jpeg_create_compress(cinfo);
  jpeg_mem_dest(cinfo, buffer, size);
  cinfo->image_width = static_cast<JDIMENSION>(width);
  cinfo->image_height = static_cast<JDIMENSION>(height);
  cinfo->input_components = 1;
  cinfo->in_color_space = JCS_GRAYSCALE;
  jpeg_set_defaults(cinfo);
  jpeg_set_quality(cinfo, quality, TRUE);
  jpeg_start_compress(cinfo, TRUE);
  while (cinfo->next_scanline < cinfo->image_height) {
    auto* row = const_cast<JSAMPROW>(pixels + static_cast<std::size_t>(cinfo->next_scanline) *
                                                  static_cast<std::size_t>(width));
    jpeg_write_scanlines(cinfo, &row, 1);
  }
  jpeg_finish_compress(cinfo);
  return true;
}

}  // namespace

bool jpeg_decode(const std::uint8_t* data, std::size_t size, int components, int expect_width,
                 int expect_height, std::vector<std::uint8_t>* pixels, int* width, int* height,
                 std::string* error) {
  if (size == 0) {
    *error = "an empty JPEG stream";
    return false;
  }
  jpeg_decompress_struct cinfo{};
  ErrorManager err{};
  install(&err);
  cinfo.err = &err.base;
  char why[256] = {};
  const bool ok = decode_into(&cinfo, &err, data, size, components, expect_width, expect_height,
                              pixels, width, height, why, sizeof why);
  jpeg_destroy_decompress(&cinfo);
  if (!ok) {
    *error = why[0] != '\0' ? std::string(why) : "JPEG error: " + std::string(err.message);
    return false;
  }
  if (err.warned) {
    *error = "corrupt JPEG data: " + std::string(err.message);
    return false;
  }
  return true;
}

bool jpeg_encode_grey(const std::uint8_t* pixels, int width, int height, int quality,
                      std::vector<std::uint8_t>* out, std::string* error) {
  jpeg_compress_struct cinfo{};
  ErrorManager err{};
  install(&err);
  cinfo.err = &err.base;
  unsigned char* buffer = nullptr;
  unsigned long size = 0;
  const bool ok = encode_into(&cinfo, &err, pixels, width, height, quality, &buffer, &size);
  jpeg_destroy_compress(&cinfo);
  if (ok) out->assign(buffer, buffer + size);
  std::free(buffer);
  if (!ok) *error = "JPEG error: " + std::string(err.message);
  return ok;
}

}  // namespace ptmkit::texture::internal
