#include "ptmkit/texture/render.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <limits>
#include <numbers>
#include <stdexcept>
#include <string>
#include <vector>

#include "ptmkit/core/colour.h"
#include "ptmkit/core/error.h"
#include "ptmkit/texture/filtering.h"
#include "ptmkit/texture/integer_model.h"
#include "ptmkit/texture/ptm8.h"
#include "ptmkit/texture/relight.h"

namespace ptmkit::texture {

Geometry parse_geometry(std::string_view name) {
  if (name == "plane") return Geometry::kPlane;
  if (name == "cylinder") return Geometry::kCylinder;
  if (name == "sphere") return Geometry::kSphere;
  throw Error("unknown geometry '" + std::string(name) + "' (plane, cylinder or sphere)");
}

CoefficientMap to_luminance_polynomial(const CoefficientMap& map) {
  if (map.model != ColourModel::kRGB) return map;
  CoefficientMap out(map.width, map.height, ColourModel::kYCC, map.colour_space);
  for (int y = 0; y < map.height; ++y)
    for (int x = 0; x < map.width; ++x) {
      const float* a = map.texel_coeffs(x, y);
      float* o = out.texel_coeffs(x, y);
      for (int k = 0; k < kPtmTerms; ++k)
        o[k] = static_cast<float>(kLumaR * a[k] + kLumaG * a[kPtmTerms + k] +
                                  kLumaB * a[2 * kPtmTerms + k]);
      const YCbCr c = to_ycbcr(a[5], a[kPtmTerms + 5], a[2 * kPtmTerms + 5]);
      out.texel_colour(x, y)[0] = static_cast<float>(c.cb);
      out.texel_colour(x, y)[1] = static_cast<float>(c.cr);
    }
  return out;
}

namespace {

struct Vertex {
  Eigen::Vector3d p, n, s;
  double u = 0, v = 0;
};

Vertex surface(Geometry g, double u, double v, double half_w, double half_h) {
  Vertex out;
  out.u = u;
  out.v = v;
  constexpr double kPi = std::numbers::pi;
  switch (g) {
    case Geometry::kPlane:
      out.p = {(2 * u - 1) * half_w, (2 * v - 1) * half_h, 0.0};
      out.n = {0, 0, 1};
      out.s = {1, 0, 0};
      break;
    case Geometry::kCylinder: {
      const double th = 2 * kPi * (u - 0.5), r = 0.3;
      out.p = {r * std::sin(th), v - 0.5, r * std::cos(th)};
      out.n = {std::sin(th), 0, std::cos(th)};
      out.s = {std::cos(th), 0, -std::sin(th)};
      break;
    }
    case Geometry::kSphere: {
      const double th = 2 * kPi * (u - 0.5), ph = kPi * (v - 0.5), r = 0.5;
      out.n = {std::cos(ph) * std::sin(th), std::sin(ph), std::cos(ph) * std::cos(th)};
      out.p = r * out.n;
      out.s = {std::cos(th), 0, -std::sin(th)};
      break;
    }
  }
  return out;
}

// Evaluates filtered values (coefficients then colour) of `model` at (lu, lv).
void evaluate_values(ColourModel model, const float* v, double lu, double lv, float rgb[3]) {
  const auto b = ptm_basis(lu, lv);
  auto poly = [&](const float* c) {
    double s = 0;
    for (int i = 0; i < kPtmTerms; ++i) s += c[i] * b[i];
    return s;
  };
  switch (model) {
    case ColourModel::kRGB:
      for (int c = 0; c < 3; ++c) rgb[c] = static_cast<float>(poly(v + c * kPtmTerms));
      break;
    case ColourModel::kLRGB: {
      const double l = poly(v);
      for (int c = 0; c < 3; ++c) rgb[c] = static_cast<float>(l * v[kPtmTerms + c]);
      break;
    }
    case ColourModel::kYCC: {
      double r = 0, g = 0, bb = 0;
      from_ycbcr({poly(v), v[kPtmTerms], v[kPtmTerms + 1]}, &r, &g, &bb);
      rgb[0] = static_cast<float>(r);
      rgb[1] = static_cast<float>(g);
      rgb[2] = static_cast<float>(bb);
      break;
    }
  }
}

}  // namespace

Image render_texture(const CoefficientMap& input, const RenderOptions& o, RenderReport* report) {
  const RenderCamera& cam = o.camera;
  if (input.width <= 0 || input.height <= 0) throw Error("render: empty texture");
  if (cam.width < 1 || cam.height < 1 || cam.width > 16384 || cam.height > 16384)
    throw Error("render: image size must be 1..16384 pixels per side");
  const Eigen::Vector3d light = normalised_light(o.light_dir);
  Eigen::Vector3d fwd = cam.target - cam.position;
  if (!(fwd.norm() > 0) || !fwd.allFinite()) throw Error("render: the camera is at its target");
  fwd.normalize();
  Eigen::Vector3d right = fwd.cross(cam.up);
  if (!(right.norm() > 1e-9)) throw Error("render: the camera's up vector is along its view");
  right.normalize();
  const Eigen::Vector3d up = right.cross(fwd);
  const bool ortho = !(cam.fov_y_deg > 0.0);
  if (!ortho && cam.fov_y_deg >= 180.0) throw Error("render: field of view must be < 180");
  const double focal =
      ortho ? cam.height / cam.ortho_height
            : 0.5 * cam.height / std::tan(0.5 * cam.fov_y_deg * std::numbers::pi / 180.0);

  // The texture, its pyramid, its bytes and their summed-area table.
  // YCC is held as its exact RGB form (the polynomials differ only in a5), as the 8-bit
  // storage holds it, so the pyramid and the summed-area table agree texel for texel.
  CoefficientMap map = to_rgb_polynomials(
      o.shading == RenderShading::kLuminance ? to_luminance_polynomial(input) : input);
  Ptm8Texture bytes;
  if (o.integer) {
    bytes = quantise_ptm8(map);
    map = dequantise_ptm8(bytes);  // filtering works on what is stored
  }
  const CoefficientPyramid pyramid = build_pyramid(map);
  const Ptm8Texture sat_bytes = o.integer ? bytes : quantise_ptm8(map);
  const bool want_sat = o.filter == RenderFilter::kSat || o.filter == RenderFilter::kAuto;
  const SummedAreaTable sat = want_sat ? SummedAreaTable(sat_bytes) : SummedAreaTable();
  const ColourModel model = map.model;
  const int nvals = pyramid.values_per_texel();
  if (want_sat && sat.channels() != nvals) {
    throw std::logic_error("render: summed-area table and pyramid disagree on values per texel");
  }
  const int tw = map.width, th = map.height;

  // Tessellate and project.
  const double m = std::max(tw, th);
  const int nt = std::max(1, o.tessellation);
  std::vector<Vertex> verts;
  for (int j = 0; j <= nt; ++j)
    for (int i = 0; i <= nt; ++i)
      verts.push_back(surface(o.geometry, static_cast<double>(i) / nt, static_cast<double>(j) / nt,
                              0.5 * tw / m, 0.5 * th / m));
  struct Projected {
    double x, y, w;  // screen position (pixels), w = view depth (1 for orthographic)
    bool front;
  };
  std::vector<Projected> proj(verts.size());
  for (std::size_t i = 0; i < verts.size(); ++i) {
    const Eigen::Vector3d d = verts[i].p - cam.position;
    const double xc = d.dot(right), yc = d.dot(up), zc = d.dot(fwd);
    if (ortho) {
      proj[i] = {0.5 * cam.width + focal * xc, 0.5 * cam.height - focal * yc, 1.0, true};
    } else {
      proj[i] = {0.5 * cam.width + focal * xc / zc, 0.5 * cam.height - focal * yc / zc, zc,
                 zc > 1e-6};
    }
  }

  Image out(cam.width, cam.height, 3, map.colour_space, o.background);
  std::vector<double> depth(static_cast<std::size_t>(cam.width) * cam.height,
                            std::numeric_limits<double>::infinity());
  RenderReport rep;
  double lod_sum = 0.0;
  std::vector<float> vals(static_cast<std::size_t>(nvals));
  std::vector<std::uint8_t> qbytes(static_cast<std::size_t>(nvals));

  auto shade = [&](const Vertex* tri[3], const double mu[3], const double mu_x[3],
                   const double mu_y[3], float* px) -> double {
    // Perspective-correct attributes: weights mu = lambda / w, normalised.
    auto interp = [&](const double* w, auto get) {
      const double sw = w[0] + w[1] + w[2];
      return (w[0] * get(*tri[0]) + w[1] * get(*tri[1]) + w[2] * get(*tri[2])) / sw;
    };
    const double u = interp(mu, [](const Vertex& q) { return q.u; });
    const double v = interp(mu, [](const Vertex& q) { return q.v; });
    const double ux = interp(mu_x, [](const Vertex& q) { return q.u; });
    const double vx = interp(mu_x, [](const Vertex& q) { return q.v; });
    const double uy = interp(mu_y, [](const Vertex& q) { return q.u; });
    const double vy = interp(mu_y, [](const Vertex& q) { return q.v; });
    const double tx = u * tw, ty = (1.0 - v) * th;
    const Eigen::Vector2d dx((ux - u) * tw, (v - vx) * th), dy((uy - u) * tw, (v - vy) * th);
    const double lx = dx.norm(), ly = dy.norm();
    const double rho = std::max(lx, ly);
    const double lod = rho > 1.0 ? std::log2(rho) : 0.0;
    if (o.output_texcoords) {
      px[0] = static_cast<float>(u);
      px[1] = static_cast<float>(v);
      px[2] = static_cast<float>(lod);
      return lod;
    }
    Eigen::Vector3d n = Eigen::Vector3d::Zero(), s = Eigen::Vector3d::Zero();
    {
      const double sw = mu[0] + mu[1] + mu[2];
      for (int k = 0; k < 3; ++k) {
        n += mu[k] / sw * tri[k]->n;
        s += mu[k] / sw * tri[k]->s;
      }
    }
    n.normalize();
    s = (s - s.dot(n) * n).normalized();
    const Eigen::Vector3d t = n.cross(s);
    const double lz = light.dot(n);
    // The lookup: footprint-chosen filter.
    const double aniso = std::max(lx, ly) / std::max(std::min(lx, ly), 1e-12);
    bool use_sat = o.filter == RenderFilter::kSat ||
                   (o.filter == RenderFilter::kAuto && rho > 1.0 && aniso > o.sat_anisotropy);
    if (use_sat) {
      const double ex = std::max(0.5, 0.5 * (std::abs(dx.x()) + std::abs(dy.x())));
      const double ey = std::max(0.5, 0.5 * (std::abs(dx.y()) + std::abs(dy.y())));
      sat_coefficients(sat, sat_bytes, static_cast<int>(std::floor(tx - ex + 0.5)),
                       static_cast<int>(std::floor(ty - ey + 0.5)),
                       static_cast<int>(std::floor(tx + ex + 0.5)),
                       static_cast<int>(std::floor(ty + ey + 0.5)), vals.data());
      ++rep.sat;
    } else {
      sample_trilinear(pyramid, tx, ty, o.filter == RenderFilter::kBilinear ? 0.0 : lod,
                       vals.data());
      if (o.filter != RenderFilter::kBilinear) ++rep.trilinear;
    }
    float rgb[3] = {0, 0, 0};
    if (o.shading == RenderShading::kPhongTexture) {
      float tex[3];
      evaluate_values(model, vals.data(), 0.0, 0.0, tex);
      const Eigen::Vector3d view =
          ortho ? Eigen::Vector3d(-fwd) : Eigen::Vector3d(-fwd);  // distant viewer
      const Eigen::Vector3d h = (light + view).normalized();
      const double diff = std::max(0.0, lz);
      const double spec = diff > 0 ? 0.2 * std::pow(std::max(0.0, n.dot(h)), 40.0) : 0.0;
      for (int c = 0; c < 3; ++c) rgb[c] = static_cast<float>(tex[c] * (0.1 + 0.9 * diff) + spec);
    } else if (lz > 0.0) {
      const double lu = light.dot(s), lv = light.dot(t);
      if (o.integer) {
        const int nc = map.polynomials() * kPtmTerms;
        for (int k = 0; k < nc; ++k) {
          const double grey = vals[static_cast<std::size_t>(k)] * 255.0 *
                              std::ldexp(1.0, bytes.shifts[ptm8_group(k % kPtmTerms)]);
          qbytes[static_cast<std::size_t>(k)] =
              static_cast<std::uint8_t>(std::clamp(std::lround(grey), -127L, 127L) + kPtm8Bias);
        }
        for (int k = nc; k < nvals; ++k)
          qbytes[static_cast<std::size_t>(k)] = static_cast<std::uint8_t>(
              std::clamp(std::lround(255.0 * vals[static_cast<std::size_t>(k)]), 0L, 255L));
        std::uint8_t b8[3];
        integer_evaluate(qbytes.data(), qbytes.data() + nc, bytes.model, bytes.shifts,
                         quantise_light(lu, lv, lz), b8);
        for (int c = 0; c < 3; ++c) rgb[c] = static_cast<float>(b8[c] / 255.0);
      } else {
        evaluate_values(model, vals.data(), lu, lv, rgb);
      }
    }
    for (int c = 0; c < 3; ++c) px[c] = std::clamp(rgb[c], 0.0f, 1.0f);
    return lod;
  };

  for (int j = 0; j < nt; ++j)
    for (int i = 0; i < nt; ++i) {
      const int a = j * (nt + 1) + i, b = a + 1, c = a + nt + 1, d = c + 1;
      for (const auto& idx : {std::array<int, 3>{a, b, d}, std::array<int, 3>{a, d, c}}) {
        const Projected* p[3] = {&proj[static_cast<std::size_t>(idx[0])],
                                 &proj[static_cast<std::size_t>(idx[1])],
                                 &proj[static_cast<std::size_t>(idx[2])]};
        if (!p[0]->front || !p[1]->front || !p[2]->front) continue;  // no near clipping
        const double area =
            (p[1]->x - p[0]->x) * (p[2]->y - p[0]->y) - (p[2]->x - p[0]->x) * (p[1]->y - p[0]->y);
        if (std::abs(area) < 1e-12) continue;
        ++rep.triangles;
        const Vertex* tri[3] = {&verts[static_cast<std::size_t>(idx[0])],
                                &verts[static_cast<std::size_t>(idx[1])],
                                &verts[static_cast<std::size_t>(idx[2])]};
        // Screen-space barycentrics (affine in x, y).
        auto bary = [&](double x, double y, double l[3]) {
          l[0] = ((p[1]->x - x) * (p[2]->y - y) - (p[2]->x - x) * (p[1]->y - y)) / area;
          l[1] = ((p[2]->x - x) * (p[0]->y - y) - (p[0]->x - x) * (p[2]->y - y)) / area;
          l[2] = 1.0 - l[0] - l[1];
        };
        const int x0 =
            std::max(0, static_cast<int>(std::floor(std::min({p[0]->x, p[1]->x, p[2]->x}))));
        const int x1 = std::min(cam.width - 1,
                                static_cast<int>(std::ceil(std::max({p[0]->x, p[1]->x, p[2]->x}))));
        const int y0 =
            std::max(0, static_cast<int>(std::floor(std::min({p[0]->y, p[1]->y, p[2]->y}))));
        const int y1 = std::min(cam.height - 1,
                                static_cast<int>(std::ceil(std::max({p[0]->y, p[1]->y, p[2]->y}))));
        for (int py = y0; py <= y1; ++py)
          for (int px = x0; px <= x1; ++px) {
            const double cx = px + 0.5, cy = py + 0.5;
            double l[3];
            bary(cx, cy, l);
            constexpr double kEdge = -1e-12;  // shared edges: either triangle may take the pixel
            if (l[0] < kEdge || l[1] < kEdge || l[2] < kEdge) continue;
            double mu[3], mux[3], muy[3], lx[3], ly[3];
            bary(cx + 1.0, cy, lx);
            bary(cx, cy + 1.0, ly);
            for (int k = 0; k < 3; ++k) {
              mu[k] = l[k] / p[k]->w;
              mux[k] = lx[k] / p[k]->w;
              muy[k] = ly[k] / p[k]->w;
            }
            const double z = 1.0 / (mu[0] + mu[1] + mu[2]);
            // Orthographic: depth along the view from the interpolated position.
            double depth_here = z;
            if (ortho) {
              Eigen::Vector3d pos = Eigen::Vector3d::Zero();
              for (int k = 0; k < 3; ++k) pos += l[k] * tri[k]->p;
              depth_here = (pos - cam.position).dot(fwd);
            }
            const std::size_t pi = static_cast<std::size_t>(py) * cam.width + px;
            if (depth_here >= depth[pi]) continue;
            const bool fresh = std::isinf(depth[pi]);
            depth[pi] = depth_here;
            const double lod =
                shade(tri, mu, mux, muy, out.row(py) + 3 * static_cast<std::size_t>(px));
            if (fresh) {
              ++rep.covered;
              lod_sum += lod;
            }
          }
      }
    }
  rep.mean_lod = rep.covered > 0 ? lod_sum / static_cast<double>(rep.covered) : 0.0;
  if (report != nullptr) *report = rep;
  return out;
}

}  // namespace ptmkit::texture
