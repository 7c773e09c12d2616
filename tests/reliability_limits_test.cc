// Inputs are bounded before memory is committed to them: declared sizes against the file's
// size, the named maxima of core/limits.h and the memory available. Each case runs the CLI
// under a 2 GiB address-space limit, so a reader that allocates what a header claims fails
// with bad_alloc (and this test) instead of succeeding on a large machine.
#include <gtest/gtest.h>

#include <sstream>

#include "ptmkit/core/limits.h"
#include "reliability_util.h"
#include "test_util.h"

namespace fs = std::filesystem;

namespace ptmkit {
namespace {

using test::run_limited;
using test::slurp;
using test::spit;

constexpr long long kAddressSpace = 2LL << 30;

// These tests run the command under an address-space limit (RLIMIT_AS). AddressSanitizer
// reserves terabytes of shadow memory at start, so under it the limited command cannot even
// start: the tests run in the plain build only.
class ReliabilityLimits : public ::testing::Test {
 protected:
  void SetUp() override {
#if defined(PTMKIT_ASAN)
    GTEST_SKIP() << "an address-space limit cannot be combined with AddressSanitizer";
#endif
  }
};

test::LimitedRun run_bounded(const std::vector<std::string>& args) {
  return run_limited(args, {.address_space_bytes = kAddressSpace});
}

void expect_error(const test::LimitedRun& r, const std::string& file, const std::string& says) {
  EXPECT_EQ(r.exit_code, 1) << r.err << r.out;
  EXPECT_NE(r.err.find(file), std::string::npos) << r.err;
  EXPECT_NE(r.err.find(says), std::string::npos) << r.err;
  EXPECT_EQ(r.err.find("bad_alloc"), std::string::npos) << r.err;
  EXPECT_LT(r.err.size(), 600u) << "error message not short: " << r.err.size() << " bytes";
}

std::string rti_header(int w, int h, int terms) {
  std::ostringstream s;
  s << "#HSH1.2\n3\n" << w << " " << h << " 3\n" << terms << " 2 1\n";
  return s.str();
}

TEST_F(ReliabilityLimits, ShortRtiDeclaringHugeSizesIsRefusedBeforeAllocating) {
  test::ScratchDir dir;
  for (const int side : {4096, 5000, 60000}) {
    const fs::path p = dir / ("big" + std::to_string(side) + ".rti");
    std::string bytes = rti_header(side, side, 16);
    bytes.resize(144, '\0');
    spit(p, bytes);
    expect_error(
        run_bounded({"relight", p.string(), "--light", "0,0,1", "-o", (dir / "x.png").string()}),
        p.filename().string(), "too short");
    expect_error(run_bounded({"info", p.string()}), p.filename().string(), "too short");
  }
  EXPECT_FALSE(fs::exists(dir / "x.png"));
}

TEST_F(ReliabilityLimits, RtiAndPtmWithBytesAfterTheDataAreErrors) {
  test::ScratchDir dir;
  const test::RunResult s =
      test::run_ptmkit({"synth", "--out", (dir / "cap").string(), "--size", "16", "--no-truth"});
  ASSERT_EQ(s.exit_code, 0) << s.err;
  const fs::path ptm = dir / "a.ptm";
  ASSERT_EQ(
      test::run_ptmkit({"fit", (dir / "cap" / "lights.lp").string(), "-o", ptm.string()}).exit_code,
      0);
  // A duplicated header line: the header then ends one line later, and the data is shifted.
  std::string bytes = slurp(ptm);
  const std::size_t second = bytes.find('\n') + 1;
  const std::size_t third = bytes.find('\n', second) + 1;
  const std::string dup =
      bytes.substr(0, second) + bytes.substr(second, third - second) + bytes.substr(second);
  const fs::path bad = dir / "dup.ptm";
  spit(bad, dup);
  const test::LimitedRun r =
      run_bounded({"relight", bad.string(), "--light", "0,0,1", "-o", (dir / "x.png").string()});
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_NE(r.err.find("dup.ptm"), std::string::npos) << r.err;
  // Trailing bytes alone.
  const fs::path trailing = dir / "trailing.ptm";
  spit(trailing, bytes + "junk");
  expect_error(run_bounded({"relight", trailing.string(), "--light", "0,0,1", "-o",
                            (dir / "x.png").string()}),
               "trailing.ptm", "4 bytes after the binary block");
  EXPECT_FALSE(fs::exists(dir / "x.png"));
  expect_error(run_bounded({"info", trailing.string()}), "trailing.ptm",
               "4 bytes after the binary block");

  const fs::path rti = dir / "a.rti";
  ASSERT_EQ(test::run_ptmkit({"fit", (dir / "cap" / "lights.lp").string(), "-o", rti.string(),
                              "--model", "hsh2"})
                .exit_code,
            0);
  spit(rti, slurp(rti) + "x");
  expect_error(run_bounded({"info", rti.string()}), "a.rti", "1 bytes after the binary block");
}

TEST_F(ReliabilityLimits, DevicesAndHugeLightFilesAreRefusedUnread) {
  test::ScratchDir dir;
  expect_error(run_bounded({"fit", "/dev/zero", "-o", (dir / "x.ptm").string()}), "/dev/zero",
               "not a regular file");
  // A sparse file one byte over the text-file limit: refused by its size, not read.
  const fs::path big = dir / "big.lp";
  { std::ofstream(big) << "1\n"; }
  fs::resize_file(big, kMaxTextFileBytes + 1);
  expect_error(run_bounded({"fit", big.string(), "-o", (dir / "x.ptm").string()}), "big.lp",
               "more than a light file may be");
  const fs::path board = dir / "board.json";
  { std::ofstream(board) << "{}"; }
  fs::resize_file(board, kMaxTextFileBytes + 1);
  expect_error(run_bounded({"calibrate", "plane", board.string(), "--board", board.string(),
                            "--camera", board.string(), "-o", (dir / "p.json").string()}),
               "board.json", "more than");
  EXPECT_FALSE(fs::exists(dir / "x.ptm"));
}

TEST_F(ReliabilityLimits, LightFileCountsAndEchoedNamesAreBounded) {
  test::ScratchDir dir;
  const fs::path lp = dir / "count.lp";
  spit(lp, std::to_string(kMaxLights + 1) + "\n");
  expect_error(run_bounded({"fit", lp.string(), "-o", (dir / "x.ptm").string()}), "count.lp",
               "more than the 10000 allowed");
  std::string many;
  for (long long i = 0; i <= kMaxLights; ++i) {
    many.append("img").append(std::to_string(i)).append(".png 0 0 1\n");
  }
  const fs::path lp2 = dir / "many.lp";
  spit(lp2, many);
  expect_error(run_bounded({"fit", lp2.string(), "-o", (dir / "x.ptm").string()}), "many.lp",
               "more than 10000 lights");
  // A 1 MB number, a 50 MB name and raw binary bytes: quoted as a short printable excerpt.
  const fs::path lp3 = dir / "long.lp";
  spit(lp3, "img.png 0 0 " + std::string(1 << 20, 'z') + "\n");
  expect_error(run_bounded({"fit", lp3.string(), "-o", (dir / "x.ptm").string()}), "long.lp",
               "is not a number");
  const fs::path lp5 = dir / "name.lp";
  spit(lp5, std::string(50 << 20, 'n') + ".png 0 0 1\n");
  expect_error(run_bounded({"fit", lp5.string(), "-o", (dir / "x.ptm").string()}), "name.lp",
               "longer than a path may be");
  const fs::path lp4 = dir / "binary.lp";
  spit(lp4, std::string("\x01\x02\xff\xfe\x7f", 5) + "\n");
  const test::LimitedRun b = run_bounded({"fit", lp4.string(), "-o", (dir / "x.ptm").string()});
  expect_error(b, "binary.lp", "\\x01\\x02\\xFF");
}

TEST_F(ReliabilityLimits, BoardGridsAndTagIdsAreBounded) {
  test::ScratchDir dir;
  const auto board_error = [&](const std::string& json, const std::string& says) {
    const fs::path p = dir / "board.json";
    spit(p, json);
    // `calibrate plane` reads the board first.
    expect_error(run_bounded({"calibrate", "plane", p.string(), "--board", p.string(), "--camera",
                              p.string(), "-o", (dir / "p.json").string()}),
                 "board.json", says);
  };
  board_error(R"({"tag_size_mm": 10, "grid": {"cols": 100000, "rows": 100000, "spacing_mm": 12}})",
              "more than the 100000 a board may have");
  board_error(R"({"tag_size_mm": 10, "grid": {"cols": 4, "rows": 4, "spacing_mm": 12,
              "first_id": 2147483640}})",
              "passes the largest tag id");
  board_error(R"({"tag_size_mm": 10, "grid": {"cols": 4, "rows": 4, "spacing_mm": 12,
              "first_id": 99999999999}})",
              "must be an integer in");
}

