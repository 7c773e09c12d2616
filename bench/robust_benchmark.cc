// Cost of the fit's solvers, and of the choices that make a per-texel Ceres solve affordable.
//
//   build/bench/robust_benchmark [--benchmark_filter=...]
//
// Scene: the synth `default` preset (relief with cast shadows and Blinn-Phong highlights) at
// 48 x 48 px, 49 lights (dome49), RGB, rendered in memory. Everything runs on one thread.
// "us_per_texel" is fitting time per texel (shown in seconds with an SI prefix: 5u = 5 us).
//
// BM_Fit/<solver>: fit::fit_images on the whole stack (no optional outputs, no residual
//   statistics): the solver's whole-fit cost, comparable across solvers.
// BM_Ceres/<variant>: one Huber solve per texel on the texels whose least-squares residuals
//   show an outlier (what `ceres_only_where_needed` selects), isolating each choice:
//   fresh      a new ceres::Problem per texel (analytic Jacobian, warm start)
//   reused     one Problem built once, its residual blocks reading the texel's values
//   autodiff   reused, ceres::AutoDiffCostFunction instead of the analytic Jacobian
//   numeric    reused, ceres::NumericDiffCostFunction (central differences)
//   cold       reused, started from zero instead of the least-squares fit
//   irls       the closed-form alternative: Huber IRLS with 6 x 6 normal equations
// BM_FitGating/<on|off>: ceres-huber on the whole stack with and without the gate.
#include <algorithm>
#include <array>
#include <cmath>
#include <memory>
#include <vector>

#include <benchmark/benchmark.h>
#include <ceres/ceres.h>
#include <Eigen/Cholesky>
#include <Eigen/Core>

#include "ptmkit/core/coefficients.h"
#include "ptmkit/core/colour.h"
#include "ptmkit/fit/design.h"
#include "ptmkit/fit/fit.h"
#include "ptmkit/synth/synth.h"

namespace {

using ptmkit::CoefficientMap;
using ptmkit::CoefficientMapSink;
using ptmkit::Image;
using ptmkit::kPtmTerms;
namespace fit = ptmkit::fit;

constexpr int kSize = 48;

struct Stack {
  std::vector<Image> images;
  std::vector<Eigen::Vector3d> dirs;
  Eigen::MatrixXd design;  // N x 6
  Eigen::MatrixXd pinv;    // 6 x N
  // Luma of the texels Ceres runs on (|LS residual| > 3 MAD scales somewhere): [texel][light].
  std::vector<std::vector<double>> gated;
  std::vector<double> gated_scale;
};

const Stack& stack() {
  static const Stack s = [] {
    Stack st;
    ptmkit::synth::SynthOptions o = ptmkit::synth::preset_options("default");
    o.width = kSize;
    o.height = kSize;
    o.write_truth = false;
    const auto scene = ptmkit::synth::build_scene(o);
    st.dirs = ptmkit::synth::resolve_lights(o);
    for (std::size_t i = 0; i < st.dirs.size(); ++i) {
      st.images.push_back(
          ptmkit::synth::render_light(scene, o, st.dirs[i], static_cast<int>(i)).observed);
    }
    const auto design = fit::LightDesign::build(st.dirs);
    st.design = design.design();
    st.pinv = design.pseudo_inverse();
    const auto n = static_cast<Eigen::Index>(st.dirs.size());
    const fit::RobustOptions ro;
    for (int y = 0; y < kSize; ++y) {
      for (int x = 0; x < kSize; ++x) {
        Eigen::VectorXd v(n);
        for (Eigen::Index i = 0; i < n; ++i) {
          const Image& im = st.images[static_cast<std::size_t>(i)];
          v(i) = ptmkit::luma(im.at(x, y, 0), im.at(x, y, 1), im.at(x, y, 2));
        }
        const Eigen::VectorXd r = v - st.design * (st.pinv * v);
        std::vector<double> a(r.data(), r.data() + n);
        std::nth_element(a.begin(), a.begin() + n / 2, a.end());
        const double med = a[static_cast<std::size_t>(n / 2)];
        for (double& e : a) e = std::abs(e - med);
        std::nth_element(a.begin(), a.begin() + n / 2, a.end());
        const double scale =
            std::max(ro.mad_factor * a[static_cast<std::size_t>(n / 2)], ro.min_scale);
        if (r.cwiseAbs().maxCoeff() > ro.label_k * scale) {
          st.gated.emplace_back(v.data(), v.data() + n);
          st.gated_scale.push_back(scale);
        }
      }
    }
    return st;
  }();
  return s;
}

void set_per_texel(benchmark::State& state, double texels) {
  state.counters["us_per_texel"] = benchmark::Counter(
      texels, benchmark::Counter::kIsIterationInvariantRate | benchmark::Counter::kInvert);
}

void BM_Fit(benchmark::State& state, fit::Solver solver) {
  const Stack& s = stack();
  fit::FitOptions o;
  o.solver = solver;
  o.threads = 1;
  o.residual_stats = false;
  for (auto _ : state) {
    CoefficientMap map;
    CoefficientMapSink sink(&map);
    benchmark::DoNotOptimize(fit::fit_images(s.images, s.dirs, o, sink));
  }
  set_per_texel(state, kSize * kSize);
}
BENCHMARK_CAPTURE(BM_Fit, ls, fit::Solver::kLS)->Unit(benchmark::kMillisecond);
BENCHMARK_CAPTURE(BM_Fit, qr, fit::Solver::kQR)->Unit(benchmark::kMillisecond);
BENCHMARK_CAPTURE(BM_Fit, irls_huber, fit::Solver::kIrlsHuber)->Unit(benchmark::kMillisecond);
BENCHMARK_CAPTURE(BM_Fit, irls_tukey, fit::Solver::kIrlsTukey)->Unit(benchmark::kMillisecond);
BENCHMARK_CAPTURE(BM_Fit, trim, fit::Solver::kTrim)->Unit(benchmark::kMillisecond);
BENCHMARK_CAPTURE(BM_Fit, sign, fit::Solver::kSign)->Unit(benchmark::kMillisecond);
BENCHMARK_CAPTURE(BM_Fit, lambert, fit::Solver::kLambert)->Unit(benchmark::kMillisecond);
BENCHMARK_CAPTURE(BM_Fit, ceres_huber, fit::Solver::kCeresHuber)->Unit(benchmark::kMillisecond);
BENCHMARK_CAPTURE(BM_Fit, ceres_cauchy, fit::Solver::kCeresCauchy)->Unit(benchmark::kMillisecond);
BENCHMARK_CAPTURE(BM_Fit, ceres_tukey, fit::Solver::kCeresTukey)->Unit(benchmark::kMillisecond);

void BM_FitGating(benchmark::State& state, bool gate) {
  const Stack& s = stack();
  fit::FitOptions o;
  o.solver = fit::Solver::kCeresHuber;
  o.robust.ceres_only_where_needed = gate;
  o.threads = 1;
  o.residual_stats = false;
  for (auto _ : state) {
    CoefficientMap map;
    CoefficientMapSink sink(&map);
    benchmark::DoNotOptimize(fit::fit_images(s.images, s.dirs, o, sink));
  }
  set_per_texel(state, kSize * kSize);
}
BENCHMARK_CAPTURE(BM_FitGating, on, true)->Unit(benchmark::kMillisecond);
BENCHMARK_CAPTURE(BM_FitGating, off, false)->Unit(benchmark::kMillisecond);

// r = b . c - y with the analytic Jacobian b.
class AnalyticCost final : public ceres::SizedCostFunction<1, kPtmTerms> {
 public:
  AnalyticCost(const double* basis, const double* value) : basis_(basis), value_(value) {}
  bool Evaluate(double const* const* p, double* r, double** j) const override {
    double f = 0.0;
    for (int k = 0; k < kPtmTerms; ++k) f += basis_[k] * p[0][k];
    r[0] = f - *value_;
    if (j != nullptr && j[0] != nullptr) std::copy(basis_, basis_ + kPtmTerms, j[0]);
    return true;
  }

