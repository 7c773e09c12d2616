#include "ptmkit/fit/plan.h"

#include <cmath>
#include <cstdio>

#include <nlohmann/json.hpp>

#include "ptmkit/core/error.h"
#include "ptmkit/core/stack_reader.h"
#include "report_json.h"

namespace ptmkit::fit {

std::string_view to_string(ModelRequest model) {
  switch (model) {
    case ModelRequest::kPtm:
      return "ptm";
    case ModelRequest::kHsh2:
      return "hsh2";
    case ModelRequest::kHsh3:
      return "hsh3";
    case ModelRequest::kHsh4:
      return "hsh4";
    case ModelRequest::kAuto:
      return "auto";
  }
  return "?";
}

ModelRequest parse_model_request(std::string_view name) {
  for (ModelRequest m : {ModelRequest::kPtm, ModelRequest::kHsh2, ModelRequest::kHsh3,
                         ModelRequest::kHsh4, ModelRequest::kAuto}) {
    if (name == to_string(m)) return m;
  }
  throw Error("unknown model '" + std::string(name) + "' (known: ptm, auto, hsh2, hsh3, hsh4)");
}

CoefficientFormat format_for(Basis basis) {
  return basis == Basis::kPtm ? CoefficientFormat::kPtm : CoefficientFormat::kRti;
}

std::string_view extension(CoefficientFormat format) {
  return format == CoefficientFormat::kPtm ? ".ptm" : ".rti";
}

namespace {

Basis requested_basis(ModelRequest model) {
  switch (model) {
    case ModelRequest::kHsh2:
      return Basis::kHsh2;
    case ModelRequest::kHsh3:
      return Basis::kHsh3;
    case ModelRequest::kHsh4:
      return Basis::kHsh4;
    default:
      return Basis::kPtm;
  }
}

}  // namespace

FitPlan plan_fit(const LightSet& lights, const FitRequest& request) {
  FitPlan plan;
  plan.options = request.options;
  if (request.model != ModelRequest::kPtm && request.options.near.plane) {
    throw Error("--plane and --lights-json (near lights) work with --model ptm only so far");
  }
  Basis basis = requested_basis(request.model);
  if (request.model == ModelRequest::kAuto) {
    ModelSelectOptions sel;
    sel.design = request.options.design;
    sel.input = request.options.input;
    if (request.colour_given) sel.colours = {request.options.model};
    plan.selection = select_model(lights, sel);
    basis = plan.selection->choice().basis;
    plan.options.model = plan.selection->choice().colour;
  }
  plan.options.basis = basis;
  plan.format = format_for(basis);
  const std::string want(extension(plan.format));
  if (request.output.extension() != want) {
    if (request.model == ModelRequest::kPtm) {
      throw Error(request.output.string() + ": the output must be a .ptm file");
    }
    throw Error(request.output.string() + ": the " + std::string(to_string(basis)) +
                " model is written as a " + want + " file: use -o NAME" + want);
  }
  if (basis != Basis::kPtm) {
    if (!is_shared_solver(plan.options.solver)) {
      throw Error("--solver " + std::string(to_string(plan.options.solver)) +
                  " is only available with the ptm model");
    }
    if (request.wants_maps) {
      throw Error(
          "--residual-map, --outlier-map, --normals, --albedo and --labels go with the "
          "ptm model");
    }
  }
  return plan;
}

std::string FitRunReport::to_json() const {
  nlohmann::json j = internal::fit_report_json(fit);
  j["input"] = std::filesystem::absolute(input).lexically_normal().string();
  j["output"] = std::filesystem::absolute(output).lexically_normal().string();
  if (selection) j["model_selection"] = nlohmann::json::parse(selection->to_json());
  nlohmann::json q = {{"file_bytes", written.file_bytes},
                      {"max_coeff_error", written.max_coeff_error},
                      {"rms_coeff_error", written.rms_coeff_error}};
  if (written.relit_mean_abs_grey) q["relit_mean_abs_grey"] = *written.relit_mean_abs_grey;
  if (written.relit_max_abs_grey) q["relit_max_abs_grey"] = *written.relit_max_abs_grey;
  if (written.relit_psnr_db) {
    q["relit_psnr_db"] = std::isfinite(*written.relit_psnr_db)
                             ? nlohmann::json(*written.relit_psnr_db)
                             : nlohmann::json("inf");
  }
  j["quantisation"] = q;
  return j.dump(2) + "\n";
}

std::string FitRunReport::brief() const {
  std::string out = "fit: " + fit.brief() + "\n";
  char line[512];
  const NearLightReport& lm = fit.light_model;
  if (lm.model == LightModel::kNear) {
    std::snprintf(line, sizeof line,
                  "near lights: per-texel directions (spread up to %.2f deg), fall-off "
                  "%.3f..%.3f%s\n",
                  lm.max_spread_deg, lm.min_falloff, lm.max_falloff,
                  lm.falloff_corrected ? " corrected" : " not corrected");
    out += line;
  } else if (!lm.note.empty()) {
    out += lm.note + "\n";
  }
  if (!is_shared_solver(fit.solver)) {
    const double total = std::max<double>(1.0, static_cast<double>(fit.outliers.samples));
    std::snprintf(line, sizeof line,
                  "solver %s: %.2f%% samples shadow, %.2f%% highlight, %llu fallback texels\n",
                  std::string(to_string(fit.solver)).c_str(),
                  100.0 * static_cast<double>(fit.outliers.shadows) / total,
                  100.0 * static_cast<double>(fit.outliers.highlights) / total,
                  static_cast<unsigned long long>(fit.outliers.fallback_texels));
    out += line;
    if (fit.lights <= fit.robust.min_inliers) {
      // Few-light captures (12-light photometric-stereo sets) would otherwise get least
      // squares with nothing said but the fallback count.
      std::snprintf(line, sizeof line,
                    "note: %d lights and at least %d inliers a texel leave the %s solver nothing "
                    "to reject: every texel kept the least-squares fit (--min-inliers lowers "
                    "the floor)\n",
                    fit.lights, fit.robust.min_inliers, std::string(to_string(fit.solver)).c_str());
      out += line;
    }
  }
  if (written.relit_mean_abs_grey) {
    std::snprintf(line, sizeof line,
                  "wrote %s (%zu bytes; quantisation: relit mean %.3f, max %.3f grey levels)\n",
                  output.string().c_str(), written.file_bytes, *written.relit_mean_abs_grey,
                  written.relit_max_abs_grey.value_or(0.0));
  } else {
    std::snprintf(line, sizeof line, "wrote %s (%zu bytes)\n", output.string().c_str(),
                  written.file_bytes);
  }
  out += line;
  return out;
}

FitPlan plan_fit(const LightSet& lights, FitRequest request, Collective* peers) {
  if (peers == nullptr || request.model != ModelRequest::kAuto) return plan_fit(lights, request);
  FitPlan plan;
  std::string chosen;
  if (peers->rank() == 0) {
    plan = plan_fit(lights, request);
    chosen = std::string(to_string(plan.options.basis)) + " " +
             std::string(to_string(plan.options.model));
  }
  peers->agree(true, "model selection");
  peers->broadcast(&chosen);
  if (peers->rank() == 0) return plan;
  const std::size_t space = chosen.find(' ');
  request.model = parse_model_request(chosen.substr(0, space));
  request.options.model = parse_colour_model(chosen.substr(space + 1));
  request.colour_given = true;
  return plan_fit(lights, request);
}

RowShare share_rows(const LightSet& lights, Collective& peers, FitOptions* options) {
  int height = 0;
  {
    const StackReader probe(lights.images(), options->input);
    height = probe.height();
  }
  if (height < peers.size()) {
    throw Error("fit: " + std::to_string(peers.size()) + " processes for " +
                std::to_string(height) + " rows; start at most one process per row");
  }
  RowShare share;
  share.full_height = height;
  share.rows = rows_of_rank(height, peers.rank(), peers.size());
  options->input.rows = share.rows;
  return share;
}

}  // namespace ptmkit::fit
