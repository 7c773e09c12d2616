// ptmkit export web IN.ptm|IN.rti -o DIR: the relight/OpenLIME web folder with this project's
// viewer. `export` is the parent of every conversion; `export ptm|rti` are added beside `web`
// by add_export_convert_commands (apps/commands.h).
#include <cstdio>
#include <filesystem>
#include <memory>
#include <string>

#include "commands.h"
#include "ptmkit/core/error.h"
#include "ptmkit/texture/ptm.h"
#include "ptmkit/texture/rti.h"
#include "ptmkit/texture/web_export.h"

namespace fs = std::filesystem;

namespace ptmkit::app {

texture::WebExportReport export_texture_to_web(const std::string& input, const fs::path& dir,
                                               const texture::WebExportOptions& options) {
  std::error_code ec;
  if (!fs::is_regular_file(input, ec)) {
    throw Error(input + ": not a readable file (give a .ptm or an HSH .rti)");
  }
  const fs::path p(input);
  const bool rti =
      p.extension() == ".rti" || (p.extension() != ".ptm" && texture::looks_like_rti(p));
  if (rti) return texture::export_web(texture::read_rti(p), dir, options);
  return texture::export_web(texture::read_ptm(p), dir, options);
}

void add_web_export_flags(CLI::App* cmd, WebExportArgs* args) {
  cmd->add_option("--layout", args->layout,
                  "image: one plane_J.jpg per three planes; deepzoom: plane_J.dzi and "
                  "plane_J_files/LEVEL/X_Y.jpg tiles (OpenLIME's level count)")
      ->check(CLI::IsMember({"image", "deepzoom"}))
      ->capture_default_str();
  cmd->add_option("--tile-size", args->options.tile_size_px,
                  "Deep-zoom tile side in pixels (16..4096)")
      ->check(CLI::Range(16, 4096))
      ->capture_default_str();
  cmd->add_option("--quality", args->options.quality,
                  "JPEG quality of the planes, 1..100 (no chroma subsampling)")
      ->check(CLI::Range(1, 100))
      ->capture_default_str();
  cmd->add_option("--jpeg-colour", args->jpeg_colour,
                  "JPEG colour transform of the planes: auto (YCbCr for the rgb colour space, "
                  "as relight writes; none for lrgb), ycbcr, or none (R, G, B components: about "
                  "1-2 fewer bytes of error per plane, larger files)")
      ->check(CLI::IsMember({"auto", "ycbcr", "none"}))
      ->capture_default_str();
  cmd->add_option("--normals", args->normals,
                  "Normal map to include as normals.png (what `ptmkit fit --normals` wrote: "
                  ".exr with x, y, z, or .png with (n + 1) / 2); same size as the texture");
  cmd->add_option("--pixel-size-mm", args->options.pixel_size_mm,
                  "Size of one pixel on the object in mm (info.json pixelSizeInMM; the viewer's "
                  "scale bar). 0 = unknown")
      ->check(CLI::NonNegativeNumber)
      ->capture_default_str();
}

texture::WebExportOptions WebExportArgs::resolved() const {
  texture::WebExportOptions o = options;
  o.layout = texture::parse_web_layout(layout);
  o.normals = normals;
  o.jpeg_colour = texture::parse_web_jpeg_colour(jpeg_colour);
  return o;
}

namespace {

struct ExportWebArgs {
  std::string input;
  std::string output;
  WebExportArgs web;
  bool no_viewer = false;
};

void run_export_web(const ExportWebArgs& args) {
  texture::WebExportOptions options = args.web.resolved();
  options.viewer = !args.no_viewer;
  const texture::WebExportReport r = export_texture_to_web(args.input, args.output, options);
  std::printf("exported %s to %s: %s\n", args.input.c_str(), r.dir.string().c_str(),
              r.brief().c_str());
  if (options.viewer) {
    std::printf("view it: ptmkit view %s   (the folder must be served over HTTP)\n",
                r.dir.string().c_str());
  }
}

}  // namespace

void add_export_command(CLI::App& root) {
  CLI::App* cmd = root.add_subcommand(
      "export",
      "Convert a texture to another format: `export web` writes the relight/OpenLIME "
      "web folder with a viewer; `export ptm` and `export rti` convert between .ptm, .rti "
      "and web folders");
  cmd->require_subcommand(1);

  auto args = std::make_shared<ExportWebArgs>();
  CLI::App* web = cmd->add_subcommand(
      "web",
      "Write the relight/OpenLIME web folder: info.json, the coefficient planes as JPEG "
      "(three per image, per-plane scale and bias), optional deep-zoom tiles and normals.png, "
      "and index.html with ptmkit's WebGL2 viewer (docs/WEB.md). Written to a temporary "
      "folder beside DIR and renamed into place when complete");
  web->add_option("input", args->input, "Texture: .ptm (RGB, LRGB) or HSH .rti")->required();
  web->add_option("-o,--output", args->output,
                  "Output folder (created; an earlier export there is replaced, any other "
                  "non-empty folder is refused)")
      ->required();
  add_web_export_flags(web, &args->web);
  web->add_flag("--no-viewer", args->no_viewer,
                "Leave out index.html, viewer.js and viewer.css (data only)");
  web->callback([args] { run_export_web(*args); });

  // The other conversions (export ptm, export rti).
  add_export_convert_commands(*cmd);
}

}  // namespace ptmkit::app
