// Inside the bucket rasterizer (the map is resample/raster.h): the state of one bucket and the
// drawing paths' declarations, which are defined by topic -
//   raster.cpp         the bucket: samples, queue, chunks in depth order, which path draws each
//   raster_static.cpp  the static path (and exact instants): one set of positions for all samples
//   raster_moving.cpp  the moving path: per-stratum time bounds, the exact moving test
//   raster_linear.cpp  the linear path (one knot segment per interval) and its chunk gathers
//   raster_lens.cpp    the lens path: depth of field, still and moving micropolygons alike
//   coverage.h         does a sample hit a micropolygon at a time (scalar reference; kernels)
//   gather.h           which samples a moving box holds (vector kernels)
//   bucket_samples.h   the bucket's samples;  hit_buffer.h  what they saw, and the resolve.
// Only those files include this one.
#pragma once

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <memory>
#include <vector>

#if defined(__SSE2__)
#include <emmintrin.h>
#endif

#include "common/check.h"
#include "resample/bucket_samples.h"
#include "resample/coverage.h"
#include "resample/gather.h"
#include "resample/hit_buffer.h"
#include "resample/raster.h"

namespace reshutter::resample {

/// A run of consecutive micropolygons of one queued part, drawn as a unit in depth order.
struct Chunk {
  float zNear;         // nearest camera depth of any vertex in [vLo, vHi] at any knot (the draw order)
  uint32_t part;       // queue index
  uint32_t m0, m1;     // micropolygons [m0, m1)
  uint32_t vLo, vHi;   // the vertices their corners use lie in [vLo, vHi]
  bool still = false;  // every vertex in [vLo, vHi] is where it is at knot 0 at every knot
};
/// 64 micropolygons are four rows of a 16×16 grid: small enough that depth order is fine-grained,
/// large enough that a chunk's per-vertex set-up is shared.
inline constexpr uint32_t kChunkSize = 64;

using kernels::MovingBox;

// The bucket's samples (BucketSamples) and what they saw (HitBuffer), with the drawing paths and
// their scratch.
struct BucketRasterizer::Impl : BucketSamples, HitBuffer {
  Impl(const SamplePattern& p, const ShutterModel& s, const View& v, const std::vector<AovChannel>& a, const RasterOptions& o);

  View view;
  RasterOptions opt;
  const bool vectorKernels;                        // the vector loops of gather.h / coverage.h (same results as the scalar ones)
  const kernels::Isa isa;                          // with vectorKernels: AVX-512 where the CPU and the options allow
  const kernels::RasterScale rasterScale;          // toRaster() for the edge tests
  const kernels::ProjectionScale projectionScale;  // project() for the projection kernel
  RasterStats stats;                               // HitBuffer counts its hits here too

  // ------------------------------------------------------------------------------------------
  // The bucket (raster.cpp)

  void begin(int rx0, int ry0, int rw, int rh);
  void add(const Source& src, const store::TileEntry& entry, const store::TilePart& part);
  void rasterizeQueued();
  void rasterizeChunk(const Source& src, const store::TileEntry& entry, const store::TilePart& part, const Chunk& ch);

  // Parts queued for rasterizeQueued(), and their chunks of micropolygons.
  struct QueuedPart {
    const Source* src;
    const store::TileEntry* entry;
    const store::TilePart* part;
  };
  std::vector<QueuedPart> queued;
  std::vector<Chunk> chunks;
  std::vector<glm::vec3> instantPos;  // a chunk's vertices at an instantaneous group's time

  // Raster position of a camera-space point; false if it lies before the near plane.
  bool project(const glm::vec3& p, float& x, float& y) const {
    if (view.perspective) {
      if (!(p.z >= view.nearClip)) return false;
      const double iz = 1.0 / double(p.z);  // one division: a bound, widened by pixelRange()'s margin
      x = float(view.ax * (double(p.x) * iz) + view.bx);
      y = float(view.ay * (double(p.y) * iz) + view.by);
    } else {
      x = float(view.ax * p.x + view.bx);
      y = float(view.ay * p.y + view.by);
    }
    return std::isfinite(x) && std::isfinite(y);
  }

