#include "test_util.h"

#include <fcntl.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <array>
#include <cstdlib>
#include <fstream>
#include <functional>
#include <sstream>

#include <gtest/gtest.h>

namespace fs = std::filesystem;

namespace ptmkit::test {

namespace {
std::string current_test_name() {
  const auto* info = ::testing::UnitTest::GetInstance()->current_test_info();
  if (info == nullptr) return "no-test";
  return std::string(info->test_suite_name()) + "." + info->name();
}

std::string read_all(const fs::path& p) {
  std::ifstream in(p, std::ios::binary);
  std::stringstream ss;
  ss << in.rdbuf();
  return ss.str();
}
}  // namespace

ScratchDir::ScratchDir() {
  std::string name = current_test_name();
  std::replace_if(
      name.begin(), name.end(), [](char c) { return c == '/' || c == '.'; }, '_');
  path_ = fs::temp_directory_path() / ("ptmkit-test-" + std::to_string(::getpid())) / name;
  fs::remove_all(path_);
  fs::create_directories(path_);
}

ScratchDir::~ScratchDir() {
  if (std::getenv("PTMKIT_KEEP_TMP") == nullptr) {
    std::error_code ec;
    fs::remove_all(path_, ec);
    // The process's folder too, once its last scratch folder is gone (remove leaves a folder
    // that is not empty): ctest runs each test in a process of its own.
    fs::remove(path_.parent_path(), ec);
  }
}

fs::path source_dir() { return fs::path(PTMKIT_SOURCE_DIR); }

std::optional<fs::path> shared_data(const std::string& sub) {
  fs::path root;
  if (const char* env = std::getenv("PTMKIT_DATA_DIR"); env != nullptr && *env != '\0') {
    root = env;
  } else {
    root = source_dir().parent_path() / "shared" / "data";
  }
  fs::path p = root / sub;
  if (!fs::exists(p)) return std::nullopt;
  return p;
}

RunResult run_ptmkit(const std::vector<std::string>& args) {
  std::vector<std::string> argv{PTMKIT_BINARY};
  argv.insert(argv.end(), args.begin(), args.end());
  return run_command(argv);
}

RunResult run_command(const std::vector<std::string>& args) {
  RunResult result;
  const fs::path tmp =
      fs::temp_directory_path() / ("ptmkit-run-" + std::to_string(::getpid()) + "-" +
                                   std::to_string(std::hash<std::string>{}(current_test_name())));
  const fs::path out_path = tmp.string() + ".out";
  const fs::path err_path = tmp.string() + ".err";
  std::vector<std::string> argv_store = args;
  std::vector<char*> argv;
  for (auto& a : argv_store) argv.push_back(a.data());
  argv.push_back(nullptr);

  const pid_t pid = ::fork();
  if (pid == 0) {
    const int out_fd = ::open(out_path.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
    const int err_fd = ::open(err_path.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
    if (out_fd < 0 || err_fd < 0) ::_exit(127);
    ::dup2(out_fd, 1);
    ::dup2(err_fd, 2);
    ::execvp(argv[0], argv.data());
    ::_exit(127);
  }
  int status = 0;
  ::waitpid(pid, &status, 0);
  result.exit_code = WIFEXITED(status) ? WEXITSTATUS(status) : 128 + WTERMSIG(status);
  result.out = read_all(out_path);
  result.err = read_all(err_path);
  std::error_code ec;
  fs::remove(out_path, ec);
  fs::remove(err_path, ec);
  return result;
}

std::uint64_t test_seed() {
  // FNV-1a of the test's name: stable across runs and platforms.
  std::uint64_t h = 1469598103934665603ull;
  for (char c : current_test_name()) {
    h ^= static_cast<unsigned char>(c);
    h *= 1099511628211ull;
  }
  return h;
}

std::vector<std::string> list_files(const fs::path& dir) {
  std::vector<std::string> names;
  if (!fs::exists(dir)) return names;
  for (const auto& e : fs::directory_iterator(dir)) {
    if (e.is_regular_file()) names.push_back(e.path().filename().string());
  }
  std::sort(names.begin(), names.end());
  return names;
}

}  // namespace ptmkit::test
