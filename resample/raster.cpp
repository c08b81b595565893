#include "resample/raster.h"

#include <algorithm>
#include <cmath>
#include <cstring>

#include "common/check.h"
#include "resample/raster_kernels.h"

#if defined(__SSE2__)
#include <emmintrin.h>
#endif

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
  staticMicropolygons += o.staticMicropolygons;
  linearMicropolygons += o.linearMicropolygons;
  chunkCulledMicropolygons += o.chunkCulledMicropolygons;
  chunkGatheredMicropolygons += o.chunkGatheredMicropolygons;
  transparentParts += o.transparentParts;
}

namespace {

// Edge order of a quad: 01 12 23 30 and the diagonal 02. A triangle uses 01 12 02.
constexpr int kEdgeVerts[5][2] = {{0, 1}, {1, 2}, {2, 3}, {3, 0}, {0, 2}};

// Edge functions are evaluated in double precision: for a one-pixel micropolygon the cross
// product of two nearly parallel vertex vectors cancels ~3 digits, and in float that moved edges
// by up to 0.01 px near the image corners (measured against the vertex bounds). Double keeps the
// test exact to ~1e-9 px at scalar cost; the exact-negation argument for shared edges holds
// in any precision.
inline glm::dvec3 cross(const glm::dvec3& a, const glm::dvec3& b) {
  return {a.y * b.z - a.z * b.y, a.z * b.x - a.x * b.z, a.x * b.y - a.y * b.x};
}

// Quadratic coefficients of one edge's cross product over a knot segment: E(f) = e0 + f(e1 + f e2).
struct EdgeQuad {
  glm::dvec3 e0, e1, e2;
  glm::dvec3 at(double f) const { return e0 + f * (e1 + f * e2); }
};

// An edge's value at raster sample (x, y): the edges are kept in raster space (toRaster()), so the
// test reads the samples' own positions and needs no per-sample view rays.
inline double edgeAt(double x, double y, const glm::dvec3& e) { return x * e.x + y * e.y + e.z; }

// A sample exactly on an edge belongs to the triangle for which the orientation-normalised edge
// vector is lexicographically positive; the neighbour sees the exact negation and declines.
inline bool ownsTie(const glm::dvec3& e, bool flip) {
  glm::dvec3 v = flip ? -e : e;
  if (v.x != 0) return v.x > 0;
  if (v.y != 0) return v.y > 0;
  return v.z > 0;
}

constexpr uint8_t kHitOpaque = 1, kHitMatte = 2;  // what resolve() finds at a sample
constexpr size_t kPad = 16;

// A per-sample array whose first element lies `skewLines` cache lines into its allocation. The
// rasterizer reads and writes several per-sample arrays at one sample index; large allocations
// all start at the same offset within a page, so unskewed those elements share one L1 set (64
// sets of 8 ways) and a hit's loads and stores evicted each other.
template <class T>
class SkewedArray {
 public:
  explicit SkewedArray(int skewLines) : skew_(size_t(skewLines) * 64 / sizeof(T)) {}
  void resize(size_t n) {
    storage_.resize(skew_ + n);
    p_ = storage_.data() + skew_;
  }
  void assign(size_t n, T v) {
    storage_.assign(skew_ + n, v);
    p_ = storage_.data() + skew_;
  }
  T* data() { return p_; }
  const T* data() const { return p_; }
  T& operator[](size_t i) { return p_[i]; }
  const T& operator[](size_t i) const { return p_[i]; }

 private:
  size_t skew_;
  std::vector<T> storage_;
  T* p_ = nullptr;
};

// The colour of the nearest opaque surface a sample has seen (its depth is in a separate array,
// the only part a hit must read), and whether that surface is a matte.
struct SurfaceColour {
  float r, g, b;
  uint32_t matte;
};

// A run of consecutive micropolygons of one queued part, drawn as a unit in depth order.
struct Chunk {
  float zNear;         // nearest camera depth of any vertex in [vLo, vHi] at any knot (the draw order)
  uint32_t part;       // queue index
  uint32_t m0, m1;     // micropolygons [m0, m1)
  uint32_t vLo, vHi;   // the vertices their corners use lie in [vLo, vHi]
  bool still = false;  // every vertex in [vLo, vHi] is where it is at knot 0 at every knot
};
// 64 micropolygons are four rows of a 16×16 grid: small enough that depth order is fine-grained,
// large enough that a chunk's per-vertex set-up is shared.
constexpr uint32_t kChunkSize = 64;

struct Fragment {
  float z;
  float c[3];
  float o[3];
  uint32_t objectId, gridId;
  uint32_t seq;
  int32_t next;
  uint32_t aovOffset, aovUOffset;
  uint8_t matte;
};

}  // namespace

struct BucketRasterizer::Impl {
  const SamplePattern& pattern;
  const ShutterModel& shutter;
  View view;
  const std::vector<AovChannel>& aovs;
  RasterOptions opt;
  const int N;
  const bool vectorKernels;  // the AVX2 loops of raster_kernels.h (same results as the scalar ones)
  const kernels::Isa isa;    // with vectorKernels: AVX-512 where the CPU and the options allow
  const double invAx, invAy;  // 1 / view.ax, 1 / view.ay
  const kernels::RasterScale rasterScale;  // toRaster() for the edge kernel
  const kernels::ProjectionScale projectionScale;  // project() for the projection kernel
  int aovFloatCount = 0, aovUIntCount = 0;
  std::vector<int> aovFloatBase, aovUIntBase;  // per AOV channel: first component slot

  // Region.
  int x0 = 0, y0 = 0, w = 0, h = 0, P = 0;
  // Stratum planes are PS >= P samples apart, PS chosen so that a plane is an odd number of cache
  // lines: with P itself (a multiple of 64 lines for the default bucket) every plane's pixel p
  // maps to the same L1 set, and a micropolygon's 16 strata evict each other.
  size_t PS = 0;
  size_t sampleSlots = 0;                     // N * PS: the length of every per-sample array
  SkewedArray<float> sx{0}, sy{8}, st{16};    // stratum-major: [s * PS + p]
  std::vector<uint32_t> idxOf;                // [p * N + i] → s * PS + p (sample i of pixel p lies in stratum s)
  std::vector<uint8_t> rowGroup;              // per region row
  std::vector<uint8_t> groupPresent;
  bool multiGroup = false;                    // more than one shutter group (fields): rows differ
  std::vector<double> stratumLo, stratumHi;   // [g * N + s], absolute frames
  double tMin = 0, tMax = 0;
  // Sample times are stored as float offsets from one base shared by every bucket, so a sample's
  // time (tBase + st) is the same whichever bucket computes it, and precise at any frame number.
  // The base is the whole frame before the earliest time, not the earliest time itself, so a
  // field rendered alone and the same field inside an interlaced frame get bit-identical times.
  double tBase = 0;

  // Per-sample results, indexed like the samples (stratum-major, s * PS + p): a micropolygon's hits
  // then land next to the sample data its tests just read; resolve() reorders them by pixel.
  // The nearest opaque surface per sample: depth INFINITY until one is found, then its colour.
  // Colours are only read where the depth is finite, so they need no clearing per bucket.
  SkewedArray<float> zbuf{24};
  SkewedArray<SurfaceColour> colour{32};
  SurfaceColour discard{};  // where a hit behind the nearest surface writes its colour
  SkewedArray<uint32_t> objectOf{56}, gridOf{4};
  std::vector<float> zAov;       // [component * sampleSlots + sample]
  std::vector<uint32_t> zAovU;   // [component * sampleSlots + sample]
  SkewedArray<int32_t> fragHead{12};
  std::vector<Fragment> frags;
  std::vector<float> fragAov;
  std::vector<uint32_t> fragAovU;
  uint32_t fragSeq = 0;
  bool anyFragments = false;

  ResolvedSamples out;
  RasterStats stats;

  // Parts queued for rasterizeQueued(), and their chunks of micropolygons.
  struct QueuedPart {
    const Source* src;
    const TileEntry* entry;
    const TilePart* part;
  };
  std::vector<QueuedPart> queued;
  std::vector<Chunk> chunks;
  struct MovingTimes;
  std::vector<std::unique_ptr<MovingTimes>> movingTimes;  // this bucket's, see timesFor()
  std::vector<glm::vec3> instantPos;   // a chunk's vertices at an instantaneous group's time

  // Per-chunk scratch, indexed by vertex - the chunk's first vertex.
  std::vector<float> projX, projY;     // [(v - vBase) * T + theta]; projX NaN = before the near plane
  std::vector<float> projRho;          // [(v - vBase) * T + theta]: perspective lag bound of theta interval (theta, theta+1)
  std::vector<float> depthScratch;     // one vertex's depths at the theta times
  SkewedArray<uint32_t> candidates{28};   // sample indices that pass the box test, per micropolygon
  SkewedArray<float> candT{36}, candX{44}, candY{52};  // and their times and positions, for the vector edge test
  std::vector<kernels::EdgeHit> edgeHits;
  std::vector<float> cullZ;            // [cull time * nV + v - vBase]: camera depth
  std::vector<EdgeQuad> segEdges;      // [segment * 5 + edge] for the current micropolygon
  std::vector<uint8_t> segReady;
  std::vector<float> cullX, cullY;     // [cull time * nV + v - vBase]; cullX NaN = before the near plane
  // The linear path's per-vertex terms (linearBox()), made once per chunk rather than once per
  // micropolygon corner: ends[] = raster x, y at the interval's two ends; reach[] = |motion| in x
  // and y, perspective lag, |depth change|; depth = nearer end depth; unbounded = before the
  // near plane at an end.
  struct LinearVertex {
    float ends[4], reach[4];
  };
  std::vector<LinearVertex> linearVertex;
  // The linear path a chunk at a time (prepareLinearChunk()): every micropolygon's box and
  // state, and, for a run of micropolygons of one grid that move together, the run's candidates
  // gathered once and sorted by cell of compensated position (gatherRun()).
  struct ChunkMicropolygon;
  std::vector<ChunkMicropolygon> chunkMps;
  struct ChunkRun {
    uint32_t begin, end;  // micropolygons [begin, end) of the chunk
    bool gathered;        // its micropolygons filter the sorted cells (else each gathers alone)
  };
  std::vector<ChunkRun> chunkRuns;
  uint32_t gatheredRun = ~0u;  // the run whose candidates the sorted arrays hold
  kernels::CellGrid cellGrid{};
  SkewedArray<uint32_t> chunkIndex{20}, sortedIndex{60};
  SkewedArray<float> chunkT{2}, chunkX{10}, chunkY{18}, sortedT{26}, sortedX{34}, sortedY{42};
  std::vector<uint32_t> cellStart;
  std::vector<uint16_t> cellScratch;
  std::vector<float> linearDepth;
  std::vector<uint8_t> linearUnbounded;
  std::vector<uint8_t> vertexStamp;    // [v - vBase]: theta projections computed for this vertex
  std::vector<float> thetaBox;         // current micropolygon's raster box per theta: x0[T] y0[T] x1[T] y1[T]

  Impl(const SamplePattern& p, const ShutterModel& s, const View& v, const std::vector<AovChannel>& a, const RasterOptions& o)
      : pattern(p), shutter(s), view(v), aovs(a), opt(o), N(p.spp()), vectorKernels(o.vectorKernels && kernels::available()),
        isa(o.avx512Kernels && kernels::available(kernels::Isa::Avx512) ? kernels::Isa::Avx512 : kernels::Isa::Avx2),
        invAx(1.0 / v.ax), invAy(1.0 / v.ay), rasterScale{invAx, invAy, v.bx, v.by, v.perspective},
        projectionScale{v.ax, v.bx, v.ay, v.by, v.nearClip, v.perspective},
        tBase(std::floor(s.earliest())) {
    for (const auto& ch : aovs) {
      if (ch.isUInt) {
        aovUIntBase.push_back(aovUIntCount);
        aovFloatBase.push_back(-1);
        aovUIntCount += 1;
      } else {
        aovFloatBase.push_back(aovFloatCount);
        aovUIntBase.push_back(-1);
        aovFloatCount += ch.components;
      }
    }
  }

