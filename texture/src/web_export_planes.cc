// The web format's view of a map: its planes in the web order of the terms (PTM or HSH) and
// their ranges. The one place web export reads a CoefficientMap.
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <string>
#include <vector>

#include "ptmkit/core/colour.h"
#include "ptmkit/core/error.h"
#include "web_export_detail.h"

namespace ptmkit::texture::internal {

namespace {

// The web order of the PTM terms (1, u, v, u^2, uv, v^2) as indices into the .ptm's a0..a5
// (u^2, v^2, uv, u, v, 1).
constexpr std::array<int, kPtmTerms> kWebFromPtm = {5, 3, 4, 0, 2, 1};

}  // namespace

PlaneSource planes_of(const CoefficientMap& map) {
  PlaneSource s;
  s.type = "ptm";
  s.width = map.width;
  s.height = map.height;
  const std::size_t texels = static_cast<std::size_t>(map.width) * map.height;
  if (map.width <= 0 || map.height <= 0 ||
      map.coeffs.size() != texels * map.polynomials() * kPtmTerms ||
      map.colour.size() != texels * map.colours()) {
    throw Error("web export: the coefficient map is empty or its buffers do not match its size");
  }
  switch (map.model) {
    case ColourModel::kRGB:
      s.colorspace = "rgb";
      s.planes = 18;
      s.fill_row = [&map](int y, float* out) {
        for (int x = 0; x < map.width; ++x, out += 18) {
          const float* a = map.texel_coeffs(x, y);
          for (int j = 0; j < kPtmTerms; ++j) {
            for (int c = 0; c < 3; ++c) out[3 * j + c] = a[c * kPtmTerms + kWebFromPtm[j]];
          }
        }
      };
      break;
    case ColourModel::kLRGB:
      s.colorspace = "lrgb";
      s.planes = 9;
      s.fixed_unit_planes = 3;
      s.fill_row = [&map](int y, float* out) {
        for (int x = 0; x < map.width; ++x, out += 9) {
          const float* a = map.texel_coeffs(x, y);
          const float* col = map.texel_colour(x, y);
          for (int c = 0; c < 3; ++c) out[c] = col[c];
          for (int j = 0; j < kPtmTerms; ++j) out[3 + j] = a[kWebFromPtm[j]];
        }
      };
      break;
    case ColourModel::kYCC:
      // rgb = from_ycbcr(Y(l), cb, cr) is linear in (Y, cb, cr): each channel is a polynomial
      // whose terms are from_ycbcr of (a_k, 0, 0), the constant term's of (a5, cb, cr).
      s.colorspace = "rgb";
      s.planes = 18;
      s.fill_row = [&map](int y, float* out) {
        for (int x = 0; x < map.width; ++x, out += 18) {
          const float* a = map.texel_coeffs(x, y);
          const float* col = map.texel_colour(x, y);
          for (int j = 0; j < kPtmTerms; ++j) {
            const int k = kWebFromPtm[j];
            const bool constant = k == 5;
            double rgb[3];
            from_ycbcr({a[k], constant ? col[0] : 0.0, constant ? col[1] : 0.0}, &rgb[0], &rgb[1],
                       &rgb[2]);
            for (int c = 0; c < 3; ++c) out[3 * j + c] = static_cast<float>(rgb[c]);
          }
        }
      };
      break;
  }
  return s;
}

// An HSH map (the rgb layout .rti holds).
PlaneSource hsh_planes_of(const CoefficientMap& map) {
  PlaneSource s;
  s.type = "hsh";
  s.colorspace = "rgb";
  s.width = map.width;
  s.height = map.height;
  const int t = map.terms();
  if (map.model != ColourModel::kRGB) {
    throw Error("web export: an HSH map is exported in the rgb layout, not " +
                std::string(to_string(map.model)));
  }
  if (map.width <= 0 || map.height <= 0 ||
      map.coeffs.size() != map.texels() * 3 * static_cast<std::size_t>(t)) {
    throw Error("web export: the HSH map is empty or its buffer does not match its size");
  }
  s.planes = 3 * t;
  s.fill_row = [&map, t](int y, float* out) {
    for (int x = 0; x < map.width; ++x, out += 3 * t) {
      const float* c = map.texel_coeffs(x, y);
      for (int j = 0; j < t; ++j) {
        for (int k = 0; k < 3; ++k) out[3 * j + k] = c[k * t + j];
      }
    }
  };
  return s;
}

// Per-plane range over every texel (exact minimum and maximum, see docs/WEB.md for why not a
// quantile); throws on a non-finite coefficient.
void plane_ranges(const PlaneSource& src, std::vector<double>* lo, std::vector<double>* hi) {
  const int p = src.planes;
  std::vector<std::vector<double>> row_lo(src.height), row_hi(src.height);
  std::vector<int> bad_row(src.height, -1);
  tbb::parallel_for(tbb::blocked_range<int>(0, src.height), [&](const tbb::blocked_range<int>& r) {
    std::vector<float> buf(static_cast<std::size_t>(src.width) * p);
    for (int y = r.begin(); y < r.end(); ++y) {
      src.fill_row(y, buf.data());
      std::vector<double> l(p, std::numeric_limits<double>::infinity());
      std::vector<double> h(p, -std::numeric_limits<double>::infinity());
      for (int x = 0; x < src.width; ++x) {
        for (int k = 0; k < p; ++k) {
          const float v = buf[static_cast<std::size_t>(x) * p + k];
          if (!std::isfinite(v)) {
            bad_row[y] = x;
            break;
          }
          l[k] = std::min(l[k], static_cast<double>(v));
          h[k] = std::max(h[k], static_cast<double>(v));
        }
      }
      row_lo[y] = std::move(l);
      row_hi[y] = std::move(h);
    }
  });
  lo->assign(p, std::numeric_limits<double>::infinity());
  hi->assign(p, -std::numeric_limits<double>::infinity());
  for (int y = 0; y < src.height; ++y) {
    if (bad_row[y] >= 0) {
      throw Error("web export: texel (" + std::to_string(bad_row[y]) + ", " + std::to_string(y) +
                  ") has a non-finite coefficient");
    }
    for (int k = 0; k < p; ++k) {
      (*lo)[k] = std::min((*lo)[k], row_lo[y][k]);
      (*hi)[k] = std::max((*hi)[k], row_hi[y][k]);
    }
  }
}

}  // namespace ptmkit::texture::internal