  // Occlusion culling: chunks are drawn nearest first (rasterizeQueued), and the gathers drop
  // every sample whose nearest opaque surface so far is no farther than the micropolygon can
  // come (the early depth test): such a hit would change nothing, as equal depths keep the
  // earlier surface. Exact: the image is the same with it off.
  // The depth a micropolygon whose corners are never nearer than zNear cannot hit in front of:
  // a hit's depth is a float blend of corner depths (barycentrics summing to 1 within a few ulp).
  float cullDepth(float zNear) const { return opt.occlusionCulling ? zNear - 1e-5f * std::abs(zNear) : -INFINITY; }

  // The source's coverage in st units, where a render spans several stores.
  struct Coverage {
    bool check;
    double lo, hi;
    bool openEnd = false;  // [lo, hi): the source's end is shared (Source::endShared)
  };

  // Appends to `candidates` (from position n) the samples of strata [s0, s1) and group g (< 0:
  // any) in pixels [px0, px1] × [py0, py1] that lie in `box` at their own time and inside the
  // source's coverage; returns the new count.
  size_t gatherCandidates(int s0, int s1, int g, int px0, int py0, int px1, int py1, const MovingBox& box, const Coverage& cover, float zCull, size_t n);
  // The candidate arrays from entry n on.
  kernels::Candidates candidateList(size_t n = 0) { return kernels::Candidates{candidates.data(), candT.data(), candX.data(), candY.data()}.from(n); }

  // Runs the vector edge test of micropolygon m over the first n candidates and records its hits,
  // exact ties to `scalarTest`. The kernel interpolates the depth from setup.za / setup.zb with
  // the scalar paths' arithmetic: zv_j = za_j + f (zb_j - za_j), z = sum b_j zv_j (for fixed
  // edges f = 0, so zv_j = za_j exactly).
  template <class ScalarTest>
  void recordKernelHits(const HitContext& hc, uint32_t m, const uint32_t* c, const kernels::EdgeTestSetup& setup, const kernels::LinearEdges& edges, size_t n,
                        ScalarTest scalarTest) {
    recordEdgeHits(hc, m, c, kernels::testLinearEdges(isa, setup, edges, n, edgeHits.data()), scalarTest);
  }
  // The first `hits` entries of edgeHits (a vector edge test's list) recorded, the undecided ones
  // through scalarTest(sample index).
  template <class ScalarTest>
  void recordEdgeHits(const HitContext& hc, uint32_t m, const uint32_t* c, size_t hits, ScalarTest scalarTest) {
    for (size_t hi = 0; hi < hits; ++hi) {
      const kernels::EdgeHit& eh = edgeHits[hi];
      const uint32_t idx = candidates[eh.candidate];
      if (eh.undecided) {
        scalarTest(idx);
        continue;
      }
      const float z = eh.z;
      if (!(z >= view.nearClip && z <= view.farClip)) continue;
      const uint32_t tv[3] = {c[0], c[1 + eh.triangle], c[2 + eh.triangle]};  // an index, not a branch: the triangle is a coin toss
      recordHit(hc, idx, m, tv, eh.b, z);
    }
  }

  // One micropolygon's candidates: at most one per pixel and stratum (plus kPad).
  SkewedArray<uint32_t> candidates{28};                // sample indices that pass the box test
  SkewedArray<float> candT{36}, candX{44}, candY{52};  // and their times and positions, for the vector edge test
  std::vector<kernels::EdgeHit> edgeHits;

  // ------------------------------------------------------------------------------------------
  // The static path (raster_static.cpp)

  void rasterizeStatic(const Source& src, const store::TilePart& part, const HitContext& hc, const glm::vec3* chunkPos, int onlyGroup, const Chunk& ch);
  void rasterizeStaticVector(const store::TilePart& part, const HitContext& hc, const glm::vec3* chunkPos, int onlyGroup, const Chunk& ch);
  void testStatic(const HitContext& hc, uint32_t m, const uint32_t* c, bool tri, const glm::dvec3 E[5], const float zv[4], uint32_t idx);

  std::vector<float> projX, projY;  // per chunk vertex (static) or [(v - vBase) * T + theta] (moving); projX NaN = before the near plane
  std::vector<float> projZ;         // the static path's vertex depths, as the projection kernel writes them (stillAreas() reads them)
  // A chunk's micropolygons' test areas and cull depths (kernels::stillAreas()).
  struct StillScratch {
    static constexpr size_t kRoom = kChunkSize + 8;
    alignas(32) int32_t px0[kRoom], py0[kRoom], px1[kRoom], py1[kRoom];
    alignas(32) float sx0[kRoom], sy0[kRoom], sx1[kRoom], sy1[kRoom], zCull[kRoom];
    alignas(32) uint8_t state[kRoom];
  } stillScratch;

