#include "resample/sampling.h"

#include <cmath>
#include <cstring>
#include <utility>
#include <vector>

#include "common/random.h"

namespace reshutter::resample {

namespace {

// The concentric map of [0, 1)² onto the unit disk: squares around the centre become rings, so
// equal cells stay equal in area and compact (a polar map would make slivers near the centre).
glm::vec2 concentricDisk(double u, double v) {
  const double a = 2 * u - 1, b = 2 * v - 1;
  if (a == 0 && b == 0) return {0.f, 0.f};
  constexpr double kQuarterPi = 0.78539816339744830962;
  double r, phi;
  if (std::abs(a) > std::abs(b)) r = a, phi = kQuarterPi * (b / a);
  else r = b, phi = 2 * kQuarterPi - kQuarterPi * (a / b);
  return {float(r * std::cos(phi)), float(r * std::sin(phi))};
}

}  // namespace

void SamplePattern::factor(int spp, int& nx, int& ny) {
  nx = int(std::sqrt(double(spp)));
  while (nx > 1 && spp % nx) --nx;
  ny = spp / nx;
}

SamplePattern::SamplePattern(int nx, int ny, uint64_t seed) : nx_(nx), ny_(ny), spp_(nx * ny), seed_(seed) {
  offsets_.resize(size_t(kPatterns) * spp_);
  for (int p = 0; p < kPatterns; ++p) {
    Rng rng(hashCombine(seed, 0x5A3F0000u + uint64_t(p)));
    for (int j = 0; j < ny; ++j)
      for (int i = 0; i < nx; ++i) {
        // Jittered grid; the float result stays strictly below 1.
        float x = float((i + rng.uniform()) / nx), y = float((j + rng.uniform()) / ny);
        offsets_[size_t(p) * spp_ + size_t(j * nx + i)] = {std::min(x, 0x1.fffffep-1f), std::min(y, 0x1.fffffep-1f)};
      }
  }
  lensPoints_.resize(size_t(kPatterns) * spp_);
  for (int p = 0; p < kPatterns; ++p) {
    Rng rng(hashCombine(seed, 0x1E450000u + uint64_t(p)));
    for (int s = 0; s < spp_; ++s) {
      const double u = (double(s % nx) + rng.uniform()) / nx, v = (double(s / nx) + rng.uniform()) / ny;
      lensPoints_[size_t(p) * spp_ + size_t(s)] = concentricDisk(u, v);
    }
  }
}

int SamplePattern::patternOf(int px, int py) const {
  uint64_t h = hashCombine(seed_, (uint64_t(uint32_t(px)) << 32) | uint32_t(py));
  return int(h % kPatterns);
}

namespace {

// Draws 1..n of the SplitMix64 stream Rng(key) gives, each on its own: draw k is
// mix64(key + k·γ), so the n mixes do not wait on each other (the generator's loop would chain
// them through its state) and the baseline x86-64 build vectorises them where the CPU allows:
// AVX-512 multiplies 64-bit lanes itself, AVX2 from 32-bit halves (still about half the
// instructions of the scalar loop).
#if defined(__x86_64__) && !defined(__clang__)
__attribute__((target_clones("arch=x86-64-v4", "arch=x86-64-v3", "default")))
#endif
void splitMixDraws(uint64_t key, int n, uint64_t* out) {
  for (int k = 0; k < n; ++k) out[k] = mix64(key + uint64_t(k + 1) * 0x9E3779B97F4A7C15ull);
}

}  // namespace

namespace {

// A pixel's draws from the stream `salt` of the seed: kept on the stack for the usual counts.
class PixelDraws {
 public:
  PixelDraws(uint64_t seed, uint64_t salt, int px, int py, int n) {
    uint64_t* r = local_;
    if (n > kLocal) heap_.resize(size_t(n)), r = heap_.data();
    splitMixDraws(hashCombine(seed ^ salt, (uint64_t(uint32_t(px)) << 32) | uint32_t(py)), n, r);
    draws_ = r;
  }
  const uint64_t* data() const { return draws_; }

