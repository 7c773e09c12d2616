#include "ptmkit/texture/filtering.h"

#include <algorithm>
#include <cmath>

namespace ptmkit::texture {

std::size_t CoefficientPyramid::total_texels() const {
  std::size_t n = 0;
  for (const auto& l : levels) n += static_cast<std::size_t>(l.width) * l.height;
  return n;
}

int CoefficientPyramid::values_per_texel() const {
  if (levels.empty()) return 0;
  return levels[0].polynomials() * kPtmTerms + levels[0].colours();
}

namespace {

// 2x2 box over interleaved floats (n per texel), ceil sizes.
std::vector<float> box_half(const float* src, int w, int h, int n, int* ow, int* oh) {
  *ow = (w + 1) / 2;
  *oh = (h + 1) / 2;
  std::vector<float> out(static_cast<std::size_t>(*ow) * *oh * n, 0.0f);
  for (int y = 0; y < *oh; ++y)
    for (int x = 0; x < *ow; ++x) {
      const int x1 = std::min(2 * x + 1, w - 1), y1 = std::min(2 * y + 1, h - 1);
      const int count = (x1 - 2 * x + 1) * (y1 - 2 * y + 1);
      float* o = out.data() + (static_cast<std::size_t>(y) * *ow + x) * n;
      for (int k = 0; k < n; ++k) {
        double s = 0.0;
        for (int yy = 2 * y; yy <= y1; ++yy)
          for (int xx = 2 * x; xx <= x1; ++xx)
            s += src[(static_cast<std::size_t>(yy) * w + xx) * n + k];
        o[k] = static_cast<float>(s / count);
      }
    }
  return out;
}

}  // namespace

CoefficientPyramid build_pyramid(const CoefficientMap& map) {
  CoefficientPyramid p;
  p.levels.push_back(map);
  while (p.levels.back().width > 1 || p.levels.back().height > 1) {
    const CoefficientMap& prev = p.levels.back();
    CoefficientMap next;
    next.model = prev.model;
    next.colour_space = prev.colour_space;
    const int nc = prev.polynomials() * kPtmTerms;
    next.coeffs =
        box_half(prev.coeffs.data(), prev.width, prev.height, nc, &next.width, &next.height);
    if (prev.colours() > 0) {
      int w = 0, h = 0;
      next.colour = box_half(prev.colour.data(), prev.width, prev.height, prev.colours(), &w, &h);
    }
    p.levels.push_back(std::move(next));
  }
  return p;
}

Image downsample_box(const Image& image) {
  int w = 0, h = 0;
  std::vector<float> px =
      box_half(image.data(), image.width(), image.height(), image.channels(), &w, &h);
  Image out(w, h, image.channels(), image.colour_space());
  std::copy(px.begin(), px.end(), out.data());
  return out;
}

std::vector<Ptm8Texture> quantise_pyramid(const CoefficientPyramid& pyramid) {
  std::vector<Ptm8Texture> out;
  for (const auto& l : pyramid.levels) out.push_back(quantise_ptm8(l));
  return out;
}

namespace {

void bilinear(const CoefficientMap& m, double x, double y, float weight, float* out) {
  const int nc = m.polynomials() * kPtmTerms, ncol = m.colours();
  const double fx = std::clamp(x - 0.5, 0.0, m.width - 1.0);
  const double fy = std::clamp(y - 0.5, 0.0, m.height - 1.0);
  const int x0 = static_cast<int>(fx), y0 = static_cast<int>(fy);
  const int x1 = std::min(x0 + 1, m.width - 1), y1 = std::min(y0 + 1, m.height - 1);
  const double tx = fx - x0, ty = fy - y0;
  const int xs[2] = {x0, x1}, ys[2] = {y0, y1};
  const double ws[4] = {(1 - tx) * (1 - ty), tx * (1 - ty), (1 - tx) * ty, tx * ty};
  for (int j = 0; j < 4; ++j) {
    const double wgt = ws[j] * weight;
    if (wgt == 0.0) continue;
    const float* c = m.texel_coeffs(xs[j & 1], ys[j >> 1]);
    for (int k = 0; k < nc; ++k) out[k] += static_cast<float>(wgt * c[k]);
    if (ncol > 0) {
      const float* col = m.texel_colour(xs[j & 1], ys[j >> 1]);
      for (int k = 0; k < ncol; ++k) out[nc + k] += static_cast<float>(wgt * col[k]);
    }
  }
}

}  // namespace

void sample_trilinear(const CoefficientPyramid& pyramid, double x, double y, double lod,
                      float* out) {
  const int n = pyramid.values_per_texel();
  std::fill(out, out + n, 0.0f);
  const int last = static_cast<int>(pyramid.levels.size()) - 1;
  if (!(lod > 0.0)) lod = 0.0;
  lod = std::min(lod, static_cast<double>(last));
  const int l0 = static_cast<int>(std::floor(lod));
  const double t = lod - l0;
  auto sample_level = [&](int level, double w) {
    // Level sizes are ceil-halved; coordinates scale with the level's actual size.
    const CoefficientMap& m = pyramid.levels[static_cast<std::size_t>(level)];
    const double sx = static_cast<double>(m.width) / pyramid.levels[0].width;
    const double sy = static_cast<double>(m.height) / pyramid.levels[0].height;
    bilinear(m, x * sx, y * sy, static_cast<float>(w), out);
  };
  sample_level(l0, 1.0 - t);
  if (t > 0.0 && l0 < last) sample_level(l0 + 1, t);
}

SummedAreaTable::SummedAreaTable(const std::uint8_t* data, int width, int height, int channels)
    : width_(width), height_(height), channels_(channels) {
  table_.assign(static_cast<std::size_t>(width + 1) * (height + 1) * channels, 0);
  std::vector<std::int64_t> row(static_cast<std::size_t>(channels));
  for (int y = 0; y < height; ++y) {
    std::fill(row.begin(), row.end(), 0);
    const std::uint8_t* src = data + static_cast<std::size_t>(y) * width * channels;
    std::int64_t* above = table_.data() + static_cast<std::size_t>(y) * (width + 1) * channels;
    std::int64_t* cur = above + static_cast<std::size_t>(width + 1) * channels;
    for (int x = 0; x < width; ++x)
      for (int c = 0; c < channels; ++c) {
        row[static_cast<std::size_t>(c)] += src[static_cast<std::size_t>(x) * channels + c];
        const std::size_t i = static_cast<std::size_t>(x + 1) * channels + c;
        cur[i] = above[i] + row[static_cast<std::size_t>(c)];
      }
  }
}

namespace {
std::vector<std::uint8_t> interleave(const Ptm8Texture& t) {
  const int nc = t.polynomials() * kPtmTerms;
  const int ncol = t.model == ColourModel::kLRGB ? 3 : 0;
  std::vector<std::uint8_t> out(t.texels() * static_cast<std::size_t>(nc + ncol));
  for (std::size_t i = 0; i < t.texels(); ++i) {
    std::copy_n(t.coeffs.data() + i * nc, nc, out.data() + i * (nc + ncol));
    if (ncol) std::copy_n(t.colour.data() + i * 3, 3, out.data() + i * (nc + ncol) + nc);
  }
  return out;
}
}  // namespace

SummedAreaTable::SummedAreaTable(const Ptm8Texture& t)
    : SummedAreaTable(interleave(t).data(), t.width, t.height,
                      t.polynomials() * kPtmTerms + (t.model == ColourModel::kLRGB ? 3 : 0)) {}

std::int64_t SummedAreaTable::sum(int c, int x0, int y0, int x1, int y1) const {
  x0 = std::clamp(x0, 0, width_);
  x1 = std::clamp(x1, 0, width_);
  y0 = std::clamp(y0, 0, height_);
  y1 = std::clamp(y1, 0, height_);
  if (x1 <= x0 || y1 <= y0) return 0;
  return at(x1, y1, c) - at(x0, y1, c) - at(x1, y0, c) + at(x0, y0, c);
}

void SummedAreaTable::mean(int x0, int y0, int x1, int y1, double* out) const {
  x0 = std::clamp(x0, 0, width_ - 1);
  y0 = std::clamp(y0, 0, height_ - 1);
  x1 = std::clamp(x1, x0 + 1, width_);
  y1 = std::clamp(y1, y0 + 1, height_);
  const double area = static_cast<double>(x1 - x0) * (y1 - y0);
  for (int c = 0; c < channels_; ++c) out[c] = static_cast<double>(sum(c, x0, y0, x1, y1)) / area;
}

void sat_coefficients(const SummedAreaTable& sat, const Ptm8Texture& t, int x0, int y0, int x1,
                      int y1, float* out) {
  std::vector<double> m(static_cast<std::size_t>(sat.channels()));
  sat.mean(x0, y0, x1, y1, m.data());
  const int nc = t.polynomials() * kPtmTerms;
  for (int k = 0; k < nc; ++k) {
    const int g = ptm8_group(k % kPtmTerms);
    out[k] =
        static_cast<float>((m[static_cast<std::size_t>(k)] - kPtm8Bias) * t.step_grey(g) / 255.0);
  }
  for (int k = nc; k < sat.channels(); ++k)
    out[k] = static_cast<float>(m[static_cast<std::size_t>(k)] / 255.0);
}

}  // namespace ptmkit::texture
