// Internal to core: image encoders core runs itself.
#pragma once

#include <filesystem>
#include <vector>

#include "ptmkit/core/image.h"

namespace ptmkit::internal {

// Writes tightly packed 8- or 16-bit samples (machine order) as PNG into `path`, recording the
// colour space (an sRGB chunk, or gAMA 1.0 for linear). Every libpng error, and the flush and
// close of the file (where a full disk shows), throws ptmkit::Error naming `target`.
void write_png(const std::filesystem::path& target, const std::filesystem::path& path, int width,
               int height, int channels, bool sixteen_bit, const void* pixels, ColourSpace colour);

// Writes tightly packed 8-bit grey or RGB samples as JPEG (baseline, `quality` 1..100, the
// library's default 4:2:0 chroma and accurate integer DCT) into `path`. Every libjpeg error
// (a full disk included) and the close throw ptmkit::Error naming `target`.
// `exif`, when not empty, is written as an APP1 EXIF segment (without the "Exif\0\0" prefix).
void write_jpeg(const std::filesystem::path& target, const std::filesystem::path& path, int width,
                int height, int channels, const unsigned char* pixels, int quality,
                const std::vector<unsigned char>& exif = {});

// A little-endian EXIF block (TIFF header, IFD0 with the EXIF IFD pointer, the EXIF IFD)
// recording a camera for an image width_px x height_px: see ImageWriteOptions::exif_camera.
std::vector<unsigned char> exif_camera_block(double focal_mm, double sensor_width_mm, int width_px,
                                             int height_px);

}  // namespace ptmkit::internal
