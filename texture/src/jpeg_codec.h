// libjpeg(-turbo) behind two calls, for the PTM JPEG planes and the web folder's planes.
// libjpeg reports errors by longjmp; these wrappers turn them (and its warnings about corrupt
// data, which it would otherwise repair silently with grey) into a false return and a message.
#pragma once

#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

namespace ptmkit::texture::internal {

// Decodes a whole JPEG held in memory. `components` is 1 (the stream must be greyscale) or 3
// (RGB out: YCbCr streams are converted, RGB-coded streams are taken as they are). When
// `expect_width`/`expect_height` are positive the stream must have that size (checked before
// any pixel buffer is allocated). Pixels are row-major, top row first, interleaved.
bool jpeg_decode(const std::uint8_t* data, std::size_t size, int components, int expect_width,
                 int expect_height, std::vector<std::uint8_t>* pixels, int* width, int* height,
                 std::string* error);

// Encodes a greyscale image (row-major, top row first) at `quality` (1..100).
bool jpeg_encode_grey(const std::uint8_t* pixels, int width, int height, int quality,
                      std::vector<std::uint8_t>* out, std::string* error);

}  // namespace ptmkit::texture::internal
