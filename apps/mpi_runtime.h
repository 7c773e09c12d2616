// The MPI calls ptmkit makes, behind an interface: MPI's libraries (Open MPI brings a dozen,
// and its own start-up) are loaded, from the libptmkit_mpi.so module, only by a process that
// an MPI launcher started. A plain run, and a build without MPI, never load them.
#pragma once

#include <optional>
#include <string>
#include <utility>

#include "ptmkit/core/collective.h"

namespace ptmkit::app {

class MpiRuntime {
 public:
  virtual ~MpiRuntime() = default;
  // MPI_Init (the calling thread is the only one that calls MPI) and MPI_Finalize.
  virtual void init(int* argc, char*** argv) = 0;
  virtual void finalize() = 0;
  // The collective over every process of the job (valid after init()).
  virtual Collective& world() = 0;
  // Point to point, for the job dispatcher (apps/mpi_collective.cc's run_children).
  virtual void send_text(const std::string& text, int to, int tag) = 0;
  // A message with `tag` from any process, if one is waiting: (sender, text).
  virtual std::optional<std::pair<int, std::string>> poll_text(int tag) = 0;
  virtual void send_int(int value, int to, int tag) = 0;
  virtual int receive_int(int from, int tag) = 0;
};

}  // namespace ptmkit::app

// The module's one exported symbol.
extern "C" ptmkit::app::MpiRuntime* ptmkit_mpi_runtime();