  // ------------------------------------------------------------------------------------------
  // The moving path (raster_moving.cpp)

  // Time mapping of one part's knot schedule for the exact sample tests.
  struct SegmentMap {
    bool twoKnots;
    float fScale, fOffset;  // two knots: segment parameter f = (st + fOffset) * fScale
    double toLocal;         // local time = st + toLocal
  };

  // A group interval [theta0, theta1] that lies inside one knot segment, for the linear path (linearBox()).
  struct LinearInterval {
    float thetaA = 0, invLen = 0;  // u = (st - thetaA) * invLen
    float uErr = 0;                // rounding of u, as a fraction of the interval
  };

  // The moving path's time set-up for one source, knot schedule and shutter group: the same for
  // every part that shares them, so made once per bucket (timesFor()).
  struct MovingTimes {
    const Source* src = nullptr;  // the key: source, schedule, group
    uint32_t schedule = 0;
    int g = 0;
    std::vector<double> thetaTimes;              // distinct local times to project vertices at
    std::vector<int> stratumFirst, stratumLast;  // theta index range per stratum
    std::vector<uint32_t> thetaSeg;              // knot segment of each theta time
    std::vector<float> thetaF;                   // and the parameter inside it
    std::vector<uint32_t> cullTheta;             // theta indices the cull projects at
    SegmentMap seg{};
    Coverage cover{};
    bool linearPath = false;
    LinearInterval li{};
    // Linear path: stratum s's span [u0, u1] in the interval, 0..1, padded to whole vectors; one
    // block of spanStride per group served (group k's at k * spanStride).
    std::vector<float> stratumU0, stratumU1;
    // Shutter groups served: one (g >= 0), or every group at once (g = -1: the fields of an
    // interlaced frame drawn in one pass over the interval that spans them; linear path only).
    int groups = 1;
    size_t spanStride = 0;
    float widestSpan = 0.f;  // the widest stratum span, in u
    const float* spanU0(int k) const { return stratumU0.data() + size_t(k) * spanStride; }
    const float* spanU1(int k) const { return stratumU1.data() + size_t(k) * spanStride; }
    // The shutter group block k serves.
    int groupOf(int k) const { return g >= 0 ? g : k; }
  };
  const MovingTimes& timesFor(const Source& src, uint32_t schedule, const store::Schedule& knots, int g);
  std::vector<std::unique_ptr<MovingTimes>> movingTimes;  // this bucket's

  // What every micropolygon of one chunk shares on the moving path for shutter group g (-1: every
  // group at once, on the linear path only).
  struct MovingPart {
    const store::TilePart& part;
    const store::Schedule& knots;
    const HitContext& hc;
    const MovingTimes& times;
    int g;
    uint32_t nV, vBase;        // the chunk's vertices [vBase, vBase + nV): the per-vertex arrays' index base
    float rx0, ry0, rx1, ry1;  // the region, widened by the projection margin
  };

  bool rasterizeMoving(const MovingTimes& mt, const store::TilePart& part, const store::Schedule& knots, const HitContext& hc, const Chunk& ch);
  void drawMoving(const MovingPart& mp, uint32_t mi);
  void projectVertexPath(const MovingTimes& mt, const store::TilePart& part, uint32_t vBase, uint32_t vi);
  void testCandidates(const MovingPart& mp, uint32_t mi, const uint32_t* c, bool tri, uint8_t flags, size_t n);
  void testCandidatesVector(const MovingPart& mp, uint32_t mi, const uint32_t* c, bool tri, uint8_t flags, size_t n);
  void testCandidate(const MovingPart& mp, uint32_t mi, const uint32_t* c, bool tri, uint8_t flags, uint32_t idx);

  static float perspectiveLag(float za, float zb) { return kernels::perspectiveLag(za, zb); }

