// Internal to core: writing through the OpenImageIO module (oiio_bridge.h).
#pragma once

#include <cstddef>
#include <filesystem>
#include <string>
#include <vector>

#include "ptmkit/core/image_io.h"

namespace ptmkit::internal {

// Whether the module can be loaded (tests compare the direct decoders with it).
bool oiio_available();

// Writes `pixels` (height rows of width * channels samples of `format`, stride_bytes apart) as
// the file type of `type_path`'s extension into `path`. Throws ptmkit::Error naming type_path
// with the encoder's or the close's error.
void oiio_write(const std::filesystem::path& type_path, const std::filesystem::path& path,
                int width, int height, int channels, PixelFormat format, const void* pixels,
                std::ptrdiff_t stride_bytes, ColourSpace colour, int jpeg_quality,
                const std::vector<std::string>& channel_names);

}  // namespace ptmkit::internal
