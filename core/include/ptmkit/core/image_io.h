// Reading and writing image files through OpenImageIO.
//
// In: PNG, JPEG, TIFF, EXR (and whatever else OpenImageIO reads), 8- and 16-bit integer or
// float samples. Out: PNG, TIFF, EXR (JPEG too, lossy). Writes are atomic: the image goes to
// a temporary file beside the target, then is renamed over it, so a failed write leaves no
// partial file. Every failure throws ptmkit::Error naming the file.
#pragma once

#include <filesystem>

#include "ptmkit/core/image.h"

namespace ptmkit {

// Sample type of a file on disk.
enum class PixelFormat { kU8, kU16, kF32 };
[[nodiscard]] std::string_view to_string(PixelFormat format);

struct ImageInfo {
  int width = 0;
  int height = 0;
  int channels = 0;
  PixelFormat format = PixelFormat::kU8;
  // From the file's metadata where it says; otherwise integer files are taken as sRGB and
  // float files as linear (what cameras and renderers write).
  ColourSpace colour_space = ColourSpace::kSRGB;
};

// Header only: size, channels, sample type, colour space.
[[nodiscard]] ImageInfo probe_image(const std::filesystem::path& path);

// The whole image as floats (integers normalised to 0..1), all channels.
[[nodiscard]] Image read_image(const std::filesystem::path& path);

struct ImageWriteOptions {
  // Sample type written. Integer formats clamp to [0, 1] and round to nearest.
  // The file type comes from the extension (.png, .tif/.tiff, .exr, .jpg).
  PixelFormat format = PixelFormat::kU8;
  // JPEG quality 1..100, used only for .jpg.
  int jpeg_quality = 95;
};

// Writes `image` atomically; the view's colour space is recorded in the file's metadata.
void write_image(const std::filesystem::path& path, ConstImageViewF image,
                 const ImageWriteOptions& options = {});

// Normal maps: unit normals, x, y, z in R, G, B (light frame). Written as floats to .exr;
// to any other type as (n + 1) / 2 in 16 bits (the usual RTI normal-map encoding).
void write_normal_map(const std::filesystem::path& path, ConstImageViewF normals);
// Reads either form: float files as stored, integer files decoded from (n + 1) / 2.
[[nodiscard]] Image read_normal_map(const std::filesystem::path& path);

}  // namespace ptmkit