TEST_F(ReliabilityLimits, RingLayoutsAreBoundedPerRingAndInAll) {
  test::ScratchDir dir;
  const test::LimitedRun over = run_bounded(
      {"synth", "--out", (dir / "s").string(), "--lights", "rings:30:100001", "--size", "8"});
  EXPECT_EQ(over.exit_code, 1);
  EXPECT_NE(over.err.find("count must be 1..10000"), std::string::npos) << over.err;
  std::string rings = "rings:";
  for (int i = 0; i < 300; ++i) rings.append(i ? ",30:100000" : "30:100000");
  const test::LimitedRun many =
      run_bounded({"synth", "--out", (dir / "s").string(), "--lights", rings, "--size", "8"});
  EXPECT_EQ(many.exit_code, 1);
  EXPECT_LT(many.err.size(), 600u);
  std::string total = "rings:";
  for (int i = 0; i < 3; ++i) total.append(i ? ",30:5000" : "30:5000");
  const test::LimitedRun all =
      run_bounded({"synth", "--out", (dir / "s").string(), "--lights", total, "--size", "8"});
  EXPECT_EQ(all.exit_code, 1);
  EXPECT_NE(all.err.find("more than 10000 lights in all"), std::string::npos) << all.err;
  EXPECT_FALSE(fs::exists(dir / "s"));
}

