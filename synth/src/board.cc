#include "ptmkit/synth/board.h"

#include <algorithm>
#include <cmath>
#include <memory>
#include <optional>
#include <vector>

#include <apriltag/apriltag.h>
#include <apriltag/tag16h5.h>
#include <apriltag/tag25h9.h>
#include <apriltag/tag36h11.h>
#include <apriltag/tagCircle21h7.h>
#include <apriltag/tagCircle49h12.h>
#include <apriltag/tagCustom48h12.h>
#include <apriltag/tagStandard41h12.h>
#include <apriltag/tagStandard52h13.h>
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <Eigen/Geometry>
#include <Eigen/LU>

#include "hash.h"
#include "ptmkit/core/error.h"

namespace ptmkit::synth {

namespace {

constexpr double kPi = 3.14159265358979323846;

struct FamilyEntry {
  const char* name;
  apriltag_family_t* (*create)();
  void (*destroy)(apriltag_family_t*);
};

const FamilyEntry kFamilies[] = {
    {"tag36h11", tag36h11_create, tag36h11_destroy},
    {"tag25h9", tag25h9_create, tag25h9_destroy},
    {"tag16h5", tag16h5_create, tag16h5_destroy},
    {"tagCircle21h7", tagCircle21h7_create, tagCircle21h7_destroy},
    {"tagCircle49h12", tagCircle49h12_create, tagCircle49h12_destroy},
    {"tagStandard41h12", tagStandard41h12_create, tagStandard41h12_destroy},
    {"tagStandard52h13", tagStandard52h13_create, tagStandard52h13_destroy},
    {"tagCustom48h12", tagCustom48h12_create, tagCustom48h12_destroy},
};

std::string lower(std::string s) {
  for (char& c : s) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  return s;
}

// Homography taking src[k] to dst[k] (exact for 4 points in general position).
Eigen::Matrix3d homography(const std::array<Eigen::Vector2d, 4>& src,
                           const std::array<Eigen::Vector2d, 4>& dst) {
  Eigen::Matrix<double, 8, 8> a;
  Eigen::Matrix<double, 8, 1> b;
  for (int k = 0; k < 4; ++k) {
    const double x = src[static_cast<std::size_t>(k)].x(), y = src[static_cast<std::size_t>(k)].y();
    const double u = dst[static_cast<std::size_t>(k)].x(), v = dst[static_cast<std::size_t>(k)].y();
    a.row(2 * k) << x, y, 1, 0, 0, 0, -u * x, -u * y;
    a.row(2 * k + 1) << 0, 0, 0, x, y, 1, -v * x, -v * y;
    b(2 * k) = u;
    b(2 * k + 1) = v;
  }
  const Eigen::Matrix<double, 8, 1> h = a.fullPivLu().solve(b);
  Eigen::Matrix3d m;
  m << h(0), h(1), h(2), h(3), h(4), h(5), h(6), h(7), 1.0;
  return m;
}

Eigen::Vector2d apply(const Eigen::Matrix3d& h, const Eigen::Vector2d& p) {
  const Eigen::Vector3d q = h * p.homogeneous();
  return q.hnormalized();
}

// The board as a function of the board point: paper, tag cells, surround.
class BoardShader {
 public:
  BoardShader(const TagBoard& board, const BoardRenderOptions& options) : options_(options) {
    if (const auto err = board.validate(); !err.empty()) throw Error("render board: " + err);
    const FamilyEntry* entry = nullptr;
    for (const auto& f : kFamilies) {
      if (lower(board.family) == lower(f.name) || lower("tag" + board.family) == lower(f.name)) {
        entry = &f;
      }
    }
    if (entry == nullptr) throw Error("render board: unknown tag family '" + board.family + "'");
    std::unique_ptr<apriltag_family_t, void (*)(apriltag_family_t*)> family(entry->create(),
                                                                            entry->destroy);
    total_ = family->total_width;
    const double border = 0.5 * (family->total_width - family->width_at_border);
    const double inner = border + family->width_at_border;
    // Board corners (bottom-left, bottom-right, top-right, top-left) in bitmap cells (x
    // right, y down): the black square's outer edge.
    const std::array<Eigen::Vector2d, 4> cells = {
        Eigen::Vector2d(border, inner), Eigen::Vector2d(inner, inner),
        Eigen::Vector2d(inner, border), Eigen::Vector2d(border, border)};
    paper_min_ = board.paper_min_mm;
    paper_max_ = board.paper_max_mm;
    cell_mm_ = board.tag_size_mm * total_ / family->width_at_border;
    cols_ = std::max(1, static_cast<int>(std::ceil((paper_max_.x() - paper_min_.x()) / cell_mm_)));
    rows_ = std::max(1, static_cast<int>(std::ceil((paper_max_.y() - paper_min_.y()) / cell_mm_)));
    buckets_.resize(static_cast<std::size_t>(cols_ * rows_));
    for (const auto& t : board.tags) {
      if (t.id < 0 || static_cast<std::uint32_t>(t.id) >= family->ncodes) {
        throw Error("render board: tag id " + std::to_string(t.id) + " is not in " + board.family);
      }
      Tag tag;
      tag.board_to_cells = homography(t.corners_mm, cells);
      std::unique_ptr<image_u8_t, void (*)(image_u8_t*)> img(apriltag_to_image(family.get(), t.id),
                                                             image_u8_destroy);
      tag.bits.resize(static_cast<std::size_t>(total_ * total_));
      for (int y = 0; y < total_; ++y) {
        for (int x = 0; x < total_; ++x) {
          tag.bits[static_cast<std::size_t>(y * total_ + x)] = img->buf[y * img->stride + x] > 127;
        }
      }
      // The bitmap's full extent on the board, for the buckets.
      const Eigen::Matrix3d cells_to_board = tag.board_to_cells.inverse();
      Eigen::Vector2d lo = Eigen::Vector2d::Constant(INFINITY);
      Eigen::Vector2d hi = -lo;
      for (const auto& c : {Eigen::Vector2d(0, 0), Eigen::Vector2d(total_, 0),
                            Eigen::Vector2d(total_, total_), Eigen::Vector2d(0, total_)}) {
        const Eigen::Vector2d p = apply(cells_to_board, c);
        lo = lo.cwiseMin(p);
        hi = hi.cwiseMax(p);
      }
      const std::size_t index = tags_.size();
      tags_.push_back(std::move(tag));
      const int c0 = std::clamp(bucket_x(lo.x()), 0, cols_ - 1);
      const int c1 = std::clamp(bucket_x(hi.x()), 0, cols_ - 1);
      const int r0 = std::clamp(bucket_y(lo.y()), 0, rows_ - 1);
      const int r1 = std::clamp(bucket_y(hi.y()), 0, rows_ - 1);
      for (int r = r0; r <= r1; ++r) {
        for (int c = c0; c <= c1; ++c)
          buckets_[static_cast<std::size_t>(r * cols_ + c)].push_back(index);
      }
    }
  }

