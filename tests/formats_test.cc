// Reading what other tools write and converting between formats: JPEG .ptm variants (planes,
// references, plane inversion, side information), negative biases, .rti line ends, relight /
// OpenLIME web folders (image and deep-zoom layouts), the one wording of every refusal, the
// conversions of `ptmkit export ptm|rti`, and the real sample files checked against an
// evaluation written here from the formats' descriptions.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <fstream>
#include <iterator>
#include <random>
#include <sstream>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "ptmkit/core/error.h"
#include "ptmkit/core/hsh.h"
#include "ptmkit/core/image_io.h"
#include "ptmkit/texture/convert.h"
#include "ptmkit/texture/formats.h"
#include "ptmkit/texture/ptm.h"
#include "ptmkit/texture/relight.h"
#include "ptmkit/texture/rti.h"
#include "ptmkit/texture/texture_file.h"
#include "ptmkit/texture/web_folder.h"
#include "test_util.h"

namespace fs = std::filesystem;

namespace ptmkit::texture {
namespace {

using test::ScratchDir;

std::string read_text(const fs::path& p) {
  std::ifstream in(p, std::ios::binary);
  return {std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
}

void write_text(const fs::path& p, const std::string& s) {
  std::ofstream out(p, std::ios::binary);
  out << s;
}

// A raw PTM 1.2 file with random bytes.
PtmFile random_file(PtmFormat format, int w, int h, std::uint64_t seed) {
  PtmFile f;
  f.format = format;
  f.width = w;
  f.height = h;
  f.quantisation.scales = {1.5f, 1.25f, 1.0f, 0.75f, 0.5f, 2.0f};
  f.quantisation.biases = {128, 120, 100, 127, 127, 0};
  f.data.resize(f.texels() * static_cast<std::size_t>(format == PtmFormat::kRGB ? 18 : 9));
  std::mt19937_64 rng(seed);
  // Smooth content (JPEG keeps it closely), plus a little noise.
  for (std::size_t i = 0; i < f.data.size(); ++i) {
    const double t = static_cast<double>(i % 977) / 977.0;
    f.data[i] = static_cast<std::uint8_t>(
        std::clamp(60.0 + 120.0 * t + static_cast<double>(rng() % 5), 0.0, 255.0));
  }
  return f;
}

// ------------------------------------------------------------------------------------------
// JPEG .ptm: round trips

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
    // Quality 100 on 8-bit noise of +-2 around a ramp: within a few levels, about 1 on average.
    EXPECT_LE(worst, 6);
    EXPECT_LE(sum / static_cast<double>(raw.data.size()), 1.5);
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

// ------------------------------------------------------------------------------------------
// Biases and refusals

TEST(PtmBias, NegativeAndOutOfRangeBiasesAreRead) {
  ScratchDir dir;
  const std::string header = "PTM_1.2\nPTM_FORMAT_RGB\n1\n1\n1 1 1 1 1 2\n0 0 0 0 300 -7\n";
  std::string data(18, '\0');
  data[5] = 10;  // R's a5
  data[4] = 1;   // R's a4
  write_text(dir / "neg.ptm", header + data);
  const PtmFile f = read_ptm_file(dir / "neg.ptm");
  EXPECT_EQ(f.quantisation.biases[5], -7);
  EXPECT_DOUBLE_EQ(f.coefficient(0, 0, 0, 5), 2.0 * (10 + 7));
  EXPECT_DOUBLE_EQ(f.coefficient(0, 0, 0, 4), 1.0 * (1 - 300));
  EXPECT_DOUBLE_EQ(f.coefficient(0, 0, 1, 5), 2.0 * 7);
  // Rewritten as read.
  write_ptm_file(dir / "again.ptm", f);
  EXPECT_EQ(read_text(dir / "again.ptm"), header + data);
}

TEST(Refusals, EveryUnsupportedVariantSaysWhatIsSupported) {
  ScratchDir dir;
  const std::string tail = "\n1\n1\n1 1 1 1 1 1\n0 0 0 0 0 0\n" + std::string(64, '\0');
  struct Case {
    std::string file;
    std::string content;
    std::string variant;
  };
  std::vector<Case> cases;
  for (const char* f : {"PTM_FORMAT_LUM", "PTM_FORMAT_PTM_LUT", "PTM_FORMAT_PTM_C_LUT",
                        "PTM_FORMAT_JPEGLS_RGB", "PTM_FORMAT_JPEGLS_LRGB", "PTM_FORMAT_PAL_RGB"}) {
    cases.push_back({std::string(f) + ".ptm", "PTM_1.2\n" + std::string(f) + tail,
                     "format " + std::string(f) + " is not supported"});
  }
  cases.push_back({"old.ptm", "PTM_1.1\nPTM_FORMAT_JPEG_LRGB" + tail,
                   "PTM_1.1 PTM_FORMAT_JPEG_LRGB is not supported"});
  cases.push_back({"type2.rti", "#HSH1.2\r\n2\r\n1 1 3\r\n9 2 1\r\n", "RTI type 2 is not"});
  for (const Case& c : cases) {
    write_text(dir / c.file, c.content);
    try {
      (void)read_texture(dir / c.file);
      ADD_FAILURE() << c.file << " was accepted";
    } catch (const Error& e) {
      const std::string msg = e.what();
      EXPECT_NE(msg.find(c.variant), std::string::npos) << msg;
      EXPECT_NE(msg.find(std::string(kSupportedFormats)), std::string::npos) << msg;
    }
  }
  // Web folders of types, colour spaces and layouts not read.
  struct WebCase {
    std::string type, colorspace, file, variant;
  };
  const std::vector<WebCase> web = {
      {"rbf", "mrgb", "plane_0.jpg", "web folder type 'rbf'"},
      {"bilinear", "mrgb", "plane_0.jpg", "web folder type 'bilinear'"},
      {"sh", "rgb", "plane_0.jpg", "web folder type 'sh'"},
      {"ptm", "mrgb", "plane_0.jpg", "colour space 'mrgb' with type 'ptm'"},
      {"ptm", "mycc", "plane_0.jpg", "colour space 'mycc' with type 'ptm'"},
      {"hsh", "lrgb", "plane_0.jpg", "colour space 'lrgb' with type 'hsh'"},
      {"ptm", "rgb", "plane_0.tzi", "layout tarzoom"},
  };
  int n = 0;
  for (const WebCase& c : web) {
    const fs::path folder = dir / ("web" + std::to_string(n++));
    fs::create_directories(folder);
    nlohmann::json j = {{"width", 4},
                        {"height", 4},
                        {"format", "jpg"},
                        {"type", c.type},
                        {"colorspace", c.colorspace},
                        {"nplanes", 18}};
    j["materials"] = {
        {{"scale", std::vector<double>(18, 1.0)}, {"bias", std::vector<double>(18, 0.0)}}};
    write_text(folder / "info.json", j.dump());
    write_text(folder / c.file, "x");
    for (const fs::path& p : {folder, folder / "info.json"}) {
      try {
        (void)read_texture(p);
        ADD_FAILURE() << c.variant << " was accepted";
      } catch (const Error& e) {
        const std::string msg = e.what();
        EXPECT_NE(msg.find(c.variant + " is not supported"), std::string::npos) << msg;
        EXPECT_NE(msg.find(std::string(kSupportedFormats)), std::string::npos) << msg;
      }
    }
  }
}

TEST(PtmScales, IntegerScalesAreWholeAndReachBothEnds) {
  std::mt19937_64 rng(test::test_seed());
  for (int trial = 0; trial < 200; ++trial) {
    std::array<double, kPtmTerms> lo{}, hi{};
    for (int i = 0; i < kPtmTerms; ++i) {
      lo[i] = -static_cast<double>(rng() % 40000) / 100.0;
      hi[i] = static_cast<double>(rng() % 40000) / 100.0;
    }
    const PtmQuantisation q = choose_quantisation(lo, hi, true);
    const PtmQuantisation fine = choose_quantisation(lo, hi);
    for (int i = 0; i < kPtmTerms; ++i) {
      const double s = q.scales[i];
      EXPECT_EQ(s, std::floor(s));
      EXPECT_GE(s, 1.0);
      EXPECT_LE(-q.biases[i] * s, lo[i] + 1e-9);         // byte 0 reaches lo
      EXPECT_GE((255 - q.biases[i]) * s, hi[i] - 1e-9);  // byte 255 reaches hi
      // At most one whole step above the finest scale rounded up (the two ends' ceilings).
      EXPECT_LE(s, std::ceil(std::max(1.0, static_cast<double>(fine.scales[i]))) + 1.0);
    }
  }
}

// ------------------------------------------------------------------------------------------
// .rti line ends

TEST(RtiLineEnds, CrlfWrittenAndBothRead) {
  ScratchDir dir;
  CoefficientMap m({5, 3, Basis::kHsh3, ColourModel::kRGB, ColourSpace::kSRGB});
  std::mt19937 rng(7);
  for (float& v : m.coeffs) v = static_cast<float>(rng() % 1000) / 1000.0f - 0.3f;
  write_rti(dir / "crlf.rti", m);
  const std::string crlf = read_text(dir / "crlf.rti");
  EXPECT_EQ(crlf.rfind("#HSH1.2\r\n3\r\n5 3 3\r\n9 2 1\r\n", 0), 0u);
  // The same file with LF line ends reads to the same coefficients.
  std::string lf = crlf;
  std::size_t header_end = 0;
  for (int i = 0; i < 4; ++i) header_end = lf.find("\r\n", header_end) + 2;
  std::string head = lf.substr(0, header_end);
  std::string body = lf.substr(header_end);
  head.erase(std::remove(head.begin(), head.end(), '\r'), head.end());
  write_text(dir / "lf.rti", head + body);
  EXPECT_EQ(read_rti(dir / "lf.rti").coeffs, read_rti(dir / "crlf.rti").coeffs);
}

// ------------------------------------------------------------------------------------------
// Web folders

// Writes plane images (nplanes / 3 JPEGs of w x h) as an `image` or `deepzoom` folder.
void write_web_folder(const fs::path& folder, const std::string& type,
                      const std::string& colorspace, const std::vector<Image>& jpegs,
                      const std::vector<double>& scale, const std::vector<double>& bias,
                      bool deepzoom, int tile = 16, int overlap = 1) {
  fs::create_directories(folder);
  const int w = jpegs[0].width(), h = jpegs[0].height();
  nlohmann::json j = {{"width", w},
                      {"height", h},
                      {"format", "jpg"},
                      {"type", type},
                      {"colorspace", colorspace},
                      {"nplanes", 3 * jpegs.size()},
                      {"quality", 100}};
  j["materials"] = {{{"scale", scale}, {"bias", bias}}};
  write_text(folder / "info.json", j.dump());
  ImageWriteOptions q;
  q.jpeg_quality = 100;
  for (std::size_t k = 0; k < jpegs.size(); ++k) {
    const std::string name = "plane_" + std::to_string(k);
    if (!deepzoom) {
      write_image(folder / (name + ".jpg"), jpegs[k].view(), q);
      continue;
    }
    write_text(folder / (name + ".dzi"),
               "<?xml version=\"1.0\" encoding=\"UTF-8\"?>\n<Image TileSize=\"" +
                   std::to_string(tile) + "\" Overlap=\"" + std::to_string(overlap) +
                   "\" Format=\"jpg\" xmlns=\"http://schemas.microsoft.com/deepzoom/2008\">"
                   "<Size Width=\"" +
                   std::to_string(w) + "\" Height=\"" + std::to_string(h) + "\"/></Image>\n");
    // Full resolution at level 3; a decoy lower level 1 that must not be used.
    for (const int level : {1, 3}) {
      const fs::path dirl = folder / (name + "_files") / std::to_string(level);
      fs::create_directories(dirl);
      if (level == 1) {
        write_image(dirl / "0_0.jpg", jpegs[k].view().crop(0, 0, 4, 4), q);
        continue;
      }
      const int cols = (w + tile - 1) / tile, rows = (h + tile - 1) / tile;
      for (int ty = 0; ty < rows; ++ty) {
        for (int tx = 0; tx < cols; ++tx) {
          const int x0 = std::max(0, tx * tile - overlap), y0 = std::max(0, ty * tile - overlap);
          const int x1 = std::min(w, (tx + 1) * tile + overlap);
          const int y1 = std::min(h, (ty + 1) * tile + overlap);
          write_image(dirl / (std::to_string(tx) + "_" + std::to_string(ty) + ".jpg"),
                      jpegs[k].view().crop(x0, y0, x1 - x0, y1 - y0), q);
        }
      }
    }
  }
}

// Plane images of smooth random-ish content (JPEG keeps it within a level or two).
std::vector<Image> smooth_planes(int count, int w, int h, std::uint64_t seed) {
  std::vector<Image> out;
  std::mt19937_64 rng(seed);
  for (int k = 0; k < count; ++k) {
    Image im(w, h, 3, ColourSpace::kSRGB);
    double f[3][3];
    for (auto& row : f)
      for (double& v : row) v = static_cast<double>(rng() % 1000) / 1000.0;
    for (int y = 0; y < h; ++y) {
      for (int x = 0; x < w; ++x) {
        for (int c = 0; c < 3; ++c) {
          im.at(x, y, c) = static_cast<float>(0.2 + 0.3 * f[c][0] + 0.25 * f[c][1] * x / w +
                                              0.2 * f[c][2] * y / h);
        }
      }
    }
    out.push_back(std::move(im));
  }
  return out;
}

TEST(WebFolder, PtmRgbImageAndDeepzoomReadTheSameCoefficients) {
  ScratchDir dir;
  const int w = 40, h = 27;
  const std::vector<Image> planes = smooth_planes(6, w, h, test::test_seed());
  std::vector<double> scale(18), bias(18);
  for (int k = 0; k < 18; ++k) {
    scale[k] = 0.5 + 0.05 * k;
    bias[k] = k % 2 ? 0.4 : -0.1;
  }
  write_web_folder(dir / "image", "ptm", "rgb", planes, scale, bias, false);
  write_web_folder(dir / "dz", "ptm", "rgb", planes, scale, bias, true);
  const WebTexture a = read_web_folder(dir / "image");
  const WebTexture b = read_web_folder(dir / "dz" / "info.json");
  EXPECT_EQ(a.info.layout, "image");
  EXPECT_EQ(b.info.layout, "deepzoom");
  ASSERT_FALSE(a.is_hsh);
  ASSERT_EQ(a.ptm.model, ColourModel::kRGB);
  // Web basis order 1, u, v, u^2, uv, v^2 against .ptm order u^2, v^2, uv, u, v, 1.
  const int web_of[6] = {3, 5, 4, 1, 2, 0};
  double worst_a = 0, worst_b = 0;
  for (int y = 0; y < h; ++y) {
    for (int x = 0; x < w; ++x) {
      for (int c = 0; c < 3; ++c) {
        for (int t = 0; t < 6; ++t) {
          const int k = 3 * web_of[t] + c;
          const double byte = planes[static_cast<std::size_t>(k / 3)].at(x, y, k % 3);
          const double expect = (byte - bias[k]) * scale[k];
          const double got = a.ptm.texel_coeffs(x, y)[c * 6 + t];
          worst_a = std::max(worst_a, std::abs(got - expect) / scale[k]);
        }
      }
    }
  }
  // JPEG at quality 100 with chroma subsampling on smooth planes: a few levels at most.
  EXPECT_LE(worst_a * 255.0, 4.0);
  // Deep zoom: against the level-3 tiles decoded by the image library and placed by the
  // descriptor's rule (tile (i, j) starts at i * 16 - 1 except on the first row and column;
  // the grey checkerboard makes a one-pixel misplacement 38 levels out).
  for (int k = 0; k < 18; ++k) {
    const int j = k / 3;
    for (int ty = 0; ty * 16 < h; ++ty) {
      for (int tx = 0; tx * 16 < w; ++tx) {
        const Image tile = read_image(dir / "dz" / ("plane_" + std::to_string(j) + "_files") / "3" /
                                      (std::to_string(tx) + "_" + std::to_string(ty) + ".jpg"));
        const int ox = tx > 0 ? 1 : 0, oy = ty > 0 ? 1 : 0;
        for (int y = ty * 16; y < std::min(h, ty * 16 + 16); ++y) {
          for (int x = tx * 16; x < std::min(w, tx * 16 + 16); ++x) {
            const double byte = tile.at(x - tx * 16 + ox, y - ty * 16 + oy, k % 3);
            const double expect = (byte - bias[k]) * scale[k];
            const int c = k % 3;
            const int t = static_cast<int>(std::find(web_of, web_of + 6, j) - web_of);
            worst_b = std::max(worst_b, std::abs(b.ptm.texel_coeffs(x, y)[c * 6 + t] - expect));
          }
        }
      }
    }
  }
  EXPECT_LE(worst_b, 1e-5);
}

TEST(WebFolder, LrgbIsColourTimesLuminance) {
  ScratchDir dir;
  const int w = 20, h = 12;
  const std::vector<Image> planes = smooth_planes(3, w, h, test::test_seed());
  std::vector<double> scale(9, 1.0), bias(9, 0.0);
  for (int k = 3; k < 9; ++k) {
    scale[k] = 1.5;
    bias[k] = 0.3;
  }
  write_web_folder(dir / "l", "ptm", "lrgb", planes, scale, bias, false);
  const WebTexture t = read_web_folder(dir / "l");
  ASSERT_EQ(t.ptm.model, ColourModel::kLRGB);
  // Independent: read the JPEGs back, evaluate colour * sum(coef * basis) at one light.
  std::vector<Image> decoded;
  for (int j = 0; j < 3; ++j)
    decoded.push_back(read_image(dir / "l" / ("plane_" + std::to_string(j) + ".jpg")));
  const double u = 0.3, v = -0.2;
  const double basis[6] = {1, u, v, u * u, u * v, v * v};
  double worst = 0;
  for (int y = 0; y < h; ++y) {
    for (int x = 0; x < w; ++x) {
      double l = 0;
      for (int k = 0; k < 6; ++k) {
        const int p = 3 + k;
        l += basis[k] * (decoded[static_cast<std::size_t>(p / 3)].at(x, y, p % 3) - bias[p]) *
             scale[p];
      }
      float rgb[3];
      t.ptm.evaluate(x, y, u, v, rgb);
      for (int c = 0; c < 3; ++c) {
        worst = std::max(worst, std::abs(rgb[c] - decoded[0].at(x, y, c) * l));
      }
    }
  }
  EXPECT_LE(worst * 255.0, 0.01);
}

TEST(WebFolder, HshFolderReadsAsAnHshMapAndConvertsToRti) {
  ScratchDir dir;
  const int w = 18, h = 10;
  const std::vector<Image> planes = smooth_planes(9, w, h, test::test_seed());
  std::vector<double> scale(27, 0.8), bias(27, 0.5);
  write_web_folder(dir / "hsh", "hsh", "rgb", planes, scale, bias, false);
  const WebTexture t = read_web_folder(dir / "hsh");
  ASSERT_TRUE(t.is_hsh);
  ASSERT_EQ(t.hsh.terms(), 9);
  std::vector<Image> decoded;
  for (int j = 0; j < 9; ++j)
    decoded.push_back(read_image(dir / "hsh" / ("plane_" + std::to_string(j) + ".jpg")));
  for (int c = 0; c < 3; ++c) {
    for (int k = 0; k < 9; ++k) {
      const double expect = (decoded[static_cast<std::size_t>(k)].at(4, 7, c) - 0.5) * 0.8;
      EXPECT_NEAR(t.hsh.texel_coeffs(4, 7)[c * 9 + k], expect, 1e-5);
    }
  }
  ConvertOptions o;
  const ConvertReport r = convert_to_rti(dir / "hsh", dir / "out.rti", o);
  EXPECT_EQ(r.from, "web folder hsh rgb image");
  const CoefficientMap back = read_rti(dir / "out.rti");
  double worst = 0;
  for (std::size_t i = 0; i < back.coeffs.size(); ++i) {
    worst = std::max(worst, static_cast<double>(std::abs(back.coeffs[i] - t.hsh.coeffs[i])));
  }
  EXPECT_LE(worst, 0.8 * 2.0 / 255.0);  // half a step of the .rti's 8-bit range, which is wider
  EXPECT_THROW((void)convert_to_ptm(dir / "hsh", dir / "x.ptm", o), Error);
  EXPECT_FALSE(fs::exists(dir / "x.ptm"));
}

TEST(WebFolder, MalformedFoldersAreClearErrors) {
  ScratchDir dir;
  const std::vector<Image> planes = smooth_planes(6, 20, 10, 1);
  std::vector<double> scale(18, 1.0), bias(18, 0.0);
  write_web_folder(dir / "ok", "ptm", "rgb", planes, scale, bias, false);
  // A missing plane, a plane of the wrong size, a corrupt plane, short scale arrays, bad JSON.
  fs::copy(dir / "ok", dir / "missing", fs::copy_options::recursive);
  fs::remove(dir / "missing" / "plane_4.jpg");
  fs::copy(dir / "ok", dir / "size", fs::copy_options::recursive);
  write_image(dir / "size" / "plane_2.jpg", planes[0].view().crop(0, 0, 10, 10));
  fs::copy(dir / "ok", dir / "corrupt", fs::copy_options::recursive);
  {
    std::string b = read_text(dir / "corrupt" / "plane_1.jpg");
    write_text(dir / "corrupt" / "plane_1.jpg", b.substr(0, b.size() / 2));
  }
  fs::copy(dir / "ok", dir / "short", fs::copy_options::recursive);
  {
    nlohmann::json j = nlohmann::json::parse(read_text(dir / "ok" / "info.json"));
    j["materials"][0]["scale"] = std::vector<double>(17, 1.0);
    write_text(dir / "short" / "info.json", j.dump());
  }
  fs::copy(dir / "ok", dir / "json", fs::copy_options::recursive);
  write_text(dir / "json" / "info.json", "{\"width\": 20,");
  const std::vector<std::pair<std::string, std::string>> cases = {
      {"missing", "plane_4.jpg: missing"}, {"size", "10 x 10 JPEG where 20 x 10"},
      {"corrupt", "plane_1.jpg"},          {"short", "must list 18 numbers"},
      {"json", "not valid JSON"},
  };
  for (const auto& [name, expect] : cases) {
    try {
      (void)read_texture(dir / name);
      ADD_FAILURE() << name << " was accepted";
    } catch (const Error& e) {
      EXPECT_NE(std::string(e.what()).find(expect), std::string::npos) << e.what();
    }
  }
}

// ------------------------------------------------------------------------------------------
// Conversions

TEST(Convert, PtmDirectionsKeepBytesOrRefuse) {
  ScratchDir dir;
  const PtmFile lrgb = random_file(PtmFormat::kLRGB, 9, 7, 3);
  const PtmFile rgb = random_file(PtmFormat::kRGB, 9, 7, 4);
  write_ptm_file(dir / "lrgb.ptm", lrgb);
  write_ptm_file(dir / "rgb.ptm", rgb);
  ConvertOptions o;
  // Same format: bit-exact copy.
  EXPECT_TRUE(convert_to_ptm(dir / "rgb.ptm", dir / "rgb2.ptm", o).bytes_kept);
  EXPECT_EQ(read_text(dir / "rgb2.ptm"), read_text(dir / "rgb.ptm"));
  // To JPEG and back to raw: the quantisation kept, bytes within JPEG loss.
  o.ptm_format = "jpeg-lrgb";
  o.jpeg_quality = 100;
  const ConvertReport j = convert_to_ptm(dir / "lrgb.ptm", dir / "j.ptm", o);
  EXPECT_EQ(j.to, "PTM_FORMAT_JPEG_LRGB");
  o.ptm_format = "lrgb";
  convert_to_ptm(dir / "j.ptm", dir / "back.ptm", o);
  const PtmFile back = read_ptm_file(dir / "back.ptm");
  EXPECT_EQ(back.quantisation, lrgb.quantisation);
  EXPECT_EQ(back.data, read_ptm_file(dir / "j.ptm").data);
  // LRGB -> RGB: relit values within the RGB file's quantisation.
  o.ptm_format = "rgb";
  convert_to_ptm(dir / "lrgb.ptm", dir / "as_rgb.ptm", o);
  const CoefficientMap a = read_ptm(dir / "lrgb.ptm"), b = read_ptm(dir / "as_rgb.ptm");
  const PtmFile brgb = read_ptm_file(dir / "as_rgb.ptm");
  double step = 0;
  for (float s : brgb.quantisation.scales) step += s / 2.0;  // worst case, |basis| <= 1
  for (int y = 0; y < 7; ++y) {
    for (int x = 0; x < 9; ++x) {
      float ra[3], rb[3];
      a.evaluate(x, y, 0.3, 0.4, ra);
      b.evaluate(x, y, 0.3, 0.4, rb);
      for (int c = 0; c < 3; ++c) EXPECT_LE(std::abs(ra[c] - rb[c]) * 255.0, step + 1e-6);
    }
  }
  // Refused: RGB -> LRGB, and polynomials to .rti; no output left.
  o.ptm_format = "lrgb";
  EXPECT_THROW((void)convert_to_ptm(dir / "rgb.ptm", dir / "no.ptm", o), Error);
  o.ptm_format.clear();
  EXPECT_THROW((void)convert_to_rti(dir / "rgb.ptm", dir / "no.rti", o), Error);
  EXPECT_FALSE(fs::exists(dir / "no.ptm"));
  EXPECT_FALSE(fs::exists(dir / "no.rti"));
}

TEST(Convert, CommandLine) {
  ScratchDir dir;
  write_ptm_file(dir / "in.ptm", random_file(PtmFormat::kLRGB, 6, 5, 9));
  auto r = test::run_ptmkit({"export", "ptm", (dir / "in.ptm").string(), "-o",
                             (dir / "out.ptm").string(), "--format", "jpeg-lrgb"});
  EXPECT_EQ(r.exit_code, 0) << r.err;
  EXPECT_NE(r.out.find("PTM_FORMAT_JPEG_LRGB"), std::string::npos) << r.out;
  r = test::run_ptmkit(
      {"export", "rti", (dir / "in.ptm").string(), "-o", (dir / "out.rti").string()});
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_NE(r.err.find("is refused"), std::string::npos) << r.err;
  EXPECT_FALSE(fs::exists(dir / "out.rti"));
  r = test::run_ptmkit({"info", (dir / "out.ptm").string()});
  EXPECT_EQ(r.exit_code, 0) << r.err;
  EXPECT_NE(r.out.find("PTM_FORMAT_JPEG_LRGB"), std::string::npos) << r.out;
  // A web folder, given as the folder and as its info.json, in info and relight.
  std::vector<double> scale(18, 1.0), bias(18, 0.0);
  write_web_folder(dir / "web", "ptm", "rgb", smooth_planes(6, 12, 8, 5), scale, bias, true);
  r = test::run_ptmkit({"info", (dir / "web").string()});
  EXPECT_EQ(r.exit_code, 0) << r.err;
  EXPECT_NE(r.out.find("web folder, type ptm, colour space rgb, layout deepzoom"),
            std::string::npos)
      << r.out;
  r = test::run_ptmkit({"relight", (dir / "web" / "info.json").string(), "--light", "0.2,0.1,1",
                        "-o", (dir / "web.png").string()});
  EXPECT_EQ(r.exit_code, 0) << r.err;
  EXPECT_EQ(read_image(dir / "web.png").width(), 12);
  r = test::run_ptmkit({"export", "ptm", (dir / "web").string(), "-o", (dir / "web.ptm").string()});
  EXPECT_EQ(r.exit_code, 0) << r.err;
  EXPECT_EQ(read_ptm_file(dir / "web.ptm").format, PtmFormat::kRGB);
}

// ------------------------------------------------------------------------------------------
// Real files, against an evaluation written here from the formats' descriptions

std::vector<std::string> words(const std::string& line) {
  std::istringstream in(line);
  std::vector<std::string> out;
  std::string w;
  while (in >> w) out.push_back(w);
  return out;
}

TEST(RealFiles, JpegLrgbTabletRelitWithinOneGreyLevel) {
  const auto root = test::shared_data("real-files");
  if (!root || !fs::exists(*root / "tablet1.ptm")) {
    GTEST_SKIP() << "../shared/data/real-files/tablet1.ptm is absent";
  }
  const fs::path path = *root / "tablet1.ptm";
  const std::string file = read_text(path);
  // Header: one item list per line in this file.
  std::vector<std::string> lines;
  std::size_t pos = 0;
  for (int i = 0; i < 14; ++i) {
    const std::size_t end = file.find('\n', pos);
    lines.push_back(file.substr(pos, end - pos));
    pos = end + 1;
  }
  ASSERT_EQ(lines[1], "PTM_FORMAT_JPEG_LRGB");
  const int w = std::stoi(lines[2]), h = std::stoi(lines[3]);
  std::vector<double> scale, bias;
  for (const auto& s : words(lines[4])) scale.push_back(std::stod(s));
  for (const auto& s : words(lines[5])) bias.push_back(std::stod(s));
  std::vector<int> transform, order, ref;
  std::vector<std::size_t> size, side;
  for (const auto& s : words(lines[7])) transform.push_back(std::stoi(s));
  for (const auto& s : words(lines[10])) order.push_back(std::stoi(s));
  for (const auto& s : words(lines[11])) ref.push_back(std::stoi(s));
  for (const auto& s : words(lines[12])) size.push_back(std::stoul(s));
  for (const auto& s : words(lines[13])) side.push_back(std::stoul(s));
  // Each stream decoded by the image library into its own plane (JPEG rows bottom-up).
  ScratchDir dir;
  std::vector<std::vector<int>> plane(9);
  for (int k = 0; k < 9; ++k) {
    const fs::path jp = dir / ("p" + std::to_string(k) + ".jpg");
    write_text(jp, file.substr(pos, size[k]));
    pos += size[k] + side[k];
    ASSERT_EQ(side[k], 0u);  // this file has none
    const Image im = read_image(jp);
    for (int y = 0; y < h; ++y)
      for (int x = 0; x < w; ++x)
        plane[k].push_back(static_cast<int>(std::lround(im.at(x, y, 0) * 255.0)));
  }
  for (int rank = 0; rank < 9; ++rank) {
    const int k = static_cast<int>(std::find(order.begin(), order.end(), rank) - order.begin());
    if (ref[k] < 0) continue;
    for (std::size_t i = 0; i < plane[k].size(); ++i) {
      const int r = transform[k] & 1 ? 255 - plane[ref[k]][i] : plane[ref[k]][i];
      int v = plane[k][i] + r - 128;
      if (v < 0) v += 256;
      plane[k][i] = std::min(v, 255);
    }
  }
  const CoefficientMap map = read_ptm(path);
  for (const Eigen::Vector3d& light : {Eigen::Vector3d(0, 0, 1), Eigen::Vector3d(0.6, 0.2, 0.77),
                                       Eigen::Vector3d(-0.5, -0.5, 0.6)}) {
    const Eigen::Vector3d l = light.normalized();
    const Image relit = relight(map, l);
    double sum = 0, worst = 0;
    for (int y = 0; y < h; ++y) {
      for (int x = 0; x < w; ++x) {
        const std::size_t i = static_cast<std::size_t>(h - 1 - y) * w + x;  // stored row
        const double b[6] = {l.x() * l.x(), l.y() * l.y(), l.x() * l.y(), l.x(), l.y(), 1.0};
        double lum = 0;
        for (int t = 0; t < 6; ++t) lum += scale[t] * (plane[t][i] - bias[t]) * b[t];
        for (int c = 0; c < 3; ++c) {
          const double expect = std::clamp(lum / 255.0 * plane[6 + c][i] / 255.0, 0.0, 1.0);
          const double d = std::abs(expect - relit.at(x, y, c)) * 255.0;
          sum += d;
          worst = std::max(worst, d);
        }
      }
    }
    EXPECT_LE(worst, 1.0);
    EXPECT_LE(sum / (3.0 * w * h), 0.01);
  }
}

TEST(RealFiles, OpenlimePtmFolderRelitWithinOneGreyLevel) {
  const auto root = test::shared_data("real-files");
  if (!root || !fs::exists(*root / "openlime-ptm" / "info.json")) {
    GTEST_SKIP() << "../shared/data/real-files/openlime-ptm is absent";
  }
  const fs::path folder = *root / "openlime-ptm";
  const nlohmann::json j = nlohmann::json::parse(read_text(folder / "info.json"));
  ASSERT_EQ(j["type"], "ptm");
  ASSERT_EQ(j["colorspace"], "rgb");
  const std::vector<double> scale = j["materials"][0]["scale"];
  const std::vector<double> bias = j["materials"][0]["bias"];
  std::vector<Image> jpegs;
  for (int k = 0; k < 6; ++k)
    jpegs.push_back(read_image(folder / ("plane_" + std::to_string(k) + ".jpg")));
  const LoadedTexture tex = read_texture(folder);
  ASSERT_FALSE(tex.is_hsh);
  const int w = jpegs[0].width(), h = jpegs[0].height();
  for (const Eigen::Vector3d& light : {Eigen::Vector3d(0, 0, 1), Eigen::Vector3d(0.5, 0.3, 0.81),
                                       Eigen::Vector3d(-0.7, 0.1, 0.7)}) {
    const Eigen::Vector3d l = light.normalized();
    const Image relit = relight(tex.ptm, l);
    const double basis[6] = {1, l.x(), l.y(), l.x() * l.x(), l.x() * l.y(), l.y() * l.y()};
    double sum = 0, worst = 0;
    for (int y = 0; y < h; ++y) {
      for (int x = 0; x < w; ++x) {
        for (int c = 0; c < 3; ++c) {
          double v = 0;
          for (int t = 0; t < 6; ++t) {
            const int k = 3 * t + c;
            v += basis[t] * (jpegs[static_cast<std::size_t>(t)].at(x, y, c) - bias[k]) * scale[k];
          }
          const double d = std::abs(std::clamp(v, 0.0, 1.0) - relit.at(x, y, c)) * 255.0;
          sum += d;
          worst = std::max(worst, d);
        }
      }
    }
    EXPECT_LE(worst, 1.0);
    EXPECT_LE(sum / (3.0 * w * h), 0.01);
  }
}

}  // namespace
}  // namespace ptmkit::texture
