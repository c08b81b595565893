// The bucket: its samples prepared, parts queued and cut into chunks drawn nearest first, each
// chunk handed to the path that draws it (static, moving, linear: see raster_impl.h), and the
// public BucketRasterizer.
#include <algorithm>
#include <cmath>

#include "common/error.h"
#include "resample/raster_impl.h"

namespace reshutter::resample {

using store::kNoCorner;
using store::TileEntry;
using store::TilePart;

void RasterStats::add(const RasterStats& o) {
  sampleTests += o.sampleTests;
  hits += o.hits;
  micropolygons += o.micropolygons;
  parts += o.parts;
  fragments += o.fragments;
  generalHits += o.generalHits;
  staticMicropolygons += o.staticMicropolygons;
  linearMicropolygons += o.linearMicropolygons;
  chunkCulledMicropolygons += o.chunkCulledMicropolygons;
  chunkGatheredMicropolygons += o.chunkGatheredMicropolygons;
  groupsTogetherMicropolygons += o.groupsTogetherMicropolygons;
  lensMicropolygons += o.lensMicropolygons;
  lensScanned += o.lensScanned;
  lensLayers += o.lensLayers;
  lensSparseLayers += o.lensSparseLayers;
  lensSortVisited += o.lensSortVisited;
  lensCulledMicropolygons += o.lensCulledMicropolygons;
  lensSegmentDraws += o.lensSegmentDraws;
  midIntervalSamples += o.midIntervalSamples;
  pixelMajorSamples += o.pixelMajorSamples;
  transparentParts += o.transparentParts;
}

BucketRasterizer::Impl::Impl(const SamplePattern& p, const ShutterModel& s, const View& v, const std::vector<AovChannel>& a, const RasterOptions& o)
    : BucketSamples(p, s, v.lens() ? o.lensTimeBlocks : 0, o.sampleTimes),
      HitBuffer(a, o, v.farClip, stats),
      view(v),
      opt(o),
      vectorKernels(o.vectorKernels && kernels::available()),
      isa(o.avx512Kernels && kernels::available(kernels::Isa::Avx512) ? kernels::Isa::Avx512 : kernels::Isa::Avx2),
      rasterScale{1.0 / v.ax, 1.0 / v.ay, v.bx, v.by, v.perspective},
      projectionScale{v.ax, v.bx, v.ay, v.by, v.nearClip, v.perspective} {}

void BucketRasterizer::Impl::begin(int rx0, int ry0, int rw, int rh) {
  prepare(rx0, ry0, rw, rh);
  const size_t slots = sampleSlots;
  // One micropolygon's candidates: at most one per pixel and stratum, and the kernels write up
  // to 7 entries past the count.
  candidates.resize(slots + kPad), candT.resize(slots + kPad), candX.resize(slots + kPad), candY.resize(slots + kPad);
  edgeHits.resize(slots + kPad);
  for (auto* a : {&chunkIndex, &sortedIndex}) a->resize(slots + kPad);
  for (auto* a : {&chunkT, &chunkX, &chunkY, &sortedT, &sortedX, &sortedY}) a->resize(slots + kPad);
  cellScratch.resize(slots + kPad);
  if (lensPlanes) {
    lensKeptSlot.resize(slots + kPad), lensKeptCell.resize(slots + kPad);
    lensSortedIndex.resize(slots + kPad), lensCandPos.resize(slots + kPad);
    lensSearches.resize(size_t(lensTimeBlocks));
    for (auto* a : {&lensSortedT, &lensSortedX, &lensSortedY, &lensSortedU, &lensSortedV, &candU, &candV, &candF}) a->resize(slots + kPad);
    lensDraws.clear(), lensChunks.clear();
  }
  reset(slots);
  stats = RasterStats{};
  if (!drawTimes) stats.midIntervalSamples = uint64_t(P) * uint64_t(N);
  if (pixelMajor) stats.pixelMajorSamples = uint64_t(P) * uint64_t(N);
  volumesHere = volumes && volumes->touches(double(x0), double(y0), double(x0 + w), double(y0 + h));
  if (volumesHere) volumes->beginRegion(x0, y0, w, h);
  queued.clear(), chunks.clear(), movingTimes.clear();
}

// Queues a part: its chunks of kChunkSize micropolygons, each with its nearest depth at any
// knot and its vertex range.
void BucketRasterizer::Impl::add(const Source& src, const TileEntry& entry, const TilePart& part) {
  const uint32_t index = uint32_t(queued.size());
  queued.push_back({&src, &entry, &part});
  ++stats.parts;
  stats.micropolygons += part.numMicropolygons;
  if (entry.effects & store::kEffectTransparent) ++stats.transparentParts;
  const uint32_t K = part.numKnots;
  for (uint32_t m0 = 0; m0 < part.numMicropolygons; m0 += kChunkSize) {
    Chunk ch{INFINITY, index, m0, std::min(part.numMicropolygons, m0 + kChunkSize), ~0u, 0, false};
    // Both loops below eight at a time with the vector kernels (the same range and depth).
    if (vectorKernels) {
      kernels::cornerRange(isa, &part.corners[size_t(ch.m0) * 4], ch.m1 - ch.m0, ch.vLo, ch.vHi);
    } else {
      for (uint32_t m = ch.m0; m < ch.m1; ++m)
        for (int j = 0; j < 4; ++j) {
          const uint32_t v = part.corners[size_t(m) * 4 + j];
          if (v != kNoCorner) ch.vLo = std::min(ch.vLo, v), ch.vHi = std::max(ch.vHi, v);
        }
    }
    if (ch.vLo > ch.vHi) continue;  // no corners: nothing to draw
    // The range's vertices (a grid's rows: few the chunk does not use) bound its depth.
    for (uint32_t k = 0; k < K; ++k) {
      if (vectorKernels) ch.zNear = kernels::nearestDepth(isa, &part.position(k, ch.vLo).x, ch.vHi - ch.vLo + 1, ch.zNear);
      else
        for (uint32_t v = ch.vLo; v <= ch.vHi; ++v) ch.zNear = std::min(ch.zNear, part.position(k, v).z);
    }
    // Rows of a moving part that stand still (a deforming grid's pinned end, a store written
    // before the writer kept still grids static) take the static path.
    ch.still = K > 1 && store::verticesStandStill(part.positions, part.numVertices, ch.vLo, ch.vHi - ch.vLo + 1);
    if (std::isnan(ch.zNear)) ch.zNear = -INFINITY;  // the sort needs a strict weak order
    chunks.push_back(ch);
  }
}

// Draws the queued chunks nearest first, so that occlusion culling finds most hidden surfaces'
// occluders already drawn. Equal depths keep queue order: the resampler queues parts in store
// order, so a depth tie resolves the same way in every bucket.
void BucketRasterizer::Impl::rasterizeQueued() {
  std::sort(chunks.begin(), chunks.end(), [](const Chunk& a, const Chunk& b) {
    return a.zNear != b.zNear ? a.zNear < b.zNear : a.part != b.part ? a.part < b.part : a.m0 < b.m0;
  });
  for (const Chunk& ch : chunks) {
    const QueuedPart& q = queued[ch.part];
    rasterizeChunk(*q.src, *q.entry, *q.part, ch);
  }
  if (view.lens()) drawLensQueued();  // the lens path queues every micropolygon, to draw them by layer
  queued.clear(), chunks.clear();
}

void BucketRasterizer::Impl::rasterizeChunk(const Source& src, const TileEntry& entry, const TilePart& part, const Chunk& ch) {
  // The chunk's corners, which every path reads first after projecting the chunk's vertices:
  // fetched now, so that the projection runs while they arrive (chunks go by depth, so parts
  // interleave and a chunk's corners are rarely in cache).
  for (const uint32_t *c = &part.corners[size_t(ch.m0) * 4], *end = &part.corners[size_t(ch.m1) * 4]; c < end; c += 16) __builtin_prefetch(c);
  const auto& meta = src.store->meta();
  const auto& knots = src.knots(entry.schedule);
  const HitContext hc = hitContext(meta, entry, part, st.data(), tBase - double(src.frame));
  if (view.lens()) {
    rasterizeLens(src, entry, part, hc, ch);
    return;
  }
  const bool moving = (entry.effects & store::kEffectMoving) && part.numKnots > 1 && !ch.still;
  if (!moving) {
    // Knot 0 holds every knot's positions: one pass serves all samples, all groups.
    rasterizeStatic(src, part, hc, &part.positions[ch.vLo], -1, ch);
    return;
  }
  const int G = int(shutter.groups().size());
  // Interlaced fields in one pass: a micropolygon is bounded, its samples gathered and tested
  // once for both fields, over the interval that spans them, where that interval lies inside
  // one knot segment (the linear path). Each sample still sees the chunks in the same order, so
  // the image is the one the group-by-group loop below makes.
  if (G > 1 && opt.groupsTogether && std::all_of(groupPresent.begin(), groupPresent.end(), [](uint8_t p) { return p != 0; })) {
    bool instant = false;
    for (int g = 0; g < G; ++g) instant |= shutter.instantaneous(g);
    if (!instant) {
      const MovingTimes& together = timesFor(src, entry.schedule, knots, -1);
      if (together.linearPath && rasterizeMoving(together, part, knots, hc, ch)) return;
    }
  }
  for (int g = 0; g < G; ++g) {
    if (!groupPresent[size_t(g)]) continue;
    if (shutter.instantaneous(g)) {
      // A zero-length shutter: the exact instantaneous image, no time sampling.
      const double tau = shutter.groups()[size_t(g)].open - double(src.frame);
      instantPos.resize(ch.vHi - ch.vLo + 1);
      positionsAt(part, knots, ch.vLo, ch.vHi - ch.vLo + 1, tau, instantPos.data());
      rasterizeStatic(src, part, hc, instantPos.data(), G > 1 ? g : -1, ch);
    } else {
      rasterizeMoving(timesFor(src, entry.schedule, knots, g), part, knots, hc, ch);
    }
  }
}

AovLayout::AovLayout(const std::vector<AovChannel>& aovs) {
  for (const auto& ch : aovs) {
    floatBase.push_back(ch.isUInt ? -1 : floatCount);
    uintBase.push_back(ch.isUInt ? uintCount : -1);
    (ch.isUInt ? uintCount : floatCount) += ch.isUInt ? 1 : ch.components;
  }
}

BucketRasterizer::BucketRasterizer(const SamplePattern& pattern, const ShutterModel& shutter, const View& view, const std::vector<AovChannel>& aovs,
                                   const RasterOptions& options)
    : impl_(std::make_unique<Impl>(pattern, shutter, view, aovs, options)) {
  const AovLayout layout(aovs);
  if (layout.floatCount > 64 || layout.uintCount > 16) fail("--aov", "too many output variables (at most 64 float components and 16 ids)");
}
BucketRasterizer::~BucketRasterizer() = default;
void BucketRasterizer::begin(int x0, int y0, int w, int h) { impl_->begin(x0, y0, w, h); }
double BucketRasterizer::earliestTime() const { return impl_->tMin; }
double BucketRasterizer::latestTime() const { return impl_->tMax; }
void BucketRasterizer::add(const Source& source, const TileEntry& entry, const TilePart& part) { impl_->add(source, entry, part); }
void BucketRasterizer::rasterizeQueued() { impl_->rasterizeQueued(); }
const ResolvedSamples& BucketRasterizer::resolve() {
  if (!impl_->chunks.empty()) impl_->rasterizeQueued();
  return impl_->resolve(*impl_);
}
void BucketRasterizer::setVolumes(VolumeTracer* tracer, double deepSliceRatio) {
  impl_->volumes = tracer;
  impl_->volumeSliceRatio = deepSliceRatio;
}
void BucketRasterizer::visitFragments(const std::function<void(size_t, const SampleFragment*, size_t)>& fn) { impl_->visitFragments(*impl_, fn); }
const RasterStats& BucketRasterizer::stats() const { return impl_->stats; }

}  // namespace reshutter::resample
