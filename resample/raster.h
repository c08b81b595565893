// The bucket rasterizer: takes the samples of one bucket (plus the filter margin) and the tile
// parts whose bounds touch it, and finds every sample each micropolygon covers. From bucket to hit:
//
//  1. begin(): the region's samples, stratum-major, with each stratum's time range (bucket_samples.h).
//  2. add(): each part is cut into chunks of 64 micropolygons with their nearest depth (raster.cpp).
//  3. rasterizeQueued(): chunks drawn nearest first; each goes to one path (raster.cpp rasterizeChunk):
//     - static (raster_static.cpp): parts that do not move, still chunks, exact instants;
//     - linear (raster_linear.cpp): a moving chunk whose interval lies in one knot segment - each
//       micropolygon's box lerped between the interval's ends; runs that move together gather once;
//       interlaced fields inside one segment are drawn together, each field's strata gathered from its rows;
//     - moving (raster_moving.cpp): other moving chunks, bounded per time stratum;
//     - lens (raster_lens.cpp): with depth of field, every chunk, queued and then drawn by depth
//       layer against the samples sorted by their lens-sheared positions.
//  4. Gather (gather.h): the samples inside a micropolygon's box at their own time, not yet hidden
//     by a nearer opaque surface (the early depth test: exact, it changes no bit).
//  5. Coverage (coverage.h): the exact edge-function test of each candidate at its time - the
//     scalar reference or the vector kernels (simd.h: AVX2, AVX-512) - giving barycentrics and depth.
//  6. Hit (hit_buffer.h): nearest opaque surface per sample, transparent fragments in front of it;
//     resolve() composites front to back, visitFragments() hands deep output the fragment lists.
// raster_impl.h holds the state those files share.
#pragma once

#include <cstdint>
#include <functional>
#include <memory>
#include <vector>

#include <glm/vec3.hpp>

#include "resample/filter.h"
#include "resample/sampling.h"
#include "resample/shutter.h"
#include "resample/volume.h"
#include "store/model.h"
#include "store/reader.h"

