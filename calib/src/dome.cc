#include "ptmkit/calib/dome.h"

#include <cstdio>

#include "ptmkit/core/error.h"
#include "ptmkit/core/light_layout.h"

namespace ptmkit::calib {

std::vector<Eigen::Vector3d> layout_directions(std::string_view spec) {
  if (spec == "icosa" || spec == "icosa1") return geodesic_dome(2);
  if (spec == "dome49") return ring_layout(parse_rings("10:18,30:12,50:10,70:8,90:1"));
  if (spec.starts_with("geodesic:")) {
    const std::string f(spec.substr(9));
    char* end = nullptr;
    const long freq = std::strtol(f.c_str(), &end, 10);
    if (end == f.c_str() || *end != '\0') {
      throw Error("layout '" + std::string(spec) + "': expected geodesic:FREQUENCY");
    }
    return geodesic_dome(static_cast<int>(freq));
  }
  if (spec.starts_with("rings:")) return ring_layout(parse_rings(spec.substr(6)));
  if (spec.ends_with(".lp")) return read_lp(std::filesystem::path(spec)).directions();
  throw Error("unknown light layout '" + std::string(spec) +
              "' (expected icosa, geodesic:F, dome49, rings:SPEC or a .lp file)");
}

LightSet layout_light_set(std::string_view spec, const std::string& name_pattern) {
  LightSet set;
  const auto dirs = layout_directions(spec);
  for (std::size_t i = 0; i < dirs.size(); ++i) {
    char name[512];
    std::snprintf(name, sizeof(name), name_pattern.c_str(), static_cast<int>(i + 1));
    Light l;
    l.image = name;
    l.direction = dirs[i];
    set.lights.push_back(std::move(l));
  }
  return set;
}

}  // namespace ptmkit::calib