  [[nodiscard]] float shade(const std::optional<Eigen::Vector2d>& p) const {
    if (!p || (p->array() < paper_min_.array()).any() || (p->array() > paper_max_.array()).any()) {
      return options_.surround;
    }
    const int c = std::clamp(bucket_x(p->x()), 0, cols_ - 1);
    const int r = std::clamp(bucket_y(p->y()), 0, rows_ - 1);
    for (const std::size_t i : buckets_[static_cast<std::size_t>(r * cols_ + c)]) {
      const Tag& t = tags_[i];
      const Eigen::Vector2d q = apply(t.board_to_cells, *p);
      if (q.x() >= 0.0 && q.y() >= 0.0 && q.x() < total_ && q.y() < total_) {
        const int x = static_cast<int>(q.x()), y = static_cast<int>(q.y());
        return t.bits[static_cast<std::size_t>(y * total_ + x)] ? options_.paper : options_.ink;
      }
    }
    return options_.paper;
  }

 private:
  struct Tag {
    Eigen::Matrix3d board_to_cells;
    std::vector<bool> bits;  // true = white
  };
  [[nodiscard]] int bucket_x(double x) const {
    return static_cast<int>(std::floor((x - paper_min_.x()) / cell_mm_));
  }
  [[nodiscard]] int bucket_y(double y) const {
    return static_cast<int>(std::floor((y - paper_min_.y()) / cell_mm_));
  }

