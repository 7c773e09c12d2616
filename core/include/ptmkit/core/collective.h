// Work shared by several processes (ranks of an MPI job): what they must agree on and how a
// failure in one reaches the others. The stages see only this interface; the MPI
// implementation lives with the command (apps/mpi_collective.h), so no library depends on MPI.
//
// The protocol every distributed writer follows: agreements (all()) separate the steps that
// can fail, and a process that fails calls fail(), which takes part in the next agreement the
// others reach with "false". Every process then stops with an error; rank 0 has created
// nothing that outlives it (its temporary files are removed by its OutputTransaction).
#pragma once

#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

#include "ptmkit/core/error.h"

namespace ptmkit {

// Thrown on every process when another process reported a failure in an agreement: that
// process prints the cause; this one says only that it stopped because of it.
class PeerFailure : public Error {
 public:
  using Error::Error;
};

class Collective {
 public:
  virtual ~Collective() = default;

  [[nodiscard]] virtual int rank() const = 0;
  [[nodiscard]] virtual int size() const = 0;

  // Element-wise over every process; the result on every process. `n` equal everywhere.
  virtual void min(double* values, std::size_t n) = 0;
  virtual void max(double* values, std::size_t n) = 0;
  virtual void sum(double* values, std::size_t n) = 0;
  virtual void sum(std::uint64_t* values, std::size_t n) = 0;
  // Rank 0's text on every process.
  virtual void broadcast(std::string* text) = 0;

  // An agreement: true on every process when `ok` is true on every process (also a barrier).
  [[nodiscard]] virtual bool all(bool ok) = 0;
  // This process failed: takes part in the next agreement the others reach, with false, so
  // they stop too. Does nothing after finish().
  virtual void fail() = 0;
  // After an agreement that failed: the lowest rank that reported the failure (the one whose
  // message is shown, so a failure every process meets is printed once); -1 before.
  [[nodiscard]] virtual int first_failed_rank() const = 0;
  // No collective follows on this process: a failure after this is its own (fail() no-ops).
  virtual void finish() = 0;

  // all(ok), throwing PeerFailure (naming `step`) when another process failed.
  void agree(bool ok, const std::string& step) {
    if (!all(ok)) {
      throw PeerFailure(step + ": another process of the job failed (its message says why)");
    }
  }
};

// Rows [begin, end) of `height` that rank `rank` of `size` takes: contiguous blocks, sizes
// differing by at most one, in rank order.
struct RowRange {
  int begin = 0;
  int end = 0;
  [[nodiscard]] int rows() const { return end - begin; }
};
[[nodiscard]] inline RowRange rows_of_rank(int height, int rank, int size) {
  const auto part = [&](int r) {
    return static_cast<int>(static_cast<long long>(height) * r / size);
  };
  return {part(rank), part(rank + 1)};
}

}  // namespace ptmkit
