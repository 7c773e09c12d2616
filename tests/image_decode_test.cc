// The direct decoders (JPEG, PNG, TIFF) against OpenImageIO, bounded and strict decoding,
// EXIF orientation, and the fit's real-capture input options on the command line.
#include <cmath>
#include <cstring>
#include <fstream>
#include <iterator>

#include <OpenImageIO/imageio.h>
#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "ptmkit/core/error.h"
#include "ptmkit/core/image_io.h"
#include "ptmkit/core/light_set.h"
#include "ptmkit/core/limits.h"
#include "ptmkit/core/stack_reader.h"
#include "ptmkit/texture/ptm.h"
#include "test_util.h"

namespace fs = std::filesystem;
using ::testing::HasSubstr;
using ::testing::Not;

namespace ptmkit {
namespace {

// A crop's coefficients against the whole image's, each .ptm quantised to 8 bits with its own
// scale and bias: within a quantisation step (measured worst 0.0042).
constexpr double kOwnScaleStepTol = 0.02;

std::string slurp(const fs::path& p) {
  std::ifstream in(p, std::ios::binary);
  return {std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
}
void spit(const fs::path& p, const std::string& bytes) {
  std::ofstream out(p, std::ios::binary);
  out << bytes;
}

// A textured image: smooth gradients and sharp edges (exercises the IDCT and upsampling).
Image pattern(int w, int h, int c) {
  Image img(w, h, c, ColourSpace::kSRGB);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x)
      for (int k = 0; k < c; ++k)
        img.at(x, y, k) = static_cast<float>(0.5 + 0.3 * std::sin(0.21 * x + 0.13 * y + k) +
                                             (((x / 5 + y / 7) % 2) ? 0.15 : -0.15));
  return img;
}

// What OpenImageIO decodes, in the file's own sample type, as doubles.
std::vector<double> oiio_samples(const fs::path& p, PixelFormat f, int* w, int* h, int* c) {
  auto in = OIIO::ImageInput::open(p.string());
  if (!in) return {};
  *w = in->spec().width;
  *h = in->spec().height;
  *c = in->spec().nchannels;
  const std::size_t n = static_cast<std::size_t>(*w) * *h * *c;
  std::vector<double> out(n);
  if (f == PixelFormat::kU8) {
    std::vector<std::uint8_t> v(n);
    in->read_image(0, 0, 0, *c, OIIO::TypeDesc::UINT8, v.data());
    std::copy(v.begin(), v.end(), out.begin());
  } else if (f == PixelFormat::kU16) {
    std::vector<std::uint16_t> v(n);
    in->read_image(0, 0, 0, *c, OIIO::TypeDesc::UINT16, v.data());
    std::copy(v.begin(), v.end(), out.begin());
  } else {
    std::vector<float> v(n);
    in->read_image(0, 0, 0, *c, OIIO::TypeDesc::FLOAT, v.data());
    std::copy(v.begin(), v.end(), out.begin());
  }
  return out;
}

// The direct decoders give exactly OpenImageIO's samples: JPEG (quality 95 and 75, 4:2:0 and
// grey), PNG and TIFF at 8 and 16 bits, written by OpenImageIO's own writers. (One deliberate
// difference, not compared here: OpenImageIO premultiplies a PNG's colour by its alpha; the
// direct reader keeps the stored colour, which is what was photographed.)
TEST(ImageDecode, DirectDecodersMatchOpenImageIOExactly) {
  test::ScratchDir dir;
  struct Case {
    std::string name;
    int channels;
    PixelFormat format;
    int quality;
  };
  const std::vector<Case> cases = {
      {"q95.jpg", 3, PixelFormat::kU8, 95},  {"q75.jpg", 3, PixelFormat::kU8, 75},
      {"grey.jpg", 1, PixelFormat::kU8, 90}, {"a8.png", 3, PixelFormat::kU8, 0},
      {"a16.png", 3, PixelFormat::kU16, 0},  {"t8.tif", 3, PixelFormat::kU8, 0},
      {"t16.tif", 1, PixelFormat::kU16, 0},  {"tf.tif", 3, PixelFormat::kF32, 0}};
  for (const Case& c : cases) {
    const Image img = pattern(61, 37, c.channels);  // odd sizes: partial MCUs
    const fs::path p = dir / c.name;
    auto out = OIIO::ImageOutput::create(p.string());
    ASSERT_TRUE(out);
    const OIIO::TypeDesc type = c.format == PixelFormat::kU8    ? OIIO::TypeDesc::UINT8
                                : c.format == PixelFormat::kU16 ? OIIO::TypeDesc::UINT16
                                                                : OIIO::TypeDesc::FLOAT;
    OIIO::ImageSpec spec(61, 37, c.channels, type);
    if (c.quality > 0) spec.attribute("Compression", "jpeg:" + std::to_string(c.quality));
    ASSERT_TRUE(out->open(p.string(), spec));
    ASSERT_TRUE(out->write_image(OIIO::TypeDesc::FLOAT, img.data()));
    ASSERT_TRUE(out->close());
    int w = 0, h = 0, ch = 0;
    const std::vector<double> ref = oiio_samples(p, c.format, &w, &h, &ch);
    const Image mine = read_image(p);
    ASSERT_EQ(mine.width(), w) << c.name;
    ASSERT_EQ(mine.height(), h) << c.name;
    ASSERT_EQ(mine.channels(), ch) << c.name;
    std::size_t differ = 0;
    // Back to the file's integers (exact: v / 255 in float rounds back to v).
    const double scale = c.format == PixelFormat::kU8    ? 255.0
                         : c.format == PixelFormat::kU16 ? 65535.0
                                                         : 1.0;
    for (std::size_t i = 0; i < ref.size(); ++i) {
      const double v = double(mine.data()[i]) * scale;
      differ += (scale == 1.0 ? v : std::round(v)) != ref[i];
    }
    EXPECT_EQ(differ, 0u) << c.name << ": samples differing from OpenImageIO's";
    EXPECT_EQ(probe_image(p).format, c.format) << c.name;
  }
}

TEST(ImageDecode, ColourSpaceDefaultsFollowTheSampleTypeWithoutMetadata) {
  test::ScratchDir dir;
  const Image img = pattern(8, 8, 3);
  // 16-bit TIFF without colour metadata (as dcraw -4 -T writes): linear.
  {
    auto out = OIIO::ImageOutput::create((dir / "raw16.tif").string());
    OIIO::ImageSpec spec(8, 8, 3, OIIO::TypeDesc::UINT16);
    ASSERT_TRUE(out->open((dir / "raw16.tif").string(), spec));
    ASSERT_TRUE(out->write_image(OIIO::TypeDesc::FLOAT, img.data()));
    ASSERT_TRUE(out->close());
  }
  const ImageInfo raw = probe_image(dir / "raw16.tif");
  EXPECT_EQ(raw.colour_space, ColourSpace::kLinear);
  EXPECT_FALSE(raw.colour_from_metadata);
  EXPECT_THAT(raw.colour_evidence, HasSubstr("16-bit"));
  // ptmkit's own writers record it: sRGB chunk, gAMA 1.0.
  write_image(dir / "s.png", img.view(), {.format = PixelFormat::kU16});
  EXPECT_EQ(probe_image(dir / "s.png").colour_space, ColourSpace::kSRGB);
  Image lin = img;
  lin.set_colour_space(ColourSpace::kLinear);
  write_image(dir / "l.png", lin.view(), {.format = PixelFormat::kU8});
  EXPECT_EQ(probe_image(dir / "l.png").colour_space, ColourSpace::kLinear);
}

// One entry of a big-endian EXIF IFD: SHORT (type 3) and LONG (4) hold `a`; RATIONAL (5)
// holds a / b, stored after the IFD. `count` other than 1 makes a malformed entry.
struct ExifEntry {
  unsigned tag = 0;
  unsigned type = 3;
  std::uint32_t a = 0;
  std::uint32_t b = 1;
  std::uint32_t count = 1;
  bool bad_offset = false;  // a RATIONAL whose offset points past the block
};

// A big-endian EXIF block: IFD0 with the EXIF IFD pointer (and the orientation, when given),
// then the EXIF IFD with `entries`.
std::string exif_block(const std::vector<ExifEntry>& entries, unsigned orientation = 0) {
  std::string b;
  auto u16 = [&](unsigned v) {
    b += static_cast<char>((v >> 8) & 0xFF);
    b += static_cast<char>(v & 0xFF);
  };
  auto u32 = [&](std::uint32_t v) {
    for (int k = 3; k >= 0; --k) b += static_cast<char>((v >> (8 * k)) & 0xFF);
  };
  b = {'M', 'M', 0, 42};
  u32(8);
  const std::uint32_t exif_ifd = orientation > 0 ? 38 : 26;
  u16(orientation > 0 ? 2 : 1);
  if (orientation > 0) u16(0x0112), u16(3), u32(1), u16(orientation), u16(0);
  u16(0x8769), u16(4), u32(1), u32(exif_ifd);
  u32(0);
  u16(static_cast<unsigned>(entries.size()));
  std::uint32_t values = exif_ifd + 2 + 12 * static_cast<std::uint32_t>(entries.size()) + 4;
  std::string tail;
  for (const ExifEntry& e : entries) {
    u16(e.tag), u16(e.type), u32(e.count);
    if (e.type == 3) {
      u16(e.a), u16(0);
    } else if (e.type == 4) {
      u32(e.a);
    } else {
      u32(e.bad_offset ? 100000 : values);
      const std::string save = b;
      b.clear();
      u32(e.a), u32(e.b);
      tail += b;
      b = save;
      values += 8;
    }
  }
  u32(0);
  return b + tail;
}

// A JPEG's bytes with an EXIF APP1 segment holding `tiff` inserted after the SOI.
std::string with_exif(const std::string& jpeg, const std::string& tiff) {
  const std::string payload = std::string("Exif\0\0", 6) + tiff;
  const std::size_t len = payload.size() + 2;
  std::string seg = {static_cast<char>(0xFF), static_cast<char>(0xE1), static_cast<char>(len >> 8),
                     static_cast<char>(len & 0xFF)};
  return jpeg.substr(0, 2) + seg + payload + jpeg.substr(2);
}

// A JPEG's bytes with an EXIF segment holding only an orientation.
std::string with_orientation(const std::string& jpeg, int orientation) {
  return with_exif(jpeg, exif_block({}, static_cast<unsigned>(orientation)));
}

TEST(ImageDecode, ExifOrientationIsAppliedAsViewersDo) {
  test::ScratchDir dir;
  const int w = 24, h = 16;
  write_image(dir / "base.jpg", pattern(w, h, 3).view(), {.jpeg_quality = 90});
  const Image base = read_image(dir / "base.jpg");
  const std::string bytes = slurp(dir / "base.jpg");
  // Where stored pixel (x, y) appears for each orientation (the TIFF/EXIF definitions).
  const auto displayed = [&](int o, int x, int y, int* dx, int* dy) {
    switch (o) {
      case 1:
        *dx = x;
        *dy = y;
        break;
      case 2:
        *dx = w - 1 - x;
        *dy = y;
        break;
      case 3:
        *dx = w - 1 - x;
        *dy = h - 1 - y;
        break;
      case 4:
        *dx = x;
        *dy = h - 1 - y;
        break;
      case 5:
        *dx = y;
        *dy = x;
        break;
      case 6:
        *dx = h - 1 - y;
        *dy = x;
        break;
      case 7:
        *dx = h - 1 - y;
        *dy = w - 1 - x;
        break;
      case 8:
        *dx = y;
        *dy = w - 1 - x;
        break;
    }
  };
  for (int o = 1; o <= 8; ++o) {
    // Built with append: GCC 12 warns falsely (-Wrestrict) on "literal" + std::string.
    const fs::path p = dir / std::string("o").append(std::to_string(o)).append(".jpg");
    spit(p, with_orientation(bytes, o));
    const ImageInfo info = probe_image(p);
    EXPECT_EQ(info.orientation, o);
    const Image img = read_image(p);
    ASSERT_EQ(img.width(), o >= 5 ? h : w) << o;
    ASSERT_EQ(img.height(), o >= 5 ? w : h) << o;
    int bad = 0;
    for (int y = 0; y < h; ++y)
      for (int x = 0; x < w; ++x) {
        int dx = 0, dy = 0;
        displayed(o, x, y, &dx, &dy);
        for (int c = 0; c < 3; ++c) bad += img.at(dx, dy, c) != base.at(x, y, c);
      }
    EXPECT_EQ(bad, 0) << "orientation " << o;
    // The stack reader turns it the same way.
    const std::vector<Image> stack = read_stack({p});
    ASSERT_EQ(stack[0].width(), img.width());
    EXPECT_EQ(std::memcmp(stack[0].data(), img.data(), img.size() * sizeof(float)), 0) << o;
  }
  // Mixed orientations in one capture: an error naming both files.
  try {
    StackReader reader({dir / "o1.jpg", dir / "o6.jpg"});
    FAIL() << "mixed orientations accepted";
  } catch (const Error& e) {
    EXPECT_THAT(e.what(), HasSubstr("o6.jpg"));
    EXPECT_THAT(e.what(), HasSubstr("o1.jpg"));
    EXPECT_THAT(e.what(), HasSubstr("orientation"));
  }
}

TEST(ImageDecode, TruncatedJpegIsAnErrorUnlessDamageIsAllowed) {
  test::ScratchDir dir;
  write_image(dir / "full.jpg", pattern(64, 64, 3).view());
  const std::string bytes = slurp(dir / "full.jpg");
  spit(dir / "cut.jpg", bytes.substr(0, bytes.size() * 85 / 100));
  try {
    (void)read_image(dir / "cut.jpg");
    FAIL() << "truncated JPEG accepted";
  } catch (const Error& e) {
    EXPECT_THAT(e.what(), HasSubstr("cut.jpg"));
    EXPECT_THAT(e.what(), HasSubstr("damaged"));
  }
  EXPECT_THROW((void)read_stack({dir / "cut.jpg"}), Error);
  const Image repaired = read_image(dir / "cut.jpg", {.allow_damaged = true});
  EXPECT_EQ(repaired.width(), 64);
}

// Images read through OpenImageIO are decoded a megabyte of rows at a time and handed out in
// the stack reader's bands: an image (planes stored separately, a layout the direct TIFF
// reader leaves to OpenImageIO) whose chunks end inside bands reads exactly what
// OpenImageIO gives for the whole image.
TEST(ImageDecode, RowsReadThroughOpenImageIOInChunksMatchItsWholeImage) {
  test::ScratchDir dir;
  const fs::path p = dir / "tall.tif";
  const int w = 300;
  const int h = 2500;  // 900 bytes a row: chunks of 1165 rows, not a multiple of 64
  {
    auto out = OIIO::ImageOutput::create(p.string());
    ASSERT_TRUE(out);
    OIIO::ImageSpec spec(w, h, 3, OIIO::TypeDesc::UINT8);
    spec.attribute("tiff:planarconfig", "separate");
    spec.attribute("compression", "none");
    ASSERT_TRUE(out->open(p.string(), spec));
    std::vector<std::uint8_t> px(static_cast<std::size_t>(w) * h * 3);
    for (std::size_t k = 0; k < px.size(); ++k) px[k] = static_cast<std::uint8_t>(k * 7 + k / 97);
    ASSERT_TRUE(out->write_image(OIIO::TypeDesc::UINT8, px.data()));
    ASSERT_TRUE(out->close());
  }
  int rw = 0, rh = 0, rc = 0;
  const std::vector<double> ref = oiio_samples(p, PixelFormat::kU8, &rw, &rh, &rc);
  const std::vector<Image> stack = read_stack({p});
  ASSERT_EQ(stack.size(), 1u);
  ASSERT_EQ(stack[0].width(), w);
  ASSERT_EQ(stack[0].height(), h);
  ASSERT_EQ(ref.size(), static_cast<std::size_t>(w) * h * 3);
  std::size_t differ = 0;
  for (std::size_t i = 0; i < ref.size(); ++i) {
    differ += std::round(double(stack[0].data()[i]) * 255.0) != ref[i];
  }
  EXPECT_EQ(differ, 0u);
}

// A progressive JPEG written by OpenImageIO (libjpeg's standard progression: 10 scans).
std::string progressive_jpeg(const fs::path& p, const Image& img) {
  auto out = OIIO::ImageOutput::create(p.string());
  OIIO::ImageSpec spec(img.width(), img.height(), img.channels(), OIIO::TypeDesc::UINT8);
  spec.attribute("jpeg:progressive", 1);
  if (!out || !out->open(p.string(), spec) ||
      !out->write_image(OIIO::TypeDesc::FLOAT, img.data()) || !out->close()) {
    return {};
  }
  return slurp(p);
}

// The frame header's height and width (bytes 5-8 after the SOF marker) set to w x h.
void set_frame_size(std::string* jpeg, std::size_t sof, int w, int h) {
  (*jpeg)[sof + 5] = static_cast<char>(h >> 8);
  (*jpeg)[sof + 6] = static_cast<char>(h & 0xFF);
  (*jpeg)[sof + 7] = static_cast<char>(w >> 8);
  (*jpeg)[sof + 8] = static_cast<char>(w & 0xFF);
}

// A JPEG of several scans is decoded into a buffer of all its coefficients (128 bytes per
// block and component) before its first row: libjpeg would allocate 2.7 GB for a 521-byte
// file declaring 30000 x 30000 (4:2:0). What the file can hold, the memory available and the number
// of scans are checked first, and a cut-short file stops at the damage.
TEST(ImageDecode, JpegOfSeveralScansIsBoundedBeforeDecoding) {
  test::ScratchDir dir;
  const std::string bytes = progressive_jpeg(dir / "prog.jpg", pattern(64, 48, 3));
  const std::size_t sof = bytes.find("\xFF\xC2");
  ASSERT_NE(sof, std::string::npos) << "OpenImageIO did not write a progressive JPEG";
  EXPECT_EQ(read_image(dir / "prog.jpg").width(), 64);

  // Huffman-coded: every block takes at least a bit in its DC scan.
  std::string huge = bytes;
  set_frame_size(&huge, sof, 30000, 30000);
  spit(dir / "huge.jpg", huge);
  try {
    (void)read_image(dir / "huge.jpg");
    FAIL() << "a 30000 x 30000 progressive JPEG in " << huge.size() << " bytes was accepted";
  } catch (const Error& e) {
    EXPECT_THAT(e.what(), HasSubstr("huge.jpg"));
    EXPECT_THAT(e.what(), HasSubstr("cannot hold"));
  }

  // Arithmetic-coded (SOF10): no bound from the file's size; the coefficient buffer is
  // checked against the memory available (here capped at 512 MiB).
  std::string arith = huge;
  arith[sof + 1] = static_cast<char>(0xCA);
  spit(dir / "arith.jpg", arith);
  set_memory_budget_bytes(std::uint64_t{512} << 20);
  try {
    (void)read_image(dir / "arith.jpg");
    ADD_FAILURE() << "a 30000 x 30000 coefficient buffer was allocated past the budget";
  } catch (const Error& e) {
    EXPECT_THAT(e.what(), HasSubstr("arith.jpg"));
    EXPECT_THAT(e.what(), HasSubstr("coefficients of this 30000x30000 JPEG"));
  }
  set_memory_budget_bytes(0);

  // The same huge file with a stray byte after its start-of-image marker: libjpeg skips it
  // (OpenImageIO's reader would then allocate the whole coefficient buffer, 2.7 GB), so a file
  // that starts FF D8 is the bounded JPEG decoder's whatever byte follows.
  std::string stray = huge;
  stray.insert(2, 1, static_cast<char>(0xFD));
  spit(dir / "stray.jpg", stray);
  try {
    (void)read_image(dir / "stray.jpg");
    FAIL() << "a 30000 x 30000 progressive JPEG after a stray byte was accepted";
  } catch (const Error& e) {
    EXPECT_THAT(e.what(), HasSubstr("stray.jpg"));
    EXPECT_THAT(e.what(), HasSubstr("cannot hold"));
  }

  // Cut short: an error at the damage unless damage is allowed.
  spit(dir / "cut.jpg", bytes.substr(0, bytes.size() / 2));
  try {
    (void)read_image(dir / "cut.jpg");
    FAIL() << "truncated progressive JPEG accepted";
  } catch (const Error& e) {
    EXPECT_THAT(e.what(), HasSubstr("cut.jpg"));
    EXPECT_THAT(e.what(), HasSubstr("damaged"));
  }
  EXPECT_EQ(read_image(dir / "cut.jpg", {.allow_damaged = true}).width(), 64);

  // 600 more copies of the last scan (before the end-of-image marker): past the scan limit,
  // even where damage (this is a bogus progression) is allowed.
  const std::size_t last_scan = bytes.rfind("\xFF\xDA");
  const std::size_t eoi = bytes.rfind("\xFF\xD9");
  ASSERT_NE(last_scan, std::string::npos);
  ASSERT_NE(eoi, std::string::npos);
  ASSERT_LT(last_scan, eoi);
  std::string many = bytes.substr(0, eoi);
  for (int k = 0; k < 600; ++k) many += bytes.substr(last_scan, eoi - last_scan);
  many += bytes.substr(eoi);
  spit(dir / "scans.jpg", many);
  for (const bool allow : {false, true}) {
    try {
      (void)read_image(dir / "scans.jpg", {.allow_damaged = allow});
      ADD_FAILURE() << "a JPEG of 610 scans was accepted (damage allowed: " << allow << ")";
    } catch (const Error& e) {
      EXPECT_THAT(e.what(), HasSubstr("scans.jpg"));
      if (allow) {
        EXPECT_THAT(e.what(), HasSubstr("more than 500 scans"));
      }
    }
  }
}

// A layout the direct TIFF reader leaves to OpenImageIO (planes stored separately), its last
// strips cut off: OpenImageIO fills what it cannot read and says so; that is damaged data too.
TEST(ImageDecode, DamagedDataOpenImageIOFillsInIsAnErrorUnlessAllowed) {
  test::ScratchDir dir;
  {
    auto out = OIIO::ImageOutput::create((dir / "planar.tif").string());
    ASSERT_TRUE(out);
    OIIO::ImageSpec spec(64, 64, 3, OIIO::TypeDesc::UINT8);
    spec.attribute("tiff:planarconfig", "separate");
    spec.attribute("compression", "none");
    spec.attribute("tiff:RowsPerStrip", 8);
    ASSERT_TRUE(out->open((dir / "planar.tif").string(), spec));
    std::vector<std::uint8_t> px(64 * 64 * 3);
    for (std::size_t k = 0; k < px.size(); ++k) px[k] = static_cast<std::uint8_t>(k * 7);
    ASSERT_TRUE(out->write_image(OIIO::TypeDesc::UINT8, px.data()));
    ASSERT_TRUE(out->close());
  }
  ASSERT_EQ(read_image(dir / "planar.tif").width(), 64);
  std::string bytes = slurp(dir / "planar.tif");
  // The last entry of StripOffsets (tag 273) pointed far beyond the file's end.
  auto u32_at = [&](std::size_t at) {
    std::uint32_t v = 0;
    std::memcpy(&v, bytes.data() + at, 4);
    return v;
  };
  ASSERT_EQ(bytes.substr(0, 2), "II");
  const std::uint32_t ifd = u32_at(4);
  std::uint16_t entries = 0;
  std::memcpy(&entries, bytes.data() + ifd, 2);
  std::size_t last = 0;
  std::size_t width = 0;
  for (std::uint16_t e = 0; e < entries; ++e) {
    const std::size_t at = ifd + 2 + 12 * std::size_t{e};
    std::uint16_t tag = 0;
    std::uint16_t type = 0;
    std::memcpy(&tag, bytes.data() + at, 2);
    std::memcpy(&type, bytes.data() + at + 2, 2);
    if (tag != 273) continue;
    width = type == 3 ? 2 : 4;
    const std::uint32_t count = u32_at(at + 4);
    ASSERT_GT(count * width, 4U) << "strip offsets held inline";
    last = u32_at(at + 8) + (count - 1) * width;
  }
  ASSERT_NE(width, 0U) << "no StripOffsets";
  ASSERT_LT(last + width, bytes.size());
  for (std::size_t k = 0; k < width; ++k) bytes[last + k] = static_cast<char>(0x7F);
  spit(dir / "damaged.tif", bytes);
  try {
    (void)read_stack({dir / "damaged.tif"});
    FAIL() << "damaged planar TIFF accepted";
  } catch (const Error& e) {
    EXPECT_THAT(e.what(), HasSubstr("damaged.tif"));
    EXPECT_THAT(e.what(), HasSubstr("damaged image data"));
  }
  EXPECT_EQ(read_image(dir / "damaged.tif", {.allow_damaged = true}).width(), 64);
}

TEST(ImageDecode, DeclaredSizeIsBoundedBeforeDecoding) {
  test::ScratchDir dir;
  write_image(dir / "small.jpg", pattern(16, 16, 3).view());
  std::string bytes = slurp(dir / "small.jpg");
  // Patch the frame header (SOF0: FF C0, length, precision, height, width) to 65500 x 65500.
  const std::size_t sof = bytes.find("\xFF\xC0");
  ASSERT_NE(sof, std::string::npos);
  for (std::size_t k : {sof + 5, sof + 7}) {
    bytes[k] = static_cast<char>(0xFF);
    bytes[k + 1] = static_cast<char>(0xDC);
  }
  spit(dir / "huge.jpg", bytes);
  try {
    (void)probe_image(dir / "huge.jpg");
    FAIL() << "a 65500 x 65500 claim in a small file was accepted";
  } catch (const Error& e) {
    EXPECT_THAT(e.what(), HasSubstr("cannot hold"));
  }
  // A text chunk declaring 1.6 GB in a small PNG (libpng would allocate it before reading).
  write_image(dir / "small.png", pattern(8, 8, 3).view());
  std::string png = slurp(dir / "small.png");
  const std::size_t after_ihdr = 8 + 8 + 13 + 4;
  png.insert(after_ihdr, std::string("\x63\x68\x6C\x69tEXtkey\0value", 17));
  spit(dir / "text.png", png);
  try {
    (void)probe_image(dir / "text.png");
    FAIL() << "a 1.6 GB text chunk in a small PNG was accepted";
  } catch (const Error& e) {
    EXPECT_THAT(e.what(), HasSubstr("tEXt chunk declares 1667787881 bytes"));
  }
  // Not a regular file: refused before reading.
  EXPECT_THROW((void)probe_image("/dev/zero"), Error);
}

// OpenEXR trusts its header: an attribute's declared size is allocated before it is read and
// the chunk offset table is sized from the data window. Both are checked against the file first.
TEST(ImageDecode, ExrHeaderIsBoundedByTheFileBeforeOpenExrReadsIt) {
  test::ScratchDir dir;
  write_image(dir / "ok.exr", pattern(16, 16, 3).view(), {.format = PixelFormat::kF32});
  EXPECT_EQ(read_image(dir / "ok.exr").width(), 16);
  const std::string good = slurp(dir / "ok.exr");
  auto put_i32 = [](std::string* bytes, std::size_t at, std::uint32_t v) {
    for (int k = 0; k < 4; ++k) (*bytes)[at + k] = static_cast<char>((v >> (8 * k)) & 0xFF);
  };
  auto expect_refused = [&](const std::string& name, const std::string& bytes,
                            const std::string& why) {
    spit(dir / name, bytes);
    for (int pass = 0; pass < 2; ++pass) {
      try {
        if (pass == 0) {
          (void)probe_image(dir / name);
        } else {
          (void)read_stack({dir / name});
        }
        ADD_FAILURE() << name << " was accepted";
      } catch (const Error& e) {
        EXPECT_THAT(e.what(), HasSubstr(name));
        EXPECT_THAT(e.what(), HasSubstr(why));
      }
    }
  };
  // An attribute declaring 1.8 GB in a file of a few hundred bytes.
  const std::string attr("compression\0compression\0", 24);
  const std::size_t at = good.find(attr);
  ASSERT_NE(at, std::string::npos);
  std::string huge_attr = good;
  put_i32(&huge_attr, at + attr.size(), 0x6D500000U);
  expect_refused("attr.exr", huge_attr, "declares 1833959424 bytes, but the file has");
  // A data window of 16 x 200001 pixels: its offset table alone needs more than the file.
  const std::string window("dataWindow\0box2i\0", 17);
  const std::size_t w = good.find(window);
  ASSERT_NE(w, std::string::npos);
  std::string tall = good;
  put_i32(&tall, w + window.size() + 4 + 12, 200000);
  expect_refused("tall.exr", tall, "cannot hold");
  // A window past the largest side accepted.
  std::string wide = good;
  put_i32(&wide, w + window.size() + 4 + 8, 0x7FFFFFF0U);
  expect_refused("wide.exr", wide, "exceeds the largest side accepted");
  // A channel list whose declared size disagrees with its content (OpenEXR reads the content).
  const std::string chlist("channels\0chlist\0", 16);
  const std::size_t c = good.find(chlist);
  ASSERT_NE(c, std::string::npos);
  std::string off_by_one = good;
  std::uint32_t declared = 0;
  std::memcpy(&declared, good.data() + c + chlist.size(), 4);
  put_i32(&off_by_one, c + chlist.size(), declared + 1);
  expect_refused("chlist.exr", off_by_one, "does not fill its declared size");
  // Deep images (the version field's deep flag) are not photographs.
  std::string deep = good;
  deep[5] = static_cast<char>(deep[5] | 0x08);
  expect_refused("deep.exr", deep, "deep OpenEXR");
  // Cut inside the header.
  expect_refused("cut.exr", good.substr(0, at + 10), "ends inside the header");
}

TEST(ImageDecode, ErrorMessagesQuoteOnlyAShortPrintableExcerpt) {
  const std::string long_name(50000, 'a');
  const std::string w = where(fs::path(long_name + "\x01\x7f.jpg"));
  EXPECT_LT(w.size(), 2 * kMaxExcerptBytes);
  EXPECT_THAT(w, HasSubstr("bytes"));
  EXPECT_THAT(w, HasSubstr(".jpg"));
  EXPECT_THAT(excerpt(std::string("a\x01\x02z", 4)), HasSubstr("\\x01"));
  EXPECT_EQ(excerpt("caf\xC3\xA9.jpg"), "caf\xC3\xA9.jpg");  // UTF-8 names stay readable
}

// A write that fails (here the file-size limit, as a full disk would) is an error and leaves
// no file: the PNG encoder's status and the close are checked.
TEST(ImageDecode, PngWriteFailureIsAnErrorAndLeavesNoFile) {
  test::ScratchDir dir;
  // Run the binary with a 4 KiB file-size limit (SIGXFSZ ignored: write() then fails).
  const std::string cmd = "cd '" + dir.path().string() +
                          "' && (trap '' XFSZ; ulimit -f 4; exec '" PTMKIT_BINARY
                          "' synth --out cap --width 200 --height 150 --no-truth) >out.txt 2>&1; "
                          "echo $? > rc.txt";
  ASSERT_EQ(std::system(cmd.c_str()), 0);
  EXPECT_NE(slurp(dir / "rc.txt"), "0\n") << slurp(dir / "out.txt");
  EXPECT_THAT(slurp(dir / "out.txt"), HasSubstr("write failed"));
  // Any image left is complete (written before the limit was reached), never a truncated one.
  if (fs::exists(dir / "cap")) {
    for (const auto& e : fs::directory_iterator(dir / "cap")) {
      if (e.path().extension() == ".png") {
        EXPECT_NO_THROW((void)read_image(e.path())) << e.path();
      }
    }
  }
}

// ---- fit on a real capture: crop, mask, lights reuse, colour space ----

struct Capture {
  test::ScratchDir dir;
  fs::path lp;
  Capture() {
    const auto r = test::run_ptmkit({"synth", "--out", (dir / "cap").string(), "--width", "40",
                                     "--height", "30", "--no-truth"});
    EXPECT_EQ(r.exit_code, 0) << r.err;
    lp = dir / "cap" / "lights.lp";
  }
};

TEST(FitInputCli, CropFitsOnlyTheRectangleWithTheSameCoefficients) {
  Capture cap;
  const fs::path full = cap.dir / "full.ptm", crop = cap.dir / "crop.ptm";
  auto r = test::run_ptmkit({"fit", cap.lp.string(), "-o", full.string()});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  r = test::run_ptmkit({"fit", cap.lp.string(), "-o", crop.string(), "--crop", "5,7,20,11",
                        "--report", (cap.dir / "r.json").string()});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const CoefficientMap a = texture::read_ptm(full);
  const CoefficientMap b = texture::read_ptm(crop);
  ASSERT_EQ(b.width, 20);
  ASSERT_EQ(b.height, 11);
  double worst = 0.0;
  for (int y = 0; y < 11; ++y)
    for (int x = 0; x < 20; ++x)
      for (int k = 0; k < 18; ++k)
        worst = std::max(worst, std::abs(double(a.texel_coeffs(x + 5, y + 7)[k]) -
                                         double(b.texel_coeffs(x, y)[k])));
  EXPECT_LT(worst, kOwnScaleStepTol);
  EXPECT_THAT(slurp(cap.dir / "r.json"), HasSubstr("\"x\": 5"));
  // Outside the image: an error, no output.
  r = test::run_ptmkit(
      {"fit", cap.lp.string(), "-o", (cap.dir / "bad.ptm").string(), "--crop", "30,20,20,20"});
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_THAT(r.err, HasSubstr("does not lie inside"));
  EXPECT_FALSE(fs::exists(cap.dir / "bad.ptm"));
  r = test::run_ptmkit(
      {"fit", cap.lp.string(), "-o", (cap.dir / "bad.ptm").string(), "--crop", "1,2,3"});
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_FALSE(fs::exists(cap.dir / "bad.ptm"));
}

TEST(FitInputCli, MaskSelectsItsBoundingBoxAndBlackensTheRest) {
  Capture cap;
  Image mask(40, 30, 1, ColourSpace::kLinear, 0.0f);
  for (int y = 10; y < 20; ++y)
    for (int x = 8; x < 30; ++x) mask.at(x, y, 0) = (x + y) % 3 == 0 ? 0.0f : 1.0f;
  write_image(cap.dir / "mask.png", mask.view());
  const fs::path out = cap.dir / "m.ptm";
  auto r = test::run_ptmkit(
      {"fit", cap.lp.string(), "-o", out.string(), "--mask", (cap.dir / "mask.png").string()});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const CoefficientMap m = texture::read_ptm(out);
  EXPECT_EQ(m.width, 22);
  EXPECT_EQ(m.height, 10);
  // A mask of another size: an error naming it, no output.
  write_image(cap.dir / "small.png", Image(20, 30, 1, ColourSpace::kLinear, 1.0f).view());
  r = test::run_ptmkit({"fit", cap.lp.string(), "-o", (cap.dir / "bad.ptm").string(), "--mask",
                        (cap.dir / "small.png").string()});
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_THAT(r.err, HasSubstr("small.png"));
  EXPECT_FALSE(fs::exists(cap.dir / "bad.ptm"));
}

TEST(FitInputCli, LightsFromAnotherCaptureApplyToTheImagesGiven) {
  Capture cap;
  const LightSet lights = read_lp(cap.lp);
  // Copy the images elsewhere under other names: another capture of the same rig.
  fs::create_directories(cap.dir / "obj");
  std::vector<std::string> args = {"fit", "--lights", cap.lp.string(), "-o",
                                   (cap.dir / "reuse.ptm").string()};
  for (std::size_t i = 0; i < lights.size(); ++i) {
    const fs::path p = cap.dir / "obj" / ("photo" + std::to_string(i) + ".png");
    fs::copy_file(lights.lights[i].image, p);
    args.push_back(p.string());
  }
  auto r = test::run_ptmkit(args);
  ASSERT_EQ(r.exit_code, 0) << r.err;
  r = test::run_ptmkit({"fit", cap.lp.string(), "-o", (cap.dir / "own.ptm").string()});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_EQ(slurp(cap.dir / "reuse.ptm"), slurp(cap.dir / "own.ptm"));
  args.pop_back();  // one image short
  args[4] = (cap.dir / "short.ptm").string();
  r = test::run_ptmkit(args);
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_THAT(r.err, HasSubstr("lights but"));
  EXPECT_FALSE(fs::exists(cap.dir / "short.ptm"));
}

TEST(FitInputCli, InputColourSpaceIsAppliedAndReported) {
  Capture cap;
  for (const std::string cs : {"srgb", "linear"}) {
    const fs::path rep = cap.dir / (cs + ".json");
    auto r = test::run_ptmkit({"fit", cap.lp.string(), "-o", (cap.dir / (cs + ".ptm")).string(),
                               "--input-colour-space", cs, "--report", rep.string()});
    ASSERT_EQ(r.exit_code, 0) << r.err;
    EXPECT_THAT(slurp(rep), HasSubstr("--input-colour-space " + cs));
  }
  auto r = test::run_ptmkit({"fit", cap.lp.string(), "-o", (cap.dir / "x.ptm").string(),
                             "--input-colour-space", "gamma"});
  EXPECT_NE(r.exit_code, 0);
  EXPECT_FALSE(fs::exists(cap.dir / "x.ptm"));
}

TEST(FitInputCli, LightFileThatIsADeviceFailsFast) {
  test::ScratchDir dir;
  const auto r = test::run_ptmkit({"fit", "/dev/zero", "-o", (dir / "z.ptm").string()});
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_THAT(r.err, HasSubstr("not a regular file"));
}

// ---- The focal length cameras record in EXIF ----

TEST(ImageDecode, FocalLengthInPixelsFromTheCamerasExif) {
  test::ScratchDir dir;
  const int w = 40, h = 30;
  write_image(dir / "base.jpg", pattern(w, h, 3).view());
  const std::string bytes = slurp(dir / "base.jpg");
  EXPECT_EQ(probe_image(dir / "base.jpg").focal_px, 0.0);  // no EXIF: not said
  const auto focal = [&](const std::vector<ExifEntry>& entries, std::string* evidence = nullptr) {
    spit(dir / "e.jpg", with_exif(bytes, exif_block(entries)));
    const ImageInfo info = probe_image(dir / "e.jpg");
    if (evidence != nullptr) *evidence = info.focal_evidence;
    return info.focal_px;
  };
  // A 50 mm lens, 4000 sensor pixels per inch, the camera's image 6000 pixels wide (a 38 mm
  // sensor) and this copy 40: 50 mm x 4000 / 25.4 pixels per mm x 40 / 6000.
  const ExifEntry lens{0x920A, 5, 50, 1};
  const ExifEntry pitch{0xA20E, 5, 4000, 1};
  const ExifEntry inch{0xA210, 3, 2};
  const ExifEntry recorded{0xA002, 4, 6000};
  const ExifEntry equivalent{0xA405, 3, 28};
  std::string evidence;
  EXPECT_NEAR(focal({lens, recorded, pitch, inch, equivalent}, &evidence),
              50.0 * 4000.0 / 25.4 * w / 6000.0, 1e-9);
  EXPECT_THAT(evidence, HasSubstr("FocalPlaneXResolution"));
  // The pitch in pixels per cm, for this width (no PixelXDimension: a 2.5 mm sensor).
  EXPECT_NEAR(focal({lens, {0xA20E, 5, 160, 1}, {0xA210, 3, 3}}), 50.0 * 16.0, 1e-9);
  // Only the 35 mm equivalent: over the frame's diagonal (43.27 mm).
  const double from_equivalent = 28.0 * std::hypot(w, h) / std::hypot(36.0, 24.0);
  EXPECT_NEAR(focal({equivalent}, &evidence), from_equivalent, 1e-9);
  EXPECT_THAT(evidence, HasSubstr("FocalLengthIn35mmFilm"));
  // A pitch implying a sensor over 100 mm wide is not believed: the equivalent is taken.
  EXPECT_NEAR(focal({lens, {0xA20E, 5, 1, 1}, inch, equivalent}), from_equivalent, 1e-9);
  // The lens alone gives no pixels; malformed entries are ignored.
  EXPECT_EQ(focal({lens}), 0.0);
  EXPECT_EQ(focal({{0x920A, 5, 50, 1, 1, true}, pitch, inch}), 0.0);
  EXPECT_EQ(focal({lens, {0xA20E, 5, 4000, 0}, inch}), 0.0);  // zero denominator
  EXPECT_EQ(focal({{0xA405, 3, 28, 1, 2}}), 0.0);             // two values
  EXPECT_EQ(focal({lens, pitch, {0xA210, 3, 9}}), 0.0);       // unknown unit
  // The same in pixels whatever the orientation.
  spit(dir / "r.jpg", with_exif(bytes, exif_block({lens, recorded, pitch, inch}, 6)));
  const ImageInfo rotated = probe_image(dir / "r.jpg");
  EXPECT_EQ(rotated.orientation, 6);
  EXPECT_EQ(rotated.width, h);
  EXPECT_NEAR(rotated.focal_px, 50.0 * 4000.0 / 25.4 * w / 6000.0, 1e-9);
}

// A PNG's bytes with an eXIf chunk holding `tiff` after the IHDR chunk.
std::string with_png_exif(const std::string& png, const std::string& tiff) {
  const std::string body = "eXIf" + tiff;
  std::uint32_t crc = 0xFFFFFFFFu;
  for (const char ch : body) {
    crc ^= static_cast<unsigned char>(ch);
    for (int k = 0; k < 8; ++k) crc = (crc >> 1) ^ (0xEDB88320u & (0u - (crc & 1u)));
  }
  crc ^= 0xFFFFFFFFu;
  auto be32 = [](std::uint32_t v) {
    return std::string{static_cast<char>(v >> 24), static_cast<char>((v >> 16) & 0xFF),
                       static_cast<char>((v >> 8) & 0xFF), static_cast<char>(v & 0xFF)};
  };
  const std::size_t after_ihdr = 8 + 25;
  return png.substr(0, after_ihdr) + be32(static_cast<std::uint32_t>(tiff.size())) + body +
         be32(crc) + png.substr(after_ihdr);
}

TEST(ImageDecode, PngExifGivesTheOrientationAndTheFocalLength) {
  test::ScratchDir dir;
  const int w = 40, h = 30;
  write_image(dir / "base.png", pattern(w, h, 3).view());
  spit(dir / "e.png", with_png_exif(slurp(dir / "base.png"), exif_block({{0xA405, 3, 28}}, 6)));
  const ImageInfo info = probe_image(dir / "e.png");
  EXPECT_EQ(info.orientation, 6);
  EXPECT_EQ(info.width, h);
  EXPECT_NEAR(info.focal_px, 28.0 * std::hypot(w, h) / std::hypot(36.0, 24.0), 1e-9);
  EXPECT_EQ(read_image(dir / "e.png").width(), h);
}

// TIFF files give the same EXIF facts, whether OpenImageIO reads them (as it reads camera RAW
// and EXR) or core does.
TEST(ImageDecode, FocalLengthFromExifThroughOpenImageIO) {
  test::ScratchDir dir;
  const int w = 48, h = 32;
  const fs::path path = dir / "tiled.tif";
  OIIO::ImageSpec spec(w, h, 3, OIIO::TypeDesc::UINT8);
  spec.tile_width = 16;
  spec.tile_height = 16;
  spec.attribute("Exif:FocalLength", 35.0f);
  spec.attribute("Exif:FocalPlaneXResolution", 2.0f);  // per mm: a 24 mm sensor
  spec.attribute("Exif:FocalPlaneResolutionUnit", 4);
  auto out = OIIO::ImageOutput::create(path.string());
  ASSERT_TRUE(out && out->open(path.string(), spec));
  const std::vector<unsigned char> pixels(static_cast<std::size_t>(w * h * 3), 100);
  ASSERT_TRUE(out->write_image(OIIO::TypeDesc::UINT8, pixels.data()));
  out->close();
  const ImageInfo info = probe_image(path);
  EXPECT_NEAR(info.focal_px, 70.0, 1e-4) << info.focal_evidence;

  // A strip TIFF (what raw converters write), read by core's own TIFF reader: the same, and
  // its rows read after the EXIF directory was visited.
  const fs::path strips = dir / "strips.tif";
  spec.tile_width = spec.tile_height = 0;
  spec.attribute("Exif:PixelXDimension", 2 * w);  // this copy is half the camera's width
  out = OIIO::ImageOutput::create(strips.string());
  ASSERT_TRUE(out && out->open(strips.string(), spec));
  ASSERT_TRUE(out->write_image(OIIO::TypeDesc::UINT8, pixels.data()));
  out->close();
  const ImageInfo strip_info = probe_image(strips);
  EXPECT_NEAR(strip_info.focal_px, 35.0, 1e-4) << strip_info.focal_evidence;
  const Image img = read_image(strips);
  EXPECT_NEAR(img.at(w - 1, h - 1, 2), 100.0f / 255.0f, 1e-6f);
}

TEST(ImageDecode, JpegWrittenWithACameraRecordsItsFocalLength) {
  test::ScratchDir dir;
  ImageWriteOptions o;
  o.exif_camera = ImageWriteOptions::ExifCamera{47.0, 23.5};
  write_image(dir / "c.jpg", pattern(64, 36, 3).view(), o);
  const ImageInfo info = probe_image(dir / "c.jpg");
  EXPECT_NEAR(info.focal_px, 47.0 / 23.5 * 64, 1e-3);
  EXPECT_THAT(info.focal_evidence, HasSubstr("FocalLength 47 mm"));
  o.exif_camera = ImageWriteOptions::ExifCamera{0.0, 23.5};
  EXPECT_THROW(write_image(dir / "bad.jpg", pattern(64, 36, 3).view(), o), Error);
  EXPECT_FALSE(fs::exists(dir / "bad.jpg"));
}

}  // namespace
}  // namespace ptmkit
