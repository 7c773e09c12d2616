// The command's side of a distributed run: whether this process is one of several started by
// an MPI launcher (mpirun, srun), and the Collective (core/collective.h) that joins them.
#pragma once

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

}  // namespace ptmkit::app