TEST_F(ReliabilityLimits, DomeJsonLightCountIsBounded) {
  test::ScratchDir dir;
  std::string json = R"({"lights": [)";
  for (long long i = 0; i <= kMaxLights; ++i) {
    json.append(i ? "," : "").append(R"({"image": "a.png", "direction": [0, 0, 1]})");
  }
  json += "]}";
  const fs::path p = dir / "dome.json";
  spit(p, json);
  expect_error(
      run_bounded({"calibrate", "dome", "--layout", p.string(), "-o", (dir / "x.lp").string()}),
      "dome.json", "more than the 10000 allowed");
}

TEST_F(ReliabilityLimits, HugeFloatCaptureIsAnErrorNamingTheTexel) {
  test::ScratchDir dir;
  const fs::path cap = dir / "cap";
  const test::RunResult s =
      test::run_ptmkit({"synth", "--out", cap.string(), "--size", "16", "--no-truth", "--format",
                        "exr", "--exposure", "1e38", "--noise", "0", "--preset", "matte"});
  ASSERT_EQ(s.exit_code, 0) << s.err;
  for (const std::string out : {"x.rti", "x.ptm"}) {
    const test::RunResult r =
        test::run_ptmkit({"fit", (cap / "lights.lp").string(), "-o", (dir / out).string(),
                          "--model", out == "x.rti" ? "hsh2" : "ptm"});
    EXPECT_EQ(r.exit_code, 1) << out;
    EXPECT_NE(r.err.find("of texel ("), std::string::npos) << r.err;
    EXPECT_FALSE(fs::exists(dir / out));
  }
}

TEST_F(ReliabilityLimits, OutOfMemoryNamesTheCommand) {
  test::ScratchDir dir;
  // A legitimate but large synthesis under a small address space: the allocation fails.
  const test::LimitedRun r =
      run_limited({"synth", "--out", (dir / "s").string(), "--size", "16384", "--threads", "1"},
                  {.address_space_bytes = 1LL << 30});
  EXPECT_EQ(r.exit_code, 1) << r.err << r.out;
  EXPECT_NE(r.err.find("ptmkit synth: error: out of memory"), std::string::npos) << r.err;
  EXPECT_FALSE(fs::exists(dir / "s"));
}

}  // namespace
}  // namespace ptmkit
