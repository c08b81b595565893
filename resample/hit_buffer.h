// What a bucket's samples saw: per sample the nearest opaque surface (depth, colour, ids, output
// variables) and a list of the transparent surfaces in front of it; recording a hit into them,
// and resolving them - front-to-back compositing into ResolvedSamples for the flat image, or the
// fragment lists for deep output (visitFragments()).
//
// Indexed like the samples (stratum-major, s * PS + p: see bucket_samples.h), so a micropolygon's
// hits land next to the sample data its tests just read; resolve() reorders them by pixel. The
// depth is INFINITY until a surface is found; colours are read only where the depth is finite, so
// they need no clearing per bucket.
#pragma once

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <functional>
#include <vector>

#include "resample/bucket_samples.h"
#include "resample/raster.h"
#include "resample/volume.h"

namespace reshutter::resample {

/// The colour of the nearest opaque surface a sample has seen (its depth is in a separate array,
/// the only part a hit must read), and whether that surface is a matte.
struct SurfaceColour {
  float r, g, b;
  uint32_t matte;
};
static_assert(sizeof(SurfaceColour) == 16, "resolve() reads four records as four vectors");

struct HitBuffer {
  HitBuffer(const std::vector<AovChannel>& aovs, const RasterOptions& options, float farClip, RasterStats& counters);

  /// Clears every sample's surfaces for a region of `slots` samples (BucketSamples::sampleSlots).
  void reset(size_t slots);

  /// What every hit of one micropolygon part shares.
  struct HitContext {
    const store::TilePart* part;
    const store::Schema* schema;
    int ci, oi;
    bool transparentPart;
    // The common cases - per-vertex colour (and, in a transparent part, per-vertex opacity), no
    // output variables - take recordOpaqueHit() / recordColourHit() with the arrays at hand
    // instead of the general attribute lookup.
    bool opaqueFast = false, transparentFast = false;
    const float* colour = nullptr;
    const float* opacity = nullptr;
    // A part shaded in time (store::kEffectShadedInTime): colour and opacity at the sample's own
    // time, linear between the two shading times around it (held at the first and last outside
    // them). The sample's local time is sampleTime[sample] + toLocal.
    bool timed = false;
    int numTimes = 0;
    const double* shadingTimes = nullptr;
    int timedCi[store::StoreMeta::kMaxShadingTimes] = {}, timedOi[store::StoreMeta::kMaxShadingTimes] = {};
    // Output variable a's slot at each time: timedAov[a * kMaxShadingTimes + k], [.. + 1] < 0 when
    // the store carries it at the first time only (null: none carried). Valid until the next
    // hitContext() call.
    const int* timedAov = nullptr;
    const float* sampleTime = nullptr;
    double toLocal = 0;
  };
  /// The context of `part`'s hits; sampleTime / toLocal map a sample to the store's local time
  /// (used by parts shaded in time).
  HitContext hitContext(const store::StoreMeta& meta, const store::TileEntry& entry, const store::TilePart& part, const float* sampleTime,
                        double toLocal) const;

  /// Records a hit of micropolygon m on a sample (its stratum-major index s * PS + p): triangle
  /// vertices v, barycentrics b, camera depth z.
  void recordHit(const HitContext& hc, uint32_t sample, uint32_t m, const uint32_t v[3], const float b[3], float z) {
    if (hc.opaqueFast) recordOpaqueHit(hc, sample, m, v, b, z);
    else if (hc.transparentFast) recordColourHit(hc, sample, m, v, b, z);
    else recordAnyHit(hc, sample, m, v, b, z);
  }

  /// Composites each sample's surfaces front to back.
  const ResolvedSamples& resolve(const BucketSamples& samples);
  /// BucketRasterizer::visitFragments().
  void visitFragments(const BucketSamples& samples, const std::function<void(size_t, const SampleFragment*, size_t)>& fn);

  const std::vector<AovChannel>& aovs;
  const float opacityThreshold;
  const bool surfaceIds;
  const float farClip;
  RasterStats& counters;  // hits, fragments
  const AovLayout aovLayout;