  // Per-chunk scratch, indexed by vertex - the chunk's first vertex.
  std::vector<float> projRho;       // [(v - vBase) * T + theta]: perspective lag bound of theta interval (theta, theta+1)
  std::vector<float> depthScratch;  // one vertex's depths at the theta times
  std::vector<float> cullX, cullY;  // [cull time * nV + v - vBase]; cullX NaN = before the near plane
  std::vector<float> cullZ;         // [cull time * nV + v - vBase]: camera depth
  std::vector<EdgeQuad> segEdges;   // [segment * 5 + edge] for the current micropolygon
  std::vector<uint8_t> segReady;
  // Marks every segment's edges unmade, per micropolygon: nearly always one segment, which a
  // store does without std::fill's call to memset (1.75 M calls, 28 M instructions, on the
  // moving bench crop).
  void resetSegments() {
    if (segReady.size() == 1) segReady[0] = 0;
    else std::fill(segReady.begin(), segReady.end(), 0);
  }
  std::vector<uint8_t> vertexStamp;  // [v - vBase]: theta projections computed for this vertex
  std::vector<float> thetaBox;       // current micropolygon's raster box per theta: x0[T] y0[T] x1[T] y1[T]

  // ------------------------------------------------------------------------------------------
  // The lens path (raster_lens.cpp): every micropolygon when the view has a lens

