#include "ptmkit/core/image_io.h"

#include <cmath>
#include <fstream>

#include <OpenImageIO/imageio.h>
#include <gmock/gmock.h>
#include <gtest/gtest.h>
#include <Eigen/Geometry>

#include "ptmkit/core/error.h"
#include "ptmkit/core/stack_reader.h"
#include "test_util.h"
#include "tolerances.h"

namespace fs = std::filesystem;
using ::testing::HasSubstr;

namespace ptmkit {
namespace {

using test::kFloatRoundoff;
using test::kHalf16BitStep;
using test::kHalf8BitStep;

// A decoded value in float: rounded to within about one ulp of values near 1 (1.2e-7).
constexpr double kFloatDecodeSlack = 1e-7;
// JPEG at quality 98 of a smooth ramp: measured worst 1.3 grey levels.
constexpr double kJpegQuality98Tol = 3.0 / 255;
// A 16-bit file read back: half a step is 7.6e-6; this is well above it and far below what a
// misplaced row or a wrong encoding moves a value (a tenth or more).
constexpr double kU16ReadBackTol = 1e-4;

Image ramp(int w, int h, int c, double phase = 0.0) {
  Image img(w, h, c, ColourSpace::kSRGB);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x)
      for (int k = 0; k < c; ++k)
        img.at(x, y, k) =
            static_cast<float>(0.5 + 0.45 * std::sin(0.3 * x + 0.7 * y + 1.3 * k + phase));
  return img;
}

double max_diff(const Image& a, const Image& b) {
  double m = 0.0;
  for (std::size_t i = 0; i < a.size(); ++i)
    m = std::max(m, double(std::abs(a.data()[i] - b.data()[i])));
  return m;
}

TEST(ImageIO, RoundTripsEachFormatWithinItsPrecision) {
  test::ScratchDir dir;
  const Image img = ramp(17, 9, 3);
  struct Case {
    std::string name;
    PixelFormat format;
    double tol;
  };
  for (const Case& c : {Case{"a.png", PixelFormat::kU8, kHalf8BitStep + kFloatDecodeSlack},
                        Case{"b.png", PixelFormat::kU16, kHalf16BitStep + kFloatDecodeSlack},
                        Case{"c.tif", PixelFormat::kU16, kHalf16BitStep + kFloatDecodeSlack},
                        Case{"d.exr", PixelFormat::kF32, 0.0}}) {
    write_image(dir / c.name, img.view(), {.format = c.format});
    const ImageInfo info = probe_image(dir / c.name);
    EXPECT_EQ(info.width, 17);
    EXPECT_EQ(info.height, 9);
    EXPECT_EQ(info.channels, 3);
    EXPECT_EQ(info.format, c.format) << c.name;
    const Image back = read_image(dir / c.name);
    EXPECT_LE(max_diff(img, back), c.tol) << c.name;
  }
}

TEST(ImageIO, JpegIsReadAndColourSpaceIsRecorded) {
  test::ScratchDir dir;
  // Smooth content: JPEG subsamples chroma 2x2, so pixel-scale colour detail would not survive.
  Image img(32, 16, 3, ColourSpace::kSRGB);
  for (int y = 0; y < 16; ++y)
    for (int x = 0; x < 32; ++x)
      for (int k = 0; k < 3; ++k)
        img.at(x, y, k) = 0.1f + 0.015f * float(x) + 0.01f * float(y) + 0.1f * float(k);
  write_image(dir / "a.jpg", img.view(), {.format = PixelFormat::kU8, .jpeg_quality = 98});
  const Image back = read_image(dir / "a.jpg");
  EXPECT_EQ(back.colour_space(), ColourSpace::kSRGB);
  EXPECT_LT(max_diff(img, back), kJpegQuality98Tol);
  img.set_colour_space(ColourSpace::kLinear);
  write_image(dir / "lin.exr", img.view(), {.format = PixelFormat::kF32});
  EXPECT_EQ(read_image(dir / "lin.exr").colour_space(), ColourSpace::kLinear);
}

TEST(ImageIO, HonoursStrideOfACroppedView) {
  test::ScratchDir dir;
  const Image img = ramp(20, 10, 3);
  const ConstImageViewF crop = img.view().crop(5, 2, 8, 4);
  write_image(dir / "crop.exr", crop, {.format = PixelFormat::kF32});
  const Image back = read_image(dir / "crop.exr");
  ASSERT_EQ(back.width(), 8);
  for (int y = 0; y < 4; ++y)
    for (int x = 0; x < 8; ++x) EXPECT_EQ(back.at(x, y, 1), img.at(x + 5, y + 2, 1));
}

TEST(ImageIO, ErrorsNameTheFileAndLeaveNothingBehind) {
  test::ScratchDir dir;
  try {
    (void)read_image(dir / "nope.png");
    FAIL();
  } catch (const Error& e) {
    EXPECT_THAT(e.what(), HasSubstr("nope.png"));
  }
  {
    std::ofstream f(dir / "junk.png");
    f << "not an image";
  }
  EXPECT_THROW((void)read_image(dir / "junk.png"), Error);
  Image bad = ramp(4, 4, 1);
  bad.at(1, 1, 0) = std::nanf("");
  EXPECT_THROW(write_image(dir / "nan.png", bad.view()), Error);
  EXPECT_FALSE(fs::exists(dir / "nan.png"));
  EXPECT_THROW(write_image(dir / "no" / "such" / "dir.png", ramp(4, 4, 1).view()), Error);
  EXPECT_THROW(write_image(dir / "x.jpg", ramp(4, 4, 3).view(), {.format = PixelFormat::kU16}),
               Error);
  // No temporary files are left in the folder.
  EXPECT_THAT(test::list_files(dir.path()), ::testing::ElementsAre("junk.png"));
}

TEST(StackReader, BandsReassembleTheImagesInAnyBandSize) {
  test::ScratchDir dir;
  std::vector<fs::path> files;
  std::vector<Image> originals;
  for (int i = 0; i < 5; ++i) {
    originals.push_back(ramp(23, 19, 3, i));
    files.push_back(dir / ("img" + std::to_string(i) + ".png"));
    write_image(files.back(), originals.back().view(), {.format = PixelFormat::kU16});
  }
  for (int rows : {1, 4, 7, 19, 64}) {
    StackReader reader(files);
    EXPECT_EQ(reader.width(), 23);
    EXPECT_EQ(reader.height(), 19);
    EXPECT_EQ(reader.count(), 5);
    StackBand band;
    int covered = 0;
    while (reader.read_band(rows, &band)) {
      EXPECT_EQ(band.y0, covered);
      for (int i = 0; i < 5; ++i)
        for (int r = 0; r < band.rows; ++r)
          for (int x = 0; x < 23; ++x)
            for (int c = 0; c < 3; ++c)
              ASSERT_NEAR(band.sample(i, r, x, c), originals[i].at(x, band.y0 + r, c),
                          kU16ReadBackTol);
      covered += band.rows;
    }
    EXPECT_EQ(covered, 19);
  }
}

TEST(StackReader, EightBitFilesCanStayBytes) {
  test::ScratchDir dir;
  std::vector<fs::path> files;
  for (int i = 0; i < 3; ++i) {
    files.push_back(dir / ("img" + std::to_string(i) + ".png"));
    write_image(files.back(), ramp(21, 9, 3, i).view(), {.format = PixelFormat::kU8});
  }
  StackReader as_float(files), as_bytes(files);
  StackBand f, b;
  while (as_float.read_band(4, &f)) {
    ASSERT_TRUE(as_bytes.read_band(4, &b, BandStorage::kNative8));
    ASSERT_TRUE(b.is_u8);
    ASSERT_FALSE(f.is_u8);
    ASSERT_EQ(b.bytes.size(), f.samples.size());
    EXPECT_TRUE(b.samples.empty());
    for (std::size_t k = 0; k < f.samples.size(); ++k) {
      // The same value both ways: v / 255 as a float.
      ASSERT_EQ(static_cast<float>(b.bytes[k]) / 255.0f, f.samples[k]) << k;
    }
    EXPECT_EQ(b.sample(2, 1, 20, 2), f.sample(2, 1, 20, 2));
  }
  EXPECT_FALSE(as_bytes.read_band(4, &b, BandStorage::kNative8));
  // 16-bit files are floats whatever is asked.
  write_image(dir / "deep.png", ramp(5, 5, 3).view(), {.format = PixelFormat::kU16});
  StackReader deep({dir / "deep.png"});
  ASSERT_TRUE(deep.read_band(8, &b, BandStorage::kNative8));
  EXPECT_FALSE(b.is_u8);
  EXPECT_EQ(b.samples.size(), 75u);
}

TEST(StackReader, MismatchedImagesAreErrorsNamingTheFile) {
  test::ScratchDir dir;
  write_image(dir / "a.png", ramp(8, 8, 3).view());
  write_image(dir / "b.png", ramp(8, 9, 3).view());
  write_image(dir / "c.png", ramp(8, 8, 1).view());
  try {
    StackReader r({dir / "a.png", dir / "b.png"});
    FAIL();
  } catch (const Error& e) {
    EXPECT_THAT(e.what(), HasSubstr("b.png"));
    EXPECT_THAT(e.what(), HasSubstr("same size"));
  }
  try {
    StackReader r({dir / "a.png", dir / "c.png"});
    FAIL();
  } catch (const Error& e) {
    EXPECT_THAT(e.what(), HasSubstr("c.png"));
    EXPECT_THAT(e.what(), HasSubstr("channel"));
  }
  try {
    StackReader r({dir / "a.png", dir / "gone.png"});
    FAIL();
  } catch (const Error& e) {
    EXPECT_THAT(e.what(), HasSubstr("gone.png"));
  }
  // Alpha is not a sample: RGBA reads as RGB.
  write_image(dir / "d.png", ramp(8, 8, 4).view());
  StackReader rgba({dir / "d.png"});
  EXPECT_EQ(rgba.channels(), 3);
}

TEST(StackReader, NaNInAFloatImageIsAnErrorNamingFileAndRow) {
  test::ScratchDir dir;
  // write_image refuses NaN, so write the poisoned file with OpenImageIO directly.
  std::vector<float> px(8 * 8 * 3, 0.5f);
  px[(5 * 8 + 2) * 3 + 1] = std::nanf("");
  auto out = OIIO::ImageOutput::create((dir / "nan.exr").string());
  ASSERT_TRUE(out);
  ASSERT_TRUE(
      out->open((dir / "nan.exr").string(), OIIO::ImageSpec(8, 8, 3, OIIO::TypeDesc::FLOAT)));
  ASSERT_TRUE(out->write_image(OIIO::TypeDesc::FLOAT, px.data()));
  out->close();
  StackReader r({dir / "nan.exr"});
  StackBand band;
  EXPECT_TRUE(r.read_band(4, &band));  // rows 0..3 are clean
  try {
    r.read_band(4, &band);
    FAIL() << "NaN not reported";
  } catch (const Error& e) {
    EXPECT_THAT(e.what(), HasSubstr("nan.exr"));
    EXPECT_THAT(e.what(), HasSubstr("row 5"));
  }
  EXPECT_THROW((void)read_image(dir / "nan.exr"), Error);
}

TEST(ImageIO, NormalMapsRoundTripAsFloatsOrAsHalfPlusHalf) {
  test::ScratchDir dir;
  Image n(9, 7, 3, ColourSpace::kLinear);
  for (int y = 0; y < 7; ++y)
    for (int x = 0; x < 9; ++x) {
      const Eigen::Vector3d v = Eigen::Vector3d(0.1 * x - 0.4, 0.3 - 0.1 * y, 1.0).normalized();
      for (int c = 0; c < 3; ++c) n.at(x, y, c) = static_cast<float>(v[c]);
    }
  write_normal_map(dir / "n.exr", n.view());
  write_normal_map(dir / "n.png", n.view());
  EXPECT_EQ(probe_image(dir / "n.png").format, PixelFormat::kU16);
  EXPECT_EQ(max_diff(read_normal_map(dir / "n.exr"), n), 0.0);
  // 16 bits of (n + 1) / 2: half a step of 1/65535, doubled by the decoding.
  EXPECT_LE(max_diff(read_normal_map(dir / "n.png"), n), 2.0 * kHalf16BitStep + kFloatRoundoff);
  // The PNG holds (n + 1) / 2: the zenith normal's z is stored as full scale.
  EXPECT_NEAR(read_image(dir / "n.png").at(4, 3, 2), 0.5 * (n.at(4, 3, 2) + 1.0), kU16ReadBackTol);
}

}  // namespace
}  // namespace ptmkit