  BoardRenderOptions options_;
  int total_ = 0;
  double cell_mm_ = 1.0;
  Eigen::Vector2d paper_min_, paper_max_;
  int cols_ = 1, rows_ = 1;
  std::vector<Tag> tags_;
  std::vector<std::vector<std::size_t>> buckets_;
};

// Averages the shade over supersamples, adds noise. The samples' board points are
// interpolated bilinearly between the exact points of the pixel's four corners (the map is
// smooth: the second-order error is ~1e-4 px for the cameras in use), which needs about two
// exact evaluations per pixel instead of supersample^2; a pixel with a corner off the board's
// plane (behind the camera) is sampled exactly.
template <class BoardPoint>
Image render(const BoardShader& shader, int width, int height, const BoardRenderOptions& options,
             const BoardPoint& board_point) {
  Image out(width, height, 1, ColourSpace::kLinear);
  const int ss = options.supersample;
  const double inv = 1.0 / (ss * ss);
  tbb::parallel_for(tbb::blocked_range<int>(0, height), [&](const tbb::blocked_range<int>& rows) {
    std::vector<std::optional<Eigen::Vector2d>> top(static_cast<std::size_t>(width) + 1);
    std::vector<std::optional<Eigen::Vector2d>> bottom(top.size());
    for (int y = rows.begin(); y < rows.end(); ++y) {
      for (int x = 0; x <= width; ++x) {
        top[static_cast<std::size_t>(x)] = board_point(Eigen::Vector2d(x - 0.5, y - 0.5));
        bottom[static_cast<std::size_t>(x)] = board_point(Eigen::Vector2d(x - 0.5, y + 0.5));
      }
      for (int x = 0; x < width; ++x) {
        const auto& p00 = top[static_cast<std::size_t>(x)];
        const auto& p10 = top[static_cast<std::size_t>(x) + 1];
        const auto& p01 = bottom[static_cast<std::size_t>(x)];
        const auto& p11 = bottom[static_cast<std::size_t>(x) + 1];
        const bool interpolate = p00 && p10 && p01 && p11;
        double sum = 0.0;
        for (int j = 0; j < ss; ++j) {
          const double v = (j + 0.5) / ss;
          for (int i = 0; i < ss; ++i) {
            const double u = (i + 0.5) / ss;
            if (interpolate) {
              const Eigen::Vector2d p =
                  (1.0 - v) * ((1.0 - u) * *p00 + u * *p10) + v * ((1.0 - u) * *p01 + u * *p11);
              sum += shader.shade(p);
            } else {
              sum += shader.shade(board_point(Eigen::Vector2d(x + u - 0.5, y + v - 0.5)));
            }
          }
        }
        double value = sum * inv;
        if (options.noise_sigma > 0.0) {
          double z0 = 0.0, z1 = 0.0;
          detail::gaussian_pair(
              detail::hash(options.seed, 0x626f617264ull, static_cast<std::uint64_t>(x),
                           static_cast<std::uint64_t>(y)),
              &z0, &z1);
          value += z0 * options.noise_sigma / 255.0;
        }
        out.at(x, y, 0) = static_cast<float>(std::clamp(value, 0.0, 1.0));
      }
    }
  });
  return out;
}

}  // namespace

std::string PinholeCamera::validate() const {
  if (width_px < 1 || height_px < 1) return "image size must be positive";
  if (!(fx > 0.0) || !(fy > 0.0) || !std::isfinite(fx) || !std::isfinite(fy)) {
    return "focal lengths must be positive";
  }
  for (const double v : {cx, cy, k1, k2, p1, p2, k3}) {
    if (!std::isfinite(v)) return "principal point and distortion must be finite";
  }
  return {};
}

Eigen::Vector2d PinholeCamera::project(const Eigen::Vector3d& p) const {
  const double x = p.x() / p.z(), y = p.y() / p.z();
  const double r2 = x * x + y * y;
  const double radial = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3));
  const double xd = x * radial + 2.0 * p1 * x * y + p2 * (r2 + 2.0 * x * x);
  const double yd = y * radial + p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * x * y;
  return {fx * xd + cx, fy * yd + cy};
}

