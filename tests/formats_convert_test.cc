// The conversions of `ptmkit export ptm|rti`: .ptm directions that keep the bytes or refuse,
// and the command line on .ptm files and web folders (info, relight, export).
#include <gtest/gtest.h>

#include <cmath>
#include <string>
#include <vector>

#include "formats_test_util.h"
#include "ptmkit/core/error.h"
#include "ptmkit/core/image_io.h"
#include "ptmkit/texture/convert.h"
#include "ptmkit/texture/ptm.h"
#include "test_util.h"

namespace fs = std::filesystem;

namespace ptmkit::texture {
namespace {

using test::random_file;
using test::read_text;
using test::ScratchDir;
using test::smooth_planes;
using test::write_web_folder;

// Rounding slack where a relit difference meets its worst-case bound (grey levels).
constexpr double kBoundSlackGrey = 1e-6;

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
      for (int c = 0; c < 3; ++c)
        EXPECT_LE(std::abs(ra[c] - rb[c]) * 255.0, step + kBoundSlackGrey);
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
  // The size printed is the file's: the command commits its output only at the end, so the
  // size cannot be read back from the path before then.
  EXPECT_NE(r.out.find(", " + std::to_string(fs::file_size(dir / "out.ptm")) + " bytes"),
            std::string::npos)
      << r.out;
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

}  // namespace
}  // namespace ptmkit::texture
