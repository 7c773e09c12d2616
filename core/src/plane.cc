#include "ptmkit/core/plane.h"

#include <cmath>
#include <fstream>
#include <limits>
#include <sstream>
#include <string>

#include <Eigen/Geometry>
#include <Eigen/LU>
#include <nlohmann/json.hpp>

#include "ptmkit/core/atomic_file.h"
#include "ptmkit/core/error.h"
#include "ptmkit/core/json_file.h"

namespace ptmkit {

Eigen::Vector2d SamplePlane::plane_mm(const Eigen::Vector2d& pixel) const {
  const Eigen::Vector3d h = pixel_to_plane_mm * Eigen::Vector3d(pixel.x(), pixel.y(), 1.0);
  return {h.x() / h.z(), h.y() / h.z()};
}

double SamplePlane::mean_mm_per_px() const {
  if (width_px < 2 || height_px < 2) return 0.0;
  const Eigen::Vector2d a = plane_mm({0.0, 0.0});
  const Eigen::Vector2d b = plane_mm({width_px - 1.0, 0.0});
  const Eigen::Vector2d c = plane_mm({0.0, height_px - 1.0});
  return 0.5 * ((b - a).norm() / (width_px - 1.0) + (c - a).norm() / (height_px - 1.0));
}

SamplePlane orthographic_plane(int width_px, int height_px, double mm_per_px) {
  if (width_px <= 0 || height_px <= 0 || !(mm_per_px > 0.0) || !std::isfinite(mm_per_px)) {
    throw Error("orthographic plane: size and mm per pixel must be positive");
  }
  SamplePlane plane;
  plane.width_px = width_px;
  plane.height_px = height_px;
  const double cx = 0.5 * (width_px - 1.0);
  const double cy = 0.5 * (height_px - 1.0);
  // X = (x - cx) m, Y = (cy - y) m: image down is plane -y.
  plane.pixel_to_plane_mm << mm_per_px, 0.0, -cx * mm_per_px, 0.0, -mm_per_px, cy * mm_per_px, 0.0,
      0.0, 1.0;
  return plane;
}

namespace {

using nlohmann::json;

Eigen::Matrix3d matrix_from(const json& j, const std::string& key, const std::string& where) {
  if (!j.contains(key)) throw Error(where + ": missing \"" + key + "\"");
  const json& m = j.at(key);
  if (!m.is_array() || m.size() != 3) throw Error(where + ": \"" + key + "\" must be 3 rows");
  Eigen::Matrix3d out;
  for (int r = 0; r < 3; ++r) {
    const json& row = m.at(static_cast<std::size_t>(r));
    if (!row.is_array() || row.size() != 3) {
      throw Error(where + ": \"" + key + "\" must be 3 rows of 3 numbers");
    }
    for (int c = 0; c < 3; ++c) {
      const json& v = row.at(static_cast<std::size_t>(c));
      if (!v.is_number()) throw Error(where + ": \"" + key + "\" holds a non-number");
      out(r, c) = v.get<double>();
      if (!std::isfinite(out(r, c))) throw Error(where + ": \"" + key + "\" is not finite");
    }
  }
  return out;
}

json rows_of(const Eigen::Matrix3d& m) {
  json out = json::array();
  for (int r = 0; r < 3; ++r) out.push_back({m(r, 0), m(r, 1), m(r, 2)});
  return out;
}

}  // namespace

SamplePlane read_plane_json(const std::filesystem::path& path) {
  const std::string where = path.string();
  const nlohmann::json j = read_json_object(path, "sample-plane file");
  SamplePlane plane;
  try {
    plane.width_px = json_int(j, "width_px", std::numeric_limits<int>::min(),
                              std::numeric_limits<int>::max(), where);
    plane.height_px = json_int(j, "height_px", std::numeric_limits<int>::min(),
                               std::numeric_limits<int>::max(), where);
  } catch (const json::exception&) {
    throw Error(where + ": width_px and height_px must be integers");
  }
  if (plane.width_px <= 0 || plane.height_px <= 0) {
    throw Error(where + ": width_px and height_px must be positive");
  }
  plane.pixel_to_plane_mm = matrix_from(j, "pixel_to_plane_mm", where);
  const double det = plane.pixel_to_plane_mm.determinant();
  if (!(std::abs(det) > 1e-300) || !std::isfinite(det)) {
    throw Error(where + ": pixel_to_plane_mm is singular");
  }
  // The plane must not pass through the homography's line at infinity inside the image.
  for (const auto& corner : {Eigen::Vector2d(0, 0), Eigen::Vector2d(plane.width_px - 1, 0),
                             Eigen::Vector2d(0, plane.height_px - 1),
                             Eigen::Vector2d(plane.width_px - 1, plane.height_px - 1)}) {
    const double w = (plane.pixel_to_plane_mm * corner.homogeneous()).z();
    const double w0 = (plane.pixel_to_plane_mm * Eigen::Vector3d(0, 0, 1)).z();
    if (!(w * w0 > 0.0)) throw Error(where + ": pixel_to_plane_mm maps the image to infinity");
  }
  if (j.contains("camera_from_plane") || j.contains("plane_origin_in_camera_mm")) {
    PlanePose pose;
    pose.camera_from_plane = matrix_from(j, "camera_from_plane", where);
    const Eigen::Matrix3d rtr = pose.camera_from_plane.transpose() * pose.camera_from_plane;
    if ((rtr - Eigen::Matrix3d::Identity()).cwiseAbs().maxCoeff() > 1e-6 ||
        pose.camera_from_plane.determinant() < 0.0) {
      throw Error(where + ": camera_from_plane is not a rotation");
    }
    if (!j.contains("plane_origin_in_camera_mm")) {
      throw Error(where + ": missing \"plane_origin_in_camera_mm\"");
    }
    const json& t = j.at("plane_origin_in_camera_mm");
    if (!t.is_array() || t.size() != 3) {
      throw Error(where + ": plane_origin_in_camera_mm must be 3 numbers");
    }
    for (int i = 0; i < 3; ++i) {
      const json& v = t.at(static_cast<std::size_t>(i));
      if (!v.is_number() || !std::isfinite(v.get<double>())) {
        throw Error(where + ": plane_origin_in_camera_mm must be 3 finite numbers");
      }
      pose.plane_origin_in_camera_mm(i) = v.get<double>();
    }
    plane.pose = pose;
  }
  return plane;
}

void write_plane_json(const std::filesystem::path& path, const SamplePlane& plane) {
  json j;
  j["width_px"] = plane.width_px;
  j["height_px"] = plane.height_px;
  j["pixel_to_plane_mm"] = rows_of(plane.pixel_to_plane_mm);
  if (plane.pose) {
    j["camera_from_plane"] = rows_of(plane.pose->camera_from_plane);
    const auto& t = plane.pose->plane_origin_in_camera_mm;
    j["plane_origin_in_camera_mm"] = {t.x(), t.y(), t.z()};
  }
  j["mm_per_px"] = plane.mean_mm_per_px();
  write_file_atomic(path, j.dump(2) + "\n");
}

}  // namespace ptmkit
