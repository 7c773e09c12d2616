// The lens and sensor of the photo renderer: vignetting, flare streaks, bloom, noise,
// clipping, encoding.
#include <algorithm>
#include <cmath>
#include <numbers>

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include "hash.h"
#include "photo_internal.h"
#include "ptmkit/core/colour.h"

namespace ptmkit::synth::detail {

namespace {

constexpr double kPi = std::numbers::pi;

// A float RGB plane on a grid of cells of `cell` pixels: pixel (x, y) lies at cell
// coordinates ((x + 0.5) / cell - 0.5, ...), so splatting and sampling bilinearly at those
// coordinates keep every first moment.
struct Grid {
  int w = 0, h = 0, cell = 1;
  std::vector<double> v;  // 3 per cell
  Grid(int width, int height, int c) : cell(c) {
    w = (width + c - 1) / c;
    h = (height + c - 1) / c;
    v.assign(static_cast<std::size_t>(w) * static_cast<std::size_t>(h) * 3, 0.0);
  }
  double* at(int x, int y) {
    return v.data() + (static_cast<std::size_t>(y) * static_cast<std::size_t>(w) +
                       static_cast<std::size_t>(x)) *
                          3;
  }
  void splat(double px, double py, const double e[3]) {
    const double gx = (px + 0.5) / cell - 0.5, gy = (py + 0.5) / cell - 0.5;
    const int x0 = static_cast<int>(std::floor(gx)), y0 = static_cast<int>(std::floor(gy));
    const double fx = gx - x0, fy = gy - y0;
    const double wts[4] = {(1 - fx) * (1 - fy), fx * (1 - fy), (1 - fx) * fy, fx * fy};
    const int xs[4] = {x0, x0 + 1, x0, x0 + 1}, ys[4] = {y0, y0, y0 + 1, y0 + 1};
    for (int k = 0; k < 4; ++k) {
      if (xs[k] < 0 || ys[k] < 0 || xs[k] >= w || ys[k] >= h || wts[k] == 0.0) continue;
      double* p = at(xs[k], ys[k]);
      for (int c = 0; c < 3; ++c) p[c] += wts[k] * e[c];
    }
  }
  void sample(double px, double py, double out[3]) {
    const double gx = std::clamp((px + 0.5) / cell - 0.5, 0.0, w - 1.0);
    const double gy = std::clamp((py + 0.5) / cell - 0.5, 0.0, h - 1.0);
    const int x0 = std::min(static_cast<int>(gx), std::max(w - 2, 0));
    const int y0 = std::min(static_cast<int>(gy), std::max(h - 2, 0));
    const int x1 = std::min(x0 + 1, w - 1), y1 = std::min(y0 + 1, h - 1);
    const double fx = gx - x0, fy = gy - y0;
    for (int c = 0; c < 3; ++c) {
      const double a = at(x0, y0)[c] + (at(x1, y0)[c] - at(x0, y0)[c]) * fx;
      const double b = at(x0, y1)[c] + (at(x1, y1)[c] - at(x0, y1)[c]) * fx;
      out[c] = a + (b - a) * fy;
    }
  }
  // Separable Gaussian of sigma (cells), zero outside.
  void blur(double sigma) {
    const int radius = std::max(1, static_cast<int>(std::ceil(3.0 * sigma)));
    std::vector<double> k(static_cast<std::size_t>(2 * radius + 1));
    double sum = 0.0;
    for (int i = -radius; i <= radius; ++i) {
      k[static_cast<std::size_t>(i + radius)] = std::exp(-0.5 * i * i / (sigma * sigma));
      sum += k[static_cast<std::size_t>(i + radius)];
    }
    for (double& x : k) x /= sum;
    std::vector<double> tmp(v.size(), 0.0);
    tbb::parallel_for(0, h, [&](int y) {
      for (int x = 0; x < w; ++x) {
        const double* src = at(x, y);
        if (src[0] == 0.0 && src[1] == 0.0 && src[2] == 0.0) continue;
        for (int i = -radius; i <= radius; ++i) {
          const int xx = x + i;
          if (xx < 0 || xx >= w) continue;
          double* dst = tmp.data() + (static_cast<std::size_t>(y) * static_cast<std::size_t>(w) +
                                      static_cast<std::size_t>(xx)) *
                                         3;
          for (int c = 0; c < 3; ++c) dst[c] += k[static_cast<std::size_t>(i + radius)] * src[c];
        }
      }
    });
    std::fill(v.begin(), v.end(), 0.0);
    tbb::parallel_for(0, w, [&](int x) {
      for (int y = 0; y < h; ++y) {
        const double* src =
            tmp.data() + (static_cast<std::size_t>(y) * static_cast<std::size_t>(w) +
                          static_cast<std::size_t>(x)) *
                             3;
        if (src[0] == 0.0 && src[1] == 0.0 && src[2] == 0.0) continue;
        for (int i = -radius; i <= radius; ++i) {
          const int yy = y + i;
          if (yy < 0 || yy >= h) continue;
          double* dst = at(x, yy);
          for (int c = 0; c < 3; ++c) dst[c] += k[static_cast<std::size_t>(i + radius)] * src[c];
        }
      }
    });
  }
};

}  // namespace

double exposure_jitter(const PhotoOptions& o, int index) {
  const double ev = o.artefacts.exposure_jitter_ev;
  if (ev <= 0.0) return 1.0;
  const double u = 2.0 * unit(hash(o.seed, 0x6578706full, static_cast<std::uint64_t>(index))) - 1.0;
  return std::exp2(u * ev);
}

Eigen::Vector2d shake_offset(const PhotoOptions& o, int index) {
  const double r = o.artefacts.shake_px;
  if (r <= 0.0) return Eigen::Vector2d::Zero();
  // Uniform in the disc: radius as the square root of a uniform draw.
  const auto i = static_cast<std::uint64_t>(index);
  const double rho = r * std::sqrt(unit(hash(o.seed, 0x7368616bull, i, 0)));
  const double phi = 2.0 * kPi * unit(hash(o.seed, 0x7368616bull, i, 1));
  return {rho * std::cos(phi), rho * std::sin(phi)};
}

void apply_shake(const Eigen::Vector2d& offset, Image* img) {
  if (offset.isZero()) return;
  const int w = img->width(), h = img->height(), ch = img->channels();
  const Image src = *img;
  tbb::parallel_for(0, h, [&](int y) {
    const double sy = std::clamp(y - offset.y(), 0.0, h - 1.0);
    const int y0 = std::min(static_cast<int>(sy), h - 1), y1 = std::min(y0 + 1, h - 1);
    const double fy = sy - y0;
    for (int x = 0; x < w; ++x) {
      const double sx = std::clamp(x - offset.x(), 0.0, w - 1.0);
      const int x0 = std::min(static_cast<int>(sx), w - 1), x1 = std::min(x0 + 1, w - 1);
      const double fx = sx - x0;
      for (int c = 0; c < ch; ++c) {
        const double a = src.at(x0, y0, c) + (src.at(x1, y0, c) - src.at(x0, y0, c)) * fx;
        const double b = src.at(x0, y1, c) + (src.at(x1, y1, c) - src.at(x0, y1, c)) * fx;
        img->at(x, y, c) = static_cast<float>(a + (b - a) * fy);
      }
    }
  });
}

void apply_lens(const PhotoOptions& o, Image* img) {
  const int w = img->width(), h = img->height();
  const PhotoArtefacts& a = o.artefacts;
  const double diag = std::hypot(static_cast<double>(w), static_cast<double>(h));
  if (a.vignetting && a.vignetting_corner_loss > 0.0) {
    // Flat over the centre (10% of the half-diagonal), then falling as the square of the
    // distance beyond it to 1 - loss in the corners.
    const double cx = 0.5 * (w - 1), cy = 0.5 * (h - 1), rc = 0.5 * diag, flat = 0.1 * rc;
    tbb::parallel_for(0, h, [&](int y) {
      for (int x = 0; x < w; ++x) {
        const double r = std::hypot(x - cx, y - cy);
        if (r <= flat) continue;
        const double t = std::min((r - flat) / (rc - flat), 1.0);
        const auto v = static_cast<float>(1.0 - a.vignetting_corner_loss * t * t);
        for (int c = 0; c < 3; ++c) img->at(x, y, c) *= v;
      }
    });
  }
  const double flare = a.flare ? a.flare_strength : 0.0;
  const double halo = a.bloom ? a.bloom_strength : 0.0;
  if (flare <= 0.0 && !a.bloom) return;
  // The excess above full scale is what the flare and the bloom spread; what stays at full
  // scale and below is untouched, so energy is kept and a core stays where it was.
  struct Excess {
    int x, y;
    double e[3];
  };
  std::vector<Excess> excess;
  for (int y = 0; y < h; ++y) {
    for (int x = 0; x < w; ++x) {
      Excess ex{x, y, {0.0, 0.0, 0.0}};
      bool any = false;
      for (int c = 0; c < 3; ++c) {
        const double v = img->at(x, y, c);
        if (v > 1.0) {
          ex.e[c] = v - 1.0;
          any = true;
          img->at(x, y, c) = 1.0f;
        }
      }
      if (any) excess.push_back(ex);
    }
  }
  if (excess.empty()) return;
  Image add(w, h, 3, ColourSpace::kLinear);
  auto add_grid = [&](Grid& g, double scale) {
    tbb::parallel_for(0, h, [&](int y) {
      double s[3];
      for (int x = 0; x < w; ++x) {
        g.sample(x, y, s);
        for (int c = 0; c < 3; ++c) add.at(x, y, c) += static_cast<float>(scale * s[c]);
      }
    });
  };
  const double core = 1.0 - flare - halo;
  if (a.bloom) {
    // The lens's point spread: a narrow Gaussian core around every saturated pixel (what
    // makes a sub-pixel highlight a saturated blob), and a wide faint halo.
    const double sigma_core = std::max(0.8, 0.0016 * diag);
    const double sigma_halo = a.bloom_sigma_frac * diag;
    for (const auto& [sigma, weight] :
         {std::pair{sigma_core, std::max(core, 0.0)}, std::pair{sigma_halo, halo}}) {
      if (weight <= 0.0) continue;
      const int cell = std::max(1, static_cast<int>(std::floor(sigma / 2.0)));
      Grid g(w, h, cell);
      for (const Excess& ex : excess) g.splat(ex.x, ex.y, ex.e);
      g.blur(sigma / cell);
      // A grid of cells > 1 px holds cell^2 pixels' energy per cell.
      add_grid(g, 1.0 / (cell * cell));
    }
  } else {
    for (const Excess& ex : excess) {
      for (int c = 0; c < 3; ++c) add.at(ex.x, ex.y, c) += static_cast<float>(core * ex.e[c]);
    }
  }
  if (flare > 0.0) {
    // Star: every saturated cell's excess along `spokes` straight streaks in opposite pairs,
    // falling off exponentially; a streak leaves the core symmetrically, so the core's
    // centroid does not move.
    const int cell = std::max(1, static_cast<int>(std::lround(diag / 1500.0)));
    Grid cells(w, h, cell);
    Grid mx(w, h, cell), my(w, h, cell);  // energy-weighted position sums
    for (const Excess& ex : excess) {
      const double tot = ex.e[0] + ex.e[1] + ex.e[2];
      const int gx = ex.x / cell, gy = ex.y / cell;
      double* p = cells.at(gx, gy);
      for (int c = 0; c < 3; ++c) p[c] += ex.e[c];
      mx.at(gx, gy)[0] += tot * ex.x;
      my.at(gx, gy)[0] += tot * ex.y;
    }
    const double length = a.flare_length_frac * diag;
    const int steps = std::max(2, static_cast<int>(std::ceil(5.0 * length)));
    double norm = 0.0;
    for (int t = 1; t <= steps; ++t) norm += std::exp(-t / length);
    const int spokes = a.flare_spokes;
    Grid star(w, h, 1);
    for (int gy = 0; gy < cells.h; ++gy) {
      for (int gx = 0; gx < cells.w; ++gx) {
        const double* e = cells.at(gx, gy);
        const double tot = e[0] + e[1] + e[2];
        if (tot <= 0.0) continue;
        const double cx = mx.at(gx, gy)[0] / tot, cy = my.at(gx, gy)[0] / tot;
        for (int k = 0; k < spokes; ++k) {
          const double th = a.flare_angle_deg * kPi / 180.0 + 2.0 * kPi * k / spokes;
          const double ux = std::cos(th), uy = std::sin(th);
          for (int t = 1; t <= steps; ++t) {
            const double f = flare * std::exp(-t / length) / (norm * spokes);
            const double s[3] = {f * e[0], f * e[1], f * e[2]};
            star.splat(cx + t * ux, cy + t * uy, s);
          }
        }
      }
    }
    for (int y = 0; y < h; ++y) {
      for (int x = 0; x < w; ++x) {
        const double* s = star.at(x, y);
        for (int c = 0; c < 3; ++c) add.at(x, y, c) += static_cast<float>(s[c]);
      }
    }
  }
  for (std::size_t i = 0; i < static_cast<std::size_t>(w) * static_cast<std::size_t>(h) * 3; ++i) {
    img->data()[i] += add.data()[i];
  }
}

Image apply_sensor(const PhotoOptions& o, const Image& radiance, int image_index) {
  const int w = radiance.width(), h = radiance.height();
  Image out(w, h, 3, o.srgb ? ColourSpace::kSRGB : ColourSpace::kLinear);
  const double levels = o.bits == 16 ? 65535.0 : 255.0;
  const PhotoArtefacts& a = o.artefacts;
  const double read = a.read_noise_grey / 255.0;
  const std::uint64_t key0 = hash(o.seed, 0x70686f746full, static_cast<std::uint64_t>(image_index));
  tbb::parallel_for(0, h, [&](int y) {
    for (int x = 0; x < w; ++x) {
      double z[4] = {0.0, 0.0, 0.0, 0.0};
      if (a.noise) {
        const std::uint64_t pixel = static_cast<std::uint64_t>(y) * static_cast<std::uint64_t>(w) +
                                    static_cast<std::uint64_t>(x);
        const std::uint64_t key = mix64(key0 ^ (pixel * 0xd6e8feb86659fd93ull));
        gaussian_pair(key, &z[0], &z[1]);
        gaussian_pair(mix64(key ^ 0x2545f4914f6cdd1dull), &z[2], &z[3]);
      }
      for (int c = 0; c < 3; ++c) {
        double v = radiance.at(x, y, c);
        if (a.noise) {
          const double sigma = std::sqrt(read * read + std::max(v, 0.0) / a.shot_full_well);
          v += sigma * z[c];
        }
        v = std::clamp(v, 0.0, 1.0);
        if (o.srgb) v = linear_to_srgb(v);
        out.at(x, y, c) = static_cast<float>(std::round(v * levels) / levels);
      }
    }
  });
  return out;
}

}  // namespace ptmkit::synth::detail
