// `ptmkit fit` shared among the processes of an MPI job (mpirun, oversubscribed on this
// machine): the output is byte-identical to one process's at 1-4 processes for every model,
// colour model, solver and input option; what cannot be shared is refused; a process that
// fails stops the job with one message and no output. Skipped in builds without MPI.
#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <fcntl.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cstdlib>
#include <filesystem>
#include <ostream>
#include <string>
#include <system_error>
#include <thread>
#include <vector>

#include <nlohmann/json.hpp>

#include "ptmkit/core/image.h"
#include "ptmkit/core/image_io.h"
#include "reliability_util.h"
#include "test_util.h"

namespace ptmkit {
namespace {

namespace fs = std::filesystem;
using ::testing::HasSubstr;

#ifdef PTMKIT_MPIEXEC
constexpr bool kHaveMpi = true;
constexpr const char* kMpiexec = PTMKIT_MPIEXEC;
#else
constexpr bool kHaveMpi = false;
constexpr const char* kMpiexec = "";
#endif

// The environment of an MPI job started by these tests. Open MPI refuses root unless told
// twice (CI runs as root). In the sanitizer build, leak checking is off in the job's
// processes: Open MPI's runtime keeps allocations in plugins it unloads at MPI_Finalize, which
// the leak checker then cannot name or suppress. (The single-process tests check ptmkit's own
// code for leaks.) Each test process gives its jobs a temporary folder of their own: Open MPI
// keeps its session under $TMPDIR/ompi.HOST.UID, which a job ending elsewhere removes while
// another (tests run two at a time) is creating its own in it ("A call to mkdir was unable to
// create the desired directory").
void mpi_environment() {
  ::setenv("OMPI_ALLOW_RUN_AS_ROOT", "1", 1);
  ::setenv("OMPI_ALLOW_RUN_AS_ROOT_CONFIRM", "1", 1);
  // Short (the session holds Unix sockets, whose paths are limited to about 100 bytes).
  struct Session {
    fs::path dir = fs::temp_directory_path() / ("ptmkit-mpi-" + std::to_string(::getpid()));
    Session() { fs::create_directories(dir); }
    ~Session() {
      std::error_code ec;
      fs::remove_all(dir, ec);
    }
  };
  static const Session session;
  ::setenv("TMPDIR", session.dir.c_str(), 1);
#ifdef PTMKIT_ASAN
  const char* asan = std::getenv("ASAN_OPTIONS");
  std::string options = asan != nullptr ? asan : "";
  if (options.find("detect_leaks=0") == std::string::npos) {
    options += options.empty() ? "detect_leaks=0" : ":detect_leaks=0";
    ::setenv("ASAN_OPTIONS", options.c_str(), 1);
  }
#endif
}

// `ptmkit ARGS` as `processes` processes of one MPI job (more processes than cores is what
// this 2-core machine can offer).
test::RunResult run_mpi(int processes, const std::vector<std::string>& args) {
  mpi_environment();
  std::vector<std::string> argv{kMpiexec, "-np", std::to_string(processes), "--oversubscribe",
                                PTMKIT_BINARY};
  argv.insert(argv.end(), args.begin(), args.end());
  return test::run_command(argv);
}

// Lines of `text` that contain `needle`.
int count_lines(const std::string& text, const std::string& needle) {
  int n = 0;
  std::size_t at = 0;
  while ((at = text.find(needle, at)) != std::string::npos) {
    ++n;
    at += needle.size();
  }
  return n;
}

// Temporaries or anything else left in `dir` besides `keep`.
std::vector<std::string> leftovers(const fs::path& dir, const std::vector<std::string>& keep) {
  std::vector<std::string> out;
  for (const std::string& name : test::list_files(dir)) {
    if (std::find(keep.begin(), keep.end(), name) == keep.end()) out.push_back(name);
  }
  return out;
}

// One capture set for the whole suite: a distant-light capture, a near-light one, a mask.
class MpiFit : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    if (!kHaveMpi) return;
    dir_ = new test::ScratchDir();
    const auto synth = [](const std::vector<std::string>& args) {
      const test::RunResult r = test::run_ptmkit(args);
      ASSERT_EQ(r.exit_code, 0) << r.err;
    };
    synth({"synth", "--out", (*dir_ / "cap").string(), "--size", "72", "--seed", "3"});
    // JPEG: the processes below the first skip rows without decoding them.
    synth({"synth", "--out", (*dir_ / "capj").string(), "--size", "80", "--seed", "6", "--format",
           "jpg"});
    synth({"synth", "--out", (*dir_ / "near").string(), "--size", "64", "--seed", "4",
           "--dome-radius", "300", "--mm-per-px", "1"});
    Image mask(72, 72, 1, ColourSpace::kLinear, 0.0f);
    for (int y = 0; y < 72; ++y) {
      for (int x = 0; x < 72; ++x) {
        const int dx = x - 40, dy = y - 30;
        mask.at(x, y, 0) = dx * dx + dy * dy < 26 * 26 ? 1.0f : 0.0f;
      }
    }
    write_image(*dir_ / "mask.png", mask.view());
  }
  static void TearDownTestSuite() {
    delete dir_;
    dir_ = nullptr;
  }
  void SetUp() override {
    if (!kHaveMpi) GTEST_SKIP() << "built without MPI (libopenmpi-dev not found)";
  }
  static fs::path at(const std::string& name) { return *dir_ / name; }
  static test::ScratchDir* dir_;
};
test::ScratchDir* MpiFit::dir_ = nullptr;

