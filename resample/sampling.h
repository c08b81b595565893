// Sample patterns. Each pixel takes N samples: positions from one of a fixed set of stratified
// (jittered nx×ny grid) patterns chosen per pixel by hash, and times from a per-pixel permutation
// of N time strata with jitter inside each stratum, so time is decorrelated from position. Every
// value is a pure function of (pixel, sample index, seed): images are bit-identical whatever the
// thread count, bucket size or farm split.
//
// Why a fixed pattern set instead of fresh positions per pixel: pixel-filter weights then depend
// only on (pattern, neighbour offset, sample), so they are tabulated once and the resolve becomes
// short dot products (see filter.h). 64 patterns, picked by hash, show no visible structure.
#pragma once

#include <cstdint>
#include <vector>

#include <glm/vec2.hpp>

namespace reshutter::resample {

class SamplePattern {
 public:
  static constexpr int kPatterns = 64;
  /// `nx`×`ny` samples per pixel (stratified positions), `seed` selects the patterns and jitter.
  SamplePattern(int nx, int ny, uint64_t seed);
  /// Chooses nx×ny for `spp` samples: the most square factorisation.
  static void factor(int spp, int& nx, int& ny);

  int spp() const { return spp_; }
  int nx() const { return nx_; }
  int ny() const { return ny_; }
  uint64_t seed() const { return seed_; }

  int patternOf(int px, int py) const;
  /// Position of sample i inside its pixel, in [0, 1)².
  glm::vec2 offset(int pattern, int i) const { return offsets_[size_t(pattern) * spp_ + i]; }
  /// A pattern's spp offsets, side by side (x, y of sample 0, then of sample 1, ...).
  const glm::vec2* offsets(int pattern) const { return &offsets_[size_t(pattern) * spp_]; }
  /// Time strata of the pixel's samples: stratumOf[i] is a permutation of 0..N-1; u[i] is the
  /// time variate (stratumOf[i] + jitter) / N ∈ [0, 1).
  void times(int px, int py, uint16_t* stratumOf, float* u) const;
  /// Lens strata of the pixel's samples, for depth of field: stratumOf[i] is a permutation of
  /// 0..N-1 independent of the time strata's (so defocus and motion blur do not alias against each
  /// other); stratum s is cell (s mod nx, s div nx) of the nx×ny grid over the unit square, jittered
  /// inside it and mapped to the unit disk by the concentric map (Shirley and Chiu), which keeps
  /// the cells' areas equal and compact. Like positions, the jittered points come from a fixed set
  /// of patterns, one chosen per pixel by hash (no trigonometry per sample).
  void lens(int px, int py, uint16_t* stratumOf, glm::vec2* disk) const;
  /// Lens points of the pixel's samples and the bucket plane each belongs to (BucketSamples),
  /// given their time strata. timeBlocks = 1: lens() - planes are lens strata. timeBlocks = A > 1
  /// (nx and ny even, A = N / 4): plane a·4 + b pairs time block a (N/A consecutive time strata)
  /// with lens block b (a quadrant of the lens strata grid, A strata): the lens path sorts each
  /// time block's samples apart, so a moving micropolygon searches one block's part of its path at
  /// a time, and each block still spans the whole aperture; each pixel still takes every time
  /// stratum and every lens stratum once, the pairings permuted per pixel.
  void lensPlanes(int px, int py, const uint16_t* timeStratumOf, int timeBlocks, uint16_t* planeOf, glm::vec2* disk) const;

 private:
  int nx_, ny_, spp_;
  uint64_t seed_;
  std::vector<glm::vec2> offsets_;
  std::vector<glm::vec2> lensPoints_;  // [pattern * spp + stratum]: a point of the unit disk in that lens stratum
};

}  // namespace reshutter::resample
