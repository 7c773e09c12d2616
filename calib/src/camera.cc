#include "ptmkit/calib/camera.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <functional>
#include <limits>
#include <string>

#include <Eigen/LU>
#include <nlohmann/json.hpp>
#include <opencv2/calib3d.hpp>
#include <opencv2/core.hpp>

#include "ptmkit/core/atomic_file.h"
#include "ptmkit/core/error.h"
#include "ptmkit/core/image_io.h"
#include "ptmkit/core/json_file.h"

namespace ptmkit::calib {

namespace {

using nlohmann::json;
constexpr double kPi = 3.14159265358979323846;

cv::Matx33d camera_matrix(const CameraIntrinsics& c) {
  return {c.fx, 0.0, c.cx, 0.0, c.fy, c.cy, 0.0, 0.0, 1.0};
}

std::vector<double> distortion(const CameraIntrinsics& c) { return {c.k1, c.k2, c.p1, c.p2, c.k3}; }

// Matched corners of one image: board points (z = 0) and detected pixels.
struct Matches {
  int detected = 0;
  int tags = 0;
  std::vector<int> ids;
  std::vector<cv::Point3f> object;
  std::vector<cv::Point2f> image;
};

Matches match_board(ConstImageViewF image, const TagBoard& board, TagDetectorOptions detector,
                    const std::optional<TagFamily>& family) {
  detector.family = family ? *family : parse_tag_family(board.family);
  const auto found = detect_tags(image, detector);
  Matches m;
  m.detected = static_cast<int>(found.size());
  for (std::size_t i = 0; i < found.size(); ++i) {
    const int id = found[i].id;
    // Two detections of one id are ambiguous (a second board, a reflection): use neither.
    const bool duplicate =
        (i > 0 && found[i - 1].id == id) || (i + 1 < found.size() && found[i + 1].id == id);
    const BoardTag* tag = board.find(id);
    if (duplicate || tag == nullptr) continue;
    ++m.tags;
    m.ids.push_back(id);
    for (std::size_t k = 0; k < 4; ++k) {
      m.object.emplace_back(static_cast<float>(tag->corners_mm[k].x()),
                            static_cast<float>(tag->corners_mm[k].y()), 0.0f);
      m.image.emplace_back(static_cast<float>(found[i].corners_px[k].x()),
                           static_cast<float>(found[i].corners_px[k].y()));
    }
  }
  return m;
}

Eigen::Matrix3d rotation(const cv::Mat& rvec) {
  cv::Matx33d r;
  cv::Rodrigues(rvec, r);
  Eigen::Matrix3d out;
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) out(i, j) = r(i, j);
  return out;
}

Eigen::Vector3d vec3(const cv::Mat& v) {
  cv::Mat d;
  v.convertTo(d, CV_64F);
  return {d.at<double>(0), d.at<double>(1), d.at<double>(2)};
}

double rms(const std::vector<cv::Point3f>& object, const std::vector<cv::Point2f>& image,
           const cv::Mat& rvec, const cv::Mat& tvec, const cv::Matx33d& k,
           const std::vector<double>& dist) {
  std::vector<cv::Point2f> projected;
  cv::projectPoints(object, rvec, tvec, k, dist, projected);
  double sum = 0.0;
  for (std::size_t i = 0; i < image.size(); ++i) {
    const double dx = projected[i].x - image[i].x, dy = projected[i].y - image[i].y;
    sum += dx * dx + dy * dy;
  }
  return image.empty() ? 0.0 : std::sqrt(sum / static_cast<double>(image.size()));
}

json rows_of(const Eigen::Matrix3d& m) {
  json out = json::array();
  for (int r = 0; r < 3; ++r) out.push_back({m(r, 0), m(r, 1), m(r, 2)});
  return out;
}

json camera_json(const CameraIntrinsics& c) {
  return {{"width_px", c.width_px},
          {"height_px", c.height_px},
          {"fx", c.fx},
          {"fy", c.fy},
          {"cx", c.cx},
          {"cy", c.cy},
          {"k1", c.k1},
          {"k2", c.k2},
          {"p1", c.p1},
          {"p2", c.p2},
          {"k3", c.k3},
          {"rms_px", c.rms_px}};
}

std::string view_name(const std::vector<std::filesystem::path>& names, std::size_t i) {
  if (i < names.size()) return names[i].filename().string();
  std::string s = "view ";
  s.append(std::to_string(i + 1));
  return s;
}

}  // namespace