  // What a chunk's micropolygons share on the lens path (kept until the bucket's layers are drawn).
  struct LensChunk {
    const store::TilePart* part;
    const store::Schedule* knots;
    HitContext hc;
    const Source* src;
    const store::TileEntry* entry;
    bool moving;
    uint32_t vBase, nV;
    size_t C;                // its bound times: cullX/Y/Z hold [(cullBase + time) * nV + v - vBase]
    uint32_t cullBase;       // its first bound time (a knot segment's draw: C = 2 of the chunk's cullTimes)
    uint32_t cullTimes;      // the chunk's bound times
    float lensAx, lensAy;    // raster displacement per unit of lens and of k = 1/d - 1/z
    float invD;              // 1 / focal distance
    float kMag;              // the rounding scale of the displacements
    Coverage cover;          // the source's coverage, in st units
    double toLocal;          // local time = st + toLocal
    float thetaA, invLen;    // invLen > 0: one knot segment, the boxes lerp by (st - thetaA) invLen between the two bound times
    float uErr;              // the rounding of that parameter
    uint32_t blockF;         // invLen > 0: lensBlockF[blockF + 2 b], [.. + 1] is time block b's span of the lerp parameter
    float segLo = -INFINITY, segHi = INFINITY;  // the sample times (st) the draw tests: its knot segment's
  };
  // One queued micropolygon: its per-sample box and its layer (INT32_MIN: unbounded, every
  // sample). Its samples' positions sheared by the layer's middle k (kl) lie in the box (over its
  // motion) widened by ex, ey (what its own displacement strays from the layer's) and qm (rounding).
  struct LensDraw {
    uint32_t chunk, m;
    int32_t layer;
    float zCull, kl;
    kernels::LensBox box;
    float ex, ey, qm;
    /// Its search box over lerp parameters [f0, f1] (LensBox::searchBox()).
    void searchBox(float f0, float f1, float q[4]) const { box.searchBox(f0, f1, ex, ey, qm, q); }
  };
  // The cells a layer's samples are sorted into: pixels of the region widened by the shear, once
  // per time block (BucketSamples::lensTimeBlocks), block-major.
  struct LensGrid {
    int x0 = 0, y0 = 0, cols = 0, rows = 0;
    size_t cells = 0;  // per block
  };
  void rasterizeLens(const Source& src, const store::TileEntry& entry, const store::TilePart& part, const HitContext& hc, const Chunk& ch);
  void queueLensDraws(const LensChunk& lc, uint32_t chunk, uint32_t m0, uint32_t m1);
  void sortLensLayer(size_t first, size_t last, float cxl, float cyl);
  void lensPlaneRuns(size_t s, float cxl, float cyl, const LensGrid& g, float rowScale, const std::array<int, 2>* rowSpan);
  void drawLensQueued();
  struct LensSample {  // a candidate: its slot and its copies of the sample's time, position and lens point
    uint32_t slot;
    float t, x, y, u, v;
  };
  void testLens(const LensChunk& lc, const HitContext& hc, uint32_t m, const uint32_t* c, bool tri, uint8_t flags, const LensSample& ls);  // moving
  void lensEdges(const store::TilePart& part, const uint32_t* c, bool tri);
  void drawMovingLens(const LensChunk& lc, const HitContext& hc, const LensDraw& d, const uint32_t* c, bool tri, uint8_t flags, size_t n);
  void testStillLens(const HitContext& hc, uint32_t m, const uint32_t* c, bool tri, uint8_t flags, const LensSample& ls);
  struct StillLensEdges {  // a still micropolygon's raster edges (c[0..2] + Lx c[3..5]) + Ly c[6..8] per edge, and corner depths
    kernels::LinearEdges edges;
    float z[4];
  } stillLens;
  std::vector<double> lensTimes;  // a chunk's bound times (local), in order
  std::vector<uint8_t> segmentBounded;  // [bound time]: every corner projects
  std::vector<uint8_t> segmentTouches;  // [knot segment of a chunk's bound times]: its box reaches the region
  std::vector<LensChunk> lensChunks;
  std::vector<LensDraw> lensDraws;
  std::vector<float> lensDrawFields;  // queueLensDraws()'s kernels::LensDraws, field by field
  std::vector<int32_t> lensDrawLayer;
  std::vector<uint8_t> lensDrawState;
  std::vector<const float*> knotXyz;
  // The lens cells' height in pixels: with time blocks a cell holds N / blocks samples of each
  // pixel, and cells two pixels tall halve the rows a search reads - what the gather's time goes
  // to - for a few more samples examined (bench/RESULTS.md, "Depth of field", thirty-ninth session).
  int lensRowSpan() const { return lensTimeBlocks > 1 ? 2 : 1; }
  std::vector<std::array<float, 6>> timeRange;  // rasterizeLens(): per bound time, x0 y0 x1 y1 of its positions and their depth range
  std::vector<uint32_t> lensOrder;        // lensDraws by layer
  std::vector<uint32_t> lensLayerStart;   // the counting sort's [layer slot]: its first place in lensOrder, its end once the order is made
  std::vector<float> lensBlockF;    // the lerping chunks' time blocks' spans of their lerp parameter
  LensGrid lensGrid;
  std::vector<uint32_t> lensCellStart;  // [cell]: the cell's first sorted sample (sortLensLayer(): the scatter's cursors too)
  std::vector<uint32_t> lensKeptSlot, lensKeptCell;  // the samples a layer's sort keeps, in slot order, and their cells
  std::vector<uint8_t> lensTileUsed;                // [block][tile of kLensTile² cells]: some search of the layer's block reaches it
  std::vector<int32_t> lensTileDiff;                // [block][tile row + 1][tile column + 1]: the marks as a difference array (sortLensLayer())
  std::vector<std::array<int, 2>> lensTileRowSpan;  // [block][tile row]: its first and last marked tile column
  // A draw's search in one time block: cells [c0, c1] × [r0, r1] of the layer's grid (r1 < r0: none).
  struct LensCellRect {
    int c0, r0, c1, r1;
  };
  std::vector<LensCellRect> lensDrawCells;  // [place in the sorted layer][block]: sortLensLayer()'s, for drawLensQueued()
  std::vector<uint32_t> lensRunFirst, lensRunCount;  // a plane's runs of slots that a layer's sort visits
  std::vector<kernels::LensSearch> lensSearches;     // a draw's searches, one per time block
  SkewedArray<uint32_t> lensSortedIndex{4};         // the sorted samples' slots, times, positions and lens points
  SkewedArray<float> lensSortedT{12}, lensSortedX{20}, lensSortedY{28}, lensSortedU{36}, lensSortedV{44};
  SkewedArray<float> candU{60}, candV{2}, candF{10};  // the lens path's candidates' lens points and, for a moving micropolygon's vector test, segment parameters (candidates, candT, candX, candY hold the rest)
  SkewedArray<uint32_t> lensCandPos{18};                // the lens gather's admitted samples: their places in the sorted arrays

  // ------------------------------------------------------------------------------------------
  // The linear path and chunk gathers (raster_linear.cpp)