  size_t hitSlots = 0;  // the length of every per-sample array
  SkewedArray<float> zbuf{24};
  SkewedArray<SurfaceColour> colour{32};
  SurfaceColour discard{};  // where a hit behind the nearest surface writes its colour
  SkewedArray<uint32_t> objectOf{56}, gridOf{4};
  std::vector<float> zAov;      // [component * hitSlots + sample]
  std::vector<uint32_t> zAovU;  // [component * hitSlots + sample]
  // Volumes (resample/volume.h): this thread's tracer, and whether the region may see a volume
  // (set per region by the rasterizer); resolve() and visitFragments() then march each sample's
  // ray between its surfaces.
  VolumeTracer* volumes = nullptr;
  bool volumesHere = false;
  double volumeSliceRatio = 1.01;  // deep output's depth slices (VolumeSlice)
  // With deep output, resolve() keeps each sample's volume slices for visitFragments(): the
  // sample's segments in order, each ended by a marker (slice kSegmentEnd) holding the whole.
  static constexpr int32_t kSegmentEnd = INT32_MIN;
  std::vector<VolumeSlice> keptSlices;
  std::vector<uint32_t> keptSliceStart;  // per slot, and the end
  bool slicesKept = false;

 private:
  // A transparent surface in front of a sample's nearest opaque one.
  struct Fragment {
    float z;
    float c[3];
    float o[3];
    uint32_t objectId, gridId;
    uint32_t seq;     // draw order; also where its output variables lie in fragAov / fragAovU (seq × count)
    uint32_t sample;  // stratum-major index
    uint8_t matte;
  };
  static constexpr uint8_t kHitOpaque = 1, kHitMatte = 2;  // what resolve() finds at a sample