std::string CameraIntrinsics::validate() const {
  if (width_px < 1 || height_px < 1) return "width_px and height_px must be positive";
  if (!(fx > 0.0) || !(fy > 0.0) || !std::isfinite(fx) || !std::isfinite(fy)) {
    return "fx and fy must be positive";
  }
  for (const double v : {cx, cy, k1, k2, p1, p2, k3, rms_px}) {
    if (!std::isfinite(v)) return "values must be finite";
  }
  return {};
}

std::vector<Eigen::Vector2d> CameraIntrinsics::undistort(
    const std::vector<Eigen::Vector2d>& pixels) const {
  if (pixels.empty()) return {};
  std::vector<cv::Point2d> in, out;
  for (const auto& p : pixels) in.emplace_back(p.x(), p.y());
  const cv::Matx33d k = camera_matrix(*this);
  cv::undistortPoints(in, out, k, distortion(*this), cv::noArray(), k,
                      cv::TermCriteria(cv::TermCriteria::COUNT | cv::TermCriteria::EPS, 50, 1e-12));
  std::vector<Eigen::Vector2d> result;
  for (const auto& p : out) result.emplace_back(p.x, p.y);
  return result;
}

SphereCamera sphere_camera(const CameraIntrinsics& camera, int width_px, int height_px,
                           const std::filesystem::path& source) {
  if (camera.width_px != width_px || camera.height_px != height_px) {
    char text[160];
    std::snprintf(text, sizeof text,
                  ": the camera was calibrated at %dx%d, the photographs are %dx%d",
                  camera.width_px, camera.height_px, width_px, height_px);
    throw Error(source.string() + text);
  }
  SphereCamera out;
  out.focal_px = 0.5 * (camera.fx + camera.fy);
  out.principal_px = Eigen::Vector2d(camera.cx, camera.cy);
  return out;
}

SphereCamera resolve_sphere_camera(const CameraSource& source, int width_px, int height_px) {
  const int given = (source.camera_json.empty() ? 0 : 1) + (source.focal_mm > 0.0 ? 1 : 0) +
                    (source.focal_px > 0.0 ? 1 : 0);
  if (given > 1) {
    throw Error(
        "give the focal length once: a camera file, a lens in mm or a focal length in pixels");
  }
  SphereCamera cam;
  char text[200];
  if (!source.camera_json.empty()) {
    cam = sphere_camera(read_camera_json(source.camera_json), width_px, height_px,
                        source.camera_json);
    cam.focal_source = "camera file " + source.camera_json.string();
  } else if (source.focal_mm > 0.0) {
    if (!(source.sensor_width_mm > 0.0)) {
      throw Error("a lens focal length in mm needs the sensor's width in mm");
    }
    cam.focal_px = focal_px_from_lens(source.focal_mm, source.sensor_width_mm, width_px);
    std::snprintf(text, sizeof text, "a %.4g mm lens on a %.4g mm wide sensor", source.focal_mm,
                  source.sensor_width_mm);
    cam.focal_source = text;
  } else if (source.focal_px > 0.0) {
    cam.focal_px = source.focal_px;
    cam.focal_source = "--focal-px";
  } else if (source.exif_focal_px > 0.0) {
    cam.focal_px = source.exif_focal_px;
    cam.focal_source = "the photographs' " + source.exif_note;
  } else {
    cam.focal_source = "none: orthographic camera" +
                       (source.exif_note.empty() ? std::string() : " (" + source.exif_note + ")");
  }
  if (source.principal_px) cam.principal_px = source.principal_px;
  return cam;
}

PhotoFocal focal_from_exif(const std::vector<std::filesystem::path>& photos) {
  PhotoFocal out;
  if (photos.empty()) return out;
  double lo = 0.0, hi = 0.0;
  int with = 0;
  std::string evidence;
  for (const std::filesystem::path& p : photos) {
    const ImageInfo info = probe_image(p);
    if (!(info.focal_px > 0.0)) continue;
    if (with == 0) {
      lo = hi = info.focal_px;
      evidence = info.focal_evidence;
    }
    lo = std::min(lo, info.focal_px);
    hi = std::max(hi, info.focal_px);
    ++with;
  }
  char text[300];
  if (with == 0) {
    out.note = "no EXIF focal length in the photographs";
  } else if (with < static_cast<int>(photos.size())) {
    std::snprintf(text, sizeof text, "EXIF focal length in %d of %zu photographs only: not used",
                  with, photos.size());
    out.note = text;
  } else if (hi > 1.005 * lo) {
    std::snprintf(text, sizeof text,
                  "EXIF focal lengths differ between the photographs (%.1f to %.1f px: the zoom "
                  "turned during the capture?): not used",
                  lo, hi);
    out.note = text;
  } else {
    out.focal_px = lo;
    out.note = evidence;
  }
  return out;
}

