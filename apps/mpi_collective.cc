#include "mpi_collective.h"

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

#ifdef PTMKIT_HAVE_MPI
// The C interface only (MPI's C++ bindings are deprecated and need their own library).
#define OMPI_SKIP_MPICXX 1
#define MPICH_SKIP_MPICXX 1
#include <mpi.h>
#endif

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

#ifdef PTMKIT_HAVE_MPI

class MpiCollective final : public Collective {
 public:
  MpiCollective() {
    MPI_Comm_rank(MPI_COMM_WORLD, &rank_);
    MPI_Comm_size(MPI_COMM_WORLD, &size_);
  }
  [[nodiscard]] int rank() const override { return rank_; }
  [[nodiscard]] int size() const override { return size_; }
  void min(double* v, std::size_t n) override { reduce(v, n, MPI_DOUBLE, MPI_MIN); }
  void max(double* v, std::size_t n) override { reduce(v, n, MPI_DOUBLE, MPI_MAX); }
  void sum(double* v, std::size_t n) override { reduce(v, n, MPI_DOUBLE, MPI_SUM); }
  void sum(std::uint64_t* v, std::size_t n) override { reduce(v, n, MPI_UINT64_T, MPI_SUM); }
  void broadcast(std::string* text) override {
    unsigned long long n = text->size();
    MPI_Bcast(&n, 1, MPI_UNSIGNED_LONG_LONG, 0, MPI_COMM_WORLD);
    text->resize(static_cast<std::size_t>(n));
    if (n > 0) MPI_Bcast(text->data(), static_cast<int>(n), MPI_CHAR, 0, MPI_COMM_WORLD);
  }
  [[nodiscard]] std::vector<std::string> gather(const std::string& text) override {
    int n = static_cast<int>(text.size());
    std::vector<int> sizes(rank_ == 0 ? static_cast<std::size_t>(size_) : 0);
    MPI_Gather(&n, 1, MPI_INT, sizes.data(), 1, MPI_INT, 0, MPI_COMM_WORLD);
    std::vector<int> offsets(sizes.size());
    int total = 0;
    for (std::size_t i = 0; i < sizes.size(); ++i) {
      offsets[i] = total;
      total += sizes[i];
    }
    std::string all(static_cast<std::size_t>(total), '\0');
    MPI_Gatherv(text.data(), n, MPI_CHAR, all.data(), sizes.data(), offsets.data(), MPI_CHAR, 0,
                MPI_COMM_WORLD);
    std::vector<std::string> out;
    for (std::size_t i = 0; i < sizes.size(); ++i) {
      out.push_back(
          all.substr(static_cast<std::size_t>(offsets[i]), static_cast<std::size_t>(sizes[i])));
    }
    return out;
  }
  [[nodiscard]] bool all(bool ok) override {
    if (finished_) return ok;
    // The lowest failing rank, or size_ when every process succeeded.
    int mine = ok ? size_ : rank_;
    int first = size_;
    MPI_Allreduce(&mine, &first, 1, MPI_INT, MPI_MIN, MPI_COMM_WORLD);
    if (first == size_) return true;
    // After a failed agreement every process stops: no further collective will be matched.
    finished_ = true;
    first_failed_ = first;
    return false;
  }
  [[nodiscard]] int first_failed_rank() const override { return first_failed_; }
  void fail() override {
    if (!finished_) (void)all(false);
  }
  void finish() override { finished_ = true; }

 private:
  void reduce(void* v, std::size_t n, MPI_Datatype type, MPI_Op op) {
    MPI_Allreduce(MPI_IN_PLACE, v, static_cast<int>(n), type, op, MPI_COMM_WORLD);
  }
  int rank_ = 0;
  int size_ = 1;
  bool finished_ = false;
  int first_failed_ = -1;
};

MpiCollective* g_mpi = nullptr;

#endif

}  // namespace

MpiSession::MpiSession(int* argc, char*** argv) {
  g_session = this;
  const int launched = launched_size();
  if (launched == 0 || launched == 1) return;
#ifdef PTMKIT_HAVE_MPI
  int provided = 0;
  // The fit's threads never call MPI: only the thread that called MPI_Init does.
  MPI_Init_thread(argc, argv, MPI_THREAD_FUNNELED, &provided);
  initialised_ = true;
  static MpiCollective collective;
  g_mpi = &collective;
  if (collective.size() > 1) collective_ = &collective;
#else
  (void)argc;
  (void)argv;
  throw Error("this ptmkit was built without MPI, but an MPI launcher started it as one of " +
              std::to_string(launched) +
              " processes (each would do the whole job): rebuild with MPI (libopenmpi-dev) "
              "or run one process");
#endif
}

MpiSession::~MpiSession() {
#ifdef PTMKIT_HAVE_MPI
  if (initialised_) MPI_Finalize();
#endif
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

#ifdef PTMKIT_HAVE_MPI
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

void send_text(const std::string& text, int to, int tag) {
  MPI_Send(text.data(), static_cast<int>(text.size()), MPI_CHAR, to, tag, MPI_COMM_WORLD);
}
#endif

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
#ifdef PTMKIT_HAVE_MPI
  const int n = static_cast<int>(commands.size());
  if (peers->rank() != 0) {
    // Ask for work, run it, send the result with the next request.
    std::string last;
    int last_index = -1;
    for (;;) {
      const std::string msg = std::to_string(last_index) + "\n" + last;
      send_text(msg, 0, kTagRequest);
      int index = -1;
      MPI_Recv(&index, 1, MPI_INT, 0, kTagJob, MPI_COMM_WORLD, MPI_STATUS_IGNORE);
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
  while (workers_left > 0 || own || next < n) {
    bool busy = false;
    if (!own && next < n) {
      own_index = next++;
      own = start_child(commands[static_cast<std::size_t>(own_index)]);
      busy = true;
    }
    int flag = 0;
    MPI_Status status;
    MPI_Iprobe(MPI_ANY_SOURCE, kTagRequest, MPI_COMM_WORLD, &flag, &status);
    if (flag != 0) {
      int bytes = 0;
      MPI_Get_count(&status, MPI_CHAR, &bytes);
      std::string msg(static_cast<std::size_t>(bytes), '\0');
      MPI_Recv(msg.data(), bytes, MPI_CHAR, status.MPI_SOURCE, kTagRequest, MPI_COMM_WORLD,
               MPI_STATUS_IGNORE);
      const std::size_t nl = msg.find('\n');
      const int done = std::stoi(msg.substr(0, nl));
      if (done >= 0) {
        results[static_cast<std::size_t>(done)] = unpack(msg.substr(nl + 1));
        if (on_done)
          on_done(static_cast<std::size_t>(done), results[static_cast<std::size_t>(done)]);
      }
      int index = next < n ? next++ : -1;
      if (index < 0) --workers_left;
      MPI_Send(&index, 1, MPI_INT, status.MPI_SOURCE, kTagJob, MPI_COMM_WORLD);
      busy = true;
    }
    if (own) {
      if (std::optional<ChildResult> r = reap(*own, false)) {
        results[static_cast<std::size_t>(own_index)] = std::move(*r);
        if (on_done)
          on_done(static_cast<std::size_t>(own_index),
                  results[static_cast<std::size_t>(own_index)]);
        own.reset();
        busy = true;
      }
    }
    if (!busy) std::this_thread::sleep_for(std::chrono::milliseconds(5));
  }
  return results;
#else
  (void)on_done;
  throw Error("run_children: several processes without MPI");
#endif
}

}  // namespace ptmkit::app
