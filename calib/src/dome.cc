#include "ptmkit/calib/dome.h"

#include <cmath>
#include <cstdio>
#include <fstream>
#include <numbers>

#include <nlohmann/json.hpp>

#include "ptmkit/core/error.h"
#include "ptmkit/core/json_file.h"
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

}  // namespace ptmkit::calib

namespace ptmkit::calib {

namespace {

Eigen::Vector3d rotate_yaw(const Eigen::Vector3d& v, double yaw_deg) {
  const double a = yaw_deg * std::numbers::pi / 180.0;
  const double c = std::cos(a), s = std::sin(a);
  return {c * v.x() - s * v.y(), s * v.x() + c * v.y(), v.z()};
}

std::string image_name(const std::string& pattern, std::size_t index) {
  char name[512];
  std::snprintf(name, sizeof(name), pattern.c_str(), static_cast<int>(index + 1));
  return name;
}

// Fills direction (and position) of a light, checking it is above the plane.
void place(Light* light, const Eigen::Vector3d& dir_or_pos, bool is_position, double radius_mm,
           double yaw_deg, const std::string& where_text) {
  const Eigen::Vector3d v = rotate_yaw(dir_or_pos, yaw_deg);
  if (v.norm() < 1e-12) throw Error(where_text + ": zero vector");
  if (v.z() <= 0.0) throw Error(where_text + ": light is not above the sample plane (z <= 0)");
  light->direction = v.normalized();
  if (is_position) {
    light->position_mm = v;
  } else if (radius_mm > 0.0) {
    light->position_mm = radius_mm * light->direction;
  }
}

}  // namespace

std::string DomeOptions::validate() const {
  if (!(radius_mm >= 0.0) || !std::isfinite(radius_mm)) return "radius must be >= 0 mm";
  if (!std::isfinite(yaw_deg)) return "yaw must be finite";
  if (name_pattern.find('%') == std::string::npos) {
    return "name pattern must contain a %d-style field for the light index";
  }
  return {};
}

LightSet dome_light_set(const DomeOptions& options) {
  if (const auto err = options.validate(); !err.empty()) throw Error("dome: " + err);
  if (options.layout.size() > 5 &&
      options.layout.compare(options.layout.size() - 5, 5, ".json") == 0) {
    return read_dome_json(options.layout, options);
  }
  const auto dirs = layout_directions(options.layout);
  LightSet set;
  for (std::size_t i = 0; i < dirs.size(); ++i) {
    Light l;
    l.image = image_name(options.name_pattern, i);
    place(&l, dirs[i], false, options.radius_mm, options.yaw_deg,
          "layout " + options.layout + " light " + std::to_string(i + 1));
    set.lights.push_back(std::move(l));
  }
  return set;
}

LightSet read_dome_json(const std::filesystem::path& path, const DomeOptions& defaults) {
  const nlohmann::json j = read_json_object(path, "dome description");
  DomeOptions o = defaults;
  try {
    if (j.contains("radius_mm")) o.radius_mm = j.at("radius_mm").get<double>();
    if (j.contains("yaw_deg")) o.yaw_deg = j.at("yaw_deg").get<double>();
  } catch (const nlohmann::json::exception&) {
    throw Error(where(path) + ": radius_mm and yaw_deg must be numbers");
  }
  if (const auto err = o.validate(); !err.empty()) throw Error(where(path) + ": " + err);
  if (j.contains("layout") == j.contains("lights")) {
    throw Error(where(path) + ": give either \"layout\" or \"lights\", not both or neither");
  }
  if (j.contains("layout")) {
    if (!j["layout"].is_string()) throw Error(where(path) + ": \"layout\" must be a string");
    o.layout = j["layout"].get<std::string>();
    if (o.layout.ends_with(".json")) throw Error(where(path) + ": a layout cannot be a .json");
    try {
      return dome_light_set(o);
    } catch (const Error& e) {
      throw Error(where(path) + ": " + e.what());
    }
  }
  // The lights themselves: the light JSON, one reader in core.
  LightJsonReadOptions lo;
  lo.name_pattern = o.name_pattern;
  lo.radius_mm = o.radius_mm;
  lo.yaw_deg = o.yaw_deg;
  return read_light_json(path, lo);
}

}  // namespace ptmkit::calib
