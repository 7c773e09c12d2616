// The light JSON (core/light_set.h): one reader and one writer for every stage.
#include <cmath>
#include <cstdio>
#include <numbers>
#include <string>

#include <nlohmann/json.hpp>

#include "ptmkit/core/atomic_file.h"
#include "ptmkit/core/error.h"
#include "ptmkit/core/json_file.h"
#include "ptmkit/core/light_set.h"
#include "ptmkit/core/limits.h"

namespace fs = std::filesystem;

namespace ptmkit {

namespace {

constexpr const char* kFrame =
    "light frame: x right, y toward the image top, z toward the camera; mm";

Eigen::Vector3d rotate_yaw(const Eigen::Vector3d& v, double yaw_deg) {
  const double a = yaw_deg * std::numbers::pi / 180.0;
  const double c = std::cos(a), s = std::sin(a);
  return {c * v.x() - s * v.y(), s * v.x() + c * v.y(), v.z()};
}

Eigen::Vector3d vec3(const nlohmann::json& j, const std::string& what) {
  if (!j.is_array() || j.size() != 3 || !j[0].is_number() || !j[1].is_number() ||
      !j[2].is_number()) {
    throw Error(what + " must be an array of three numbers");
  }
  Eigen::Vector3d v(j[0].get<double>(), j[1].get<double>(), j[2].get<double>());
  if (!v.allFinite()) throw Error(what + " is not finite");
  return v;
}

std::string image_name(const std::string& pattern, std::size_t index) {
  char name[512];
  std::snprintf(name, sizeof(name), pattern.c_str(), static_cast<int>(index + 1));
  return name;
}

// The name as write_lp writes it: relative to `base` when it has a folder.
std::string relative_name(const fs::path& image, const fs::path& base) {
  fs::path name = image;
  if (name.is_absolute() || name.has_parent_path()) {
    name = fs::absolute(image).lexically_normal().lexically_relative(base);
    if (name.empty()) name = image;
  }
  return name.generic_string();
}

}  // namespace

LightSet read_light_json(const fs::path& path, const LightJsonReadOptions& options) {
  const nlohmann::json j = read_json_object(path, "light JSON");
  double radius_mm = options.radius_mm;
  double yaw_deg = options.yaw_deg;
  try {
    if (j.contains("radius_mm")) radius_mm = j.at("radius_mm").get<double>();
    if (j.contains("yaw_deg")) yaw_deg = j.at("yaw_deg").get<double>();
  } catch (const nlohmann::json::exception&) {
    throw Error(where(path) + ": radius_mm and yaw_deg must be numbers");
  }
  if (!(radius_mm >= 0.0) || !std::isfinite(radius_mm)) {
    throw Error(where(path) + ": radius must be >= 0 mm");
  }
  if (!std::isfinite(yaw_deg)) throw Error(where(path) + ": yaw must be finite");
  if (j.contains("layout")) {
    throw Error(where(path) +
                ": a dome description (\"layout\"), not a list of lights; write its lights "
                "with `ptmkit calibrate dome --layout " +
                path.filename().string() + " --json LIGHTS.json`");
  }
  if (!j.contains("lights") || !j["lights"].is_array() || j["lights"].empty()) {
    throw Error(where(path) + ": \"lights\" must be a non-empty array");
  }
  const auto& lights = j["lights"];
  if (static_cast<long long>(lights.size()) > kMaxLights) {
    throw Error(where(path) + ": " + std::to_string(lights.size()) + " lights, more than the " +
                std::to_string(kMaxLights) + " allowed");
  }
  LightSet set;
  set.source = path;
  const fs::path base = path.has_parent_path() ? path.parent_path() : ".";
  for (std::size_t i = 0; i < lights.size(); ++i) {
    const std::string what = where(path) + ": light " + std::to_string(i + 1);
    const auto& e = lights[i];
    if (!e.is_object()) throw Error(what + ": expected an object");
    Light l;
    l.image = e.contains("image") && e["image"].is_string()
                  ? (base / e["image"].get<std::string>()).lexically_normal()
                  : fs::path(image_name(options.name_pattern, i));
    const bool has_dir = e.contains("direction");
    const bool has_pos = e.contains("position_mm");
    if (!has_dir && !has_pos) throw Error(what + ": give a direction or position_mm");
    const Eigen::Vector3d v =
        rotate_yaw(vec3(has_pos ? e["position_mm"] : e["direction"], what), yaw_deg);
    if (v.norm() < 1e-12) throw Error(what + ": zero vector");
    if (v.z() <= 0.0) throw Error(what + ": light is not above the sample plane (z <= 0)");
    l.direction = v.normalized();
    if (has_pos) {
      l.position_mm = v;
    } else if (radius_mm > 0.0) {
      l.position_mm = radius_mm * l.direction;
    }
    if (has_dir && has_pos) {
      // Both (as write_light_json writes them): the position rules; the direction must be
      // the one toward it from the plane centre.
      const Eigen::Vector3d d = vec3(e["direction"], what);
      if (d.norm() < 1e-12 ||
          rotate_yaw(d, yaw_deg).normalized().dot(l.direction) < std::cos(0.01)) {
        throw Error(what + ": direction does not point at position_mm from the plane centre");
      }
    }
    if (e.contains("intensity")) {
      if (!e["intensity"].is_number() || !(e["intensity"].get<double>() > 0.0)) {
        throw Error(what + ": intensity must be a positive number");
      }
      l.intensity = e["intensity"].get<double>();
    }
    set.lights.push_back(std::move(l));
  }
  return set;
}

void write_light_json(const fs::path& path, const LightSet& lights) {
  if (lights.empty()) throw Error(where(path) + ": refusing to write an empty light JSON");
  nlohmann::json j;
  j["frame"] = kFrame;
  j["lights"] = nlohmann::json::array();
  const fs::path base = fs::absolute(path).parent_path();
  for (const Light& l : lights.lights) {
    nlohmann::json e;
    e["image"] = relative_name(l.image, base);
    e["direction"] = {l.direction.x(), l.direction.y(), l.direction.z()};
    if (l.position_mm)
      e["position_mm"] = {l.position_mm->x(), l.position_mm->y(), l.position_mm->z()};
    e["intensity"] = l.intensity;
    j["lights"].push_back(e);
  }
  write_file_atomic(path, j.dump(2) + "\n");
}

void attach_light_positions(LightSet* lights, const fs::path& light_json) {
  const LightSet json = read_light_json(light_json);
  const std::string name = where(light_json);
  if (json.size() != lights->size()) {
    throw Error(name + ": " + std::to_string(json.size()) + " lights but the light file has " +
                std::to_string(lights->size()));
  }
  for (std::size_t i = 0; i < json.size(); ++i) {
    const Light& j = json.lights[i];
    Light& l = lights->lights[i];
    if (j.image.filename() != l.image.filename()) {
      throw Error(name + ": light " + std::to_string(i + 1) + " is " + j.image.filename().string() +
                  " but the light file's is " + l.image.filename().string());
    }
    if (!j.position_mm) {
      throw Error(name + ": light " + std::to_string(i + 1) +
                  " has no position_mm (directions only describe distant lights; give "
                  "\"radius_mm\" or each light's \"position_mm\")");
    }
    l.position_mm = j.position_mm;
  }
}

}  // namespace ptmkit
