#include "ptmkit/fit/model_select.h"

#include <tbb/parallel_for.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>

#include <nlohmann/json.hpp>

#include "ptmkit/core/colour.h"
#include "ptmkit/core/error.h"
#include "ptmkit/core/holdout.h"
#include "ptmkit/core/stack_reader.h"

namespace ptmkit::fit {

namespace {

// The sampled texels: [texel][light][3] (grey replicated), plus what the clamp should be.
struct SampleGrid {
  int texels = 0;
  int lights = 0;
  int channels = 0;
  bool clamp_top = true;  // integer files: predictions clamped to [0, 1]; float: >= 0
  std::vector<float> v;
  [[nodiscard]] float at(int t, int i, int k) const {
    return v[(static_cast<std::size_t>(t) * lights + i) * 3 + k];
  }
};

int grid_stride(int width, int height, int sample_texels) {
  const double area = static_cast<double>(width) * height;
  return std::max(1, static_cast<int>(std::floor(std::sqrt(area / std::max(1, sample_texels)))));
}

struct Evaluation {
  std::vector<double> texel_mse;  // held-out, per texel
  double heldout_rms = 0.0;
  double train_rms = 0.0;
};

double clampv(double p, bool top) { return top ? std::clamp(p, 0.0, 1.0) : std::max(p, 0.0); }

// Fits texel t's samples at lights `idx` with P and predicts at the rows of `b_test`; adds the
// squared errors (grey levels) at lights `test` to *sum.
void predict_texel(const SampleGrid& g, int t, const std::vector<int>& idx,
                   const std::vector<int>& test, const Eigen::MatrixXd& p,
                   const Eigen::MatrixXd& b_test, bool lum, bool clamp, double* sum) {
  const auto n = static_cast<Eigen::Index>(idx.size());
  const int nch = g.channels == 3 ? 3 : 1;
  Eigen::VectorXd y(n);
  if (lum) {
    LrgbSums sums;
    for (Eigen::Index i = 0; i < n; ++i) {
      const int li = idx[static_cast<std::size_t>(i)];
      const double r = g.at(t, li, 0), gg = g.at(t, li, 1), b = g.at(t, li, 2);
      y(i) = nch == 3 ? luma(r, gg, b) : r;
      sums.add(1.0, y(i), r, gg, b);
    }
    const Eigen::VectorXd pred = b_test * (p * y);
    for (std::size_t j = 0; j < test.size(); ++j) {
      for (int k = 0; k < nch; ++k) {
        const double kc = sums.factor(k);
        const double v = clamp ? clampv(pred(static_cast<Eigen::Index>(j)) * kc, g.clamp_top)
                               : pred(static_cast<Eigen::Index>(j)) * kc;
        const double e = 255.0 * (v - g.at(t, test[j], k));
        *sum += e * e;
      }
    }
    return;
  }
  for (int k = 0; k < nch; ++k) {
    for (Eigen::Index i = 0; i < n; ++i) y(i) = g.at(t, idx[static_cast<std::size_t>(i)], k);
    const Eigen::VectorXd pred = b_test * (p * y);
    for (std::size_t j = 0; j < test.size(); ++j) {
      const double pv = pred(static_cast<Eigen::Index>(j));
      const double e = 255.0 * ((clamp ? clampv(pv, g.clamp_top) : pv) - g.at(t, test[j], k));
      *sum += e * e;
    }
  }
}

Evaluation evaluate(const SampleGrid& g, const std::vector<Eigen::Vector3d>& dirs, Basis basis,
                    bool lum, int folds, const DesignOptions& design) {
  Evaluation ev;
  ev.texel_mse.assign(static_cast<std::size_t>(g.texels), 0.0);
  const int nch = g.channels == 3 ? 3 : 1;
  for (const Fold& fold : kfold_splits(g.lights, folds)) {
    const std::vector<int>& train = fold.train;
    const std::vector<int>& test = fold.test;
    std::vector<Eigen::Vector3d> train_dirs, test_dirs;
    for (int i : train) train_dirs.push_back(dirs[static_cast<std::size_t>(i)]);
    for (int i : test) test_dirs.push_back(dirs[static_cast<std::size_t>(i)]);
    const BasisDesign d = BasisDesign::build(basis, train_dirs, design);
    const Eigen::MatrixXd bt = basis_matrix(basis, test_dirs);
    tbb::parallel_for(0, g.texels, [&](int t) {
      double sum = 0.0;
      predict_texel(g, t, train, test, d.pseudo_inverse, bt, lum, true, &sum);
      ev.texel_mse[static_cast<std::size_t>(t)] += sum;
    });
  }
  const double per_texel = static_cast<double>(g.lights) * nch;
  double total = 0.0;
  for (double& m : ev.texel_mse) {
    m /= per_texel;
    total += m;
  }
  ev.heldout_rms = std::sqrt(total / std::max(1, g.texels));
  // Training residual: fit on every light, evaluated there (unclamped: the fit's own misfit).
  std::vector<int> all(static_cast<std::size_t>(g.lights));
  for (int i = 0; i < g.lights; ++i) all[static_cast<std::size_t>(i)] = i;
  const BasisDesign d = BasisDesign::build(basis, dirs, design);
  std::vector<double> sums(static_cast<std::size_t>(g.texels), 0.0);
  tbb::parallel_for(0, g.texels, [&](int t) {
    predict_texel(g, t, all, all, d.pseudo_inverse, d.design, lum, false,
                  &sums[static_cast<std::size_t>(t)]);
  });
  double tsum = 0.0;
  for (double s : sums) tsum += s;
  ev.train_rms = std::sqrt(tsum / (per_texel * std::max(1, g.texels)));
  return ev;
}

ModelReport run_selection(const SampleGrid& g, const std::vector<Eigen::Vector3d>& dirs, int width,
                          int height, int stride, const ModelSelectOptions& o) {
  const auto start = std::chrono::steady_clock::now();
  ModelReport rep;
  rep.lights = g.lights;
  rep.width = width;
  rep.height = height;
  rep.channels = g.channels;
  rep.texels = g.texels;
  rep.stride = stride;
  rep.folds = o.folds;
  rep.tolerance = o.tolerance;
  const std::vector<Basis> bases = o.bases.empty() ? all_bases() : o.bases;
  std::vector<ColourModel> colours =
      o.colours.empty() ? std::vector<ColourModel>{ColourModel::kLRGB, ColourModel::kRGB}
                        : o.colours;
  if (g.channels != 3) colours = {ColourModel::kLRGB};
  std::vector<Evaluation> evals;
  for (Basis b : bases) {
    for (ColourModel c : colours) {
      ModelCandidate m;
      m.basis = b;
      m.colour = c;
      m.terms = basis_terms(b);
      const bool lum = c == ColourModel::kLRGB || g.channels != 3;
      m.parameters = g.channels != 3 ? m.terms : (lum ? m.terms + 3 : 3 * m.terms);
      Evaluation ev;
      try {
        ev = evaluate(g, dirs, b, lum, o.folds, o.design);
        m.heldout_rms_grey = ev.heldout_rms;
        m.train_rms_grey = ev.train_rms;
      } catch (const Error& e) {
        m.problem = e.what();
      }
      rep.candidates.push_back(m);
      evals.push_back(std::move(ev));
    }
  }
  // Fewest parameters first; ties: fewer basis terms (stable: the listing order after that).
  std::vector<std::size_t> order(rep.candidates.size());
  for (std::size_t i = 0; i < order.size(); ++i) order[i] = i;
  std::stable_sort(order.begin(), order.end(), [&](std::size_t a, std::size_t b) {
    const ModelCandidate& x = rep.candidates[a];
    const ModelCandidate& y = rep.candidates[b];
    if (x.parameters != y.parameters) return x.parameters < y.parameters;
    return x.terms < y.terms;
  });
  std::vector<ModelCandidate> sorted;
  std::vector<Evaluation> sorted_ev;
  for (std::size_t i : order) {
    sorted.push_back(rep.candidates[i]);
    sorted_ev.push_back(std::move(evals[i]));
  }
  rep.candidates = std::move(sorted);
  for (std::size_t i = 0; i < rep.candidates.size(); ++i) {
    if (!rep.candidates[i].problem.empty()) continue;
    if (rep.best < 0 || rep.candidates[i].heldout_rms_grey <
                            rep.candidates[static_cast<std::size_t>(rep.best)].heldout_rms_grey) {
      rep.best = static_cast<int>(i);
    }
  }
  if (rep.best < 0) {
    throw Error("model selection: no candidate model can be fitted on this layout (" +
                rep.candidates.front().problem + ")");
  }
  const auto bi = static_cast<std::size_t>(rep.best);
  const double best_rms = rep.candidates[bi].heldout_rms_grey;
  for (std::size_t i = 0; i < rep.candidates.size(); ++i) {
    ModelCandidate& m = rep.candidates[i];
    if (!m.problem.empty()) continue;
    const auto n = static_cast<double>(g.texels);
    double mean = 0.0;
    for (int t = 0; t < g.texels; ++t) {
      mean += sorted_ev[i].texel_mse[static_cast<std::size_t>(t)] -
              sorted_ev[bi].texel_mse[static_cast<std::size_t>(t)];
    }
    mean /= n;
    double var = 0.0;
    for (int t = 0; t < g.texels; ++t) {
      const double dd = sorted_ev[i].texel_mse[static_cast<std::size_t>(t)] -
                        sorted_ev[bi].texel_mse[static_cast<std::size_t>(t)] - mean;
      var += dd * dd;
    }
    m.excess_mse = mean;
    m.excess_se = g.texels > 1 ? std::sqrt(var / (n - 1) / n) : 0.0;
    m.equivalent = m.heldout_rms_grey <= best_rms * (1.0 + o.tolerance) || mean <= m.excess_se;
    if (m.equivalent && rep.chosen < 0) rep.chosen = static_cast<int>(i);
  }
  rep.candidates[static_cast<std::size_t>(rep.chosen)].chosen = true;
  rep.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  return rep;
}

}  // namespace

std::string ModelSelectOptions::validate() const {
  if (sample_texels < 1) return "sample_texels must be at least 1";
  if (folds < 2) return "folds must be at least 2";
  if (!(tolerance >= 0.0)) return "tolerance must be >= 0";
  for (ColourModel c : colours) {
    if (c == ColourModel::kYCC) return "model selection compares rgb and lrgb only";
  }
  if (band_rows < 1) return "band_rows must be at least 1";
  return {};
}

std::string ModelReport::table() const {
  std::string out;
  char line[256];
  std::snprintf(line, sizeof line, "  %-6s %-5s %5s %6s %12s %10s %14s  %s\n", "basis", "colour",
                "terms", "params", "heldout rms", "train rms", "excess mse+-se", "");
  out += line;
  for (const ModelCandidate& m : candidates) {
    if (!m.problem.empty()) {
      std::snprintf(line, sizeof line, "  %-6s %-5s %5d %6d  not fitted: %s\n",
                    std::string(to_string(m.basis)).c_str(),
                    std::string(ptmkit::to_string(m.colour)).c_str(), m.terms, m.parameters,
                    m.problem.c_str());
    } else {
      std::snprintf(line, sizeof line, "  %-6s %-5s %5d %6d %12.3f %10.3f %7.3f+-%.3f  %s\n",
                    std::string(to_string(m.basis)).c_str(),
                    std::string(ptmkit::to_string(m.colour)).c_str(), m.terms, m.parameters,
                    m.heldout_rms_grey, m.train_rms_grey, m.excess_mse, m.excess_se,
                    m.chosen ? "<- chosen" : (m.equivalent ? "equivalent" : ""));
    }
    out += line;
  }
  return out;
}

std::string ModelReport::to_json() const {
  nlohmann::json j;
  j["lights"] = lights;
  j["width"] = width;
  j["height"] = height;
  j["channels"] = channels;
  j["sampled_texels"] = texels;
  j["grid_stride_px"] = stride;
  j["folds"] = folds;
  j["tolerance"] = tolerance;
  j["rule"] =
      "fewest parameters among candidates whose held-out RMS is within tolerance of the best, "
      "or whose per-texel excess MSE over the best is within one standard error";
  j["seconds"] = seconds;
  nlohmann::json rows = nlohmann::json::array();
  for (const ModelCandidate& m : candidates) {
    nlohmann::json r;
    r["basis"] = std::string(to_string(m.basis));
    r["colour"] = std::string(ptmkit::to_string(m.colour));
    r["terms"] = m.terms;
    r["parameters"] = m.parameters;
    if (m.problem.empty()) {
      r["heldout_rms_grey"] = m.heldout_rms_grey;
      r["train_rms_grey"] = m.train_rms_grey;
      r["excess_mse_grey2"] = m.excess_mse;
      r["excess_se_grey2"] = m.excess_se;
      r["equivalent"] = m.equivalent;
    } else {
      r["problem"] = m.problem;
    }
    r["chosen"] = m.chosen;
    rows.push_back(r);
  }
  j["candidates"] = rows;
  if (chosen >= 0) {
    j["chosen"] = {{"basis", std::string(to_string(choice().basis))},
                   {"colour", std::string(ptmkit::to_string(choice().colour))}};
  }
  return j.dump(2);
}

ModelReport select_model(const LightSet& lights, const ModelSelectOptions& options) {
  if (const std::string p = options.validate(); !p.empty()) throw Error(p);
  StackReader reader(lights.images(), options.input);
  const int w = reader.width();
  const int h = reader.height();
  const int ch = reader.channels();
  const int stride = grid_stride(w, h, options.sample_texels);
  const int off = stride / 2;
  const int nx = (w - off + stride - 1) / stride;
  const int ny = (h - off + stride - 1) / stride;
  SampleGrid g;
  g.lights = reader.count();
  g.channels = ch;
  g.texels = nx * ny;
  g.clamp_top = reader.info().format != PixelFormat::kF32;
  g.v.assign(static_cast<std::size_t>(g.texels) * g.lights * 3, 0.0f);
  StackBand band;
  while (reader.read_band(options.band_rows, &band)) {
    for (int r = 0; r < band.rows; ++r) {
      const int y = band.y0 + r;
      if (y < off || (y - off) % stride != 0) continue;
      const int gy = (y - off) / stride;
      for (int gx = 0; gx < nx; ++gx) {
        const int x = off + gx * stride;
        const int t = gy * nx + gx;
        for (int i = 0; i < g.lights; ++i) {
          for (int k = 0; k < 3; ++k) {
            g.v[(static_cast<std::size_t>(t) * g.lights + i) * 3 + k] =
                band.sample(i, r, x, ch == 3 ? k : 0);
          }
        }
      }
    }
  }
  if (options.folds > g.lights) throw Error("model selection: more folds than lights");
  return run_selection(g, lights.directions(), w, h, stride, options);
}

}  // namespace ptmkit::fit
