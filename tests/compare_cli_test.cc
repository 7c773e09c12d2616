// `ptmkit compare` and eval::compare_solvers on small synthetic captures.
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <utility>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include "ptmkit/core/image_io.h"
#include "ptmkit/eval/compare.h"
#include "ptmkit/synth/synth.h"
#include "test_util.h"

namespace fs = std::filesystem;

namespace ptmkit::eval {
namespace {

using fit::Solver;

using test::list_files;
using test::run_ptmkit;
using test::ScratchDir;

// Rendering noise is 1 grey level; the 6-term polynomial's own misfit on a relief is a few
// grey levels, so held-out PSNR sits in the 20s-30s dB: anything outside 15..50 dB is a bug.
constexpr double kMinSanePsnrDb = 15.0;
constexpr double kMaxSanePsnrDb = 50.0;
// The robust default's truth PSNR over least squares on the 32 px default capture: measured
// +3.2 dB (docs/TARGETS.md requires 2.0 dB on the default preset at 64 px).
constexpr double kRobustTruthGainDb = 1.0;

fs::path render(const fs::path& dir, const std::string& lights, int size = 32) {
  synth::SynthOptions o = synth::preset_options("default");
  o.width = size;
  o.height = size;
  o.lights = lights;
  return synth::render_capture(o, dir).lp_file;
}

std::string read_text(const fs::path& p) {
  std::ifstream in(p);
  std::stringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

TEST(CompareLibrary, FoldsAndTruthGiveSaneNumbers) {
  ScratchDir dir;
  const fs::path lp = render(dir / "cap", "dome49");
  CompareOptions o;
  o.solvers = {Solver::kLS, Solver::kRobust};
  o.folds = 4;
  o.threads = 2;
  const CompareReport r = compare_solvers(lp, std::nullopt, o);
  ASSERT_EQ(r.results.size(), 2u);
  EXPECT_TRUE(r.has_truth);
  EXPECT_TRUE(r.has_normals);
  EXPECT_EQ(r.folds, 4);
  EXPECT_EQ(r.lights, 49);
  EXPECT_EQ(r.width, 32);
  for (const auto& s : r.results) {
    EXPECT_GT(s.heldout_psnr_db, kMinSanePsnrDb) << to_string(s.solver);
    EXPECT_LT(s.heldout_psnr_db, kMaxSanePsnrDb) << to_string(s.solver);
    EXPECT_GT(s.heldout_ssim, 0.0);
    EXPECT_LE(s.heldout_ssim, 1.0);
    // Every light held out once: texels x lights x 3 channels.
    EXPECT_EQ(s.heldout_samples, 32u * 32u * 49u * 3u);
    EXPECT_GT(s.us_per_texel, 0.0);
    EXPECT_GT(s.truth_psnr_db, kMinSanePsnrDb);
    EXPECT_GT(s.normals.texels, 0u);
  }
  const SolverResult& ls = r.results[0];
  const SolverResult& robust = r.results[1];
  // The robust default rejects shadows and highlights: closer to the diffuse truth and
  // better normals than least squares (the robust targets of docs/TARGETS.md).
  EXPECT_GT(robust.truth_psnr_db, ls.truth_psnr_db + kRobustTruthGainDb);
  EXPECT_LT(robust.normals.mean_deg, ls.normals.mean_deg);
  EXPECT_EQ(ls.shadow_fraction + ls.highlight_fraction, 0.0);
  EXPECT_GT(robust.shadow_fraction, 0.0);
  // With two solvers, at least one is on the Pareto front; ls is, unless robust beats it on
  // both axes (it cannot be faster).
  EXPECT_TRUE(ls.pareto);
  EXPECT_TRUE(robust.pareto);  // more accurate than ls
}

// The capture is streamed in bands of rows; bands of 7 rows (fewer than the SSIM window's 11,
// and not dividing the height) give the scores of one band over the whole capture. Sums are
// added in another order, so equal to double rounding; counts and the median exactly.
TEST(CompareLibrary, BandsGiveTheScoresOfTheWholeCapture) {
  ScratchDir dir;
  synth::SynthOptions so = synth::preset_options("default");
  so.width = 24;
  so.height = 45;
  so.lights = "dome49";
  const fs::path lp = synth::render_capture(so, dir / "cap").lp_file;
  CompareOptions o;
  o.solvers = {Solver::kLS, Solver::kRobust};
  o.folds = 3;
  o.threads = 2;
  const CompareReport whole = compare_solvers(lp, std::nullopt, o);
  o.band_rows = 7;
  const CompareReport banded = compare_solvers(lp, std::nullopt, o);
  // A test set too: the held-out scores come from the capture's whole fit.
  const fs::path test_lp = synth::render_capture(so, dir / "test").lp_file;
  o.band_rows = 0;
  const CompareReport whole_test = compare_solvers(lp, test_lp, o);
  o.band_rows = 7;
  const CompareReport banded_test = compare_solvers(lp, test_lp, o);
  constexpr double kSumReordering = 1e-9;  // relative: sums of about 1e5 terms in another order
  for (const auto& [a, b] : {std::pair{&whole, &banded}, std::pair{&whole_test, &banded_test}}) {
    ASSERT_EQ(a->results.size(), b->results.size());
    for (std::size_t k = 0; k < a->results.size(); ++k) {
      const SolverResult& x = a->results[k];
      const SolverResult& y = b->results[k];
      SCOPED_TRACE(std::string(fit::to_string(x.solver)));
      EXPECT_EQ(x.heldout_samples, y.heldout_samples);
      EXPECT_NEAR(x.heldout_psnr_db, y.heldout_psnr_db, kSumReordering * x.heldout_psnr_db);
      EXPECT_NEAR(x.heldout_ssim, y.heldout_ssim, kSumReordering);
      EXPECT_NEAR(x.truth_psnr_db, y.truth_psnr_db, kSumReordering * x.truth_psnr_db);
      EXPECT_EQ(x.normals.texels, y.normals.texels);
      EXPECT_NEAR(x.normals.mean_deg, y.normals.mean_deg, kSumReordering * x.normals.mean_deg);
      EXPECT_EQ(x.normals.median_deg, y.normals.median_deg);
      EXPECT_EQ(x.outliers.labelled, y.outliers.labelled);
      EXPECT_EQ(x.outliers.true_outliers, y.outliers.true_outliers);
      EXPECT_EQ(x.outliers.precision, y.outliers.precision);
      EXPECT_EQ(x.shadow_fraction, y.shadow_fraction);
      EXPECT_EQ(x.highlight_fraction, y.highlight_fraction);
    }
  }
  EXPECT_GT(banded.results[1].outliers.labelled, 0u);
  EXPECT_GT(banded.results[0].heldout_ssim, 0.0);
}

TEST(CompareCli, WritesTableCsvJsonAndPlotWithATestSet) {
  ScratchDir dir;
  const fs::path lp = render(dir / "cap", "dome49");
  const fs::path test = render(dir / "test", "rings:20:6:15,60:4:40");
  const fs::path out = dir / "out";
  const auto r = run_ptmkit({"compare", lp.string(), "--test", test.string(), "--solvers",
                             "ls,sign", "--threads", "2", "-o", out.string()});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_NE(r.out.find("10 test lights"), std::string::npos) << r.out;
  EXPECT_EQ(list_files(out),
            (std::vector<std::string>{"plot.png", "results.csv", "results.json", "table.md"}));
  const auto j = nlohmann::json::parse(read_text(out / "results.json"));
  EXPECT_EQ(j["test_lights"], 10);
  EXPECT_EQ(j["folds"], 0);
  ASSERT_EQ(j["results"].size(), 2u);
  EXPECT_EQ(j["results"][1]["solver"], "sign");
  const double psnr = j["results"][0]["heldout_psnr_db"];
  EXPECT_GT(psnr, kMinSanePsnrDb);
  EXPECT_LT(psnr, kMaxSanePsnrDb);
  const std::string csv = read_text(out / "results.csv");
  EXPECT_EQ(std::count(csv.begin(), csv.end(), '\n'), 3);
  // Header, separator and one row per solver (Pareto rows are in bold).
  const std::string md = read_text(out / "table.md");
  EXPECT_NE(md.find("sign"), std::string::npos);
  std::size_t rows = 0;
  for (std::size_t p = md.find("\n|"); p != std::string::npos; p = md.find("\n|", p + 1)) ++rows;
  EXPECT_EQ(rows, 4u) << md;
  const ImageInfo plot = probe_image(out / "plot.png");
  EXPECT_EQ(plot.width, 800);
  EXPECT_EQ(plot.channels, 3);
}

TEST(CompareCli, BadInputsExitOneAndWriteNothing) {
  ScratchDir dir;
  const fs::path lp = render(dir / "cap", "rings:30:6,60:4");
  const fs::path small = render(dir / "small", "rings:30:6,60:4", 16);
  const fs::path out = dir / "out";
  struct Case {
    std::vector<std::string> args;
    std::string message;
  };
  const std::vector<Case> cases = {
      {{"compare", (dir / "missing.lp").string(), "-o", out.string()}, "missing.lp"},
      {{"compare", lp.string(), "--solvers", "ls,nope", "-o", out.string()}, "nope"},
      {{"compare", lp.string(), "--solvers", "ls,ls", "-o", out.string()}, "twice"},
      {{"compare", lp.string(), "--folds", "11", "-o", out.string()}, "only 10 lights"},
      // A fold of a 2-ring layout leaves a training set that is still fittable, but 5 folds
      // of 10 lights leave 8: fine; a test set of another size is not.
      {{"compare", lp.string(), "--test", small.string(), "-o", out.string()}, "16x16"},
  };
  for (const auto& c : cases) {
    const auto r = run_ptmkit(c.args);
    EXPECT_EQ(r.exit_code, 1) << c.message << ": " << r.out;
    EXPECT_NE(r.err.find(c.message), std::string::npos) << r.err;
    EXPECT_FALSE(fs::exists(out)) << c.message;
  }
}

}  // namespace
}  // namespace ptmkit::eval
