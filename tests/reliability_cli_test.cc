// What a failed command leaves behind: full disks (a file-size limit makes every write past it
// fail, as a full disk does), outputs that are not regular files, symbolic links, folders of
// outputs that fail partway, and commands whose several outputs must commit together.
#include <sys/stat.h>
#include <sys/sysmacros.h>

#include <gtest/gtest.h>

#include <map>

#include "ptmkit/core/image_io.h"
#include "reliability_util.h"
#include "test_util.h"

namespace fs = std::filesystem;

namespace ptmkit {
namespace {

using test::Limits;
using test::run_limited;
using test::slurp;
using test::spit;

// A small synthetic capture (linear 8-bit PNGs, 49 lights) and its fitted .ptm.
struct Capture {
  fs::path lp;
  fs::path ptm;
};
Capture make_capture(const test::ScratchDir& dir, int size = 32) {
  Capture c;
  const test::RunResult s = test::run_ptmkit(
      {"synth", "--out", (dir / "cap").string(), "--size", std::to_string(size), "--no-truth"});
  EXPECT_EQ(s.exit_code, 0) << s.err;
  c.lp = dir / "cap" / "lights.lp";
  c.ptm = dir / "cap.ptm";
  const test::RunResult f = test::run_ptmkit({"fit", c.lp.string(), "-o", c.ptm.string()});
  EXPECT_EQ(f.exit_code, 0) << f.err;
  return c;
}

// Every regular file under `dir` with its content.
std::map<std::string, std::string> snapshot(const fs::path& dir) {
  std::map<std::string, std::string> m;
  for (const auto& e : fs::recursive_directory_iterator(dir)) {
    if (e.is_regular_file()) m[fs::relative(e.path(), dir).string()] = slurp(e.path());
  }
  return m;
}

constexpr long long kFullDiskBytes = 1000;  // every image below is larger

TEST(ReliabilityFullDisk, RelightSingleImageFailsAndKeepsTheEarlierFile) {
  test::ScratchDir dir;
  const Capture c = make_capture(dir);
  for (const std::string ext : {".png", ".tif", ".exr", ".jpg"}) {
    SCOPED_TRACE(ext);
    const fs::path out = dir / ("relit" + ext);
    const fs::path fresh = dir / ("fresh" + ext);
    spit(out, "earlier content");
    for (const fs::path& p : {out, fresh}) {
      const test::LimitedRun r =
          run_limited({"relight", c.ptm.string(), "--light", "0.3,0.2,0.9", "-o", p.string()},
                      {.file_size_bytes = kFullDiskBytes});
      EXPECT_NE(r.exit_code, 0) << r.out;
      EXPECT_EQ(r.out.find("wrote"), std::string::npos) << r.out;
    }
    EXPECT_EQ(slurp(out), "earlier content");
    EXPECT_FALSE(fs::exists(fresh));
  }
  // Whatever a failed run left (a library that exits on its own skips clean-up), the next
  // run in the folder removes it.
  const test::RunResult ok =
      test::run_ptmkit({"relight", c.ptm.string(), "--light", "0,0,1", "-o", (dir / "ok.png")});
  ASSERT_EQ(ok.exit_code, 0) << ok.err;
  EXPECT_TRUE(test::temporaries(dir.path()).empty());
}

TEST(ReliabilityFullDisk, RelightOutDirReportsNoSuccessAndKeepsEarlierResults) {
  test::ScratchDir dir;
  const Capture c = make_capture(dir);
  const fs::path out = dir / "relit";
  const test::RunResult first =
      test::run_ptmkit({"relight", c.ptm.string(), "--lights", c.lp.string(), "--out-dir",
                        out.string(), "--colour-space", "linear", "--bits", "16"});
  ASSERT_EQ(first.exit_code, 0) << first.err;
  const auto before = snapshot(out);
  ASSERT_EQ(before.size(), 49u);
  const test::LimitedRun r = run_limited({"relight", c.ptm.string(), "--lights", c.lp.string(),
                                          "--out-dir", out.string(), "--colour-space", "linear"},
                                         {.file_size_bytes = kFullDiskBytes});
  EXPECT_NE(r.exit_code, 0);
  EXPECT_EQ(r.out.find("relit images"), std::string::npos) << r.out;
  EXPECT_EQ(snapshot(out), before);
  EXPECT_TRUE(test::temporaries(dir.path()).empty());
  // Into a new folder: nothing at all.
  const test::LimitedRun fresh =
      run_limited({"relight", c.ptm.string(), "--lights", c.lp.string(), "--out-dir",
                   (dir / "new").string(), "--colour-space", "linear"},
                  {.file_size_bytes = kFullDiskBytes});
  EXPECT_NE(fresh.exit_code, 0);
  EXPECT_FALSE(fs::exists(dir / "new"));
}

TEST(ReliabilityFullDisk, SynthLeavesNoEmptyImages) {
  test::ScratchDir dir;
  for (const std::string format : {"png", "tif", "exr", "jpg"}) {
    SCOPED_TRACE(format);
    const fs::path out = dir / ("synth-" + format);
    const test::LimitedRun r = run_limited(
        {"synth", "--out", out.string(), "--size", "32", "--no-truth", "--format", format},
        {.file_size_bytes = kFullDiskBytes});
    EXPECT_EQ(r.exit_code, 1) << r.err;
    EXPECT_NE(r.err.find("write failed"), std::string::npos) << r.err;
    EXPECT_FALSE(fs::exists(out)) << test::list_files(out).size() << " files left";
    const test::RunResult next = test::run_ptmkit(
        {"synth", "--out", out.string(), "--size", "16", "--no-truth", "--format", format});
    EXPECT_EQ(next.exit_code, 0) << next.err;
    EXPECT_TRUE(test::temporaries(out).empty());
  }
  // Into an earlier capture (with truth): it stays as it was.
  const fs::path cap = dir / "cap";
  ASSERT_EQ(
      test::run_ptmkit({"synth", "--out", cap.string(), "--size", "32", "--seed", "7"}).exit_code,
      0);
  const auto before = snapshot(cap);
  const test::LimitedRun r = run_limited({"synth", "--out", cap.string(), "--size", "32"},
                                         {.file_size_bytes = kFullDiskBytes});
  EXPECT_NE(r.exit_code, 0);
  EXPECT_EQ(snapshot(cap), before);
}

TEST(ReliabilityFullDisk, FitPtmAndRtiFailAndKeepTheEarlierFile) {
  test::ScratchDir dir;
  const Capture c = make_capture(dir);
  const fs::path rti = dir / "cap.rti";
  spit(rti, "earlier rti");
  const std::string earlier_ptm = slurp(c.ptm);
  const test::LimitedRun p = run_limited({"fit", c.lp.string(), "-o", c.ptm.string()},
                                         {.file_size_bytes = kFullDiskBytes});
  EXPECT_NE(p.exit_code, 0);
  EXPECT_NE(p.err.find("cap.ptm"), std::string::npos) << p.err;
  EXPECT_EQ(slurp(c.ptm), earlier_ptm);
  const test::LimitedRun h =
      run_limited({"fit", c.lp.string(), "-o", rti.string(), "--model", "hsh2"},
                  {.file_size_bytes = kFullDiskBytes});
  EXPECT_NE(h.exit_code, 0);
  EXPECT_EQ(slurp(rti), "earlier rti");
  EXPECT_TRUE(test::temporaries(dir.path()).empty());
}

// A folder of outputs written as a whole: a web export and a JPEG .ptm conversion on a full
// disk leave the earlier folder and file as they were, a new one absent, and no staging
// folder behind.
TEST(ReliabilityFullDisk, ExportsFailAndKeepTheEarlierOutputs) {
  test::ScratchDir dir;
  const Capture c = make_capture(dir);
  const fs::path web = dir / "web";
  const test::RunResult first =
      test::run_ptmkit({"export", "web", c.ptm.string(), "-o", web.string()});
  ASSERT_EQ(first.exit_code, 0) << first.err;
  const auto before = snapshot(web);
  const fs::path jpeg = dir / "j.ptm";
  spit(jpeg, "earlier ptm");
  for (const std::vector<std::string>& args :
       {std::vector<std::string>{"export", "web", c.ptm.string(), "-o", web.string(), "--quality",
                                 "80"},
        {"export", "web", c.ptm.string(), "-o", (dir / "fresh").string()},
        {"export", "ptm", c.ptm.string(), "-o", jpeg.string(), "--format", "jpeg-rgb"}}) {
    const test::LimitedRun r = run_limited(args, {.file_size_bytes = kFullDiskBytes});
    EXPECT_EQ(r.exit_code, 1) << args[1] << " " << r.out;
  }
  EXPECT_EQ(snapshot(web), before);
  EXPECT_FALSE(fs::exists(dir / "fresh"));
  EXPECT_EQ(slurp(jpeg), "earlier ptm");
  EXPECT_TRUE(test::temporaries(dir.path()).empty());
}

TEST(ReliabilityOutputs, FitCommitsThePtmOnlyWithItsMapsAndReport) {
  test::ScratchDir dir;
  const Capture c = make_capture(dir);
  const std::string earlier = slurp(c.ptm);
  fs::create_directory(dir / "normals.png");  // a map path that cannot be written
  const test::RunResult r = test::run_ptmkit(
      {"fit", c.lp.string(), "-o", c.ptm.string(), "--solver", "robust", "--normals",
       (dir / "normals.png").string(), "--report", (dir / "report.json").string()});
  EXPECT_NE(r.exit_code, 0);
  EXPECT_EQ(slurp(c.ptm), earlier);
  EXPECT_FALSE(fs::exists(dir / "report.json"));
  // The report into a missing folder: the same.
  const test::RunResult r2 =
      test::run_ptmkit({"fit", c.lp.string(), "-o", (dir / "new.ptm").string(), "--report",
                        (dir / "missing" / "report.json").string()});
  EXPECT_NE(r2.exit_code, 0);
  EXPECT_FALSE(fs::exists(dir / "new.ptm"));
  EXPECT_TRUE(test::temporaries(dir.path()).empty());
}

TEST(ReliabilityOutputs, ReportIntoAFifoOrADeviceIsRefused) {
  test::ScratchDir dir;
  const Capture c = make_capture(dir);
  const fs::path fifo = dir / "fifo.json";
  ASSERT_EQ(::mkfifo(fifo.c_str(), 0600), 0);
  const test::RunResult r = test::run_ptmkit(
      {"fit", c.lp.string(), "-o", (dir / "x.ptm").string(), "--report", fifo.string()});
  EXPECT_NE(r.exit_code, 0);
  EXPECT_NE(r.err.find("not a regular file"), std::string::npos) << r.err;
  EXPECT_TRUE(fs::is_fifo(fifo));
  EXPECT_FALSE(fs::exists(dir / "x.ptm"));
  // A copy of /dev/null's node stands for /dev/null (replacing the real one would break the
  // machine if this failed).
  const fs::path null = dir / "null";
  if (::mknod(null.c_str(), S_IFCHR | 0666, makedev(1, 3)) == 0) {
    const test::RunResult n = test::run_ptmkit(
        {"fit", c.lp.string(), "-o", (dir / "y.ptm").string(), "--report", null.string()});
    EXPECT_NE(n.exit_code, 0);
    EXPECT_TRUE(fs::is_character_file(null));
  }
}

TEST(ReliabilityOutputs, OutputThroughASymbolicLinkReplacesItsTarget) {
  test::ScratchDir dir;
  const Capture c = make_capture(dir);
  fs::create_directory(dir / "store");
  spit(dir / "store" / "relit.png", "earlier");
  fs::create_symlink(dir / "store" / "relit.png", dir / "link.png");
  const test::RunResult r = test::run_ptmkit(
      {"relight", c.ptm.string(), "--light", "0,0,1", "-o", (dir / "link.png").string()});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_TRUE(fs::is_symlink(dir / "link.png"));
  EXPECT_NE(slurp(dir / "store" / "relit.png"), "earlier");
  EXPECT_EQ(slurp(dir / "store" / "relit.png").substr(1, 3), "PNG");
}

TEST(ReliabilityOutputs, RelightOutDirFailingPartwayRestoresEarlierResults) {
  test::ScratchDir dir;
  const Capture c = make_capture(dir);
  const fs::path out = dir / "relit";
  ASSERT_EQ(test::run_ptmkit({"relight", c.ptm.string(), "--lights", c.lp.string(), "--out-dir",
                              out.string(), "--colour-space", "linear", "--bits", "16"})
                .exit_code,
            0);
  const auto before = snapshot(out);
  // A photo cut short halfway through the set: the comparison fails after 24 images.
  const fs::path photo = dir / "cap" / "image_025.png";
  const std::string bytes = slurp(photo);
  spit(photo, bytes.substr(0, bytes.size() / 2));
  const test::RunResult r =
      test::run_ptmkit({"relight", c.ptm.string(), "--lights", c.lp.string(), "--out-dir",
                        out.string(), "--colour-space", "linear"});
  EXPECT_NE(r.exit_code, 0);
  EXPECT_NE(r.err.find("image_025.png"), std::string::npos) << r.err;
  EXPECT_EQ(snapshot(out), before);
  spit(photo, bytes);
  // A name that is a folder.
  fs::remove(out / "image_030.png");
  fs::create_directory(out / "image_030.png");
  const auto before2 = snapshot(out);
  const test::RunResult r2 =
      test::run_ptmkit({"relight", c.ptm.string(), "--lights", c.lp.string(), "--out-dir",
                        out.string(), "--colour-space", "linear"});
  EXPECT_NE(r2.exit_code, 0);
  EXPECT_EQ(snapshot(out), before2);
  EXPECT_TRUE(test::temporaries(dir.path()).empty());
}

// A mask caught among the photographs by a shell pattern (`chrome.*.png` takes
// `chrome.mask.png` too) is named as the problem, with what to do, before any search.
TEST(ReliabilityCli, CalibrationNamesAMaskGivenAsAPhotograph) {
  test::ScratchDir dir;
  Image photo(64, 48, 3, ColourSpace::kSRGB, 0.2f);
  Image mask(64, 48, 1, ColourSpace::kSRGB, 0.0f);
  for (int y = 10; y < 30; ++y)
    for (int x = 20; x < 40; ++x) mask.at(x, y, 0) = 1.0f;
  for (int y = 10; y < 30; ++y) mask.at(40, y, 0) = 0.5f;  // an anti-aliased edge
  write_image(dir / "ball.0.png", photo.view());
  write_image(dir / "ball.1.png", photo.view());
  write_image(dir / "ball.mask.png", mask.view());
  const test::RunResult r = test::run_ptmkit(
      {"calibrate", "sphere", (dir / "ball.0.png").string(), (dir / "ball.1.png").string(),
       (dir / "ball.mask.png").string(), "-o", (dir / "lights.lp").string()});
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_NE(r.err.find("ball.mask.png: a mask"), std::string::npos) << r.err;
  EXPECT_NE(r.err.find("--mask"), std::string::npos) << r.err;
  EXPECT_FALSE(fs::exists(dir / "lights.lp"));
}

}  // namespace
}  // namespace ptmkit