struct Case {
  const char* name;
  std::vector<std::string> args;  // after `fit LIGHTS -o OUT`
  const char* capture;            // "cap" or "near"
  const char* ext;                // ".ptm" or ".rti"
};

void PrintTo(const Case& c, std::ostream* os) { *os << c.name; }

std::string case_name(const ::testing::TestParamInfo<Case>& info) { return info.param.name; }

class MpiIdentical : public MpiFit, public ::testing::WithParamInterface<Case> {};

TEST_P(MpiIdentical, SameBytesAsOneProcessAtOneToFourProcesses) {
  const Case& c = GetParam();
  const std::string lp = (at(c.capture) / "lights.lp").string();
  std::vector<std::string> extra = c.args;
  for (std::string& a : extra) {
    if (a == "MASK") a = at("mask.png").string();
    if (a == "LIGHTS_JSON") a = (at(c.capture) / "lights.json").string();
    if (a == "PLANE") a = (at(c.capture) / "plane.json").string();
  }
  test::ScratchDir out;
  const fs::path single = out / (std::string("single") + c.ext);
  std::vector<std::string> args{"fit", lp, "-o", single.string()};
  args.insert(args.end(), extra.begin(), extra.end());
  const test::RunResult one = test::run_ptmkit(args);
  ASSERT_EQ(one.exit_code, 0) << one.err;
  const std::string expected = test::slurp(single);
  ASSERT_GT(expected.size(), 1000u);
  for (int n = 1; n <= 4; ++n) {
    const fs::path shared = out / ("shared" + std::to_string(n) + c.ext);
    const fs::path report = out / ("report" + std::to_string(n) + ".json");
    args = {"fit", lp, "-o", shared.string(), "--report", report.string()};
    args.insert(args.end(), extra.begin(), extra.end());
    const test::RunResult r = run_mpi(n, args);
    ASSERT_EQ(r.exit_code, 0) << n << " processes: " << r.err << r.out;
    EXPECT_TRUE(test::slurp(shared) == expected) << n << " processes: the bytes differ";
    // One report, for the whole job.
    const nlohmann::json j = nlohmann::json::parse(test::slurp(report));
    EXPECT_EQ(j["processes"].get<int>(), n);
    EXPECT_EQ(count_lines(r.out, "wrote "), 1) << r.out;
  }
}

