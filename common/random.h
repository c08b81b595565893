// Deterministic, platform-independent random numbers and hashing (the standard library's
// distributions are implementation-defined, which would break bit-identical output).
#pragma once

#include <cstdint>

namespace reshutter {

/// SplitMix64 finaliser: a high-quality 64-bit mix, used to hash (pixel, sample, seed) tuples.
constexpr uint64_t mix64(uint64_t x) {
  x += 0x9E3779B97F4A7C15ull;
  x = (x ^ (x >> 30)) * 0xBF58476D1CE4E5B9ull;
  x = (x ^ (x >> 27)) * 0x94D049BB133111EBull;
  return x ^ (x >> 31);
}

constexpr uint64_t hashCombine(uint64_t a, uint64_t b) { return mix64(a ^ (mix64(b) + 0x632BE59BD9B4E019ull)); }

/// Uniform float in [0, 1) from the top 24 bits.
constexpr float toUnitFloat(uint64_t bits) { return float(bits >> 40) * 0x1.0p-24f; }
constexpr double toUnitDouble(uint64_t bits) { return double(bits >> 11) * 0x1.0p-53; }

/// A small sequential generator (SplitMix64 stream).
class Rng {
 public:
  explicit constexpr Rng(uint64_t seed) : state_(seed) {}
  constexpr uint64_t next() {
    state_ += 0x9E3779B97F4A7C15ull;
    return mix64(state_);
  }
  constexpr double uniform() { return toUnitDouble(next()); }
  constexpr double uniform(double lo, double hi) { return lo + (hi - lo) * uniform(); }
  constexpr uint32_t below(uint32_t n) { return uint32_t((next() >> 32) * n >> 32); }

 private:
  uint64_t state_;
};

}  // namespace reshutter
