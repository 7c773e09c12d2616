// Counter-based randomness: every random number is a pure function of (seed, counters), so
// results never depend on evaluation order or thread count.
#pragma once

#include <cmath>
#include <cstdint>

namespace ptmkit::synth::detail {

// splitmix64's finaliser: a bijective mix with good avalanche.
[[nodiscard]] inline std::uint64_t mix64(std::uint64_t z) {
  z += 0x9e3779b97f4a7c15ull;
  z = (z ^ (z >> 30)) * 0xbf58476d1ce4e5b9ull;
  z = (z ^ (z >> 27)) * 0x94d049bb133111ebull;
  return z ^ (z >> 31);
}

[[nodiscard]] inline std::uint64_t hash(std::uint64_t seed, std::uint64_t a, std::uint64_t b = 0,
                                        std::uint64_t c = 0) {
  std::uint64_t h = mix64(seed ^ 0x5bd1e9955bd1e995ull);
  h = mix64(h ^ a);
  h = mix64(h ^ (b * 0xd6e8feb86659fd93ull));
  return mix64(h ^ (c * 0xa0761d6478bd642full));
}

// Uniform in [0, 1) from the top 53 bits.
[[nodiscard]] inline double unit(std::uint64_t h) {
  return static_cast<double>(h >> 11) * (1.0 / 9007199254740992.0);
}

// Two independent standard normal deviates, a pure function of `key`: Marsaglia's polar
// method on successive hashes of (key, attempt) (accepts 79% of attempts; no sin or cos).
inline void gaussian_pair(std::uint64_t key, double* z0, double* z1) {
  for (std::uint64_t attempt = 0;; ++attempt) {
    const std::uint64_t h = attempt == 0 ? key : mix64(key ^ (attempt * 0x9e3779b97f4a7c15ull));
    const double u = (static_cast<double>(h >> 32) + 0.5) * (2.0 / 4294967296.0) - 1.0;
    const double v = (static_cast<double>(h & 0xffffffffull) + 0.5) * (2.0 / 4294967296.0) - 1.0;
    const double s = u * u + v * v;
    if (s >= 1.0 || s == 0.0) continue;
    const double f = std::sqrt(-2.0 * std::log(s) / s);
    *z0 = u * f;
    *z1 = v * f;
    return;
  }
}

// Sequential draws for scene parameters: draw k of stream `tag` is hash(seed, tag, k).
class Stream {
 public:
  Stream(std::uint64_t seed, std::uint64_t tag) : seed_(seed), tag_(tag) {}
  [[nodiscard]] double uniform(double lo, double hi) {
    return lo + (hi - lo) * unit(hash(seed_, tag_, counter_++));
  }

 private:
  std::uint64_t seed_;
  std::uint64_t tag_;
  std::uint64_t counter_ = 0;
};

}  // namespace ptmkit::synth::detail
