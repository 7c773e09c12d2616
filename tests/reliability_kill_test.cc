// Crash safety: `fit`, `relight --out-dir` and `synth` killed with SIGKILL at seeded random
// moments. After every kill each output path holds either its earlier content or the complete
// new content; after the next full run no temporary is left.
#include <gtest/gtest.h>

#include <chrono>
#include <map>
#include <random>

#include "reliability_util.h"
#include "test_util.h"

namespace fs = std::filesystem;

namespace ptmkit {
namespace {

using test::slurp;

constexpr int kKills = 10;

using Contents = std::map<std::string, std::string>;  // relative path -> bytes

// The outputs, by path relative to `root`: the named files, or every regular file under the
// named folders (temporaries excepted: they are checked separately).
Contents outputs(const fs::path& root, const std::vector<std::string>& names) {
  Contents c;
  for (const std::string& n : names) {
    const fs::path p = root / n;
    if (fs::is_directory(p)) {
      for (const auto& e : fs::recursive_directory_iterator(p)) {
        const std::string name = e.path().filename().string();
        if (e.is_regular_file() && name.rfind(".ptmkit-tmp-", 0) != 0) {
          c[fs::relative(e.path(), root).string()] = slurp(e.path());
        }
      }
    } else if (fs::exists(p)) {
      c[n] = slurp(p);
    }
  }
  return c;
}

double seconds_of(const std::vector<std::string>& args) {
  const auto t0 = std::chrono::steady_clock::now();
  const test::RunResult r = test::run_ptmkit(args);
  EXPECT_EQ(r.exit_code, 0) << r.err;
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

// Runs `before` (the earlier outputs) and then `after` to completion in `root` to learn both
// states, then `kKills` times: `after` killed at a random moment (after `before` again when
// the previous run was not killed), and checks every output path.
void kill_and_check(const fs::path& root, const std::vector<std::string>& names,
                    const std::vector<std::string>& before, const std::vector<std::string>& after) {
  seconds_of(before);
  const Contents old_state = outputs(root, names);
  ASSERT_FALSE(old_state.empty());
  double full_s = seconds_of(after);
  const Contents new_state = outputs(root, names);
  ASSERT_FALSE(new_state.empty());
  std::mt19937_64 rng(test::test_seed());
  // Most of a short run is start-up; the draws favour its later part, where outputs are
  // written and committed. The run time is re-estimated from every run that ended before its
  // kill (the machine's load varies), so most runs are killed.
  std::uniform_real_distribution<double> fraction(0.3, 1.0);
  int killed = 0;
  bool completed = true;  // the outputs are all new: put the old ones back first
  for (int k = 0; k < kKills; ++k) {
    if (completed) seconds_of(before);
    const double delay = fraction(rng) * full_s;
    const test::LimitedRun r = test::run_limited(after, {.kill_after_s = delay});
    killed += r.killed ? 1 : 0;
    completed = !r.killed;
    if (completed) full_s = std::min(full_s, 0.9 * r.elapsed_s);
    const Contents now = outputs(root, names);
    for (const auto& [path, bytes] : now) {
      const auto o = old_state.find(path);
      const auto n = new_state.find(path);
      const bool is_old = o != old_state.end() && o->second == bytes;
      const bool is_new = n != new_state.end() && n->second == bytes;
      EXPECT_TRUE(is_old || is_new) << path << " after a kill at " << delay
                                    << " s: " << bytes.size() << " bytes, neither old nor new";
    }
    for (const auto& [path, bytes] : old_state) {
      EXPECT_TRUE(now.count(path)) << path << " disappeared after a kill at " << delay << " s";
    }
  }
  EXPECT_GT(killed, kKills / 3) << "too few runs were killed before they ended";
  seconds_of(after);
  EXPECT_EQ(outputs(root, names), new_state);
  EXPECT_TRUE(test::temporaries(root).empty());
}

// A 128 x 128 synthetic capture without truth; its light file, or "" if synth failed.
std::string small_capture(const fs::path& cap) {
  const auto r = test::run_ptmkit({"synth", "--out", cap.string(), "--size", "128", "--no-truth"});
  EXPECT_EQ(r.exit_code, 0) << r.err;
  return r.exit_code == 0 ? (cap / "lights.lp").string() : std::string();
}

TEST(ReliabilityKill, FitOutputsAreOldOrNew) {
  test::ScratchDir dir;
  const std::string lp = small_capture(dir / "cap");
  ASSERT_FALSE(lp.empty());
  const std::string ptm = (dir / "out.ptm").string();
  const std::string normals = (dir / "normals.png").string();
  kill_and_check(dir.path(), {"out.ptm", "normals.png"},
                 {"fit", lp, "-o", ptm, "--normals", normals, "--format", "lrgb"},
                 {"fit", lp, "-o", ptm, "--normals", normals});
}

TEST(ReliabilityKill, RelightOutDirImagesAreOldOrNew) {
  test::ScratchDir dir;
  const std::string lp = small_capture(dir / "cap");
  ASSERT_FALSE(lp.empty());
  const std::string ptm = (dir / "a.ptm").string();
  ASSERT_EQ(test::run_ptmkit({"fit", lp, "-o", ptm}).exit_code, 0);
  const std::string out = (dir / "relit").string();
  kill_and_check(dir.path(), {"relit"},
                 {"relight", ptm, "--lights", lp, "--out-dir", out, "--colour-space", "linear",
                  "--bits", "16"},
                 {"relight", ptm, "--lights", lp, "--out-dir", out, "--colour-space", "linear"});
}

// A web export replaces an earlier one as a whole: its folder is exchanged in one step.
TEST(ReliabilityKill, WebExportFilesAreOldOrNew) {
  test::ScratchDir dir;
  const std::string lp = small_capture(dir / "cap");
  ASSERT_FALSE(lp.empty());
  const std::string ptm = (dir / "a.ptm").string();
  ASSERT_EQ(test::run_ptmkit({"fit", lp, "-o", ptm}).exit_code, 0);
  const std::string web = (dir / "web").string();
  kill_and_check(dir.path(), {"web"}, {"export", "web", ptm, "-o", web, "--quality", "70"},
                 {"export", "web", ptm, "-o", web, "--quality", "95"});
}

TEST(ReliabilityKill, SynthCaptureFilesAreOldOrNew) {
  test::ScratchDir dir;
  const std::string out = (dir / "cap").string();
  kill_and_check(dir.path(), {"cap"}, {"synth", "--out", out, "--size", "96", "--seed", "1"},
                 {"synth", "--out", out, "--size", "96", "--seed", "2"});
}

}  // namespace
}  // namespace ptmkit
