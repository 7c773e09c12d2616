// Subcommands of the ptmkit binary. Each binds its flags to a stage's Options, makes one
// library call, and prints a short summary. A subcommand's callback throws ptmkit::Error on
// a user error; main() turns that into a message on stderr and exit code 1.
#pragma once

#include <CLI/CLI.hpp>

#include "ptmkit/fit/robust.h"

namespace ptmkit::app {

void add_synth_command(CLI::App& root);
void add_fit_command(CLI::App& root);
void add_relight_command(CLI::App& root);
void add_info_command(CLI::App& root);
void add_render_command(CLI::App& root);
void add_direct_command(CLI::App& root);
void add_compare_command(CLI::App& root);
void add_calibrate_command(CLI::App& root);
void add_calibrate_board_commands(CLI::App* calibrate);  // calibrate camera, calibrate plane

// The robust solvers' tuning flags (--shadow-k, --highlight-k, --readmit-k, --dark-fraction,
// --keep-within-grey, --no-fill), bound to *robust; shared by fit and compare.
void add_robust_flags(CLI::App* cmd, fit::RobustOptions* robust);

}  // namespace ptmkit::app
