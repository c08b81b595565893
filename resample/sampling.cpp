#include "resample/sampling.h"

#include <cmath>

#include "common/random.h"

namespace reshutter::resample {

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
}

int SamplePattern::patternOf(int px, int py) const {
  uint64_t h = hashCombine(seed_, (uint64_t(uint32_t(px)) << 32) | uint32_t(py));
  return int(h % kPatterns);
}

void SamplePattern::times(int px, int py, uint16_t* stratumOf, float* u) const {
  uint64_t key = hashCombine(seed_ ^ 0x7157000000000000ull, (uint64_t(uint32_t(px)) << 32) | uint32_t(py));
  Rng rng(key);
  for (int i = 0; i < spp_; ++i) stratumOf[i] = uint16_t(i);
  for (int i = spp_ - 1; i > 0; --i) {  // Fisher-Yates with a deterministic generator
    int j = int(rng.below(uint32_t(i + 1)));
    std::swap(stratumOf[i], stratumOf[j]);
  }
  const float inv = 1.0f / float(spp_);
  for (int i = 0; i < spp_; ++i) {
    float v = (float(stratumOf[i]) + toUnitFloat(rng.next())) * inv;
    u[i] = std::min(v, 0x1.fffffep-1f);
  }
}

}  // namespace reshutter::resample