  // A micropolygon's moving box over the interval (linearBox()), with the depth no hit can come
  // nearer than, the pixel ranges' rounding margin, and the motion and size that choose between
  // shared and per-stratum ranges.
  struct LinearBox {
    MovingBox box;
    float zCull, rangeMargin, motion, size;
  };
  enum class LinearState : uint8_t { Unbounded, Misses, Draw };
  struct ChunkMicropolygon {
    LinearState state;
    LinearBox lb;
    uint32_t run;            // the run of the chunk's micropolygons of one grid it belongs to
    int cx0, cy0, cx1, cy1;  // cells of its compensated box (when its run was gathered); in this order, stored as one vector
  };
  struct ChunkRun {
    uint32_t begin, end;  // micropolygons [begin, end) of the chunk
    bool gathered;        // its micropolygons filter the sorted cells (else each gathers alone)
  };

  bool drawLinearChunk(const MovingPart& mp, const Chunk& ch);
  void prepareLinearVertices(uint32_t nV);
  LinearState linearBox(const MovingPart& mp, const uint32_t* c, int nc, LinearBox& out) const;
  void drawLinear(const MovingPart& mp, uint32_t mi, const uint32_t* c, bool tri, const LinearBox& lb);
  void prepareLinearChunk(const MovingPart& mp, const Chunk& ch);
  void gatherRun(const MovingPart& mp, uint32_t r);
  bool rasterizeLinearInChunk(const MovingPart& mp, uint32_t mi, const Chunk& ch, const uint32_t* c, bool tri);

