// The streaming .ptm writer (PtmStreamWriter): write_ptm's file within half-float rounding,
// spilling to a temporary file, buffer sizes, misuse and bad values, replacing an existing
// output, and the colour bytes of every value.
#include <gmock/gmock.h>
#include <gtest/gtest.h>
#include <sys/stat.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <iterator>
#include <limits>
#include <stdexcept>
#include <string>
#include <vector>

#include "ptm_test_util.h"
#include "ptmkit/core/error.h"
#include "ptmkit/core/light_layout.h"
#include "ptmkit/texture/ptm.h"
#include "ptmkit/texture/relight.h"
#include "test_util.h"
#include "tolerances.h"

namespace fs = std::filesystem;

namespace ptmkit::texture {
namespace {

using test::half_step_bound_grey;
using test::kRelitGreySlack;
using test::smooth_map;

// Half rounding moves a value by at most 2^-12 of its magnitude (under 0.07 grey levels against
// steps of 0.6-0.8): a byte flips by at most one, and seldom (under a fifth of the bytes).
constexpr int kMaxByteDifference = 1;
constexpr double kMaxFractionDiffering = 0.2;

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
      ASSERT_LE(std::abs(a.data[k] - b.data[k]), kMaxByteDifference) << k;
      differing += a.data[k] != b.data[k] ? 1 : 0;
    }
    EXPECT_LT(static_cast<double>(differing),
              kMaxFractionDiffering * static_cast<double>(a.data.size()));
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
    EXPECT_LE(worst, 2.0 * half_step_bound_grey(a.quantisation) + kRelitGreySlack);
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
