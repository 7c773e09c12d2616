// JPEG .ptm files as other tools write them: round trips within JPEG loss, reference planes,
// plane inversion, decode order and side information, and the error of every malformed part.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <sstream>
#include <string>
#include <vector>

#include "formats_test_util.h"
#include "ptmkit/core/error.h"
#include "ptmkit/texture/ptm.h"
#include "test_util.h"

namespace fs = std::filesystem;

namespace ptmkit::texture {
namespace {

using test::random_file;
using test::read_text;
using test::ScratchDir;
using test::write_text;

// Quality 100 on 8-bit noise of +-2 around a ramp: within a few levels, about 1 on average.
constexpr int kMaxJpegByteError = 6;
constexpr double kMeanJpegByteError = 1.5;

TEST(JpegPtm, WrittenAndReadBackWithinJpegLoss) {
  ScratchDir dir;
  for (const PtmFormat format : {PtmFormat::kRGB, PtmFormat::kLRGB}) {
    PtmFile raw = random_file(format, 37, 21, test::test_seed());
    PtmFile jpeg = raw;
    jpeg.compression = PtmCompression::kJpeg;
    jpeg.compression_parameter = 100;
    const fs::path p = dir / "j.ptm";
    write_ptm_file(p, jpeg);
    const std::string text = read_text(p);
    EXPECT_EQ(text.rfind(format == PtmFormat::kRGB ? "PTM_1.2\nPTM_FORMAT_JPEG_RGB\n"
                                                   : "PTM_1.2\nPTM_FORMAT_JPEG_LRGB\n",
                         0),
              0u);
    const PtmFile back = read_ptm_file(p);
    EXPECT_EQ(back.format, format);
    EXPECT_EQ(back.compression, PtmCompression::kJpeg);
    EXPECT_EQ(back.compression_parameter, 100);
    EXPECT_EQ(back.quantisation, raw.quantisation);
    ASSERT_EQ(back.data.size(), raw.data.size());
    double sum = 0.0;
    int worst = 0;
    for (std::size_t i = 0; i < raw.data.size(); ++i) {
      const int d = std::abs(int{back.data[i]} - int{raw.data[i]});
      worst = std::max(worst, d);
      sum += d;
    }
    EXPECT_LE(worst, kMaxJpegByteError);
    EXPECT_LE(sum / static_cast<double>(raw.data.size()), kMeanJpegByteError);
    // Rewriting the decoded bytes raw keeps them exactly.
    PtmFile again = back;
    again.compression = PtmCompression::kNone;
    write_ptm_file(dir / "raw.ptm", again);
    EXPECT_EQ(read_ptm_file(dir / "raw.ptm").data, back.data);
  }
}

// The pieces of a JPEG .ptm written by write_ptm_file: header lines and the streams.
struct JpegParts {
  std::vector<std::string> lines;  // 14 header lines, without line ends
  std::vector<std::string> streams;
};

JpegParts split(const std::string& file, int planes) {
  JpegParts parts;
  std::size_t pos = 0;
  for (int i = 0; i < 14; ++i) {
    const std::size_t end = file.find('\n', pos);
    parts.lines.push_back(file.substr(pos, end - pos));
    pos = end + 1;
  }
  std::istringstream sizes(parts.lines[12]);
  for (int k = 0; k < planes; ++k) {
    std::size_t n = 0;
    sizes >> n;
    parts.streams.push_back(file.substr(pos, n));
    pos += n;
  }
  return parts;
}

std::string join(const JpegParts& parts, const std::vector<std::string>& side) {
  std::string out;
  for (const auto& l : parts.lines) out += l + "\n";
  for (std::size_t k = 0; k < parts.streams.size(); ++k) {
    out += parts.streams[k];
    if (!side.empty()) out += side[k];
  }
  return out;
}

std::string ints(const std::vector<long long>& v) {
  std::ostringstream s;
  for (std::size_t i = 0; i < v.size(); ++i) s << (i ? " " : "") << v[i];
  return s.str();
}

// A 16 x 8 LRGB file whose nine planes are constant (exact through JPEG at quality 100).
JpegParts constant_lrgb(const ScratchDir& dir, const std::vector<int>& values) {
  PtmFile f;
  f.format = PtmFormat::kLRGB;
  f.width = 16;
  f.height = 8;
  f.data.resize(f.texels() * 9);
  for (std::size_t i = 0; i < f.texels(); ++i) {
    for (int t = 0; t < 6; ++t) f.data[i * 6 + t] = static_cast<std::uint8_t>(values[t]);
    for (int c = 0; c < 3; ++c) {
      f.data[f.texels() * 6 + i * 3 + c] = static_cast<std::uint8_t>(values[6 + c]);
    }
  }
  f.compression = PtmCompression::kJpeg;
  f.compression_parameter = 100;
  write_ptm_file(dir / "constant.ptm", f);
  return split(read_text(dir / "constant.ptm"), 9);
}

TEST(JpegPtm, ReferencePlanesInversionOrderAndSideInformation) {
  ScratchDir dir;
  // Stored planes: 0..5 luminance, 6..8 colour.
  JpegParts parts = constant_lrgb(dir, {100, 138, 138, 10, 127, 60, 200, 128, 90});
  parts.lines[7] = ints({0, 0, 1, 0, 0, 0, 0, 0, 0});        // transforms: plane 2 inverts its ref
  parts.lines[10] = ints({0, 3, 4, 5, 1, 2, 6, 7, 8});       // decode ranks
  parts.lines[11] = ints({-1, 0, 0, 0, -1, -1, -1, 6, -1});  // references
  parts.lines[13] = ints({5, 0, 0, 0, 0, 0, 0, 10, 0});      // side information bytes
  std::vector<std::string> side(9);
  side[0] = std::string("\0\0\0\3\x4d", 5);                   // sample 3 of plane 0 := 77
  side[7] = std::string("\0\0\0\x11\x05\0\0\0\x7f\x09", 10);  // samples 17 := 5, 127 := 9
  write_text(dir / "diff.ptm", join(parts, side));
  const PtmFile f = read_ptm_file(dir / "diff.ptm");
  // JPEG raster = stored rows (bottom-up): sample 3 is (3, bottom row); 17 is (1, second row
  // from the bottom); 127 is (15, top row).
  const int bottom = f.height - 1;
  EXPECT_EQ(f.coeff_byte(3, bottom, 0, 0), 77);
  EXPECT_EQ(f.coeff_byte(4, bottom, 0, 0), 100);
  EXPECT_EQ(f.coeff_byte(0, 0, 0, 1), 138 + 100 - 128);          // difference from plane 0
  EXPECT_EQ(f.coeff_byte(3, bottom, 0, 1), 138 + 77 - 128);      // after plane 0's side info
  EXPECT_EQ(f.coeff_byte(0, 0, 0, 2), 138 + (255 - 100) - 128);  // inverted reference
  EXPECT_EQ(f.coeff_byte(0, 0, 0, 3), 10 + 100 - 128 + 256);     // negative sum wraps
  EXPECT_EQ(f.coeff_byte(5, 3, 0, 4), 127);
  EXPECT_EQ(f.rgb_byte(0, 0, 1), 128 + 200 - 128);
  EXPECT_EQ(f.rgb_byte(1, bottom - 1, 1), 5);
  EXPECT_EQ(f.rgb_byte(15, 0, 1), 9);
  EXPECT_EQ(f.rgb_byte(2, 2, 2), 90);
}

TEST(JpegPtm, MalformedFilesAreClearErrors) {
  ScratchDir dir;
  const JpegParts good = constant_lrgb(dir, {100, 110, 120, 130, 140, 150, 160, 170, 180});
  const std::string bytes = join(good, {});
  struct Case {
    std::string name;
    std::string content;
    std::string expect;
  };
  std::vector<Case> cases;
  cases.push_back({"truncated.ptm", bytes.substr(0, bytes.size() - 40), "truncated"});
  {
    // Stream 3 said 10 bytes shorter, stream 4 10 longer: the total is right, the planes not.
    JpegParts p = good;
    std::vector<long long> sizes;
    for (const auto& s : p.streams) sizes.push_back(static_cast<long long>(s.size()));
    sizes[3] -= 10;
    sizes[4] += 10;
    p.lines[12] = ints(sizes);
    cases.push_back({"stream_size.ptm", join(p, {}), "plane 3"});
  }
  {
    // A corrupted stream (its entropy-coded data overwritten) of the right declared size.
    JpegParts p = good;
    std::string& s = p.streams[5];
    for (std::size_t i = s.size() - 20; i < s.size() - 2; ++i) s[i] = '\xff';
    cases.push_back({"corrupt.ptm", join(p, {}), "plane 5"});
  }
  {
    JpegParts p = good;
    p.lines[8] = ints({0, 0, 3, 0, 0, 0, 0, 0, 0});
    cases.push_back({"motion.ptm", join(p, {}), "motion compensation"});
  }
  {
    JpegParts p = good;
    p.lines[10] = ints({0, 0, 2, 3, 4, 5, 6, 7, 8});
    cases.push_back({"order.ptm", join(p, {}), "same decode order"});
  }
  {
    JpegParts p = good;
    p.lines[11] = ints({1, -1, -1, -1, -1, -1, -1, -1, -1});  // plane 0 refers to later plane 1
    cases.push_back({"reference.ptm", join(p, {}), "not decoded before it"});
  }
  {
    JpegParts p = good;
    p.lines[13] = ints({4, 0, 0, 0, 0, 0, 0, 0, 0});
    std::vector<std::string> side(9);
    side[0] = "abcd";
    cases.push_back({"side.ptm", join(p, side), "5-byte records"});
  }
  {
    JpegParts p = good;
    p.lines[13] = ints({5, 0, 0, 0, 0, 0, 0, 0, 0});
    std::vector<std::string> side(9);
    side[0] = std::string("\0\0\x10\0\x01", 5);  // sample 4096 of a 128-sample image
    cases.push_back({"side_range.ptm", join(p, side), "outside"});
  }
  for (const Case& c : cases) {
    write_text(dir / c.name, c.content);
    try {
      (void)read_ptm_file(dir / c.name);
      ADD_FAILURE() << c.name << " was accepted";
    } catch (const Error& e) {
      const std::string msg = e.what();
      EXPECT_NE(msg.find(c.name), std::string::npos) << msg;
      EXPECT_NE(msg.find(c.expect), std::string::npos) << c.name << ": " << msg;
    }
  }
}

}  // namespace
}  // namespace ptmkit::texture
