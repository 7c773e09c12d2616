// ptmkit fit LIGHTS.lp -o OUT.ptm: polynomial fit of a capture, least squares or robust.
#include <cstdio>
#include <filesystem>
#include <memory>

#include "commands.h"
#include "fit_batch.h"
#include "mpi_collective.h"
#include "progress.h"
#include "ptmkit/core/atomic_file.h"
#include "ptmkit/core/collective.h"
#include "ptmkit/core/error.h"
#include "ptmkit/core/image_io.h"
#include "ptmkit/core/light_set.h"
#include "ptmkit/core/plane.h"
#include "ptmkit/fit/fit.h"
#include "ptmkit/fit/plan.h"
#include "ptmkit/texture/ptm.h"
#include "ptmkit/texture/rti.h"

namespace fs = std::filesystem;

namespace ptmkit::app {

namespace {

// The fit options of this command line for each capture of --batch: everything after `fit`
// except --batch and --report (the batch's own) and their values.
std::vector<std::string> batch_common_options() {
  const std::vector<std::string>& all = command_line();
  std::vector<std::string> out;
  std::size_t i = 1;
  while (i < all.size() && all[i] != "fit") ++i;
  for (++i; i < all.size(); ++i) {
    const std::string& a = all[i];
    if (a == "--batch" || a == "--report") {
      ++i;
      continue;
    }
    if (a.rfind("--batch=", 0) == 0 || a.rfind("--report=", 0) == 0) continue;
    out.push_back(a);
  }
  return out;
}

struct FitArgs {
  std::vector<std::string> inputs;  // the .lp, or with --lights the photographs
  std::string lights_file;          // --lights
  std::string batch;                // --batch JOBS.txt
  std::string crop;                 // --crop x,y,w,h
  std::string input_colour_space = "auto";
  std::string output;
  std::string format = "rgb";
  std::string report;
  std::string precision = "float";
  std::string solver = "ls";
  std::string residual_map;
  std::string outlier_map;
  std::string normals;
  std::string albedo;
  std::string labels;
  fit::FitOptions options;
  // --model: ptm (default), auto, hsh2, hsh3, hsh4 (fit/plan.h).
  std::string model = "ptm";
  bool format_given = false;
  std::string lights_json;  // near lights: positions (--lights-json)
  std::string plane;        // near lights: sample plane (--plane)
};

// The capture's lights: the .lp with its own images, or --lights applied to the images given.
LightSet load_lights(const FitArgs& args) {
  if (args.lights_file.empty()) {
    if (args.inputs.size() != 1) {
      throw Error("fit: give one light file (.lp), or --lights LIGHTS.lp and the images (" +
                  std::to_string(args.inputs.size()) + " arguments given)");
    }
    return read_lp(args.inputs[0]);
  }
  std::vector<fs::path> images(args.inputs.begin(), args.inputs.end());
  return with_images(read_lp(args.lights_file), images);
}

// Checks an output map's extension before the fit runs (no work lost on a typo).
void check_map_path(const std::string& path, const char* flag, bool png_ok) {
  if (path.empty()) return;
  const auto ext = fs::path(path).extension();
  if (ext == ".exr" || (png_ok && ext == ".png")) return;
  throw Error(path + ": " + flag + " must be an .exr file" + (png_ok ? " or a .png file" : ""));
}

// The coefficient file's writer for the planned format.
struct CoefficientWriter {
  std::unique_ptr<texture::PtmStreamWriter> ptm;
  std::unique_ptr<texture::RtiWriter> rti;
  CoefficientSink& sink() { return ptm ? static_cast<CoefficientSink&>(*ptm) : *rti; }
  [[nodiscard]] fit::WriteSummary summary() const {
    fit::WriteSummary w;
    if (ptm) {
      const texture::PtmWriteReport& r = ptm->report();
      w.file_bytes = r.file_bytes;
      w.max_coeff_error = r.max_coeff_error;
      w.rms_coeff_error = r.rms_coeff_error;
      if (r.relit_samples > 0) {  // not measured by a fit shared among processes
        w.relit_mean_abs_grey = r.relit_mean_abs_grey;
        w.relit_max_abs_grey = r.relit_max_abs_grey;
        w.relit_psnr_db = r.relit_psnr_db;
      }
    } else {
      const texture::RtiWriteReport& r = rti->report();
      w.file_bytes = r.file_bytes;
      w.max_coeff_error = r.max_coeff_error;
      w.rms_coeff_error = r.rms_coeff_error;
    }
    return w;
  }
};

// One process's share of a fit run by several (an MPI job): its rows of the region.
struct Share {
  Collective* peers = nullptr;
  RowRange rows;
  int full_height = 0;
};

CoefficientWriter make_writer(fit::CoefficientFormat format, const fs::path& path,
                              const Share& share) {
  CoefficientWriter w;
  if (format == fit::CoefficientFormat::kPtm) {
    texture::PtmWriteOptions o;
    o.collective = share.peers;
    o.row_offset = share.rows.begin;
    o.full_height = share.full_height;
    w.ptm = std::make_unique<texture::PtmStreamWriter>(path, o);
  } else {
    w.rti = std::make_unique<texture::RtiWriter>(
        path, texture::RtiShare{share.peers, share.rows.begin, share.full_height});
  }
  return w;
}

void run_fit(const FitArgs& args) {
  // Flags -> request.
  fit::FitRequest request;
  request.options = args.options;
  request.options.model = parse_colour_model(args.format);
  request.options.precision =
      args.precision == "double" ? fit::Precision::kDouble : fit::Precision::kFloat;
  request.options.solver = fit::parse_solver(args.solver);
  Collective* const peers = mpi_session() != nullptr ? mpi_session()->collective() : nullptr;
  const bool lead = peers == nullptr || peers->rank() == 0;
  if (lead) request.options.progress = make_progress("fit");
  if (!args.crop.empty()) request.options.input.crop = parse_pixel_rect(args.crop);
  request.options.input.colour_space = parse_input_colour_space(args.input_colour_space);
  request.model = fit::parse_model_request(args.model);
  request.colour_given = args.format_given;
  request.output = args.output;
  fit::FitOutputs maps;
  maps.want_residual_map = !args.residual_map.empty();
  maps.want_outlier_counts = !args.outlier_map.empty();
  maps.want_normals = !args.normals.empty() || !args.albedo.empty();
  maps.want_labels = !args.labels.empty();
  request.wants_maps =
      maps.want_residual_map || maps.want_outlier_counts || maps.want_normals || maps.want_labels;
  if (peers != nullptr && request.wants_maps) {
    throw Error(
        "--residual-map, --outlier-map, --normals, --albedo and --labels are written by a fit "
        "in one process; under mpirun only the coefficient file and --report are (fit the "
        "maps without mpirun)");
  }
  check_map_path(args.residual_map, "--residual-map", false);
  check_map_path(args.outlier_map, "--outlier-map", false);
  check_map_path(args.normals, "--normals", true);
  check_map_path(args.albedo, "--albedo", true);
  if (!args.labels.empty() && fs::exists(args.labels) && !fs::is_directory(args.labels)) {
    throw Error(args.labels + ": --labels must be a folder");
  }
  LightSet lights = load_lights(args);
  if (!args.lights_json.empty()) {
    attach_light_positions(&lights, args.lights_json);
  }
  if (!args.plane.empty()) request.options.near.plane = read_plane_json(args.plane);

  // One library call each: plan (model, format, what goes together), fit.
  fit::FitPlan plan = fit::plan_fit(lights, request, peers);
  Share share;
  if (peers != nullptr) {
    const fit::RowShare rows = fit::share_rows(lights, *peers, &plan.options);
    share = Share{peers, rows.rows, rows.full_height};
  }
  if (plan.selection && lead) {
    std::printf("model selection: %d texels (every %d px), %d folds over %d lights, %.2f s\n%s",
                plan.selection->texels, plan.selection->stride, plan.selection->folds,
                plan.selection->lights, plan.selection->seconds, plan.selection->table().c_str());
  }
  // Every output reaches its path together with the others once all are written (the
  // command's OutputTransaction, apps/main.cc): a failure anywhere leaves none of them.
  const fs::path out_path(args.output);
  CoefficientWriter writer = make_writer(plan.format, out_path, share);
  fit::FitRunReport run;
  run.fit =
      fit::fit_capture(lights, plan.options, writer.sink(), request.wants_maps ? &maps : nullptr);
  if (peers != nullptr) fit::combine_shares(&run.fit, *peers);
  run.selection = plan.selection;
  run.input = args.lights_file.empty() ? args.inputs[0] : args.lights_file;
  run.output = out_path;
  run.written = writer.summary();

  const ImageWriteOptions exr{PixelFormat::kF32};
  if (maps.want_residual_map) {
    write_image(args.residual_map, maps.residual_map.view(), exr);
  }
  if (maps.want_outlier_counts) {
    write_image(args.outlier_map, maps.outlier_counts.view(), exr);
  }
  if (!args.albedo.empty()) {
    const bool png = fs::path(args.albedo).extension() == ".png";
    write_image(args.albedo, maps.albedo.view(),
                ImageWriteOptions{png ? PixelFormat::kU16 : PixelFormat::kF32});
  }
  if (maps.want_labels) {
    fit::write_label_images(args.labels, maps, lights, run.fit.width, run.fit.height);
  }
  if (!args.normals.empty()) write_normal_map(args.normals, maps.normals.view());
  if (!lead) return;  // rank 0 reports for the job
  if (!args.report.empty()) write_file_atomic(args.report, run.to_json());
  std::printf("%s", run.brief().c_str());
}

}  // namespace

void add_fit_command(CLI::App& root) {
  auto args = std::make_shared<FitArgs>();
  CLI::App* cmd = root.add_subcommand(
      "fit",
      "Fit a polynomial texture map to the photographs listed in a light file (.lp): per texel, "
      "the least-squares biquadratic in the light direction. Writes a PTM 1.2 file.");
  cmd->add_option("lights", args->inputs,
                  "Light file (.lp); its images are the capture. With --lights: the photographs, "
                  "one per light in the light file's order");
  cmd->add_option("--batch", args->batch,
                  "Fit many captures: a jobs file with one capture per line, `LIGHTS OUTPUT "
                  "[fit options]` (# comments; double quotes around words with blanks). The "
                  "options given here apply to every line. Each capture is fitted by its own "
                  "process and committed on its own; a failing one is reported and the rest "
                  "go on. Under mpirun the captures are handed out to processes as they become "
                  "free. Prints a table (capture, status, seconds, residual); --report writes "
                  "it as JSON. Exit code 1 if any capture failed");
  cmd->add_option("--lights", args->lights_file,
                  "Use this light file's lights for the images given instead of its own (a "
                  "calibration capture's lights applied to an object's photos from the same "
                  "rig, same order; the counts must match)");
  cmd->add_option("--crop", args->crop,
                  "Fit and write only this rectangle of the photos: x,y,width,height in the "
                  "photos' pixels as displayed (x right, y down from the top-left); near lights "
                  "and the plane keep the photos' coordinates");
  cmd->add_option("--mask", args->options.input.mask,
                  "Mask image of the photos' size: only its object pixels (above half of full "
                  "scale) are fitted; the output covers the mask's bounding box (within --crop) "
                  "and texels outside the mask are black");
  cmd->add_option("--input-colour-space", args->input_colour_space,
                  "What the photos' values are: auto (the files' colour metadata; without it "
                  "8-bit files are sRGB and 16-bit and float files linear, as raw converters "
                  "write them), srgb or linear. The choice and why go in the report")
      ->capture_default_str()
      ->check(CLI::IsMember({"auto", "srgb", "linear"}));
  cmd->add_flag("--allow-damaged-images", args->options.input.image.allow_damaged,
                "Accept photos whose decoder reports damaged data (a truncated JPEG, corrupt "
                "blocks) with a warning; by default they are errors");
  cmd->add_option("-o,--output", args->output,
                  "Output file: .ptm for the ptm model, .rti for hsh2/3/4");
  cmd->add_option("--model", args->model,
                  "Basis: ptm (the 6-term polynomial, .ptm output), hsh2, hsh3, hsh4 "
                  "(hemispherical harmonics, 4/9/16 terms, .rti output), or auto (chosen per "
                  "capture from held-out error with a complexity penalty; with --format only "
                  "the basis is chosen). See docs/MODELS.md")
      ->capture_default_str()
      ->check(CLI::IsMember({"ptm", "auto", "hsh2", "hsh3", "hsh4"}));
  cmd->add_option("--format", args->format,
                  "Colour model: rgb (three polynomials, PTM_FORMAT_RGB), lrgb (luminance "
                  "polynomial times per-texel colour, PTM_FORMAT_LRGB), ycc (the seed paper: "
                  "polynomial on Y of YCbCr, constant chroma; written as PTM_FORMAT_RGB)")
      ->capture_default_str()
      ->check(CLI::IsMember({"rgb", "lrgb", "ycc"}));
  cmd->add_option("--report", args->report, "Write a JSON fit report here");
  cmd->add_option("--threads", args->options.threads, "Worker threads (0 = all cores)")
      ->capture_default_str()
      ->check(CLI::NonNegativeNumber);
  cmd->add_option("--ridge", args->options.design.ridge_lambda,
                  "Ridge regularisation weight (relative to the number of lights; 0 = plain "
                  "least squares). Makes single-ring layouts fittable, with a biased fit")
      ->capture_default_str()
      ->check(CLI::NonNegativeNumber);
  cmd->add_option("--max-condition", args->options.design.max_condition,
                  "Refuse light layouts whose design condition number cond(A) exceeds this")
      ->capture_default_str();
  cmd->add_option("--band-rows", args->options.band_rows,
                  "Image rows decoded and fitted at a time (memory ~ 2 x rows x width x "
                  "channels x lights x 4 bytes)")
      ->capture_default_str()
      ->check(CLI::PositiveNumber);
  cmd->add_option("--precision", args->precision,
                  "Arithmetic applying the pseudo-inverse: float (fast) or double")
      ->capture_default_str()
      ->check(CLI::IsMember({"float", "double"}));
  std::string solvers;
  for (const auto& n : fit::solver_names()) solvers += (solvers.empty() ? "" : ", ") + n;
  cmd->add_option("--solver", args->solver,
                  "Per-texel solver: ls (shared pseudo-inverse, Cholesky), qr, svd, ridge "
                  "(lambda from --ridge, else 1e-3), irls-huber, irls-tukey, trim, sign, lambert, "
                  "qtrim (drops each texel's darkest quarter and brightest tenth), ceres-huber, "
                  "ceres-cauchy, ceres-tukey, or robust (rejects shadowed and "
                  "specular samples; = lambert). Speed and accuracy: docs/SOLVERS.md")
      ->capture_default_str()
      ->check(CLI::IsMember(fit::solver_names()));
  add_robust_flags(cmd, &args->options.robust);
  cmd->add_option("--residual-map", args->residual_map,
                  "Write the RMS residual over each texel's inlier samples (grey levels) as a "
                  "1-channel float .exr");
  cmd->add_option("--outlier-map", args->outlier_map,
                  "Write per-texel counts of shadow and highlight samples as a 2-channel float "
                  ".exr");
  cmd->add_option("--normals", args->normals,
                  "Write Lambertian photometric-stereo normals from the inlier samples: .exr "
                  "(float xyz) or .png (16-bit, (n + 1) / 2); R, G, B = x, y, z in the light "
                  "file's frame");
  cmd->add_option("--albedo", args->albedo,
                  "Write the per-channel Lambertian albedo (with the --normals model, inlier "
                  "samples): .exr (float) or .png (16-bit)");
  cmd->add_option("--labels", args->labels,
                  "Write each sample's label into this folder: one 8-bit PNG per light, named "
                  "after its photograph, 0 inlier, 1 shadow, 2 highlight (the codes of `ptmkit "
                  "synth`'s truth/labels; all 0 for least-squares solvers)");
  cmd->add_option("--lights-json", args->lights_json,
                  "Near lights: a lights JSON with each light's position_mm (as written by "
                  "`ptmkit calibrate dome --radius` or `ptmkit synth --dome-radius`), matched to "
                  "the light file's lights in order");
  cmd->add_option("--plane", args->plane,
                  "Near lights: the sample plane (plane.json: pixel -> plane mm). With "
                  "--lights-json, every texel is fitted with its own light directions (solvers "
                  "ls and ridge only)");
  cmd->add_flag("--falloff", args->options.near.falloff,
                "Near lights: divide out the inverse-square fall-off relative to the plane "
                "centre (needs --plane and --lights-json)");
  cmd->add_flag("!--no-residuals", args->options.residual_stats,
                "Skip the residual statistics (a few percent of a large fit's time)");
  cmd->callback([args, cmd] {
    args->format_given = cmd->count("--format") > 0;
    if (!args->batch.empty()) {
      if (!args->inputs.empty() || !args->output.empty()) {
        throw CLI::ValidationError("--batch",
                                   "the captures and outputs come from the jobs file; give no "
                                   "light file and no -o");
      }
      const int failed = run_fit_batch(args->batch, batch_common_options(), args->report);
      if (failed > 0) {
        throw Error("fit --batch: " + std::to_string(failed) +
                    " capture(s) failed (see the table above)");
      }
      return;
    }
    // Command-line errors (exit code 2), as CLI11's own.
    if (args->inputs.empty()) {
      throw CLI::RequiredError("a light file (.lp), or --batch JOBS.txt,");
    }
    if (args->output.empty()) throw CLI::RequiredError("-o,--output");
    run_fit(*args);
  });
}

}  // namespace ptmkit::app
