// Relighting a coefficient map, image comparison, and relighting a whole light set.
#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <string>

#include "ptmkit/core/colour.h"
#include "ptmkit/core/error.h"
#include "ptmkit/core/image_io.h"
#include "ptmkit/core/light_set.h"
#include "ptmkit/core/parallel.h"
#include "ptmkit/texture/metrics.h"
#include "ptmkit/texture/relight.h"
#include "test_util.h"
#include "tolerances.h"

namespace fs = std::filesystem;

namespace ptmkit::texture {
namespace {

using test::kFloatRoundoff;

// 0.5 + sqrt(0.5) = 1.207 unclamped: above this, clearly past the clamp at 1.
constexpr float kUnclampedAbove = 1.2f;
// 0.5 - sqrt(0.5) = -0.207 unclamped: below this, clearly past the clamp at 0.
constexpr float kUnclampedBelow = -0.2f;
// Metrics of float pixels: 0.6f - 0.5f is 0.1 to 2.4e-7 relative, which moves a PSNR (dB) or a
// mean (grey levels) by about 1e-6.
constexpr double kFloatMetricTol = 1e-3;
// A difference of float rounding only (1e-7 at most) scores above 140 dB; one grey level of
// real difference scores 48 dB.
constexpr double kRoundingOnlyPsnrDb = 120.0;
// 8-bit rounding only: RMS 1/sqrt(12) grey levels, about 59 dB.
constexpr double kEightBitPsnrDb = 55.0;
// 8-bit rounding only: at most half a grey level per sample (a quarter on average).
constexpr double kEightBitMeanAbsGrey = 0.5;

// Same polynomial in every channel of every texel, plus a texel-dependent a5 so rows differ.
CoefficientMap polynomial_map(int w, int h, const std::array<float, 6>& a) {
  CoefficientMap map(w, h, ColourModel::kRGB);
  for (int y = 0; y < h; ++y) {
    for (int x = 0; x < w; ++x) {
      for (int p = 0; p < 3; ++p) {
        float* c = map.texel_coeffs(x, y) + p * kPtmTerms;
        for (int i = 0; i < kPtmTerms; ++i) c[i] = a[i];
        c[5] += 0.01f * static_cast<float>(x + 2 * y + p);
      }
    }
  }
  return map;
}

TEST(Relight, ConstantPolynomialGivesItsValueForAnyLight) {
  const CoefficientMap map = polynomial_map(5, 4, {0, 0, 0, 0, 0, 0.4f});
  for (const Eigen::Vector3d& l : {Eigen::Vector3d(0, 0, 1), Eigen::Vector3d(3, -2, 1)}) {
    const Image img = relight(map, l);
    ASSERT_EQ(img.channels(), 3);
    for (int y = 0; y < 4; ++y)
      for (int x = 0; x < 5; ++x)
        for (int c = 0; c < 3; ++c)
          EXPECT_FLOAT_EQ(img.at(x, y, c), 0.4f + 0.01f * static_cast<float>(x + 2 * y + c));
  }
}

TEST(Relight, QuadraticMatchesTheAnalyticValueWithANonUnitLight) {
  const std::array<float, 6> a = {-0.2f, 0.1f, 0.3f, 0.25f, -0.15f, 0.5f};
  const CoefficientMap map = polynomial_map(3, 2, a);
  const Eigen::Vector3d light(2.0, 1.0, 2.0);  // norm 3: (lu, lv) = (2/3, 1/3)
  const double lu = 2.0 / 3.0, lv = 1.0 / 3.0;
  const double expected0 =
      a[0] * lu * lu + a[1] * lv * lv + a[2] * lu * lv + a[3] * lu + a[4] * lv + a[5];
  const Image img = relight(map, light);
  EXPECT_NEAR(img.at(0, 0, 0), expected0, kFloatRoundoff);
  EXPECT_NEAR(img.at(2, 1, 1), expected0 + 0.01 * (2 + 2 + 1), kFloatRoundoff);
}

TEST(Relight, LightAtOrBelowTheHorizonIsBlack) {
  const CoefficientMap map = polynomial_map(4, 3, {0, 0, 0, 0.3f, 0.3f, 0.6f});
  for (const Eigen::Vector3d& l : {Eigen::Vector3d(1, 0, 0), Eigen::Vector3d(0.3, 0.2, -1)}) {
    const Image img = relight(map, l);
    ASSERT_EQ(img.width(), 4);
    for (std::size_t k = 0; k < img.size(); ++k) EXPECT_EQ(img.data()[k], 0.0f);
  }
}

TEST(Relight, NonFiniteOrZeroLightIsAnError) {
  const CoefficientMap map = polynomial_map(2, 2, {0, 0, 0, 0, 0, 0.5f});
  const double nan = std::numeric_limits<double>::quiet_NaN();
  const double inf = std::numeric_limits<double>::infinity();
  EXPECT_THROW((void)relight(map, {0, 0, 0}), Error);
  EXPECT_THROW((void)relight(map, {nan, 0, 1}), Error);
  EXPECT_THROW((void)relight(map, {0, inf, 1}), Error);
}

TEST(Relight, ClampIsOptional) {
  const CoefficientMap map = polynomial_map(2, 2, {0, 0, 0, 1.0f, 0, 0.5f});
  RelightOptions raw;
  raw.clamp = false;
  const Eigen::Vector3d l(1, 0, 1);  // lu = 0.707: 0.5 + 0.707 > 1
  EXPECT_EQ(relight(map, l).at(0, 0, 0), 1.0f);
  EXPECT_GT(relight(map, l, raw).at(0, 0, 0), kUnclampedAbove);
  const Eigen::Vector3d dark(-1, 0, 1);  // 0.5 - 0.707 < 0
  EXPECT_EQ(relight(map, dark).at(0, 0, 0), 0.0f);
  EXPECT_LT(relight(map, dark, raw).at(0, 0, 0), kUnclampedBelow);
}

TEST(Relight, LrgbAndYccFollowTheirColourModels) {
  CoefficientMap lrgb(1, 1, ColourModel::kLRGB);
  const float poly[6] = {0, 0, 0, 0.2f, 0, 0.6f};
  std::copy_n(poly, 6, lrgb.texel_coeffs(0, 0));
  const float col[3] = {1.0f, 0.5f, 0.25f};
  std::copy_n(col, 3, lrgb.texel_colour(0, 0));
  const Eigen::Vector3d l(0.6, 0, 0.8);
  const double lum = 0.6 + 0.2 * 0.6;
  const Image a = relight(lrgb, l);
  for (int c = 0; c < 3; ++c) EXPECT_NEAR(a.at(0, 0, c), lum * col[c], kFloatRoundoff);

  CoefficientMap ycc(1, 1, ColourModel::kYCC);
  std::copy_n(poly, 6, ycc.texel_coeffs(0, 0));
  ycc.texel_colour(0, 0)[0] = 0.05f;   // cb
  ycc.texel_colour(0, 0)[1] = -0.04f;  // cr
  double r = 0, g = 0, b = 0;
  from_ycbcr({lum, 0.05f, -0.04f}, &r, &g, &b);
  const Image y = relight(ycc, l);
  EXPECT_NEAR(y.at(0, 0, 0), r, kFloatRoundoff);
  EXPECT_NEAR(y.at(0, 0, 1), g, kFloatRoundoff);
  EXPECT_NEAR(y.at(0, 0, 2), b, kFloatRoundoff);
}

TEST(Relight, SameResultForAnyThreadCount) {
  CoefficientMap map(97, 61, ColourModel::kRGB);
  for (std::size_t k = 0; k < map.coeffs.size(); ++k) {
    map.coeffs[k] = static_cast<float>(std::sin(0.37 * static_cast<double>(k)));
  }
  Image one, two;
  {
    ThreadLimit limit(1);
    one = relight(map, {0.2, 0.5, 0.8});
  }
  {
    ThreadLimit limit(2);
    two = relight(map, {0.2, 0.5, 0.8});
  }
  ASSERT_EQ(one.size(), two.size());
  for (std::size_t k = 0; k < one.size(); ++k) ASSERT_EQ(one.data()[k], two.data()[k]);
}

// ---------------------------------------------------------------------------------------------

TEST(CompareImages, KnownOffsetAndMask) {
  Image a(4, 2, 3, ColourSpace::kSRGB, 0.5f), b(4, 2, 3, ColourSpace::kSRGB, 0.5f);
  const ImageComparison same = compare_images(a.view(), b.view());
  EXPECT_TRUE(std::isinf(same.psnr_db));
  for (int x = 0; x < 4; ++x)
    for (int c = 0; c < 3; ++c) b.at(x, 1, c) = 0.6f;  // bottom row off by 0.1
  const ImageComparison half = compare_images(a.view(), b.view());
  // MSE = 0.01 over half the pixels: 0.005, PSNR = 10 log10(1 / 0.005) = 23.01 dB.
  EXPECT_NEAR(half.psnr_db, 10.0 * std::log10(1.0 / 0.005), kFloatMetricTol);
  EXPECT_NEAR(half.mean_abs_grey, 0.05 * 255.0, kFloatMetricTol);
  EXPECT_NEAR(half.max_abs, 0.1, kFloatRoundoff);
  Image mask(4, 2, 1, ColourSpace::kLinear, 0.0f);
  for (int x = 0; x < 4; ++x) mask.at(x, 1, 0) = 1.0f;
  const ConstImageViewF mv = mask.view();
  const ImageComparison masked = compare_images(a.view(), b.view(), &mv);
  EXPECT_EQ(masked.pixels, 4u);
  EXPECT_NEAR(masked.psnr_db, 20.0, kFloatMetricTol);
  const Image empty_mask(4, 2, 1);
  const ConstImageViewF ev = empty_mask.view();
  EXPECT_THROW((void)compare_images(a.view(), b.view(), &ev), Error);
}

TEST(CompareImages, GreyReferenceUsesLumaAndMismatchesAreErrors) {
  Image rgb(2, 2, 3, ColourSpace::kSRGB, 0.0f);
  for (int y = 0; y < 2; ++y)
    for (int x = 0; x < 2; ++x) {
      rgb.at(x, y, 0) = 0.8f;
      rgb.at(x, y, 1) = 0.4f;
      rgb.at(x, y, 2) = 0.2f;
    }
  const Image grey(2, 2, 1, ColourSpace::kSRGB, static_cast<float>(luma(0.8f, 0.4f, 0.2f)));
  EXPECT_GT(compare_images(rgb.view(), grey.view()).psnr_db, kRoundingOnlyPsnrDb);
  EXPECT_THROW((void)compare_images(rgb.view(), Image(3, 2, 3, ColourSpace::kSRGB).view()), Error);
  EXPECT_THROW((void)compare_images(rgb.view(), Image(2, 2, 3, ColourSpace::kLinear).view()),
               Error);
  EXPECT_THROW((void)compare_images(rgb.view(), Image(2, 2, 2, ColourSpace::kSRGB).view()), Error);
}

// ---------------------------------------------------------------------------------------------

CoefficientMap gradient_map(int w, int h) {
  CoefficientMap map(w, h, ColourModel::kRGB);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x)
      for (int p = 0; p < 3; ++p) {
        float* c = map.texel_coeffs(x, y) + p * kPtmTerms;
        c[3] = 0.2f * static_cast<float>(x) / static_cast<float>(w);
        c[4] = -0.1f;
        c[5] = 0.3f + 0.1f * static_cast<float>(p) +
               0.2f * static_cast<float>(y) / static_cast<float>(h);
      }
  return map;
}

TEST(RelightSet, WritesImagesAndComparesWithExistingPhotos) {
  test::ScratchDir dir;
  const CoefficientMap map = gradient_map(24, 16);
  LightSet set;
  set.source = dir / "test.lp";
  const Eigen::Vector3d dirs[3] = {{0, 0, 1}, {0.5, 0.2, 0.8}, {-0.4, 0.4, 0.7}};
  for (int i = 0; i < 3; ++i) {
    Light l;
    l.image = dir / ("photo" + std::to_string(i) + ".png");
    l.direction = dirs[i].normalized();
    set.lights.push_back(l);
  }
  // Photos 0 and 1 exist (the relit images themselves, saved as 8-bit); photo 2 does not.
  for (int i = 0; i < 2; ++i) write_image(set.lights[i].image, relight(map, dirs[i]).view());
  RelightSetOptions options;
  options.out_dir = dir / "out";
  options.report_json = dir / "report.json";
  const RelightSetReport report = relight_light_set(map, set, options);
  ASSERT_EQ(report.entries.size(), 3u);
  EXPECT_EQ(report.compared, 2u);
  EXPECT_FALSE(report.entries[2].compared);
  EXPECT_GT(report.mean_psnr_db, kEightBitPsnrDb);
  EXPECT_LT(report.mean_abs_grey, kEightBitMeanAbsGrey);
  EXPECT_EQ(test::list_files(options.out_dir),
            (std::vector<std::string>{"photo0.png", "photo1.png", "photo2.png"}));
  EXPECT_TRUE(fs::exists(options.report_json));
  EXPECT_NE(report.to_json().find("\"mean_psnr_db\""), std::string::npos);
}

TEST(RelightSet, FailureLeavesNothingBehind) {
  test::ScratchDir dir;
  const CoefficientMap map = gradient_map(24, 16);
  LightSet set;
  set.source = dir / "test.lp";
  for (int i = 0; i < 2; ++i) {
    Light l;
    l.image = dir / ("p" + std::to_string(i) + ".png");
    set.lights.push_back(l);
  }
  // The second photo has the wrong size.
  write_image(set.lights[0].image, relight(map, {0, 0, 1}).view());
  write_image(set.lights[1].image, Image(5, 5, 3, ColourSpace::kSRGB, 0.5f).view());
  RelightSetOptions options;
  options.out_dir = dir / "out";
  options.report_json = dir / "r.json";
  try {
    (void)relight_light_set(map, set, options);
    FAIL() << "expected an error";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("p1.png"), std::string::npos) << e.what();
  }
  EXPECT_FALSE(fs::exists(options.out_dir));
  EXPECT_FALSE(fs::exists(options.report_json));

  // Two lights whose images share a file name cannot both be written.
  LightSet clash = set;
  clash.lights[1].image = dir / "sub" / "p0.png";
  EXPECT_THROW((void)relight_light_set(map, clash, options), Error);
  EXPECT_FALSE(fs::exists(options.out_dir));

  // A failure after the images were written (the report cannot be written: its path is a
  // folder) removes them and the folder made for them.
  write_image(set.lights[1].image, relight(map, {0, 0, 1}).view());
  options.report_json = dir.path();
  EXPECT_THROW((void)relight_light_set(map, set, options), Error);
  EXPECT_FALSE(fs::exists(options.out_dir));
}

}  // namespace
}  // namespace ptmkit::texture