  void begin(int rx0, int ry0, int rw, int rh) {
    x0 = rx0, y0 = ry0, w = rw, h = rh, P = w * h;
    constexpr size_t kLine = 64 / sizeof(float);
    PS = (size_t(P) + kLine - 1) / kLine * kLine;
    if ((PS / kLine) % 2 == 0) PS += kLine;
    const size_t slots = PS * N;
    sampleSlots = slots;
    // The vector kernels read up to 7 floats past a row's end.
    sx.resize(slots + kPad), sy.resize(slots + kPad), st.resize(slots + kPad);
    idxOf.resize(size_t(P) * N);
    rowGroup.resize(size_t(h));
    const int G = int(shutter.groups().size());
    groupPresent.assign(size_t(G), 0);
    for (int r = 0; r < h; ++r) {
      rowGroup[size_t(r)] = uint8_t(shutter.groupOfRow(y0 + r));
      groupPresent[rowGroup[size_t(r)]] = 1;
    }
    std::vector<uint16_t> stratumOf(static_cast<size_t>(N));
    std::vector<float> u(static_cast<size_t>(N));
    tMin = INFINITY, tMax = -INFINITY;
    // Time range of each stratum over this region's rows (rolling shutter widens it), widened to
    // the samples' stored times: a time rounded to float may leave its stratum's exact range, and
    // a bound that missed it would drop the hit. The widening is taken in the sample loop below.
    stratumLo.assign(size_t(G) * N, 0.0), stratumHi.assign(size_t(G) * N, 0.0);
    for (int g = 0; g < G; ++g)
      for (int s = 0; s < N; ++s) {
        double lo, hi;
        shutter.timeRange(g, double(y0), double(y0 + h), double(s) / N, double(s + 1) / N, lo, hi);
        stratumLo[size_t(g) * N + s] = lo;
        stratumHi[size_t(g) * N + s] = hi;
      }
    for (int py = 0; py < h; ++py)
      for (int px = 0; px < w; ++px) {
        const int p = py * w + px, gx = x0 + px, gy = y0 + py;
        const int pat = pattern.patternOf(gx, gy);
        pattern.times(gx, gy, stratumOf.data(), u.data());
        const int g = rowGroup[size_t(py)];
        // A global box shutter (the usual case): time() is open + u * length for every sample,
        // the same sum, without its per-sample test.
        const ShutterGroup& group = shutter.groups()[size_t(g)];
        const bool globalBox = shutter.rolling().duration == 0.0 && group.shape.isBox();
        const double open = group.open, length = group.length();
        for (int i = 0; i < N; ++i) {
          const size_t idx = size_t(stratumOf[size_t(i)]) * PS + size_t(p);
          glm::vec2 o = pattern.offset(pat, i);
          const float x = float(gx) + o.x, y = float(gy) + o.y;
          sx[idx] = x, sy[idx] = y;
          const double t = globalBox ? open + double(u[size_t(i)]) * length : shutter.time(g, y, u[size_t(i)]);
          st[idx] = float(t - tBase);
          idxOf[size_t(p) * N + i] = uint32_t(idx);
        }
      }
    // The widening, per stratum plane and row: tBase + double(st) rises with st (rounding is
    // monotonic), so the extreme stored times are those of the extreme st, found row by row.
    for (int s = 0; s < N; ++s)
      for (int py = 0; py < h; ++py) {
        const float* row = &st[size_t(s) * PS + size_t(py) * w];
        float lo = row[0], hi = row[0];
        int px = 1;
#if defined(__SSE2__)
        // Four at a time (the compiler will not vectorise a float min without -ffast-math);
        // times are finite and not -0, so the order of the comparisons does not matter.
        __m128 lo4 = _mm_set1_ps(lo), hi4 = lo4;
        for (; px + 4 <= w; px += 4) {
          const __m128 v = _mm_loadu_ps(row + px);
          lo4 = _mm_min_ps(v, lo4), hi4 = _mm_max_ps(v, hi4);
        }
        alignas(16) float l4[4], h4[4];
        _mm_store_ps(l4, lo4), _mm_store_ps(h4, hi4);
        for (int k = 0; k < 4; ++k) lo = std::min(lo, l4[k]), hi = std::max(hi, h4[k]);
#endif
        for (; px < w; ++px) lo = row[px] < lo ? row[px] : lo, hi = row[px] > hi ? row[px] : hi;
        const double tcLo = tBase + double(lo), tcHi = tBase + double(hi);
        const size_t gs = size_t(rowGroup[size_t(py)]) * N + size_t(s);
        stratumLo[gs] = std::min(stratumLo[gs], tcLo), stratumHi[gs] = std::max(stratumHi[gs], tcHi);
        tMin = std::min(tMin, tcLo), tMax = std::max(tMax, tcHi);
      }

    // One micropolygon's candidates: at most one per pixel and stratum, and the kernels write up
    // to 7 entries past the count.
    candidates.resize(slots + kPad), candT.resize(slots + kPad), candX.resize(slots + kPad), candY.resize(slots + kPad);
    edgeHits.resize(slots + kPad);
    for (auto* a : {&chunkIndex, &sortedIndex}) a->resize(slots + kPad);
    for (auto* a : {&chunkT, &chunkX, &chunkY, &sortedT, &sortedX, &sortedY}) a->resize(slots + kPad);
    cellScratch.resize(slots + kPad);
    multiGroup = G > 1;
    zbuf.assign(slots + kPad, INFINITY);  // the gathers' early depth test reads up to 7 past a row's end
    colour.resize(slots);
    if (opt.surfaceIds) objectOf.assign(slots, 0), gridOf.assign(slots, 0);
    zAov.assign(slots * size_t(aovFloatCount), 0.f);
    zAovU.assign(slots * size_t(aovUIntCount), 0u);
    fragHead.assign(slots, -1);
    frags.clear(), fragAov.clear(), fragAovU.clear();
    fragSeq = 0;
    anyFragments = false;
    stats = RasterStats{};
    queued.clear(), chunks.clear(), movingTimes.clear();
  }

  // ------------------------------------------------------------------------------------------
  // Shading a hit

  // Interpolates attribute `ai` for micropolygon m at barycentrics b over triangle verts v.
  static void attrAt(const store::TilePart& part, const store::Schema& schema, int ai, uint32_t m, const uint32_t v[3], const float b[3],
                     float* outv) {
    const auto& decl = schema.attrs[size_t(ai)];
    const auto& arr = part.attrs[size_t(ai)];
    const int nc = store::componentCount(decl.type);
    if (arr.f.empty()) {
      for (int c = 0; c < nc; ++c) outv[c] = 0.f;
      return;
    }
    if (decl.rate == store::AttrRate::Micropolygon) {
      for (int c = 0; c < nc; ++c) outv[c] = arr.f[size_t(m) * nc + c];
      return;
    }
    for (int c = 0; c < nc; ++c)
      outv[c] = b[0] * arr.f[size_t(v[0]) * nc + c] + b[1] * arr.f[size_t(v[1]) * nc + c] + b[2] * arr.f[size_t(v[2]) * nc + c];
  }

  void aovValues(const store::TilePart& part, const store::Schema& schema, uint32_t m, const uint32_t v[3], const float b[3], float z,
                 float* f, uint32_t* u) {
    for (size_t a = 0; a < aovs.size(); ++a) {
      const auto& ch = aovs[a];
      if (ch.isUInt) {
        uint32_t val = 0;
        if (ch.builtin == AovChannel::Builtin::ObjectId) val = part.objectId[m];
        else if (ch.schemaIndex >= 0 && !part.attrs[size_t(ch.schemaIndex)].u.empty()) {
          const auto& arr = part.attrs[size_t(ch.schemaIndex)].u;
          if (schema.attrs[size_t(ch.schemaIndex)].rate == store::AttrRate::Micropolygon) val = arr[m];
          else val = arr[v[b[1] > b[0] ? (b[2] > b[1] ? 2 : 1) : (b[2] > b[0] ? 2 : 0)]];  // nearest vertex
        }
        u[aovUIntBase[a]] = val;
      } else if (ch.builtin == AovChannel::Builtin::Depth) {
        f[aovFloatBase[a]] = z;
      } else {
        attrAt(part, schema, ch.schemaIndex, m, v, b, f + aovFloatBase[a]);
      }
    }
  }

  struct HitContext {
    const store::TilePart* part;
    const store::Schema* schema;
    int ci, oi;
    bool transparentPart;
    // The common case - an opaque part, per-vertex colour, no output variables - takes
    // recordOpaqueHit() with the colour array at hand instead of the general attribute lookup.
    bool opaqueFast = false;
    const float* colour = nullptr;
  };

  HitContext hitContext(const store::StoreMeta& meta, const TileEntry& entry, const TilePart& part) const {
    HitContext hc{&part, &meta.schema, meta.schema.ci(), meta.schema.oi(), (entry.effects & store::kEffectTransparent) != 0};
    if (!hc.transparentPart && !aovFloatCount && !aovUIntCount && hc.ci >= 0) {
      const auto& decl = meta.schema.attrs[size_t(hc.ci)];
      const auto& arr = part.attrs[size_t(hc.ci)].f;
      if (decl.rate == store::AttrRate::Vertex && store::componentCount(decl.type) == 3 && !arr.empty()) hc.opaqueFast = true, hc.colour = arr.data();
    }
    return hc;
  }

  // Records a hit of micropolygon m on a sample (its stratum-major index s * PS + p).
  void recordHit(const HitContext& hc, uint32_t sample, uint32_t m, const uint32_t v[3], const float b[3], float z) {
    if (hc.opaqueFast) recordOpaqueHit(hc, sample, m, v, b, z);
    else recordAnyHit(hc, sample, m, v, b, z);
  }

  // Same values as recordAnyHit() gives an opaque surface (attrAt's arithmetic, in its order).
  inline void recordOpaqueHit(const HitContext& hc, uint32_t sample, uint32_t m, const uint32_t v[3], const float b[3], float z) {
    ++stats.hits;
    const float *c0 = hc.colour + size_t(v[0]) * 3, *c1 = hc.colour + size_t(v[1]) * 3, *c2 = hc.colour + size_t(v[2]) * 3;
    const store::TilePart& part = *hc.part;
    const SurfaceColour c{b[0] * c0[0] + b[1] * c1[0] + b[2] * c2[0], b[0] * c0[1] + b[1] * c1[1] + b[2] * c2[1],
                          b[0] * c0[2] + b[1] * c1[2] + b[2] * c2[2], uint32_t(part.flags[m] & store::kMatte)};
    // No branch: whether a surface is nearer is a coin toss that the predictor loses, so the
    // depth is a min and the colour goes to the sample or, when hidden, to a scratch record.
    // Ties keep the surface drawn first: deterministic by draw order (rasterizeQueued).
    const float old = zbuf[sample];
    const bool nearer = z < old;
    zbuf[sample] = nearer ? z : old;
    *(nearer ? &colour[sample] : &discard) = c;
    if (opt.surfaceIds && nearer) objectOf[sample] = part.objectId[m], gridOf[sample] = part.gridId[m];
  }

  void recordAnyHit(const HitContext& hc, uint32_t sample, uint32_t m, const uint32_t v[3], const float b[3], float z) {
    ++stats.hits;
    const store::TilePart& part = *hc.part;
    const bool matte = part.flags[m] & store::kMatte;
    float o[3] = {1.f, 1.f, 1.f};
    if (hc.transparentPart) attrAt(part, *hc.schema, hc.oi, m, v, b, o);
    const bool opaque = o[0] >= 1.f && o[1] >= 1.f && o[2] >= 1.f;
    if (opaque) {
      if (!(z < zbuf[sample])) return;  // ties keep the surface drawn first (rasterizeQueued)
      float c[3];
      attrAt(part, *hc.schema, hc.ci, m, v, b, c);
      zbuf[sample] = z;
      colour[sample] = {c[0], c[1], c[2], uint32_t(matte)};
      if (opt.surfaceIds) objectOf[sample] = part.objectId[m], gridOf[sample] = part.gridId[m];
      if (aovFloatCount || aovUIntCount) {
        float fv[64];
        uint32_t uv[16];
        aovValues(part, *hc.schema, m, v, b, z, fv, uv);
        for (int c2 = 0; c2 < aovFloatCount; ++c2) zAov[size_t(c2) * sampleSlots + sample] = fv[c2];
        for (int c2 = 0; c2 < aovUIntCount; ++c2) zAovU[size_t(c2) * sampleSlots + sample] = uv[c2];
      }
      return;
    }
    if (!(z < zbuf[sample])) return;  // hidden behind an opaque surface already found
    for (float& x : o) x = std::clamp(x, 0.f, 1.f);
    Fragment f;
    f.z = z;
    attrAt(part, *hc.schema, hc.ci, m, v, b, f.c);
    std::copy(o, o + 3, f.o);
    f.objectId = part.objectId[m];
    f.gridId = part.gridId[m];
    f.seq = fragSeq++;
    f.matte = matte;
    f.next = fragHead[sample];
    f.aovOffset = uint32_t(fragAov.size());
    f.aovUOffset = uint32_t(fragAovU.size());
    if (aovFloatCount || aovUIntCount) {
      float fv[64];
      uint32_t uv[16];
      aovValues(part, *hc.schema, m, v, b, z, fv, uv);
      fragAov.insert(fragAov.end(), fv, fv + aovFloatCount);
      fragAovU.insert(fragAovU.end(), uv, uv + aovUIntCount);
    }
    fragHead[sample] = int32_t(frags.size());
    frags.push_back(f);
    anyFragments = true;
    ++stats.fragments;
  }

  // ------------------------------------------------------------------------------------------
  // Coverage

