// .ptm reading: hand-written RGB, LRGB and PTM 1.1 files, foreign header spellings kept on
// rewriting, and the error of every malformed file.
#include <gtest/gtest.h>

#include <algorithm>
#include <cstddef>
#include <string>
#include <vector>

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
using test::kFloatRoundoff;
using test::read_bytes;
using test::write_bytes;

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
        EXPECT_NEAR(img.at(x, y, c), l / 255.0 * rgb / 255.0, kFloatRoundoff);
      }
      // The map keeps its convention: largest colour channel is 1.
      EXPECT_FLOAT_EQ(map.texel_colour(x, y)[0], 1.0f);
    }
  }
  write_ptm_file(dir / "copy.ptm", f);
  EXPECT_EQ(read_bytes(dir / "copy.ptm"), read_bytes(path));
}

// PTM_FORMAT_LUM: one luminance polynomial a texel, no colour. It reads as an LRGB file whose
// colour is white, so every LRGB path relights it as grey = the polynomial; written back, it
// is a PTM_FORMAT_LRGB file with the same coefficient bytes. A LUM file with a colour block
// after the luminance block (a layout no reader agrees on) is refused, not guessed.
TEST(PtmRead, LuminanceOnlyFileReadsAsGrey) {
  test::ScratchDir dir;
  const int w = 3, h = 2;  // non-square, distinct rows: a flipped row order shows
  const std::string header = "PTM_1.2\nPTM_FORMAT_LUM\n3\n2\n1 1 1 1 1 1\n0 0 0 0 0 0\n";
  Bytes lum;
  for (int sr = 0; sr < h; ++sr)
    for (int x = 0; x < w; ++x)
      for (int i = 0; i < kPtmTerms; ++i)
        lum.push_back(static_cast<std::uint8_t>(i == 5 ? 60 + 90 * sr + 20 * x : 2 * i + x));
  const fs::path path = dir / "lum.ptm";
  write_bytes(path, header, lum);

  const PtmInfo info = read_ptm_info(path);
  EXPECT_TRUE(info.luminance_only);
  EXPECT_EQ(info.format_line(), "PTM_FORMAT_LUM");
  EXPECT_EQ(info.bytes_per_texel(), kPtmTerms);
  EXPECT_EQ(info.data_bytes, lum.size());
  const PtmFile f = read_ptm_file(path);
  EXPECT_TRUE(f.luminance_only);
  ASSERT_EQ(f.format, PtmFormat::kLRGB);
  const Image img = relight(decode_ptm(f), {0, 0, 1});
  for (int y = 0; y < h; ++y) {
    for (int x = 0; x < w; ++x) {
      const double l = 60 + 90 * (h - 1 - y) + 20 * x;  // a5, file units; top row stored last
      for (int c = 0; c < 3; ++c) {
        EXPECT_EQ(f.rgb_byte(x, y, c), 255);
        EXPECT_NEAR(img.at(x, y, c), l / 255.0, kFloatRoundoff);
      }
    }
  }
  // The same bytes as an LRGB file with a white colour block relight identically.
  Bytes lrgb = lum;
  lrgb.resize(lum.size() + static_cast<std::size_t>(w) * h * 3, 255);
  write_bytes(dir / "white.ptm", "PTM_1.2\nPTM_FORMAT_LRGB\n3\n2\n1 1 1 1 1 1\n0 0 0 0 0 0\n",
              lrgb);
  const Image white = relight(decode_ptm(read_ptm_file(dir / "white.ptm")), {0.3, -0.2, 0.93});
  const Image grey = relight(decode_ptm(f), {0.3, -0.2, 0.93});
  ASSERT_EQ(grey.width() * grey.height() * grey.channels(),
            white.width() * white.height() * white.channels());
  EXPECT_TRUE(std::equal(grey.data(), grey.data() + grey.width() * grey.height() * grey.channels(),
                         white.data()));
  // Written back: PTM_FORMAT_LRGB, the same bytes as that file.
  write_ptm_file(dir / "copy.ptm", f);
  EXPECT_EQ(read_ptm_info(dir / "copy.ptm").format_line(), "PTM_FORMAT_LRGB");
  EXPECT_EQ(read_ptm_file(dir / "copy.ptm").data, lrgb);

  // Two or three colour bytes a texel after the luminance block: refused by name.
  for (const int extra : {2, 3}) {
    Bytes more = lum;
    more.resize(lum.size() + static_cast<std::size_t>(w) * h * extra, 128);
    const fs::path p = dir / ("lum" + std::to_string(extra) + ".ptm");
    write_bytes(p, header, more);
    try {
      (void)read_ptm_file(p);
      ADD_FAILURE() << p << " was accepted";
    } catch (const Error& e) {
      const std::string msg = e.what();
      EXPECT_NE(msg.find(p.filename().string()), std::string::npos) << msg;
      EXPECT_NE(msg.find("PTM_FORMAT_LUM with " + std::to_string(extra) +
                         " colour bytes a texel after the luminance block is not supported"),
                std::string::npos)
          << msg;
    }
  }
  // PTM 1.1 has no LUM variant.
  write_bytes(dir / "old.ptm", "PTM_1.1\nPTM_FORMAT_LUM\n3\n2\n1 1 1 1 1 1\n0 0 0 0 0 0\n", lum);
  EXPECT_THROW((void)read_ptm_file(dir / "old.ptm"), Error);
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
  EXPECT_NEAR(img.at(0, 0, 0), 200.0 / 255.0, kFloatRoundoff);
  EXPECT_NEAR(img.at(0, 0, 1), 200.0 / 255.0 * 128.0 / 255.0, kFloatRoundoff);
  EXPECT_NEAR(img.at(1, 0, 2), 100.0 / 255.0, kFloatRoundoff);
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

}  // namespace
}  // namespace ptmkit::texture
