// Synthetic stacks rendered in memory and scored against their truth (test support: the
// robust tests and bench/robust_quality).
#pragma once

#include <string>
#include <vector>

#include "ptmkit/eval/truth.h"
#include "ptmkit/fit/fit.h"
#include "ptmkit/synth/synth.h"

namespace ptmkit::test {

struct SynthStack {
  synth::Scene scene;
  std::vector<Eigen::Vector3d> dirs;
  std::vector<Image> observed;
  std::vector<Image> diffuse;
};

// A preset rendered at size x size (the relief scales with the width).
// A preset rendered at size x size; ks and exponent, when given (> 0), replace its specular
// lobe (the default preset with ks 0.25, exponent 8 is the broad, unclipped lobe of
// docs/SOLVERS.md).
inline SynthStack render_preset(const std::string& preset, int size, double ks = -1.0,
                                double exponent = -1.0) {
  synth::SynthOptions o = synth::preset_options(preset);
  o.width = size;
  o.height = size;
  o.write_truth = false;
  if (ks >= 0.0) o.material.ks = ks;
  if (exponent > 0.0) o.material.exponent = exponent;
  SynthStack s;
  s.scene = synth::build_scene(o);
  s.dirs = synth::resolve_lights(o);
  for (std::size_t i = 0; i < s.dirs.size(); ++i) {
    synth::RenderedLight r = synth::render_light(s.scene, o, s.dirs[i], static_cast<int>(i));
    s.observed.push_back(std::move(r.observed));
    s.diffuse.push_back(std::move(r.diffuse));
  }
  return s;
}

struct SolverScores {
  double psnr_db = 0.0;
  eval::OutlierScores outliers_all;
  eval::OutlierScores outliers_lit;
  eval::NormalError normals;
  fit::FitReport report;
};

inline SolverScores score_solver(const SynthStack& s, fit::Solver solver,
                                 const fit::RobustOptions& robust = {}) {
  fit::FitOptions o;
  o.solver = solver;
  o.robust = robust;
  o.residual_stats = false;
  fit::FitOutputs out;
  out.want_labels = true;
  out.want_normals = true;
  CoefficientMap map;
  CoefficientMapSink sink(&map);
  SolverScores r;
  r.report = fit::fit_images(s.observed, s.dirs, o, sink, &out);
  r.psnr_db = eval::psnr_against_truth(map, s.dirs, s.diffuse, s.scene.normals).psnr_db;
  r.outliers_all =
      eval::outlier_scores(out.labels, s.observed, s.diffuse, s.dirs, s.scene.normals, false);
  r.outliers_lit =
      eval::outlier_scores(out.labels, s.observed, s.diffuse, s.dirs, s.scene.normals, true);
  r.normals = eval::normal_error(out.normals, s.scene.normals);
  return r;
}

}  // namespace ptmkit::test
