// Shading of the photo scene: spheres, bases, ground, object, distractor, room; the adaptive
// supersampled trace of one light; the truth that needs ray casting.
#include <algorithm>
#include <cmath>
#include <numbers>

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include "hash.h"
#include "optics.h"
#include "photo_internal.h"
#include "render.h"

namespace ptmkit::synth::detail {

namespace {

constexpr double kPi = std::numbers::pi;
constexpr double kGlassIndex = 1.5;
constexpr double kDielectricF0 = 0.04;
constexpr double kBlackF0 = 0.05;
constexpr double kBlackAlbedo = 0.02;
constexpr double kChromeF0 = 0.8;
// Peak radiance of the glow where a glass ball's focused beam leaves it, per unit irradiance.
constexpr double kGlassGlow = 20.0;
constexpr int kMaxDepth = 3;
// The optics' blur around highlights (pixels), and the half-size of the block it is rendered
// in around each mirror highlight.
constexpr double kPsfSigmaPx = 0.6;
constexpr int kPsfBlock = 4;
// Sample ids (edges between them are supersampled).
constexpr int kIdSky = 1, kIdCloth = 2, kIdObject = 3, kIdDistractor = 4, kIdCamera = 5,
              kIdSphere = 10, kIdBase = 20;

using V3 = Eigen::Vector3d;
using V2 = Eigen::Vector2d;
using Rgb = Eigen::Array3d;

double value_noise(std::uint64_t seed, std::uint64_t tag, double x, double y) {
  const double fx = std::floor(x), fy = std::floor(y);
  const auto ix = static_cast<std::int64_t>(fx), iy = static_cast<std::int64_t>(fy);
  auto at = [&](std::int64_t a, std::int64_t b) {
    return unit(hash(seed, tag, static_cast<std::uint64_t>(a), static_cast<std::uint64_t>(b)));
  };
  const double tx = x - fx, ty = y - fy;
  const double sx = tx * tx * (3.0 - 2.0 * tx), sy = ty * ty * (3.0 - 2.0 * ty);
  const double a = at(ix, iy) + (at(ix + 1, iy) - at(ix, iy)) * sx;
  const double b = at(ix, iy + 1) + (at(ix + 1, iy + 1) - at(ix, iy + 1)) * sx;
  return a + (b - a) * sy;
}

Rgb bilinear(const Image& img, double x, double y) {
  x = std::clamp(x, 0.0, img.width() - 1.0);
  y = std::clamp(y, 0.0, img.height() - 1.0);
  const int x0 = std::min(static_cast<int>(x), img.width() - 2);
  const int y0 = std::min(static_cast<int>(y), img.height() - 2);
  const double fx = x - x0, fy = y - y0;
  Rgb out;
  for (int c = 0; c < 3; ++c) {
    const double a = img.at(x0, y0, c) + (img.at(x0 + 1, y0, c) - img.at(x0, y0, c)) * fx;
    const double b =
        img.at(x0, y0 + 1, c) + (img.at(x0 + 1, y0 + 1, c) - img.at(x0, y0 + 1, c)) * fx;
    out[c] = a + (b - a) * fy;
  }
  return out;
}

// Normalised Blinn-Phong lobe (energy roughly independent of the exponent).
double blinn(const V3& n, const V3& l, const V3& v, double exponent) {
  const V3 h = (l + v).normalized();
  const double nh = n.dot(h);
  if (nh <= 0.0) return 0.0;
  return (exponent + 8.0) / (8.0 * kPi) * std::pow(nh, exponent);
}

}  // namespace

LightState PhotoScene::light_state(int index) const {
  LightState s;
  s.index = index;
  const V3& l = light_dirs[static_cast<std::size_t>(index)];
  s.l_cam = V3(l.x(), -l.y(), -l.z()).normalized();
  if (has_object) {
    std::vector<std::uint8_t> shadow;
    if (relief_options.cast_shadows) shadow = cast_shadow_mask(relief, l);
    render_into(relief, relief_options, l, index, shadow.empty() ? nullptr : shadow.data(),
                &s.relief, nullptr, nullptr);
  }
  return s;
}

Rgb PhotoScene::ground(const V3& p, const V3& view, const LightState* light, int* id) const {
  const V3 rel = p - ground_origin;
  const double u = rel.dot(g1), v = rel.dot(g2);
  const V3 l = light != nullptr ? light->l_cam : V3::Zero();
  double direct = 0.0;  // irradiance from the light (with shadows), 0 when static
  double focused = 0.0;
  if (light != nullptr) {
    const double cos_l = up.dot(l);
    if (cos_l > 0.0) direct = o.light_irradiance * cos_l * light_visibility(p, l, -1);
    focused = caustic(p, l);
  }
  const double half = 0.5 * o.object_size_mm;
  if (has_object && std::abs(u) < half && std::abs(v) < half) {
    if (id != nullptr) *id = kIdObject;
    const int n = relief.width;
    const double tx = (u + half) / o.object_size_mm * n - 0.5;
    const double ty = (v + half) / o.object_size_mm * n - 0.5;
    const Rgb albedo = bilinear(relief.albedo, tx, ty);
    Rgb c = albedo * (ambient + focused);
    if (light != nullptr && direct > 0.0) {
      // The relief's own shading (Lambert, specular, its cast shadows) for irradiance 1,
      // scaled by what reaches the ground here (the spheres' shadows).
      c += bilinear(light->relief, tx, ty) * direct / std::max(up.dot(l), 1e-9);
    }
    return c;
  }
  const V2 q = V2(u, v) - o.distractor_offset_mm;
  const double rd = o.distractor_radius_mm;
  if (o.distractor != Distractor::kNone && q.norm() < rd) {
    if (id != nullptr) *id = kIdDistractor;
    const double r = q.norm() / rd;
    const V3 radial = r > 1e-9 ? V3((q.x() * g1 + q.y() * g2).normalized()) : V3(g1);
    V3 n = up;
    Rgb f0, diffuse;
    double exponent;
    if (o.distractor == Distractor::kCoin) {
      // Brass centre, silver ring, a bevelled rim, a raised lip between them and a low relief.
      const bool brass = r < 0.6;
      f0 = brass ? Rgb(0.9, 0.68, 0.36) : Rgb(0.9, 0.9, 0.88);
      diffuse = 0.1 * f0;
      exponent = 250.0;
      double tilt = 0.0;
      if (r > 0.88) tilt = (r - 0.88) / 0.12 * 1.1;              // outward, up to 63 degrees
      if (r > 0.57 && r < 0.63) tilt = (0.6 - r) / 0.03 * 0.45;  // the lip
      const double scale = rd / 5.0;
      const double x = q.x() / scale, y = q.y() / scale, hstep = 0.05;
      const std::uint64_t tag = brass ? 11 : 12;
      const double gx =
          (value_noise(o.seed, tag, x + hstep, y) - value_noise(o.seed, tag, x - hstep, y)) /
          (2.0 * hstep);
      const double gy =
          (value_noise(o.seed, tag, x, y + hstep) - value_noise(o.seed, tag, x, y - hstep)) /
          (2.0 * hstep);
      const double relief_slope = r < 0.86 ? 0.35 : 0.0;
      n = (std::cos(tilt) * up + std::sin(tilt) * radial - relief_slope * (gx * g1 + gy * g2))
              .normalized();
    } else {
      // A shallow glazed bowl: normals lean inward (concave), a rounded lip at the rim.
      f0 = Rgb::Constant(kDielectricF0);
      diffuse = Rgb(0.72, 0.71, 0.68);
      exponent = 600.0;
      double tilt = -0.35 * std::min(r, 0.88) / 0.88;
      if (r > 0.88) tilt = -0.35 + (r - 0.88) / 0.12 * 1.6;
      n = (std::cos(tilt) * up + std::sin(tilt) * radial).normalized();
    }
    const double cos_v = std::max(n.dot(view), 0.0);
    const Rgb fres = f0 + (Rgb::Ones() - f0) * std::pow(1.0 - cos_v, 5.0);
    const V3 refl = reflect(-view, n);
    Rgb c = diffuse * ambient + fres * environment(refl) * 0.6;
    if (light != nullptr) {
      const double nl = n.dot(l);
      if (nl > 0.0) {
        const double irr = o.light_irradiance * nl * light_visibility(p, l, -1);
        c += irr * (diffuse / kPi * kPi + fres * blinn(n, l, view, exponent));
      }
      c += diffuse * focused;
    }
    return c;
  }
  if (id != nullptr) *id = kIdCloth;
  // The cloth: a dark fabric with a weave and uneven dye.
  const double dye = 0.8 + 0.4 * value_noise(o.seed, 21, u / 7.0, v / 7.0);
  const double weave = 0.9 + 0.2 * value_noise(o.seed, 22, u / 0.6, v / 0.6);
  const Rgb albedo = o.ground_albedo * dye * weave * Rgb(1.0, 0.96, 0.93);
  return albedo * (ambient + direct + focused);
}

Rgb PhotoScene::reflection(int i, const V3& p, const V3& r, const LightState* light,
                           int depth) const {
  if (o.reflect_scene && depth > 0) {
    const Hit h = intersect(p, r, true, i);
    if (h.kind != HitKind::kNone) return radiance(p, r, nullptr, depth - 1, i, nullptr);
  }
  Rgb c = environment(r);
  if (light != nullptr) c += light_term(r, light->l_cam, false);
  return c;
}

Rgb PhotoScene::sphere(int i, const V3& p, const V3& d, const LightState* light, int depth) const {
  const PhotoSphere& s = o.spheres[static_cast<std::size_t>(i)];
  const V3 n = (p - s.centre_mm) / s.radius_mm;
  const double cos_v = std::clamp(-d.dot(n), 0.0, 1.0);
  const V3 r = reflect(d, n);
  switch (s.material) {
    case SphereMaterial::kChrome: {
      const double f = schlick(kChromeF0, cos_v);
      return f * reflection(i, p, r, light, depth) * Rgb(0.97, 0.97, 0.99);
    }
    case SphereMaterial::kBlackGlossy: {
      const double f = schlick(kBlackF0, cos_v);
      double irr = ambient;
      if (light != nullptr) {
        const double nl = n.dot(light->l_cam);
        if (nl > 0.0) irr += o.light_irradiance * nl * light_visibility(p, light->l_cam, i);
      }
      return f * reflection(i, p, r, light, depth) + (1.0 - f) * kBlackAlbedo * irr;
    }
    case SphereMaterial::kGlass:
      break;
  }
  // Glass: the surface reflection, then the light through the ball: straight through (out
  // the far side, into the scene: the caustic on the ground shows there) and once reflected
  // inside (out the near side, to the room and the light).
  const double f = schlick(kDielectricF0, cos_v);
  Rgb c = f * reflection(i, p, r, light, depth);
  V3 t1;
  if (!refract(d, n, 1.0 / kGlassIndex, &t1)) return c;
  const Rgb tint(0.93, 0.98, 0.95);
  const V3 p2 = p + t1 * (-2.0 * (p - s.centre_mm).dot(t1));
  const V3 n2 = (p2 - s.centre_mm) / s.radius_mm;
  V3 out;
  double f2 = 1.0;
  Rgb through = Rgb::Zero();
  if (refract(t1, -n2, kGlassIndex, &out)) {
    f2 = schlick(kDielectricF0, out.dot(n2));
    if (depth > 0) {
      const Hit h = intersect(p2, out, true, i);
      if (h.kind != HitKind::kNone) {
        through = radiance(p2, out, light, depth - 1, i, nullptr);
      } else {
        through = environment(out);
        if (light != nullptr) through += light_term(out, light->l_cam, true);
      }
    } else {
      through = environment(out);
    }
  }
  if (light != nullptr) {
    // The ball focuses the light it lets in toward the far side (focus at 1.5 r from the
    // centre for index 1.5); bubbles and striae in the glass scatter some of that converging
    // beam, brightest where it is narrowest, near the far surface. Seen through the glass it
    // is a hot spot on the side away from the light, where no mirror reflection of the light
    // can be: the closest approach of this ray's path in the glass to the beam's axis.
    const V3 axis = -light->l_cam;
    const V3 w0 = p - s.centre_mm;
    const double len = (p2 - p).norm();
    const double b = t1.dot(axis), dw = t1.dot(w0), e = axis.dot(w0);
    const double den = 1.0 - b * b;
    double tr = 0.0, ua = 0.0;
    if (den > 1e-9) {
      tr = std::clamp((b * e - dw) / den, 0.0, len);
      ua = std::clamp(e + b * tr, 0.6 * s.radius_mm, 0.97 * s.radius_mm);
      tr = std::clamp(ua * b - dw, 0.0, len);
    }
    const V3 q = p + tr * t1;
    const V3 qa = s.centre_mm + ua * axis;
    const double sigma = 0.07 * s.radius_mm;
    const double u = (ua / s.radius_mm - 0.6) / 0.37;  // 0 .. 1 toward the far surface
    through += kGlassGlow * o.light_irradiance * u * u *
               std::exp(-(q - qa).squaredNorm() / (2.0 * sigma * sigma));
  }
  Rgb inner = Rgb::Zero();
  const V3 t2 = reflect(t1, n2);
  const V3 p3 = p2 + t2 * (-2.0 * (p2 - s.centre_mm).dot(t2));
  const V3 n3 = (p3 - s.centre_mm) / s.radius_mm;
  V3 out3;
  if (refract(t2, -n3, kGlassIndex, &out3)) {
    const double f3 = schlick(kDielectricF0, out3.dot(n3));
    inner = (1.0 - f3) * environment(out3);
    if (light != nullptr) inner += (1.0 - f3) * light_term(out3, light->l_cam, true);
  }
  c += (1.0 - f) * tint * ((1.0 - f2) * through + f2 * inner);
  return c;
}

Rgb PhotoScene::radiance(const V3& origin, const V3& d, const LightState* light, int depth,
                         int skip_sphere, int* id) const {
  const Hit h = intersect(origin, d, depth < kMaxDepth, skip_sphere);
  switch (h.kind) {
    case HitKind::kNone: {
      if (id != nullptr) *id = kIdSky;
      Rgb c = environment(d);
      if (light != nullptr) c += light_term(d, light->l_cam, false);
      return c;
    }
    case HitKind::kGround:
      return ground(h.point, -d, light, id);
    case HitKind::kSphere:
      if (id != nullptr) *id = kIdSphere + h.index;
      if (depth <= 0) return environment(d);
      return sphere(h.index, h.point, d, light, depth);
    case HitKind::kBase: {
      if (id != nullptr) *id = kIdBase + h.index;
      const Base& b = bases[static_cast<std::size_t>(h.index)];
      const V3 w = h.point - b.rim_mm;
      // The side (radial normal) or the flat top (up).
      const V3 radial =
          std::abs(w.dot(up)) < 1e-6 ? V3(up) : V3((w - w.dot(-up) * (-up)).normalized());
      // Matt dark grey plastic with a faint sheen.
      double irr = ambient;
      if (light != nullptr) {
        const double nl = radial.dot(light->l_cam);
        if (nl > 0.0) irr += o.light_irradiance * nl * light_visibility(h.point, light->l_cam, -1);
      }
      return Rgb(0.09, 0.085, 0.08) * irr;
    }
    case HitKind::kCamera:
      if (id != nullptr) *id = kIdCamera;
      return Rgb::Constant(0.003);
  }
  return Rgb::Zero();
}

Sample PhotoScene::sample(double x, double y, const LightState* light) const {
  Sample s;
  const V3 d = pinhole_ray(x, y, o.focal_px, pp);
  s.rgb = radiance(V3::Zero(), d, light, kMaxDepth, -1, &s.id) * o.exposure;
  if (light != nullptr) s.rgb *= exposure_jitter(o, light->index);
  s.hot = s.rgb.maxCoeff() > 1.0;
  return s;
}

Image PhotoScene::trace(const LightState& light) const {
  const int w = o.width, h = o.height;
  Image img(w, h, 3, ColourSpace::kLinear);
  std::vector<int> ids(static_cast<std::size_t>(w) * static_cast<std::size_t>(h));
  std::vector<std::uint8_t> hot(ids.size());
  tbb::parallel_for(tbb::blocked_range<int>(0, h), [&](const tbb::blocked_range<int>& rows) {
    for (int y = rows.begin(); y < rows.end(); ++y) {
      for (int x = 0; x < w; ++x) {
        const Sample s = sample(x, y, &light);
        const std::size_t at =
            static_cast<std::size_t>(y) * static_cast<std::size_t>(w) + static_cast<std::size_t>(x);
        ids[at] = s.id;
        hot[at] = s.hot ? 1 : 0;
        for (int c = 0; c < 3; ++c) img.at(x, y, c) = static_cast<float>(s.rgb[c]);
      }
    }
  });
  // Refinement: 1 = supersample x supersample sub-samples (edges between surfaces, strong
  // contrast, saturated samples, glass), 2 = 16 x 16 (around the light's mirror highlights,
  // sub-pixel discs that one sample per pixel can miss).
  std::vector<std::uint8_t> level(ids.size(), 0);
  const int ss = o.supersample;
  if (ss > 1) {
    // The static scene's map, and this light's saturated samples with their neighbours.
    tbb::parallel_for(0, h, [&](int y) {
      for (int x = 0; x < w; ++x) {
        const std::size_t at =
            static_cast<std::size_t>(y) * static_cast<std::size_t>(w) + static_cast<std::size_t>(x);
        bool refine = static_refine[at] != 0;
        for (int dy = -1; dy <= 1 && !refine; ++dy) {
          for (int dx = -1; dx <= 1; ++dx) {
            const int xx = x + dx, yy = y + dy;
            if (xx < 0 || yy < 0 || xx >= w || yy >= h) continue;
            if (hot[static_cast<std::size_t>(yy) * static_cast<std::size_t>(w) +
                    static_cast<std::size_t>(xx)] != 0) {
              refine = true;
              break;
            }
          }
        }
        if (refine) level[at] = 1;
      }
    });
  }
  // Around each mirror highlight of this light: the light's image is a sub-pixel disc, so
  // pixel integration alone would put its centroid at a pixel centre. A camera blurs the
  // optical image before the pixels integrate it (lens, anti-aliasing filter): there, dense
  // point samples are filtered with a Gaussian of kPsfSigmaPx, which keeps the sub-pixel
  // position in the pixels' values.
  struct Block {
    int x0, y0, x1, y1;
  };
  std::vector<Block> blocks;
  for (const PhotoSphereTruth& t : truth.spheres) {
    const auto& hl = t.highlight_px[static_cast<std::size_t>(light.index)];
    if (!hl) continue;
    const int cx = static_cast<int>(std::lround(hl->x()));
    const int cy = static_cast<int>(std::lround(hl->y()));
    Block b{std::max(cx - kPsfBlock, 0), std::max(cy - kPsfBlock, 0),
            std::min(cx + kPsfBlock, w - 1), std::min(cy + kPsfBlock, h - 1)};
    blocks.push_back(b);
    for (int y = b.y0; y <= b.y1; ++y) {
      for (int x = b.x0; x <= b.x1; ++x) {
        level[static_cast<std::size_t>(y) * static_cast<std::size_t>(w) +
              static_cast<std::size_t>(x)] = 2;
      }
    }
  }
  for (const Block& b : blocks) {
    constexpr int kN = 16;  // samples per pixel side
    constexpr double kReach = 3.0 * kPsfSigmaPx;
    const double sx0 = b.x0 - kReach - 0.5, sy0 = b.y0 - kReach - 0.5;
    const int nx = static_cast<int>(std::ceil((b.x1 - b.x0 + 1 + 2.0 * kReach) * kN));
    const int ny = static_cast<int>(std::ceil((b.y1 - b.y0 + 1 + 2.0 * kReach) * kN));
    std::vector<Rgb> samples(static_cast<std::size_t>(nx) * static_cast<std::size_t>(ny));
    tbb::parallel_for(0, ny, [&](int j) {
      for (int i = 0; i < nx; ++i) {
        samples[static_cast<std::size_t>(j) * static_cast<std::size_t>(nx) +
                static_cast<std::size_t>(i)] =
            sample(sx0 + (i + 0.5) / kN, sy0 + (j + 0.5) / kN, &light).rgb;
      }
    });
    tbb::parallel_for(b.y0, b.y1 + 1, [&](int y) {
      for (int x = b.x0; x <= b.x1; ++x) {
        Rgb acc = Rgb::Zero();
        double wsum = 0.0;
        const int i0 = std::max(0, static_cast<int>(std::floor((x - kReach - sx0) * kN)));
        const int i1 = std::min(nx - 1, static_cast<int>(std::ceil((x + kReach - sx0) * kN)));
        const int j0 = std::max(0, static_cast<int>(std::floor((y - kReach - sy0) * kN)));
        const int j1 = std::min(ny - 1, static_cast<int>(std::ceil((y + kReach - sy0) * kN)));
        for (int j = j0; j <= j1; ++j) {
          const double dy = sy0 + (j + 0.5) / kN - y;
          for (int i = i0; i <= i1; ++i) {
            const double dx = sx0 + (i + 0.5) / kN - x;
            const double wt = std::exp(-(dx * dx + dy * dy) / (2.0 * kPsfSigmaPx * kPsfSigmaPx));
            acc += wt * samples[static_cast<std::size_t>(j) * static_cast<std::size_t>(nx) +
                                static_cast<std::size_t>(i)];
            wsum += wt;
          }
        }
        acc /= wsum;
        for (int c = 0; c < 3; ++c) img.at(x, y, c) = static_cast<float>(acc[c]);
      }
    });
  }
  tbb::parallel_for(0, h, [&](int y) {
    for (int x = 0; x < w; ++x) {
      const std::size_t at =
          static_cast<std::size_t>(y) * static_cast<std::size_t>(w) + static_cast<std::size_t>(x);
      if (level[at] != 1) continue;
      const int n = ss;
      Rgb acc = Rgb::Zero();
      for (int sy = 0; sy < n; ++sy) {
        for (int sx = 0; sx < n; ++sx) {
          acc += sample(x - 0.5 + (sx + 0.5) / n, y - 0.5 + (sy + 0.5) / n, &light).rgb;
        }
      }
      acc /= static_cast<double>(n * n);
      for (int c = 0; c < 3; ++c) img.at(x, y, c) = static_cast<float>(acc[c]);
    }
  });
  return img;
}

void PhotoScene::build_static_refine() {
  const int w = o.width, h = o.height;
  const std::size_t count = static_cast<std::size_t>(w) * static_cast<std::size_t>(h);
  static_refine.assign(count, 0);
  if (o.supersample <= 1) return;
  std::vector<int> ids(count);
  std::vector<float> lum(count);
  std::vector<std::uint8_t> hot(count);
  tbb::parallel_for(0, h, [&](int y) {
    for (int x = 0; x < w; ++x) {
      const Sample s = sample(x, y, nullptr);
      const std::size_t at =
          static_cast<std::size_t>(y) * static_cast<std::size_t>(w) + static_cast<std::size_t>(x);
      ids[at] = s.id;
      hot[at] = s.hot ? 1 : 0;
      lum[at] = static_cast<float>(0.25 * s.rgb[0] + 0.5 * s.rgb[1] + 0.25 * s.rgb[2]);
    }
  });
  // Edges between surfaces, strong contrast, saturated samples and their neighbours, and
  // glass (whose refracted view changes quickly).
  tbb::parallel_for(0, h, [&](int y) {
    for (int x = 0; x < w; ++x) {
      const std::size_t at =
          static_cast<std::size_t>(y) * static_cast<std::size_t>(w) + static_cast<std::size_t>(x);
      bool refine = ids[at] >= kIdSphere && ids[at] < kIdSphere + 10 &&
                    o.spheres[static_cast<std::size_t>(ids[at] - kIdSphere)].material ==
                        SphereMaterial::kGlass;
      float lo = lum[at], hi = lum[at];
      for (int dy = -1; dy <= 1 && !refine; ++dy) {
        for (int dx = -1; dx <= 1; ++dx) {
          const int xx = x + dx, yy = y + dy;
          if (xx < 0 || yy < 0 || xx >= w || yy >= h) continue;
          const std::size_t n = static_cast<std::size_t>(yy) * static_cast<std::size_t>(w) +
                                static_cast<std::size_t>(xx);
          if (ids[n] != ids[at] || hot[n] != 0) {
            refine = true;
            break;
          }
          lo = std::min(lo, lum[n]);
          hi = std::max(hi, lum[n]);
        }
      }
      if (refine || hi - lo > 0.02f + 0.1f * hi) static_refine[at] = 1;
    }
  });
}

void PhotoScene::build_truth() {
  truth = PhotoTruth{};
  truth.light_dirs = light_dirs;
  truth.principal_px = pp;
  const double w = o.width, h = o.height;
  auto inside = [&](const V2& q) {
    return q.x() >= -0.5 && q.y() >= -0.5 && q.x() <= w - 0.5 && q.y() <= h - 0.5;
  };
  for (std::size_t i = 0; i < o.spheres.size(); ++i) {
    const PhotoSphere& s = o.spheres[i];
    PhotoSphereTruth t;
    t.sphere = s;
    t.outline = sphere_outline(s.centre_mm, s.radius_mm, o.focal_px, pp);
    const double ang = t.outline.angle_deg * kPi / 180.0;
    const V2 major(std::cos(ang), std::sin(ang)), minor(-std::sin(ang), std::cos(ang));
    constexpr int kSamples = 720;
    int in_frame = 0, visible = 0;
    for (int k = 0; k < kSamples; ++k) {
      const double phi = 2.0 * kPi * (k + 0.5) / kSamples;
      const V2 q = t.outline.centre_px + t.outline.semi_major_px * std::cos(phi) * major +
                   t.outline.semi_minor_px * std::sin(phi) * minor;
      if (!inside(q)) continue;
      ++in_frame;
      // Just inside the outline: does the pixel ray see this sphere first?
      const V2 qi = q + 0.75 * (t.outline.centre_px - q).normalized();
      const Hit hit = intersect(V3::Zero(), pinhole_ray(qi.x(), qi.y(), o.focal_px, pp), false, -1);
      if (hit.kind == HitKind::kSphere && hit.index == static_cast<int>(i)) ++visible;
    }
    t.outline_inside_frame = static_cast<double>(in_frame) / kSamples;
    t.outline_visible = static_cast<double>(visible) / kSamples;
    for (const V3& l : light_dirs) {
      std::optional<V2> px = mirror_highlight_px(s.centre_mm, s.radius_mm, l, o.focal_px, pp);
      if (px && !inside(*px)) px.reset();
      if (px) {
        const Hit hit =
            intersect(V3::Zero(), pinhole_ray(px->x(), px->y(), o.focal_px, pp), false, -1);
        if (hit.kind != HitKind::kSphere || hit.index != static_cast<int>(i)) {
          px.reset();
        } else if (o.reflect_scene) {
          const V3 l_cam = V3(l.x(), -l.y(), -l.z()).normalized();
          if (intersect(hit.point, l_cam, true, static_cast<int>(i)).kind != HitKind::kNone) {
            px.reset();
          }
        }
      }
      t.highlight_px.push_back(px);
    }
    truth.spheres.push_back(std::move(t));
  }
  if (o.distractor != Distractor::kNone) {
    const V3 centre =
        ground_origin + o.distractor_offset_mm.x() * g1 + o.distractor_offset_mm.y() * g2;
    truth.distractor_centre_px =
        pp + o.focal_px * V2(centre.x() / centre.z(), centre.y() / centre.z());
    truth.distractor_radius_px = o.focal_px * o.distractor_radius_mm / centre.z();
  }
}

}  // namespace ptmkit::synth::detail
