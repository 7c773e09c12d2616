// `ptmkit fit --batch JOBS.txt`: every capture fitted by its own child process, a failing one
// reported while the rest finish, a table and a JSON summary, exit code 1 when any failed.
#include <gtest/gtest.h>

#include <filesystem>
#include <string>

#include <nlohmann/json.hpp>

#include "reliability_util.h"
#include "test_util.h"

namespace ptmkit {
namespace {

namespace fs = std::filesystem;

TEST(FitBatch, EveryCaptureIsFittedAndAFailingOneIsReportedWhileTheRestFinish) {
  test::ScratchDir dir;
  for (const char* name : {"a", "b"}) {
    const test::RunResult s =
        test::run_ptmkit({"synth", "--out", (dir / name).string(), "--size", "40", "--seed", "7"});
    ASSERT_EQ(s.exit_code, 0) << s.err;
  }
  const std::string a = (dir / "a" / "lights.lp").string();
  const std::string b = (dir / "b" / "lights.lp").string();
  test::spit(dir / "jobs.txt",
             "# three captures, one missing\n" + a + " " + (dir / "a.ptm").string() + "\n\n\"" + b +
                 "\" " + (dir / "b.ptm").string() + " --format lrgb\n" +
                 (dir / "gone.lp").string() + " " + (dir / "gone.ptm").string() + "\n");
  const fs::path summary = dir / "summary.json";
  const test::RunResult r = test::run_ptmkit({"fit", "--batch", (dir / "jobs.txt").string(),
                                              "--report", summary.string(), "--threads", "1"});
  EXPECT_EQ(r.exit_code, 1) << r.err;
  EXPECT_NE(r.err.find("1 capture(s) failed"), std::string::npos) << r.err;
  EXPECT_NE(r.out.find("3 captures: 2 ok, 1 failed"), std::string::npos) << r.out;
  // The good captures are exactly what a plain fit writes, options of the line applied.
  const fs::path ref = dir / "ref.ptm";
  ASSERT_EQ(test::run_ptmkit({"fit", b, "-o", ref.string(), "--format", "lrgb"}).exit_code, 0);
  EXPECT_TRUE(test::slurp(ref) == test::slurp(dir / "b.ptm"));
  EXPECT_TRUE(fs::exists(dir / "a.ptm"));
  EXPECT_FALSE(fs::exists(dir / "gone.ptm"));
  // The summary is written though the command failed.
  const nlohmann::json j = nlohmann::json::parse(test::slurp(summary));
  ASSERT_EQ(j["captures"].size(), 3u);
  EXPECT_EQ(j["failed"].get<int>(), 1);
  EXPECT_EQ(j["captures"][0]["status"], "ok");
  EXPECT_GT(j["captures"][0]["residual_rms_grey"].get<double>(), 0.0);
  EXPECT_EQ(j["captures"][1]["line"].get<int>(), 4);
  EXPECT_EQ(j["captures"][2]["status"], "failed");
  EXPECT_NE(j["captures"][2]["error"].get<std::string>().find("gone.lp"), std::string::npos);
}

TEST(FitBatch, BadJobsFilesAreErrorsNamingTheLine) {
  test::ScratchDir dir;
  test::spit(dir / "short.txt", "# header\nonly-one-word\n");
  test::RunResult r = test::run_ptmkit({"fit", "--batch", (dir / "short.txt").string()});
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_NE(r.err.find("short.txt:2"), std::string::npos) << r.err;
  test::spit(dir / "quote.txt", "\"a.lp b.ptm\n");
  r = test::run_ptmkit({"fit", "--batch", (dir / "quote.txt").string()});
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_NE(r.err.find("quote is not closed"), std::string::npos) << r.err;
  test::spit(dir / "empty.txt", "# nothing\n\n");
  r = test::run_ptmkit({"fit", "--batch", (dir / "empty.txt").string()});
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_NE(r.err.find("no jobs"), std::string::npos) << r.err;
  r = test::run_ptmkit({"fit", "--batch", (dir / "missing.txt").string()});
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_NE(r.err.find("missing.txt"), std::string::npos) << r.err;
  r = test::run_ptmkit({"fit", "--batch", (dir / "empty.txt").string(), "x.lp"});
  EXPECT_EQ(r.exit_code, 2);  // a command-line error
  EXPECT_NE(r.err.find("give no light file"), std::string::npos) << r.err;
  EXPECT_EQ(test::list_files(dir.path()).size(), 3u);
}

}  // namespace
}  // namespace ptmkit
