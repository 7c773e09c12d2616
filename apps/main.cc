// ptmkit: polynomial texture maps from photographs under known lights.
#include <cstdio>
#include <exception>
#include <new>
#include <string>

#include <CLI/CLI.hpp>

#include "commands.h"
#include "ptmkit/core/atomic_file.h"
#include "ptmkit/core/error.h"
#include "ptmkit/core/version.h"

namespace {
constexpr const char* kExitCodes =
    "Exit codes: 0 success; 1 bad input or a failed step (the message names the file and the "
    "problem; no output is written: every output path keeps what it held before, see "
    "docs/RELIABILITY.md); 2 bad command line.";
}

int main(int argc, char** argv) {
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
  } catch (const ptmkit::Error& e) {
    std::fprintf(stderr, "ptmkit: error: %s\n", e.what());
    return 1;
  } catch (const std::bad_alloc&) {
    std::string name = "ptmkit";
    for (const CLI::App* sub : app.get_subcommands()) name += " " + sub->get_name();
    std::fprintf(stderr,
                 "%s: error: out of memory (an input larger than this machine can hold?); "
                 "nothing was written\n",
                 name.c_str());
    return 1;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "ptmkit: error: %s\n", e.what());
    return 1;
  }
  return 0;
}
