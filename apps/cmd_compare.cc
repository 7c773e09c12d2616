// ptmkit compare CAPTURE.lp [--test TEST.lp] --solvers a,b,c -o DIR: the speed/accuracy trade
// of the fit's solvers on one capture, measured on held-out lights (and ground truth when the
// capture is a `ptmkit synth` set).
#include <cmath>
#include <cstdio>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "commands.h"
#include "flags.h"
#include "ptmkit/core/error.h"
#include "ptmkit/eval/compare.h"

namespace ptmkit::app {

namespace {

struct CompareArgs {
  std::string capture;
  std::string test;
  std::string output;
  std::string solvers = "ls,robust";
  std::string format = "rgb";
  eval::CompareOptions options;
};

std::vector<fit::Solver> parse_solver_list(const std::string& list) {
  std::vector<fit::Solver> out;
  for (const std::string& name : parse_list(list, "--solvers"))
    out.push_back(fit::parse_solver(name));
  return out;
}

void run_compare(const CompareArgs& args) {
  eval::CompareOptions options = args.options;
  options.solvers = parse_solver_list(args.solvers);
  options.model = parse_colour_model(args.format);
  std::optional<std::filesystem::path> test;
  if (!args.test.empty()) test = args.test;
  const eval::CompareReport report = eval::compare_solvers(args.capture, test, options);
  eval::write_compare(report, args.output);
  std::printf("compare: %dx%d, %d lights, held out: %s\n", report.width, report.height,
              report.lights,
              report.folds > 0 ? (std::to_string(report.folds) + " folds").c_str()
                               : (std::to_string(report.test_lights) + " test lights").c_str());
  for (const auto& r : report.results) {
    std::printf("  %-13s %8.2f us/texel  held-out %6.2f dB",
                std::string(to_string(r.solver)).c_str(), r.us_per_texel, r.heldout_psnr_db);
    if (report.has_truth) std::printf("  truth %6.2f dB", r.truth_psnr_db);
    if (report.has_normals) std::printf("  normals %5.2f deg", r.normals.mean_deg);
    std::printf("%s\n", r.pareto ? "  (Pareto)" : "");
  }
  std::printf("wrote %s/{table.md,results.csv,results.json,plot.png}\n", args.output.c_str());
}

}  // namespace

void add_compare_command(CLI::App& root) {
  auto args = std::make_shared<CompareArgs>();
  CLI::App* cmd = root.add_subcommand(
      "compare",
      "Compare fit solvers on one capture: time per texel, PSNR/SSIM at held-out lights (a test "
      "set, or K folds over the capture's lights) and, for a `ptmkit synth` capture, accuracy "
      "against its ground truth. Writes table.md, results.csv, results.json and plot.png "
      "(accuracy against time, Pareto front marked).");
  cmd->add_option("capture", args->capture, "Light file (.lp) of the capture to fit")->required();
  cmd->add_option("--test", args->test,
                  "Light file (.lp) of held-out photographs of the same view (otherwise K folds "
                  "over the capture's lights)");
  cmd->add_option("--folds", args->options.folds,
                  "Folds over the capture's lights when no --test is given (light i is in fold "
                  "i mod K)")
      ->capture_default_str()
      ->check(CLI::Range(2, 1000));
  std::string names;
  for (const auto& n : fit::solver_names()) names += (names.empty() ? "" : ", ") + n;
  cmd->add_option("--solvers", args->solvers,
                  "Comma-separated solvers to compare (of: " + names + ")")
      ->capture_default_str();
  cmd->add_option("-o,--output", args->output,
                  "Output folder (created if needed; written only when every measurement "
                  "succeeded)")
      ->required();
  cmd->add_option("--format", args->format, "Colour model of every fit: rgb, lrgb or ycc")
      ->capture_default_str()
      ->check(CLI::IsMember({"rgb", "lrgb", "ycc"}));
  cmd->add_option("--threads", args->options.threads,
                  "Worker threads for every fit (0 = all cores); timings are for this many")
      ->capture_default_str()
      ->check(CLI::NonNegativeNumber);
  cmd->add_option("--repeats", args->options.timing_repeats,
                  "Timing fits per solver; the fastest is reported")
      ->capture_default_str()
      ->check(CLI::Range(1, 100));
  cmd->add_flag("!--no-ssim", args->options.ssim, "Skip the held-out SSIM");
  cmd->add_option("--band-rows", args->options.band_rows,
                  "Rows read and fitted at a time (0 = as many as fit in about 64 MiB); the "
                  "scores do not depend on it")
      ->capture_default_str()
      ->check(CLI::NonNegativeNumber);
  add_robust_flags(cmd, &args->options.robust);
  cmd->callback([args] { run_compare(*args); });
}

}  // namespace ptmkit::app
