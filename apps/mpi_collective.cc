#include "mpi_collective.h"

#include <dlfcn.h>
#include <fcntl.h>
#include <spawn.h>
#include <sys/wait.h>
#include <unistd.h>

#include <array>
#include <chrono>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <optional>
#include <string>
#include <thread>
#include <vector>

#include <cerrno>

#include "mpi_runtime.h"
#include "ptmkit/core/error.h"

namespace ptmkit::app {

namespace {

const MpiSession* g_session = nullptr;

// Processes the launcher says it started (Open MPI, PMI/PMIx as Slurm's srun sets them); 0
// when no launcher started this one.
int launched_size() {
  for (const char* name : {"OMPI_COMM_WORLD_SIZE", "PMI_SIZE"}) {
    const char* v = std::getenv(name);
    if (v != nullptr && *v != '\0') return std::atoi(v);
  }
  // PMIx launchers (srun --mpi=pmix) always set the rank; the size comes from MPI itself.
  if (const char* v = std::getenv("PMIX_RANK"); v != nullptr && *v != '\0') return -1;
  return 0;
}

MpiRuntime* g_runtime = nullptr;

// Where the MPI module may be: $PTMKIT_MPI_MODULE, beside the executable, ../lib/ptmkit from
// it (an installed tree), and where the build put it.
std::vector<std::filesystem::path> module_candidates() {
  std::vector<std::filesystem::path> out;
  if (const char* env = std::getenv("PTMKIT_MPI_MODULE"); env != nullptr && *env != '\0') {
    out.emplace_back(env);
    return out;
  }
  std::array<char, 4096> exe{};
  const ssize_t n = ::readlink("/proc/self/exe", exe.data(), exe.size() - 1);
  if (n > 0) {
    const std::filesystem::path dir =
        std::filesystem::path(std::string(exe.data(), static_cast<std::size_t>(n))).parent_path();
    out.push_back(dir / "libptmkit_mpi.so");
    out.push_back(dir / ".." / "lib" / "ptmkit" / "libptmkit_mpi.so");
  }
#ifdef PTMKIT_MPI_MODULE_BUILD_PATH
  out.emplace_back(PTMKIT_MPI_MODULE_BUILD_PATH);
#endif
  return out;
}

// The module's runtime, or an error saying why there is none.
MpiRuntime* load_runtime(int processes) {
  std::string tried;
  for (const std::filesystem::path& p : module_candidates()) {
    std::error_code ec;
    if (!std::filesystem::exists(p, ec)) continue;
    void* handle = ::dlopen(p.c_str(), RTLD_NOW | RTLD_GLOBAL);
    if (handle == nullptr) {
      const char* why = ::dlerror();
      tried.append(" ").append(p.string()).append(" (").append(why != nullptr ? why : "?");
      tried.append(")");
      continue;
    }
    auto* factory = reinterpret_cast<MpiRuntime* (*)()>(::dlsym(handle, "ptmkit_mpi_runtime"));
    if (factory != nullptr) return factory();
  }
  throw Error("an MPI launcher started this ptmkit as one of " + std::to_string(processes) +
              " processes, but its MPI module (libptmkit_mpi.so) " +
              (tried.empty() ? std::string("is not installed: this build has no MPI support")
                             : "could not be loaded:" + tried) +
              "; rebuild with MPI (Debian: libopenmpi-dev) or run one process (each would do "
              "the whole job)");
}

}  // namespace

MpiSession::MpiSession(int* argc, char*** argv) {
  g_session = this;
  const int launched = launched_size();
  if (launched == 0 || launched == 1) return;
  g_runtime = load_runtime(launched);
  g_runtime->init(argc, argv);
  initialised_ = true;
  if (g_runtime->world().size() > 1) collective_ = &g_runtime->world();
}

MpiSession::~MpiSession() {
  if (initialised_) g_runtime->finalize();
  g_session = nullptr;
}

int MpiSession::rank() const { return collective_ != nullptr ? collective_->rank() : 0; }
int MpiSession::size() const { return collective_ != nullptr ? collective_->size() : 1; }

const MpiSession* mpi_session() { return g_session; }

namespace {

std::vector<std::string> g_command_line;

// The environment minus what tells a process it was started by an MPI launcher.
std::vector<std::string> plain_environment() {
  std::vector<std::string> out;
  for (char** e = environ; *e != nullptr; ++e) {
    const std::string v = *e;
    if (v.rfind("OMPI_", 0) == 0 || v.rfind("PMIX_", 0) == 0 || v.rfind("PMI_", 0) == 0 ||
        v.rfind("OPAL_", 0) == 0) {
      continue;
    }
    out.push_back(v);
  }
  return out;
}

std::string read_whole(const std::filesystem::path& p) {
  std::ifstream in(p, std::ios::binary);
  return {std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
}

// One running child: its pid, start time and where its output goes.
struct Child {
  pid_t pid = -1;
  std::chrono::steady_clock::time_point start;
  std::filesystem::path out, err;
};

Child start_child(const std::vector<std::string>& args) {
  Child c;
  char tmpl_out[] = "/tmp/ptmkit-child-XXXXXX";
  char tmpl_err[] = "/tmp/ptmkit-child-XXXXXX";
  const int out_fd = ::mkstemp(tmpl_out);
  const int err_fd = ::mkstemp(tmpl_err);
  if (out_fd < 0 || err_fd < 0) throw Error("cannot create a temporary file in /tmp");
  c.out = tmpl_out;
  c.err = tmpl_err;
  posix_spawn_file_actions_t actions;
  posix_spawn_file_actions_init(&actions);
  posix_spawn_file_actions_adddup2(&actions, out_fd, 1);
  posix_spawn_file_actions_adddup2(&actions, err_fd, 2);
  std::vector<std::string> argv_store{"/proc/self/exe"};
  argv_store.insert(argv_store.end(), args.begin(), args.end());
  std::vector<char*> argv;
  for (std::string& a : argv_store) argv.push_back(a.data());
  argv.push_back(nullptr);
  std::vector<std::string> env_store = plain_environment();
  std::vector<char*> envp;
  for (std::string& e : env_store) envp.push_back(e.data());
  envp.push_back(nullptr);
  c.start = std::chrono::steady_clock::now();
  const int rc =
      ::posix_spawn(&c.pid, "/proc/self/exe", &actions, nullptr, argv.data(), envp.data());
  posix_spawn_file_actions_destroy(&actions);
  ::close(out_fd);
  ::close(err_fd);
  if (rc != 0) throw Error(std::string("cannot start a child process: ") + std::strerror(rc));
  return c;
}

// The child's result once it has ended (blocking or not); nullopt while it runs.
std::optional<ChildResult> reap(const Child& c, bool block) {
  int status = 0;
  pid_t r = 0;
  do {
    r = ::waitpid(c.pid, &status, block ? 0 : WNOHANG);
  } while (r < 0 && errno == EINTR);
  if (r == 0) return std::nullopt;
  ChildResult res;
  res.exit_code = r < 0                 ? 127
                  : WIFEXITED(status)   ? WEXITSTATUS(status)
                  : WIFSIGNALED(status) ? 128 + WTERMSIG(status)
                                        : 127;
  res.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - c.start).count();
  res.out = read_whole(c.out);
  res.err = read_whole(c.err);
  std::error_code ec;
  std::filesystem::remove(c.out, ec);
  std::filesystem::remove(c.err, ec);
  return res;
}

// A result through MPI: exit code, seconds, then the two texts.
std::string pack(const ChildResult& r) {
  std::string s = std::to_string(r.exit_code) + "\n" + std::to_string(r.seconds) + "\n" +
                  std::to_string(r.out.size()) + "\n" + r.out + r.err;
  return s;
}
ChildResult unpack(const std::string& s) {
  ChildResult r;
  std::size_t a = s.find('\n');
  std::size_t b = s.find('\n', a + 1);
  std::size_t c = s.find('\n', b + 1);
  r.exit_code = std::stoi(s.substr(0, a));
  r.seconds = std::stod(s.substr(a + 1, b - a - 1));
  const std::size_t n = std::stoul(s.substr(b + 1, c - b - 1));
  r.out = s.substr(c + 1, n);
  r.err = s.substr(c + 1 + n);
  return r;
}

constexpr int kTagRequest = 101;  // worker -> 0: "give me work" (+ the last result)
constexpr int kTagJob = 102;      // 0 -> worker: the job index, or -1 for none left

}  // namespace

void set_command_line(int argc, char** argv) { g_command_line.assign(argv, argv + argc); }
const std::vector<std::string>& command_line() { return g_command_line; }

std::vector<ChildResult> run_children(
    const std::vector<std::vector<std::string>>& commands, Collective* peers,
    const std::function<void(std::size_t, const ChildResult&)>& on_done) {
  std::vector<ChildResult> results(commands.size());
  if (peers == nullptr) {
    for (std::size_t i = 0; i < commands.size(); ++i) {
      results[i] = *reap(start_child(commands[i]), true);
      if (on_done) on_done(i, results[i]);
    }
    return results;
  }
  MpiRuntime& mpi = *g_runtime;
  const int n = static_cast<int>(commands.size());
  if (peers->rank() != 0) {
    // Ask for work, run it, send the result with the next request.
    std::string last;
    int last_index = -1;
    for (;;) {
      mpi.send_text(std::to_string(last_index) + "\n" + last, 0, kTagRequest);
      const int index = mpi.receive_int(0, kTagJob);
      if (index < 0) return {};
      last = pack(*reap(start_child(commands[static_cast<std::size_t>(index)]), true));
      last_index = index;
    }
  }
  // Rank 0 hands out work and runs its own, polling both (MPI is only called from here).
  int next = 0;
  int workers_left = peers->size() - 1;
  std::optional<Child> own;
  int own_index = -1;
  const auto record = [&](int index, ChildResult r) {
    results[static_cast<std::size_t>(index)] = std::move(r);
    if (on_done) on_done(static_cast<std::size_t>(index), results[static_cast<std::size_t>(index)]);
  };
  while (workers_left > 0 || own || next < n) {
    bool busy = false;
    if (!own && next < n) {
      own_index = next++;
      own = start_child(commands[static_cast<std::size_t>(own_index)]);
      busy = true;
    }
    if (auto msg = mpi.poll_text(kTagRequest)) {
      const std::string& text = msg->second;
      const std::size_t nl = text.find('\n');
      const int done = std::stoi(text.substr(0, nl));
      if (done >= 0) record(done, unpack(text.substr(nl + 1)));
      const int index = next < n ? next++ : -1;
      if (index < 0) --workers_left;
      mpi.send_int(index, msg->first, kTagJob);
      busy = true;
    }
    if (own) {
      if (std::optional<ChildResult> r = reap(*own, false)) {
        record(own_index, std::move(*r));
        own.reset();
        busy = true;
      }
    }
    if (!busy) std::this_thread::sleep_for(std::chrono::milliseconds(5));
  }
  return results;
}

}  // namespace ptmkit::app
