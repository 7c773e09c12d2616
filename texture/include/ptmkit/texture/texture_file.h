// Any texture ptmkit reads, by what the path is: a web folder (a folder with info.json, or
// that info.json), an HSH .rti (by extension, or by content), or a .ptm (everything else).
#pragma once

#include <filesystem>
#include <string>

#include "ptmkit/core/coefficients.h"
#include "ptmkit/texture/rti.h"

namespace ptmkit::texture {

enum class TextureSource { kPtm, kRti, kWebFolder };
[[nodiscard]] TextureSource detect_texture_source(const std::filesystem::path& path);

struct LoadedTexture {
  TextureSource source = TextureSource::kPtm;
  bool is_hsh = false;  // hsh set, else ptm set
  CoefficientMap ptm;
  CoefficientMap hsh;  // an HSH basis in the rgb layout (rti.h)
  std::string format;  // "PTM_FORMAT_JPEG_LRGB", "RTI HSH 9 terms", "web ptm rgb image", ...
};
// Reads the texture; errors as the format's reader.
[[nodiscard]] LoadedTexture read_texture(const std::filesystem::path& path,
                                         ColourSpace colour_space = ColourSpace::kSRGB);

}  // namespace ptmkit::texture
