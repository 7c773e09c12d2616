// FitOptions' validation and FitReport's JSON and one-line forms.
#include "ptmkit/fit/fit.h"

#include <cmath>
#include <cstdio>
#include <limits>

#include <nlohmann/json.hpp>

#include "report_json.h"

namespace ptmkit::fit {

std::string FitOptions::validate() const {
  if (band_rows < 1) return "band_rows must be at least 1";
  if (threads < 0) return "threads must be >= 0 (0 = all cores)";
  if (!(design.max_condition > 1.0)) return "max_condition must be > 1";
  if (!(design.ridge_lambda >= 0.0) || !std::isfinite(design.ridge_lambda)) {
    return "ridge lambda must be a finite number >= 0";
  }
  if (const auto err = robust.validate(); !err.empty()) return err;
  if (const auto err = near.validate(); !err.empty()) return err;
  if (basis != Basis::kPtm) {
    const std::string b(to_string(basis));
    if (!is_shared_solver(solver)) {
      return "the " + b + " basis is fitted by the least-squares solvers only (ls, qr, svd, ridge)";
    }
    if (model == ColourModel::kYCC) {
      return "the ycc colour model is only available with the PTM basis: use rgb or lrgb";
    }
    if (near.plane) return "near lights (a sample plane) are fitted with the PTM basis only";
  }
  return {};
}

namespace internal {

nlohmann::json fit_report_json(const FitReport& r) {
  nlohmann::json j;
  j["lights"] = r.lights;
  j["width"] = r.width;
  j["height"] = r.height;
  j["channels"] = r.channels;
  j["basis"] = std::string(to_string(r.basis));
  j["terms"] = basis_terms(r.basis);
  j["model"] = std::string(to_string(r.model));
  j["colour_space"] = std::string(to_string(r.colour_space));
  auto num = [](double v) -> nlohmann::json {
    if (std::isnan(v)) return nullptr;
    if (std::isfinite(v)) return v;
    return "inf";
  };
  j["design"] = {{"condition_number", num(r.design.condition_number)},
                 {"smallest_singular_value", r.design.smallest_singular},
                 {"largest_singular_value", r.design.largest_singular},
                 {"min_elevation_deg", r.design.min_elevation_deg},
                 {"max_elevation_deg", r.design.max_elevation_deg},
                 {"single_ring", r.design.single_ring},
                 {"regularised", r.design.regularised}};
  j["residuals_grey"] = {{"rms", r.residuals.rms_grey},
                         {"mean_abs", r.residuals.mean_abs_grey},
                         {"p99_abs", num(r.residuals.p99_abs_grey)},
                         {"max_abs", r.residuals.max_abs_grey},
                         {"samples", r.residuals.samples},
                         {"row_step", r.residuals.row_step}};
  j["solver"] = std::string(to_string(r.solver));
  j["outliers"] = {{"samples", r.outliers.samples},
                   {"shadow", r.outliers.shadows},
                   {"highlight", r.outliers.highlights},
                   {"fallback_texels", r.outliers.fallback_texels},
                   {"ceres_texels", r.outliers.ceres_texels}};
  if (!is_shared_solver(r.solver)) {
    // Thresholds in grey levels of 8 bits (1/255 of full scale), as the flags give them.
    const RobustOptions& o = r.robust;
    j["robust_options"] = {{"shadow_k", o.shadow_k},
                           {"highlight_k", o.highlight_k},
                           {"min_scale_grey", o.min_scale * 255.0},
                           {"dark_fraction", o.dark_fraction},
                           {"saturation_level", num(o.saturation_level)},
                           {"keep_within_grey", o.keep_within * 255.0},
                           {"keep_within_fraction", o.keep_within_fraction},
                           {"min_inliers", o.min_inliers},
                           {"fill_rejected", o.fill_rejected}};
  }
  {
    nlohmann::json lm = {{"model", std::string(to_string(r.light_model.model))}};
    if (r.light_model.model == LightModel::kNear) {
      lm["max_spread_deg"] = r.light_model.max_spread_deg;
      lm["mean_spread_deg"] = r.light_model.mean_spread_deg;
      lm["falloff_range"] = {r.light_model.min_falloff, r.light_model.max_falloff};
      lm["falloff_corrected"] = r.light_model.falloff_corrected;
      lm["singular_texels"] = r.light_model.singular_texels;
    }
    if (!r.light_model.note.empty()) lm["note"] = r.light_model.note;
    j["light_model"] = lm;
  }
  if (r.input.full_width > 0) j["images"] = nlohmann::json::parse(r.input.to_json());
  j["processes"] = r.processes;
  j["threads"] = r.threads;
  j["timings_s"] = {{"decode", r.decode_seconds},
                    {"fit", r.fit_seconds},
                    {"total", r.total_seconds},
                    {"texels_per_second", r.texels_per_second()}};
  return j;
}

}  // namespace internal

std::string FitReport::to_json() const { return internal::fit_report_json(*this).dump(2); }

void combine_shares(FitReport* report, Collective& peers) {
  FitReport& r = *report;
  ResidualStats& res = r.residuals;
  const auto n = static_cast<double>(res.samples);
  // Sums: rows, samples, squared and absolute residuals, label counts, masked texels.
  double sums[5] = {static_cast<double>(r.height), n, res.rms_grey * res.rms_grey * n,
                    res.mean_abs_grey * n, static_cast<double>(r.input.region.height)};
  peers.sum(sums, 5);
  std::uint64_t counts[7] = {r.outliers.samples,       r.outliers.shadows,
                             r.outliers.highlights,    r.outliers.fallback_texels,
                             r.outliers.ceres_texels,  r.light_model.singular_texels,
                             r.input.masked_out_texels};
  peers.sum(counts, 7);
  double maxima[4] = {res.max_abs_grey, r.decode_seconds, r.fit_seconds, r.total_seconds};
  peers.max(maxima, 4);
  double first_row = r.input.region.y;
  peers.min(&first_row, 1);
  r.height = static_cast<int>(sums[0]);
  res.samples = static_cast<std::uint64_t>(sums[1]);
  res.rms_grey = sums[1] > 0 ? std::sqrt(sums[2] / sums[1]) : 0.0;
  res.mean_abs_grey = sums[1] > 0 ? sums[3] / sums[1] : 0.0;
  res.p99_abs_grey = std::numeric_limits<double>::quiet_NaN();
  res.max_abs_grey = maxima[0];
  r.outliers = {counts[0], counts[1], counts[2], counts[3], counts[4]};
  r.light_model.singular_texels = counts[5];
  r.input.masked_out_texels = counts[6];
  r.input.region.y = static_cast<int>(first_row);
  r.input.region.height = static_cast<int>(sums[4]);
  r.decode_seconds = maxima[1];
  r.fit_seconds = maxima[2];
  r.total_seconds = maxima[3];
  r.processes = peers.size();
}

std::string FitReport::brief() const {
  char p99[32] = "";
  if (!std::isnan(residuals.p99_abs_grey)) {
    std::snprintf(p99, sizeof p99, " (p99 %.2f)", residuals.p99_abs_grey);
  }
  char line[320];
  std::snprintf(line, sizeof line,
                "%d lights, %dx%d, %s %s, cond(A) %.3g, residual rms %.2f grey%s, "
                "%.3f s (%.2f Mtexel/s, %d threads)",
                lights, width, height, std::string(to_string(basis)).c_str(),
                std::string(to_string(model)).c_str(), design.condition_number, residuals.rms_grey,
                p99, total_seconds, texels_per_second() / 1e6, threads);
  std::string out = line;
  if (processes > 1) out += ", " + std::to_string(processes) + " processes";
  return out;
}

}  // namespace ptmkit::fit
