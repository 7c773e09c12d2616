#include "ptmkit/core/light_set.h"

#include <fstream>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "ptmkit/core/error.h"
#include "ptmkit/core/light_layout.h"
#include "test_util.h"
#include "tolerances.h"

namespace fs = std::filesystem;
using ::testing::HasSubstr;

namespace ptmkit {
namespace {

using test::kDoubleRoundoff;

// Written with 17 significant digits a double reads back exactly; the reader's normalisation
// then moves each component by a few ulps (2.2e-16).
constexpr double kRoundTripTol = 1e-15;

void write_text(const fs::path& p, const std::string& s) {
  std::ofstream f(p, std::ios::binary);
  f << s;
}

// Expects read_lp to throw an Error whose message names the file (and line) and the problem.
void expect_lp_error(const fs::path& p, const std::string& where_sub, const std::string& what) {
  try {
    (void)read_lp(p);
    FAIL() << "expected an error for " << p;
  } catch (const Error& e) {
    EXPECT_THAT(e.what(), HasSubstr(where_sub));
    EXPECT_THAT(e.what(), HasSubstr(what));
  }
}

TEST(LightSet, ReadsCountLineTabsCrlfAndNormalises) {
  test::ScratchDir dir;
  write_text(dir / "a.lp", "3\r\nimg1.png\t0 0 2\r\nimg2.png  0.6 0 0.8\r\n\r\nimg3.png 1 1 1\r\n");
  const LightSet set = read_lp(dir / "a.lp");
  ASSERT_EQ(set.size(), 3u);
  EXPECT_EQ(set.lights[0].image, dir.path() / "img1.png");
  EXPECT_NEAR(set.lights[0].direction.z(), 1.0, kDoubleRoundoff);
  EXPECT_NEAR(set.lights[1].direction.x(), 0.6, kDoubleRoundoff);
  for (const auto& l : set.lights) EXPECT_NEAR(l.direction.norm(), 1.0, kDoubleRoundoff);
  EXPECT_NEAR(set.lights[2].direction.x(), 1.0 / std::sqrt(3.0), kDoubleRoundoff);
}

TEST(LightSet, CountLineIsOptionalAndRelativePathsResolve) {
  test::ScratchDir dir;
  fs::create_directories(dir / "lp");
  write_text(dir / "lp" / "b.lp", "../photos/x.jpg 0 0 1\nsub/y.jpg 0.1 0.2 0.9\n");
  const LightSet set = read_lp(dir / "lp" / "b.lp");
  ASSERT_EQ(set.size(), 2u);
  EXPECT_EQ(set.lights[0].image, dir.path() / "photos" / "x.jpg");
  EXPECT_EQ(set.lights[1].image, dir.path() / "lp" / "sub" / "y.jpg");
}

TEST(LightSet, RejectsBadFilesNamingFileAndLine) {
  test::ScratchDir dir;
  write_text(dir / "below.lp", "2\na.png 0 0 1\nb.png 0.5 0 -0.1\n");
  expect_lp_error(dir / "below.lp", "below.lp:3", "z <= 0");
  write_text(dir / "flat.lp", "a.png 1 0 0\n");
  expect_lp_error(dir / "flat.lp", "flat.lp:1", "z <= 0");
  write_text(dir / "nan.lp", "a.png 0 0 1\nb.png nan 0 1\n");
  expect_lp_error(dir / "nan.lp", "nan.lp:2", "NaN");
  write_text(dir / "inf.lp", "a.png 0 inf 1\n");
  expect_lp_error(dir / "inf.lp", "inf.lp:1", "NaN or infinite");
  write_text(dir / "dup.lp", "a.png 0 0 1\n./a.png 0.1 0 1\n");
  expect_lp_error(dir / "dup.lp", "dup.lp:2", "listed twice");
  write_text(dir / "count.lp", "3\na.png 0 0 1\nb.png 0.1 0 1\n");
  expect_lp_error(dir / "count.lp", "count.lp:1", "says 3 lights but the file lists 2");
  write_text(dir / "short.lp", "a.png 0 0\n");
  expect_lp_error(dir / "short.lp", "short.lp:1", "expected 'image x y z'");
  write_text(dir / "word.lp", "a.png 0 zero 1\n");
  expect_lp_error(dir / "word.lp", "word.lp:1", "not a number");
  write_text(dir / "zero.lp", "a.png 0 0 0\n");
  expect_lp_error(dir / "zero.lp", "zero.lp:1", "zero vector");
  write_text(dir / "empty.lp", "0\n");
  expect_lp_error(dir / "empty.lp", "empty.lp", "no lights");
  expect_lp_error(dir / "missing.lp", "missing.lp", "not found");
}

TEST(LightSet, WriteThenReadIsExactAndRewriteIsByteIdentical) {
  test::ScratchDir dir;
  LightSet set;
  const auto dirs = geodesic_dome(2);
  for (std::size_t i = 0; i < dirs.size(); ++i) {
    set.lights.push_back({dir.path() / ("img" + std::to_string(i) + ".png"), dirs[i], {}, 1.0});
  }
  write_lp(dir / "out.lp", set, {.count_line = true, .precision = 17});
  const LightSet back = read_lp(dir / "out.lp");
  ASSERT_EQ(back.size(), set.size());
  for (std::size_t i = 0; i < set.size(); ++i) {
    EXPECT_EQ(back.lights[i].image, set.lights[i].image);
    EXPECT_NEAR((back.lights[i].direction - set.lights[i].direction).norm(), 0.0, kRoundTripTol);
  }
  write_lp(dir / "again.lp", back, {.count_line = true, .precision = 17});
  std::ifstream a(dir / "out.lp"), b(dir / "again.lp");
  const std::string sa((std::istreambuf_iterator<char>(a)), {});
  const std::string sb((std::istreambuf_iterator<char>(b)), {});
  EXPECT_EQ(sa, sb);
  EXPECT_THAT(sa, ::testing::StartsWith("40\nimg0.png "));
}

TEST(LightLayout, GeodesicDomeMatchesThePaper) {
  const auto d1 = geodesic_dome(1);
  const auto d2 = geodesic_dome(2);
  EXPECT_EQ(d1.size(), 10u);
  EXPECT_EQ(d2.size(), 40u);  // the seed paper's 40 lights
  for (const auto& d : d2) {
    EXPECT_NEAR(d.norm(), 1.0, kDoubleRoundoff);
    EXPECT_GT(d.z(), 0.0);
  }
  // Ordered from the zenith down.
  EXPECT_GE(elevation_deg(d2.front()), elevation_deg(d2.back()));
  // Frequency f has 20 f^2 faces, half of them above the horizon.
  EXPECT_EQ(geodesic_dome(4).size(), 160u);
  EXPECT_THROW((void)geodesic_dome(0), Error);
}

TEST(LightLayout, RingsParseAndLayOut) {
  const auto rings = parse_rings("10:18,30:12,50:10,70:8,90:1");
  ASSERT_EQ(rings.size(), 5u);
  EXPECT_EQ(ring_layout(rings).size(), 49u);
  const auto r = ring_layout(parse_rings("45:4:90"));
  ASSERT_EQ(r.size(), 4u);
  EXPECT_NEAR(r[0].x(), 0.0, kDoubleRoundoff);
  EXPECT_NEAR(r[0].y(), std::cos(M_PI / 4), kDoubleRoundoff);
  EXPECT_THROW((void)parse_rings("45"), Error);
  EXPECT_THROW((void)parse_rings("0:4"), Error);
  EXPECT_THROW((void)parse_rings("95:4"), Error);
  EXPECT_THROW((void)parse_rings("45:0"), Error);
  EXPECT_THROW((void)parse_rings("45:x"), Error);
  EXPECT_THROW((void)parse_rings(""), Error);
}

}  // namespace
}  // namespace ptmkit
