// libptmkit_mpi.so: ptmkit's MPI calls (apps/mpi_runtime.h), loaded by apps/mpi_collective.cc
// only when an MPI launcher started the process.
#include <cstdint>
#include <string>
#include <vector>

// The C interface only (MPI's C++ bindings are deprecated and need their own library).
#define OMPI_SKIP_MPICXX 1
#define MPICH_SKIP_MPICXX 1
#include <mpi.h>

#include "../mpi_runtime.h"

namespace ptmkit::app {
namespace {

class MpiCollective final : public Collective {
 public:
  void attach() {
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
  static void reduce(void* v, std::size_t n, MPI_Datatype type, MPI_Op op) {
    MPI_Allreduce(MPI_IN_PLACE, v, static_cast<int>(n), type, op, MPI_COMM_WORLD);
  }
  int rank_ = 0;
  int size_ = 1;
  bool finished_ = false;
  int first_failed_ = -1;
};

class Runtime final : public MpiRuntime {
 public:
  void init(int* argc, char*** argv) override {
    int provided = 0;
    MPI_Init_thread(argc, argv, MPI_THREAD_FUNNELED, &provided);
    world_.attach();
  }
  void finalize() override { MPI_Finalize(); }
  Collective& world() override { return world_; }
  void send_text(const std::string& text, int to, int tag) override {
    MPI_Send(text.data(), static_cast<int>(text.size()), MPI_CHAR, to, tag, MPI_COMM_WORLD);
  }
  std::optional<std::pair<int, std::string>> poll_text(int tag) override {
    int flag = 0;
    MPI_Status status;
    MPI_Iprobe(MPI_ANY_SOURCE, tag, MPI_COMM_WORLD, &flag, &status);
    if (flag == 0) return std::nullopt;
    int bytes = 0;
    MPI_Get_count(&status, MPI_CHAR, &bytes);
    std::string text(static_cast<std::size_t>(bytes), '\0');
    MPI_Recv(text.data(), bytes, MPI_CHAR, status.MPI_SOURCE, tag, MPI_COMM_WORLD,
             MPI_STATUS_IGNORE);
    return std::make_pair(status.MPI_SOURCE, std::move(text));
  }
  void send_int(int value, int to, int tag) override {
    MPI_Send(&value, 1, MPI_INT, to, tag, MPI_COMM_WORLD);
  }
  int receive_int(int from, int tag) override {
    int value = 0;
    MPI_Recv(&value, 1, MPI_INT, from, tag, MPI_COMM_WORLD, MPI_STATUS_IGNORE);
    return value;
  }

 private:
  MpiCollective world_;
};

}  // namespace
}  // namespace ptmkit::app

extern "C" __attribute__((visibility("default"))) ptmkit::app::MpiRuntime* ptmkit_mpi_runtime() {
  static ptmkit::app::Runtime runtime;
  return &runtime;
}
