// Pixel filters. The convolution filters are RenderMan's (box, triangle, gaussian, catmull-rom,
// windowed sinc) plus blackman-harris and mitchell, all separable: w(dx, dy) = f(dx)·f(dy), with
// a width per axis (the full support, in pixels). Pixel values are Σ w·v / Σ w over every sample
// within the support, so filters are normalised by construction; samples exist beyond the image
// edge (a margin of the filter's radius) so the sum never collapses at borders, and a guard keeps
// negative-lobed filters from dividing by ~0. The special filters min, max, average, zmin and
// zmax (the AOV reference's semantics) take one value per sample from the pixel's own samples.
#pragma once

#include <string>
#include <vector>

#include "resample/sampling.h"

namespace reshutter::resample {

enum class FilterKind { Box, Triangle, Gaussian, CatmullRom, Sinc, BlackmanHarris, Mitchell, Min, Max, Average, ZMin, ZMax };

struct FilterSpec {
  FilterKind kind = FilterKind::Gaussian;
  float width = 2.0f, height = 2.0f;  // full support in pixels
  bool special() const { return kind >= FilterKind::Min; }
  std::string str() const;
  /// "gaussian", "gaussian:2", "gaussian:2x3", "box:1", "zmin". Throws Error naming `where`.
  static FilterSpec parse(const std::string& text, const std::string& where);
};

const char* filterName(FilterKind k);
/// Default full width of a filter kind (RenderMan's defaults where it has them).
float defaultFilterWidth(FilterKind k);
/// The 1D filter at offset x pixels for a support of `width` pixels (0 outside).
float filter1D(FilterKind k, float x, float width);

/// Filter weights tabulated per (pattern, neighbour offset, sample): the weight a sample of a
/// pixel at offset (dx, dy) from the target pixel gets.
class FilterTable {
 public:
  FilterTable(const FilterSpec& spec, const SamplePattern& pattern);
  int margin() const { return margin_; }  // neighbours each side
  int span() const { return 2 * margin_ + 1; }
  /// Weights for `pattern` at neighbour offset (dx, dy) ∈ [-margin, margin]², one per sample.
  const float* weights(int pattern, int dx, int dy) const { return tapWeights(pattern, tapOf(dx, dy)); }
  float weightSum(int pattern, int dx, int dy) const { return tapWeightSum(pattern, tapOf(dx, dy)); }
  /// The same by tap number: tapOf(dx, dy), neighbours in (dy, dx) order.
  int tapOf(int dx, int dy) const { return (dy + margin_) * span() + dx + margin_; }
  const float* tapWeights(int pattern, int tap) const { return &weights_[(size_t(pattern) * size_t(span() * span()) + size_t(tap)) * spp_]; }
  float tapWeightSum(int pattern, int tap) const { return sums_[size_t(pattern) * size_t(span() * span()) + size_t(tap)]; }

 private:
  int margin_, spp_;
  std::vector<float> weights_, sums_;
};

/// One pixel's weighted sums over its neighbourhood. For neighbour j < taps (weights w[j], one per
/// sample; the channel values at in[c] + offset[j]) and channel c < nc <= 8:
/// lanes[c][k] += w[j][i + k] * v[i + k] for i = 0, 8, ... below n rounded down to 8, and tail[c]
/// over the samples past that, neighbour by neighbour. Eight running sums per channel, because a
/// single running sum is a serial chain of adds. Compiled for the x86-64 baseline and for AVX2,
/// picked when the program loads; both do the same IEEE operations in the same order (no fused
/// multiply-add), so the bits are the same.
void accumulateTaps(int n, int nc, const float* const* in, const float* const* w, const size_t* offset, int taps, float lanes[8][8], float tail[8]);

}  // namespace reshutter::resample
