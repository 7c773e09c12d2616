// .ptm writing and quantisation: bit-exact rewrites, the canonical header, scales and biases,
// relit error within the half-step bound, LRGB and YCC mappings, non-finite coefficients, and
// the file summary.
#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <string>

#include "ptm_test_util.h"
#include "ptmkit/core/error.h"
#include "ptmkit/texture/ptm.h"
#include "ptmkit/texture/relight.h"
#include "test_util.h"
#include "tolerances.h"

namespace fs = std::filesystem;

namespace ptmkit::texture {
namespace {

using test::Bytes;
using test::half_step_bound_grey;
using test::kFloatRoundoff;
using test::kRelitGreySlack;
using test::max_relit_difference_grey;
using test::read_bytes;
using test::smooth_map;

// float32 rounding of a scale near 1 (2^-23 ~ 1.2e-7), with room.
constexpr float kScaleFloatTol = 1e-6f;
// Quantisation of a smooth map: the mean relit error is a fraction of the worst case (the six
// coefficients' rounding errors mostly cancel), and 50 dB is an RMS error of 0.8 grey levels
// (255 / 10^(50 / 20)).
constexpr double kMaxMeanRelitGrey = 0.3;
constexpr double kMinRelitPsnrDb = 50.0;
// float32 rounding of a normalised coefficient below 1 (under 6e-8), with room.
constexpr double kCoeffErrorSlack = 1e-7;
// LRGB colour bytes: half a byte of a colour <= 1 times L <= 1, in grey levels.
constexpr double kColourRoundingGrey = 0.5;
// float32 rounding of coefficients in file units (up to 255: ~1.5e-5), with room.
constexpr double kFileUnitSlack = 1e-4;

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
  EXPECT_LE(q.scales[5], 1.0f + kScaleFloatTol);
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
  EXPECT_LE(measured, bound + kRelitGreySlack);
  // Rounding errors of six coefficients rarely line up: well under one grey level here.
  constexpr double kMaxRelitGrey = 1.0;
  EXPECT_LE(measured, kMaxRelitGrey);
  EXPECT_NEAR(report.relit_max_abs_grey, measured, kRelitGreySlack);
  EXPECT_GT(report.relit_mean_abs_grey, 0.0);
  EXPECT_LT(report.relit_mean_abs_grey, kMaxMeanRelitGrey);
  EXPECT_GT(report.relit_psnr_db, kMinRelitPsnrDb);
  // Coefficient error: at most half a step (file units / 255 = normalised).
  float max_scale = 0.0f;
  for (float s : f.quantisation.scales) max_scale = std::max(max_scale, s);
  EXPECT_LE(report.max_coeff_error, 0.5 * max_scale / 255.0 + kCoeffErrorSlack);
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
  // Relit: quantisation of L (half-step bound, scaled by colour <= 1) plus colour rounding.
  const double bound = half_step_bound_grey(f.quantisation) + kColourRoundingGrey;
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
      EXPECT_NEAR(a[5], y5 + 1.402 * cr, 0.5 * step + kFloatRoundoff);
      EXPECT_NEAR(a[11], y5 - 0.344136 * cb - 0.714136 * cr, 0.5 * step + kFloatRoundoff);
      EXPECT_NEAR(a[17], y5 + 1.772 * cb, 0.5 * step + kFloatRoundoff);
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
  EXPECT_NEAR(s.coeff_min[5], lo5, 0.5 * step + kFileUnitSlack);
  EXPECT_NEAR(s.coeff_max[5], hi5, 0.5 * step + kFileUnitSlack);
  EXPECT_LE(s.representable_min[5], s.coeff_min[5]);
  EXPECT_GE(s.representable_max[5], s.coeff_max[5]);
}

}  // namespace
}  // namespace ptmkit::texture