double focal_px_from_lens(double focal_mm, double sensor_width_mm, int width_px) {
  if (!(focal_mm > 0.0) || !(sensor_width_mm > 0.0) || !std::isfinite(focal_mm) ||
      !std::isfinite(sensor_width_mm)) {
    throw Error("the lens focal length and the sensor width must both be positive (mm)");
  }
  return focal_mm / sensor_width_mm * width_px;
}

CameraIntrinsics read_camera_json(const std::filesystem::path& path) {
  const std::string where = path.string();
  const nlohmann::json j = read_json_object(path, "camera file");
  CameraIntrinsics c;
  try {
    c.width_px = json_int(j, "width_px", std::numeric_limits<int>::min(),
                          std::numeric_limits<int>::max(), where);
    c.height_px = json_int(j, "height_px", std::numeric_limits<int>::min(),
                           std::numeric_limits<int>::max(), where);
    c.fx = j.at("fx").get<double>();
    c.fy = j.at("fy").get<double>();
    c.cx = j.at("cx").get<double>();
    c.cy = j.at("cy").get<double>();
    c.k1 = j.value("k1", 0.0);
    c.k2 = j.value("k2", 0.0);
    c.p1 = j.value("p1", 0.0);
    c.p2 = j.value("p2", 0.0);
    c.k3 = j.value("k3", 0.0);
    c.rms_px = j.value("rms_px", 0.0);
  } catch (const json::exception& e) {
    throw Error(where + ": malformed camera file (" + e.what() + ")");
  }
  if (const auto err = c.validate(); !err.empty()) throw Error(where + ": " + err);
  return c;
}

void write_camera_json(const std::filesystem::path& path, const CameraIntrinsics& camera) {
  if (const auto err = camera.validate(); !err.empty()) {
    throw Error(path.string() + ": not writing invalid intrinsics: " + err);
  }
  write_file_atomic(path, camera_json(camera).dump(2) + "\n");
}

std::string CameraCalibrationOptions::validate() const {
  if (const auto err = detector.validate(); !err.empty()) return err;
  if (min_tags_per_view < 1) return "min_tags_per_view must be at least 1";
  return {};
}

std::string PlaneOptions::validate() const {
  if (const auto err = detector.validate(); !err.empty()) return err;
  if (!origin_mm.allFinite()) return "origin_mm must be finite";
  return {};
}

std::string CameraReport::to_json() const {
  json j;
  j["camera"] = camera_json(camera);
  j["rms_px"] = rms_px;
  j["views_used"] = views_used;
  j["corners_used"] = corners_used;
  j["calibrate_camera_flags"] = flags;
  json vs = json::array();
  for (const auto& v : views) {
    json jv = {{"image", v.image},
               {"tags_detected", v.tags_detected},
               {"tags_used", v.tags_used},
               {"used", v.used}};
    if (v.used) {
      jv["rms_px"] = v.rms_px;
      jv["camera_from_board"] = rows_of(v.camera_from_board);
      const auto& t = v.board_origin_in_camera_mm;
      jv["board_origin_in_camera_mm"] = {t.x(), t.y(), t.z()};
    } else {
      jv["reason"] = v.reason;
    }
    vs.push_back(jv);
  }
  j["views"] = vs;
  return j.dump(2);
}

CameraReport calibrate_camera(const std::vector<Image>& images,
                              const std::vector<std::filesystem::path>& names,
                              const TagBoard& board, const CameraCalibrationOptions& options) {
  return calibrate_camera(
      images.size(), [&](std::size_t i) { return images[i]; }, names, board, options);
}

