// Sample labels as images: one 8-bit PNG per light.
#include <string>

#include "ptmkit/core/atomic_file.h"
#include "ptmkit/core/error.h"
#include "ptmkit/core/image_io.h"
#include "ptmkit/fit/fit.h"

namespace ptmkit::fit {

void write_label_images(const std::filesystem::path& dir, const FitOutputs& outputs,
                        const LightSet& lights, int width, int height) {
  const std::size_t n = lights.size();
  const std::size_t texels = static_cast<std::size_t>(width) * static_cast<std::size_t>(height);
  if (outputs.labels.size() != texels * n) {
    throw Error(where(dir) + ": no labels of this size to write (" +
                std::to_string(outputs.labels.size()) + " for " + std::to_string(texels) +
                " texels x " + std::to_string(n) + " lights)");
  }
  ensure_directory(dir);
  Image lab(width, height, 1, ColourSpace::kLinear);
  for (std::size_t i = 0; i < n; ++i) {
    for (std::size_t t = 0; t < texels; ++t) {
      lab.data()[t] = static_cast<float>(outputs.labels[t * n + i]) / 255.0f;
    }
    const auto name = lights.lights[i].image.filename().replace_extension(".png");
    write_image(dir / name, lab.view(), ImageWriteOptions{PixelFormat::kU8});
  }
}

}  // namespace ptmkit::fit
