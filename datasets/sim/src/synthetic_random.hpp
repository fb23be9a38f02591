#pragma once
// Random numbers for the synthetic generator that give the same bytes on every platform:
// std::mt19937_64 (its output sequence is fixed by the C++ standard) with our own uniform and
// normal transforms (std::normal_distribution is implementation-defined, so it is not used).
#include <cmath>
#include <cstdint>
#include <random>

namespace planeslam::datasets {

/// SplitMix64 finaliser: decorrelates seeds such as (seed, frame index) before seeding mt19937_64.
inline std::uint64_t MixSeed(std::uint64_t x) {
  x += 0x9e3779b97f4a7c15ULL;
  x = (x ^ (x >> 30)) * 0xbf58476d1ce4e5b9ULL;
  x = (x ^ (x >> 27)) * 0x94d049bb133111ebULL;
  return x ^ (x >> 31);
}

class SplitMixRandom {
 public:
  explicit SplitMixRandom(std::uint64_t seed) : engine_(MixSeed(seed)) {}

  /// Uniform in [0, 1): the top 53 bits of one draw.
  double Uniform() { return static_cast<double>(engine_() >> 11) * 0x1.0p-53; }
  double Uniform(double a, double b) { return a + (b - a) * Uniform(); }

  /// Standard normal by the Marsaglia polar method (exact, no tables).
  double Normal() {
    if (have_spare_) {
      have_spare_ = false;
      return spare_;
    }
    double u, v, s;
    do {
      u = 2.0 * Uniform() - 1.0;
      v = 2.0 * Uniform() - 1.0;
      s = u * u + v * v;
    } while (s >= 1.0 || s == 0.0);
    const double f = std::sqrt(-2.0 * std::log(s) / s);
    spare_ = v * f;
    have_spare_ = true;
    return u * f;
  }

  /// Standard normal truncated to [-limit, limit] by rejection.
  double TruncatedNormal(double limit) {
    for (;;) {
      const double x = Normal();
      if (std::abs(x) <= limit) return x;
    }
  }

 private:
  std::mt19937_64 engine_;
  bool have_spare_ = false;
  double spare_ = 0.0;
};

}  // namespace planeslam::datasets