  // One triangle's coverage from its three edge values, oriented around it, and - for exact
  // zeros only, so they may be computed on demand - its edge vectors vecOf(0..2). On a hit, the
  // perspective-correct barycentrics of its three vertices.
  template <class EdgeVector>
  inline bool triangleCovers(double a0, double a1, double a2, EdgeVector vecOf, uint8_t flags, float bOut[3]) const {
    const double S = a0 + a1 + a2;
    if (S == 0.0 || (opt.backfaceCull && S > 0.0 && !(flags & store::kTwoSided))) return false;
    const bool flip = S < 0.0;
    const bool in0 = a0 == 0.0 ? ownsTie(vecOf(0), flip) : (flip ? a0 < 0.0 : a0 > 0.0);
    const bool in1 = a1 == 0.0 ? ownsTie(vecOf(1), flip) : (flip ? a1 < 0.0 : a1 > 0.0);
    const bool in2 = a2 == 0.0 ? ownsTie(vecOf(2), flip) : (flip ? a2 < 0.0 : a2 > 0.0);
    if (!(in0 && in1 && in2)) return false;
    const double inv = 1.0 / S;
    bOut[0] = float(a0 * inv), bOut[1] = float(a1 * inv), bOut[2] = float(a2 * inv);
    return true;
  }

  // Given the edge values e[5] (edges 01 12 23 30 02) and vectors E[5] at the sample's time,
  // decides coverage: triangle A (p0 p1 p2) first, then B (p0 p2 p3). On a hit, returns which
  // triangle and the perspective-correct barycentrics of its three vertices.
  inline bool inside(const double e[5], const glm::dvec3 E[5], bool triangle, uint8_t flags, int& triOut, float bOut[3]) const {
    triOut = 0;
    if (triangleCovers(e[1], -e[4], e[0], [&](int i) { return i == 0 ? E[1] : i == 1 ? -E[4] : E[0]; }, flags, bOut)) return true;
    triOut = 1;
    return !triangle && triangleCovers(e[2], e[3], e[4], [&](int i) { return E[2 + i]; }, flags, bOut);
  }

  // An edge (the plane through the eye and two vertices, or the line through two orthographic
  // vertices) as a function of raster position: E · (x', y', 1) with x' = (x - bx) / ax equals
  // (E.x / ax) x + (E.y / ay) y + (E.z - bx E.x / ax - by E.y / ay). Every operation is odd in E,
  // so the neighbour's exactly negated edge stays exactly negated (watertight ties), and the
  // edge test then reads only the samples' positions. It is linear, so it commutes with the
  // quadratic time expansion of EdgeQuad.
  glm::dvec3 toRaster(const glm::dvec3& e) const {
    const double ex = e.x * invAx, ey = e.y * invAy;  // reciprocals: 30 divisions per micropolygon otherwise
    return {ex, ey, (e.z - ex * view.bx) - ey * view.by};
  }

  glm::dvec3 homogeneous(const glm::vec3& p) const { return view.perspective ? glm::dvec3(p) : glm::dvec3(p.x, p.y, 1.0); }

  // Raster bounds of a set of camera-space points; false if one lies before the near plane.
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

  // Where to test a micropolygon with raster box (bx0, by0)-(bx1, by1): the pixels its box
  // touches, and the box (widened for float rounding) that each sample must lie in before its
  // edge functions are evaluated. An unbounded micropolygon (a corner before the near plane) is
  // tested everywhere. False when nothing in the region can be covered.
  struct TestArea {
    int px0, py0, px1, py1;
    float sx0 = -INFINITY, sy0 = -INFINITY, sx1 = INFINITY, sy1 = INFINITY;
  };
  bool testArea(bool bounded, float bx0, float by0, float bx1, float by1, TestArea& a) const {
    if (!bounded) {
      a.px0 = x0, a.py0 = y0, a.px1 = x0 + w - 1, a.py1 = y0 + h - 1;
      return true;
    }
    if (!pixelRange(bx0, by0, bx1, by1, a.px0, a.py0, a.px1, a.py1)) return false;
    const float sm = 1e-3f + 1e-6f * std::max(std::max(std::abs(bx0), std::abs(bx1)), std::max(std::abs(by0), std::abs(by1)));
    a.sx0 = bx0 - sm, a.sy0 = by0 - sm, a.sx1 = bx1 + sm, a.sy1 = by1 + sm;
    return true;
  }

  // Pixel range of a raster box, clipped to the region; false if empty.
  bool pixelRange(float bx0, float by0, float bx1, float by1, int& px0, int& py0, int& px1, int& py1) const {
    // A sample at x lies in pixel floor(x); a small margin absorbs float rounding of projections.
    const float mag = std::max(std::max(std::abs(bx0), std::abs(bx1)), std::max(std::abs(by0), std::abs(by1)));
    const float m = 1e-3f + 1e-6f * mag;
    // Clamped into the region first (NaN goes to the low end), so the floor is a plain int cast:
    // std::floor is a libm call on baseline x86-64 and this runs once per stratum.
    auto clampTo = [](float v, float lo, float hi) { return v >= lo ? (v <= hi ? v : hi) : lo; };
    auto floorInt = [](float v) {
      const int i = int(v);
      return i - (float(i) > v);
    };
    px0 = floorInt(clampTo(bx0 - m, float(x0), float(x0 + w)));
    py0 = floorInt(clampTo(by0 - m, float(y0), float(y0 + h)));
    px1 = std::min(x0 + w - 1, floorInt(clampTo(bx1 + m, float(x0 - 1), float(x0 + w))));
    py1 = std::min(y0 + h - 1, floorInt(clampTo(by1 + m, float(y0 - 1), float(y0 + h))));
    return px0 <= px1 && py0 <= py1;
  }

  // ------------------------------------------------------------------------------------------
  // Occlusion culling: chunks are drawn nearest first (rasterizeQueued), and the gathers drop
  // every sample whose nearest opaque surface so far is no farther than the micropolygon can
  // come (the early depth test): such a hit would change nothing, as equal depths keep the
  // earlier surface. Exact: the image is the same with it off.

  // The depth a micropolygon whose corners are never nearer than zNear cannot hit in front of:
  // a hit's depth is a float blend of corner depths (barycentrics summing to 1 within a few ulp).
  float cullDepth(float zNear) const { return opt.occlusionCulling ? zNear - 1e-5f * std::abs(zNear) : -INFINITY; }

  // ------------------------------------------------------------------------------------------
  // Static micropolygons: one set of positions for every sample time.

  // Micropolygons [ch.m0, ch.m1) at the positions chunkPos (the chunk's vertices: vertex v at
  // chunkPos[v - ch.vLo]), for every sample or only group onlyGroup's (>= 0).
  void rasterizeStatic(const Source& src, const TilePart& part, const HitContext& hc, const glm::vec3* chunkPos, int onlyGroup, const Chunk& ch) {
    const double covLo = src.coverStart(), covHi = src.coverEnd();
    const bool checkCover = tMin < covLo || tMax > covHi;
    const uint32_t vBase = ch.vLo, nV = ch.vHi - ch.vLo + 1;
    projX.resize(nV), projY.resize(nV);
    // Each vertex is projected once, not once per micropolygon that shares it (about four).
    for (size_t i = 0; i < nV; ++i)
      if (!project(chunkPos[i], projX[i], projY[i])) projX[i] = NAN;
    // A chunk wholly outside the region (a part's edge beyond the bucket, usually) is dropped
    // whole: its box and margin bound every micropolygon's, so testArea() would reject each.
    if (pointsMissRegion(projX.data(), projY.data(), nV, 1.f)) {
      stats.chunkCulledMicropolygons += ch.m1 - ch.m0;
      return;
    }
    for (uint32_t m = ch.m0; m < ch.m1; ++m) {
      const uint32_t* c = &part.corners[size_t(m) * 4];
      const bool tri = c[3] == kNoCorner;
      const int nc = tri ? 3 : 4;
      // The edges, made only for micropolygons that reach the sample tests (most of a part's miss
      // a given bucket).
      glm::dvec3 E[5];  // set by makeEdges(), not per micropolygon
      auto makeEdges = [&] {
        for (int k = 0; k < 5; ++k)
          E[k] = tri && (k == 2 || k == 3)
                     ? glm::dvec3(0.0)
                     : toRaster(cross(homogeneous(chunkPos[c[kEdgeVerts[k][0]] - vBase]), homogeneous(chunkPos[c[kEdgeVerts[k][1]] - vBase])));
      };
      float zv[4];
      float bx0 = INFINITY, by0 = INFINITY, bx1 = -INFINITY, by1 = -INFINITY;
      bool bounded = true;
      for (int j = 0; j < nc; ++j) {
        const uint32_t v = c[j] - vBase;
        zv[j] = chunkPos[v].z;
        const float x = projX[v], y = projY[v];
        if (std::isnan(x)) bounded = false;
        else bx0 = std::min(bx0, x), by0 = std::min(by0, y), bx1 = std::max(bx1, x), by1 = std::max(by1, y);
      }
      if (tri) zv[3] = zv[2];
      TestArea ta;
      if (!testArea(bounded, bx0, by0, bx1, by1, ta)) continue;
      const int px0 = ta.px0, py0 = ta.py0, px1 = ta.px1, py1 = ta.py1;
      const float sbx0 = ta.sx0, sby0 = ta.sy0, sbx1 = ta.sx1, sby1 = ta.sy1;
      ++stats.staticMicropolygons;
      const float zCull = cullDepth(*std::min_element(zv, zv + nc));
      if (vectorKernels && !checkCover) {
        // Every stratum's samples in the box that pass the early depth test, then the vector
        // edge test with fixed edges.
        const MovingBox box{ta.sx0, 0.f, ta.sx1, 0.f, ta.sy0, 0.f, ta.sy1, 0.f, 0.f, 0.f};
        const size_t n = gatherCandidates(0, N, onlyGroup, px0, py0, px1, py1, box, Coverage{false, 0, 0}, zCull, 0);
        if (!n) continue;
        stats.sampleTests += n;
        // makeEdges()' values, four edges at a time; the scalar tie test makes its own.
        const float* at[4];
        for (int j = 0; j < 4; ++j) at[j] = &chunkPos[c[tri && j == 3 ? 2 : j] - vBase].x;
        kernels::LinearEdges edges;
        kernels::fixedEdges(isa, at, rasterScale, edges);
        kernels::EdgeTestSetup setup{candT.data(), candX.data(), candY.data(), 0.f, 0.f, tri, opt.backfaceCull && !(part.flags[m] & store::kTwoSided), true};
        std::copy(zv, zv + 4, setup.za), std::copy(zv, zv + 4, setup.zb);
        bool edgesMade = false;
        recordKernelHits(hc, m, c, setup, edges, n, [&](uint32_t idx) {
          if (!edgesMade) makeEdges(), edgesMade = true;
          testStatic(hc, m, c, tri, E, zv, idx);
        });
        continue;
      }
      makeEdges();
      for (int py = py0; py <= py1; ++py) {
        if (onlyGroup >= 0 && rowGroup[size_t(py - y0)] != onlyGroup) continue;
        for (int px = px0; px <= px1; ++px) {
          const size_t p = size_t(py - y0) * w + size_t(px - x0);
          for (int s = 0; s < N; ++s) {
            const size_t idx = size_t(s) * PS + p;
            if (sx[idx] < sbx0 || sx[idx] > sbx1 || sy[idx] < sby0 || sy[idx] > sby1) continue;
            if (checkCover && !(tBase + st[idx] >= covLo && tBase + st[idx] <= covHi)) continue;
            if (!(zbuf[idx] > zCull)) continue;  // the early depth test
            ++stats.sampleTests;
            testStatic(hc, m, c, tri, E, zv, uint32_t(idx));
          }
        }
      }
    }
  }

  // Exact coverage test of static micropolygon m (edge vectors E, corner depths zv) against one sample.
  void testStatic(const HitContext& hc, uint32_t m, const uint32_t* c, bool tri, const glm::dvec3 E[5], const float zv[4], uint32_t idx) {
    double e[5] = {0, 0, 0, 0, 0};
    for (int k = 0; k < 5; ++k)
      if (!tri || k == 0 || k == 1 || k == 4) e[k] = edgeAt(sx[idx], sy[idx], E[k]);
    float b[3];
    int t;
    if (!inside(e, E, tri, hc.part->flags[m], t, b)) return;
    const float z = t == 0 ? b[0] * zv[0] + b[1] * zv[1] + b[2] * zv[2] : b[0] * zv[0] + b[1] * zv[2] + b[2] * zv[3];
    if (!(z >= view.nearClip && z <= view.farClip)) return;
    const uint32_t tv[3] = {c[0], c[t == 0 ? 1 : 2], c[t == 0 ? 2 : 3]};
    recordHit(hc, idx, m, tv, b, z);
  }

  // ------------------------------------------------------------------------------------------
  // Moving micropolygons, one shutter group at a time.

