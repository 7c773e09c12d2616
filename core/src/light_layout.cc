#include "ptmkit/core/light_layout.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <numbers>
#include <sstream>
#include <string>

#include "ptmkit/core/error.h"
#include "ptmkit/core/light_set.h"
#include "ptmkit/core/limits.h"

namespace ptmkit {

namespace {

// Icosahedron with a vertex at the zenith: the zenith, a ring of five at z = 1/sqrt(5), a ring
// of five at z = -1/sqrt(5) rotated by 36 degrees, and the nadir.
std::vector<std::array<Eigen::Vector3d, 3>> icosahedron_faces() {
  const double z = 1.0 / std::sqrt(5.0);
  const double r = 2.0 / std::sqrt(5.0);
  const double step = 2.0 * std::numbers::pi / 5.0;
  std::array<Eigen::Vector3d, 5> upper;
  std::array<Eigen::Vector3d, 5> lower;
  for (int k = 0; k < 5; ++k) {
    upper[k] = {r * std::cos(k * step), r * std::sin(k * step), z};
    lower[k] = {r * std::cos(k * step + step / 2), r * std::sin(k * step + step / 2), -z};
  }
  const Eigen::Vector3d top(0, 0, 1);
  const Eigen::Vector3d bottom(0, 0, -1);
  std::vector<std::array<Eigen::Vector3d, 3>> faces;
  for (int k = 0; k < 5; ++k) {
    const int n = (k + 1) % 5;
    faces.push_back({top, upper[k], upper[n]});
    faces.push_back({upper[k], lower[k], upper[n]});
    faces.push_back({lower[k], lower[n], upper[n]});
    faces.push_back({bottom, lower[n], lower[k]});
  }
  return faces;
}

}  // namespace

std::vector<Eigen::Vector3d> geodesic_dome(int frequency) {
  if (frequency < 1 || frequency > 64) {
    throw Error("geodesic dome frequency must be 1..64, got " + std::to_string(frequency));
  }
  const int f = frequency;
  std::vector<Eigen::Vector3d> centres;
  for (const auto& face : icosahedron_faces()) {
    auto point = [&](int i, int j) -> Eigen::Vector3d {
      const int k = f - i - j;
      return ((i * face[0] + j * face[1] + k * face[2]) / f).normalized();
    };
    auto add = [&](const Eigen::Vector3d& a, const Eigen::Vector3d& b, const Eigen::Vector3d& c) {
      const Eigen::Vector3d centre = (a + b + c).normalized();
      // A centre on the horizon lights nothing; none occurs for the usual frequencies.
      if (centre.z() > 1e-9) centres.push_back(centre);
    };
    for (int i = 0; i < f; ++i) {
      for (int j = 0; j < f - i; ++j) {
        add(point(i, j), point(i + 1, j), point(i, j + 1));
        if (i + j <= f - 2) add(point(i + 1, j), point(i + 1, j + 1), point(i, j + 1));
      }
    }
  }
  auto key = [](const Eigen::Vector3d& d) {
    const double el = std::round(elevation_deg(d) * 1e6);
    double az = std::atan2(d.y(), d.x()) * 180.0 / std::numbers::pi;
    if (az < 0) az += 360.0;
    return std::pair<double, double>(-el, std::round(az * 1e6));
  };
  std::sort(centres.begin(), centres.end(),
            [&](const auto& a, const auto& b) { return key(a) < key(b); });
  return centres;
}

std::vector<Ring> parse_rings(std::string_view spec) {
  std::vector<Ring> rings;
  long long total = 0;
  std::string s(spec);
  if (s.empty()) throw Error("empty ring specification (expected elevation:count,...)");
  std::stringstream all(s);
  std::string item;
  while (std::getline(all, item, ',')) {
    std::vector<std::string> parts;
    std::stringstream one(item);
    std::string p;
    while (std::getline(one, p, ':')) parts.push_back(p);
    if (parts.size() < 2 || parts.size() > 3) {
      throw Error("ring '" + excerpt(item) + "': expected elevation:count[:azimuth_offset]");
    }
    Ring ring;
    try {
      std::size_t used = 0;
      ring.elevation_deg = std::stod(parts[0], &used);
      if (used != parts[0].size()) throw std::invalid_argument("trailing");
      ring.count = std::stoi(parts[1], &used);
      if (used != parts[1].size()) throw std::invalid_argument("trailing");
      if (parts.size() == 3) {
        ring.azimuth_offset_deg = std::stod(parts[2], &used);
        if (used != parts[2].size()) throw std::invalid_argument("trailing");
      }
    } catch (const std::exception&) {
      throw Error("ring '" + excerpt(item) +
                  "': not numbers (expected elevation:count[:azimuth_offset])");
    }
    if (!(ring.elevation_deg > 0.0 && ring.elevation_deg <= 90.0)) {
      throw Error("ring '" + excerpt(item) + "': elevation must be in (0, 90] degrees");
    }
    if (ring.count < 1 || ring.count > kMaxRingLights) {
      throw Error("ring '" + excerpt(item) + "': count must be 1.." +
                  std::to_string(kMaxRingLights));
    }
    if (!std::isfinite(ring.azimuth_offset_deg)) {
      throw Error("ring '" + excerpt(item) + "': azimuth offset is not finite");
    }
    rings.push_back(ring);
    total += ring.elevation_deg >= 90.0 ? 1 : ring.count;
    if (total > kMaxLights) {
      throw Error("ring specification: more than " + std::to_string(kMaxLights) + " lights in all");
    }
  }
  return rings;
}

std::vector<Eigen::Vector3d> ring_layout(const std::vector<Ring>& rings) {
  std::vector<Eigen::Vector3d> dirs;
  for (const Ring& ring : rings) {
    const int n = ring.elevation_deg >= 90.0 ? 1 : ring.count;
    for (int k = 0; k < n; ++k) {
      dirs.push_back(
          direction_from_angles_deg(ring.elevation_deg, ring.azimuth_offset_deg + 360.0 * k / n));
    }
  }
  return dirs;
}

}  // namespace ptmkit
