#include "ptmkit/texture/ptm8.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <limits>
#include <nlohmann/json.hpp>
#include <sstream>
#include <system_error>

#include "ptmkit/core/atomic_file.h"
#include "ptmkit/core/colour.h"
#include "ptmkit/core/error.h"
#include "ptmkit/core/holdout.h"
#include "ptmkit/core/image_io.h"
#include "ptmkit/core/json_file.h"
#include "ptmkit/core/light_layout.h"
#include "ptmkit/texture/integer_model.h"
#include "ptmkit/texture/ptm.h"
#include "ptmkit/texture/relight.h"

namespace fs = std::filesystem;

namespace ptmkit::texture {

double Ptm8Texture::step_grey(int group) const { return std::ldexp(1.0, -shifts[group]); }

int choose_ptm8_shift(double max_abs_grey) {
  if (!(max_abs_grey > 0.0)) return kPtm8MaxShift;
  for (int s = kPtm8MaxShift; s > kPtm8MinShift; --s) {
    if (std::round(max_abs_grey * std::ldexp(1.0, s)) <= 127.0) return s;
  }
  return kPtm8MinShift;  // larger values saturate at +-127 (documented range of shifts)
}

CoefficientMap to_rgb_polynomials(const CoefficientMap& map) {
  if (map.model != ColourModel::kYCC) return map;
  CoefficientMap out(map.width, map.height, ColourModel::kRGB, map.colour_space);
  for (int y = 0; y < map.height; ++y) {
    for (int x = 0; x < map.width; ++x) {
      const float* a = map.texel_coeffs(x, y);
      const float* cc = map.texel_colour(x, y);
      double r = 0, g = 0, b = 0;
      from_ycbcr({a[5], cc[0], cc[1]}, &r, &g, &b);
      const double a5[3] = {r, g, b};
      float* o = out.texel_coeffs(x, y);
      for (int p = 0; p < 3; ++p) {
        for (int i = 0; i < 5; ++i) o[p * kPtmTerms + i] = a[i];
        o[p * kPtmTerms + 5] = static_cast<float>(a5[p]);
      }
    }
  }
  return out;
}

namespace {

std::uint8_t to_byte(double v) {
  return static_cast<std::uint8_t>(std::clamp(std::lround(v), 0L, 255L));
}

}  // namespace

Ptm8Texture quantise_ptm8(const CoefficientMap& input) {
  const CoefficientMap map = to_rgb_polynomials(input);
  Ptm8Texture t;
  t.width = map.width;
  t.height = map.height;
  t.model = map.model;
  t.colour_space = map.colour_space;
  const int np = t.polynomials();
  const std::size_t n = t.texels();
  // LRGB: renormalise the colour so its largest channel is 1 (the luminance takes the rest).
  std::vector<double> lscale(map.model == ColourModel::kLRGB ? n : 0, 1.0);
  if (map.model == ColourModel::kLRGB) {
    t.colour.resize(n * 3);
    for (std::size_t i = 0; i < n; ++i) {
      const float* c = map.colour.data() + i * 3;
      const double m = std::max({c[0], c[1], c[2], 0.0f});
      lscale[i] = m;
      for (int k = 0; k < 3; ++k) t.colour[i * 3 + k] = m > 0 ? to_byte(255.0 * c[k] / m) : 0;
    }
  }
  std::array<double, 3> max_abs{0, 0, 0};
  for (std::size_t i = 0; i < n; ++i) {
    const double scale = 255.0 * (lscale.empty() ? 1.0 : lscale[i]);
    for (int p = 0; p < np; ++p) {
      for (int k = 0; k < kPtmTerms; ++k) {
        const double a = map.coeffs[(i * np + p) * kPtmTerms + k] * scale;
        max_abs[ptm8_group(k)] = std::max(max_abs[ptm8_group(k)], std::abs(a));
      }
    }
  }
  for (int g = 0; g < 3; ++g) t.shifts[g] = choose_ptm8_shift(max_abs[g]);
  t.coeffs.resize(n * np * kPtmTerms);
  for (std::size_t i = 0; i < n; ++i) {
    const double scale = 255.0 * (lscale.empty() ? 1.0 : lscale[i]);
    for (int p = 0; p < np; ++p) {
      for (int k = 0; k < kPtmTerms; ++k) {
        const std::size_t j = (i * np + p) * kPtmTerms + k;
        const double a = map.coeffs[j] * scale;
        const long q =
            std::clamp(std::lround(a * std::ldexp(1.0, t.shifts[ptm8_group(k)])), -127L, 127L);
        t.coeffs[j] = static_cast<std::uint8_t>(q + kPtm8Bias);
      }
    }
  }
  return t;
}

CoefficientMap dequantise_ptm8(const Ptm8Texture& t) {
  CoefficientMap map(t.width, t.height, t.model, t.colour_space);
  std::array<double, 3> step{};
  for (int g = 0; g < 3; ++g) step[g] = t.step_grey(g) / 255.0;
  const int np = t.polynomials();
  for (std::size_t j = 0; j < map.coeffs.size(); ++j) {
    const int k = static_cast<int>(j % kPtmTerms);
    map.coeffs[j] = static_cast<float>(
        std::clamp(static_cast<int>(t.coeffs[j]) - kPtm8Bias, -127, 127) * step[ptm8_group(k)]);
  }
  (void)np;
  for (std::size_t j = 0; j < t.colour.size(); ++j)
    map.colour[j] = static_cast<float>(t.colour[j] / 255.0);
  return map;
}

// ---------------------------------------------------------------------------------------------
// Container

namespace {

Image bytes_to_image(const std::vector<std::uint8_t>& src, int w, int h, int stride, int offset) {
  Image img(w, h, 3, ColourSpace::kLinear);
  const std::size_t n = static_cast<std::size_t>(w) * h;
  for (std::size_t i = 0; i < n; ++i)
    for (int c = 0; c < 3; ++c)
      img.data()[i * 3 + c] = static_cast<float>(src[i * stride + offset + c] / 255.0);
  return img;
}

void image_to_bytes(const Image& img, std::vector<std::uint8_t>& dst, int stride, int offset,
                    const fs::path& file, int w, int h) {
  if (img.width() != w || img.height() != h || img.channels() < 3) {
    throw Error(where(file) + ": expected a " + std::to_string(w) + " x " + std::to_string(h) +
                " RGB image, found " + std::to_string(img.width()) + " x " +
                std::to_string(img.height()) + " with " + std::to_string(img.channels()) +
                " channels");
  }
  const std::size_t n = static_cast<std::size_t>(w) * h;
  const int ch = img.channels();
  for (std::size_t i = 0; i < n; ++i)
    for (int c = 0; c < 3; ++c)
      dst[i * stride + offset + c] = to_byte(img.data()[i * ch + c] * 255.0);
}

}  // namespace

void write_ptm8(const fs::path& folder, const Ptm8Texture& t) {
  if (t.width <= 0 || t.height <= 0) throw Error(where(folder) + ": empty texture");
  fs::path target = folder;
  if (target.filename().empty()) target = target.parent_path();
  std::error_code ec;
  if (fs::exists(target, ec) && !fs::exists(target / "manifest.json", ec)) {
    throw Error(where(target) + ": exists and is not a .ptm8 container; not replacing it");
  }
  // The files are assembled in a staged folder, put in place as a whole at the end.
  StagedFolder tmp(target, ".ptm8");
  nlohmann::json j;
  j["format"] = "ptmkit-ptm8";
  j["version"] = 1;
  j["width"] = t.width;
  j["height"] = t.height;
  j["model"] = t.model == ColourModel::kRGB ? "rgb" : "lrgb";
  j["colour_space"] = t.colour_space == ColourSpace::kSRGB ? "srgb" : "linear";
  j["bias"] = kPtm8Bias;
  j["shifts"] = {{"high", t.shifts[0]}, {"mid", t.shifts[1]}, {"low", t.shifts[2]}};
  j["planes"] = nlohmann::json::array();
  const int np = t.polynomials();
  ImageWriteOptions wo;
  wo.format = PixelFormat::kU8;
  for (int p = 0; p < np; ++p) {
    std::string a = "p";
    a += std::to_string(p);
    std::string b = a;
    a += "_a012.png";
    b += "_a345.png";
    write_image(tmp.path() / a,
                bytes_to_image(t.coeffs, t.width, t.height, np * kPtmTerms, p * kPtmTerms).view(),
                wo);
    write_image(
        tmp.path() / b,
        bytes_to_image(t.coeffs, t.width, t.height, np * kPtmTerms, p * kPtmTerms + 3).view(), wo);
    j["planes"].push_back({{"a012", a}, {"a345", b}});
  }
  if (t.model == ColourModel::kLRGB) {
    write_image(tmp.path() / "colour.png", bytes_to_image(t.colour, t.width, t.height, 3, 0).view(),
                wo);
    j["colour"] = "colour.png";
  }
  write_file_atomic(tmp.path() / "manifest.json", j.dump(2) + "\n");
  tmp.commit();
}

Ptm8Texture read_ptm8(const fs::path& folder) {
  const fs::path manifest = folder / "manifest.json";
  std::ifstream in(manifest);
  if (!in) throw Error(where(manifest) + ": cannot open (is this a .ptm8 container?)");
  nlohmann::json j;
  try {
    in >> j;
  } catch (const std::exception& e) {
    throw Error(where(manifest) + ": not valid JSON: " + e.what());
  }
  Ptm8Texture t;
  try {
    constexpr long long kIntMin = std::numeric_limits<int>::min();
    constexpr long long kIntMax = std::numeric_limits<int>::max();
    if (j.at("format").get<std::string>() != "ptmkit-ptm8" ||
        json_int(j, "version", kIntMin, kIntMax, "manifest") != 1)
      throw Error("not a version 1 ptmkit-ptm8 manifest");
    t.width = json_int(j, "width", kIntMin, kIntMax, "manifest");
    t.height = json_int(j, "height", kIntMin, kIntMax, "manifest");
    if (t.width <= 0 || t.height <= 0 || t.width > (1 << 20) || t.height > (1 << 20))
      throw Error("bad size");
    const std::string model = j.at("model").get<std::string>();
    if (model != "rgb" && model != "lrgb") throw Error("model must be rgb or lrgb");
    t.model = model == "rgb" ? ColourModel::kRGB : ColourModel::kLRGB;
    t.colour_space = j.at("colour_space").get<std::string>() == "linear" ? ColourSpace::kLinear
                                                                         : ColourSpace::kSRGB;
    if (json_int(j, "bias", kIntMin, kIntMax, "manifest") != kPtm8Bias)
      throw Error("bias must be 127");
    const auto& s = j.at("shifts");
    t.shifts = {json_int(s, "high", kIntMin, kIntMax, "shifts"),
                json_int(s, "mid", kIntMin, kIntMax, "shifts"),
                json_int(s, "low", kIntMin, kIntMax, "shifts")};
    for (int v : t.shifts)
      if (v < kPtm8MinShift || v > kPtm8MaxShift) throw Error("shift out of range -8..24");
    if (static_cast<int>(j.at("planes").size()) != t.polynomials())
      throw Error("wrong number of planes for the model");
  } catch (const Error& e) {
    throw Error(where(manifest) + ": " + e.what());
  } catch (const std::exception& e) {
    throw Error(where(manifest) + ": missing or malformed field: " + e.what());
  }
  const int np = t.polynomials();
  t.coeffs.resize(t.texels() * np * kPtmTerms);
  for (int p = 0; p < np; ++p) {
    const auto& pl = j["planes"][static_cast<std::size_t>(p)];
    const fs::path a = folder / pl.value("a012", std::string());
    const fs::path b = folder / pl.value("a345", std::string());
    image_to_bytes(read_image(a), t.coeffs, np * kPtmTerms, p * kPtmTerms, a, t.width, t.height);
    image_to_bytes(read_image(b), t.coeffs, np * kPtmTerms, p * kPtmTerms + 3, b, t.width,
                   t.height);
  }
  if (t.model == ColourModel::kLRGB) {
    t.colour.resize(t.texels() * 3);
    const fs::path c = folder / j.value("colour", std::string("colour.png"));
    image_to_bytes(read_image(c), t.colour, 3, 0, c, t.width, t.height);
  }
  return t;
}

// ---------------------------------------------------------------------------------------------
// Comparison of the schemes

namespace {

struct ErrorAccumulator {
  double sum_abs = 0, sum_sq = 0, max_abs = 0;
  std::size_t n = 0;
  void add(double test_grey, double ref_grey) {
    const double d = std::abs(test_grey - ref_grey);
    sum_abs += d;
    sum_sq += d * d;
    max_abs = std::max(max_abs, d);
    ++n;
  }
  [[nodiscard]] SchemeError result() const {
    SchemeError e;
    if (n == 0) return e;
    e.mean_abs_grey = sum_abs / static_cast<double>(n);
    e.max_abs_grey = max_abs;
    const double mse = sum_sq / static_cast<double>(n);
    e.psnr_db = psnr_db(mse, 255.0);
    return e;
  }
};

}  // namespace

QuantisationComparison compare_quantisations(const CoefficientMap& map,
                                             std::vector<Eigen::Vector3d> lights) {
  if (lights.empty()) lights = geodesic_dome(2);
  QuantisationComparison out;
  PtmWriteOptions po;
  po.report_max_texels = 0;
  const CoefficientMap ptm_map = decode_ptm(encode_ptm(map, po), map.colour_space);
  const Ptm8Texture t8 = quantise_ptm8(map);
  const CoefficientMap ptm8_map = dequantise_ptm8(t8);
  out.shifts = t8.shifts;
  ErrorAccumulator ep, e8, ei;
  for (const auto& l : lights) {
    const Image ref = relight(map, l);
    const Image a = relight(ptm_map, l);
    const Image b = relight(ptm8_map, l);
    const std::vector<std::uint8_t> c = relight_integer_bytes(t8, l);
    for (std::size_t i = 0; i < ref.size(); ++i) {
      const double r = 255.0 * ref.data()[i];
      ep.add(255.0 * a.data()[i], r);
      e8.add(255.0 * b.data()[i], r);
      ei.add(c[i], r);
    }
  }
  out.ptm = ep.result();
  out.ptm8 = e8.result();
  out.integer = ei.result();
  out.samples = ep.n;
  return out;
}

std::string QuantisationComparison::brief() const {
  char buf[512];
  std::snprintf(buf, sizeof buf,
                ".ptm scale/bias: mean %.3f max %.3f grey, PSNR %.2f dB; paper shifts (%d,%d,%d) "
                "float: mean %.3f max %.3f, PSNR %.2f dB; integer model: mean %.3f max %.3f, "
                "PSNR %.2f dB",
                ptm.mean_abs_grey, ptm.max_abs_grey, ptm.psnr_db, shifts[0], shifts[1], shifts[2],
                ptm8.mean_abs_grey, ptm8.max_abs_grey, ptm8.psnr_db, integer.mean_abs_grey,
                integer.max_abs_grey, integer.psnr_db);
  return buf;
}

}  // namespace ptmkit::texture