CameraReport calibrate_camera(std::size_t views, const std::function<Image(std::size_t)>& load,
                              const std::vector<std::filesystem::path>& names,
                              const TagBoard& board, const CameraCalibrationOptions& options) {
  if (const auto err = options.validate(); !err.empty()) throw Error("calibrate camera: " + err);
  if (const auto err = board.validate(); !err.empty()) throw Error("calibrate camera: " + err);
  if (views == 0) throw Error("calibrate camera: no images");
  int width = 0, height = 0;
  CameraReport report;
  std::vector<std::vector<cv::Point3f>> object;
  std::vector<std::vector<cv::Point2f>> image_points;
  std::vector<std::size_t> used_index;
  for (std::size_t i = 0; i < views; ++i) {
    CameraView view;
    view.image = view_name(names, i);
    const Image image = load(i);  // one view in memory at a time
    if (i == 0) {
      width = image.width();
      height = image.height();
    }
    if (image.width() != width || image.height() != height) {
      throw Error("calibrate camera: " + view.image + " is " + std::to_string(image.width()) + "x" +
                  std::to_string(image.height()) + ", the first view is " + std::to_string(width) +
                  "x" + std::to_string(height));
    }
    const Matches m = match_board(image.view(), board, options.detector, options.family);
    view.tags_detected = m.detected;
    view.tags_used = m.tags;
    if (m.tags < options.min_tags_per_view) {
      char buf[160];
      std::snprintf(buf, sizeof buf, "%d board tags found (%d detections), fewer than %d", m.tags,
                    m.detected, options.min_tags_per_view);
      view.reason = buf;
    } else {
      view.used = true;
      object.push_back(m.object);
      image_points.push_back(m.image);
      used_index.push_back(i);
    }
    report.views.push_back(view);
  }
  if (object.size() < 3) {
    std::string msg = "calibrate camera: " + std::to_string(object.size()) +
                      " usable views, at least 3 are needed";
    for (const auto& v : report.views) {
      if (!v.used) msg += "\n  " + v.image + ": " + v.reason;
    }
    throw Error(msg);
  }
  int flags = 0;
  if (options.fix_k3) flags |= cv::CALIB_FIX_K3;
  if (options.zero_tangential) flags |= cv::CALIB_ZERO_TANGENT_DIST;
  cv::Matx33d k = cv::Matx33d::eye();
  if (options.square_pixels) flags |= cv::CALIB_FIX_ASPECT_RATIO;  // keeps fx / fy = 1
  std::vector<double> dist(5, 0.0);
  std::vector<cv::Mat> rvecs, tvecs;
  cv::calibrateCamera(
      object, image_points, cv::Size(width, height), k, dist, rvecs, tvecs, flags,
      cv::TermCriteria(cv::TermCriteria::COUNT | cv::TermCriteria::EPS, 100, 1e-12));
  report.flags = flags;
  CameraIntrinsics& c = report.camera;
  c.width_px = width;
  c.height_px = height;
  c.fx = k(0, 0);
  c.fy = k(1, 1);
  c.cx = k(0, 2);
  c.cy = k(1, 2);
  c.k1 = dist[0];
  c.k2 = dist[1];
  c.p1 = dist[2];
  c.p2 = dist[3];
  c.k3 = dist[4];
  double sum = 0.0;
  for (std::size_t v = 0; v < object.size(); ++v) {
    CameraView& view = report.views[used_index[v]];
    view.rms_px = rms(object[v], image_points[v], rvecs[v], tvecs[v], k, dist);
    view.camera_from_board = rotation(rvecs[v]);
    view.board_origin_in_camera_mm = vec3(tvecs[v]);
    sum += view.rms_px * view.rms_px * static_cast<double>(object[v].size());
    report.corners_used += static_cast<int>(object[v].size());
  }
  report.views_used = static_cast<int>(object.size());
  report.rms_px = std::sqrt(sum / report.corners_used);
  c.rms_px = report.rms_px;
  return report;
}

std::string PlaneReport::to_json() const {
  json j;
  j["tags_used"] = tags_used;
  j["corners_used"] = corners_used;
  j["tag_ids"] = tag_ids;
  j["rms_px"] = rms_px;
  j["tilt_deg"] = tilt_deg;
  j["distance_mm"] = distance_mm;
  j["mm_per_px"] = plane.mean_mm_per_px();
  j["pixel_to_plane_mm"] = rows_of(plane.pixel_to_plane_mm);
  j["pixels"] = "undistorted";
  if (plane.pose) {
    j["camera_from_plane"] = rows_of(plane.pose->camera_from_plane);
    const auto& t = plane.pose->plane_origin_in_camera_mm;
    j["plane_origin_in_camera_mm"] = {t.x(), t.y(), t.z()};
  }
  return j.dump(2);
}

