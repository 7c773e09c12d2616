// Subcommands of the ptmkit binary. Each binds its flags to a stage's Options, makes one
// library call, and prints a short summary. A subcommand's callback throws ptmkit::Error on
// a user error; main() turns that into a message on stderr and exit code 1.
#pragma once

#include <CLI/CLI.hpp>

#include <filesystem>
#include <string>

#include "ptmkit/fit/robust.h"
#include "ptmkit/texture/web_export.h"

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
// `export` and its children: `web`, and `ptm`, `rti` (added by
// add_export_convert_commands(export_cmd)).
void add_export_command(CLI::App& root);
void add_view_command(CLI::App& root);

// Flags shared by `export web` and `view` (how a texture becomes a web folder).
struct WebExportArgs {
  std::string layout = "image";
  std::string normals;
  std::string jpeg_colour = "auto";
  texture::WebExportOptions options;
  // options with the layout and normals applied; throws ptmkit::Error on a bad layout.
  [[nodiscard]] texture::WebExportOptions resolved() const;
};
void add_web_export_flags(CLI::App* cmd, WebExportArgs* args);
// Reads a .ptm or an HSH .rti (by extension, else by content) and exports it.
texture::WebExportReport export_texture_to_web(const std::string& input,
                                               const std::filesystem::path& dir,
                                               const texture::WebExportOptions& options);
// export ptm, export rti (format conversions), children of the `export` parent.
void add_export_convert_commands(CLI::App& export_cmd);

// The robust solvers' tuning flags (--shadow-k, --highlight-k, --readmit-k, --dark-fraction,
// --keep-within-grey, --no-fill), bound to *robust; shared by fit and compare.
void add_robust_flags(CLI::App* cmd, fit::RobustOptions* robust);

}  // namespace ptmkit::app
