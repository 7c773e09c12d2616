// truth/coefficients.exr: 18 named float channels.
//
// OpenEXR stores channels sorted by name, and readers return them in that order (apart from
// R, G, B, A, which come first). Unnamed extra channels ("channel4" ... "channel17") would
// therefore come back shuffled, so each channel is named `cNN_<colour>_a<k>`, whose sorted
// order is the layout's order: channel 6 c + k is term a_k of colour c.
#include <OpenImageIO/imageio.h>

#include <string>

#include "coefficients_exr.h"
#include "ptmkit/core/atomic_file.h"
#include "ptmkit/core/error.h"

namespace ptmkit::synth::detail {

void write_coefficients_exr(const std::filesystem::path& path, const CoefficientMap& map) {
  const int channels = map.polynomials() * kPtmTerms;
  AtomicOutput out_file(path);
  auto out = OIIO::ImageOutput::create(path.string());
  if (!out) throw Error(where(path) + ": cannot write EXR files");
  OIIO::ImageSpec spec(map.width, map.height, channels, OIIO::TypeDesc::FLOAT);
  spec.channelnames.clear();
  const char* colours = "RGB";
  for (int i = 0; i < channels; ++i) {
    std::string name = "c";
    if (i < 10) name += "0";
    name += std::to_string(i) + "_" + colours[i / kPtmTerms] + "_a" + std::to_string(i % kPtmTerms);
    spec.channelnames.push_back(name);
  }
  spec.alpha_channel = -1;
  spec.attribute("oiio:ColorSpace", "Linear");
  spec.attribute("compression", "zip");
  spec.attribute("DateTime", "");  // no time stamp: the file depends on the options only
  if (!out->open(out_file.temp_path().string(), spec)) {
    throw Error(where(path) + ": cannot open for writing: " + out->geterror());
  }
  if (!out->write_image(OIIO::TypeDesc::FLOAT, map.coeffs.data()) || !out->close()) {
    throw Error(where(path) + ": write failed: " + out->geterror());
  }
  out_file.commit();
}

}  // namespace ptmkit::synth::detail
