// ptmkit fit LIGHTS.lp -o OUT.ptm: polynomial fit of a capture, least squares or robust.
#include <cstdio>
#include <filesystem>
#include <memory>

#include <nlohmann/json.hpp>

#include "commands.h"
#include "progress.h"
#include "ptmkit/calib/dome.h"
#include "ptmkit/core/atomic_file.h"
#include "ptmkit/core/error.h"
#include "ptmkit/core/image_io.h"
#include "ptmkit/core/light_set.h"
#include "ptmkit/core/plane.h"
#include "ptmkit/core/stack_reader.h"
#include "ptmkit/fit/basis.h"
#include "ptmkit/fit/fit.h"
#include "ptmkit/fit/model_select.h"
#include "ptmkit/texture/ptm.h"
#include "ptmkit/texture/rti.h"

namespace fs = std::filesystem;

namespace ptmkit::app {

namespace {

struct FitArgs {
  std::vector<std::string> inputs;  // the .lp, or with --lights the photographs
  std::string lights_file;          // --lights
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
  // --model: ptm (default), auto, hsh2, hsh3, hsh4 (fit/model_select.h, fit/basis.h).
  std::string model = "ptm";
  bool format_given = false;
  std::string lights_json;  // near lights: positions (--lights-json)
  std::string plane;        // near lights: sample plane (--plane)
};

// Near lights: the positions of a lights JSON (calib's format: `ptmkit calibrate dome
// --radius`, `ptmkit synth --dome-radius`) onto the .lp's lights, matched in order; the
// image names must agree.
void attach_light_positions(LightSet* lights, const std::string& json_path) {
  const LightSet json = calib::read_dome_json(json_path);
  if (json.size() != lights->size()) {
    throw Error(json_path + ": " + std::to_string(json.size()) + " lights but the light file has " +
                std::to_string(lights->size()));
  }
  for (std::size_t i = 0; i < json.size(); ++i) {
    const Light& j = json.lights[i];
    Light& l = lights->lights[i];
    if (j.image.filename() != l.image.filename()) {
      throw Error(json_path + ": light " + std::to_string(i + 1) + " is " +
                  j.image.filename().string() + " but the light file's is " +
                  l.image.filename().string());
    }
    if (!j.position_mm) {
      throw Error(json_path + ": light " + std::to_string(i + 1) +
                  " has no position_mm (directions only describe distant lights; give "
                  "\"radius_mm\" or each light's \"position_mm\")");
    }
    l.position_mm = j.position_mm;
  }
}

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

// --model other than ptm: chooses the model (auto) and fits an HSH basis into an .rti. Returns
// false when the PTM is to be fitted (auto chose it; options->model is then its colour model).
bool run_model_fit(const FitArgs& args, fit::FitOptions* options, std::string* model_json) {
  const fs::path out_path(args.output);
  const LightSet lights = load_lights(args);
  fit::Basis basis = fit::Basis::kPtm;
  ColourModel colour = options->model;
  if (args.model == "auto") {
    fit::ModelSelectOptions sel;
    sel.design = options->design;
    if (args.format_given) sel.colours = {options->model};
    const fit::ModelReport report = fit::select_model(lights, sel);
    std::printf("model selection: %d texels (every %d px), %d folds over %d lights, %.2f s\n%s",
                report.texels, report.stride, report.folds, report.lights, report.seconds,
                report.table().c_str());
    *model_json = report.to_json();
    basis = report.choice().basis;
    colour = report.choice().colour;
  } else {
    basis = fit::parse_basis(args.model);
  }
  const char* want = basis == fit::Basis::kPtm ? ".ptm" : ".rti";
  if (out_path.extension() != want) {
    throw Error(out_path.string() + ": the " + std::string(fit::to_string(basis)) +
                " model is written as a " + want + " file: use -o NAME" + want);
  }
  if (basis == fit::Basis::kPtm) {
    options->model = colour;
    return false;
  }
  if (!fit::is_shared_solver(fit::parse_solver(args.solver))) {
    throw Error("--solver " + args.solver + " is only available with the ptm model");
  }
  if (!args.residual_map.empty() || !args.outlier_map.empty() || !args.normals.empty() ||
      !args.albedo.empty() || !args.labels.empty()) {
    throw Error(
        "--residual-map, --outlier-map, --normals, --albedo and --labels go with the "
        "ptm model");
  }
  fit::BasisFitOptions bo;
  bo.basis = basis;
  bo.model = colour;
  bo.design = options->design;
  bo.threads = options->threads;
  bo.band_rows = options->band_rows;
  bo.progress = make_progress("fit");
  bo.input = options->input;
  fit::BasisMap map;
  const fit::BasisFitReport report = fit::fit_basis_capture(lights, bo, &map);
  texture::RtiMap rti(map.width, map.height, map.terms(), map.colour_space);
  rti.coeffs = std::move(map.coeffs);
  const texture::RtiWriteReport written = texture::write_rti(out_path, rti);
  if (!args.report.empty()) {
    nlohmann::json j = nlohmann::json::parse(report.to_json());
    j["input"] = fs::absolute(args.lights_file.empty() ? args.inputs[0] : args.lights_file)
                     .lexically_normal()
                     .string();
    j["output"] = fs::absolute(out_path).lexically_normal().string();
    j["quantisation"] = {{"file_bytes", written.file_bytes},
                         {"max_coeff_error", written.max_coeff_error},
                         {"rms_coeff_error", written.rms_coeff_error}};
    if (!model_json->empty()) j["model_selection"] = nlohmann::json::parse(*model_json);
    write_file_atomic(args.report, j.dump(2) + "\n");
  }
  std::printf(
      "fit: %d lights, %dx%d, %s %s (%d terms), cond(A) %.3g, residual rms %.2f grey, "
      "%.3f s\nwrote %s (%zu bytes)\n",
      report.lights, report.width, report.height, std::string(fit::to_string(basis)).c_str(),
      std::string(to_string(report.model)).c_str(), fit::basis_terms(basis),
      report.condition_number, report.residual_rms_grey, report.total_seconds,
      out_path.string().c_str(), written.file_bytes);
  return true;
}

void run_fit(const FitArgs& args) {
  fit::FitOptions options = args.options;
  if (!args.crop.empty()) options.input.crop = parse_pixel_rect(args.crop);
  options.input.colour_space = parse_input_colour_space(args.input_colour_space);
  options.model = parse_colour_model(args.format);
  if (args.precision == "double") {
    options.precision = fit::Precision::kDouble;
  } else if (args.precision != "float") {
    throw Error("--precision must be float or double, got '" + args.precision + "'");
  }
  std::string model_json;  // --model auto's evidence
  if (args.model != "ptm" && (!args.plane.empty() || !args.lights_json.empty())) {
    throw Error("--plane and --lights-json (near lights) work with --model ptm only so far");
  }
  if (args.model != "ptm" && run_model_fit(args, &options, &model_json)) return;
  const fs::path out_path(args.output);
  if (out_path.extension() != ".ptm") {
    throw Error(out_path.string() + ": the output must be a .ptm file");
  }
  options.solver = fit::parse_solver(args.solver);
  check_map_path(args.residual_map, "--residual-map", false);
  check_map_path(args.outlier_map, "--outlier-map", false);
  check_map_path(args.normals, "--normals", true);
  check_map_path(args.albedo, "--albedo", true);
  if (!args.labels.empty() && fs::exists(args.labels) && !fs::is_directory(args.labels)) {
    throw Error(args.labels + ": --labels must be a folder");
  }
  fit::FitOutputs outputs;
  outputs.want_residual_map = !args.residual_map.empty();
  outputs.want_outlier_counts = !args.outlier_map.empty();
  outputs.want_normals = !args.normals.empty() || !args.albedo.empty();
  outputs.want_labels = !args.labels.empty();
  if (outputs.want_residual_map || outputs.want_outlier_counts || outputs.want_normals ||
      outputs.want_labels) {
    options.outputs = &outputs;
  }
  options.progress = make_progress("fit");
  LightSet lights = load_lights(args);
  if (!args.lights_json.empty()) attach_light_positions(&lights, args.lights_json);
  if (!args.plane.empty()) options.near.plane = read_plane_json(args.plane);
  texture::PtmStreamWriter writer(out_path);
  const fit::FitReport report = fit::fit_capture(lights, options, writer);
  const ImageWriteOptions exr{PixelFormat::kF32};
  if (outputs.want_residual_map) write_image(args.residual_map, outputs.residual_map.view(), exr);
  if (outputs.want_outlier_counts) {
    write_image(args.outlier_map, outputs.outlier_counts.view(), exr);
  }
  if (!args.albedo.empty()) {
    const bool png = fs::path(args.albedo).extension() == ".png";
    write_image(args.albedo, outputs.albedo.view(),
                ImageWriteOptions{png ? PixelFormat::kU16 : PixelFormat::kF32});
  }
  if (outputs.want_labels) {
    fit::write_label_images(args.labels, outputs, lights, report.width, report.height);
  }
  if (!args.normals.empty()) write_normal_map(args.normals, outputs.normals.view());
  const texture::PtmWriteReport& ptm = writer.report();

  if (!args.report.empty()) {
    nlohmann::json j = nlohmann::json::parse(report.to_json());
    j["input"] = fs::absolute(args.lights_file.empty() ? args.inputs[0] : args.lights_file)
                     .lexically_normal()
                     .string();
    j["output"] = fs::absolute(out_path).lexically_normal().string();
    if (!model_json.empty()) j["model_selection"] = nlohmann::json::parse(model_json);
    j["quantisation"] = {
        {"file_bytes", ptm.file_bytes},
        {"max_coeff_error", ptm.max_coeff_error},
        {"rms_coeff_error", ptm.rms_coeff_error},
        {"relit_mean_abs_grey", ptm.relit_mean_abs_grey},
        {"relit_max_abs_grey", ptm.relit_max_abs_grey},
        {"relit_psnr_db", std::isfinite(ptm.relit_psnr_db) ? nlohmann::json(ptm.relit_psnr_db)
                                                           : nlohmann::json("inf")}};
    write_file_atomic(args.report, j.dump(2) + "\n");
  }
  std::printf(
      "fit: %d lights, %dx%d, %s, cond(A) %.3g, residual rms %.2f grey (p99 %.2f), %.3f s "
      "(%.2f Mtexel/s, %d threads)\n",
      report.lights, report.width, report.height, std::string(to_string(report.model)).c_str(),
      report.design.condition_number, report.residuals.rms_grey, report.residuals.p99_abs_grey,
      report.total_seconds, report.texels_per_second() / 1e6, report.threads);
  if (report.light_model.model == "near") {
    std::printf(
        "near lights: per-texel directions (spread up to %.2f deg), fall-off %.3f..%.3f%s\n",
        report.light_model.max_spread_deg, report.light_model.min_falloff,
        report.light_model.max_falloff,
        report.light_model.falloff_corrected ? " corrected" : " not corrected");
  } else if (!report.light_model.note.empty()) {
    std::printf("%s\n", report.light_model.note.c_str());
  }
  if (!fit::is_shared_solver(report.solver)) {
    const double total = std::max<double>(1.0, static_cast<double>(report.outliers.samples));
    std::printf("solver %s: %.2f%% samples shadow, %.2f%% highlight, %llu fallback texels\n",
                std::string(fit::to_string(report.solver)).c_str(),
                100.0 * static_cast<double>(report.outliers.shadows) / total,
                100.0 * static_cast<double>(report.outliers.highlights) / total,
                static_cast<unsigned long long>(report.outliers.fallback_texels));
  }
  std::printf("wrote %s (%zu bytes; quantisation: relit mean %.3f, max %.3f grey levels)\n",
              out_path.string().c_str(), ptm.file_bytes, ptm.relit_mean_abs_grey,
              ptm.relit_max_abs_grey);
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
                  "one per light in the light file's order")
      ->required();
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
                  "Output file: .ptm for the ptm model, .rti for hsh2/3/4")
      ->required();
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
                  "ceres-huber, ceres-cauchy, ceres-tukey, or robust (rejects shadowed and "
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
    run_fit(*args);
  });
}

}  // namespace ptmkit::app