 private:
  static constexpr int kLocal = 256;
  uint64_t local_[kLocal];
  std::vector<uint64_t> heap_;
  const uint64_t* draws_;
};

// Fisher-Yates' swap target for position i from one draw: below i + 1 (Rng::below's mapping).
constexpr int swapTarget(uint64_t draw, int i) { return int(uint32_t((draw >> 32) * uint64_t(uint32_t(i + 1)) >> 32)); }

// permutation() of 0..3 from 3 draws, by a table of the 24 outcomes (indexed by the three swap
// targets): the same permutation without the three dependent swaps through memory (the lens
// blocks' permutations, eight a pixel at 16 samples).
struct Permutations4 {
  uint16_t v[24][4] = {};
  constexpr Permutations4() {
    for (int j3 = 0; j3 < 4; ++j3)
      for (int j2 = 0; j2 < 3; ++j2)
        for (int j1 = 0; j1 < 2; ++j1) {
          uint16_t* p = v[j3 * 6 + j2 * 2 + j1];
          for (int i = 0; i < 4; ++i) p[i] = uint16_t(i);
          std::swap(p[3], p[j3]), std::swap(p[2], p[j2]), std::swap(p[1], p[j1]);
        }
  }
};
constexpr Permutations4 kPermutations4;
const uint64_t* permutation4(const uint64_t* r, uint16_t* v) {
  std::memcpy(v, kPermutations4.v[swapTarget(r[0], 3) * 6 + swapTarget(r[1], 2) * 2 + swapTarget(r[2], 1)], 4 * sizeof(uint16_t));
  return r + 3;
}

// A permutation of 0..n-1 into v by Fisher-Yates from n - 1 draws (Rng::below's mapping); returns
// the draws after those it used.
const uint64_t* permutation(const uint64_t* r, uint16_t* v, int n) {
  if (n == 4) return permutation4(r, v);
  for (int i = 0; i < n; ++i) v[i] = uint16_t(i);
  for (int i = n - 1; i > 0; --i, ++r) std::swap(v[i], v[swapTarget(*r, i)]);
  return r;
}

}  // namespace

void SamplePattern::times(int px, int py, uint16_t* stratumOf, float* u) const {
  // The same values as Rng(key): spp - 1 draws for the shuffle, then one jitter per sample.
  const PixelDraws draws(seed_, 0x7157000000000000ull, px, py, 2 * spp_ - 1);
  const uint64_t* jitter = permutation(draws.data(), stratumOf, spp_);
  const float inv = 1.0f / float(spp_);
  for (int i = 0; i < spp_; ++i) {
    float v = (float(stratumOf[i]) + toUnitFloat(jitter[i])) * inv;
    u[i] = std::min(v, 0x1.fffffep-1f);
  }
}

void SamplePattern::lens(int px, int py, uint16_t* stratumOf, glm::vec2* disk) const {
  // A stream of its own (not the time stream's): renders without a lens keep their samples.
  // The pattern, then the shuffle.
  const PixelDraws draws(seed_, 0x1E45000000000000ull, px, py, spp_);
  const glm::vec2* points = &lensPoints_[size_t(draws.data()[0] % kPatterns) * spp_];
  permutation(draws.data() + 1, stratumOf, spp_);
  for (int i = 0; i < spp_; ++i) disk[i] = points[stratumOf[i]];
}

void SamplePattern::lensPlanes(int px, int py, const uint16_t* timeStratumOf, int timeBlocks, uint16_t* planeOf, glm::vec2* disk) const {
  if (timeBlocks <= 1) {
    lens(px, py, planeOf, disk);
    return;
  }
  const int A = timeBlocks, B = 4, halfX = nx_ / 2, halfY = ny_ / 2;
  // A stream of its own again: the pattern, a permutation of the lens blocks per time block, and
  // a permutation of each lens block's strata over the time blocks.
  const PixelDraws draws(seed_, 0x1E4B000000000000ull, px, py, 1 + A * (B - 1) + B * (A - 1));
  const glm::vec2* points = &lensPoints_[size_t(draws.data()[0] % kPatterns) * spp_];
  const uint64_t* r = draws.data() + 1;
  uint16_t blockOf[64][4], cellOf[4][64];  // per time block: lens block by time sub-stratum; per lens block: its stratum by time block
  for (int a = 0; a < A; ++a) r = permutation(r, blockOf[a], B);
  for (int b = 0; b < B; ++b) r = permutation(r, cellOf[b], A);
  // Lens block b's stratum k is point (b % 2) halfX + k % halfX, (b / 2) halfY + k / halfX of the
  // nx × ny pattern: its offset within the block per k, and each block's first point, made once
  // per call (the divisions by halfX, per sample, were most of this function).
  int cellAt[64], blockAt[4];
  for (int k = 0; k < A; ++k) cellAt[k] = (k / halfX) * nx_ + k % halfX;
  for (int b = 0; b < B; ++b) blockAt[b] = (b / 2) * halfY * nx_ + (b % 2) * halfX;
  for (int i = 0; i < spp_; ++i) {
    const int ts = timeStratumOf[i], a = ts / B, b = blockOf[a][ts % B], k = cellOf[b][a];
    planeOf[i] = uint16_t(a * B + b);
    disk[i] = points[blockAt[b] + cellAt[k]];
  }
}

}  // namespace reshutter::resample