Eigen::Vector2d PinholeCamera::undistort(const Eigen::Vector2d& pixel) const {
  const Eigen::Vector2d target((pixel.x() - cx) / fx, (pixel.y() - cy) / fy);
  Eigen::Vector2d q = target;
  for (int it = 0; it < 20; ++it) {
    const double x = q.x(), y = q.y();
    const double r2 = x * x + y * y;
    const double radial = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3));
    const double dradial = k1 + r2 * (2.0 * k2 + 3.0 * k3 * r2);  // d radial / d r2
    const Eigen::Vector2d f(x * radial + 2.0 * p1 * x * y + p2 * (r2 + 2.0 * x * x) - target.x(),
                            y * radial + p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * x * y - target.y());
    Eigen::Matrix2d jac;
    jac(0, 0) = radial + 2.0 * x * x * dradial + 2.0 * p1 * y + 6.0 * p2 * x;
    jac(0, 1) = 2.0 * x * y * dradial + 2.0 * p1 * x + 2.0 * p2 * y;
    jac(1, 0) = 2.0 * x * y * dradial + 2.0 * p1 * x + 2.0 * p2 * y;
    jac(1, 1) = radial + 2.0 * y * y * dradial + 6.0 * p1 * y + 2.0 * p2 * x;
    const Eigen::Vector2d step = jac.inverse() * f;
    q -= step;
    if (step.squaredNorm() < 1e-28) break;
  }
  return q;
}

BoardPose facing_pose(double distance_mm, double tilt_deg, double tilt_axis_deg, double roll_deg) {
  // Facing: board x = camera x, board y = camera -y, board z = camera -z.
  Eigen::Matrix3d facing;
  facing << 1, 0, 0, 0, -1, 0, 0, 0, -1;
  const double a = tilt_axis_deg * kPi / 180.0;
  const Eigen::Vector3d axis(std::cos(a), std::sin(a), 0.0);
  const Eigen::Matrix3d tilt = Eigen::AngleAxisd(tilt_deg * kPi / 180.0, axis).toRotationMatrix();
  const Eigen::Matrix3d roll =
      Eigen::AngleAxisd(roll_deg * kPi / 180.0, Eigen::Vector3d::UnitZ()).toRotationMatrix();
  BoardPose pose;
  pose.camera_from_board = roll * facing * tilt;
  pose.board_origin_in_camera_mm = {0.0, 0.0, distance_mm};
  return pose;
}

std::string BoardRenderOptions::validate() const {
  if (supersample < 1 || supersample > 16) return "supersample must be 1..16";
  if (!(noise_sigma >= 0.0) || !std::isfinite(noise_sigma)) return "noise_sigma must be >= 0";
  return {};
}

Image render_board(const TagBoard& board, const PinholeCamera& camera, const BoardPose& pose,
                   const BoardRenderOptions& options) {
  if (const auto err = camera.validate(); !err.empty()) throw Error("render board: " + err);
  if (const auto err = options.validate(); !err.empty()) throw Error("render board: " + err);
  const BoardShader shader(board, options);
  const Eigen::Matrix3d& r = pose.camera_from_board;
  const Eigen::Vector3d& t = pose.board_origin_in_camera_mm;
  const Eigen::Vector3d normal = r.col(2);
  const double nt = normal.dot(t);
  return render(shader, camera.width_px, camera.height_px, options,
                [&](const Eigen::Vector2d& pixel) -> std::optional<Eigen::Vector2d> {
                  const Eigen::Vector3d ray = camera.undistort(pixel).homogeneous();
                  const double nd = normal.dot(ray);
                  if (nd == 0.0) return std::nullopt;
                  const double s = nt / nd;
                  if (!(s > 0.0)) return std::nullopt;
                  const Eigen::Vector3d b = r.transpose() * (s * ray - t);
                  return Eigen::Vector2d(b.x(), b.y());
                });
}

Image render_board_orthographic(const TagBoard& board, int width_px, int height_px,
                                double mm_per_px, const BoardRenderOptions& options) {
  if (width_px < 1 || height_px < 1 || !(mm_per_px > 0.0) || !std::isfinite(mm_per_px)) {
    throw Error("render board: size and mm per pixel must be positive");
  }
  if (const auto err = options.validate(); !err.empty()) throw Error("render board: " + err);
  const BoardShader shader(board, options);
  const double cx = 0.5 * (width_px - 1.0), cy = 0.5 * (height_px - 1.0);
  return render(shader, width_px, height_px, options,
                [&](const Eigen::Vector2d& pixel) -> std::optional<Eigen::Vector2d> {
                  return Eigen::Vector2d((pixel.x() - cx) * mm_per_px,
                                         (cy - pixel.y()) * mm_per_px);
                });
}

}  // namespace ptmkit::synth