namespace reshutter::resample {

/// The output camera's projection as the rasterizer needs it.
struct View {
  double ax = 1, bx = 0, ay = 1, by = 0;  // raster = a·(x/z) + b (perspective) or a·x + b
  bool perspective = true;
  float nearClip = 1e-4f, farClip = 1e30f;
  /// A thin lens (depth of field): a sample at lens point L (camera space, |L| <= lensRadius) sees
  /// camera-space point P where the pinhole sees P + L (P.z / focalDistance - 1), i.e. displaced
  /// on the raster by a L (1 / focalDistance - 1 / P.z). Radius 0: the pinhole.
  double lensRadius = 0, focalDistance = 1;
  bool lens() const { return lensRadius > 0; }
};

/// One store contributing to the render: its micropolygons cover [frame + open, frame + close]
/// in absolute frames (neighbouring frames' stores for intervals that cross frame boundaries).
struct Source {
  std::shared_ptr<const store::StoreReader> store;
  int64_t frame = 0;
  /// Another store of the render starts where this one ends (whole-frame stores of consecutive
  /// frames): a time exactly at coverEnd() is that store's - coverage [start, end) - so a surface
  /// is drawn once, not twice, at a frame boundary (render() sets it).
  bool endShared = false;
  /// The knot schedules its entries refer to when they are not the store's own (a store carried
  /// into a camera that moves relative to the one it was shaded from: resample/camera_view.h).
  const std::vector<store::Schedule>* schedules = nullptr;
  const store::Schedule& knots(uint32_t schedule) const { return schedules ? (*schedules)[schedule] : store->meta().schedules[schedule]; }
  double coverStart() const { return double(frame) + store->meta().shutterOpen; }
  double coverEnd() const { return double(frame) + store->meta().shutterClose; }
  /// Whether absolute time t (frames) lies in this store's coverage.
  static bool covers(double t, double start, double end, bool endShared) { return t >= start && (endShared ? t < end : t <= end); }
};

/// An output variable requested on the image, resolved against the stores' schema.
struct AovChannel {
  std::string name;  // attribute name in the store ("N", "s", "Cs") or "id" / "z"
  FilterSpec filter;
  int components = 1;
  bool isUInt = false;   // object ids
  int schemaIndex = -1;  // -1: built-in ("id", "z")
  enum class Builtin { None, ObjectId, Depth } builtin = Builtin::None;
  /// Composited outputs blend every surface with its opacity, like colour; special filters
  /// (min max average zmin zmax) sample only the closest surface above the opacity threshold.
  bool composited() const { return !filter.special(); }
};

/// Where each output variable's values lie among ResolvedSamples::aov (the float components of
/// every non-uint variable, in request order) and aovU (one per uint variable): the one layout the
/// rasterizer writes and the filters and deep output read.
struct AovLayout {
  explicit AovLayout(const std::vector<AovChannel>& aovs);
  std::vector<int> floatBase, uintBase;  // per variable: its first slot (-1 in the other kind's)
  int floatCount = 0, uintCount = 0;
};

struct RasterOptions {
  float opacityThreshold = 0.996f;  // a sample stops once every channel's opacity reaches this
  bool backfaceCull = false;        // knock out back-facing micropolygons unless two-sided
  /// Bound moving micropolygons per time stratum (default) or once over the whole interval. Same
  /// image either way; the accuracy study measures what the per-stratum bounds save.
  bool perStratumBounds = true;
  /// Use the vector inner loops (resample/simd.h) where the CPU has them; off = the
  /// scalar loops. Same image either way.
  bool vectorKernels = true;
  /// With vectorKernels: the AVX-512 gathers and edge test where the CPU has them (else AVX2).
  /// Same image either way.
  bool avx512Kernels = true;
  /// Keep the object and grid id of each sample's opaque surface for visitFragments() (deep
  /// output); a flat render turns it off to keep the bucket's working set small.
  bool surfaceIds = true;
  /// Occlusion culling: draw nearest first and skip samples already covered by a nearer opaque
  /// surface. Exact (the same image either way); off only to measure what it saves.
  bool occlusionCulling = true;
  /// With vectorKernels: micropolygons that move together gather their samples a chunk at a time
  /// (one gather, sorted into cells) instead of one gather each. The same candidates, hits and
  /// image either way; off only to measure what it saves.
  bool chunkGathers = true;
  /// Interlaced fields: moving micropolygons inside one knot segment are bounded, gathered and
  /// tested once for both fields instead of once per field. The same hits and image either way;
  /// off only to measure what it saves.
  bool groupsTogether = true;
  /// With a lens: the bucket's sample planes pair this many time blocks with N / this many lens
  /// strata (SamplePattern::lensPlanes; 1 = lens strata alone), and the lens path sorts each time
  /// block's samples apart. render() chooses it (lensTimeBlocks() in resampler.h).
  int lensTimeBlocks = 1;
  /// With a lens: the depth layers' width, raster pixels of circle-of-confusion radius (a layer's
  /// micropolygons search up to half of it more each way; a bucket sorts its samples once per
  /// layer). The same in every bucket, so that the draw order is. 0: render() chooses it
  /// (lensLayerWidth() in resampler.h; a rasterizer made directly takes 2).
  float lensLayerWidth = 0.f;
  /// With a lens: each layer's sort visits the samples that can be sheared into a cell some search
  /// of the layer reads (tile marks, and per plane the pixels its lens points can displace there).
  /// Off, it sorts every sample of the region: the same searches find the same samples, and the
  /// image is the same; off only to measure what it saves and to test that.
  bool lensSortReached = true;
  /// Skip drawing the samples' times where they are one per group (an instant) or nothing in the
  /// render reads them (a motion-free render): each sample then takes its row's time at the middle
  /// of the interval and planes follow the sample order. A sample's hits do not depend on its
  /// plane, nor a still surface's on its time, so the image is the same; off only to measure what
  /// it saves.
  bool skipUnreadTimes = true;
  /// Whether the samples draw their times: set by render() from skipUnreadTimes and what the
  /// render reads.
  bool sampleTimes = true;
};

/// Counters for --stats; summed over buckets.
struct RasterStats {
  uint64_t sampleTests = 0, hits = 0, micropolygons = 0, parts = 0, fragments = 0;
  uint64_t staticMicropolygons = 0, transparentParts = 0;
  uint64_t linearMicropolygons = 0;         // moving ones bounded from their interval ends (one knot segment)
  uint64_t chunkCulledMicropolygons = 0;    // moving ones skipped with their whole chunk (its path misses the region)
  uint64_t chunkGatheredMicropolygons = 0;  // linear-path ones whose candidates came from their chunk's one gather
  uint64_t groupsTogetherMicropolygons = 0;  // moving ones drawn for every shutter group (both fields) in one pass
  uint64_t generalHits = 0;                 // hits through the general attribute lookup (output variables, other attribute layouts)
  uint64_t lensMicropolygons = 0;           // drawn on the lens path (depth of field)
  uint64_t lensScanned = 0;                 // samples the lens path's gathers examined (in the cells of their search boxes)
  uint64_t lensLayers = 0;                  // times the lens path sorted a bucket's samples for a layer of depths
  uint64_t lensSparseLayers = 0;            // of those, sorts that left out samples in tiles of cells no search of the layer reaches
  uint64_t lensSortVisited = 0;             // samples the lens path's sorts visited (every sample of the region, or those that can reach a searched tile)
  uint64_t lensCulledMicropolygons = 0;     // lens micropolygons whose search box misses every sample of the bucket
  uint64_t lensSegmentDraws = 0;            // lens draws of moving micropolygons cut at their knots (one per knot segment of a bucket's times)
  uint64_t midIntervalSamples = 0;          // samples laid out at their row's middle time, none drawn (RasterOptions::sampleTimes)
  uint64_t pixelMajorSamples = 0;           // of those, laid out pixel-major (no lens: BucketSamples::pixelMajor)
  void add(const RasterStats& o);
};

/// The resolved samples of one bucket region (interior + margin), ready to be filtered:
/// per sample R G B A Z and the requested AOV components, indexed [pixel * spp + i].
struct ResolvedSamples {
  int x0 = 0, y0 = 0, width = 0, height = 0, spp = 1;
  std::vector<float> r, g, b, a, z;
  std::vector<std::vector<float>> aov;      // per AOV component
  std::vector<std::vector<uint32_t>> aovU;  // per uint AOV
  std::vector<float> aovZ;                  // depth of the surface the single-closest AOVs took (only with AOVs)
};

/// One surface a sample saw, for deep output: fragments come front to back, transparent ones
/// first and the nearest opaque surface last (nothing behind an opaque surface is kept).
/// `aov`/`aovU` point at the fragment's output-variable values in the layout of ResolvedSamples
/// (float components of every non-uint AOV in request order; one uint per uint AOV).
struct SampleFragment {
  float z = 0;
  float c[3] = {0, 0, 0};  // premultiplied colour (zero for matte surfaces)
  float o[3] = {1, 1, 1};  // per-channel opacity
  uint32_t objectId = 0, gridId = 0;
  bool matte = false;
  /// A stretch of volume (objectId kVolumeObjectId): it spans [z, zBack] and belongs to depth
  /// slice `slice` (VolumeSlice), which deep output merges across a pixel's samples.
  bool volume = false;
  int32_t slice = 0;
  float zBack = 0;
  const float* aov = nullptr;
  const uint32_t* aovU = nullptr;
};

class BucketRasterizer {
 public:
  BucketRasterizer(const SamplePattern& pattern, const ShutterModel& shutter, const View& view, const std::vector<AovChannel>& aovs,
                   const RasterOptions& options);
  ~BucketRasterizer();

