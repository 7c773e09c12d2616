// Rendering one light: cast shadows, shading and the sensor model.
#include "render.h"

#include <algorithm>
#include <cassert>
#include <cmath>
#include <limits>
#include <numbers>

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include "hash.h"
#include "ptmkit/core/colour.h"

namespace ptmkit::synth {

namespace {

// Side of the square blocks whose maximum height lets the shadow march skip empty space.
constexpr int kBlock = 8;
// March step along the ground, pixels.
constexpr double kStepPx = 0.5;
// The ray starts this far above its texel, so bilinear lookups on a curved slope that faces
// the light do not shadow the texel itself.
constexpr double kStartBiasPx = 0.05;

// Maximum height over each block, dilated by one pixel on the high side (a bilinear lookup at
// a point of block (bx, by) reads pixels up to (bx + 1) * kBlock).
struct BlockMax {
  int bw = 0;
  int bh = 0;
  std::vector<float> max;

  explicit BlockMax(const Scene& s) {
    bw = (s.width + kBlock - 1) / kBlock;
    bh = (s.height + kBlock - 1) / kBlock;
    max.assign(static_cast<std::size_t>(bw) * bh, 0.0f);
    tbb::parallel_for(0, bh, [&](int by) {
      for (int bx = 0; bx < bw; ++bx) {
        float m = -std::numeric_limits<float>::infinity();
        const int y1 = std::min((by + 1) * kBlock, s.height - 1);
        const int x1 = std::min((bx + 1) * kBlock, s.width - 1);
        for (int y = by * kBlock; y <= y1; ++y) {
          for (int x = bx * kBlock; x <= x1; ++x) m = std::max(m, s.height_at(x, y));
        }
        max[static_cast<std::size_t>(by) * bw + bx] = m;
      }
    });
  }
  [[nodiscard]] float at(int bx, int by) const {
    return max[static_cast<std::size_t>(by) * bw + bx];
  }
};

double bilinear_height(const Scene& s, double px, double py) {
  int ix = static_cast<int>(px);
  int iy = static_cast<int>(py);
  ix = std::min(ix, s.width - 2);
  iy = std::min(iy, s.height - 2);
  const double fx = px - ix;
  const double fy = py - iy;
  const double h00 = s.height_at(ix, iy);
  const double h10 = s.height_at(ix + 1, iy);
  const double h01 = s.height_at(ix, iy + 1);
  const double h11 = s.height_at(ix + 1, iy + 1);
  const double a = h00 + (h10 - h00) * fx;
  const double b = h01 + (h11 - h01) * fx;
  return a + (b - a) * fy;
}

// Whether the ray from texel (x, y) toward the light hits the height field.
bool marched_shadow(const Scene& s, const BlockMax& blocks, int x, int y, double ux, double uy,
                    double rise_per_px) {
  const double xmax = s.width - 1;
  const double ymax = s.height - 1;
  const double h0 = s.height_at(x, y) + kStartBiasPx;
  const double top = s.max_height_px;
  double t = kStepPx;
  for (;;) {
    const double px = x + t * ux;
    const double py = y + t * uy;
    if (px < 0.0 || py < 0.0 || px > xmax || py > ymax) return false;
    const double ray = h0 + t * rise_per_px;
    if (ray > top) return false;
    const int bx = static_cast<int>(px) / kBlock;
    const int by = static_cast<int>(py) / kBlock;
    if (ray > blocks.at(bx, by)) {
      // The ray only rises: nothing in this block can reach it. Jump to the block's exit.
      double t_exit = std::numeric_limits<double>::infinity();
      if (ux > 0.0) t_exit = std::min(t_exit, ((bx + 1) * kBlock - x) / ux);
      if (ux < 0.0) t_exit = std::min(t_exit, (bx * kBlock - x) / ux);
      if (uy > 0.0) t_exit = std::min(t_exit, ((by + 1) * kBlock - y) / uy);
      if (uy < 0.0) t_exit = std::min(t_exit, (by * kBlock - y) / uy);
      // (A lookup on the block's edge can make the exit lie behind; then just step.)
      if (t_exit > t) {
        t = t_exit + 1e-6;
        continue;
      }
    }
    if (bilinear_height(s, px, py) > ray) return true;
    t += kStepPx;
  }
}

// Marching direction of a ray along unit light direction l: ground direction in image pixels
// (rows grow downward, the light frame's y upward) and rise per pixel. False for an overhead
// light (the ray never comes down: nothing casts a shadow) or one below the horizon.
bool march_direction(const Eigen::Vector3d& l, double* ux, double* uy, double* rise) {
  const double ground = std::hypot(l.x(), l.y());
  if (ground < 1e-9 || l.z() <= 0.0) return false;
  // Components below rounding noise (cos 90 degrees) are zeroed so the march never creeps
  // along a block edge.
  auto clean = [](double v) { return std::abs(v) < 1e-12 ? 0.0 : v; };
  *ux = clean(l.x() / ground);
  *uy = clean(-l.y() / ground);
  *rise = l.z() / ground;
  return true;
}

}  // namespace

namespace detail {

TexelLight::TexelLight(const Scene& scene, const SynthOptions& options,
                       const Eigen::Vector3d& light_dir)
    : scene_(scene), dir_(light_dir.normalized()) {
  near_ = options.dome_radius_mm > 0.0;
  if (!near_) return;
  falloff_ = options.inverse_square_falloff;
  position_mm_ = options.dome_radius_mm * dir_;
  position_sq_ = position_mm_.squaredNorm();
  mm_per_px_ = options.mm_per_px;
  plane_ = orthographic_plane(scene.width, scene.height, options.mm_per_px);
}

Eigen::Vector3d TexelLight::at(int x, int y, double* falloff) const {
  if (!near_) {
    if (falloff != nullptr) *falloff = 1.0;
    return dir_;
  }
  const Eigen::Vector2d xy = plane_.plane_mm(x, y);
  const double z = scene_.height_px.empty() ? 0.0 : scene_.height_at(x, y) * mm_per_px_;
  const Eigen::Vector3d v = position_mm_ - Eigen::Vector3d(xy.x(), xy.y(), z);
  const double d_sq = v.squaredNorm();
  if (falloff != nullptr) *falloff = falloff_ ? position_sq_ / d_sq : 1.0;
  return v / std::sqrt(d_sq);
}

}  // namespace detail

Eigen::Vector3d texel_light_dir(const Scene& scene, const SynthOptions& options,
                                const Eigen::Vector3d& light_dir, int x, int y, double* falloff) {
  return detail::TexelLight(scene, options, light_dir).at(x, y, falloff);
}

std::vector<std::uint8_t> cast_shadow_mask(const Scene& scene, const SynthOptions& options,
                                           const Eigen::Vector3d& light_dir) {
  if (!(options.dome_radius_mm > 0.0)) return cast_shadow_mask(scene, light_dir);
  std::vector<std::uint8_t> mask(static_cast<std::size_t>(scene.width) * scene.height, 0);
  if (scene.kind != SceneKind::kRelief || scene.height_px.empty()) return mask;
  const detail::TexelLight light(scene, options, light_dir);
  const BlockMax blocks(scene);
  // The ray from a texel toward a point light is a straight line: marching along the
  // texel's own direction is exact.
  tbb::parallel_for(tbb::blocked_range<int>(0, scene.height),
                    [&](const tbb::blocked_range<int>& r) {
                      for (int y = r.begin(); y < r.end(); ++y) {
                        std::uint8_t* row = mask.data() + static_cast<std::size_t>(y) * scene.width;
                        for (int x = 0; x < scene.width; ++x) {
                          double ux = 0.0, uy = 0.0, rise = 0.0;
                          if (!march_direction(light.at(x, y, nullptr), &ux, &uy, &rise)) continue;
                          row[x] = marched_shadow(scene, blocks, x, y, ux, uy, rise) ? 1 : 0;
                        }
                      }
                    });
  return mask;
}

std::vector<std::uint8_t> cast_shadow_mask(const Scene& scene, const Eigen::Vector3d& light_dir) {
  std::vector<std::uint8_t> mask(static_cast<std::size_t>(scene.width) * scene.height, 0);
  if (scene.kind != SceneKind::kRelief || scene.height_px.empty()) return mask;
  const Eigen::Vector3d l = light_dir.normalized();
  const double ground = std::hypot(l.x(), l.y());
  // Overhead light: the ray never comes down, nothing casts a shadow.
  if (ground < 1e-9 || l.z() <= 0.0) return mask;
  // Image rows grow downward, the light frame's y upward.
  // Components below rounding noise (cos 90 degrees) are zeroed so the march never creeps
  // along a block edge.
  auto clean = [](double v) { return std::abs(v) < 1e-12 ? 0.0 : v; };
  const double ux = clean(l.x() / ground);
  const double uy = clean(-l.y() / ground);
  const double rise = l.z() / ground;
  const BlockMax blocks(scene);
  tbb::parallel_for(tbb::blocked_range<int>(0, scene.height),
                    [&](const tbb::blocked_range<int>& r) {
                      for (int y = r.begin(); y < r.end(); ++y) {
                        std::uint8_t* row = mask.data() + static_cast<std::size_t>(y) * scene.width;
                        for (int x = 0; x < scene.width; ++x) {
                          row[x] = marched_shadow(scene, blocks, x, y, ux, uy, rise) ? 1 : 0;
                        }
                      }
                    });
  return mask;
}

namespace detail {

Sensor::Sensor(const SynthOptions& o)
    : exposure_(o.sensor.exposure),
      srgb_(o.sensor.srgb),
      integer_(o.sensor.bits != 32),
      levels_(o.sensor.bits == 16 ? 65535.0 : 255.0),
      sigma_(o.sensor.noise_sigma_grey / levels_),
      highlight_(o.highlight_threshold_grey / levels_),
      seed_(o.seed) {}

double Sensor::encode(double radiance) const {
  double v = exposure_ * radiance;
  if (srgb_) v = linear_to_srgb(std::max(v, 0.0));
  return v;
}

double Sensor::finish(double encoded) const {
  if (!integer_) return encoded;
  return std::round(std::clamp(encoded, 0.0, 1.0) * levels_) / levels_;
}

void render_into(const Scene& s, const SynthOptions& o, const Eigen::Vector3d& light_dir,
                 int image_index, const std::uint8_t* shadow, Image* observed, Image* diffuse,
                 std::vector<std::uint8_t>* labels) {
  const int w = s.width;
  const int h = s.height;
  const ColourSpace space = o.sensor.srgb ? ColourSpace::kSRGB : ColourSpace::kLinear;
  if (observed != nullptr &&
      (observed->width() != w || observed->height() != h || observed->channels() != 3)) {
    *observed = Image(w, h, 3, space);
  }
  if (diffuse != nullptr &&
      (diffuse->width() != w || diffuse->height() != h || diffuse->channels() != 3)) {
    *diffuse = Image(w, h, 3, space);
  }
  if (observed != nullptr) observed->set_colour_space(space);
  if (diffuse != nullptr) diffuse->set_colour_space(space);
  if (labels != nullptr) labels->assign(static_cast<std::size_t>(w) * h, kLabelInlier);

  const Sensor sensor(o);
  const TexelLight light(s, o, light_dir);
  const bool near = light.near();
  const Eigen::Vector3d l0 = light.nominal();
  const Eigen::Vector3d half0 = (l0 + Eigen::Vector3d(0.0, 0.0, 1.0)).normalized();
  const double ks = o.material.ks * (o.material.normalise_specular
                                         ? (o.material.exponent + 8.0) / (8.0 * std::numbers::pi)
                                         : 1.0);
  const double exponent = o.material.exponent;
  // Below this n.h the lobe is under 1e-9 of ks: skipping pow() there changes no file value
  // (8- and 16-bit steps are 4e-3 and 1.5e-5) and saves most of the specular cost.
  const double ndoth_cutoff = std::exp(std::log(1e-9) / exponent);
  const double ambient = o.material.ambient;
  const bool noisy = o.sensor.noise_sigma_grey > 0.0;
  const bool poly = s.kind == SceneKind::kPolynomial;
  // Noise of texel t in this image: a function of (seed, image_index, t, channel) only.
  const std::uint64_t image_key = hash(sensor.seed(), static_cast<std::uint64_t>(image_index));

  tbb::parallel_for(tbb::blocked_range<int>(0, h), [&](const tbb::blocked_range<int>& r) {
    for (int y = r.begin(); y < r.end(); ++y) {
      for (int x = 0; x < w; ++x) {
        const std::size_t texel = static_cast<std::size_t>(y) * w + x;
        double truth[3];  // diffuse + ambient radiance, no cast shadow
        double seen[3];   // observed radiance before the specular term
        double spec = 0.0;
        bool shadowed = false;
        // Near lights: this texel's own direction and fall-off (distant: the nominal ones).
        double falloff = 1.0;
        const Eigen::Vector3d l = near ? light.at(x, y, &falloff) : l0;
        const Eigen::Vector3d half =
            near ? (l + Eigen::Vector3d(0.0, 0.0, 1.0)).normalized() : half0;
        if (poly) {
          evaluate_polynomial(s, x, y, l.x(), l.y(), truth);
          if (near) {
            for (double& v : truth) v *= falloff;
          }
          for (int c = 0; c < 3; ++c) seen[c] = truth[c];
        } else {
          const double nx = s.normals.at(x, y, 0);
          const double ny = s.normals.at(x, y, 1);
          const double nz = s.normals.at(x, y, 2);
          const double ndotl = nx * l.x() + ny * l.y() + nz * l.z();
          const bool cast = shadow != nullptr && shadow[texel] != 0;
          shadowed = ndotl <= 0.0 || cast;
          double lambert = std::max(ndotl, 0.0);
          double lit = shadowed ? 0.0 : ndotl;
          if (!shadowed && ks > 0.0) {
            const double ndoth = nx * half.x() + ny * half.y() + nz * half.z();
            if (ndoth > ndoth_cutoff) spec = ks * std::pow(ndoth, exponent);
          }
          if (near) {  // the light's radiance falls off; the ambient term does not
            lambert *= falloff;
            lit *= falloff;
            spec *= falloff;
          }
          for (int c = 0; c < 3; ++c) {
            const double a = s.albedo.at(x, y, c);
            truth[c] = a * (lambert + ambient);
            seen[c] = a * (lit + ambient);
          }
        }
        if (diffuse != nullptr) {
          for (int c = 0; c < 3; ++c) {
            diffuse->at(x, y, c) = static_cast<float>(sensor.finish(sensor.encode(truth[c])));
          }
        }
        if (observed == nullptr && labels == nullptr) continue;
        double noise[4] = {0.0, 0.0, 0.0, 0.0};
        if (noisy) {
          const std::uint64_t key = mix64(image_key ^ (texel * 0xd6e8feb86659fd93ull));
          gaussian_pair(key, &noise[0], &noise[1]);
          gaussian_pair(mix64(key ^ 0x2545f4914f6cdd1dull), &noise[2], &noise[3]);
        }
        bool highlight = false;
        for (int c = 0; c < 3; ++c) {
          const double base = sensor.encode(seen[c]);
          const double value = spec > 0.0 ? sensor.encode(seen[c] + spec) : base;
          const double noisy_value = value + sensor.sigma() * noise[c];
          if (value - base > sensor.highlight_threshold()) highlight = true;
          if (sensor.integer() && noisy_value > 1.0) highlight = true;
          if (observed != nullptr)
            observed->at(x, y, c) = static_cast<float>(sensor.finish(noisy_value));
        }
        if (labels != nullptr) {
          (*labels)[texel] = shadowed ? kLabelShadow : highlight ? kLabelHighlight : kLabelInlier;
        }
      }
    }
  });
}

}  // namespace detail

RenderedLight render_light(const Scene& scene, const SynthOptions& options,
                           const Eigen::Vector3d& light_dir, int image_index) {
  RenderedLight out;
  std::vector<std::uint8_t> shadow;
  if (options.cast_shadows && scene.kind == SceneKind::kRelief) {
    shadow = cast_shadow_mask(scene, options, light_dir);
  }
  detail::render_into(scene, options, light_dir, image_index,
                      shadow.empty() ? nullptr : shadow.data(), &out.observed, &out.diffuse,
                      &out.labels);
  return out;
}

}  // namespace ptmkit::synth
