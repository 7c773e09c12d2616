#include <set>
#include <string>

#include "ptmkit/core/error.h"
#include "ptmkit/core/light_set.h"

namespace fs = std::filesystem;

namespace ptmkit {

LightSet with_images(const LightSet& lights, const std::vector<fs::path>& images) {
  const std::string name = lights.source.empty() ? "light set" : where(lights.source);
  if (images.size() != lights.size()) {
    throw Error(name + ": " + std::to_string(lights.size()) + " lights but " +
                std::to_string(images.size()) +
                " images were given; the images must be one per light, in the light file's "
                "order");
  }
  std::set<fs::path> seen;
  LightSet out = lights;
  for (std::size_t i = 0; i < images.size(); ++i) {
    const fs::path key = images[i].lexically_normal();
    if (!seen.insert(key).second) {
      throw Error(where(images[i]) + ": given twice (image " + std::to_string(i + 1) +
                  "); each light needs its own photograph");
    }
    out.lights[i].image = images[i];
  }
  return out;
}

}  // namespace ptmkit
