// Internal to core: shared OpenImageIO helpers.
#pragma once

#include <filesystem>
#include <memory>
#include <string>

#include <OpenImageIO/imageio.h>

#include "ptmkit/core/image_io.h"

namespace ptmkit::internal {

// Opens an image for reading or throws ptmkit::Error naming the file.
std::unique_ptr<OIIO::ImageInput> open_input(const std::filesystem::path& path);
ImageInfo info_from_spec(const OIIO::ImageSpec& spec);
std::string oiio_error(const OIIO::ImageInput* in);

}  // namespace ptmkit::internal
