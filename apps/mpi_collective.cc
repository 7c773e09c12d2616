#include "mpi_collective.h"

#include <cstdlib>
#include <cstring>
#include <string>
#include <vector>

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

}  // namespace ptmkit::app
