// Plain .ptm and .rti details other tools rely on: negative and out-of-range biases, whole
// integer scales that reach both ends, and .rti line ends (CRLF written, CRLF and LF read).
#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <random>
#include <string>

#include "formats_test_util.h"
#include "ptmkit/texture/ptm.h"
#include "ptmkit/texture/rti.h"
#include "test_util.h"

namespace ptmkit::texture {
namespace {

using test::read_text;
using test::ScratchDir;
using test::write_text;

// Double rounding of scale x byte against a range end (values up to 400: ~1e-13), with room.
constexpr double kRangeEndSlack = 1e-9;
// Integer scales: at most one whole step above the finest scale rounded up (the two ends'
// ceilings).
constexpr double kMaxWholeStepsAbove = 1.0;

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
      EXPECT_LE(-q.biases[i] * s, lo[i] + kRangeEndSlack);         // byte 0 reaches lo
      EXPECT_GE((255 - q.biases[i]) * s, hi[i] - kRangeEndSlack);  // byte 255 reaches hi
      // At most one whole step above the finest scale rounded up (the two ends' ceilings).
      EXPECT_LE(
          s, std::ceil(std::max(1.0, static_cast<double>(fine.scales[i]))) + kMaxWholeStepsAbove);
    }
  }
}

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

}  // namespace
}  // namespace ptmkit::texture
