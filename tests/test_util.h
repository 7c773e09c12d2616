// Helpers shared by the tests: scratch folders, the third-party data folder, running the CLI,
// and reproducible seeds.
#pragma once

#include <cstdint>
#include <filesystem>
#include <optional>
#include <string>
#include <vector>

namespace ptmkit::test {

// Whether this is the AddressSanitizer + UBSan build (scripts/test.sh --sanitize).
#ifdef PTMKIT_SANITIZED_BUILD
inline constexpr bool kSanitizedBuild = true;
#else
inline constexpr bool kSanitizedBuild = false;
#endif

// The first statement of a test that renders or calibrates a photo-size capture (an accuracy
// figure, or a refusal only such a capture shows): under the sanitizers each takes a minute or
// more, so they run in the release build only, and the sanitizer build checks the same render
// and calibration code on the suite's smaller captures.
#define PTMKIT_RELEASE_BUILD_ONLY()                                                    \
  do {                                                                                 \
    if (::ptmkit::test::kSanitizedBuild) {                                             \
      GTEST_SKIP() << "accuracy on a large render: checked in the release build only"; \
    }                                                                                  \
  } while (false)

// A fresh empty folder for the current test, removed at destruction unless PTMKIT_KEEP_TMP is
// set in the environment.
class ScratchDir {
 public:
  ScratchDir();
  ~ScratchDir();
  ScratchDir(const ScratchDir&) = delete;
  ScratchDir& operator=(const ScratchDir&) = delete;
  [[nodiscard]] const std::filesystem::path& path() const { return path_; }
  [[nodiscard]] std::filesystem::path operator/(const std::string& name) const {
    return path_ / name;
  }

 private:
  std::filesystem::path path_;
};

// ../shared/data beside the source tree, or $PTMKIT_DATA_DIR; nullopt when the named
// sub-folder is absent (the caller then GTEST_SKIP()s with a message).
[[nodiscard]] std::optional<std::filesystem::path> shared_data(const std::string& sub);

// The source tree (for data/ files shipped with the project).
[[nodiscard]] std::filesystem::path source_dir();

struct RunResult {
  int exit_code = -1;
  std::string out;  // stdout
  std::string err;  // stderr
};
// Runs the built ptmkit binary with `args` (no shell), capturing its output.
[[nodiscard]] RunResult run_ptmkit(const std::vector<std::string>& args);
// Runs `argv` (argv[0] a path, or a name looked up on PATH; no shell), capturing its output.
[[nodiscard]] RunResult run_command(const std::vector<std::string>& argv);

// A seed derived from the running test's full name, so each test's randomness is fixed and a
// failure can be replayed.
[[nodiscard]] std::uint64_t test_seed();

// Lists the regular files in a folder (names only), sorted.
[[nodiscard]] std::vector<std::string> list_files(const std::filesystem::path& dir);

}  // namespace ptmkit::test