PlaneReport estimate_plane(const Image& image, const TagBoard& board,
                           const CameraIntrinsics& camera, const PlaneOptions& options) {
  if (const auto err = options.validate(); !err.empty()) throw Error("calibrate plane: " + err);
  if (const auto err = board.validate(); !err.empty()) throw Error("calibrate plane: " + err);
  if (const auto err = camera.validate(); !err.empty()) throw Error("calibrate plane: " + err);
  if (image.width() != camera.width_px || image.height() != camera.height_px) {
    throw Error("calibrate plane: the image is " + std::to_string(image.width()) + "x" +
                std::to_string(image.height()) + ", the camera was calibrated at " +
                std::to_string(camera.width_px) + "x" + std::to_string(camera.height_px));
  }
  const Matches m = match_board(image.view(), board, options.detector, options.family);
  if (m.tags < 1) {
    throw Error("calibrate plane: no tag of the board found (" + std::to_string(m.detected) +
                " detections of the family)");
  }
  const cv::Matx33d k = camera_matrix(camera);
  const std::vector<double> dist = distortion(camera);
  // Object points relative to the plane origin; pixels undistorted (ideal pinhole).
  std::vector<cv::Point3d> object;
  std::vector<cv::Point2d> distorted, ideal;
  for (std::size_t i = 0; i < m.object.size(); ++i) {
    object.emplace_back(m.object[i].x - options.origin_mm.x(),
                        m.object[i].y - options.origin_mm.y(), 0.0);
    distorted.emplace_back(m.image[i].x, m.image[i].y);
  }
  cv::undistortPoints(distorted, ideal, k, dist, cv::noArray(), k,
                      cv::TermCriteria(cv::TermCriteria::COUNT | cv::TermCriteria::EPS, 50, 1e-12));
  cv::Mat rvec, tvec;
  if (!cv::solvePnP(object, ideal, k, cv::noArray(), rvec, tvec, false, cv::SOLVEPNP_IPPE)) {
    throw Error("calibrate plane: the board pose could not be solved");
  }
  cv::solvePnPRefineLM(object, ideal, k, cv::noArray(), rvec, tvec);

  PlaneReport report;
  report.tags_used = m.tags;
  report.tag_ids = m.ids;
  report.corners_used = static_cast<int>(object.size());
  {
    std::vector<cv::Point2d> projected;
    cv::projectPoints(object, rvec, tvec, k, dist, projected);
    double sum = 0.0;
    for (std::size_t i = 0; i < projected.size(); ++i) {
      const double dx = projected[i].x - distorted[i].x, dy = projected[i].y - distorted[i].y;
      sum += dx * dx + dy * dy;
    }
    report.rms_px = std::sqrt(sum / static_cast<double>(projected.size()));
  }
  const Eigen::Matrix3d r = rotation(rvec);
  const Eigen::Vector3d t = vec3(tvec);
  Eigen::Matrix3d kk;
  kk << camera.fx, 0.0, camera.cx, 0.0, camera.fy, camera.cy, 0.0, 0.0, 1.0;
  Eigen::Matrix3d h;  // plane (X, Y, 1) -> undistorted pixel
  h.col(0) = r.col(0);
  h.col(1) = r.col(1);
  h.col(2) = t;
  h = kk * h;
  Eigen::Matrix3d inv = h.inverse();
  // Scale so that W = 1 at pixel (0, 0), unless the plane's horizon passes there.
  inv /= std::abs(inv(2, 2)) > 1e-12 * inv.cwiseAbs().maxCoeff() ? inv(2, 2)
                                                                 : inv.cwiseAbs().maxCoeff();
  SamplePlane& plane = report.plane;
  plane.width_px = image.width();
  plane.height_px = image.height();
  plane.pixel_to_plane_mm = inv;
  PlanePose pose;
  pose.camera_from_plane = r;
  pose.plane_origin_in_camera_mm = t;
  plane.pose = pose;
  // The plane normal points toward the camera, i.e. along -z of the camera frame.
  report.tilt_deg = std::acos(std::clamp(-r(2, 2), -1.0, 1.0)) * 180.0 / kPi;
  report.distance_mm = t.norm();
  return report;
}

}  // namespace ptmkit::calib
