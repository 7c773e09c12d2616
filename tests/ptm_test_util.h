// Helpers shared by the .ptm tests (ptm_*_test.cc): files as bytes, a smooth coefficient map
// of realistic ranges, and the relit difference between two maps with its half-step bound.
#pragma once

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <string>
#include <vector>

#include "ptmkit/core/coefficients.h"
#include "ptmkit/core/image.h"
#include "ptmkit/core/light_layout.h"
#include "ptmkit/texture/ptm.h"
#include "ptmkit/texture/relight.h"

namespace ptmkit::test {

using Bytes = std::vector<std::uint8_t>;

inline Bytes read_bytes(const std::filesystem::path& p) {
  std::ifstream in(p, std::ios::binary);
  return Bytes(std::istreambuf_iterator<char>(in), {});
}

inline void write_bytes(const std::filesystem::path& p, const std::string& header,
                        const Bytes& data) {
  std::ofstream out(p, std::ios::binary);
  out << header;
  out.write(reinterpret_cast<const char*>(data.data()), static_cast<std::streamsize>(data.size()));
}

// A smooth map with realistic coefficient ranges (normalised units): a5 in [0.2, 0.8],
// a3, a4 within +-0.3, a0..a2 within +-0.15; colours with largest channel 1 (LRGB) or chroma
// within +-0.1 (YCC). Not symmetric in x or y.
inline CoefficientMap smooth_map(int w, int h, ColourModel model) {
  CoefficientMap map(w, h, model);
  for (int y = 0; y < h; ++y) {
    for (int x = 0; x < w; ++x) {
      const double u = (x + 0.5) / w, v = (y + 0.5) / h;
      float* a = map.texel_coeffs(x, y);
      for (int p = 0; p < map.polynomials(); ++p) {
        const double ph = 0.7 * p;
        float* c = a + p * kPtmTerms;
        c[0] = static_cast<float>(-0.15 * std::cos(3.0 * u + ph));
        c[1] = static_cast<float>(-0.12 * std::sin(2.0 * v + 1.0 + ph));
        c[2] = static_cast<float>(0.1 * std::sin(4.0 * u * v + ph));
        c[3] = static_cast<float>(0.3 * std::sin(2.5 * u + 2.0 * v + ph));
        c[4] = static_cast<float>(0.25 * std::cos(3.5 * v - u + ph));
        c[5] = static_cast<float>(0.5 + 0.3 * std::sin(2.0 * u - 1.5 * v + ph));
      }
      if (model == ColourModel::kLRGB) {
        float* col = map.texel_colour(x, y);
        col[0] = 1.0f;
        col[1] = static_cast<float>(0.5 + 0.4 * u);
        col[2] = static_cast<float>(0.3 + 0.5 * v);
      } else if (model == ColourModel::kYCC) {
        float* col = map.texel_colour(x, y);
        col[0] = static_cast<float>(0.1 * std::sin(3.0 * u));
        col[1] = static_cast<float>(-0.08 * std::cos(2.0 * v));
      }
    }
  }
  return map;
}

// Max over `lights` and texels of the clamped relit difference, grey levels.
inline double max_relit_difference_grey(const CoefficientMap& a, const CoefficientMap& b) {
  double worst = 0.0;
  for (const auto& l : geodesic_dome(2)) {
    const Image ia = texture::relight(a, l), ib = texture::relight(b, l);
    for (std::size_t k = 0; k < ia.size(); ++k) {
      worst = std::max(worst, 255.0 * std::abs(static_cast<double>(ia.data()[k] - ib.data()[k])));
    }
  }
  return worst;
}

// Worst-case relit error from rounding every coefficient by half a step: sum_i s_i / 2 times
// the largest |basis_i| over the unit disc (1 for lu^2, lv^2, lu, lv, 1; 1/2 for lu lv),
// in grey levels (file units are grey levels).
inline double half_step_bound_grey(const texture::PtmQuantisation& q) {
  const double basis_max[kPtmTerms] = {1.0, 1.0, 0.5, 1.0, 1.0, 1.0};
  double bound = 0.0;
  for (int i = 0; i < kPtmTerms; ++i) bound += 0.5 * std::abs(q.scales[i]) * basis_max[i];
  return bound;
}

}  // namespace ptmkit::test
