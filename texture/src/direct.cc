#include "ptmkit/texture/direct.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <map>
#include <opencv2/imgproc.hpp>
#include <string>
#include <utility>

#include "ptmkit/core/error.h"
#include "ptmkit/core/image_io.h"
#include "ptmkit/texture/relight.h"

namespace ptmkit::texture {

namespace {
constexpr double kScale = 1000.0;  // Subdiv2D works in a float rectangle with integer bounds

// Barycentric coordinates of q in triangle (a, b, c).
std::array<double, 3> barycentric(const Eigen::Vector2d& a, const Eigen::Vector2d& b,
                                  const Eigen::Vector2d& c, const Eigen::Vector2d& q) {
  const double det = (b.y() - c.y()) * (a.x() - c.x()) + (c.x() - b.x()) * (a.y() - c.y());
  const double l0 = ((b.y() - c.y()) * (q.x() - c.x()) + (c.x() - b.x()) * (q.y() - c.y())) / det;
  const double l1 = ((c.y() - a.y()) * (q.x() - c.x()) + (a.x() - c.x()) * (q.y() - c.y())) / det;
  return {l0, l1, 1.0 - l0 - l1};
}

Eigen::Vector2d closest_on_segment(const Eigen::Vector2d& a, const Eigen::Vector2d& b,
                                   const Eigen::Vector2d& q) {
  const Eigen::Vector2d d = b - a;
  const double t = std::clamp((q - a).dot(d) / d.squaredNorm(), 0.0, 1.0);
  return a + t * d;
}
}  // namespace

LightTriangulation::LightTriangulation(const std::vector<Eigen::Vector3d>& dirs) {
  cv::Subdiv2D sub(cv::Rect(-2000, -2000, 4000, 4000));
  std::map<std::pair<float, float>, int> index;
  for (const auto& d : dirs) {
    const Eigen::Vector3d n = normalised_light(d);
    const cv::Point2f p(static_cast<float>(n.x() * kScale), static_cast<float>(n.y() * kScale));
    if (index.count({p.x, p.y})) continue;  // duplicate direction: keep the first
    // Photo index = position in `dirs`.
    index[{p.x, p.y}] = static_cast<int>(&d - dirs.data());
    sub.insert(p);
  }
  points_.resize(dirs.size());
  for (std::size_t i = 0; i < dirs.size(); ++i) {
    const Eigen::Vector3d n = normalised_light(dirs[i]);
    points_[i] = {n.x(), n.y()};
  }
  std::vector<cv::Vec6f> tris;
  sub.getTriangleList(tris);
  for (const auto& t : tris) {
    std::array<int, 3> ids{};
    bool ok = true;
    for (int k = 0; k < 3 && ok; ++k) {
      const auto it = index.find({t[2 * k], t[2 * k + 1]});
      ok = it != index.end();
      if (ok) ids[static_cast<std::size_t>(k)] = it->second;
    }
    if (!ok) continue;  // a triangle touching Subdiv2D's outer vertices
    const auto& a = points_[static_cast<std::size_t>(ids[0])];
    const auto& b = points_[static_cast<std::size_t>(ids[1])];
    const auto& c = points_[static_cast<std::size_t>(ids[2])];
    const double area = (b - a).x() * (c - a).y() - (b - a).y() * (c - a).x();
    if (std::abs(area) < 1e-14) continue;
    triangles_.push_back(ids);
  }
  if (triangles_.empty())
    throw Error("direct rendering needs at least 3 distinct light directions not on one line");
}

LightWeights LightTriangulation::weights(const Eigen::Vector3d& light_dir) const {
  const Eigen::Vector3d n = normalised_light(light_dir);
  const Eigen::Vector2d q(n.x(), n.y());
  LightWeights best;
  // A light at an input light (to rounding of the normalisation): that photo alone, exactly.
  for (const auto& t : triangles_)
    for (int k = 0; k < 3; ++k)
      if ((points_[static_cast<std::size_t>(t[static_cast<std::size_t>(k)])] - q).norm() < 1e-12) {
        best.index = {t[static_cast<std::size_t>(k)], t[static_cast<std::size_t>(k)],
                      t[static_cast<std::size_t>(k)]};
        best.weight = {1.0, 0.0, 0.0};
        return best;
      }
  double best_dist = std::numeric_limits<double>::infinity();
  for (const auto& t : triangles_) {
    const auto& a = points_[static_cast<std::size_t>(t[0])];
    const auto& b = points_[static_cast<std::size_t>(t[1])];
    const auto& c = points_[static_cast<std::size_t>(t[2])];
    const auto l = barycentric(a, b, c, q);
    if (l[0] >= -1e-12 && l[1] >= -1e-12 && l[2] >= -1e-12) {
      best.index = t;
      best.weight = {std::max(l[0], 0.0), std::max(l[1], 0.0), std::max(l[2], 0.0)};
      const double s = best.weight[0] + best.weight[1] + best.weight[2];
      for (double& w : best.weight) w /= s;
      best.inside = true;
      return best;
    }
    // Outside this triangle: its nearest point (on an edge) is a candidate.
    for (const auto& e : {std::pair{a, b}, std::pair{b, c}, std::pair{c, a}}) {
      const Eigen::Vector2d p = closest_on_segment(e.first, e.second, q);
      const double d = (p - q).norm();
      if (d < best_dist) {
        best_dist = d;
        best.index = t;
        const auto lp = barycentric(a, b, c, p);
        best.weight = {std::max(lp[0], 0.0), std::max(lp[1], 0.0), std::max(lp[2], 0.0)};
        const double s = best.weight[0] + best.weight[1] + best.weight[2];
        for (double& w : best.weight) w /= s;
        best.inside = false;
      }
    }
  }
  return best;
}

Image render_direct(const std::vector<Image>& photos, const LightTriangulation& tri,
                    const Eigen::Vector3d& light_dir, LightWeights* used) {
  if (photos.empty()) throw Error("direct rendering: no photos");
  const Image& first = photos.front();
  Image out(first.width(), first.height(), first.channels(), first.colour_space(), 0.0f);
  const Eigen::Vector3d n = normalised_light(light_dir);
  if (n.z() <= 0.0) return out;  // no light from behind the surface
  const LightWeights w = tri.weights(n);
  if (used != nullptr) *used = w;
  for (int k = 0; k < 3; ++k) {
    const double wk = w.weight[static_cast<std::size_t>(k)];
    if (wk == 0.0) continue;
    const Image& p = photos[static_cast<std::size_t>(w.index[static_cast<std::size_t>(k)])];
    for (std::size_t i = 0; i < out.size(); ++i)
      out.data()[i] += static_cast<float>(wk * p.data()[i]);
  }
  return out;
}

DirectReport direct_from_light_set(const LightSet& lights, const Eigen::Vector3d& light_dir,
                                   const std::filesystem::path& output) {
  const LightTriangulation tri(lights.directions());
  // Every photo's header is checked (one size and channel count), but only the (at most
  // three) photos the light blends are decoded: a capture's stack is never held whole.
  const ImageInfo first = probe_image(lights.lights.front().image);
  for (const auto& l : lights.lights) {
    const ImageInfo p = probe_image(l.image);
    if (p.width != first.width || p.height != first.height || p.channels != first.channels) {
      throw Error(where(l.image) + ": size or channels differ from " +
                  lights.lights.front().image.string());
    }
  }
  DirectReport rep;
  const Eigen::Vector3d n = normalised_light(light_dir);
  Image img(first.width, first.height, first.channels, first.colour_space, 0.0f);
  if (n.z() > 0.0) {
    rep.weights = tri.weights(n);
    for (int k = 0; k < 3; ++k) {
      const double wk = rep.weights.weight[static_cast<std::size_t>(k)];
      if (wk == 0.0) continue;
      const auto index = static_cast<std::size_t>(rep.weights.index[static_cast<std::size_t>(k)]);
      const Image p = read_image(lights.lights[index].image);
      for (std::size_t i = 0; i < img.size(); ++i) {
        img.data()[i] += static_cast<float>(wk * p.data()[i]);
      }
    }
  }
  write_image(output, img.view());
  rep.photos = static_cast<int>(lights.size());
  rep.triangles = static_cast<int>(tri.triangles().size());
  rep.width = img.width();
  rep.height = img.height();
  return rep;
}

}  // namespace ptmkit::texture