  // Position of vertex v at local time tau: linear between knots, constant outside them.
  static glm::vec3 positionAt(const TilePart& part, const store::Schedule& knots, uint32_t v, double tau) {
    const uint32_t K = part.numKnots;
    if (K == 1 || tau <= knots[0]) return part.position(0, v);
    if (tau >= knots[K - 1]) return part.position(K - 1, v);
    uint32_t k = 0;
    while (k + 2 < K && knots[k + 1] <= tau) ++k;
    const float f = float((tau - knots[k]) / (knots[k + 1] - knots[k]));
    const glm::vec3& a = part.position(k, v);
    return a + f * (part.position(k + 1, v) - a);
  }

  // Knot segment and parameter for a local time (general schedules; two-knot schedules take a
  // precomputed linear map instead).
  static void segmentAt(const store::Schedule& knots, double tau, uint32_t& k, float& f) {
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

  // The source's coverage in st units, where a render spans several stores.
  struct Coverage {
    bool check;
    double lo, hi;
  };

  // What every micropolygon of one part shares on the moving path for shutter group g.
  struct MovingPart {
    const TilePart& part;
    const store::Schedule& knots;
    const HitContext& hc;
    const MovingTimes& times;
    int g;
    uint32_t nV, vBase;  // the chunk's vertices [vBase, vBase + nV): the per-vertex arrays' index base
    float rx0, ry0, rx1, ry1;  // the region, widened by the projection margin
  };

  using MovingBox = kernels::MovingBox;

  // How far perspective can make a projected corner stray from its linear schedule between
  // depths za and zb, per pixel of its motion: x(u) = xa + (xb - xa) g(u) with
  // g(u) - u = u (1 - u) (zb - za) / z(u), at most |dz| / (4 z_min). Inside one knot segment.
  static float perspectiveLag(float za, float zb) { return std::abs(zb - za) / (4.f * std::min(za, zb)) * 1.001f; }

  kernels::Candidates candidateList() { return {candidates.data(), candT.data(), candX.data(), candY.data()}; }

  // Appends to `candidates` (from position n) the samples of strata [s0, s1) and group g (< 0:
  // any) in pixels [px0, px1] × [py0, py1] that lie in `box` at their own time and inside the
  // source's coverage; returns the new count. Branch-free: the in/out pattern is random, so
  // branches would mispredict.
  size_t gatherCandidates(int s0, int s1, int g, int px0, int py0, int px1, int py1, const MovingBox& box, const Coverage& cover, float zCull,
                          size_t n) {
    if (vectorKernels && !cover.check) {
      const kernels::SampleRows rows{st.data(), sx.data(), sy.data(), size_t(s0) * PS + size_t(py0 - y0) * w + size_t(px0 - x0), size_t(w),
                                     px1 - px0 + 1, py1 - py0 + 1, multiGroup && g >= 0 ? &rowGroup[size_t(py0 - y0)] : nullptr, uint8_t(g),
                                     s1 - s0, PS, zbuf.data(), zCull};
      return kernels::gatherInBox(isa, rows, box, candidateList(), n);
    }
    uint32_t* __restrict cand = candidates.data();
    float* __restrict ct = candT.data();
    float* __restrict cx = candX.data();
    float* __restrict cy = candY.data();
    for (int s = s0; s < s1; ++s)
    for (int py = py0; py <= py1; ++py) {
      if (multiGroup && g >= 0 && rowGroup[size_t(py - y0)] != g) continue;
      const uint32_t rowBase = uint32_t(size_t(s) * PS + size_t(py - y0) * w - size_t(x0));
      for (int px = px0; px <= px1; ++px) {
        const uint32_t idx = rowBase + uint32_t(px);
        const float t = st[idx];
        const float u = std::min(std::max((t - box.thetaA) * box.invLen, 0.f), 1.f);  // minss/maxss, no branches
        const float x = sx[idx], y = sy[idx];
        bool in = (x >= box.x0 + u * box.dx0) & (x <= box.x1 + u * box.dx1) & (y >= box.y0 + u * box.dy0) & (y <= box.y1 + u * box.dy1);
        if (cover.check) in &= (double(t) >= cover.lo) & (double(t) <= cover.hi);
        in &= zbuf[idx] > zCull;  // the early depth test
        cand[n] = idx, ct[n] = t, cx[n] = x, cy[n] = y;
        n += in;
      }
    }
    return n;
  }

  // The moving path's time set-up for one source, knot schedule and shutter group: the same for
  // every part that shares them, so made once per bucket (timesFor()).
  struct MovingTimes {
    const Source* src = nullptr;  // the key: source, schedule, group
    uint32_t schedule = 0;
    int g = 0;
    std::vector<double> thetaTimes;               // distinct local times to project vertices at
    std::vector<int> stratumFirst, stratumLast;   // theta index range per stratum
    std::vector<uint32_t> thetaSeg;               // knot segment of each theta time
    std::vector<float> thetaF;                    // and the parameter inside it
    std::vector<uint32_t> cullTheta;              // theta indices the cull projects at
    SegmentMap seg{};
    Coverage cover{};
    bool linearPath = false;
    LinearInterval li{};
    std::vector<float> stratumU0, stratumU1;      // linear path: stratum s's span [u0, u1] in the group interval, 0..1, padded to whole vectors
  };

  const MovingTimes& timesFor(const Source& src, uint32_t schedule, const store::Schedule& knots, int g) {
    for (const auto& t : movingTimes)
      if (t->src == &src && t->schedule == schedule && t->g == g) return *t;
    movingTimes.push_back(std::make_unique<MovingTimes>());
    MovingTimes& mt = *movingTimes.back();
    mt.src = &src, mt.schedule = schedule, mt.g = g;
    const uint32_t K = uint32_t(knots.size());
    const double F = double(src.frame);
    const double toLocal = tBase - F;  // local time = st + toLocal
    mt.cover = {tMin < src.coverStart() || tMax > src.coverEnd(), src.coverStart() - tBase, src.coverEnd() - tBase};
    const double* lo = &stratumLo[size_t(g) * N];
    const double* hi = &stratumHi[size_t(g) * N];

    // Distinct local times to project vertices at: strata boundaries and the knots between them.
    auto& thetaTimes = mt.thetaTimes;
    for (int s = 0; s < N; ++s) thetaTimes.push_back(lo[s] - F), thetaTimes.push_back(hi[s] - F);
    for (uint32_t k = 0; k < K; ++k)
      if (knots[k] > lo[0] - F && knots[k] < hi[N - 1] - F) thetaTimes.push_back(knots[k]);
    std::sort(thetaTimes.begin(), thetaTimes.end());
    thetaTimes.erase(std::unique(thetaTimes.begin(), thetaTimes.end()), thetaTimes.end());
    const size_t T = thetaTimes.size();
    mt.stratumFirst.resize(size_t(N)), mt.stratumLast.resize(size_t(N));
    for (int s = 0; s < N; ++s) {
      mt.stratumFirst[size_t(s)] = int(std::lower_bound(thetaTimes.begin(), thetaTimes.end(), lo[s] - F) - thetaTimes.begin());
      mt.stratumLast[size_t(s)] = int(std::upper_bound(thetaTimes.begin(), thetaTimes.end(), hi[s] - F) - thetaTimes.begin()) - 1;
      if (!opt.perStratumBounds) mt.stratumFirst[size_t(s)] = 0, mt.stratumLast[size_t(s)] = int(T) - 1;  // one bound for the interval
    }
    mt.thetaSeg.resize(T), mt.thetaF.resize(T);
    for (size_t ti = 0; ti < T; ++ti) segmentAt(knots, thetaTimes[ti], mt.thetaSeg[ti], mt.thetaF[ti]);

    // Vertices are projected at the group's first and last theta times and at the knots between:
    // within a knot segment a vertex's screen path is straight, so the boxes at those times bound
    // the micropolygon over the whole group interval - a cull, tight for short intervals, before
    // any per-stratum work.
    for (size_t ti = 0; ti < T; ++ti)
      if (ti == 0 || ti + 1 == T || std::binary_search(knots.begin(), knots.end(), thetaTimes[ti])) mt.cullTheta.push_back(uint32_t(ti));
    const size_t C = mt.cullTheta.size();

    // Two-knot schedules (the common case): the segment parameter is a linear map of st.
    const bool twoKnots = K == 2;
    mt.seg = {twoKnots, twoKnots ? float(1.0 / (knots[1] - knots[0])) : 0.f, twoKnots ? float(toLocal - knots[0]) : 0.f, toLocal};

    // The whole group interval inside one knot segment (always, for two-knot schedules): every
    // corner moves along one straight screen line over it, so the two end projections the cull
    // made bound the micropolygon at any time (see linearBox()), with no per-theta work.
    mt.linearPath = opt.perStratumBounds && C == 2 && thetaTimes[0] >= knots[0] && thetaTimes[T - 1] <= knots[K - 1];
    if (mt.linearPath) {
      LinearInterval& li = mt.li;
      const double th0 = thetaTimes[0], th1 = thetaTimes[T - 1], len = th1 - th0;
      li.thetaA = float(th0 - toLocal);
      li.invLen = float(1.0 / len);
      const uint32_t k0 = mt.thetaSeg[0];
      const double knotSpan = K > 1 ? knots[std::min(k0 + 1, K - 1)] - knots[k0] : 0.0;
      // A sample's time and segment parameter are floats: their rounding, as a fraction of the
      // interval, widens the box by that fraction of the micropolygon's motion.
      li.uErr = float(5e-7 * (std::max({1.0, std::abs(th0 - toLocal), std::abs(th1 - toLocal)}) + knotSpan) / len);
      mt.stratumU0.assign(size_t(N + 7) / 8 * 8, 0.f), mt.stratumU1.assign(size_t(N + 7) / 8 * 8, 0.f);
      for (int s = 0; s < N; ++s) {
        mt.stratumU0[size_t(s)] = std::clamp(float((lo[s] - F - th0) / len) - 1e-6f, 0.f, 1.f);
        mt.stratumU1[size_t(s)] = std::clamp(float((hi[s] - F - th0) / len) + 1e-6f, 0.f, 1.f);
      }
    }
    return mt;
  }

  // True when a chunk's raster vertex positions (xs / ys, n entries; a moving chunk's at every cull
  // time) lie wholly outside the region: then so does every micropolygon's path, since within a knot
  // segment each corner moves along the straight screen segment between two cull positions. The
  // margin is twice the one the per-micropolygon culls use for float rounding (the static path's
  // chunks, whose vertices do not move, use the culls' own). A vertex before the near plane (x
  // NaN) keeps the chunk.
  bool pointsMissRegion(const float* xs, const float* ys, size_t n, float scale) const {
    float bx0 = INFINITY, by0 = INFINITY, bx1 = -INFINITY, by1 = -INFINITY;
    bool nan = false;
    for (size_t i = 0; i < n; ++i) {
      const float x = xs[i], y = ys[i];
      nan |= x != x;
      bx0 = std::min(bx0, x), bx1 = std::max(bx1, x), by0 = std::min(by0, y), by1 = std::max(by1, y);
    }
    return !nan && boxMissesRegion(bx0, by0, bx1, by1, scale);
  }

  // True when the raster box [bx0, bx1] × [by0, by1] of float-projected positions lies outside
  // the region by more than `scale` times the culls' rounding margin (1e-3 px plus 1e-6 of the
  // coordinates' magnitude).
  bool boxMissesRegion(float bx0, float by0, float bx1, float by1, float scale) const {
    const float mm = scale * 1e-3f + scale * 1e-6f * std::max(std::max(std::abs(bx0), std::abs(bx1)), std::max(std::abs(by0), std::abs(by1)));
    return bx1 + mm < float(x0) || bx0 - mm >= float(x0 + w) || by1 + mm < float(y0) || by0 - mm >= float(y0 + h);
  }

  // Micropolygons [ch.m0, ch.m1) of a moving part in shutter group mt.g. Per-vertex work covers
  // the chunk's vertices [ch.vLo, ch.vHi] only.
  void rasterizeMoving(const MovingTimes& mt, const TilePart& part, const store::Schedule& knots, const HitContext& hc, const Chunk& ch) {
    const uint32_t K = part.numKnots, vBase = ch.vLo, nV = ch.vHi - ch.vLo + 1;
    const int g = mt.g;
    const auto& thetaTimes = mt.thetaTimes;
    const auto& stratumFirst = mt.stratumFirst;
    const auto& stratumLast = mt.stratumLast;
    const double toLocal = mt.seg.toLocal;
    const Coverage& cover = mt.cover;
    const size_t T = thetaTimes.size(), C = mt.cullTheta.size();
    cullX.resize(C * nV), cullY.resize(C * nV), cullZ.resize(C * nV);
    bool missesRegion;
    if (vectorKernels) {
      // project()'s values four vertices at a time, with the chunk's box.
      bool unbounded = false;
      float bx0 = INFINITY, by0 = INFINITY, bx1 = -INFINITY, by1 = -INFINITY;
      for (size_t ci = 0; ci < C; ++ci) {
        const uint32_t k = mt.thetaSeg[mt.cullTheta[ci]];
        float box[4];
        unbounded |= kernels::projectLerped(isa, &part.position(k, vBase).x, &part.position(k + 1, vBase).x, mt.thetaF[mt.cullTheta[ci]], nV, projectionScale,
                                            &cullX[ci * nV], &cullY[ci * nV], &cullZ[ci * nV], box);
        bx0 = std::min(bx0, box[0]), by0 = std::min(by0, box[1]), bx1 = std::max(bx1, box[2]), by1 = std::max(by1, box[3]);
      }
      missesRegion = !unbounded && boxMissesRegion(bx0, by0, bx1, by1, 2.f);
    } else {
      for (size_t ci = 0; ci < C; ++ci) {
        const uint32_t k = mt.thetaSeg[mt.cullTheta[ci]];
        const float f = mt.thetaF[mt.cullTheta[ci]];
        for (uint32_t i = 0; i < nV; ++i) {
          const glm::vec3& a = part.position(k, vBase + i);
          const glm::vec3 p = a + f * (part.position(k + 1, vBase + i) - a);
          float x, y;
          if (project(p, x, y)) cullX[ci * nV + i] = x, cullY[ci * nV + i] = y;
          else cullX[ci * nV + i] = NAN;
          cullZ[ci * nV + i] = p.z;
        }
      }
      missesRegion = pointsMissRegion(cullX.data(), cullY.data(), C * nV, 2.f);
    }
    if (missesRegion) {
      stats.chunkCulledMicropolygons += ch.m1 - ch.m0;
      return;
    }
    if (mt.linearPath) prepareLinearVertices(nV);
    projX.resize(T * nV), projY.resize(T * nV), projRho.resize(T * nV), depthScratch.resize(T);
    thetaBox.resize(4 * T);
    vertexStamp.assign(nV, 0u);

    const uint32_t segments = K - 1;
    segEdges.resize(size_t(segments) * 5);
    segReady.resize(segments);
    const float m = 1e-3f;
    const float rx0 = float(x0) - m, ry0 = float(y0) - m, rx1 = float(x0 + w) + m, ry1 = float(y0 + h) + m;
    const MovingPart mp{part, knots, hc, mt, g, nV, vBase, rx0, ry0, rx1, ry1};

    if (mt.linearPath) prepareLinearChunk(mp, ch);
    for (uint32_t mi = ch.m0; mi < ch.m1; ++mi) {
      const uint32_t* c = &part.corners[size_t(mi) * 4];
      const bool tri = c[3] == kNoCorner;
      const int nc = tri ? 3 : 4;
      if (mt.linearPath && rasterizeLinearInChunk(mp, mi, ch, c, tri)) continue;
      // Cull against the region over the knots in range.
      float zCull;
      {
        float bx0 = INFINITY, by0 = INFINITY, bx1 = -INFINITY, by1 = -INFINITY;
        bool bounded = true;
        for (size_t ci = 0; ci < C && bounded; ++ci)
          for (int j = 0; j < nc; ++j) {
            const float x = cullX[ci * nV + (c[j] - vBase)];
            if (std::isnan(x)) {
              bounded = false;
              break;
            }
            const float y = cullY[ci * nV + (c[j] - vBase)];
            bx0 = std::min(bx0, x), by0 = std::min(by0, y), bx1 = std::max(bx1, x), by1 = std::max(by1, y);
          }
        if (bounded && boxMissesRegion(bx0, by0, bx1, by1, 1.f)) continue;
        // The nearest depth over the whole path (depths are linear between the cull times too).
        float zNear = INFINITY;
        for (size_t ci = 0; ci < C; ++ci)
          for (int j = 0; j < nc; ++j) zNear = std::min(zNear, cullZ[ci * nV + (c[j] - vBase)]);
        zCull = cullDepth(zNear);
      }
      // Corner projections at the strata boundaries, computed once per vertex. Vertex-major and
      // branch-free per knot segment so the compiler vectorises it: this is the per-micropolygon
      // cost that remains when the shutter (and so the number of sample tests) shrinks.
      for (int j = 0; j < nc; ++j) {
        const uint32_t v = c[j] - vBase;
        if (vertexStamp[v]) continue;
        vertexStamp[v] = 1;
        projectVertexPath(mt, part, vBase, v);
      }
      std::fill(segReady.begin(), segReady.end(), 0);
      const uint8_t flags = part.flags[mi];

      // The micropolygon's raster box at every theta time (min/max over its corners), in
      // straight vectorisable loops; a NaN anywhere (a corner before the near plane) makes the
      // whole path unbounded. Per stratum the box is then the union over its few theta times, so
      // the strata that miss this region (most of them, for fast motion) cost a handful of loads.
      bool pathBounded = true;
      {
        float* __restrict tx0 = thetaBox.data();
        float* __restrict ty0 = tx0 + T;
        float* __restrict tx1 = ty0 + T;
        float* __restrict ty1 = tx1 + T;
        const float* xa = &projX[size_t(c[0] - vBase) * T];
        const float* ya = &projY[size_t(c[0] - vBase) * T];
        int nanCount = 0;
        for (size_t ti = 0; ti < T; ++ti) tx0[ti] = tx1[ti] = xa[ti], ty0[ti] = ty1[ti] = ya[ti], nanCount += xa[ti] != xa[ti];
        for (int j = 1; j < nc; ++j) {
          const float* xs = &projX[size_t(c[j] - vBase) * T];
          const float* ys = &projY[size_t(c[j] - vBase) * T];
          for (size_t ti = 0; ti < T; ++ti) {
            tx0[ti] = std::min(tx0[ti], xs[ti]), tx1[ti] = std::max(tx1[ti], xs[ti]);
            ty0[ti] = std::min(ty0[ti], ys[ti]), ty1[ti] = std::max(ty1[ti], ys[ti]);
            nanCount += xs[ti] != xs[ti];
          }
        }
        pathBounded = nanCount == 0;
      }
      const float* tx0 = thetaBox.data();
      const float* ty0 = tx0 + T;
      const float* tx1 = ty0 + T;
      const float* ty1 = tx1 + T;
      for (int s = 0; s < N; ++s) {
        const int first = stratumFirst[size_t(s)], last = stratumLast[size_t(s)];
        float bx0 = INFINITY, by0 = INFINITY, bx1 = -INFINITY, by1 = -INFINITY;
        const bool bounded = pathBounded;
        if (bounded) {
          for (int ti = first; ti <= last; ++ti)
            bx0 = std::min(bx0, tx0[ti]), by0 = std::min(by0, ty0[ti]), bx1 = std::max(bx1, tx1[ti]), by1 = std::max(by1, ty1[ti]);
          const float mm = 1e-6f * std::max(std::max(std::abs(bx0), std::abs(bx1)), std::max(std::abs(by0), std::abs(by1)));
          if (bx1 + mm < rx0 || bx0 - mm >= rx1 || by1 + mm < ry0 || by0 - mm >= ry1) continue;  // pixelRange()'s margin
        }
        TestArea ta;
        if (!testArea(bounded, bx0, by0, bx1, by1, ta)) continue;
        // One theta interval inside one knot segment: each corner moves along a straight screen
        // line, so the box at time u is the lerp of the boxes at the interval's ends (min of
        // lerps >= lerp of mins), widened by the perspective lag and for float rounding; each
        // sample is tested against the box at its own time. Otherwise the stratum's fixed box.
        float mx = INFINITY, my = INFINITY;
        if (bounded && last == first + 1) {
          float rho = 0.f;
          if (view.perspective)
            for (int j = 0; j < nc; ++j) rho = std::max(rho, projRho[size_t(c[j] - vBase) * T + size_t(first)]);
          const float mag = std::max(std::max(std::abs(bx0), std::abs(bx1)), std::max(std::abs(by0), std::abs(by1)));
          mx = 1e-3f + 1e-6f * mag + (rho + 1e-5f) * (bx1 - bx0);
          my = 1e-3f + 1e-6f * mag + (rho + 1e-5f) * (by1 - by0);
        }
        MovingBox box{ta.sx0, 0.f, ta.sx1, 0.f, ta.sy0, 0.f, ta.sy1, 0.f};
        if (std::isfinite(mx) && std::isfinite(my))
          box = {tx0[first] - mx, tx0[last] - tx0[first], tx1[first] + mx, tx1[last] - tx1[first],
                 ty0[first] - my, ty0[last] - ty0[first], ty1[first] + my, ty1[last] - ty1[first],
                 float(thetaTimes[size_t(first)] - toLocal), float(1.0 / (thetaTimes[size_t(last)] - thetaTimes[size_t(first)]))};
        const size_t n = gatherCandidates(s, s + 1, g, ta.px0, ta.py0, ta.px1, ta.py1, box, cover, zCull, 0);
        if (n) testCandidates(mp, mi, c, tri, flags, n);
      }
    }
  }

  // The per-vertex terms of linearBox() for the chunk's nV vertices (cull rows 0 and 1).
  void prepareLinearVertices(uint32_t nV) {
    linearVertex.resize(nV), linearDepth.resize(nV), linearUnbounded.resize(nV);
    for (uint32_t v = 0; v < nV; ++v) {
      const float xa = cullX[v], ya = cullY[v], xb = cullX[nV + v], yb = cullY[nV + v], za = cullZ[v], zb = cullZ[nV + v];
      linearUnbounded[v] = std::isnan(xa) || std::isnan(xb);
      linearVertex[v] = {{xa, ya, xb, yb}, {std::abs(xb - xa), std::abs(yb - ya), view.perspective ? perspectiveLag(za, zb) : 0.f, std::abs(zb - za)}};
      linearDepth[v] = std::min(za, zb);
    }
  }

  // The linear path: a micropolygon over a group interval inside one knot segment, from its
  // corners' raster positions A and B at the interval's ends (cullX/cullY rows 0 and 1). Corner
  // j's raster position at fraction u is x_j(u) = A_j + (B_j - A_j) g_j(u), a straight line in
  // screen space; with perspective g_j(u) - u = u (1 - u) (zB - zA) / z(u), at most |dz| / (4
  // z_min) = rho_j. As min of lerps >= lerp of mins, min_j x_j(u) >= lerp(min_j A_j, min_j B_j, u)
  // - max_j rho_j |B_j - A_j|: the box at any time is the lerped end boxes widened by that margin.
  // Each stratum tests only its samples inside the box at the sample's own time.
  //
  // linearBox() makes that box (with the depth no hit can come nearer than, the pixel ranges'
  // rounding margin, and the motion and size that choose between shared and per-stratum
  // ranges), Unbounded when a corner lies before the near plane at either end (the general path
  // handles it); drawLinear() gathers and tests the micropolygon's samples on its own, and
  // rasterizeLinearInChunk() through its run's chunk gather.
  struct LinearBox {
    MovingBox box;
    float zCull, rangeMargin, motion, size;
  };
  enum class LinearState : uint8_t { Unbounded, Misses, Draw };
  LinearState linearBox(const MovingPart& mp, const uint32_t* c, int nc, LinearBox& out) const {
    const LinearInterval& li = mp.times.li;
    // Min and max of the corners' end positions and max of their reach, four lanes each.
    alignas(16) float lo[4], hi[4], reach[4];
    float zNear, mag;
    {
      const uint32_t v = c[0] - mp.vBase;
      bool unbounded = linearUnbounded[v];
      zNear = linearDepth[v];
      const LinearVertex& first = linearVertex[v];
#if defined(__SSE2__)
      // std::min(a, b) is _mm_min_ps(b, a) and std::max(a, b) is _mm_max_ps(b, a), NaN and
      // signed zeros included.
      __m128 l = _mm_loadu_ps(first.ends), u = l, r = _mm_loadu_ps(first.reach);
      for (int j = 1; j < nc; ++j) {
        const uint32_t vj = c[j] - mp.vBase;
        const LinearVertex& lv = linearVertex[vj];
        unbounded |= linearUnbounded[vj];
        zNear = std::min(zNear, linearDepth[vj]);
        const __m128 e = _mm_loadu_ps(lv.ends);
        l = _mm_min_ps(e, l), u = _mm_max_ps(e, u), r = _mm_max_ps(_mm_loadu_ps(lv.reach), r);
      }
      if (unbounded) return LinearState::Unbounded;
      _mm_store_ps(lo, l), _mm_store_ps(hi, u), _mm_store_ps(reach, r);
      // The largest magnitude of the eight box ends (max is exact: any order gives the same).
      const __m128 absMask = _mm_castsi128_ps(_mm_set1_epi32(0x7FFFFFFF));
      __m128 m = _mm_max_ps(_mm_and_ps(l, absMask), _mm_and_ps(u, absMask));
      m = _mm_max_ps(m, _mm_shuffle_ps(m, m, _MM_SHUFFLE(1, 0, 3, 2)));
      m = _mm_max_ps(m, _mm_shuffle_ps(m, m, _MM_SHUFFLE(2, 3, 0, 1)));
      mag = _mm_cvtss_f32(m);
#else
      for (int k = 0; k < 4; ++k) lo[k] = hi[k] = first.ends[k], reach[k] = first.reach[k];
      for (int j = 1; j < nc; ++j) {
        const uint32_t vj = c[j] - mp.vBase;
        const LinearVertex& lv = linearVertex[vj];
        unbounded |= linearUnbounded[vj];
        zNear = std::min(zNear, linearDepth[vj]);
        for (int k = 0; k < 4; ++k) lo[k] = std::min(lo[k], lv.ends[k]), hi[k] = std::max(hi[k], lv.ends[k]), reach[k] = std::max(reach[k], lv.reach[k]);
      }
      if (unbounded) return LinearState::Unbounded;
      mag = 0.f;
      for (int k = 0; k < 4; ++k) mag = std::max({mag, std::abs(lo[k]), std::abs(hi[k])});
#endif
    }
    const float ax0 = lo[0], ay0 = lo[1], bx0 = lo[2], by0 = lo[3], ax1 = hi[0], ay1 = hi[1], bx1 = hi[2], by1 = hi[3];
    const float mvx = reach[0], mvy = reach[1], rho = reach[2], dz = reach[3];
    const float slack = rho + li.uErr + 1e-5f;
    const float mx = 1e-3f + 1e-6f * mag + slack * mvx, my = 1e-3f + 1e-6f * mag + slack * mvy;
    if (!(std::isfinite(mx) && std::isfinite(my))) return LinearState::Unbounded;
    // The whole interval first: most parts' micropolygons miss a given bucket.
    if (std::max(ax1, bx1) + mx < mp.rx0 || std::min(ax0, bx0) - mx >= mp.rx1 || std::max(ay1, by1) + my < mp.ry0 ||
        std::min(ay0, by0) - my >= mp.ry1)
      return LinearState::Misses;
    // Depths are linear over the interval; a sample's rounded time may stray li.uErr of it.
    out.zCull = cullDepth(zNear) - li.uErr * dz;
    out.box = MovingBox{ax0 - mx, bx0 - ax0, ax1 + mx, bx1 - ax1, ay0 - my, by0 - ay0, ay1 + my, by1 - ay1, li.thetaA, li.invLen};
    out.rangeMargin = 1e-3f + 1e-6f * mag;
    out.motion = std::max(mvx, mvy), out.size = std::max(std::max(ax1 - ax0, ay1 - ay0), 1.f);
    return LinearState::Draw;
  }

  void drawLinear(const MovingPart& mp, uint32_t mi, const uint32_t* c, bool tri, const LinearBox& lb) {
    ++stats.linearMicropolygons;
    const float zCull = lb.zCull;
    const MovingBox& box = lb.box;
    std::fill(segReady.begin(), segReady.end(), 0);
    const uint8_t flags = mp.part.flags[mi];
    // Strata share one pixel range while their combined motion stays under half the
    // micropolygon's size (at least half a pixel): short intervals and slow motion then pay the
    // per-bound set-up once for several strata instead of once each (the samples' own-time box
    // test below keeps the candidates as tight either way).
    const float motion = lb.motion, size = lb.size;
    const int span = motion > 0.f ? std::clamp(int(0.5f * size * float(N) / motion), 1, N) : N;
    size_t n = 0;
    if (span < N && vectorKernels && !mp.times.cover.check && N <= 64) {
      // Every stratum's pixel range and samples in one vector pass: cheaper than the shared
      // ranges below whenever the micropolygon moves at all (the ranges are computed eight at a
      // time; cachegrind: -3 % on a quarter shutter), though not when one range serves all strata.
      const kernels::SampleRows region{st.data(), sx.data(), sy.data(), 0, size_t(w), w, h, multiGroup ? rowGroup.data() : nullptr,
                                       uint8_t(mp.g), N, PS, zbuf.data(), zCull};
      const kernels::StrataSpans spans{mp.times.stratumU0.data(), mp.times.stratumU1.data(), N, x0, y0, w, h, lb.rangeMargin};
      n = kernels::gatherStrata(isa, region, spans, box, candidateList());
      if (n) testCandidates(mp, mi, c, tri, flags, n);
      return;
    }
    for (int s0 = 0; s0 < N; s0 += span) {
      const int s1 = std::min(N, s0 + span);  // strata [s0, s1)
      const float u0 = mp.times.stratumU0[size_t(s0)], u1 = mp.times.stratumU1[size_t(s1 - 1)];
      const float sx0 = std::min(box.x0 + u0 * box.dx0, box.x0 + u1 * box.dx0), sx1 = std::max(box.x1 + u0 * box.dx1, box.x1 + u1 * box.dx1);
      const float sy0 = std::min(box.y0 + u0 * box.dy0, box.y0 + u1 * box.dy0), sy1 = std::max(box.y1 + u0 * box.dy1, box.y1 + u1 * box.dy1);
      if (sx1 < mp.rx0 || sx0 >= mp.rx1 || sy1 < mp.ry0 || sy0 >= mp.ry1) continue;
      int px0, py0, px1, py1;
      if (!pixelRange(sx0, sy0, sx1, sy1, px0, py0, px1, py1)) continue;
      if (multiGroup) {  // fields: trim to this group's rows (a one-row range is often the other field's)
        while (py0 <= py1 && rowGroup[size_t(py0 - y0)] != mp.g) ++py0;
        while (py1 >= py0 && rowGroup[size_t(py1 - y0)] != mp.g) --py1;
        if (py0 > py1) continue;
      }
      n = gatherCandidates(s0, s1, mp.g, px0, py0, px1, py1, box, mp.times.cover, zCull, n);
    }
    // Every stratum's candidates tested together: the vector test fills its lanes.
    if (n) testCandidates(mp, mi, c, tri, flags, n);
  }

  struct ChunkMicropolygon {
    LinearState state;
    LinearBox lb;
    uint32_t run;            // the run of the chunk's micropolygons of one grid it belongs to
    int cx0, cy0, cx1, cy1;  // cells of its compensated box (when its run was gathered)
  };

  // The linear path's boxes for the chunk's micropolygons, and - for each run of them from one
  // grid, which moves together - one gather for the run. A micropolygon's own gather reads every
  // sample of its strata's pixel ranges (a one-pixel micropolygon moving a pixel and a half per
  // stratum: ~110 of them for ~6 candidates), and its neighbours read most of them again; the
  // run reads each once: the samples inside the run's moving box (the union of its
  // micropolygons' - min of lerps >= lerp of mins, as in linearBox()) at their own time
  // that pass the loosest of their early depth tests. They are then sorted into cells of
  // compensated position (the sample's position less its time times a reference motion), where
  // each micropolygon's box over the whole interval is about its own size: a micropolygon's
  // candidates are those of the few cells its compensated box touches that pass its own box and
  // depth tests (filterCandidates()) - exactly the samples its own gather would have found, so
  // the hits, the counts and the image are the same. (Depths only fall, so gathering the run
  // before its micropolygons draw keeps every sample any of them would keep.)
  void prepareLinearChunk(const MovingPart& mp, const Chunk& ch) {
    const uint32_t count = ch.m1 - ch.m0;
    chunkMps.resize(count);
    chunkRuns.clear();
    gatheredRun = ~0u;
    for (uint32_t i = 0; i < count; ++i) {
      const uint32_t m = ch.m0 + i;
      const uint32_t* c = &mp.part.corners[size_t(m) * 4];
      ChunkMicropolygon& cm = chunkMps[i];
      cm.state = linearBox(mp, c, c[3] == kNoCorner ? 3 : 4, cm.lb);
      if (i == 0 || mp.part.gridId[m] != mp.part.gridId[m - 1]) chunkRuns.push_back({i, i, false});
      cm.run = uint32_t(chunkRuns.size() - 1);
      chunkRuns.back().end = i + 1;
    }
  }

  // Gathers run r's candidates, when its micropolygons move together enough to pay.
  void gatherRun(const MovingPart& mp, uint32_t r) {
    ChunkRun& run = chunkRuns[r];
    gatheredRun = r;
    run.gathered = false;
    float x0a = INFINITY, x0b = INFINITY, x1a = -INFINITY, x1b = -INFINITY, y0a = INFINITY, y0b = INFINITY, y1a = -INFINITY, y1b = -INFINITY;
    float zCull = INFINITY, margin = 0.f, spread = 0.f;
    uint32_t drawn = 0;
    for (uint32_t i = run.begin; i < run.end; ++i) {
      const ChunkMicropolygon& cm = chunkMps[i];
      if (cm.state != LinearState::Draw) continue;
      const MovingBox& b = cm.lb.box;
      ++drawn;
      x0a = std::min(x0a, b.x0), x0b = std::min(x0b, b.x0 + b.dx0), x1a = std::max(x1a, b.x1), x1b = std::max(x1b, b.x1 + b.dx1);
      y0a = std::min(y0a, b.y0), y0b = std::min(y0b, b.y0 + b.dy0), y1a = std::max(y1a, b.y1), y1b = std::max(y1b, b.y1 + b.dy1);
      zCull = std::min(zCull, cm.lb.zCull), margin = std::max(margin, cm.lb.rangeMargin);
      spread += (b.x1 - b.x0 + 1.f) * (b.y1 - b.y0 + 1.f);
    }
    if (drawn < 4 || !vectorKernels || !opt.chunkGathers || mp.times.cover.check || N > 64) return;
    const float mag = std::max({std::abs(x0a), std::abs(x0b), std::abs(x1a), std::abs(x1b), std::abs(y0a), std::abs(y0b), std::abs(y1a), std::abs(y1b)});
    // Float rounding of the lerps: the run's box must hold every sample any of its
    // micropolygons' boxes holds, as the float tests compute them.
    const float e = 1e-5f + 2e-6f * mag;
    const MovingBox box{x0a - e, x0b - x0a, x1a + e, x1b - x1a, y0a - e, y0b - y0a, y1a + e, y1b - y1a, mp.times.li.thetaA, mp.times.li.invLen};
    // Worth it when the run's box is small next to its micropolygons' boxes together (it is
    // about their union when they move together); else each gathers on its own.
    const float motion = std::max({std::abs(box.dx0), std::abs(box.dx1), std::abs(box.dy0), std::abs(box.dy1)}) / float(N);
    const float runArea = (box.x1 - box.x0 + motion + 1.f) * (box.y1 - box.y0 + motion + 1.f);
    const float alone = spread + float(drawn) * (motion * motion + 2.f * motion);
    if (!(runArea < 0.5f * alone)) return;
    // Compensated boxes: x - u dx stays within [x0 + min(0, dx0 - dx), x1 + max(0, dx1 - dx)] for a
    // sample inside the box at u; cells as large as the largest of them.
    const float dx = 0.5f * (box.dx0 + box.dx1), dy = 0.5f * (box.dy0 + box.dy1);
    const float ec = 1e-5f + 4e-6f * (mag + std::abs(dx) + std::abs(dy));
    float gx0 = INFINITY, gy0 = INFINITY, gx1 = -INFINITY, gy1 = -INFINITY, size = 0.f;
    for (uint32_t i = run.begin; i < run.end; ++i) {
      const ChunkMicropolygon& cm = chunkMps[i];
      if (cm.state != LinearState::Draw) continue;
      const MovingBox& b = cm.lb.box;
      const float bx0 = b.x0 + std::min(0.f, b.dx0 - dx) - ec, bx1 = b.x1 + std::max(0.f, b.dx1 - dx) + ec;
      const float by0 = b.y0 + std::min(0.f, b.dy0 - dy) - ec, by1 = b.y1 + std::max(0.f, b.dy1 - dy) + ec;
      gx0 = std::min(gx0, bx0), gy0 = std::min(gy0, by0), gx1 = std::max(gx1, bx1), gy1 = std::max(gy1, by1);
      size = std::max({size, bx1 - bx0, by1 - by0});
    }
    if (!(size > 0.f) || !std::isfinite(size) || size > 8.f) return;
    const float invSize = 1.f / size;
    const float colsF = std::floor((gx1 - gx0) * invSize) + 1.f, rowsF = std::floor((gy1 - gy0) * invSize) + 1.f;
    if (!(colsF * rowsF <= 4096.f)) return;
    cellGrid = kernels::CellGrid{gx0, gy0, invSize, int(colsF), int(rowsF), dx, dy, box.thetaA, box.invLen};
    // A micropolygon's cells: its compensated box's, computed as sortByCell() places a sample
    // (floor of the offset over the cell size, clamped), so that a sample inside the box lands
    // inside its cell range.
    auto cell = [&](float v, float origin, int cells) { return int(std::min(float(cells - 1), std::max(0.f, std::floor((v - origin) * invSize)))); };
    for (uint32_t i = run.begin; i < run.end; ++i) {
      ChunkMicropolygon& cm = chunkMps[i];
      if (cm.state != LinearState::Draw) continue;
      const MovingBox& b = cm.lb.box;
      cm.cx0 = cell(b.x0 + std::min(0.f, b.dx0 - dx) - ec, gx0, cellGrid.cols), cm.cx1 = cell(b.x1 + std::max(0.f, b.dx1 - dx) + ec, gx0, cellGrid.cols);
      cm.cy0 = cell(b.y0 + std::min(0.f, b.dy0 - dy) - ec, gy0, cellGrid.rows), cm.cy1 = cell(b.y1 + std::max(0.f, b.dy1 - dy) + ec, gy0, cellGrid.rows);
    }
    const kernels::SampleRows region{st.data(), sx.data(), sy.data(), 0, size_t(w), w, h, multiGroup ? rowGroup.data() : nullptr,
                                     uint8_t(mp.g), N, PS, zbuf.data(), zCull};
    const kernels::StrataSpans spans{mp.times.stratumU0.data(), mp.times.stratumU1.data(), N, x0, y0, w, h, margin + e};
    const kernels::Candidates gathered{chunkIndex.data(), chunkT.data(), chunkX.data(), chunkY.data()};
    const size_t n = kernels::gatherStrata(isa, region, spans, box, gathered);
    cellStart.resize(size_t(cellGrid.cols) * size_t(cellGrid.rows) + 1);
    kernels::sortByCell(isa, cellGrid, gathered, n, {sortedIndex.data(), sortedT.data(), sortedX.data(), sortedY.data()}, cellStart.data(), cellScratch.data());
    run.gathered = true;
  }

  // Micropolygon mi of the chunk prepareLinearChunk() prepared, on the linear path: through its
  // run's chunk gather, or on its own (drawLinear()). False (nothing done) when it is unbounded:
  // the general path handles it.
  bool rasterizeLinearInChunk(const MovingPart& mp, uint32_t mi, const Chunk& ch, const uint32_t* c, bool tri) {
    const ChunkMicropolygon& cm = chunkMps[mi - ch.m0];
    if (cm.state == LinearState::Unbounded) return false;
    if (cm.state == LinearState::Misses) return true;
    if (cm.run != gatheredRun) gatherRun(mp, cm.run);
    if (!chunkRuns[cm.run].gathered) {
      drawLinear(mp, mi, c, tri, cm.lb);
      return true;
    }
    ++stats.linearMicropolygons;
    ++stats.chunkGatheredMicropolygons;
    std::fill(segReady.begin(), segReady.end(), 0);
    const kernels::Candidates sorted{sortedIndex.data(), sortedT.data(), sortedX.data(), sortedY.data()};
    size_t n = 0;
    for (int cy = cm.cy0; cy <= cm.cy1; ++cy) {
      const size_t row = size_t(cy) * size_t(cellGrid.cols);
      n = kernels::filterCandidates(isa, sorted, cellStart[row + size_t(cm.cx0)], cellStart[row + size_t(cm.cx1) + 1], cm.lb.box, zbuf.data(), cm.lb.zCull,
                                    candidateList(), n);
    }
    if (n) testCandidates(mp, mi, c, tri, mp.part.flags[mi], n);
    return true;
  }

  // Exact coverage test of micropolygon mi against the first n sample indices in `candidates`.
  void testCandidates(const MovingPart& mp, uint32_t mi, const uint32_t* c, bool tri, uint8_t flags, size_t n) {
    stats.sampleTests += n;
    if (vectorKernels && mp.times.seg.twoKnots) {
      testCandidatesVector(mp, mi, c, tri, flags, n);
      return;
    }
    const uint32_t* cand = candidates.data();
    for (size_t ci = 0; ci < n; ++ci) testCandidate(mp, mi, c, tri, flags, cand[ci]);
  }

  // Two-knot schedules through the vector kernel; the rare exact ties go to testCandidate().
  void testCandidatesVector(const MovingPart& mp, uint32_t mi, const uint32_t* c, bool tri, uint8_t flags, size_t n) {
    const TilePart& part = mp.part;
    // prepareEdges()' values, four edges at a time (the scalar tie test still prepares its own).
    const float* at[4];
    const float* to[4];
    for (int j = 0; j < 4; ++j) {
      const uint32_t v = c[tri && j == 3 ? 2 : j];
      at[j] = &part.position(0, v).x, to[j] = &part.position(1, v).x;
    }
    kernels::LinearEdges edges;
    kernels::linearEdges(isa, at, to, rasterScale, edges);
    kernels::EdgeTestSetup setup{candT.data(), candX.data(), candY.data(), mp.times.seg.fOffset, mp.times.seg.fScale, tri,
                                 opt.backfaceCull && !(flags & store::kTwoSided)};
    for (int j = 0; j < (tri ? 3 : 4); ++j) setup.za[j] = part.position(0, c[j]).z, setup.zb[j] = part.position(1, c[j]).z;
    recordKernelHits(mp.hc, mi, c, setup, edges, n, [&](uint32_t idx) { testCandidate(mp, mi, c, tri, flags, idx); });
  }

  // Runs the vector edge test of micropolygon m over the first n candidates and records its hits,
  // exact ties to `scalarTest`. The kernel interpolates the depth from setup.za / setup.zb with
  // the scalar paths' arithmetic: zv_j = za_j + f (zb_j - za_j), z = sum b_j zv_j (for fixed
  // edges f = 0, so zv_j = za_j exactly).
  template <class ScalarTest>
  void recordKernelHits(const HitContext& hc, uint32_t m, const uint32_t* c, const kernels::EdgeTestSetup& setup, const kernels::LinearEdges& edges,
                        size_t n, ScalarTest scalarTest) {
    const size_t hits = kernels::testLinearEdges(isa, setup, edges, n, edgeHits.data());
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

  // Exact coverage test of micropolygon mi against one sample, in scalar double precision.
  void testCandidate(const MovingPart& mp, uint32_t mi, const uint32_t* c, bool tri, uint8_t flags, uint32_t idx) {
    const TilePart& part = mp.part;
    const SegmentMap& seg = mp.times.seg;
    const float t = st[idx];
    uint32_t k = 0;
    float f;
    if (seg.twoKnots) f = std::clamp((t + seg.fOffset) * seg.fScale, 0.f, 1.f);
    else segmentAt(mp.knots, double(t) + seg.toLocal, k, f);
    EdgeQuad* q = &segEdges[size_t(k) * 5];
    if (!segReady[k]) {
      prepareEdges(part, c, tri, k, q);
      segReady[k] = 1;
    }
    // Triangle A's edges first; B's two others only if A misses. Edge vectors only for ties.
    const double rx = sx[idx], ry = sy[idx];
    const double fd = f;
    auto edgeValue = [&](int ei) { return edgeAt(rx, ry, q[ei].at(fd)); };
    const double e0 = edgeValue(0), e1 = edgeValue(1), e4 = edgeValue(4);
    int tr = 0;
    float b[3];
    if (!triangleCovers(e1, -e4, e0, [&](int i) { return i == 0 ? q[1].at(fd) : i == 1 ? -q[4].at(fd) : q[0].at(fd); }, flags, b)) {
      if (tri || !triangleCovers(edgeValue(2), edgeValue(3), e4, [&](int i) { return q[2 + i].at(fd); }, flags, b)) return;
      tr = 1;
    }
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

  // Raster positions of the chunk's vertex vi (vBase + vi) at every theta time (projX/projY
  // [vi * T + ti]); NaN x marks a position before the near plane. Float arithmetic: pixelRange()
  // widens by the relative error.
  void projectVertexPath(const MovingTimes& mt, const TilePart& part, uint32_t vBase, uint32_t vi) {
    const size_t T = mt.thetaTimes.size();
    const uint32_t v = vBase + vi;
    const auto& thetaSeg = mt.thetaSeg;
    float* __restrict xs = &projX[size_t(vi) * T];
    float* __restrict ys = &projY[size_t(vi) * T];
    const float* __restrict fs = mt.thetaF.data();
    const float ax = float(view.ax), bx = float(view.bx), ay = float(view.ay), by = float(view.by), nearZ = view.nearClip;
    float* __restrict zd = depthScratch.data();
    size_t ti = 0;
    while (ti < T) {
      const uint32_t k = thetaSeg[ti];
      size_t end = ti;
      while (end < T && thetaSeg[end] == k) ++end;
      const glm::vec3 a = part.position(k, v), d = part.position(k + 1, v) - a;
      if (view.perspective) {
        for (size_t i = ti; i < end; ++i) {
          const float px = a.x + fs[i] * d.x, py = a.y + fs[i] * d.y, pz = a.z + fs[i] * d.z;
          const float iz = 1.0f / pz;
          const float x = ax * (px * iz) + bx, y = ay * (py * iz) + by;
          xs[i] = pz >= nearZ ? x : NAN;
          ys[i] = y;
          zd[i] = pz;
        }
      } else {
        for (size_t i = ti; i < end; ++i) {
          xs[i] = ax * (a.x + fs[i] * d.x) + bx;
          ys[i] = ay * (a.y + fs[i] * d.y) + by;
        }
      }
      ti = end;
    }
    // Infinite or NaN results (a vertex exactly at the eye) count as unbounded.
    for (size_t i = 0; i < T; ++i)
      if (!std::isfinite(xs[i]) || !std::isfinite(ys[i])) xs[i] = NAN;
    if (!view.perspective) return;
    // The perspective lag of each theta interval (i, i+1).
    float* __restrict rho = &projRho[size_t(vi) * T];
    const float* __restrict zs = depthScratch.data();
    for (size_t i = 0; i + 1 < T; ++i) rho[i] = perspectiveLag(zs[i], zs[i + 1]);
    rho[T - 1] = 0.f;
  }

  void prepareEdges(const TilePart& part, const uint32_t* c, bool tri, uint32_t k, EdgeQuad* q) const {
    glm::dvec3 A[4], D[4];
    const int nc = tri ? 3 : 4;
    for (int j = 0; j < nc; ++j) {
      A[j] = homogeneous(part.position(k, c[j]));
      D[j] = homogeneous(part.position(k + 1, c[j])) - A[j];
      if (!view.perspective) D[j].z = 0.0;
    }
    for (int e = 0; e < 5; ++e) {
      if (tri && (e == 2 || e == 3)) continue;
      const int a = kEdgeVerts[e][0], b = kEdgeVerts[e][1];
      q[e].e0 = toRaster(cross(A[a], A[b]));
      q[e].e1 = toRaster(cross(A[a], D[b]) + cross(D[a], A[b]));
      q[e].e2 = toRaster(cross(D[a], D[b]));
    }
  }

  // Queues a part: its chunks of kChunkSize micropolygons, each with its nearest depth at any
  // knot and its vertex range.
  void add(const Source& src, const TileEntry& entry, const TilePart& part) {
    const uint32_t index = uint32_t(queued.size());
    queued.push_back({&src, &entry, &part});
    ++stats.parts;
    stats.micropolygons += part.numMicropolygons;
    if (entry.effects & store::kEffectTransparent) ++stats.transparentParts;
    const uint32_t K = part.numKnots;
    for (uint32_t m0 = 0; m0 < part.numMicropolygons; m0 += kChunkSize) {
      Chunk ch{INFINITY, index, m0, std::min(part.numMicropolygons, m0 + kChunkSize), ~0u, 0, false};
      for (uint32_t m = ch.m0; m < ch.m1; ++m)
        for (int j = 0; j < 4; ++j) {
          const uint32_t v = part.corners[size_t(m) * 4 + j];
          if (v != kNoCorner) ch.vLo = std::min(ch.vLo, v), ch.vHi = std::max(ch.vHi, v);
        }
      if (ch.vLo > ch.vHi) continue;  // no corners: nothing to draw
      // The range's vertices (a grid's rows: few the chunk does not use) bound its depth.
      for (uint32_t k = 0; k < K; ++k)
        for (uint32_t v = ch.vLo; v <= ch.vHi; ++v) ch.zNear = std::min(ch.zNear, part.position(k, v).z);
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
  void rasterizeQueued() {
    std::sort(chunks.begin(), chunks.end(), [](const Chunk& a, const Chunk& b) {
      return a.zNear != b.zNear ? a.zNear < b.zNear : a.part != b.part ? a.part < b.part : a.m0 < b.m0;
    });
    for (const Chunk& ch : chunks) {
      const QueuedPart& q = queued[ch.part];
      rasterizeChunk(*q.src, *q.entry, *q.part, ch);
    }
    queued.clear(), chunks.clear();
  }

  void rasterizeChunk(const Source& src, const TileEntry& entry, const TilePart& part, const Chunk& ch) {
    const auto& meta = src.store->meta();
    const auto& knots = meta.schedules[entry.schedule];
    const HitContext hc = hitContext(meta, entry, part);
    const bool moving = (entry.effects & store::kEffectMoving) && part.numKnots > 1 && !ch.still;
    if (!moving) {
      // Knot 0 holds every knot's positions: one pass serves all samples, all groups.
      rasterizeStatic(src, part, hc, &part.positions[ch.vLo], -1, ch);
      return;
    }
    const int G = int(shutter.groups().size());
    for (int g = 0; g < G; ++g) {
      if (!groupPresent[size_t(g)]) continue;
      if (shutter.instantaneous(g)) {
        // A zero-length shutter: the exact instantaneous image, no time sampling.
        const double tau = shutter.groups()[size_t(g)].open - double(src.frame);
        instantPos.resize(ch.vHi - ch.vLo + 1);
        for (uint32_t v = ch.vLo; v <= ch.vHi; ++v) instantPos[v - ch.vLo] = positionAt(part, knots, v, tau);
        rasterizeStatic(src, part, hc, instantPos.data(), G > 1 ? g : -1, ch);
      } else {
        rasterizeMoving(timesFor(src, entry.schedule, knots, g), part, knots, hc, ch);
      }
    }
  }

  // ------------------------------------------------------------------------------------------
  // Resolve

  uint8_t hitState(size_t k) const {
    if (!(zbuf[k] < INFINITY)) return 0;
    return kHitOpaque | (colour[k].matte ? kHitMatte : 0);
  }

  const ResolvedSamples& resolve() {
    if (!chunks.empty()) rasterizeQueued();
    const size_t slots = size_t(P) * N;
    out.x0 = x0, out.y0 = y0, out.width = w, out.height = h, out.spp = N;
    out.r.resize(slots), out.g.resize(slots), out.b.resize(slots), out.a.resize(slots), out.z.resize(slots);
    out.aov.resize(size_t(aovFloatCount));
    for (auto& v : out.aov) v.assign(slots, 0.f);
    out.aovU.resize(size_t(aovUIntCount));
    for (auto& v : out.aovU) v.assign(slots, 0u);
    const bool anyAovs = aovFloatCount || aovUIntCount;
    // The depths the single-closest filters compare: only when there are output variables.
    if (anyAovs) out.aovZ.assign(slots, INFINITY);
    const float far = view.farClip;
    if (!anyFragments && !anyAovs) {
      // Opaque surfaces only, no output variables (the common case): each sample is its nearest
      // surface's colour or empty, as the general loop below computes it, without its branches.
      for (size_t slot = 0; slot < slots; ++slot) {
        const size_t k = idxOf[slot];
        const float zo = zbuf[k];
        const SurfaceColour& nh = colour[k];
        const bool hit = zo < INFINITY, visible = hit && !nh.matte;
        out.r[slot] = visible ? nh.r : 0.f;
        out.g[slot] = visible ? nh.g : 0.f;
        out.b[slot] = visible ? nh.b : 0.f;
        out.a[slot] = visible ? 1.f : 0.f;
        out.z[slot] = hit ? zo : far;
      }
      return out;
    }
    const float stopT = 1.f - opt.opacityThreshold;
    std::vector<const Fragment*> list;
    for (size_t slot = 0; slot < slots; ++slot) {
      const size_t k = idxOf[slot];  // the rasterizer keeps samples stratum-major
      const float zo = zbuf[k];
      const SurfaceColour& nh = colour[k];
      const uint8_t s = hitState(k);
      if (!anyFragments || fragHead[k] < 0) {
        const bool visible = (s & kHitOpaque) && !(s & kHitMatte);
        out.r[slot] = visible ? nh.r : 0.f;
        out.g[slot] = visible ? nh.g : 0.f;
        out.b[slot] = visible ? nh.b : 0.f;
        const float a = visible ? 1.f : 0.f;
        out.a[slot] = a;
        out.z[slot] = (s & kHitOpaque) ? zo : far;
        if ((s & kHitOpaque) && anyAovs) {
          out.aovZ[slot] = zo;
          for (int c = 0; c < aovFloatCount; ++c) out.aov[size_t(c)][slot] = zAov[size_t(c) * sampleSlots + k];
          for (int c = 0; c < aovUIntCount; ++c) out.aovU[size_t(c)][slot] = zAovU[size_t(c) * sampleSlots + k];
        }
        // Composited AOVs of a matte surface are zero like its colour.
        if ((s & kHitMatte)) zeroCompositedAovs(slot);
        continue;
      }
      // Transparent surfaces in front of the nearest opaque one, front to back.
      list.clear();
      for (int32_t f = fragHead[k]; f >= 0; f = frags[size_t(f)].next)
        if (frags[size_t(f)].z < zo) list.push_back(&frags[size_t(f)]);
      std::sort(list.begin(), list.end(), [](const Fragment* a, const Fragment* b) { return a->z != b->z ? a->z < b->z : a->seq < b->seq; });
      float T[3] = {1.f, 1.f, 1.f}, C[3] = {0.f, 0.f, 0.f}, A[3] = {0.f, 0.f, 0.f};
      float closestZ = INFINITY;
      bool closestChosen = false;
      float aovAcc[64] = {};
      bool opaqueReached = false;
      auto takeSingle = [&](const float* fv, const uint32_t* uv, float z) {
        closestChosen = true;
        closestZ = z;
        if (anyAovs) out.aovZ[slot] = z;
        for (size_t a = 0; a < aovs.size(); ++a) {
          if (aovs[a].isUInt) out.aovU[size_t(aovUIntBase[a])][slot] = uv[aovUIntBase[a]];
          else if (!aovs[a].composited())
            for (int c = 0; c < aovs[a].components; ++c) out.aov[size_t(aovFloatBase[a] + c)][slot] = fv[aovFloatBase[a] + c];
        }
      };
      for (const Fragment* f : list) {
        const float oAvg = (f->o[0] + f->o[1] + f->o[2]) / 3.f;
        const float tAvg = (T[0] + T[1] + T[2]) / 3.f;
        const float* fv = fragAov.data() + f->aovOffset;
        const uint32_t* uv = fragAovU.data() + f->aovUOffset;
        if (!f->matte) {
          for (int c = 0; c < 3; ++c) C[c] += T[c] * f->c[c], A[c] += T[c] * f->o[c];
          for (size_t a = 0; a < aovs.size(); ++a)
            if (!aovs[a].isUInt && aovs[a].composited())
              for (int c = 0; c < aovs[a].components; ++c) aovAcc[aovFloatBase[a] + c] += tAvg * oAvg * fv[aovFloatBase[a] + c];
        }
        if (!closestChosen && oAvg >= opt.opacityThreshold) takeSingle(fv, uv, f->z);
        for (int c = 0; c < 3; ++c) T[c] *= 1.f - f->o[c];
        if (T[0] <= stopT && T[1] <= stopT && T[2] <= stopT) {
          opaqueReached = true;
          break;
        }
      }
      if (!opaqueReached && (s & kHitOpaque)) {
        const float tAvg = (T[0] + T[1] + T[2]) / 3.f;
        if (!(s & kHitMatte)) {
          C[0] += T[0] * nh.r, C[1] += T[1] * nh.g, C[2] += T[2] * nh.b;
          for (int c = 0; c < 3; ++c) A[c] += T[c];
          for (size_t a = 0; a < aovs.size(); ++a)
            if (!aovs[a].isUInt && aovs[a].composited())
              for (int c = 0; c < aovs[a].components; ++c) aovAcc[aovFloatBase[a] + c] += tAvg * zAov[size_t(aovFloatBase[a] + c) * sampleSlots + k];
        }
        if (!closestChosen) {
          float fv[64];
          uint32_t uv[16];
          for (int c = 0; c < aovFloatCount; ++c) fv[c] = zAov[size_t(c) * sampleSlots + k];
          for (int c = 0; c < aovUIntCount; ++c) uv[c] = zAovU[size_t(c) * sampleSlots + k];
          takeSingle(fv, uv, zo);
        }
      }
      out.r[slot] = C[0], out.g[slot] = C[1], out.b[slot] = C[2];
      out.a[slot] = (A[0] + A[1] + A[2]) / 3.f;
      out.z[slot] = closestChosen ? closestZ : far;
      for (size_t a = 0; a < aovs.size(); ++a)
        if (!aovs[a].isUInt && aovs[a].composited())
          for (int c = 0; c < aovs[a].components; ++c) out.aov[size_t(aovFloatBase[a] + c)][slot] = aovAcc[aovFloatBase[a] + c];
    }
    return out;
  }

  void visitFragments(const std::function<void(size_t, const SampleFragment*, size_t)>& fn) {
    CHECK(opt.surfaceIds, "visitFragments() needs RasterOptions::surfaceIds");
    const size_t slots = size_t(P) * N;
    const float stopT = 1.f - opt.opacityThreshold;
    std::vector<const Fragment*> list;
    std::vector<SampleFragment> outList;
    std::vector<float> opaqueAov(static_cast<size_t>(aovFloatCount));
    std::vector<uint32_t> opaqueAovU(static_cast<size_t>(aovUIntCount));
    for (size_t slot = 0; slot < slots; ++slot) {
      const size_t k = idxOf[slot];  // the rasterizer keeps samples stratum-major
      const float zo = zbuf[k];
      const SurfaceColour& nh = colour[k];
      const uint8_t s = hitState(k);
      list.clear();
      outList.clear();
      if (anyFragments)
        for (int32_t f = fragHead[k]; f >= 0; f = frags[size_t(f)].next)
          if (frags[size_t(f)].z < zo) list.push_back(&frags[size_t(f)]);
      std::sort(list.begin(), list.end(), [](const Fragment* a, const Fragment* b) { return a->z != b->z ? a->z < b->z : a->seq < b->seq; });
      float T[3] = {1.f, 1.f, 1.f};
      bool opaqueReached = false;
      for (const Fragment* f : list) {
        SampleFragment sf;
        sf.z = f->z;
        for (int c = 0; c < 3; ++c) sf.c[c] = f->matte ? 0.f : f->c[c], sf.o[c] = f->o[c];
        sf.objectId = f->objectId, sf.gridId = f->gridId, sf.matte = f->matte;
        sf.aov = fragAov.data() + f->aovOffset;
        sf.aovU = fragAovU.data() + f->aovUOffset;
        outList.push_back(sf);
        for (int c = 0; c < 3; ++c) T[c] *= 1.f - f->o[c];
        if (T[0] <= stopT && T[1] <= stopT && T[2] <= stopT) {
          opaqueReached = true;
          break;
        }
      }
      if (!opaqueReached && (s & kHitOpaque)) {
        SampleFragment sf;
        sf.z = zo;
        const bool matte = s & kHitMatte;
        sf.c[0] = matte ? 0.f : nh.r, sf.c[1] = matte ? 0.f : nh.g, sf.c[2] = matte ? 0.f : nh.b;
        sf.objectId = objectOf[k], sf.gridId = gridOf[k], sf.matte = matte;
        for (int c = 0; c < aovFloatCount; ++c) opaqueAov[size_t(c)] = zAov[size_t(c) * sampleSlots + k];
        for (int c = 0; c < aovUIntCount; ++c) opaqueAovU[size_t(c)] = zAovU[size_t(c) * sampleSlots + k];
        sf.aov = opaqueAov.data(), sf.aovU = opaqueAovU.data();
        outList.push_back(sf);
      }
      fn(slot, outList.data(), outList.size());
    }
  }

  void zeroCompositedAovs(size_t slot) {
    for (size_t a = 0; a < aovs.size(); ++a)
      if (!aovs[a].isUInt && aovs[a].composited())
        for (int c = 0; c < aovs[a].components; ++c) out.aov[size_t(aovFloatBase[a] + c)][slot] = 0.f;
  }
};

BucketRasterizer::BucketRasterizer(const SamplePattern& pattern, const ShutterModel& shutter, const View& view,
                                   const std::vector<AovChannel>& aovs, const RasterOptions& options)
    : impl_(std::make_unique<Impl>(pattern, shutter, view, aovs, options)) {
  int floats = 0, uints = 0;
  for (const auto& a : aovs) (a.isUInt ? uints : floats) += a.isUInt ? 1 : a.components;
  if (floats > 64 || uints > 16) fail("--aov", "too many output variables (at most 64 float components and 16 ids)");
}
BucketRasterizer::~BucketRasterizer() = default;
void BucketRasterizer::begin(int x0, int y0, int w, int h) { impl_->begin(x0, y0, w, h); }
double BucketRasterizer::earliestTime() const { return impl_->tMin; }
double BucketRasterizer::latestTime() const { return impl_->tMax; }
void BucketRasterizer::add(const Source& source, const TileEntry& entry, const TilePart& part) { impl_->add(source, entry, part); }
void BucketRasterizer::rasterizeQueued() { impl_->rasterizeQueued(); }
const ResolvedSamples& BucketRasterizer::resolve() { return impl_->resolve(); }
void BucketRasterizer::visitFragments(const std::function<void(size_t, const SampleFragment*, size_t)>& fn) { impl_->visitFragments(fn); }
const RasterStats& BucketRasterizer::stats() const { return impl_->stats; }

}  // namespace reshutter::resample
