#include "ptmkit/core/light_set.h"

#include <cmath>
#include <fstream>
#include <iomanip>
#include <limits>
#include <numbers>
#include <sstream>
#include <unordered_map>

#include "ptmkit/core/atomic_file.h"
#include "ptmkit/core/error.h"
#include "ptmkit/core/limits.h"

namespace fs = std::filesystem;

namespace ptmkit {

std::vector<fs::path> LightSet::images() const {
  std::vector<fs::path> out;
  out.reserve(lights.size());
  for (const auto& l : lights) out.push_back(l.image);
  return out;
}

std::vector<Eigen::Vector3d> LightSet::directions() const {
  std::vector<Eigen::Vector3d> out;
  out.reserve(lights.size());
  for (const auto& l : lights) out.push_back(l.direction);
  return out;
}

namespace {

std::vector<std::string> split_ws(const std::string& line) {
  std::vector<std::string> tokens;
  std::istringstream ss(line);
  std::string t;
  while (ss >> t) tokens.push_back(t);
  return tokens;
}

bool parse_double(const std::string& s, double* out) {
  // strtod accepts "nan" and "inf": they parse, and are rejected by the caller with a
  // specific message.
  const char* begin = s.c_str();
  char* end = nullptr;
  *out = std::strtod(begin, &end);
  return end != begin && *end == '\0';
}

bool parse_int(const std::string& s, long* out) {
  const char* begin = s.c_str();
  char* end = nullptr;
  *out = std::strtol(begin, &end, 10);
  return end != begin && *end == '\0';
}

}  // namespace

LightSet read_lp(const fs::path& path) {
  std::error_code ec;
  if (!fs::exists(path, ec)) throw Error(where(path) + ": light file not found");
  checked_input_size(path, kMaxTextFileBytes, "light file");
  std::ifstream in(path, std::ios::binary);
  if (!in) throw Error(where(path) + ": cannot open light file");
  LightSet set;
  set.source = path;
  const fs::path base = path.has_parent_path() ? path.parent_path() : fs::path(".");

  std::string line;
  int line_no = 0;
  long declared = -1;
  int declared_line = 0;
  std::unordered_map<std::string, int> seen;  // normalised image path -> line
  while (std::getline(in, line)) {
    ++line_no;
    if (!line.empty() && line.back() == '\r') line.pop_back();
    if (line_no == 1 && line.size() >= 3 && static_cast<unsigned char>(line[0]) == 0xEF &&
        static_cast<unsigned char>(line[1]) == 0xBB &&
        static_cast<unsigned char>(line[2]) == 0xBF) {
      line.erase(0, 3);  // UTF-8 byte-order mark
    }
    const auto tokens = split_ws(line);
    if (tokens.empty()) continue;
    if (tokens[0][0] == '#') continue;
    if (set.lights.empty() && declared < 0 && tokens.size() == 1) {
      long n = 0;
      if (!parse_int(tokens[0], &n) || n < 0) {
        throw Error(where(path, line_no) + ": expected a light count or 'image x y z', got '" +
                    excerpt(tokens[0]) + "'");
      }
      if (n > kMaxLights) {
        throw Error(where(path, line_no) + ": the count line says " + std::to_string(n) +
                    " lights, more than the " + std::to_string(kMaxLights) + " allowed");
      }
      declared = n;
      declared_line = line_no;
      continue;
    }
    if (tokens.size() < 4) {
      throw Error(where(path, line_no) + ": expected 'image x y z', got " +
                  std::to_string(tokens.size()) + " field(s)");
    }
    // The file name may contain spaces: the last three fields are the vector.
    const std::size_t n = tokens.size();
    std::string name = tokens[0];
    for (std::size_t i = 1; i + 3 < n; ++i) name += " " + tokens[i];
    if (name.size() > kMaxPathChars) {
      throw Error(where(path, line_no) + ": image name of " + std::to_string(name.size()) +
                  " characters, longer than a path may be (" + std::to_string(kMaxPathChars) +
                  "): '" + excerpt(name) + "'");
    }
    Eigen::Vector3d v;
    for (int k = 0; k < 3; ++k) {
      if (!parse_double(tokens[n - 3 + k], &v[k])) {
        throw Error(where(path, line_no) + ": '" + excerpt(tokens[n - 3 + k]) +
                    "' is not a number");
      }
    }
    if (!v.allFinite()) {
      throw Error(where(path, line_no) + ": light direction has NaN or infinite components");
    }
    const double norm = v.norm();
    if (norm < 1e-12) throw Error(where(path, line_no) + ": light direction is the zero vector");
    // Leave vectors that are unit to rounding untouched, so write -> read is exact.
    if (std::abs(norm - 1.0) > 4.0 * std::numeric_limits<double>::epsilon()) v /= norm;
    if (v.z() <= 0.0) {
      throw Error(where(path, line_no) + ": light direction has z <= 0 (" + excerpt(tokens[n - 1]) +
                  "): the light is at or below the sample plane, which lights nothing");
    }
    Light light;
    light.image = (base / name).lexically_normal();
    light.direction = v;
    const std::string key = light.image.string();
    if (auto it = seen.find(key); it != seen.end()) {
      throw Error(where(path, line_no) + ": image '" + excerpt(name) +
                  "' is listed twice (first on line " + std::to_string(it->second) + ")");
    }
    seen.emplace(key, line_no);
    if (static_cast<long long>(set.lights.size()) >= kMaxLights) {
      throw Error(where(path, line_no) + ": more than " + std::to_string(kMaxLights) + " lights");
    }
    set.lights.push_back(std::move(light));
  }
  if (in.bad()) throw Error(where(path) + ": read error");
  if (declared >= 0 && static_cast<std::size_t>(declared) != set.lights.size()) {
    throw Error(where(path, declared_line) + ": the count line says " + std::to_string(declared) +
                " lights but the file lists " + std::to_string(set.lights.size()));
  }
  if (set.lights.empty()) throw Error(where(path) + ": no lights listed");
  return set;
}

void write_lp(const fs::path& path, const LightSet& lights, const LpWriteOptions& options) {
  if (lights.empty()) throw Error(where(path) + ": refusing to write an empty light file");
  const fs::path base = fs::absolute(path).parent_path();
  std::ostringstream out;
  out << std::setprecision(options.precision);
  if (options.count_line) out << lights.size() << "\n";
  for (const auto& l : lights.lights) {
    const Eigen::Vector3d& d = l.direction;
    if (!d.allFinite() || d.norm() < 1e-12 || d.z() <= 0.0) {
      throw Error(where(path) + ": light for '" + l.image.string() +
                  "' has an invalid direction (must be finite with z > 0)");
    }
    const double norm = d.norm();
    const Eigen::Vector3d u =
        std::abs(norm - 1.0) > 4.0 * std::numeric_limits<double>::epsilon() ? d / norm : d;
    fs::path name = l.image;
    if (name.is_absolute() || name.has_parent_path()) {
      name = fs::absolute(l.image).lexically_normal().lexically_relative(base);
      if (name.empty()) name = l.image;
    }
    out << name.generic_string() << " " << u.x() << " " << u.y() << " " << u.z() << "\n";
  }
  write_file_atomic(path, out.str());
}

Eigen::Vector3d direction_from_angles_deg(double elevation_deg, double azimuth_deg) {
  const double el = elevation_deg * std::numbers::pi / 180.0;
  const double az = azimuth_deg * std::numbers::pi / 180.0;
  return {std::cos(el) * std::cos(az), std::cos(el) * std::sin(az), std::sin(el)};
}

double elevation_deg(const Eigen::Vector3d& direction) {
  const Eigen::Vector3d u = direction.normalized();
  return std::asin(std::clamp(u.z(), -1.0, 1.0)) * 180.0 / std::numbers::pi;
}

}  // namespace ptmkit
