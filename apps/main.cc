// ptmkit: polynomial texture maps from photographs under known lights.
#include <cstdio>
#include <exception>
#include <memory>
#include <new>
#include <string>

#include <CLI/CLI.hpp>

#include "commands.h"
#include "mpi_collective.h"
#include "ptmkit/core/atomic_file.h"
#include "ptmkit/core/collective.h"
#include "ptmkit/core/error.h"
#include "ptmkit/core/version.h"

namespace {
constexpr const char* kExitCodes =
    "Exit codes: 0 success; 1 bad input or a failed step (the message names the file and the "
    "problem; no output is written: every output path keeps what it held before, see "
    "docs/RELIABILITY.md); 2 bad command line.";
}

namespace {

// Prints a command's error: under MPI only the process whose failure stopped the job (the
// lowest rank that failed), named; the others stop quietly.
void report_error(const ptmkit::app::MpiSession* mpi, const char* what, bool peer) {
  ptmkit::Collective* peers = mpi != nullptr ? mpi->collective() : nullptr;
  if (peers == nullptr) {
    std::fprintf(stderr, "ptmkit: error: %s\n", what);
    return;
  }
  if (!peer) peers->fail();
  if (peer) return;
  const int first = peers->first_failed_rank();
  if (first >= 0 && first != peers->rank()) return;
  std::fprintf(stderr, "ptmkit: error (process %d of %d): %s\n", peers->rank(), peers->size(),
               what);
}

// The subcommand named on the command line (the first word that is not an option).
std::string subcommand_of(int argc, char** argv) {
  for (int i = 1; i < argc; ++i) {
    if (argv[i][0] != '-') return argv[i];
  }
  return "";
}

}  // namespace

int main(int argc, char** argv) {
  ptmkit::app::set_command_line(argc, argv);
  std::unique_ptr<ptmkit::app::MpiSession> mpi;
  try {
    mpi = std::make_unique<ptmkit::app::MpiSession>(&argc, &argv);
    if (mpi->size() > 1 && subcommand_of(argc, argv) != "fit") {
      if (mpi->rank() == 0) {
        std::fprintf(stderr,
                     "ptmkit: error: only `ptmkit fit` runs as several processes (mpirun, srun); "
                     "start `ptmkit %s` as one process\n",
                     subcommand_of(argc, argv).c_str());
      }
      return 2;
    }
  } catch (const std::exception& e) {
    std::fprintf(stderr, "ptmkit: error: %s\n", e.what());
    return 1;
  }
  CLI::App app{
      "ptmkit: light-dependent textures (polynomial texture maps) from photographs "
      "under known lights.",
      "ptmkit"};
  app.footer(kExitCodes);
  app.require_subcommand(1);
  app.set_version_flag("--version", std::string("ptmkit ") + ptmkit::kVersion);
  ptmkit::app::add_synth_command(app);
  ptmkit::app::add_fit_command(app);
  ptmkit::app::add_relight_command(app);
  ptmkit::app::add_info_command(app);
  ptmkit::app::add_render_command(app);
  ptmkit::app::add_direct_command(app);
  ptmkit::app::add_compare_command(app);
  ptmkit::app::add_calibrate_command(app);
  ptmkit::app::add_export_command(app);
  ptmkit::app::add_view_command(app);
  // Every output of the command reaches its path together, after the command succeeded;
  // on any failure none does and earlier files stay as they were.
  ptmkit::OutputTransaction outputs;
  try {
    app.parse(argc, argv);
    outputs.commit();
  } catch (const CLI::CallForHelp& e) {
    return app.exit(e);
  } catch (const CLI::CallForAllHelp& e) {
    return app.exit(e);
  } catch (const CLI::CallForVersion& e) {
    return app.exit(e);
  } catch (const CLI::ParseError& e) {
    app.exit(e);
    return 2;
  } catch (const ptmkit::PeerFailure& e) {
    report_error(mpi.get(), e.what(), true);
    return 1;
  } catch (const ptmkit::Error& e) {
    report_error(mpi.get(), e.what(), false);
    return 1;
  } catch (const std::bad_alloc&) {
    if (mpi->collective() != nullptr) mpi->collective()->fail();
    std::string name = "ptmkit";
    for (const CLI::App* sub : app.get_subcommands()) name += " " + sub->get_name();
    std::fprintf(stderr,
                 "%s: error: out of memory (an input larger than this machine can hold?); "
                 "nothing was written\n",
                 name.c_str());
    return 1;
  } catch (const std::exception& e) {
    report_error(mpi.get(), e.what(), false);
    return 1;
  }
  return 0;
}
