// The 8-bit fit kernels on one band as `ptmkit fit` reads it (49 images, 8 rows of 4000 RGB
// texels): the one-pass LRGB row (luma, colour sums and product) and the RGB product, in
// texels per second on one thread. The band (4.7 MB) stays in the last-level cache, as a band
// just decoded does.
#include <cstdint>
#include <random>
#include <vector>

#include <benchmark/benchmark.h>

#include "../fit/src/kernels.h"

namespace {

constexpr int kImages = 49;
constexpr int kRows = 8;
constexpr int kWidth = 4000;
constexpr std::ptrdiff_t kImageStride = std::ptrdiff_t{kRows} * kWidth * 3;

struct Band {
  std::vector<std::uint8_t> bytes;
  std::vector<float> pinv;  // 6 x 49, column-major
  Band() : bytes(static_cast<std::size_t>(kImages * kImageStride)), pinv(6 * kImages) {
    std::mt19937 rng(11);
    std::uniform_int_distribution<int> byte(0, 255);
    for (auto& b : bytes) b = static_cast<std::uint8_t>(byte(rng));
    std::uniform_real_distribution<float> u(-0.2f, 0.2f);
    for (float& p : pinv) p = u(rng);
  }
};

const Band& band() {
  static const Band b;
  return b;
}

// Argument: the kernel path (0 portable, 1 AVX2, 2 AVX-512); a path this CPU lacks is skipped.
void BM_LrgbRowU8(benchmark::State& state) {
  const Band& b = band();
  const auto path = static_cast<ptmkit::fit::internal::KernelPath>(state.range(0));
  std::vector<float> coeffs(std::size_t{kWidth} * 6), sums(std::size_t{kWidth} * 4);
  for (auto _ : state) {
    for (int r = 0; r < kRows; ++r) {
      if (!ptmkit::fit::internal::lrgb_row_u8_path(
              path, b.pinv.data(), kImages, b.bytes.data() + r * kWidth * 3, kImageStride, kWidth,
              coeffs.data(), &sums[0], &sums[kWidth], &sums[2 * kWidth], &sums[3 * kWidth])) {
        state.SkipWithError("this CPU lacks the path");
        return;
      }
    }
    benchmark::DoNotOptimize(coeffs.data());
    benchmark::ClobberMemory();
  }
  state.SetItemsProcessed(state.iterations() * kRows * kWidth);
}

void BM_RgbProductU8(benchmark::State& state) {
  const Band& b = band();
  std::vector<float> coeffs(std::size_t{kWidth} * 3 * 6);
  for (auto _ : state) {
    for (int r = 0; r < kRows; ++r) {
      ptmkit::fit::internal::apply_pinv_u8(b.pinv.data(), kImages, b.bytes.data() + r * kWidth * 3,
                                           kImageStride, std::ptrdiff_t{kWidth} * 3, coeffs.data());
    }
    benchmark::DoNotOptimize(coeffs.data());
    benchmark::ClobberMemory();
  }
  state.SetItemsProcessed(state.iterations() * kRows * kWidth);
}

BENCHMARK(BM_LrgbRowU8)->Arg(0)->Arg(1)->Arg(2)->Unit(benchmark::kMicrosecond);
BENCHMARK(BM_RgbProductU8)->Unit(benchmark::kMicrosecond);

}  // namespace

BENCHMARK_MAIN();