  // The linear path's per-vertex terms (linearBox()), made once per chunk rather than once per
  // micropolygon corner: ends[] = raster x, y at the interval's two ends; reach[] = |motion| in x
  // and y, perspective lag, |depth change|; depth = nearer end depth; unbounded = before the
  // near plane at an end.
  struct LinearVertex {
    float ends[4], reach[4];
  };
  std::vector<LinearVertex> linearVertex;
  std::vector<float> linearDepth;
  std::vector<uint8_t> linearUnbounded;
  // The linear path a chunk at a time (prepareLinearChunk()): every micropolygon's box and
  // state, and, for a run of micropolygons of one grid that move together, the run's candidates
  // gathered once and sorted by cell of compensated position (gatherRun()).
  std::vector<ChunkMicropolygon> chunkMps;
  std::vector<ChunkRun> chunkRuns;
  std::vector<std::array<float, 4>> compensated;  // per chunk micropolygon, gatherRun()'s compensated box: x0 y0 x1 y1
  uint32_t gatheredRun = ~0u;  // the run whose candidates the sorted arrays hold
  kernels::CellGrid cellGrid{};
  SkewedArray<uint32_t> chunkIndex{20}, sortedIndex{60};
  SkewedArray<float> chunkT{2}, chunkX{10}, chunkY{18}, sortedT{26}, sortedX{34}, sortedY{42};
  std::vector<uint32_t> cellStart;
  std::vector<uint16_t> cellScratch;
};

// Knot segment and parameter for a local time (general schedules; two-knot schedules take a
// precomputed linear map instead).
inline void segmentAt(const store::Schedule& knots, double tau, uint32_t& k, float& f) {
  const uint32_t K = uint32_t(knots.size());
  k = 0;
  if (tau <= knots[0]) {
    f = 0.f;
    return;
  }
  if (tau >= knots[K - 1]) {
    k = K - 2, f = 1.f;
    return;
  }
  while (k + 2 < K && knots[k + 1] <= tau) ++k;
  f = float((tau - knots[k]) / (knots[k + 1] - knots[k]));
}

// Where positionAt() takes a vertex at local time tau from: knot ka lerped to knot kb by f, or
// knot ka itself (kb == ka: before the first knot, after the last, or a still part).
inline void knotsAt(const store::TilePart& part, const store::Schedule& knots, double tau, uint32_t& ka, uint32_t& kb, float& f) {
  const uint32_t K = part.numKnots;
  const bool before = K == 1 || tau <= knots[0], after = !before && tau >= knots[K - 1];
  f = 0.f;
  if (before || after) {
    ka = kb = before ? 0 : K - 1;
    return;
  }
  segmentAt(knots, tau, ka, f);
  kb = ka + 1;
}

// Position of vertex v at local time tau: linear between knots, constant outside them.
inline glm::vec3 positionAt(const store::TilePart& part, const store::Schedule& knots, uint32_t v, double tau) {
  uint32_t ka, kb;
  float f;
  knotsAt(part, knots, tau, ka, kb, f);
  const glm::vec3& a = part.position(ka, v);
  return ka == kb ? a : a + f * (part.position(kb, v) - a);
}

// positionAt() of vertices first .. first + count - 1, into out: every vertex shares the time's
// knot segment and parameter, so they are found once and the lerp runs over the coordinates as
// one array (the same a + f (b - a) per coordinate, four at a time).
inline void positionsAt(const store::TilePart& part, const store::Schedule& knots, uint32_t first, uint32_t count, double tau, glm::vec3* out) {
  uint32_t ka, kb;
  float f;
  knotsAt(part, knots, tau, ka, kb, f);
  if (ka == kb) {
    std::copy_n(&part.position(ka, first), count, out);
    return;
  }
  const float* __restrict a = &part.position(ka, first).x;
  const float* __restrict b = &part.position(kb, first).x;
  float* __restrict o = &out[0].x;
  const size_t n = size_t(count) * 3;
  size_t i = 0;
#if defined(__SSE2__)
  const __m128 f4 = _mm_set1_ps(f);
  for (; i + 4 <= n; i += 4) {
    const __m128 va = _mm_loadu_ps(a + i);
    _mm_storeu_ps(o + i, _mm_add_ps(va, _mm_mul_ps(f4, _mm_sub_ps(_mm_loadu_ps(b + i), va))));
  }
#endif
  for (; i < n; ++i) o[i] = a[i] + f * (b[i] - a[i]);
}

// ------------------------------------------------------------------------------------------
// Gathering a micropolygon's candidates, for the static and moving paths (inline: per micropolygon).

// Appends to `candidates` (from position n) the samples of strata [s0, s1) and group g (< 0:
// any) in pixels [px0, px1] × [py0, py1] that lie in `box` at their own time and inside the
// source's coverage; returns the new count. The scalar loop is branch-free: the in/out pattern is random, so
// branches would mispredict.
inline size_t BucketRasterizer::Impl::gatherCandidates(int s0, int s1, int g, int px0, int py0, int px1, int py1, const MovingBox& box, const Coverage& cover,
                                                       float zCull, size_t n) {
  // The box's samples as rows: each stratum plane's pixel rows, or - pixel-major - each row of
  // the box's pixels as one run of their samples.
  const uint8_t* groups = multiGroup && g >= 0 ? &rowGroup[size_t(py0 - y0)] : nullptr;
  kernels::SampleRows rows{st.data(), sx.data(), sy.data(), 0, 0, 0, py1 - py0 + 1, groups, uint8_t(g), 1, 0, zbuf.data(), zCull};
  if (pixelMajor) {
    CHECK(s0 == 0 && s1 == N, "pixel-major samples are gathered for every stratum at once");
    rows.stride = size_t(w) * size_t(N), rows.first = size_t(py0 - y0) * rows.stride + size_t(px0 - x0) * size_t(N);
    rows.cols = (px1 - px0 + 1) * N, rows.planeStride = sampleSlots;
  } else {
    rows.stride = size_t(w), rows.first = size_t(s0) * PS + size_t(py0 - y0) * w + size_t(px0 - x0);
    rows.cols = px1 - px0 + 1, rows.planes = s1 - s0, rows.planeStride = PS;
  }
  if (vectorKernels && !cover.check) return kernels::gatherInBox(isa, rows, box, candidateList(), n);
  uint32_t* __restrict cand = candidates.data();
  float* __restrict ct = candT.data();
  float* __restrict cx = candX.data();
  float* __restrict cy = candY.data();
  for (int plane = 0; plane < rows.planes; ++plane)
    for (int row = 0; row < rows.rows; ++row) {
      if (groups && groups[row] != g) continue;
      const size_t rowStart = rows.first + size_t(plane) * rows.planeStride + size_t(row) * rows.stride;
      for (int col = 0; col < rows.cols; ++col) {
        const uint32_t idx = uint32_t(rowStart + size_t(col));
        const float t = st[idx];
        const float u = std::min(std::max((t - box.thetaA) * box.invLen, 0.f), 1.f);  // minss/maxss, no branches
        const float x = sx[idx], y = sy[idx];
        bool in = (x >= box.x0 + u * box.dx0) & (x <= box.x1 + u * box.dx1) & (y >= box.y0 + u * box.dy0) & (y <= box.y1 + u * box.dy1);
        if (cover.check) in &= Source::covers(double(t), cover.lo, cover.hi, cover.openEnd);
        in &= zbuf[idx] > zCull;  // the early depth test
        cand[n] = idx, ct[n] = t, cx[n] = x, cy[n] = y;
        n += in;
      }
    }
  return n;
}

// ------------------------------------------------------------------------------------------
// The exact test of a moving micropolygon's candidates, shared by the moving and linear paths;
// inline, as it runs per micropolygon (and, in the scalar loops, per candidate).

// Exact coverage test of micropolygon mi against the first n sample indices in `candidates`.
inline void BucketRasterizer::Impl::testCandidates(const MovingPart& mp, uint32_t mi, const uint32_t* c, bool tri, uint8_t flags, size_t n) {
  stats.sampleTests += n;
  if (vectorKernels && mp.times.seg.twoKnots) {
    testCandidatesVector(mp, mi, c, tri, flags, n);
    return;
  }
  const uint32_t* cand = candidates.data();
  for (size_t ci = 0; ci < n; ++ci) testCandidate(mp, mi, c, tri, flags, cand[ci]);
}

// Two-knot schedules through the vector kernel; the rare exact ties go to testCandidate().
inline void BucketRasterizer::Impl::testCandidatesVector(const MovingPart& mp, uint32_t mi, const uint32_t* c, bool tri, uint8_t flags, size_t n) {
  const store::TilePart& part = mp.part;
  // The scalar linearEdges()' values, four edges at a time (the scalar tie test still makes its own).
  const float* at[4];
  const float* to[4];
  for (int j = 0; j < 4; ++j) {
    const uint32_t v = c[tri && j == 3 ? 2 : j];
    at[j] = &part.position(0, v).x, to[j] = &part.position(1, v).x;
  }
  kernels::LinearEdges edges;
  kernels::linearEdges(isa, at, to, rasterScale, edges);
  kernels::EdgeTestSetup setup{
      candT.data(), candX.data(), candY.data(), mp.times.seg.fOffset, mp.times.seg.fScale, tri, opt.backfaceCull && !(flags & store::kTwoSided)};
  for (int j = 0; j < (tri ? 3 : 4); ++j) setup.za[j] = part.position(0, c[j]).z, setup.zb[j] = part.position(1, c[j]).z;
  recordKernelHits(mp.hc, mi, c, setup, edges, n, [&](uint32_t idx) { testCandidate(mp, mi, c, tri, flags, idx); });
}

// Exact coverage test of micropolygon mi against one sample, in scalar double precision.
inline void BucketRasterizer::Impl::testCandidate(const MovingPart& mp, uint32_t mi, const uint32_t* c, bool tri, uint8_t flags, uint32_t idx) {
  const store::TilePart& part = mp.part;
  const SegmentMap& seg = mp.times.seg;
  const float t = st[idx];
  uint32_t k = 0;
  float f;
  if (seg.twoKnots) f = std::clamp((t + seg.fOffset) * seg.fScale, 0.f, 1.f);
  else segmentAt(mp.knots, double(t) + seg.toLocal, k, f);
  EdgeQuad* q = &segEdges[size_t(k) * 5];
  if (!segReady[k]) {
    const glm::vec3* at[4];
    const glm::vec3* to[4];
    for (int j = 0; j < 4; ++j) {
      const uint32_t v = c[tri && j == 3 ? 2 : j];
      at[j] = &part.position(k, v), to[j] = &part.position(k + 1, v);
    }
    linearEdges(at, to, tri, rasterScale, q);
    segReady[k] = 1;
  }
  int tr;
  float b[3];
  if (!coversMoving(q, tri, opt.backfaceCull && !(flags & store::kTwoSided), sx[idx], sy[idx], f, tr, b)) return;
  float zv[3];
  const uint32_t tv[3] = {c[0], c[tr == 0 ? 1 : 2], c[tr == 0 ? 2 : 3]};
  for (int j = 0; j < 3; ++j) {
    const float za = part.position(k, tv[j]).z, zb = part.position(k + 1, tv[j]).z;
    zv[j] = za + f * (zb - za);
  }
  const float z = b[0] * zv[0] + b[1] * zv[1] + b[2] * zv[2];
  if (!(z >= view.nearClip && z <= view.farClip)) return;
  recordHit(mp.hc, idx, mi, tv, b, z);
}

}  // namespace reshutter::resample
