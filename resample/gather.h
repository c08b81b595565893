// Sample gathering, the rasterizer's vectorised first step: of a bucket's samples, those that lie
// inside a micropolygon's moving box at their own time and are not yet hidden (the early depth
// test) - per stratum's pixel rows, per micropolygon over all its strata, or once for a run of
// micropolygons that move together, sorted into cells of motion-compensated position and
// filtered per micropolygon. Also the chunk set-up that projects a chunk's vertices. The exact
// coverage test of the candidates is resample/coverage.h; the instruction sets and their dispatch
// resample/simd.h.
#pragma once

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <cstdint>

#include "resample/simd.h"

#if defined(__SSE2__)
#include <emmintrin.h>
#endif

namespace reshutter::resample::kernels {

/// An axis-aligned box moving linearly over a time span: [x0 + u dx0, x1 + u dx1] ×
/// [y0 + u dy0, y1 + u dy1] at u = clamp((st - thetaA) invLen, 0, 1). A fixed box has zero d's.
struct MovingBox {
  float x0, dx0, x1, dx1, y0, dy0, y1, dy1;
  float thetaA = 0, invLen = 0;
};

/// Strata's samples laid out row-major over the region, one plane per stratum:
/// index = first + plane * planeStride + row * stride + col.
struct SampleRows {
  const float* st;  // sample time offsets
  const float* sx;  // raster positions
  const float* sy;
  size_t first;   // index of the range's first sample
  size_t stride;  // region width
  int cols, rows;
  const uint8_t* rowGroup = nullptr;  // when set: skip rows whose group differs from `group`
  uint8_t group = 0;
  int planes = 1;
  size_t planeStride = 0;
  // Early depth test (required: the gathers always read `depth`): only samples whose nearest
  // surface so far (indexed like st) lies beyond zCull are kept; a surface no nearer than zCull
  // cannot change the others. zCull = -INFINITY keeps every sample.
  const float* depth = nullptr;
  float zCull = -INFINITY;
  // gatherStrata(): when rowGroup is set and the groups alternate by row (interlaced fields),
  // the group of row 0 of the region; lets small strata mask the other group's rows instead of
  // walking row by row. -1: not known to alternate.
  int rowParity = -1;
};

/// A list of candidate samples: each one's index and a copy of its time and position, so that
/// the edge test reads them in order instead of gathering them from the sample arrays.
struct Candidates {
  uint32_t* index;
  float* t;
  float* x;
  float* y;
  /// The same arrays from entry n on (a list appended to after its first n).
  Candidates from(size_t n) const { return {index + n, t + n, x + n, y + n}; }
};

/// Appends to `out` from position n the samples in `rows` (plane by plane; a fixed box of at most
/// 2×2 pixels takes two planes at a time, their candidates interleaved) that lie inside `box` at
/// their own time and pass the early depth test; returns the new count. Reads up to 7 floats
/// past a row's end (arrays need that padding) and writes up to 15 entries past the returned count.
size_t gatherInBox(Isa isa, const SampleRows& rows, const MovingBox& box, const Candidates& out, size_t n);

/// The lens path's box (raster_lens.cpp): a micropolygon's pinhole box over the render's times,
/// widened by the rounding margin, and the raster displacement per unit of lens point over its
/// depths, [cx0, cx1] in x and [cy0, cy1] in y. A sample at lens point (u, v) may see the
/// micropolygon only if x - d lies in [x0, x1] for some displacement d in u [cx0, cx1], and so for y.
/// A moving micropolygon's box is the lerp of its boxes at the interval's ends, by the sample's
/// own time (MovingBox's thetaA, invLen and motions; all zero for a fixed box).
struct LensBox {
  float x0, x1, y0, y1;
  float cx0, cx1, cy0, cy1;
  float thetaA = 0, invLen = 0, mx0 = 0, mx1 = 0, my0 = 0, my1 = 0;
  /// The test, in the operations and order of every implementation (vector kernels included).
  bool admits(float t, float x, float y, float u, float v) const {
    const float a = (t - thetaA) * invLen, f = a < 1.f ? (a > 0.f ? a : 0.f) : 1.f;
    const float dx0 = u * cx0, dx1 = u * cx1, dy0 = v * cy0, dy1 = v * cy1;
    const float xLo = (x0 + f * mx0) + (dx1 < dx0 ? dx1 : dx0), xHi = (x1 + f * mx1) + (dx0 < dx1 ? dx1 : dx0);
    const float yLo = (y0 + f * my0) + (dy1 < dy0 ? dy1 : dy0), yHi = (y1 + f * my1) + (dy0 < dy1 ? dy1 : dy0);
    return x >= xLo && x <= xHi && y >= yLo && y <= yHi;
  }
  /// The box (x0, x1, y0, y1) the sheared positions of its samples with lerp parameter in [f0, f1]
  /// lie in: the lerped box over that span, widened by (ex, ey) - what a micropolygon's
  /// displacement strays from its layer's - and by qm.
  void searchBox(float f0, float f1, float ex, float ey, float qm, float q[4]) const {
    q[0] = x0 + std::min(f0 * mx0, f1 * mx0) - ex - qm, q[1] = x1 + std::max(f0 * mx1, f1 * mx1) + ex + qm;
    q[2] = y0 + std::min(f0 * my0, f1 * my0) - ey - qm, q[3] = y1 + std::max(f0 * my1, f1 * my1) + ey + qm;
  }
};

/// A layer's samples sorted into cells by their sheared positions (raster_lens.cpp): cell c's
/// samples are [start[c], start[c + 1]) of the sorted arrays - each one's time, position and lens
/// point - cells row-major, `stride` to a row. The arrays have kPad entries of room past their
/// last sample.
struct LensCells {
  const float *t, *x, *y, *u, *v;
  uint64_t* examined;  // += the samples in the cells searched (--stats)
};

/// One time block's search: cells [c0, c1] × [r0, r1] of the block's cells, whose samples are
/// [start[c], start[c + 1]) of the sorted arrays.
struct LensSearch {
  const uint32_t* start;
  int c0, r0, c1, r1;
};

/// The lens path's candidates: each one's slot, time, position and lens point (copies, so that
/// the exact test reads them in order).
struct LensCandidates {
  uint32_t* index;
  float *t, *x, *y, *u, *v;
};

/// Appends to positions[] from n the places in the sorted arrays of the samples in the cells of
/// searches[0..count) (one per time block) that the lens box admits at their lens points, in
/// search and sorted order; returns the new count. Reads up to 15 entries past a row's last
/// sample (the arrays' room) and writes up to 15 entries past the returned count. Only places:
/// few samples pass, and one stream per vector of samples costs a sixth of copying all six (the
/// caller copies what passed).
size_t gatherLensCells(Isa isa, const LensCells& cells, size_t stride, const LensSearch* searches, size_t count, const LensBox& box, uint32_t* positions,
                       size_t n);

/// The gather kernels' walk: rowRun(first, last) for the sorted samples [first, last) of each row
/// of each search, in order; returns how many samples those hold (--stats' examined). A search's
/// fields are read once: the kernels' stores may alias them.
template <class RowRun>
inline uint64_t forEachLensRow(const LensSearch* searches, size_t count, size_t stride, RowRun&& rowRun) {
  uint64_t examined = 0;
  for (size_t k = 0; k < count; ++k) {
    const uint32_t* start = searches[k].start;
    const int r0 = searches[k].r0, r1 = searches[k].r1, c0 = searches[k].c0, c1 = searches[k].c1;
    for (int r = r0; r <= r1; ++r) {
      const size_t row = size_t(r) * stride;
      const uint32_t first = start[row + size_t(c0)], last = start[row + size_t(c1) + 1];
      examined += last - first;
      rowRun(first, last);
    }
  }
  return examined;
}

/// The lens sort's tiles, which its draws mark where they search: squares of kLensTile cells a
/// side (4 × 4 marked a layer's moving streaks more closely than 8 × 8 did, for more marks to read).
inline constexpr int kLensTileShift = 2, kLensTile = 1 << kLensTileShift;
/// The tiles that cover `cells` cells along one side.
inline constexpr int lensTiles(int cells) { return (cells + kLensTile - 1) >> kLensTileShift; }

/// A layer's grid of cells as its searches see it: a coordinate's column is
/// clampedCell(x - x0, cols), its row clampedCell((y - y0) rowScale, rows), where clampedCell(v, n)
/// is int(min(max(0, v), n - 1)) (a NaN takes cell 0).
struct LensCellGrid {
  float x0, y0, rowScale;
  int cols, rows;
};
/// A draw's search over lerp parameters [f0, f1] in the grid's cells: out = c0 r0 c1 r1, the cells
/// of box.searchBox(f0, f1, ex, ey, qm) (raster_lens_sort.cpp).
void lensSearchCells(const LensBox& box, float ex, float ey, float qm, float f0, float f1, const LensCellGrid& g, int out[4]);
/// lensSearchCells() for one grid, what the layer sort calls for its searches: in four lanes of
/// x86-64's baseline vectors, one edge a lane, the same cells (tested); without SSE2,
/// lensSearchCells() itself. Defined where the caller is (the baseline build,
/// raster_lens_sort.cpp): the vector-kernel files, built for other CPUs, do not define it.
struct LensCellLanes {
  explicit LensCellLanes(const LensCellGrid& g);
  void operator()(const LensBox& box, float ex, float ey, float qm, float f0, float f1, int out[4]) const;
#if defined(__SSE2__)
  __m128 origin, scale, maxCell, lowLanes, lowSign;
#else
  LensCellGrid grid;
#endif
};

/// A depth layer's sort keys (raster_lens.cpp, sortLensLayer()): a sample's cell is that of its
/// position sheared by the layer's displacement, col = int(clamp(x - cx u - x0, 0, maxCol)) and
/// row = int(clamp((y - cy v - y0) rowScale, 0, maxRow)) (cells rowScale⁻¹ pixels tall; each clamp
/// `v >= 0 ? (v <= hi ? v : hi) : 0`, so a NaN takes cell 0), keyed
/// key + row * cols + col. A sample is kept when its nearest surface so far lies beyond zMin and,
/// where tileUsed is set, its tile is marked there (tileUsed[(row >> kLensTileShift) tileCols +
/// (col >> kLensTileShift)], read 32 bits at a time: 3 bytes of room past its end).
struct LensShear {
  float cx, cy, x0, y0, maxCol, maxRow;
  uint32_t cols, tileCols;
  const uint8_t* tileUsed;
  float zMin;
  float rowScale = 1.f;  // cell rows per pixel
};

/// Runs of slots: [first[r], first[r] + count[r]) for r < n, in increasing order.
struct LensRuns {
  const uint32_t* first;
  const uint32_t* count;
  size_t n;
};

/// Appends the kept samples among the runs' slots (x, y, u, v and depth indexed by slot) to slot[]
/// and their cells to cell[] from position n, in slot order; returns the new count. Writes up to
/// 15 entries past the count.
size_t lensLayerCells(Isa isa, const LensShear& shear, const float* x, const float* y, const float* u, const float* v, const float* depth, const LensRuns& runs,
                      uint32_t key, uint32_t* slot, uint32_t* cell, size_t n);

/// The strata of one moving box: stratum s covers box times u in [u0[s], u1[s]] and its
/// samples are plane s of `rows` (whose first/cols/rows describe the whole region). u0 and u1
/// are read in whole vectors of eight: readable up to the next multiple of eight entries.
struct StrataSpans {
  const float* u0;
  const float* u1;
  int strata;
  int x0, y0, w, h;  // the region, raster pixels
  float margin;      // widening for float rounding of the box (pixelRange's margin or more)
};

/// For each stratum, the pixels its part of the box's path touches, then gatherInBox() over
/// them: one call per micropolygon instead of one per stratum. The same candidates, in an order
/// of its own (small strata share vectors, and the strata are visited kind by kind).
size_t gatherStrata(Isa isa, const SampleRows& region, const StrataSpans& spans, const MovingBox& box, const Candidates& out);

/// Cells for the micropolygons of one chunk, in compensated position: a candidate at raster
/// (x, y) and box time u (MovingBox's u) sits at (x - u dx, y - u dy), taking out a reference
/// motion (dx, dy) that the chunk's micropolygons share more or less, so that each one's box over
/// the whole interval, compensated, stays about its own size. Square cells of `size` pixels.
struct CellGrid {
  float x0, y0;    // compensated position of cell (0, 0)'s corner
  float invSize;   // 1 / cell size
  int cols, rows;  // cols * rows <= 65535
  float dx, dy;    // the reference motion
  float thetaA, invLen;
};

/// Sorts candidates [0, n) of `in` into `out` (same layout, room for n) by their cell, row-major;
/// positions outside the grid clamp to its border cells. cellStart (cols * rows + 1 entries)
/// receives each cell's first position in `out`, and the total at the end; `scratch` needs n + 16
/// entries, `in` 15 readable entries past n.
void sortByCell(Isa isa, const CellGrid& grid, const Candidates& in, size_t n, const Candidates& out, uint32_t* cellStart, uint16_t* scratch);

/// Appends to `out` from position n the candidates [begin, end) of `in` that lie inside `box` at
/// their own time (gatherInBox()'s test); returns the new count. No early depth test: of these it
/// would drop only samples covered since the run's gather, whose hits the record's depth compare
/// hides anyway, for a depth read per candidate scanned (raster_linear.cpp, prepareLinearChunk()).
/// Reads up to 15 entries past `end`, writes up to 15 past the count.
size_t filterCandidates(Isa isa, const Candidates& in, size_t begin, size_t end, const MovingBox& box, const Candidates& out, size_t n);

/// The camera's map from camera space to raster, as the rasterizer's project() applies it:
/// x = float(ax (x / z) + bx) with the division as 1 / z in double (perspective), or
/// float(ax x + bx); a point before the near plane, or one that lands off the float range, has
/// no raster position.
struct ProjectionScale {
  double ax, bx, ay, by;
  float nearClip;
  bool perspective;
};

/// The static path's per-micropolygon set-up for a run of a chunk's micropolygons (raster_static.cpp),
/// eight at a time: each one's corner box from its corners' projections (a NaN x: unbounded),
/// BucketSamples::testArea() of that box over the region, and the depth no hit can come nearer
/// than (the nearest corner depth, less 1e-5 of it with occlusion culling, else -infinity) - the
/// scalar code's values, bit for bit.
struct StillAreaSetup {
  const uint32_t* corners;   // the first micropolygon's four corners (a triangle's fourth: 0xffffffff)
  uint32_t vBase;            // corner v is chunk vertex v - vBase
  const float* projX;        // per chunk vertex: raster x (NaN: none) and y
  const float* projY;
  const float* depth;        // per chunk vertex: camera depth (projectLerped()'s z)
  int x0, y0, w, h;          // the region, raster pixels
  bool occlusionCulling;
};
/// Per micropolygon: state 0 (its box misses the region), 1 (drawn in pixels px0..px1 × py0..py1,
/// samples within sx0..sx1 × sy0..sy1), 2 (unbounded: every pixel, every sample); and zCull. The
/// arrays need room for the count rounded up to eight.
struct StillAreas {
  int32_t *px0, *py0, *px1, *py1;
  float *sx0, *sy0, *sx1, *sy1, *zCull;
  uint8_t* state;
};
void stillAreas(Isa isa, const StillAreaSetup& setup, size_t count, const StillAreas& out);

/// How far perspective can make a projected corner stray from its linear schedule between
/// depths za and zb, per pixel of its motion: x(u) = xa + (xb - xa) g(u) with
/// g(u) - u = u (1 - u) (zb - za) / z(u), at most |dz| / (4 z_min). Inside one knot segment.
inline float perspectiveLag(float za, float zb) { return std::abs(zb - za) / (4.f * (zb < za ? zb : za)) * 1.001f; }

/// The lens path's per-micropolygon set-up for a run of one chunk's micropolygons, still or one
/// knot segment's draw of moving ones (raster_lens.cpp, queueLensDraws()): each one's box for the
/// per-sample test (lerped between the draw's two bound times), its displacement range per unit
/// of lens, its depth layer and how far its search strays from the layer's shear, and whether its
/// search box reaches the region at all. lensDraw() is the definition (the scalar rasterizer runs
/// it); the vector kernel computes its values eight at a time, bit for bit.
struct LensQueueSetup {
  const uint32_t* corners;  // the first micropolygon's four corners (a triangle's fourth: 0xffffffff)
  uint32_t vBase, nV;       // corner v is chunk vertex v - vBase, of nV
  const float* projX;       // per chunk vertex at the draw's first bound time: raster x (NaN: none),
  const float* projY;       // y and camera depth; with two bound times the second's follow, nV on
  const float* depth;
  int times;                // the draw's bound times: 1 or 2
  bool lerp;                // the box lerps between them (a knot segment's draw)
  float uErr;               // with lerp: the rounding of a sample's lerp parameter
  bool moving;              // the layer from the depths at the part's knots:
  const float* const* knotXyz;  // per knot, vertex vBase's xyz (stride 3)
  uint32_t numKnots;
  float nearClip;           // ... unless a knot lies before it: then from
  const float* allDepth;    // the depths at every bound time of the chunk (allTimes × nV)
  uint32_t allTimes;
  float lensAx, lensAy;  // raster displacement per unit of lens and of k = 1/d - 1/z
  float invD;            // 1 / focal distance
  float kMag;            // the rounding scale of the displacements (the chunk's)
  float layerScale;      // layers per unit of k: max(|lensAx|, |lensAy|) / the layers' width
  int x0, y0, w, h;      // the region, raster pixels
  bool occlusionCulling;
};
/// Per micropolygon: state 0 (its search box misses every sample of the region), 1 (drawn: the
/// other fields are LensDraw's and its box's; mx..my 0 without lerp), 2 (unbounded: a corner has
/// no raster position; only zCull is set, the rest 0), and from the vector kernel 3: not set (a
/// knot before the near plane; lensDraw() gives it). The arrays need room for the count rounded
/// up to eight.
struct LensDraws {
  float *zCull, *kl, *x0, *x1, *y0, *y1, *cx0, *cx1, *cy0, *cy1, *ex, *ey, *qm, *mx0, *mx1, *my0, *my1;
  int32_t* layer;
  uint8_t* state;
  static constexpr int kFloatFields = 17;
};
void lensDraw(const LensQueueSetup& setup, size_t m, const LensDraws& out);
void lensDraws(Isa isa, const LensQueueSetup& setup, size_t count, const LensDraws& out);

/// The vertex range of `count` micropolygons' corners (four each; 0xffffffff, a triangle's missing
/// fourth, is not a vertex): lo = smallest, hi = largest (lo > hi when there is none).
void cornerRange(Isa isa, const uint32_t* corners, size_t count, uint32_t& lo, uint32_t& hi);
/// The smallest z of n xyz triples, NaN ignored (std::min(nearest, z) in order: z < nearest ? z :
/// nearest), or `nearest` when none is smaller.
float nearestDepth(Isa isa, const float* xyz, size_t n, float nearest);

/// Points p_i = a_i + f (b_i - a_i) for i < n (a and b: xyz triples), projected: x[i], y[i] their
/// raster position (x[i] NaN where there is none, y[i] then unspecified), z[i] the depth p_i.z;
/// project()'s operations, bit for bit. Returns whether any x is NaN; box = min x, min y, max x,
/// max y over the others. With b == a (a still chunk) p_i is a_i itself, not lerped.
bool projectLerped(Isa isa, const float* a, const float* b, float f, size_t n, const ProjectionScale& scale, float* x, float* y, float* z, float box[4]);

}  // namespace reshutter::resample::kernels
