// A web JPEG's three planes: quantised to bytes, halved for the deep-zoom pyramid, and coded
// and decoded through libjpeg.
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
// clang-format off
#include <cstdio>  // jpeglib.h needs FILE and size_t declared first
#include <jpeglib.h>
// clang-format on

#include <algorithm>
#include <csetjmp>
#include <cstdlib>
#include <string>
#include <vector>

#include "ptmkit/core/error.h"
#include "web_export_detail.h"

namespace ptmkit::texture::internal {

namespace {

struct JpegErrorManager {
  jpeg_error_mgr pub;
  std::jmp_buf jump;
  char message[JMSG_LENGTH_MAX];
};

void jpeg_error_exit(j_common_ptr cinfo) {
  auto* err = reinterpret_cast<JpegErrorManager*>(cinfo->err);
  (*cinfo->err->format_message)(cinfo, err->message);
  std::longjmp(err->jump, 1);
}

}  // namespace

// Encodes interleaved 8-bit RGB. `ycbcr`: the ordinary colour transform; otherwise the
// components are stored as R, G, B (Adobe marker, no transform). No chroma subsampling.
std::vector<unsigned char> encode_jpeg(const unsigned char* rgb, int width, int height, int quality,
                                       bool ycbcr) {
  jpeg_compress_struct cinfo{};
  JpegErrorManager err{};
  cinfo.err = jpeg_std_error(&err.pub);
  err.pub.error_exit = jpeg_error_exit;
  unsigned char* mem = nullptr;
  unsigned long mem_size = 0;  // NOLINT(runtime/int): libjpeg's type
  if (setjmp(err.jump)) {
    jpeg_destroy_compress(&cinfo);
    std::free(mem);
    throw Error(std::string("JPEG encoding failed: ") + err.message);
  }
  jpeg_create_compress(&cinfo);
  jpeg_mem_dest(&cinfo, &mem, &mem_size);
  cinfo.image_width = static_cast<JDIMENSION>(width);
  cinfo.image_height = static_cast<JDIMENSION>(height);
  cinfo.input_components = 3;
  cinfo.in_color_space = JCS_RGB;
  jpeg_set_defaults(&cinfo);
  jpeg_set_colorspace(&cinfo, ycbcr ? JCS_YCbCr : JCS_RGB);
  for (int c = 0; c < 3; ++c) {
    cinfo.comp_info[c].h_samp_factor = 1;
    cinfo.comp_info[c].v_samp_factor = 1;
  }
  jpeg_set_quality(&cinfo, quality, TRUE);
  cinfo.optimize_coding = TRUE;
  cinfo.dct_method = JDCT_ISLOW;
  jpeg_start_compress(&cinfo, TRUE);
  const std::size_t stride = static_cast<std::size_t>(width) * 3;
  while (cinfo.next_scanline < cinfo.image_height) {
    JSAMPROW row = const_cast<JSAMPROW>(rgb + cinfo.next_scanline * stride);
    jpeg_write_scanlines(&cinfo, &row, 1);
  }
  jpeg_finish_compress(&cinfo);
  jpeg_destroy_compress(&cinfo);
  std::vector<unsigned char> out(mem, mem + mem_size);
  std::free(mem);
  return out;
}

// Decodes to interleaved RGB (for measuring what the coding lost).
std::vector<unsigned char> decode_jpeg(const std::vector<unsigned char>& data, int width,
                                       int height) {
  jpeg_decompress_struct cinfo{};
  JpegErrorManager err{};
  // Declared before setjmp: a longjmp back here must not skip an object's construction.
  std::vector<unsigned char> out;
  cinfo.err = jpeg_std_error(&err.pub);
  err.pub.error_exit = jpeg_error_exit;
  if (setjmp(err.jump)) {
    jpeg_destroy_decompress(&cinfo);
    throw Error(std::string("JPEG decoding failed: ") + err.message);
  }
  jpeg_create_decompress(&cinfo);
  jpeg_mem_src(&cinfo, data.data(), static_cast<unsigned long>(data.size()));  // NOLINT
  jpeg_read_header(&cinfo, TRUE);
  cinfo.out_color_space = JCS_RGB;
  cinfo.dct_method = JDCT_ISLOW;
  jpeg_start_decompress(&cinfo);
  if (static_cast<int>(cinfo.output_width) != width ||
      static_cast<int>(cinfo.output_height) != height || cinfo.output_components != 3) {
    jpeg_destroy_decompress(&cinfo);
    throw Error("JPEG decoding: unexpected size");
  }
  out.resize(static_cast<std::size_t>(width) * height * 3);
  while (cinfo.output_scanline < cinfo.output_height) {
    JSAMPROW row = out.data() + static_cast<std::size_t>(cinfo.output_scanline) * width * 3;
    jpeg_read_scanlines(&cinfo, &row, 1);
  }
  jpeg_finish_decompress(&cinfo);
  jpeg_destroy_decompress(&cinfo);
  return out;
}

Level half(const Level& src) {
  Level d;
  d.width = src.width / 2;
  d.height = src.height / 2;
  d.v.resize(static_cast<std::size_t>(d.width) * d.height * 3);
  tbb::parallel_for(tbb::blocked_range<int>(0, d.height), [&](const tbb::blocked_range<int>& r) {
    for (int y = r.begin(); y < r.end(); ++y) {
      const float* a = src.v.data() + static_cast<std::size_t>(2 * y) * src.width * 3;
      const float* b = a + static_cast<std::size_t>(src.width) * 3;
      float* o = d.v.data() + static_cast<std::size_t>(y) * d.width * 3;
      for (int x = 0; x < d.width; ++x) {
        for (int c = 0; c < 3; ++c) {
          const std::size_t i = static_cast<std::size_t>(2 * x) * 3 + c;
          o[3 * x + c] = 0.25f * (a[i] + a[i + 3] + b[i] + b[i + 3]);
        }
      }
    }
  });
  return d;
}

std::vector<unsigned char> quantise_region(const Level& l, const Quantiser& q, int x0, int y0,
                                           int w, int h) {
  std::vector<unsigned char> out(static_cast<std::size_t>(w) * h * 3);
  for (int y = 0; y < h; ++y) {
    const float* row = l.v.data() + (static_cast<std::size_t>(y0 + y) * l.width + x0) * 3;
    unsigned char* o = out.data() + static_cast<std::size_t>(y) * w * 3;
    for (int i = 0; i < w * 3; ++i) o[i] = q.byte(i % 3, row[i]);
  }
  return out;
}

}  // namespace ptmkit::texture::internal