INSTANTIATE_TEST_SUITE_P(
    Models, MpiIdentical,
    ::testing::Values(Case{"ptm_rgb", {}, "cap", ".ptm"},
                      Case{"ptm_lrgb", {"--format", "lrgb"}, "cap", ".ptm"},
                      Case{"ptm_ycc", {"--format", "ycc"}, "cap", ".ptm"},
                      Case{"ptm_double", {"--precision", "double"}, "cap", ".ptm"},
                      Case{"hsh3_rti", {"--model", "hsh3"}, "cap", ".rti"},
                      Case{"auto", {"--model", "auto", "--format", "rgb"}, "cap", ".rti"},
                      Case{
                          "robust_lrgb", {"--solver", "robust", "--format", "lrgb"}, "cap", ".ptm"},
                      Case{"crop", {"--crop", "5,9,51,47"}, "cap", ".ptm"},
                      Case{"jpeg_lrgb", {"--format", "lrgb"}, "capj", ".ptm"},
                      Case{"jpeg_crop", {"--crop", "3,21,70,45"}, "capj", ".ptm"},
                      Case{"mask", {"--mask", "MASK", "--format", "lrgb"}, "cap", ".ptm"},
                      Case{"near_falloff",
                           {"--lights-json", "LIGHTS_JSON", "--plane", "PLANE", "--falloff"},
                           "near",
                           ".ptm"}),
    case_name);

TEST_F(MpiFit, AFailingProcessStopsTheJobWithOneMessageAndNoOutput) {
  // A copy of the capture whose last image lost its second half: the processes that read
  // the lower rows fail, the first (top rows) does not.
  test::ScratchDir work;
  const fs::path cap = work / "cap";
  fs::copy(at("cap"), cap, fs::copy_options::recursive);
  const fs::path last = cap / "image_049.png";
  const std::string bytes = test::slurp(last);
  test::spit(last, bytes.substr(0, bytes.size() / 2));
  const fs::path out = work / "out.ptm";
  test::spit(out, "what was there before");
  const test::RunResult r = run_mpi(3, {"fit", (cap / "lights.lp").string(), "-o", out.string()});
  EXPECT_NE(r.exit_code, 0);
  EXPECT_EQ(count_lines(r.err, "ptmkit: error"), 1) << r.err;
  EXPECT_THAT(r.err, HasSubstr("image_049.png"));
  EXPECT_EQ(test::slurp(out), "what was there before");
  const std::vector<std::string> left = leftovers(work.path(), {"out.ptm"});
  EXPECT_TRUE(left.empty()) << left.size() << " files left, e.g. " << (left.empty() ? "" : left[0]);
}

// Processes whose command line holds `needle` and that are not the launcher itself.
std::vector<pid_t> ranks_with(const std::string& needle) {
  std::vector<pid_t> out;
  for (const auto& e : fs::directory_iterator("/proc")) {
    const std::string name = e.path().filename().string();
    if (name.find_first_not_of("0123456789") != std::string::npos) continue;
    std::string cmd = test::slurp(e.path() / "cmdline");
    for (char& c : cmd) c = c == '\0' ? ' ' : c;
    if (cmd.find(needle) == std::string::npos || cmd.find("mpirun") != std::string::npos ||
        cmd.find("mpiexec") != std::string::npos || cmd.find("orterun") != std::string::npos) {
      continue;
    }
    out.push_back(static_cast<pid_t>(std::stol(name)));
  }
  return out;
}

TEST_F(MpiFit, AKilledProcessEndsTheJobAndLeavesNoOutput) {
  // A slow solver (Ceres per texel) so the job is still running when one process is killed.
  test::ScratchDir work;
  const fs::path out = work / "killed.ptm";
  std::vector<std::string> argv{kMpiexec,
                                "-np",
                                "2",
                                "--oversubscribe",
                                PTMKIT_BINARY,
                                "fit",
                                (at("cap") / "lights.lp").string(),
                                "-o",
                                out.string(),
                                "--solver",
                                "ceres-huber",
                                "--threads",
                                "1"};
  mpi_environment();
  std::vector<char*> args;
  for (std::string& a : argv) args.push_back(a.data());
  args.push_back(nullptr);
  const pid_t job = ::fork();
  if (job == 0) {
    const int null_fd = ::open("/dev/null", O_WRONLY);
    ::dup2(null_fd, 1);
    ::dup2(null_fd, 2);
    ::execvp(args[0], args.data());
    ::_exit(127);
  }
  // Wait for the two processes, then kill one of them.
  std::vector<pid_t> ranks;
  for (int i = 0; i < 400 && ranks.size() < 2; ++i) {
    std::this_thread::sleep_for(std::chrono::milliseconds(25));
    ranks = ranks_with(out.string());
  }
  ASSERT_EQ(ranks.size(), 2u) << "the job's processes did not appear";
  std::this_thread::sleep_for(std::chrono::milliseconds(150));
  int status = 0;
  ASSERT_EQ(::waitpid(job, &status, WNOHANG), 0) << "the job ended before the kill";
  ASSERT_EQ(::kill(ranks.back(), SIGKILL), 0);
  ::waitpid(job, &status, 0);
  EXPECT_FALSE(WIFEXITED(status) && WEXITSTATUS(status) == 0) << "the job reported success";
  EXPECT_FALSE(fs::exists(out));
  // What a killed process may leave (rank 0's hidden temporary) goes with the next run there.
  const test::RunResult next = test::run_ptmkit(
      {"fit", (at("cap") / "lights.lp").string(), "-o", (work / "next.ptm").string()});
  ASSERT_EQ(next.exit_code, 0) << next.err;
  const std::vector<std::string> left = leftovers(work.path(), {"next.ptm"});
  EXPECT_TRUE(left.empty()) << left.size() << " files left, e.g. " << (left.empty() ? "" : left[0]);
}

