// truth/coefficients.exr: 18 named float channels.
//
// OpenEXR stores channels sorted by name, and readers return them in that order (apart from
// R, G, B, A, which come first). Unnamed extra channels ("channel4" ... "channel17") would
// therefore come back shuffled, so each channel is named `cNN_<colour>_a<k>`, whose sorted
// order is the layout's order: channel 6 c + k is term a_k of colour c.
#include <string>
#include <vector>

#include "coefficients_exr.h"
#include "ptmkit/core/image_io.h"

namespace ptmkit::synth::detail {

void write_coefficients_exr(const std::filesystem::path& path, const CoefficientMap& map) {
  const int channels = map.polynomials() * kPtmTerms;
  ImageWriteOptions options;
  options.format = PixelFormat::kF32;
  const char* colours = "RGB";
  for (int i = 0; i < channels; ++i) {
    std::string name = "c";
    if (i < 10) name += "0";
    name += std::to_string(i) + "_" + colours[i / kPtmTerms] + "_a" + std::to_string(i % kPtmTerms);
    options.channel_names.push_back(name);
  }
  const ConstImageViewF view{map.coeffs.data(),
                             map.width,
                             map.height,
                             channels,
                             static_cast<std::ptrdiff_t>(map.width) * channels,
                             ColourSpace::kLinear};
  write_image(path, view, options);
}

}  // namespace ptmkit::synth::detail
