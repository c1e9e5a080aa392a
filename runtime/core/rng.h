#pragma once
// Counter-based random numbers: every draw is a pure function of (seed, tree, node, index), so
// any random choice of a training run can be recomputed anywhere (another worker, a resumed
// coordinator) without replaying a generator's history.

#include <cstdint>

namespace poseforest::core {

/// The SplitMix64 finaliser: a bijective 64-bit mixer with full avalanche.
constexpr uint64_t Mix64(uint64_t z) {
  z += 0x9e3779b97f4a7c15ull;
  z = (z ^ (z >> 30)) * 0xbf58476d1ce4e5b9ull;
  z = (z ^ (z >> 27)) * 0x94d049bb133111ebull;
  return z ^ (z >> 31);
}

/// 128-bit unsigned (a GCC/Clang extension; __extension__ keeps -Wpedantic quiet).
__extension__ typedef unsigned __int128 Uint128;

/// Draws keyed by (seed, tree, node, stream); draw i is a pure function of the key and i.
/// `stream` separates independent uses at the same node (features, thresholds, sampling...).
class CounterRng {
 public:
  constexpr CounterRng(uint64_t seed, uint64_t tree = 0, uint64_t node = 0, uint64_t stream = 0)
      : key_(Mix64(Mix64(Mix64(Mix64(seed) ^ tree) ^ node) ^ stream)) {}

  /// 64 random bits for draw `index`.
  constexpr uint64_t Bits(uint64_t index) const { return Mix64(key_ ^ Mix64(index + 0x632be59bd9b4e019ull)); }
  /// Uniform double in [0, 1) (53 bits).
  constexpr double Uniform01(uint64_t index) const { return double(Bits(index) >> 11) * 0x1.0p-53; }
  /// Uniform integer in [0, n), n > 0 (multiply-shift; bias below 2^-32 for n < 2^32).
  constexpr uint32_t UniformInt(uint64_t index, uint32_t n) const {
    return uint32_t(Uint128(Bits(index)) * n >> 64);
  }
  /// Uniform integer in [lo, hi] inclusive.
  constexpr int32_t UniformIntIn(uint64_t index, int32_t lo, int32_t hi) const {
    return lo + int32_t(UniformInt(index, uint32_t(int64_t(hi) - lo + 1)));
  }
  /// Uniform double in [lo, hi).
  constexpr double UniformIn(uint64_t index, double lo, double hi) const {
    return lo + (hi - lo) * Uniform01(index);
  }
  /// Standard normal via Box-Muller on draws 2*index and 2*index+1.
  double Normal(uint64_t index) const;

  constexpr uint64_t key() const { return key_; }

 private:
  uint64_t key_;
};

/// A sequential view of a CounterRng for code that just wants "the next draw"; still fully
/// reproducible because the position is explicit.
class RngStream {
 public:
  constexpr explicit RngStream(CounterRng rng, uint64_t start = 0) : rng_(rng), next_(start) {}
  uint64_t Bits() { return rng_.Bits(next_++); }
  double Uniform01() { return rng_.Uniform01(next_++); }
  uint32_t UniformInt(uint32_t n) { return rng_.UniformInt(next_++, n); }
  int32_t UniformIntIn(int32_t lo, int32_t hi) { return rng_.UniformIntIn(next_++, lo, hi); }
  double UniformIn(double lo, double hi) { return rng_.UniformIn(next_++, lo, hi); }
  double Normal() { return rng_.Normal(next_++); }
  uint64_t position() const { return next_; }

 private:
  CounterRng rng_;
  uint64_t next_;
};

}  // namespace poseforest::core
