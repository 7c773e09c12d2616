// Throughput of the least-squares fit stage alone (no decoding): texels per second for each
// colour model and precision, with and without residual statistics, on an in-memory stack.
#include <random>

#include <benchmark/benchmark.h>

#include "ptmkit/calib/dome.h"
#include "ptmkit/fit/fit.h"

namespace {

constexpr int kSide = 512;

const std::vector<ptmkit::Image>& stack() {
  static const std::vector<ptmkit::Image> images = [] {
    const auto dirs = ptmkit::calib::layout_directions("dome49");
    std::vector<ptmkit::Image> out;
    std::mt19937 rng(7);
    std::uniform_real_distribution<float> u(0.0f, 1.0f);
    for (std::size_t i = 0; i < dirs.size(); ++i) {
      ptmkit::Image img(kSide, kSide, 3);
      for (std::size_t k = 0; k < img.size(); ++k) img.data()[k] = u(rng);
      out.push_back(std::move(img));
    }
    return out;
  }();
  return images;
}

void BM_Fit(benchmark::State& state) {
  ptmkit::fit::FitOptions options;
  options.model = static_cast<ptmkit::ColourModel>(state.range(0));
  options.precision = static_cast<ptmkit::fit::Precision>(state.range(1));
  options.residual_stats = state.range(2) != 0;
  options.threads = static_cast<int>(state.range(3));
  const auto dirs = ptmkit::calib::layout_directions("dome49");
  const auto& images = stack();
  for (auto _ : state) {
    ptmkit::CoefficientMap map;
    ptmkit::CoefficientMapSink sink(&map);
    benchmark::DoNotOptimize(ptmkit::fit::fit_images(images, dirs, options, sink));
  }
  state.SetItemsProcessed(state.iterations() * kSide * kSide);
  state.SetLabel(std::string(ptmkit::to_string(options.model)) +
                 (options.precision == ptmkit::fit::Precision::kFloat ? " float" : " double") +
                 (options.residual_stats ? " +residuals" : "") +
                 " threads=" + std::to_string(options.threads));
}

// model (0 rgb, 1 lrgb, 2 ycc), precision (0 float, 1 double), residuals, threads
BENCHMARK(BM_Fit)
    ->Args({0, 0, 0, 1})
    ->Args({0, 0, 1, 1})
    ->Args({0, 1, 0, 1})
    ->Args({1, 0, 0, 1})
    ->Args({2, 0, 0, 1})
    ->Args({0, 0, 0, 2})
    ->Args({1, 0, 0, 2})
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime();

}  // namespace

BENCHMARK_MAIN();