 private:
  const double* basis_;
  const double* value_;
};

struct TemplatedCost {
  const double* basis;
  const double* value;
  template <class T>
  bool operator()(const T* c, T* r) const {
    T f(0.0);
    for (int k = 0; k < kPtmTerms; ++k) f += basis[k] * c[k];
    r[0] = f - *value;
    return true;
  }
};

enum class Variant { kFresh, kReused, kAutoDiff, kNumeric, kCold };

ceres::Solver::Options solver_options() {
  ceres::Solver::Options o;
  o.linear_solver_type = ceres::DENSE_NORMAL_CHOLESKY;
  o.max_num_iterations = 25;
  o.num_threads = 1;
  o.logging_type = ceres::SILENT;
  o.function_tolerance = 1e-8;
  o.gradient_tolerance = 1e-12;
  o.parameter_tolerance = 1e-9;
  return o;
}

struct CeresRig {
  std::vector<std::array<double, kPtmTerms>> basis;
  std::vector<double> values;
  std::array<double, kPtmTerms> params{};
  std::unique_ptr<ceres::LossFunctionWrapper> loss;
  std::unique_ptr<ceres::Problem> problem;

  CeresRig(const Eigen::MatrixXd& design, Variant v) {
    const auto n = static_cast<std::size_t>(design.rows());
    basis.resize(n);
    values.assign(n, 0.0);
    for (std::size_t i = 0; i < n; ++i)
      for (int k = 0; k < kPtmTerms; ++k)
        basis[i][static_cast<std::size_t>(k)] = design(static_cast<Eigen::Index>(i), k);
    loss = std::make_unique<ceres::LossFunctionWrapper>(new ceres::HuberLoss(1.0),
                                                        ceres::TAKE_OWNERSHIP);
    if (v != Variant::kFresh) build(v);
  }
  void build(Variant v) {
    ceres::Problem::Options po;
    po.loss_function_ownership = ceres::DO_NOT_TAKE_OWNERSHIP;
    problem = std::make_unique<ceres::Problem>(po);
    for (std::size_t i = 0; i < values.size(); ++i) {
      ceres::CostFunction* cost = nullptr;
      if (v == Variant::kAutoDiff) {
        cost = new ceres::AutoDiffCostFunction<TemplatedCost, 1, kPtmTerms>(
            new TemplatedCost{basis[i].data(), &values[i]});
      } else if (v == Variant::kNumeric) {
        cost = new ceres::NumericDiffCostFunction<TemplatedCost, ceres::CENTRAL, 1, kPtmTerms>(
            new TemplatedCost{basis[i].data(), &values[i]});
      } else {
        cost = new AnalyticCost(basis[i].data(), &values[i]);
      }
      problem->AddResidualBlock(cost, loss.get(), params.data());
    }
  }
};

void BM_Ceres(benchmark::State& state, Variant v) {
  const Stack& s = stack();
  const ceres::Solver::Options so = solver_options();
  CeresRig rig(s.design, v);
  const auto n = static_cast<Eigen::Index>(s.dirs.size());
  double checksum = 0.0;
  for (auto _ : state) {
    for (std::size_t t = 0; t < s.gated.size(); ++t) {
      std::copy(s.gated[t].begin(), s.gated[t].end(), rig.values.begin());
      const Eigen::Map<const Eigen::VectorXd> y(s.gated[t].data(), n);
      const Eigen::Matrix<double, kPtmTerms, 1> ls = s.pinv * y;
      for (int k = 0; k < kPtmTerms; ++k)
        rig.params[static_cast<std::size_t>(k)] = v == Variant::kCold ? 0.0 : ls(k);
      rig.loss->Reset(new ceres::HuberLoss(1.345 * s.gated_scale[t]), ceres::TAKE_OWNERSHIP);
      if (v == Variant::kFresh) rig.build(Variant::kFresh);
      ceres::Solver::Summary summary;
      ceres::Solve(so, rig.problem.get(), &summary);
      checksum += rig.params[5];
    }
  }
  benchmark::DoNotOptimize(checksum);
  set_per_texel(state, static_cast<double>(s.gated.size()));
  state.counters["texels"] = static_cast<double>(s.gated.size());
}
BENCHMARK_CAPTURE(BM_Ceres, fresh, Variant::kFresh)->Unit(benchmark::kMillisecond);
BENCHMARK_CAPTURE(BM_Ceres, reused, Variant::kReused)->Unit(benchmark::kMillisecond);
BENCHMARK_CAPTURE(BM_Ceres, autodiff, Variant::kAutoDiff)->Unit(benchmark::kMillisecond);
BENCHMARK_CAPTURE(BM_Ceres, numeric, Variant::kNumeric)->Unit(benchmark::kMillisecond);
BENCHMARK_CAPTURE(BM_Ceres, cold, Variant::kCold)->Unit(benchmark::kMillisecond);

// Huber IRLS on the same texels, 6 x 6 fixed-size normal equations.
void BM_CeresAlternativeIrls(benchmark::State& state) {
  const Stack& s = stack();
  const auto n = static_cast<Eigen::Index>(s.dirs.size());
  using Vec6 = Eigen::Matrix<double, kPtmTerms, 1>;
  using Mat6 = Eigen::Matrix<double, kPtmTerms, kPtmTerms>;
  std::vector<Vec6> rows(static_cast<std::size_t>(n));
  for (Eigen::Index i = 0; i < n; ++i)
    rows[static_cast<std::size_t>(i)] = s.design.row(i).transpose();
  double checksum = 0.0;
  for (auto _ : state) {
    for (std::size_t t = 0; t < s.gated.size(); ++t) {
      const Eigen::Map<const Eigen::VectorXd> y(s.gated[t].data(), n);
      Vec6 c = s.pinv * y;
      const double width = 1.345 * s.gated_scale[t];
      for (int it = 0; it < 6; ++it) {
        Mat6 m = Mat6::Zero();
        Vec6 rhs = Vec6::Zero();
        for (Eigen::Index i = 0; i < n; ++i) {
          const Vec6& b = rows[static_cast<std::size_t>(i)];
          const double r = std::abs(y(i) - b.dot(c));
          const double w = r <= width ? 1.0 : width / r;
          m.selfadjointView<Eigen::Lower>().rankUpdate(b, w);
          rhs += (w * y(i)) * b;
        }
        const Vec6 next = m.selfadjointView<Eigen::Lower>().llt().solve(rhs);
        const double step = (next - c).cwiseAbs().maxCoeff();
        c = next;
        if (step < 1e-7) break;
      }
      checksum += c(5);
    }
  }
  benchmark::DoNotOptimize(checksum);
  set_per_texel(state, static_cast<double>(s.gated.size()));
}
BENCHMARK(BM_CeresAlternativeIrls)->Name("BM_Ceres/irls")->Unit(benchmark::kMillisecond);

}  // namespace

BENCHMARK_MAIN();
