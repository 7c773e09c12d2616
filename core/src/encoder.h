// Internal to core: image encoders core runs itself.
#pragma once

#include <filesystem>

#include "ptmkit/core/image.h"

namespace ptmkit::internal {

// Writes tightly packed 8- or 16-bit samples (machine order) as PNG into `path`, recording the
// colour space (an sRGB chunk, or gAMA 1.0 for linear). Every libpng error, and the flush and
// close of the file (where a full disk shows), throws ptmkit::Error naming `target`.
void write_png(const std::filesystem::path& target, const std::filesystem::path& path, int width,
               int height, int channels, bool sixteen_bit, const void* pixels, ColourSpace colour);

}  // namespace ptmkit::internal
