#include "ptmkit/core/image.h"

#include <algorithm>

namespace ptmkit {

std::string_view to_string(ColourSpace space) {
  switch (space) {
    case ColourSpace::kLinear:
      return "linear";
    case ColourSpace::kSRGB:
      return "sRGB";
  }
  return "unknown";
}

Image::Image(int width, int height, int channels, ColourSpace colour_space, float fill)
    : width_(width),
      height_(height),
      channels_(channels),
      colour_space_(colour_space),
      pixels_(static_cast<std::size_t>(width) * height * channels, fill) {
  assert(width >= 0 && height >= 0 && channels >= 0);
}

ImageViewF Image::view() {
  return {
      pixels_.data(), width_, height_, channels_, static_cast<std::ptrdiff_t>(width_) * channels_,
      colour_space_};
}

ConstImageViewF Image::view() const {
  return {
      pixels_.data(), width_, height_, channels_, static_cast<std::ptrdiff_t>(width_) * channels_,
      colour_space_};
}

}  // namespace ptmkit
