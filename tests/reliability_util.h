// Helpers of the reliability tests: running the CLI under a file-size or address-space limit
// (a full disk, a small machine), killing it after a delay, and reading files back whole.
#pragma once

#include <fcntl.h>
#include <signal.h>
#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <string>
#include <thread>
#include <vector>

#include "test_util.h"

namespace ptmkit::test {

struct Limits {
  long long file_size_bytes = -1;      // RLIMIT_FSIZE: writes past it fail with EFBIG (a full disk)
  long long address_space_bytes = -1;  // RLIMIT_AS
  double kill_after_s = -1.0;          // SIGKILL the run after this long
};

struct LimitedRun {
  int exit_code = -1;  // 128 + signal when killed
  bool killed = false;
  double elapsed_s = 0.0;  // from fork to exit or kill
  std::string out;
  std::string err;
};

inline std::string slurp(const std::filesystem::path& p) {
  std::ifstream in(p, std::ios::binary);
  return {std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
}

inline void spit(const std::filesystem::path& p, const std::string& bytes) {
  std::ofstream out(p, std::ios::binary | std::ios::trunc);
  out.write(bytes.data(), static_cast<std::streamsize>(bytes.size()));
}

// Runs the built ptmkit with `args` (no shell) under `limits`.
inline LimitedRun run_limited(const std::vector<std::string>& args, const Limits& limits) {
  LimitedRun result;
  char tmpl_out[] = "/tmp/ptmkit-rel-out-XXXXXX";
  char tmpl_err[] = "/tmp/ptmkit-rel-err-XXXXXX";
  const int out_fd = ::mkstemp(tmpl_out);
  const int err_fd = ::mkstemp(tmpl_err);
  std::vector<std::string> store{PTMKIT_BINARY};
  store.insert(store.end(), args.begin(), args.end());
  std::vector<char*> argv;
  for (auto& a : store) argv.push_back(a.data());
  argv.push_back(nullptr);
  const auto start = std::chrono::steady_clock::now();
  const pid_t pid = ::fork();
  if (pid == 0) {
    ::dup2(out_fd, 1);
    ::dup2(err_fd, 2);
    ::signal(SIGXFSZ, SIG_IGN);  // a write past the limit then fails with EFBIG, as on a full disk
    if (limits.file_size_bytes >= 0) {
      const rlimit rl{static_cast<rlim_t>(limits.file_size_bytes),
                      static_cast<rlim_t>(limits.file_size_bytes)};
      ::setrlimit(RLIMIT_FSIZE, &rl);
    }
    if (limits.address_space_bytes >= 0) {
      const rlimit rl{static_cast<rlim_t>(limits.address_space_bytes),
                      static_cast<rlim_t>(limits.address_space_bytes)};
      ::setrlimit(RLIMIT_AS, &rl);
    }
    ::execv(argv[0], argv.data());
    ::_exit(127);
  }
  int status = 0;
  if (limits.kill_after_s >= 0.0) {
    const auto end = std::chrono::steady_clock::now() +
                     std::chrono::microseconds(static_cast<long long>(limits.kill_after_s * 1e6));
    while (std::chrono::steady_clock::now() < end) {
      if (::waitpid(pid, &status, WNOHANG) == pid) goto done;
      std::this_thread::sleep_for(std::chrono::microseconds(200));
    }
    ::kill(pid, SIGKILL);
    result.killed = true;
  }
  ::waitpid(pid, &status, 0);
done:
  result.elapsed_s =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  result.exit_code = WIFEXITED(status) ? WEXITSTATUS(status) : 128 + WTERMSIG(status);
  if (WIFEXITED(status)) result.killed = false;
  ::close(out_fd);
  ::close(err_fd);
  result.out = slurp(tmpl_out);
  result.err = slurp(tmpl_err);
  ::unlink(tmpl_out);
  ::unlink(tmpl_err);
  return result;
}

// Files under `dir` (recursively) whose name starts with ".ptmkit-tmp-".
inline std::vector<std::string> temporaries(const std::filesystem::path& dir) {
  std::vector<std::string> found;
  std::error_code ec;
  for (std::filesystem::recursive_directory_iterator it(dir, ec), end; !ec && it != end;
       it.increment(ec)) {
    const std::string name = it->path().filename().string();
    if (name.rfind(".ptmkit-tmp-", 0) == 0 || name.find(".tmp-") != std::string::npos) {
      found.push_back(it->path().string());
    }
  }
  return found;
}

}  // namespace ptmkit::test
