// What a reader that truncates (byte - bias) * scale to an integer (RTIViewer does) loses on
// a .ptm, with the finest scales (the default) and with whole-number scales
// (PtmWriteOptions::integer_scales). Usage: ptm_truncation CAPTURE.lp|FILE.ptm... A capture
// is fitted in memory (RGB and LRGB, unquantised); a .ptm is decoded (its own quantisation is
// then part of the reference). Each map is encoded both ways and relit at the 40 lights of the
// once-subdivided geodesic dome above the horizon: the mean signed and absolute differences
// from the map, in grey levels, for an exact reader and for a truncating one.
// Results: docs/FORMATS.md.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <exception>

#include "ptmkit/core/light_layout.h"
#include "ptmkit/core/light_set.h"
#include "ptmkit/fit/fit.h"
#include "ptmkit/texture/ptm.h"

using namespace ptmkit;
using namespace ptmkit::texture;

namespace {

struct Errors {
  double exact_abs = 0, trunc_signed = 0, trunc_abs = 0;
  std::size_t n = 0;
};

Errors measure(const CoefficientMap& map, const PtmFile& f) {
  Errors e;
  const auto& q = f.quantisation;
  const int planes = f.format == PtmFormat::kRGB ? 3 : 1;
  const CoefficientMap decoded = decode_ptm(f);
  for (const Eigen::Vector3d& light : geodesic_dome(2)) {
    if (light.z() <= 0) continue;
    const Eigen::Vector3d l = light.normalized();
    const auto basis = ptm_basis(l.x(), l.y());
    for (int y = 0; y < f.height; ++y) {
      for (int x = 0; x < f.width; ++x) {
        float ref[3], exact[3];
        map.evaluate(x, y, l.x(), l.y(), ref);
        decoded.evaluate(x, y, l.x(), l.y(), exact);
        double poly[3] = {0, 0, 0};
        for (int p = 0; p < planes; ++p) {
          for (int i = 0; i < kPtmTerms; ++i) {
            // C's conversion: toward zero.
            const int c = static_cast<int>(
                static_cast<float>(f.coeff_byte(x, y, p, i) - q.biases[i]) * q.scales[i]);
            poly[p] += c * basis[i];
          }
        }
        for (int c = 0; c < 3; ++c) {
          const double t =
              f.format == PtmFormat::kRGB ? poly[c] : poly[0] / 255.0 * f.rgb_byte(x, y, c);
          const double r = std::clamp(255.0 * ref[c], 0.0, 255.0);
          const double tr = std::clamp(t, 0.0, 255.0);
          e.exact_abs += std::abs(std::clamp(255.0 * exact[c], 0.0, 255.0) - r);
          e.trunc_signed += tr - r;
          e.trunc_abs += std::abs(tr - r);
          ++e.n;
        }
      }
    }
  }
  const double n = static_cast<double>(e.n);
  e.exact_abs /= n;
  e.trunc_signed /= n;
  e.trunc_abs /= n;
  return e;
}

}  // namespace

int main(int argc, char** argv) {
  if (argc < 2) {
    std::fprintf(stderr, "usage: ptm_truncation FILE.ptm...\n");
    return 2;
  }
  try {
    std::printf("%-28s %-8s %-40s %10s %12s %10s\n", "file", "scales", "scales a0..a5", "exact|d|",
                "trunc mean d", "trunc|d|");
    for (int a = 1; a < argc; ++a) {
      std::vector<std::pair<std::string, CoefficientMap>> maps;
      const std::string arg = argv[a];
      if (arg.size() > 3 && arg.substr(arg.size() - 3) == ".lp") {
        for (const ColourModel model : {ColourModel::kRGB, ColourModel::kLRGB}) {
          CoefficientMap map;
          CoefficientMapSink sink(&map);
          fit::FitOptions options;
          options.model = model;
          (void)fit::fit_capture(read_lp(arg), options, sink);
          maps.emplace_back(arg + (model == ColourModel::kRGB ? " rgb" : " lrgb"), std::move(map));
        }
      } else {
        maps.emplace_back(arg, read_ptm(arg));
      }
      for (const auto& [label, map] : maps)
        for (const bool integer : {false, true}) {
          PtmWriteOptions o;
          o.integer_scales = integer;
          o.report_max_texels = 0;
          const PtmFile f = encode_ptm(map, o);
          const Errors e = measure(map, f);
          char sc[64];
          const auto& s = f.quantisation.scales;
          std::snprintf(sc, sizeof sc, "%.3g %.3g %.3g %.3g %.3g %.3g", s[0], s[1], s[2], s[3],
                        s[4], s[5]);
          std::string name = label;
          if (name.size() > 28) name = "..." + name.substr(name.size() - 25);
          std::printf("%-28s %-8s %-40s %10.3f %12.3f %10.3f\n", name.c_str(),
                      integer ? "integer" : "finest", sc, e.exact_abs, e.trunc_signed, e.trunc_abs);
        }
    }
  } catch (const std::exception& e) {
    std::fprintf(stderr, "ptm_truncation: %s\n", e.what());
    return 1;
  }
  return 0;
}
