// Procedural scenes: the relief (height field, normals, albedo) and the polynomial world.
#include <algorithm>
#include <cassert>
#include <cmath>
#include <cstdint>
#include <utility>
#include <vector>

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include "hash.h"
#include "ptmkit/synth/synth.h"

namespace ptmkit::synth {

namespace {

using detail::hash;
using detail::Stream;
using detail::unit;

// Stream tags, so that each use of the seed draws independent numbers.
enum Tag : std::uint64_t {
  kTagBumps = 1,
  kTagGrooves = 2,
  kTagCrumple = 3,
  kTagAlbedo = 4,
  kTagPolynomial = 5,
};

// Smooth value noise: lattice values hash(seed, tag, ix, iy) in [0, 1), interpolated with a
// quintic fade (C2, so normals from central differences have no creases at cell borders).
// `cell` is the lattice spacing in pixels.
class ValueNoise {
 public:
  ValueNoise(std::uint64_t seed, std::uint64_t tag, double cell)
      : base_(hash(seed, tag)), inv_cell_(1.0 / cell) {}

  [[nodiscard]] double operator()(double x, double y) const {
    const double gx = x * inv_cell_;
    const double gy = y * inv_cell_;
    const double fx0 = std::floor(gx);
    const double fy0 = std::floor(gy);
    const auto ix = static_cast<std::int64_t>(fx0);
    const auto iy = static_cast<std::int64_t>(fy0);
    const double tx = fade(gx - fx0);
    const double ty = fade(gy - fy0);
    const double v00 = lattice(ix, iy);
    const double v10 = lattice(ix + 1, iy);
    const double v01 = lattice(ix, iy + 1);
    const double v11 = lattice(ix + 1, iy + 1);
    const double a = v00 + (v10 - v00) * tx;
    const double b = v01 + (v11 - v01) * tx;
    return a + (b - a) * ty;
  }