TEST_F(MpiFit, WhatCannotBeSharedIsRefused) {
  test::ScratchDir work;
  const std::string lp = (at("cap") / "lights.lp").string();
  // Per-texel maps are written by one process.
  test::RunResult r = run_mpi(
      2, {"fit", lp, "-o", (work / "a.ptm").string(), "--normals", (work / "n.png").string()});
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_EQ(count_lines(r.err, "ptmkit: error"), 1) << r.err;
  EXPECT_THAT(r.err, HasSubstr("in one process"));
  // Commands other than fit run as one process.
  r = run_mpi(2, {"synth", "--out", (work / "s").string(), "--size", "16"});
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_THAT(r.err, HasSubstr("only `ptmkit fit` runs as several processes"));
  // More processes than rows.
  r = run_mpi(4, {"fit", lp, "-o", (work / "b.ptm").string(), "--crop", "0,0,10,3"});
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_THAT(r.err, HasSubstr("4 processes for 3 rows"));
  EXPECT_TRUE(test::list_files(work.path()).empty());
}

TEST_F(MpiFit, BatchHandsCapturesToEveryProcessAndGathersOneSummary) {
  test::ScratchDir work;
  const std::string lp = (at("cap") / "lights.lp").string();
  const std::string near = (at("near") / "lights.lp").string();
  // (Names built by append: gcc 12 warns falsely on "c" + std::to_string(i).)
  const auto out_of = [&](int i) {
    std::string name = "c";
    name.append(std::to_string(i)).append(".ptm");
    return work / name;
  };
  std::string jobs;
  for (int i = 0; i < 5; ++i) {
    const fs::path out = out_of(i);
    jobs.append(lp).append(" ").append(out.string());
    jobs.append(i % 2 == 1 ? " --format lrgb\n" : "\n");
  }
  jobs += near + " " + (work / "bad.txt").string() + "\n";  // not .ptm: this one fails
  test::spit(work / "jobs.txt", jobs);
  const fs::path summary = work / "summary.json";
  const test::RunResult r =
      run_mpi(3, {"fit", "--batch", (work / "jobs.txt").string(), "--report", summary.string()});
  EXPECT_EQ(r.exit_code, 1) << r.err;
  EXPECT_EQ(count_lines(r.out, "6 captures: 5 ok, 1 failed"), 1) << r.out;
  const nlohmann::json j = nlohmann::json::parse(test::slurp(summary));
  EXPECT_EQ(j["processes"].get<int>(), 3);
  ASSERT_EQ(j["captures"].size(), 6u);
  EXPECT_EQ(j["captures"][5]["status"], "failed");
  // Each capture as one plain fit writes it.
  const fs::path ref = work / "ref.ptm";
  ASSERT_EQ(test::run_ptmkit({"fit", lp, "-o", ref.string(), "--format", "lrgb"}).exit_code, 0);
  EXPECT_TRUE(test::slurp(ref) == test::slurp(work / "c3.ptm"));
  for (int i = 0; i < 5; ++i) {
    EXPECT_TRUE(fs::exists(out_of(i))) << i;
  }
}

}  // namespace
}  // namespace ptmkit