  // Same values as recordAnyHit() gives an opaque surface (attrAt's arithmetic, in its order).
  void recordOpaqueHit(const HitContext& hc, uint32_t sample, uint32_t m, const uint32_t v[3], const float b[3], float z) {
    ++counters.hits;
    const store::TilePart& part = *hc.part;
    float rgb[3];
    interpolate3(hc.colour, v, b, rgb);
    const SurfaceColour c{rgb[0], rgb[1], rgb[2], uint32_t(part.flags[m] & store::kMatte)};
    // No branch: whether a surface is nearer is a coin toss that the predictor loses, so the
    // depth is a min and the colour goes to the sample or, when hidden, to a scratch record.
    // Ties keep the surface drawn first: deterministic by draw order (rasterizeQueued).
    const float old = zbuf[sample];
    const bool nearer = z < old;
    zbuf[sample] = nearer ? z : old;
    *(nearer ? &colour[sample] : &discard) = c;
    if (surfaceIds && nearer) objectOf[sample] = part.objectId[m], gridOf[sample] = part.gridId[m];
  }
  // A hit of a transparent part with per-vertex colour and opacity and no output variables: the
  // values recordAnyHit() gives it (attrAt's arithmetic, in its order), without its lookups.
  void recordColourHit(const HitContext& hc, uint32_t sample, uint32_t m, const uint32_t v[3], const float b[3], float z) {
    ++counters.hits;
    if (!(z < zbuf[sample])) return;  // hidden; ties keep the surface drawn first (rasterizeQueued)
    const store::TilePart& part = *hc.part;
    float o[3], c[3];
    interpolate3(hc.opacity, v, b, o);
    interpolate3(hc.colour, v, b, c);
    const bool matte = part.flags[m] & store::kMatte;
    if (o[0] >= 1.f && o[1] >= 1.f && o[2] >= 1.f) setNearestOpaque(sample, z, c, matte, part, m);
    else addFragment(sample, z, c, o, part.objectId[m], part.gridId[m], matte);
  }
  // A per-vertex colour3 array at barycentrics b over triangle v (attrAt's arithmetic, in its order).
  static void interpolate3(const float* values, const uint32_t v[3], const float b[3], float out[3]) {
    const float *a0 = values + size_t(v[0]) * 3, *a1 = values + size_t(v[1]) * 3, *a2 = values + size_t(v[2]) * 3;
    for (int k = 0; k < 3; ++k) out[k] = b[0] * a0[k] + b[1] * a1[k] + b[2] * a2[k];
  }
  // The sample's nearest opaque surface is now micropolygon m of `part` at depth z.
  void setNearestOpaque(uint32_t sample, float z, const float c[3], bool matte, const store::TilePart& part, uint32_t m) {
    zbuf[sample] = z;
    colour[sample] = {c[0], c[1], c[2], uint32_t(matte)};
    if (surfaceIds) objectOf[sample] = part.objectId[m], gridOf[sample] = part.gridId[m];
  }
  void addFragment(uint32_t sample, float z, const float c[3], const float o[3], uint32_t objectId, uint32_t gridId, bool matte);
  void recordAnyHit(const HitContext& hc, uint32_t sample, uint32_t m, const uint32_t v[3], const float b[3], float z);
  // Colour (slots = timedCi) or opacity (timedOi) of a hit: the stored attribute, or for a part
  // shaded in time the blend at the sample's time.
  void shadingAt(const HitContext& hc, const int* slots, uint32_t sample, uint32_t m, const uint32_t v[3], const float b[3], float out[3]) const;
  // An attribute of `components` (at most 16) at the sample's time, linear between the shading
  // times around it (slots[k]: its schema slot at time k).
  void timedAt(const HitContext& hc, const int* slots, uint32_t sample, uint32_t m, const uint32_t v[3], const float b[3], int components, float* out) const;
  // Puts each sample's fragments next to each other, in the order resolve() visits the samples
  // (a counting sort by sample): the lists are then read sequentially, not chased through memory.
  void groupFragments(const BucketSamples& samples);
  // Sample slot's fragments nearer than its opaque depth zo, front to back into `list`.
  void nearerFragments(size_t k, float zo, std::vector<const Fragment*>& list) const;
  // Sample's output variables for a hit (at the sample's time where the part carries them in time).
  void aovValues(const HitContext& hc, uint32_t sample, uint32_t m, const uint32_t v[3], const float b[3], float z, float* f, uint32_t* u) const;
  uint8_t hitState(size_t k) const {
    if (!(zbuf[k] < INFINITY)) return 0;
    return kHitOpaque | (colour[k].matte ? kHitMatte : 0);
  }
  void zeroCompositedAovs(size_t slot);
  // Resolving visits the samples pixel by pixel, which is across the stratum-major arrays: a
  // sample's depth and colour are fetched ahead, as no hardware prefetcher follows that order.
  static constexpr size_t kPrefetchAhead = 16;
  void prefetchSample(const std::vector<uint32_t>& idxOf, size_t slot, size_t slots) const {
    if (slot >= slots) return;
    const size_t k = idxOf[slot];
    __builtin_prefetch(&zbuf[k]);
    __builtin_prefetch(&colour[k]);
  }

  // hitContext()'s lookup of a store's "Ci@k" / "Oi@k" (and output variables') slots, kept for
  // the store it was made for.
  struct TimedSlots {
    const store::StoreMeta* meta = nullptr;
    int ci[store::StoreMeta::kMaxShadingTimes] = {}, oi[store::StoreMeta::kMaxShadingTimes] = {};
    std::vector<int> aov;  // HitContext::timedAov's layout
  };
  mutable TimedSlots timedSlots;

  SkewedArray<uint32_t> fragCount{12};  // per sample, after groupFragments(): its fragments
  std::vector<uint32_t> fragEnd;        // per sample, after groupFragments(): the end of its run in frags
  std::vector<Fragment> frags, fragScratch;
  bool fragmentsGrouped = false;
  std::vector<float> fragAov;
  std::vector<uint32_t> fragAovU;
  uint32_t fragSeq = 0;
  bool anyFragments = false;
  ResolvedSamples out;
};

}  // namespace reshutter::resample