 private:
  static double fade(double t) { return t * t * t * (t * (t * 6.0 - 15.0) + 10.0); }
  // One mix per lattice point (the scene build evaluates about 40 per pixel).
  [[nodiscard]] double lattice(std::int64_t ix, std::int64_t iy) const {
    const auto ux = static_cast<std::uint64_t>(ix);
    const auto uy = static_cast<std::uint64_t>(iy);
    return unit(
        detail::mix64(base_ ^ (ux * 0xd6e8feb86659fd93ull) ^ ((uy * 0xa0761d6478bd642full) << 1)));
  }
  std::uint64_t base_;
  double inv_cell_;
};

struct Bump {
  double cx, cy, sigma, amplitude;
};
struct Groove {
  double x0, y0, x1, y1, sigma, depth;
};

double segment_distance_sq(double px, double py, const Groove& g) {
  const double dx = g.x1 - g.x0;
  const double dy = g.y1 - g.y0;
  const double len_sq = dx * dx + dy * dy;
  double t = len_sq > 0.0 ? ((px - g.x0) * dx + (py - g.y0) * dy) / len_sq : 0.0;
  t = std::clamp(t, 0.0, 1.0);
  const double ex = px - (g.x0 + t * dx);
  const double ey = py - (g.y0 + t * dy);
  return ex * ex + ey * ey;
}

template <class Fn>
void parallel_rows(int height, Fn&& fn) {
  tbb::parallel_for(tbb::blocked_range<int>(0, height), [&](const tbb::blocked_range<int>& r) {
    for (int y = r.begin(); y < r.end(); ++y) fn(y);
  });
}

// Height field in arbitrary units (rescaled by the caller).
std::vector<float> relief_heights(const SynthOptions& o) {
  const int w = o.width;
  const int h = o.height;
  const double size = static_cast<double>(w);
  const std::uint64_t seed = o.seed;

  std::vector<Bump> bumps;
  Stream bump_rng(seed, kTagBumps);
  for (int i = 0; i < o.relief.bumps; ++i) {
    Bump b{};
    b.cx = bump_rng.uniform(-0.05, 1.05) * w;
    b.cy = bump_rng.uniform(-0.05, 1.05) * h;
    b.sigma = bump_rng.uniform(0.03, 0.07) * size;
    b.amplitude = bump_rng.uniform(0.4, 1.0);
    if (bump_rng.uniform(0.0, 1.0) < 0.2) b.amplitude *= -0.5;  // a few dimples
    bumps.push_back(b);
  }
  std::vector<Groove> grooves;
  Stream groove_rng(seed, kTagGrooves);
  for (int i = 0; i < o.relief.grooves; ++i) {
    const double cx = groove_rng.uniform(0.25, 0.75) * w;
    const double cy = groove_rng.uniform(0.25, 0.75) * h;
    const double angle = groove_rng.uniform(0.0, 3.14159265358979323846);
    const double half = 0.5 * groove_rng.uniform(0.6, 0.9) * size;
    Groove g{};
    g.x0 = cx - half * std::cos(angle);
    g.y0 = cy - half * std::sin(angle);
    g.x1 = cx + half * std::cos(angle);
    g.y1 = cy + half * std::sin(angle);
    g.sigma = std::max(0.01 * size, 1.0);
    g.depth = groove_rng.uniform(0.3, 0.5);
    grooves.push_back(g);
  }

  // Crumple: ridged fractal noise (1 - |2v - 1| per octave), whose creases look like folds.
  constexpr int kOctaves = 5;
  std::vector<ValueNoise> octaves;
  double amp_sum = 0.0;
  for (int k = 0; k < kOctaves; ++k) {
    octaves.emplace_back(seed, kTagCrumple * 100 + static_cast<std::uint64_t>(k),
                         size / (6.0 * std::pow(2.0, k)));
    amp_sum += std::pow(0.5, k);
  }
  const double crumple = o.relief.crumple / amp_sum;

  std::vector<float> out(static_cast<std::size_t>(w) * h);
  parallel_rows(h, [&](int y) {
    float* row = out.data() + static_cast<std::size_t>(y) * w;
    for (int x = 0; x < w; ++x) {
      const double px = x;
      const double py = y;
      double v = 0.0;
      for (const Bump& b : bumps) {
        const double dx = px - b.cx;
        const double dy = py - b.cy;
        const double d2 = dx * dx + dy * dy;
        const double s2 = b.sigma * b.sigma;
        if (d2 < 25.0 * s2) v += b.amplitude * std::exp(-0.5 * d2 / s2);
      }
      for (const Groove& g : grooves) {
        const double d2 = segment_distance_sq(px, py, g);
        const double s2 = g.sigma * g.sigma;
        if (d2 < 25.0 * s2) v -= g.depth * std::exp(-0.5 * d2 / s2);
      }
      if (crumple != 0.0) {
        double c = 0.0;
        double amp = 1.0;
        for (const ValueNoise& n : octaves) {
          c += amp * (1.0 - std::abs(2.0 * n(px, py) - 1.0));
          amp *= 0.5;
        }
        v += crumple * c;
      }
      row[x] = static_cast<float>(v);
    }
  });
  return out;
}

void compute_normals(Scene& s) {
  const int w = s.width;
  const int h = s.height;
  s.normals = Image(w, h, 3, ColourSpace::kLinear);
  parallel_rows(h, [&](int y) {
    for (int x = 0; x < w; ++x) {
      const int xl = std::max(x - 1, 0);
      const int xr = std::min(x + 1, w - 1);
      const int yu = std::max(y - 1, 0);  // image row above: +y in the light frame
      const int yd = std::min(y + 1, h - 1);
      const double dhdx =
          (static_cast<double>(s.height_at(xr, y)) - s.height_at(xl, y)) / (xr - xl);
      const double dhdy =
          (static_cast<double>(s.height_at(x, yu)) - s.height_at(x, yd)) / (yd - yu);
      const double nx = -dhdx;
      const double ny = -dhdy;
      const double inv = 1.0 / std::sqrt(nx * nx + ny * ny + 1.0);
      s.normals.at(x, y, 0) = static_cast<float>(nx * inv);
      s.normals.at(x, y, 1) = static_cast<float>(ny * inv);
      s.normals.at(x, y, 2) = static_cast<float>(inv);
    }
  });
}

// Smooth colour patches: per channel, two octaves of value noise, sharpened with a smoothstep
// so patches have distinct colours, mapped to [0.3, 0.9].
Image relief_albedo(const SynthOptions& o) {
  const int w = o.width;
  const int h = o.height;
  const double size = static_cast<double>(w);
  Image albedo(w, h, 3, ColourSpace::kLinear);
  std::vector<ValueNoise> coarse;
  std::vector<ValueNoise> fine;
  for (std::uint64_t c = 0; c < 3; ++c) {
    coarse.emplace_back(o.seed, kTagAlbedo * 100 + c, size / 4.0);
    fine.emplace_back(o.seed, kTagAlbedo * 100 + 10 + c, size / 12.0);
  }
  parallel_rows(h, [&](int y) {
    for (int x = 0; x < w; ++x) {
      for (int c = 0; c < 3; ++c) {
        double v = 0.85 * coarse[c](x, y) + 0.15 * fine[c](x, y);
        v = v * v * (3.0 - 2.0 * v);
        albedo.at(x, y, c) = static_cast<float>(0.3 + 0.6 * v);
      }
    }
  });
  return albedo;
}

// Polynomial world coefficients: smooth random fields, scaled per texel so that
// |L - a5| <= sqrt(a3^2 + a4^2) + max|eig([[a0, a2/2], [a2/2, a1]])| stays within the margin
// to [0.05, 0.95] for every (lu, lv) in the unit disk (the whole upper hemisphere).
CoefficientMap polynomial_coefficients(const SynthOptions& o) {
  const int w = o.width;
  const int h = o.height;
  const double size = static_cast<double>(std::max(w, h));
  CoefficientMap map(w, h, ColourModel::kRGB, ColourSpace::kLinear);
  map.coeffs.assign(static_cast<std::size_t>(w) * h * 3 * kPtmTerms, 0.0f);
  std::vector<ValueNoise> fields;
  for (std::uint64_t i = 0; i < 3 * kPtmTerms; ++i) {
    fields.emplace_back(o.seed, kTagPolynomial * 100 + i, size / 3.0);
  }
  constexpr double kLow = 0.05;
  constexpr double kHigh = 0.95;
  constexpr double kMargin = 0.01;  // keeps float rounding of the coefficients inside
  parallel_rows(h, [&](int y) {
    for (int x = 0; x < w; ++x) {
      float* a = map.texel_coeffs(x, y);
      for (int c = 0; c < 3; ++c) {
        double f[kPtmTerms];
        for (int k = 0; k < kPtmTerms; ++k) f[k] = 2.0 * fields[c * kPtmTerms + k](x, y) - 1.0;
        // Shaped like a lit surface: bright overhead, darker toward grazing light.
        double q0 = -0.25 + 0.15 * f[0];
        double q1 = -0.25 + 0.15 * f[1];
        double q2 = 0.2 * f[2];
        double l3 = 0.3 * f[3];
        double l4 = 0.3 * f[4];
        const double a5 = 0.5 + 0.1 * f[5];
        const double mean = 0.5 * (q0 + q1);
        const double dev = std::sqrt(0.25 * (q0 - q1) * (q0 - q1) + 0.25 * q2 * q2);
        const double bound = std::sqrt(l3 * l3 + l4 * l4) + std::abs(mean) + dev;
        const double budget = std::min(a5 - kLow, kHigh - a5) - kMargin;
        if (bound > budget) {
          const double s = budget / bound;
          q0 *= s;
          q1 *= s;
          q2 *= s;
          l3 *= s;
          l4 *= s;
        }
        float* ac = a + c * kPtmTerms;
        ac[0] = static_cast<float>(q0);
        ac[1] = static_cast<float>(q1);
        ac[2] = static_cast<float>(q2);
        ac[3] = static_cast<float>(l3);
        ac[4] = static_cast<float>(l4);
        ac[5] = static_cast<float>(a5);
      }
    }
  });
  return map;
}

}  // namespace

namespace {
Scene relief_from_height(int width, int height, std::vector<float> height_px) {
  assert(width >= 2 && height >= 2);
  assert(height_px.size() == static_cast<std::size_t>(width) * height);
  Scene s;
  s.kind = SceneKind::kRelief;
  s.width = width;
  s.height = height;
  s.height_px = std::move(height_px);
  s.max_height_px = *std::max_element(s.height_px.begin(), s.height_px.end());
  compute_normals(s);
  return s;
}
}  // namespace

Scene scene_from_height(int width, int height, std::vector<float> height_px, double albedo) {
  Scene s = relief_from_height(width, height, std::move(height_px));
  s.albedo = Image(width, height, 3, ColourSpace::kLinear, static_cast<float>(albedo));
  return s;
}

Scene build_scene(const SynthOptions& options) {
  validate(options);
  Scene s;
  s.kind = options.scene;
  s.width = options.width;
  s.height = options.height;
  if (options.scene == SceneKind::kPolynomial) {
    s.coefficients = polynomial_coefficients(options);
    return s;
  }
  std::vector<float> raw = relief_heights(options);
  const auto [lo_it, hi_it] = std::minmax_element(raw.begin(), raw.end());
  const double lo = *lo_it;
  const double span = *hi_it - lo;
  const double max_height = options.relief.relief_height_frac * options.width;
  const double scale = span > 0.0 ? max_height / span : 0.0;
  for (float& v : raw) v = static_cast<float>((v - lo) * scale);
  s = relief_from_height(options.width, options.height, std::move(raw));
  s.albedo = relief_albedo(options);
  return s;
}

void evaluate_polynomial(const Scene& scene, int x, int y, double lu, double lv, double rgb[3]) {
  assert(scene.kind == SceneKind::kPolynomial);
  const float* a = scene.coefficients.texel_coeffs(x, y);
  const auto basis = ptm_basis(lu, lv);
  for (int c = 0; c < 3; ++c) {
    double v = 0.0;
    for (int k = 0; k < kPtmTerms; ++k) v += static_cast<double>(a[c * kPtmTerms + k]) * basis[k];
    rgb[c] = v;
  }
}

}  // namespace ptmkit::synth
