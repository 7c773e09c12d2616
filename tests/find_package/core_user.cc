// Writes and reads back a light file through an installed ptmkit::core.
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <string>

#include "ptmkit/core/error.h"
#include "ptmkit/core/light_layout.h"
#include "ptmkit/core/light_set.h"
#include "ptmkit/core/version.h"

int main(int argc, char** argv) {
  if (argc != 2) return 2;
  const std::filesystem::path lp = std::filesystem::path(argv[1]) / "lights.lp";
  ptmkit::LightSet set;
  const auto dirs = ptmkit::geodesic_dome(2);
  for (std::size_t i = 0; i < dirs.size(); ++i) {
    ptmkit::Light l;
    l.image = "image_" + std::to_string(i) + ".png";
    l.direction = dirs[i];
    set.lights.push_back(l);
  }
  ptmkit::write_lp(lp, set);
  const ptmkit::LightSet back = ptmkit::read_lp(lp);
  if (back.size() != set.size()) return 1;
  for (std::size_t i = 0; i < set.size(); ++i) {
    if ((back.lights[i].direction - set.lights[i].direction).norm() > 1e-8) return 1;
  }
  try {
    (void)ptmkit::read_lp(std::filesystem::path(argv[1]) / "missing.lp");
    return 1;  // a missing file must be an error
  } catch (const ptmkit::Error&) {
  }
  std::printf("ptmkit %s core: %zu lights written and read back\n", ptmkit::kVersion, back.size());
  return 0;
}
