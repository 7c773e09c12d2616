// Synthetic stacks rendered in memory and scored against their truth (test support: the
// robust tests and bench/robust_quality).
#pragma once

#include <cmath>
#include <string>
#include <utility>
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
// docs/SOLVERS.md); lights, when given, its light layout (SynthOptions::lights).
inline SynthStack render_preset(const std::string& preset, int size, double ks = -1.0,
                                double exponent = -1.0, const std::string& lights = "") {
  synth::SynthOptions o = synth::preset_options(preset);
  o.width = size;
  o.height = size;
  o.write_truth = false;
  if (!lights.empty()) o.lights = lights;
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

// A glossy ball seen from above (orthographic, radius 0.45 of the frame, on flat ground) under
// 96 distant lights on a 12 x 8 grid of a plane facing it, within cone_deg of the view axis,
// rendered in 16 bits, linear, with noise of 20 16-bit levels: the layout of photometric-stereo
// captures of a ball. exposure scales every value (intensity-normalised captures often sit at
// a tenth of full scale). `mask` keeps the ball without its outermost 3% of radius, where the
// height field's finite differences are not the sphere's normals.
struct BallStack : SynthStack {
  Image mask;
  double radius_px = 0.0;
};

inline BallStack render_ball(int size, double ks, double exponent, double cone_deg,
                             double exposure) {
  synth::SynthOptions o = synth::preset_options("default");
  o.width = size;
  o.height = size;
  o.write_truth = false;
  o.material.ks = ks;
  o.material.exponent = exponent;
  o.sensor.bits = 16;
  o.sensor.exposure = exposure;
  o.sensor.noise_sigma_grey = 20.0;
  const double t = std::tan(cone_deg * 3.14159265358979 / 180.0) / std::sqrt(2.0);
  for (int j = 0; j < 8; ++j) {
    for (int i = 0; i < 12; ++i) {
      const double x = t * (-1.0 + 2.0 * i / 11.0), y = t * (-1.0 + 2.0 * j / 7.0);
      o.light_dirs.push_back(Eigen::Vector3d(x, y, 1.0).normalized());
    }
  }
  BallStack b;
  b.radius_px = 0.45 * size;
  const double c = 0.5 * (size - 1), r = b.radius_px;
  std::vector<float> h(static_cast<std::size_t>(size) * static_cast<std::size_t>(size), 0.0f);
  b.mask = Image(size, size, 1);
  for (int y = 0; y < size; ++y) {
    for (int x = 0; x < size; ++x) {
      const double r2 = (x - c) * (x - c) + (y - c) * (y - c);
      if (r2 < r * r) {
        h[static_cast<std::size_t>(y) * static_cast<std::size_t>(size) +
          static_cast<std::size_t>(x)] = static_cast<float>(std::sqrt(r * r - r2));
      }
      b.mask.at(x, y, 0) = r2 < 0.97 * 0.97 * r * r ? 1.0f : 0.0f;
    }
  }
  b.scene = synth::scene_from_height(size, size, std::move(h), 0.6);
  b.dirs = o.light_dirs;
  for (std::size_t i = 0; i < b.dirs.size(); ++i) {
    synth::RenderedLight rl = synth::render_light(b.scene, o, b.dirs[i], static_cast<int>(i));
    b.observed.push_back(std::move(rl.observed));
    b.diffuse.push_back(std::move(rl.diffuse));
  }
  return b;
}

struct SolverScores {
  double psnr_db = 0.0;
  eval::OutlierScores outliers_all;
  eval::OutlierScores outliers_lit;
  eval::NormalError normals;  // within `mask` where one is given
  Image normal_map;           // the fit's normals (FitOutputs::normals)
  fit::FitReport report;
};

inline SolverScores score_solver(const SynthStack& s, fit::Solver solver,
                                 const fit::RobustOptions& robust = {},
                                 const Image* mask = nullptr) {
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
  r.normals = eval::normal_error(out.normals, s.scene.normals, mask);
  r.normal_map = std::move(out.normals);
  return r;
}

}  // namespace ptmkit::test