  /// Prepares the samples of region [x0, x0+w) × [y0, y0+h) (raster pixels).
  void begin(int x0, int y0, int w, int h);
  /// Earliest and latest sample time of the prepared region (for gathering parts).
  double earliestTime() const;
  double latestTime() const;
  /// Queues one decoded part of `source` (entry flags tell which shortcuts apply); it must stay
  /// alive until rasterizeQueued() or resolve().
  void add(const Source& source, const store::TileEntry& entry, const store::TilePart& part);
  /// Rasterizes the queued parts in runs of micropolygons, nearest first, so that occlusion
  /// culling skips most hidden surfaces. Depth ties keep the surface drawn first (store order
  /// among runs of equal nearest depth, given parts queued in store order; through a lens, the
  /// nearer depth layer first, then that order).
  void rasterizeQueued();
  /// Composites each sample's surfaces front to back and returns the region's samples
  /// (rasterizing what is still queued first).
  const ResolvedSamples& resolve();
  /// For deep output, after rasterize(): calls fn(slot, fragments, count) for every sample of the
  /// region (slot = pixel * spp + i, pixel row-major in the region) with the surfaces it saw
  /// front to back, cut after the first that makes it opaque (opacity threshold). Depth ties keep
  /// draw order, so the lists are deterministic.
  void visitFragments(const std::function<void(size_t slot, const SampleFragment* fragments, size_t count)>& fn);
  const RasterStats& stats() const;
  /// Volumes to march each sample's ray through in resolve() and visitFragments() (which cuts
  /// them into depth slices of ratio deepSliceRatio); the tracer must outlive the rasterizer's
  /// use of it (null: none).
  void setVolumes(VolumeTracer* tracer, double deepSliceRatio = 1.01);

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace reshutter::resample
