// .ptm reading, writing, quantisation and streaming.
#include <gmock/gmock.h>
#include <gtest/gtest.h>
#include <sys/stat.h>

#include <cmath>
#include <cstdio>
#include <fstream>
#include <sstream>
#include <stdexcept>
#include <string>
#include <vector>

#include "ptmkit/core/colour.h"
#include "ptmkit/core/error.h"
#include "ptmkit/core/light_layout.h"
#include "ptmkit/texture/ptm.h"
#include "ptmkit/texture/relight.h"
#include "test_util.h"

namespace fs = std::filesystem;

namespace ptmkit::texture {
namespace {

using Bytes = std::vector<std::uint8_t>;

Bytes read_bytes(const fs::path& p) {
  std::ifstream in(p, std::ios::binary);
  return Bytes(std::istreambuf_iterator<char>(in), {});
}

void write_bytes(const fs::path& p, const std::string& header, const Bytes& data) {
  std::ofstream out(p, std::ios::binary);
  out << header;
  out.write(reinterpret_cast<const char*>(data.data()), static_cast<std::streamsize>(data.size()));
}

// A smooth map with realistic coefficient ranges (normalised units): a5 in [0.2, 0.8],
// a3, a4 within +-0.3, a0..a2 within +-0.15; colours with largest channel 1 (LRGB) or chroma
// within +-0.1 (YCC). Not symmetric in x or y.
CoefficientMap smooth_map(int w, int h, ColourModel model) {
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
double max_relit_difference_grey(const CoefficientMap& a, const CoefficientMap& b) {
  double worst = 0.0;
  for (const auto& l : geodesic_dome(2)) {
    const Image ia = relight(a, l), ib = relight(b, l);
    for (std::size_t k = 0; k < ia.size(); ++k) {
      worst = std::max(worst, 255.0 * std::abs(static_cast<double>(ia.data()[k] - ib.data()[k])));
    }
  }
  return worst;
}

// Worst-case relit error from rounding every coefficient by half a step: sum_i s_i / 2 times
// the largest |basis_i| over the unit disc (1 for lu^2, lv^2, lu, lv, 1; 1/2 for lu lv),
// in grey levels (file units are grey levels).
double half_step_bound_grey(const PtmQuantisation& q) {
  const double basis_max[kPtmTerms] = {1.0, 1.0, 0.5, 1.0, 1.0, 1.0};
  double bound = 0.0;
  for (int i = 0; i < kPtmTerms; ++i) bound += 0.5 * std::abs(q.scales[i]) * basis_max[i];
  return bound;
}

// ---------------------------------------------------------------------------------------------

TEST(PtmRead, HandWrittenRgbFileDecodesBottomUp) {
  test::ScratchDir dir;
  const int w = 3, h = 2;  // non-square, every byte distinct: a flipped row order shows
  const std::string header = "PTM_1.2\nPTM_FORMAT_RGB\n3\n2\n2 1 1 1 1 0.5\n10 0 0 0 0 0\n";
  Bytes data(static_cast<std::size_t>(w) * h * 18);
  auto stored = [&](int plane, int stored_row, int x, int term) {
    return static_cast<std::uint8_t>(plane * 60 + stored_row * 25 + x * 7 + term);
  };
  std::size_t k = 0;
  for (int p = 0; p < 3; ++p)
    for (int sr = 0; sr < h; ++sr)
      for (int x = 0; x < w; ++x)
        for (int i = 0; i < kPtmTerms; ++i) data[k++] = stored(p, sr, x, i);
  const fs::path path = dir / "hand.ptm";
  write_bytes(path, header, data);

  const PtmFile f = read_ptm_file(path);
  EXPECT_EQ(f.format, PtmFormat::kRGB);
  EXPECT_EQ(f.width, 3);
  EXPECT_EQ(f.height, 2);
  EXPECT_EQ(f.header.size(), header.size());
  const CoefficientMap map = decode_ptm(f);
  const double scales[6] = {2, 1, 1, 1, 1, 0.5};
  const int biases[6] = {10, 0, 0, 0, 0, 0};
  for (int y = 0; y < h; ++y) {
    for (int x = 0; x < w; ++x) {
      for (int p = 0; p < 3; ++p) {
        for (int i = 0; i < kPtmTerms; ++i) {
          // Top row (y = 0) is the last stored row.
          const int byte = stored(p, h - 1 - y, x, i);
          EXPECT_EQ(f.coeff_byte(x, y, p, i), byte);
          const double expected = scales[i] * (byte - biases[i]);
          EXPECT_DOUBLE_EQ(f.coefficient(x, y, p, i), expected);
          EXPECT_FLOAT_EQ(map.texel_coeffs(x, y)[p * kPtmTerms + i],
                          static_cast<float>(expected / 255.0));
        }
      }
    }
  }
  // Read -> write is bit-exact.
  write_ptm_file(dir / "copy.ptm", f);
  EXPECT_EQ(read_bytes(dir / "copy.ptm"), read_bytes(path));
}

TEST(PtmRead, HandWrittenLrgbFileDecodes) {
  test::ScratchDir dir;
  const int w = 2, h = 3;
  const std::string header = "PTM_1.2\nPTM_FORMAT_LRGB\n2\n3\n1 1 1 1 1 1\n0 0 0 0 0 0\n";
  Bytes data;
  for (int sr = 0; sr < h; ++sr)
    for (int x = 0; x < w; ++x)
      for (int i = 0; i < kPtmTerms; ++i)
        data.push_back(static_cast<std::uint8_t>(i == 5 ? 100 + 40 * sr + x : 3 * i + sr));
  for (int sr = 0; sr < h; ++sr)
    for (int x = 0; x < w; ++x)
      for (int c = 0; c < 3; ++c) data.push_back(static_cast<std::uint8_t>(200 - 50 * c + sr + x));
  const fs::path path = dir / "lrgb.ptm";
  write_bytes(path, header, data);
  const PtmFile f = read_ptm_file(path);
  ASSERT_EQ(f.format, PtmFormat::kLRGB);
  const CoefficientMap map = decode_ptm(f);
  ASSERT_EQ(map.model, ColourModel::kLRGB);
  // Overhead light: output = L/255 * rgb/255 with L = a5 (file units).
  const Image img = relight(map, {0, 0, 1});
  for (int y = 0; y < h; ++y) {
    for (int x = 0; x < w; ++x) {
      const int sr = h - 1 - y;
      const double l = 100 + 40 * sr + x;
      for (int c = 0; c < 3; ++c) {
        const double rgb = 200 - 50 * c + sr + x;
        EXPECT_EQ(f.rgb_byte(x, y, c), rgb);
        EXPECT_NEAR(img.at(x, y, c), l / 255.0 * rgb / 255.0, 1e-6);
      }
      // The map keeps its convention: largest colour channel is 1.
      EXPECT_FLOAT_EQ(map.texel_colour(x, y)[0], 1.0f);
    }
  }
  write_ptm_file(dir / "copy.ptm", f);
  EXPECT_EQ(read_bytes(dir / "copy.ptm"), read_bytes(path));
}

TEST(PtmRead, Ptm11LrgbInterleaved) {
  test::ScratchDir dir;
  const std::string header = "PTM_1.1\nPTM_FORMAT_LRGB\n2\n1\n1 1 1 1 1 1\n0 0 0 0 0 0\n";
  const Bytes data = {0, 0, 0, 0, 0, 200, 255, 128, 0,     // pixel 0: a5 = 200, orange
                      0, 0, 0, 0, 0, 100, 0,   0,   255};  // pixel 1: a5 = 100, blue
  const fs::path path = dir / "old.ptm";
  write_bytes(path, header, data);
  const PtmFile f = read_ptm_file(path);
  EXPECT_EQ(f.version, PtmVersion::k1_1);
  EXPECT_EQ(f.rgb_byte(0, 0, 1), 128);
  EXPECT_EQ(f.coeff_byte(1, 0, 0, 5), 100);
  const Image img = relight(decode_ptm(f), {0, 0, 1});
  EXPECT_NEAR(img.at(0, 0, 0), 200.0 / 255.0, 1e-6);
  EXPECT_NEAR(img.at(0, 0, 1), 200.0 / 255.0 * 128.0 / 255.0, 1e-6);
  EXPECT_NEAR(img.at(1, 0, 2), 100.0 / 255.0, 1e-6);
  write_ptm_file(dir / "copy.ptm", f);
  EXPECT_EQ(read_bytes(dir / "copy.ptm"), read_bytes(path));
}

TEST(PtmRead, ForeignHeaderSpellingIsToleratedAndKept) {
  test::ScratchDir dir;
  // CRLF, scales split over lines, tabs, trailing spaces, a number spelled 5.0e-1; the first
  // data byte is a newline and the second a space, which must not be taken for header.
  const std::string header =
      "PTM_1.2\r\nPTM_FORMAT_RGB\r\n1  \r\n1\r\n1.0 2\t3\r\n4 5 5.0e-1\r\n0 1 2 3 4 5  \r\n";
  Bytes data(18, 7);
  data[0] = '\n';
  data[1] = ' ';
  const fs::path path = dir / "foreign.ptm";
  write_bytes(path, header, data);
  const PtmFile f = read_ptm_file(path);
  EXPECT_EQ(f.quantisation.scales[5], 0.5f);
  EXPECT_EQ(f.quantisation.biases[5], 5);
  EXPECT_EQ(f.coeff_byte(0, 0, 0, 0), '\n');
  EXPECT_EQ(f.coeff_byte(0, 0, 0, 1), ' ');
  EXPECT_EQ(f.trailing.size(), 0u);
  write_ptm_file(dir / "copy.ptm", f);
  EXPECT_EQ(read_bytes(dir / "copy.ptm"), read_bytes(path));
  const PtmInfo info = read_ptm_info(path);
  EXPECT_EQ(info.header_bytes, header.size());
  EXPECT_EQ(info.trailing_bytes, 0u);

  // Changing a field makes the writer fall back to the canonical header.
  PtmFile changed = f;
  changed.quantisation.biases[0] = 9;
  write_ptm_file(dir / "changed.ptm", changed);
  EXPECT_EQ(read_ptm_file(dir / "changed.ptm").quantisation.biases[0], 9);
}

TEST(PtmWrite, WriteReadWriteIsBitExactForEveryModel) {
  test::ScratchDir dir;
  for (const ColourModel model : {ColourModel::kRGB, ColourModel::kLRGB, ColourModel::kYCC}) {
    SCOPED_TRACE(std::string(to_string(model)));
    const CoefficientMap map = smooth_map(13, 7, model);
    const fs::path a = dir / "a.ptm", b = dir / "b.ptm";
    write_ptm(a, map);
    const PtmFile f = read_ptm_file(a);
    EXPECT_EQ(f.header, f.canonical_header());
    write_ptm_file(b, f);
    EXPECT_EQ(read_bytes(a), read_bytes(b));
    // And once more from the re-written file.
    write_ptm_file(a, read_ptm_file(b));
    EXPECT_EQ(read_bytes(a), read_bytes(b));
  }
}

TEST(PtmWrite, CanonicalHeaderHasOneItemPerLine) {
  test::ScratchDir dir;
  write_ptm(dir / "m.ptm", smooth_map(5, 4, ColourModel::kRGB));
  const Bytes bytes = read_bytes(dir / "m.ptm");
  const std::string text(bytes.begin(), bytes.end());
  EXPECT_EQ(text.rfind("PTM_1.2\nPTM_FORMAT_RGB\n5\n4\n", 0), 0u);
}

TEST(PtmQuantisation, ZeroIsExactAndEndsAreReachable) {
  const std::array<double, kPtmTerms> lo = {-38.0, 0.0, -1e-3, 10.0, -200.0, 0.0};
  const std::array<double, kPtmTerms> hi = {38.0, 0.0, 5.0, 240.0, -20.0, 255.0};
  const PtmQuantisation q = choose_quantisation(lo, hi);
  for (int i = 0; i < kPtmTerms; ++i) {
    SCOPED_TRACE(i);
    EXPECT_GT(q.scales[i], 0.0f);
    EXPECT_GE(q.biases[i], 0);
    EXPECT_LE(q.biases[i], 255);
    const double s = q.scales[i];
    // Both ends of the range (widened to 0) are covered to within half a step.
    EXPECT_LE(s * (0 - q.biases[i]), std::min(lo[i], 0.0) + 0.5 * s);
    EXPECT_GE(s * (255 - q.biases[i]), std::max(hi[i], 0.0) - 0.5 * s);
  }
  // A range of 255 units including 0 needs a step of at most about one unit.
  EXPECT_LE(q.scales[5], 1.0f + 1e-6f);
  EXPECT_EQ(q.biases[5], 0);
  EXPECT_EQ(q.biases[4], 255);  // all negative: zero at the top byte
}

TEST(PtmQuantisation, ConstantMapStaysConstant) {
  CoefficientMap map(6, 5, ColourModel::kRGB);
  for (std::size_t t = 0; t < 30; ++t) {
    for (int p = 0; p < 3; ++p)
      map.coeffs[t * 18 + p * 6 + 5] = 0.25f + 0.2f * static_cast<float>(p);
  }
  PtmWriteReport report;
  const PtmFile f = encode_ptm(map, {}, &report);
  const CoefficientMap back = decode_ptm(f);
  for (std::size_t t = 0; t < 30; ++t) {
    for (int p = 0; p < 3; ++p) {
      for (int i = 0; i < 5; ++i) EXPECT_EQ(back.coeffs[t * 18 + p * 6 + i], 0.0f);
    }
  }
  // Every light gives the same image (no light-dependent wobble from quantised zeros).
  const Image top = relight(back, {0, 0, 1}), side = relight(back, {0.9, -0.3, 0.2});
  for (std::size_t k = 0; k < top.size(); ++k) EXPECT_EQ(top.data()[k], side.data()[k]);
}

TEST(PtmQuantisation, RelitErrorOfSmoothMapIsBelowOneGreyLevel) {
  const CoefficientMap map = smooth_map(64, 48, ColourModel::kRGB);
  PtmWriteReport report;
  const PtmFile f = encode_ptm(map, {}, &report);
  const double bound = half_step_bound_grey(f.quantisation);
  const double measured = max_relit_difference_grey(map, decode_ptm(f));
  EXPECT_LE(measured, bound + 1e-3);
  // Rounding errors of six coefficients rarely line up: well under one grey level here.
  constexpr double kMaxRelitGrey = 1.0;
  EXPECT_LE(measured, kMaxRelitGrey);
  EXPECT_NEAR(report.relit_max_abs_grey, measured, 1e-3);
  EXPECT_GT(report.relit_mean_abs_grey, 0.0);
  EXPECT_LT(report.relit_mean_abs_grey, 0.3);
  EXPECT_GT(report.relit_psnr_db, 50.0);
  // Coefficient error: at most half a step (file units / 255 = normalised).
  float max_scale = 0.0f;
  for (float s : f.quantisation.scales) max_scale = std::max(max_scale, s);
  EXPECT_LE(report.max_coeff_error, 0.5 * max_scale / 255.0 + 1e-7);
  EXPECT_GT(report.rms_coeff_error, 0.0);
  EXPECT_EQ(report.relit_samples, 64u * 48u * 40u * 3u);
}

TEST(PtmMapping, LrgbColourBytesAndRelitValues) {
  const CoefficientMap map = smooth_map(16, 9, ColourModel::kLRGB);
  const PtmFile f = encode_ptm(map);
  ASSERT_EQ(f.format, PtmFormat::kLRGB);
  for (int y = 0; y < map.height; ++y) {
    for (int x = 0; x < map.width; ++x) {
      for (int c = 0; c < 3; ++c) {
        EXPECT_EQ(f.rgb_byte(x, y, c), std::lround(255.0 * map.texel_colour(x, y)[c]));
      }
    }
  }
  // Relit: quantisation of L (half-step bound, scaled by colour <= 1) plus colour rounding
  // (half a byte of a colour <= 1 times L <= 1: 0.5 grey).
  const double bound = half_step_bound_grey(f.quantisation) + 0.5;
  EXPECT_LE(max_relit_difference_grey(map, decode_ptm(f)), bound);
}

TEST(PtmMapping, YccIsWrittenAsRgbSharingA0ToA4) {
  const CoefficientMap map = smooth_map(16, 9, ColourModel::kYCC);
  const PtmFile f = encode_ptm(map);
  ASSERT_EQ(f.format, PtmFormat::kRGB);
  const CoefficientMap rgb = decode_ptm(f);
  for (int y = 0; y < map.height; ++y) {
    for (int x = 0; x < map.width; ++x) {
      for (int i = 0; i < 5; ++i) {
        EXPECT_EQ(f.coeff_byte(x, y, 0, i), f.coeff_byte(x, y, 1, i));
        EXPECT_EQ(f.coeff_byte(x, y, 0, i), f.coeff_byte(x, y, 2, i));
      }
      // a5 per plane: R = Y + 1.402 Cr, G = Y - 0.344136 Cb - 0.714136 Cr, B = Y + 1.772 Cb.
      const double y5 = map.texel_coeffs(x, y)[5];
      const double cb = map.texel_colour(x, y)[0], cr = map.texel_colour(x, y)[1];
      const double step = f.quantisation.scales[5] / 255.0;
      const float* a = rgb.texel_coeffs(x, y);
      EXPECT_NEAR(a[5], y5 + 1.402 * cr, 0.5 * step + 1e-6);
      EXPECT_NEAR(a[11], y5 - 0.344136 * cb - 0.714136 * cr, 0.5 * step + 1e-6);
      EXPECT_NEAR(a[17], y5 + 1.772 * cb, 0.5 * step + 1e-6);
    }
  }
  EXPECT_LE(max_relit_difference_grey(map, rgb), half_step_bound_grey(f.quantisation));
}

TEST(PtmWrite, NonFiniteCoefficientsAreRefusedAndNothingIsWritten) {
  test::ScratchDir dir;
  CoefficientMap map = smooth_map(4, 4, ColourModel::kRGB);
  map.coeffs[7] = std::numeric_limits<float>::quiet_NaN();
  const fs::path path = dir / "nan.ptm";
  try {
    (void)write_ptm(path, map);
    FAIL() << "expected an error";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("nan.ptm"), std::string::npos) << e.what();
  }
  EXPECT_TRUE(test::list_files(dir.path()).empty());
}

// ---------------------------------------------------------------------------------------------
// Malformed files

struct BadFile {
  const char* name;
  std::string header;
  std::size_t data_bytes;
  const char* expect;  // part of the message
};

TEST(PtmReadErrors, EveryMalformedFileNamesTheFileAndTheProblem) {
  test::ScratchDir dir;
  const std::string ok_tail = "1 1 1 1 1 1\n0 0 0 0 0 0\n";
  const std::vector<BadFile> cases = {
      {"empty", "", 0, "empty"},
      {"magic", "P6\n2 2\n255\n", 12, "not a PTM file"},
      {"version", "PTM_1.3\nPTM_FORMAT_RGB\n1\n1\n" + ok_tail, 18, "unsupported PTM version"},
      {"jpeg_short", "PTM_1.2\nPTM_FORMAT_JPEG_LRGB\n1\n1\n" + ok_tail, 9, "compression parameter"},
      {"unknown", "PTM_1.2\nPTM_FORMAT_FOO\n1\n1\n" + ok_tail, 9,
       "format PTM_FORMAT_FOO is not supported (supported: "},
      {"not_format", "PTM_1.2\nRGB\n1\n1\n" + ok_tail, 9, "unknown format 'RGB'"},
      {"old_rgb", "PTM_1.1\nPTM_FORMAT_RGB\n1\n1\n" + ok_tail, 18, "PTM_1.1 PTM_FORMAT_RGB"},
      {"width_text", "PTM_1.2\nPTM_FORMAT_RGB\nabc\n1\n" + ok_tail, 18, "width 'abc'"},
      {"width_zero", "PTM_1.2\nPTM_FORMAT_RGB\n0\n1\n" + ok_tail, 18, "not a positive integer"},
      {"height_negative", "PTM_1.2\nPTM_FORMAT_RGB\n1\n-4\n" + ok_tail, 18,
       "not a positive integer"},
      {"height_absurd", "PTM_1.2\nPTM_FORMAT_RGB\n1\n99999999\n" + ok_tail, 18, "absurd"},
      {"size_absurd", "PTM_1.2\nPTM_FORMAT_RGB\n1000000\n1000000\n" + ok_tail, 18, "absurd"},
      {"scale_nan", "PTM_1.2\nPTM_FORMAT_RGB\n1\n1\n1 1 nan 1 1 1\n0 0 0 0 0 0\n", 18, "scale 2"},
      {"scale_inf", "PTM_1.2\nPTM_FORMAT_RGB\n1\n1\n1 1 1 inf 1 1\n0 0 0 0 0 0\n", 18, "scale 3"},
      {"scale_zero", "PTM_1.2\nPTM_FORMAT_RGB\n1\n1\n1 1 1 1 0 1\n0 0 0 0 0 0\n", 18, "non-zero"},
      {"scale_text", "PTM_1.2\nPTM_FORMAT_RGB\n1\n1\n1 x 1 1 1 1\n0 0 0 0 0 0\n", 18,
       "not a number"},
      {"bias_range",
       "PTM_1.2\nPTM_FORMAT_RGB\n1\n1\n" + std::string("1 1 1 1 1 1\n0 0 3000000 0 0 0\n"), 18,
       "bias 2"},
      {"bias_fraction", "PTM_1.2\nPTM_FORMAT_RGB\n1\n1\n1 1 1 1 1 1\n0 0 0 0 1.5 0\n", 18,
       "bias 4"},
      {"short_header", "PTM_1.2\nPTM_FORMAT_RGB\n1\n1\n1 1 1\n", 0, "header ends before"},
      {"no_line_end", "PTM_1.2\nPTM_FORMAT_RGB\n1\n1\n1 1 1 1 1 1\n0 0 0 0 0 0", 0, "line end"},
      {"truncated", "PTM_1.2\nPTM_FORMAT_RGB\n2\n2\n" + ok_tail, 70,
       "needs 72 bytes after the header, found 70"},
      {"truncated_lrgb", "PTM_1.2\nPTM_FORMAT_LRGB\n2\n2\n" + ok_tail, 24,
       "needs 36 bytes after the header, found 24"},
  };
  for (const auto& c : cases) {
    SCOPED_TRACE(c.name);
    const fs::path path = dir / (std::string(c.name) + ".ptm");
    write_bytes(path, c.header, Bytes(c.data_bytes, 0));
    try {
      (void)read_ptm_file(path);
      ADD_FAILURE() << "no error";
    } catch (const Error& e) {
      const std::string msg = e.what();
      EXPECT_NE(msg.find(path.string()), std::string::npos) << msg;
      EXPECT_NE(msg.find(c.expect), std::string::npos) << msg;
    }
  }
  for (const fs::path& p : {dir / "missing.ptm", dir.path()}) {
    try {
      (void)read_ptm(p);
      ADD_FAILURE() << "no error for " << p;
    } catch (const Error& e) {
      EXPECT_NE(std::string(e.what()).find(p.string()), std::string::npos) << e.what();
    }
  }
}

TEST(PtmReadErrors, InfoReadsTheHeaderOfATruncatedFile) {
  test::ScratchDir dir;
  const fs::path path = dir / "t.ptm";
  write_bytes(path, "PTM_1.2\nPTM_FORMAT_LRGB\n20\n10\n1 1 1 1 1 1\n0 0 0 0 0 0\n", Bytes(5, 0));
  const PtmInfo info = read_ptm_info(path);
  EXPECT_EQ(info.format, PtmFormat::kLRGB);
  EXPECT_EQ(info.width, 20);
  EXPECT_EQ(info.height, 10);
  EXPECT_EQ(info.data_bytes, 20u * 10u * 9u);
  EXPECT_EQ(info.bytes_per_texel(), 9);
  EXPECT_THROW((void)summarise_ptm(path), Error);
}

TEST(PtmSummary, RangesAndMemory) {
  test::ScratchDir dir;
  const CoefficientMap map = smooth_map(10, 8, ColourModel::kRGB);
  write_ptm(dir / "m.ptm", map);
  const PtmSummary s = summarise_ptm(dir / "m.ptm");
  EXPECT_EQ(s.file_bytes_per_texel, 18);
  EXPECT_EQ(s.map_bytes_per_texel, 72);
  double lo5 = 1e9, hi5 = -1e9;
  for (int p = 0; p < 3; ++p) {
    for (std::size_t t = 0; t < 80; ++t) {
      lo5 = std::min<double>(lo5, 255.0 * map.coeffs[t * 18 + p * 6 + 5]);
      hi5 = std::max<double>(hi5, 255.0 * map.coeffs[t * 18 + p * 6 + 5]);
    }
  }
  const double step = s.info.quantisation.scales[5];
  EXPECT_NEAR(s.coeff_min[5], lo5, 0.5 * step + 1e-4);
  EXPECT_NEAR(s.coeff_max[5], hi5, 0.5 * step + 1e-4);
  EXPECT_LE(s.representable_min[5], s.coeff_min[5]);
  EXPECT_GE(s.representable_max[5], s.coeff_max[5]);
}

// ---------------------------------------------------------------------------------------------
// Streaming

void stream_map(const CoefficientMap& map, int band_rows, CoefficientSink& sink) {
  sink.begin(map.layout());
  const std::size_t nc = static_cast<std::size_t>(map.polynomials()) * kPtmTerms;
  for (int y0 = 0; y0 < map.height; y0 += band_rows) {
    const int rows = std::min(band_rows, map.height - y0);
    const float* colour =
        map.colours() > 0 ? map.colour.data() + map.texel_index(0, y0) * map.colours() : nullptr;
    sink.write_rows(y0, rows, map.coeffs.data() + map.texel_index(0, y0) * nc, colour);
  }
  sink.end();
}

TEST(PtmStream, MatchesWritePtmWithinHalfFloatRounding) {
  test::ScratchDir dir;
  for (const ColourModel model : {ColourModel::kRGB, ColourModel::kLRGB, ColourModel::kYCC}) {
    SCOPED_TRACE(std::string(to_string(model)));
    // Rows for three of the writer's slices, each many pages wide: the writer frees a slice's
    // memory once it is encoded, and must free no other slice's.
    const CoefficientMap map = smooth_map(200, 150, model);
    const fs::path direct = dir / "direct.ptm", streamed = dir / "streamed.ptm";
    const PtmWriteReport direct_report = write_ptm(direct, map);
    PtmStreamWriter writer(streamed);
    stream_map(map, 7, writer);
    const PtmFile a = read_ptm_file(direct), b = read_ptm_file(streamed);
    ASSERT_EQ(a.format, b.format);
    // Same ranges, so the same scales and biases, so the same header.
    EXPECT_EQ(a.quantisation, b.quantisation);
    EXPECT_EQ(a.header, b.header);
    EXPECT_EQ(writer.report().file_bytes, direct_report.file_bytes);
    // Half rounding moves a value by at most 2^-12 of its magnitude (under 0.07 grey levels
    // here, a step is about 0.6-0.8): a byte differs by at most one, and seldom.
    ASSERT_EQ(a.data.size(), b.data.size());
    std::size_t differing = 0;
    for (std::size_t k = 0; k < a.data.size(); ++k) {
      ASSERT_LE(std::abs(a.data[k] - b.data[k]), 1) << k;
      differing += a.data[k] != b.data[k] ? 1 : 0;
    }
    EXPECT_LT(static_cast<double>(differing), 0.2 * static_cast<double>(a.data.size()));
    // Relit: never more than one step of every coefficient (twice the half-step bound); on
    // average a few hundredths of a grey level; more than one grey level only where several
    // flipped bytes line up, which is rare.
    const CoefficientMap ma = decode_ptm(a), mb = decode_ptm(b);
    double worst = 0.0, sum = 0.0;
    std::size_t n = 0, above_one = 0;
    for (const auto& l : geodesic_dome(2)) {
      const Image ia = relight(ma, l), ib = relight(mb, l);
      for (std::size_t k = 0; k < ia.size(); ++k) {
        const double d = 255.0 * std::abs(static_cast<double>(ia.data()[k] - ib.data()[k]));
        worst = std::max(worst, d);
        sum += d;
        above_one += d > 1.0 ? 1 : 0;
        ++n;
      }
    }
    EXPECT_LE(worst, 2.0 * half_step_bound_grey(a.quantisation) + 1e-3);
    constexpr double kMeanStreamDifferenceGrey = 0.05;
    constexpr double kFractionAboveOneGreyLevel = 1e-3;
    EXPECT_LT(sum / static_cast<double>(n), kMeanStreamDifferenceGrey);
    EXPECT_LT(static_cast<double>(above_one), kFractionAboveOneGreyLevel * static_cast<double>(n));
    EXPECT_LE(writer.report().relit_max_abs_grey, 2.0 * half_step_bound_grey(b.quantisation));
    std::printf(
        "[ stream %-4s ] bytes differing %.2f%%; relit difference mean %.4f, max %.3f "
        "grey, %.4f%% above 1 grey\n",
        std::string(to_string(model)).c_str(),
        100.0 * static_cast<double>(differing) / static_cast<double>(a.data.size()),
        sum / static_cast<double>(n), worst,
        100.0 * static_cast<double>(above_one) / static_cast<double>(n));
  }
}

// Above spill_above_bytes the half floats go to an unnamed temporary file: the same file comes
// out, and nothing is left in the folder but it.
TEST(PtmStream, SpilledCoefficientsGiveTheSameFile) {
  test::ScratchDir dir;
  for (const ColourModel model : {ColourModel::kRGB, ColourModel::kLRGB, ColourModel::kYCC}) {
    SCOPED_TRACE(std::string(to_string(model)));
    const CoefficientMap map = smooth_map(70, 131, model);  // more rows than one slice
    PtmStreamWriter in_memory(dir / "memory.ptm");
    in_memory.begin({1, 1, Basis::kPtm, model, ColourSpace::kSRGB});
    EXPECT_FALSE(in_memory.spilled());
    stream_map(map, 9, in_memory);  // begins again, for the map's size
    const std::vector<std::uint8_t> expected = read_ptm_file(dir / "memory.ptm").data;
    // Budgets: below one row (every row spilled); 50 rows (a 9-row band and a 64-row slice
    // each straddle the boundary); just under the whole.
    const std::size_t halfs_per_texel = model == ColourModel::kRGB   ? 18
                                        : model == ColourModel::kYCC ? 8
                                                                     : 6;
    const std::size_t row_bytes = 70 * halfs_per_texel * 2;
    for (const std::size_t budget : {std::size_t{1}, 50 * row_bytes + 7, 131 * row_bytes - 1}) {
      SCOPED_TRACE("budget " + std::to_string(budget));
      PtmWriteOptions spill;
      spill.spill_above_bytes = budget;
      PtmStreamWriter spilled(dir / "spilled.ptm", spill);
      spilled.begin({70, 131, Basis::kPtm, model, ColourSpace::kSRGB});
      EXPECT_TRUE(spilled.spilled());
      stream_map(map, 9, spilled);
      EXPECT_EQ(expected, read_ptm_file(dir / "spilled.ptm").data);
      EXPECT_EQ(in_memory.report().relit_mean_abs_grey, spilled.report().relit_mean_abs_grey);
      EXPECT_EQ(in_memory.report().rms_coeff_error, spilled.report().rms_coeff_error);
      EXPECT_THAT(test::list_files(dir.path()),
                  ::testing::ElementsAre("memory.ptm", "spilled.ptm"));
    }
  }
}

TEST(PtmStream, BufferIsHalfFloatSized) {
  test::ScratchDir dir;
  const CoefficientMap map = smooth_map(20, 10, ColourModel::kYCC);
  PtmStreamWriter writer(dir / "s.ptm");
  writer.begin({20, 10, Basis::kPtm, ColourModel::kYCC, ColourSpace::kSRGB});
  // a0..a4 shared plus three a5, 2 bytes each.
  EXPECT_EQ(writer.buffer_bytes(), 200u * 8u * 2u);
  PtmStreamWriter rgb(dir / "r.ptm");
  rgb.begin({20, 10, Basis::kPtm, ColourModel::kRGB, ColourSpace::kSRGB});
  EXPECT_EQ(rgb.buffer_bytes(), 200u * 18u * 2u);
  PtmStreamWriter lrgb(dir / "l.ptm");
  lrgb.begin({20, 10, Basis::kPtm, ColourModel::kLRGB, ColourSpace::kSRGB});
  EXPECT_EQ(lrgb.buffer_bytes(), 200u * (6u * 2u + 3u));
  (void)map;
}

TEST(PtmStream, MisuseAndBadValuesLeaveNoFile) {
  test::ScratchDir dir;
  const CoefficientMap map = smooth_map(8, 8, ColourModel::kRGB);
  {
    PtmStreamWriter writer(dir / "order.ptm");
    writer.begin({8, 8, Basis::kPtm, ColourModel::kRGB, ColourSpace::kSRGB});
    EXPECT_THROW(writer.write_rows(2, 2, map.coeffs.data(), nullptr), std::logic_error);
    writer.write_rows(0, 4, map.coeffs.data(), nullptr);
    EXPECT_THROW(writer.end(), std::logic_error);
  }
  {
    CoefficientMap bad = map;
    bad.coeffs[100] = std::numeric_limits<float>::infinity();
    PtmStreamWriter writer(dir / "inf.ptm");
    try {
      stream_map(bad, 3, writer);
      ADD_FAILURE() << "no error";
    } catch (const Error& e) {
      EXPECT_NE(std::string(e.what()).find("inf.ptm"), std::string::npos) << e.what();
    }
  }
  EXPECT_TRUE(test::list_files(dir.path()).empty());
}

// Over an existing output the writer first drops that file's cached pages: the file must end
// up replaced by the new map, a failed run must leave the old bytes as they were, and a FIFO at
// the path must neither make the writer wait for a writer of its own nor be replaced.
TEST(PtmStream, ReplacesAnExistingOutputAndKeepsItOnFailure) {
  test::ScratchDir dir;
  const auto bytes = [](const fs::path& p) {
    std::ifstream in(p, std::ios::binary);
    return std::string(std::istreambuf_iterator<char>(in), {});
  };
  const CoefficientMap first = smooth_map(12, 10, ColourModel::kRGB);
  CoefficientMap second = first;
  for (float& c : second.coeffs) c *= 0.5f;
  const fs::path out = dir / "out.ptm";
  const fs::path fresh = dir / "fresh.ptm";
  {
    PtmStreamWriter writer(out);
    stream_map(first, 4, writer);
  }
  const std::string old_bytes = bytes(out);
  {
    PtmStreamWriter writer(fresh);
    stream_map(second, 4, writer);
  }
  {
    PtmStreamWriter writer(out);
    stream_map(second, 4, writer);
  }
  EXPECT_EQ(bytes(out), bytes(fresh));
  EXPECT_NE(bytes(out), old_bytes);

  CoefficientMap bad = first;
  bad.coeffs[7] = std::numeric_limits<float>::quiet_NaN();
  const std::string before = bytes(out);
  {
    PtmStreamWriter writer(out);
    EXPECT_THROW(stream_map(bad, 4, writer), Error);
  }
  EXPECT_EQ(bytes(out), before);

  const fs::path fifo = dir / "fifo.ptm";
  ASSERT_EQ(::mkfifo(fifo.c_str(), 0600), 0);
  {
    // Only regular files are replaced: a FIFO (or device) at the path is an error, kept.
    PtmStreamWriter writer(fifo);
    EXPECT_THROW(stream_map(second, 4, writer), Error);
  }
  EXPECT_TRUE(fs::is_fifo(fifo));
  fs::remove(fresh);
  fs::remove(fifo);
  EXPECT_EQ(test::list_files(dir.path()).size(), 1u);  // out.ptm alone: no temporary left
}

// The writer's range pass takes 4 texels' terms at a time and the rest one by one: a bad
// value anywhere (either part, any term) is caught, and the ranges, so the scales and biases,
// are write_ptm's. Bands of 3 rows of 9 texels leave a tail in both formats.
TEST(PtmStream, BadValueInAnyTermIsCaughtAndRangesMatch) {
  test::ScratchDir dir;
  for (const ColourModel model : {ColourModel::kRGB, ColourModel::kLRGB}) {
    SCOPED_TRACE(std::string(to_string(model)));
    const CoefficientMap map = smooth_map(9, 6, model);
    {
      PtmStreamWriter writer(dir / "clean.ptm");
      stream_map(map, 3, writer);
      write_ptm(dir / "direct.ptm", map);
      EXPECT_EQ(read_ptm_file(dir / "clean.ptm").quantisation,
                read_ptm_file(dir / "direct.ptm").quantisation);
    }
    const std::size_t band_values = 3u * 9u * static_cast<std::size_t>(map.polynomials()) * 6u;
    for (const float bad :
         {std::numeric_limits<float>::infinity(), -std::numeric_limits<float>::infinity(),
          std::numeric_limits<float>::quiet_NaN(), 70000.0f, -70000.0f}) {
      for (const std::size_t at : {std::size_t{0}, std::size_t{5}, std::size_t{29}, band_values - 1,
                                   band_values + 3, map.coeffs.size() - 1}) {
        CoefficientMap broken = map;
        broken.coeffs[at] = bad;
        PtmStreamWriter writer(dir / "bad.ptm");
        EXPECT_THROW(stream_map(broken, 3, writer), Error) << "value " << bad << " at " << at;
      }
    }
  }
  EXPECT_THAT(test::list_files(dir.path()), ::testing::ElementsAre("clean.ptm", "direct.ptm"));
}

// LRGB colour bytes, 16 at a time in the writer: the same bytes as write_ptm's, one by one,
// for values on and beside every rounding half, out of range, signed zeros and NaN, in the
// vector part and in the tail of each band (3 rows of 37 texels: 333 values, 13 in the tail).
TEST(PtmStream, ColourBytesAreWritePtmsForEveryValue) {
  test::ScratchDir dir;
  CoefficientMap map = smooth_map(37, 5, ColourModel::kLRGB);
  std::vector<float> values = {0.0f,
                               -0.0f,
                               -1e-9f,
                               -0.5f,
                               1.0f,
                               1.0000001f,
                               7.0f,
                               std::numeric_limits<float>::quiet_NaN(),
                               std::numeric_limits<float>::infinity(),
                               -std::numeric_limits<float>::infinity()};
  for (int k = 0; k < 255; ++k) {
    const float h = static_cast<float>((k + 0.5) / 255.0);
    values.insert(values.end(), {h, std::nextafter(h, 0.0f), std::nextafter(h, 1.0f),
                                 static_cast<float>(k / 255.0)});
  }
  for (std::size_t k = 0; k < map.colour.size(); ++k) map.colour[k] = values[k % values.size()];
  write_ptm(dir / "direct.ptm", map);
  PtmStreamWriter writer(dir / "streamed.ptm");
  stream_map(map, 3, writer);
  const PtmFile a = read_ptm_file(dir / "direct.ptm"), b = read_ptm_file(dir / "streamed.ptm");
  const std::size_t texels = 37u * 5u;
  const std::size_t rgb_at = texels * kPtmTerms;
  ASSERT_EQ(a.data.size(), rgb_at + texels * 3);
  ASSERT_EQ(b.data.size(), a.data.size());
  for (std::size_t k = rgb_at; k < a.data.size(); ++k) {
    ASSERT_EQ(int{a.data[k]}, int{b.data[k]}) << "colour value " << (k - rgb_at);
  }
}

}  // namespace
}  // namespace ptmkit::texture
