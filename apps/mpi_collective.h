// The command's side of a distributed run: whether this process is one of several started by
// an MPI launcher (mpirun, srun), and the Collective (core/collective.h) that joins them.
#pragma once

#include <cstddef>
#include <functional>
#include <string>
#include <vector>

#include "ptmkit/core/collective.h"

namespace ptmkit::app {

// Lives for the whole of main(). Starts MPI only when an MPI launcher started this process
// (its environment says so), so a plain run never loads MPI's runtime state. A build
// without MPI refuses a launch with several processes (each would do the whole job).
class MpiSession {
 public:
  MpiSession(int* argc, char*** argv);
  ~MpiSession();
  MpiSession(const MpiSession&) = delete;
  MpiSession& operator=(const MpiSession&) = delete;

  // The job's collective when there are at least two processes; nullptr for one.
  [[nodiscard]] Collective* collective() const { return collective_; }
  // Rank and size (0 and 1 for a plain run).
  [[nodiscard]] int rank() const;
  [[nodiscard]] int size() const;

 private:
  Collective* collective_ = nullptr;
  bool initialised_ = false;
};

// The session of this process (set by MpiSession's constructor; nullptr before).
[[nodiscard]] const MpiSession* mpi_session();

// The command line main() was given (for commands that start copies of themselves).
void set_command_line(int argc, char** argv);
[[nodiscard]] const std::vector<std::string>& command_line();

// What one child command did.
struct ChildResult {
  int exit_code = -1;  // 128 + signal when it was killed
  double seconds = 0.0;
  std::string out;  // its stdout
  std::string err;  // its stderr
};

// Runs each of `commands` (arguments of this same ptmkit binary) as a child process, one at a
// time per process of the job, handed out in order as processes become free (rank 0 runs
// them too). Children never see the MPI launcher's environment: each is a plain run. Returns
// every command's result in order on rank 0 (or the one process), nothing elsewhere.
// `on_done(index, result)` is called on rank 0 as each finishes (progress lines).
std::vector<ChildResult> run_children(
    const std::vector<std::vector<std::string>>& commands, Collective* peers,
    const std::function<void(std::size_t, const ChildResult&)>& on_done);

}  // namespace ptmkit::app
