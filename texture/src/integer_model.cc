#include "ptmkit/texture/integer_model.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>
#include <limits>

#include "ptmkit/core/holdout.h"
#include "ptmkit/texture/relight.h"

namespace ptmkit::texture {

IntegerLight quantise_light(double lu, double lv, double lz) {
  IntegerLight l;
  l.above = lz > 0.0;
  auto q = [](double v) {
    return static_cast<int>(std::clamp(std::lround(128.0 * v), -127L, 127L));
  };
  l.lu_q = q(lu);
  l.lv_q = q(lv);
  // 8x8 multipliers, 16-bit products rounded back to 8 bits (arithmetic shift: round half up).
  l.basis[0] = (l.lu_q * l.lu_q + 64) >> 7;
  l.basis[1] = (l.lv_q * l.lv_q + 64) >> 7;
  l.basis[2] = (l.lu_q * l.lv_q + 64) >> 7;
  l.basis[3] = l.lu_q;
  l.basis[4] = l.lv_q;
  l.basis[5] = 128;
  return l;
}

namespace {

// Shift of a group sum into the accumulator (F = 8 fraction bits): the group's value is
// G / 2^(7 + s), so the shift right is k = 7 + s - 8.
struct Aligner {
  int k = 0;
  std::int32_t round = 0;
  std::int32_t mul = 1;
  explicit Aligner(int shift) : k(shift + 7 - kAccumulatorFraction) {
    if (k > 0) round = std::int32_t{1} << (k - 1);
    if (k < 0) mul = std::int32_t{1} << (-k);
  }
  [[nodiscard]] std::int32_t operator()(std::int32_t g) const {
    return k > 0 ? (g + round) >> k : g * mul;
  }
};

int coefficient(std::uint8_t byte) {
  return std::clamp(static_cast<int>(byte) - kPtm8Bias, -127, 127);
}

std::uint8_t modulate(std::int32_t acc, std::uint8_t k) {
  const std::int64_t a = std::clamp<std::int32_t>(acc, 0, (1 << 18) - 1);
  return static_cast<std::uint8_t>(std::min<std::int64_t>(255, (a * k + 32640) / 65280));
}

}  // namespace

std::int32_t integer_accumulator(const std::uint8_t bytes[kPtmTerms],
                                 const std::array<int, 3>& shifts, const IntegerLight& light) {
  std::int32_t p[kPtmTerms];
  for (int i = 0; i < kPtmTerms; ++i) p[i] = coefficient(bytes[i]) * light.basis[i];
  const std::int32_t g[3] = {p[0] + p[1] + p[2], p[3] + p[4], p[5]};
  std::int32_t acc = 0;
  for (int k = 0; k < 3; ++k) acc += Aligner(shifts[k])(g[k]);
  return acc;
}

std::uint8_t integer_output(std::int32_t accumulator) {
  return static_cast<std::uint8_t>(std::clamp((accumulator + 128) >> 8, 0, 255));
}

void integer_evaluate(const std::uint8_t* coeffs, const std::uint8_t* colour, ColourModel model,
                      const std::array<int, 3>& shifts, const IntegerLight& light,
                      std::uint8_t rgb[3]) {
  if (!light.above) {
    rgb[0] = rgb[1] = rgb[2] = 0;
    return;
  }
  if (model == ColourModel::kLRGB) {
    const std::int32_t a = integer_accumulator(coeffs, shifts, light);
    for (int c = 0; c < 3; ++c) rgb[c] = modulate(a, colour[c]);
    return;
  }
  for (int c = 0; c < 3; ++c)
    rgb[c] = integer_output(integer_accumulator(coeffs + c * kPtmTerms, shifts, light));
}

void integer_texel_reference(const Ptm8Texture& t, int x, int y, const IntegerLight& light,
                             std::uint8_t rgb[3]) {
  integer_evaluate(t.texel(x, y), t.model == ColourModel::kLRGB ? t.texel_colour(x, y) : nullptr,
                   t.model, t.shifts, light, rgb);
}

std::vector<std::uint8_t> relight_integer_bytes(const Ptm8Texture& t,
                                                const Eigen::Vector3d& light_dir) {
  const Eigen::Vector3d l = normalised_light(light_dir);
  std::vector<std::uint8_t> out(t.texels() * 3, 0);
  const IntegerLight il = quantise_light(l.x(), l.y(), l.z());
  if (!il.above || out.empty()) return out;
  // Per-light product tables: table[i][byte] = c(byte) * B_i, the same exact products as the
  // reference; the low group is c(byte) * 128.
  std::array<std::array<std::int32_t, 256>, kPtmTerms> table{};
  for (int i = 0; i < kPtmTerms; ++i)
    for (int b = 0; b < 256; ++b)
      table[i][b] = coefficient(static_cast<std::uint8_t>(b)) * il.basis[i];
  const Aligner ah(t.shifts[0]), am(t.shifts[1]), al(t.shifts[2]);
  const int np = t.polynomials();
  const bool lrgb = t.model == ColourModel::kLRGB;
  tbb::parallel_for(tbb::blocked_range<int>(0, t.height), [&](const tbb::blocked_range<int>& r) {
    for (int y = r.begin(); y < r.end(); ++y) {
      const std::uint8_t* src = t.texel(0, y);
      std::uint8_t* dst = out.data() + static_cast<std::size_t>(y) * t.width * 3;
      for (int x = 0; x < t.width; ++x, src += np * kPtmTerms, dst += 3) {
        std::int32_t acc[3];
        for (int p = 0; p < np; ++p) {
          const std::uint8_t* b = src + p * kPtmTerms;
          acc[p] = ah(table[0][b[0]] + table[1][b[1]] + table[2][b[2]]) +
                   am(table[3][b[3]] + table[4][b[4]]) + al(table[5][b[5]]);
        }
        if (lrgb) {
          const std::uint8_t* k = t.colour.data() + (static_cast<std::size_t>(y) * t.width + x) * 3;
          for (int c = 0; c < 3; ++c) dst[c] = modulate(acc[0], k[c]);
        } else {
          for (int c = 0; c < 3; ++c) dst[c] = integer_output(acc[c]);
        }
      }
    }
  });
  return out;
}

Image relight_integer(const Ptm8Texture& t, const Eigen::Vector3d& light_dir) {
  const std::vector<std::uint8_t> bytes = relight_integer_bytes(t, light_dir);
  Image img(t.width, t.height, 3, t.colour_space);
  for (std::size_t i = 0; i < bytes.size(); ++i)
    img.data()[i] = static_cast<float>(bytes[i] / 255.0);
  return img;
}

double integer_error_bound_grey(const double coeffs_grey[kPtmTerms],
                                const std::array<int, 3>& shifts, double lu, double lv) {
  const double lz2 = 1.0 - lu * lu - lv * lv;
  const IntegerLight il = quantise_light(lu, lv, lz2 > 0 ? 1.0 : 0.0);
  const auto exact = ptm_basis(lu, lv);
  double bound = 0.5 + 3.0 * std::ldexp(1.0, -9);
  for (int i = 0; i < kPtmTerms; ++i) {
    const double bq = il.basis[i] / 128.0;
    const double step = std::ldexp(1.0, -shifts[ptm8_group(i)]);
    bound += 0.5 * step * std::abs(bq) + std::abs(coeffs_grey[i]) * std::abs(exact[i] - bq);
  }
  return bound;
}

IntegerErrorReport integer_vs_float(const CoefficientMap& map,
                                    const std::vector<Eigen::Vector3d>& lights) {
  const Ptm8Texture t = quantise_ptm8(map);
  IntegerErrorReport rep;
  double sum_abs = 0, sum_sq = 0;
  for (const auto& l : lights) {
    const Image ref = relight(map, l);
    const std::vector<std::uint8_t> got = relight_integer_bytes(t, l);
    for (std::size_t i = 0; i < got.size(); ++i) {
      const double d = std::abs(got[i] - 255.0 * ref.data()[i]);
      sum_abs += d;
      sum_sq += d * d;
      rep.max_abs_grey = std::max(rep.max_abs_grey, d);
    }
    rep.samples += got.size();
  }
  if (rep.samples > 0) {
    const double n = static_cast<double>(rep.samples);
    rep.mean_abs_grey = sum_abs / n;
    rep.psnr_db = psnr_db(sum_sq / n, 255.0);
  }
  return rep;
}

}  // namespace ptmkit::texture
