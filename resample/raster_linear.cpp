// The linear path: a moving micropolygon over a shutter-group interval that lies inside one knot
// segment (always, for two-knot schedules), bounded from its corners' raster positions at the
// interval's two ends - and its chunk gathers, which find the samples of a run of micropolygons
// that move together once for the run.
#include <algorithm>
#include <cmath>

#if defined(__SSE2__)
#include <emmintrin.h>
#endif

#include "resample/raster_impl.h"

namespace reshutter::resample {

using store::kNoCorner;

// The functions below run per micropolygon and are called from this file only: inline, so they
// fold into the chunk loop (drawLinearChunk) as they did when they were one class body.

// A chunk's micropolygons on the linear path, those it cannot bound (a corner before the near
// plane at an interval end) on the general path (drawMoving()). With every shutter group's times
// at once the general path is not at hand: such a chunk draws nothing and returns false.
bool BucketRasterizer::Impl::drawLinearChunk(const MovingPart& mp, const Chunk& ch) {
  prepareLinearVertices(mp.nV);
  prepareLinearChunk(mp, ch);
  if (mp.times.groups > 1)
    for (const ChunkMicropolygon& cm : chunkMps)
      if (cm.state == LinearState::Unbounded) return false;
  for (uint32_t mi = ch.m0; mi < ch.m1; ++mi) {
    const uint32_t* c = &mp.part.corners[size_t(mi) * 4];
    if (!rasterizeLinearInChunk(mp, mi, ch, c, c[3] == kNoCorner)) drawMoving(mp, mi);
  }
  stats.groupsTogetherMicropolygons += mp.times.groups > 1 ? ch.m1 - ch.m0 : 0;
  return true;
}

// The per-vertex terms of linearBox() for the chunk's nV vertices (cull rows 0 and 1).
inline void BucketRasterizer::Impl::prepareLinearVertices(uint32_t nV) {
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
inline BucketRasterizer::Impl::LinearState BucketRasterizer::Impl::linearBox(const MovingPart& mp, const uint32_t* c, int nc, LinearBox& out) const {
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
  if (std::max(ax1, bx1) + mx < mp.rx0 || std::min(ax0, bx0) - mx >= mp.rx1 || std::max(ay1, by1) + my < mp.ry0 || std::min(ay0, by0) - my >= mp.ry1)
    return LinearState::Misses;
  // Depths are linear over the interval; a sample's rounded time may stray li.uErr of it.
  out.zCull = cullDepth(zNear) - li.uErr * dz;
  out.box = MovingBox{ax0 - mx, bx0 - ax0, ax1 + mx, bx1 - ax1, ay0 - my, by0 - ay0, ay1 + my, by1 - ay1, li.thetaA, li.invLen};
  out.rangeMargin = 1e-3f + 1e-6f * mag;
  out.motion = std::max(mvx, mvy), out.size = std::max(std::max(ax1 - ax0, ay1 - ay0), 1.f);
  return LinearState::Draw;
}

inline void BucketRasterizer::Impl::drawLinear(const MovingPart& mp, uint32_t mi, const uint32_t* c, bool tri, const LinearBox& lb) {
  ++stats.linearMicropolygons;
  const float zCull = lb.zCull;
  const MovingBox& box = lb.box;
  resetSegments();
  const uint8_t flags = mp.part.flags[mi];
  // Strata share one pixel range while their combined motion stays under half the
  // micropolygon's size (at least half a pixel): short intervals and slow motion then pay the
  // per-bound set-up once for several strata instead of once each (the samples' own-time box
  // test below keeps the candidates as tight either way).
  // (With every group at once, a stratum spans widestSpan of the interval, not 1/N of it.)
  const MovingTimes& mt = mp.times;
  const float motion = mt.groups > 1 ? lb.motion * mt.widestSpan * float(N) : lb.motion, size = lb.size;
  const int span = motion > 0.f ? std::clamp(int(0.5f * size * float(N) / motion), 1, N) : N;
  size_t n = 0;
  if (span < N && vectorKernels && !mt.cover.check && N <= 64) {
    // Every stratum's pixel range and samples in one vector pass: cheaper than the shared
    // ranges below whenever the micropolygon moves at all (the ranges are computed eight at a
    // time; cachegrind: -3 % on a quarter shutter), though not when one range serves all strata.
    for (int k = 0; k < mt.groups; ++k) {
      const kernels::SampleRows region{st.data(), sx.data(), sy.data(), 0,  size_t(w),   w,    h, multiGroup ? rowGroup.data() : nullptr,
                                       uint8_t(mt.groupOf(k)), N, PS, zbuf.data(), zCull, rowParity};
      const kernels::StrataSpans spans{mt.spanU0(k), mt.spanU1(k), N, x0, y0, w, h, lb.rangeMargin};
      n += kernels::gatherStrata(isa, region, spans, box, candidateList(n));
    }
    if (n) testCandidates(mp, mi, c, tri, flags, n);
    return;
  }
  for (int k = 0; k < mt.groups; ++k) {
    const int g = mt.groupOf(k);
    const float* U0 = mt.spanU0(k);
    const float* U1 = mt.spanU1(k);
    for (int s0 = 0; s0 < N; s0 += span) {
      const int s1 = std::min(N, s0 + span);  // strata [s0, s1)
      const float u0 = U0[size_t(s0)], u1 = U1[size_t(s1 - 1)];
      const float sx0 = std::min(box.x0 + u0 * box.dx0, box.x0 + u1 * box.dx0), sx1 = std::max(box.x1 + u0 * box.dx1, box.x1 + u1 * box.dx1);
      const float sy0 = std::min(box.y0 + u0 * box.dy0, box.y0 + u1 * box.dy0), sy1 = std::max(box.y1 + u0 * box.dy1, box.y1 + u1 * box.dy1);
      if (sx1 < mp.rx0 || sx0 >= mp.rx1 || sy1 < mp.ry0 || sy0 >= mp.ry1) continue;
      int px0, py0, px1, py1;
      if (!pixelRange(sx0, sy0, sx1, sy1, px0, py0, px1, py1)) continue;
      if (multiGroup) {  // fields: trim to this group's rows (a one-row range is often the other field's)
        while (py0 <= py1 && rowGroup[size_t(py0 - y0)] != g) ++py0;
        while (py1 >= py0 && rowGroup[size_t(py1 - y0)] != g) --py1;
        if (py0 > py1) continue;
      }
      n = gatherCandidates(s0, s1, g, px0, py0, px1, py1, box, mt.cover, zCull, n);
    }
  }
  // Every stratum's candidates tested together: the vector test fills its lanes.
  if (n) testCandidates(mp, mi, c, tri, flags, n);
}

// The linear path's boxes for the chunk's micropolygons, and - for each run of them from one
// grid, which moves together - one gather for the run. A micropolygon's own gather reads every
// sample of its strata's pixel ranges (a one-pixel micropolygon moving a pixel and a half per
// stratum: ~110 of them for ~6 candidates), and its neighbours read most of them again; the
// run reads each once: the samples inside the run's moving box (the union of its
// micropolygons' - min of lerps >= lerp of mins, as in linearBox()) at their own time
// that pass the loosest of their early depth tests. They are then sorted into cells of
// compensated position (the sample's position less its time times a reference motion), where
// each micropolygon's box over the whole interval is about its own size: a micropolygon's
// candidates are those of the few cells its compensated box touches that pass its own box test
// (filterCandidates()): the samples its own gather would have found, and the few of them its own
// early depth test would have dropped since the run's gather - those covered meanwhile by the
// run's earlier micropolygons at a depth before this one's nearest. Depths only fall, so
// gathering the run before its micropolygons draw keeps every sample any of them would keep, and
// a candidate its own depth test would have dropped lies behind the surface already there: its
// hit, if any, is hidden, so the image is the same. (The filter's depth test dropped 0.04 % of
// its candidates on the moving bench frame, and reading a depth per candidate cost more than
// those edge tests.)
inline void BucketRasterizer::Impl::prepareLinearChunk(const MovingPart& mp, const Chunk& ch) {
  const uint32_t count = ch.m1 - ch.m0;
  chunkMps.resize(count);
  compensated.resize(count);
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

#if defined(__SSE2__)
// A moving box's sides as vectors: ends = (x0 y0 x1 y1), moves = (dx0 dy0 dx1 dy1).
inline void boxEnds(const MovingBox& b, __m128& ends, __m128& moves) {
  const __m128 xs = _mm_loadu_ps(&b.x0), ys = _mm_loadu_ps(&b.y0);  // (x0 dx0 x1 dx1), (y0 dy0 y1 dy1)
  const __m128 lo = _mm_unpacklo_ps(xs, ys), hi = _mm_unpackhi_ps(xs, ys);  // (x0 y0 dx0 dy0), (x1 y1 dx1 dy1)
  ends = _mm_shuffle_ps(lo, hi, _MM_SHUFFLE(1, 0, 1, 0));
  moves = _mm_shuffle_ps(lo, hi, _MM_SHUFFLE(3, 2, 3, 2));
}
#endif

// Gathers run r's candidates, when its micropolygons move together enough to pay.
inline void BucketRasterizer::Impl::gatherRun(const MovingPart& mp, uint32_t r) {
  ChunkRun& run = chunkRuns[r];
  gatheredRun = r;
  run.gathered = false;
  float x0a = INFINITY, x0b = INFINITY, x1a = -INFINITY, x1b = -INFINITY, y0a = INFINITY, y0b = INFINITY, y1a = -INFINITY, y1b = -INFINITY;
  float zCull = INFINITY, margin = 0.f, spread = 0.f;
  uint32_t drawn = 0;
#if defined(__SSE2__)
  {
    // The run's box at the interval's ends, (x0 y0 x1 y1) at its start and its end, lane for
    // lane the scalar loop's operations (the std::min / std::max operand order as below).
    __m128 startLo = _mm_set1_ps(INFINITY), startHi = _mm_set1_ps(-INFINITY), endLo = startLo, endHi = startHi;
    for (uint32_t i = run.begin; i < run.end; ++i) {
      const ChunkMicropolygon& cm = chunkMps[i];
      if (cm.state != LinearState::Draw) continue;
      ++drawn;
      __m128 ends, moves;
      boxEnds(cm.lb.box, ends, moves);
      const __m128 late = _mm_add_ps(ends, moves);
      startLo = _mm_min_ps(ends, startLo), startHi = _mm_max_ps(ends, startHi), endLo = _mm_min_ps(late, endLo), endHi = _mm_max_ps(late, endHi);
      zCull = std::min(zCull, cm.lb.zCull), margin = std::max(margin, cm.lb.rangeMargin);
      const __m128 extent = _mm_add_ps(_mm_sub_ps(_mm_movehl_ps(ends, ends), ends), _mm_set1_ps(1.f));  // x1 - x0 + 1, y1 - y0 + 1
      spread += _mm_cvtss_f32(extent) * _mm_cvtss_f32(_mm_shuffle_ps(extent, extent, _MM_SHUFFLE(1, 1, 1, 1)));
    }
    alignas(16) float sl[4], sh[4], el[4], eh[4];
    _mm_store_ps(sl, startLo), _mm_store_ps(sh, startHi), _mm_store_ps(el, endLo), _mm_store_ps(eh, endHi);
    x0a = sl[0], y0a = sl[1], x1a = sh[2], y1a = sh[3], x0b = el[0], y0b = el[1], x1b = eh[2], y1b = eh[3];
  }
#else
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
#endif
  if (drawn < 4 || !vectorKernels || !opt.chunkGathers || mp.times.cover.check || N > 64) return;
  const float mag = std::max({std::abs(x0a), std::abs(x0b), std::abs(x1a), std::abs(x1b), std::abs(y0a), std::abs(y0b), std::abs(y1a), std::abs(y1b)});
  // Float rounding of the lerps: the run's box must hold every sample any of its
  // micropolygons' boxes holds, as the float tests compute them.
  const float e = 1e-5f + 2e-6f * mag;
  const MovingBox box{x0a - e, x0b - x0a, x1a + e, x1b - x1a, y0a - e, y0b - y0a, y1a + e, y1b - y1a, mp.times.li.thetaA, mp.times.li.invLen};
  // Worth it when the run's box is small next to its micropolygons' boxes together (it is
  // about their union when they move together); else each gathers on its own.
  const MovingTimes& mt = mp.times;
  const float reach = std::max({std::abs(box.dx0), std::abs(box.dx1), std::abs(box.dy0), std::abs(box.dy1)});
  const float motion = mt.groups > 1 ? reach * mt.widestSpan : reach / float(N);  // over one stratum
  const float runArea = (box.x1 - box.x0 + motion + 1.f) * (box.y1 - box.y0 + motion + 1.f);
  const float alone = spread + float(drawn) * (motion * motion + 2.f * motion);
  if (!(runArea < 0.5f * alone)) return;
  // Compensated boxes: x - u dx stays within [x0 + min(0, dx0 - dx), x1 + max(0, dx1 - dx)] for a
  // sample inside the box at u; cells as large as the largest of them.
  const float dx = 0.5f * (box.dx0 + box.dx1), dy = 0.5f * (box.dy0 + box.dy1);
  const float ec = 1e-5f + 4e-6f * (mag + std::abs(dx) + std::abs(dy));
  float gx0 = INFINITY, gy0 = INFINITY, gx1 = -INFINITY, gy1 = -INFINITY, size = 0.f;
#if defined(__SSE2__)
  // Each micropolygon's compensated box as one vector (x0, y0, x1, y1), kept for its cells
  // below. Lane for lane the scalar operations: std::min(a, b) is _mm_min_ps(b, a), std::max(a,
  // b) is _mm_max_ps(b, a), and x - ec is x + (-ec).
  {
    const __m128 zero = _mm_setzero_ps(), shift = _mm_setr_ps(dx, dy, dx, dy), slack = _mm_setr_ps(-ec, -ec, ec, ec);
    const __m128 upper = _mm_castsi128_ps(_mm_setr_epi32(0, 0, -1, -1));  // lanes 2, 3: the box's far ends
    __m128 lo = _mm_set1_ps(INFINITY), hi = _mm_set1_ps(-INFINITY), widest = zero;
    for (uint32_t i = run.begin; i < run.end; ++i) {
      const ChunkMicropolygon& cm = chunkMps[i];
      if (cm.state != LinearState::Draw) continue;
      __m128 ends, moves;
      boxEnds(cm.lb.box, ends, moves);
      const __m128 d = _mm_sub_ps(moves, shift);
      const __m128 lag = _mm_or_ps(_mm_andnot_ps(upper, _mm_min_ps(d, zero)), _mm_and_ps(upper, _mm_max_ps(d, zero)));
      const __m128 comp = _mm_add_ps(_mm_add_ps(ends, lag), slack);
      _mm_storeu_ps(compensated[i].data(), comp);
      lo = _mm_min_ps(comp, lo), hi = _mm_max_ps(comp, hi);
      const __m128 extent = _mm_sub_ps(_mm_movehl_ps(comp, comp), comp);  // x1 - x0, y1 - y0
      widest = _mm_max_ps(extent, widest);
      widest = _mm_max_ps(_mm_shuffle_ps(extent, extent, _MM_SHUFFLE(1, 1, 1, 1)), widest);
    }
    alignas(16) float l[4], u[4];
    _mm_store_ps(l, lo), _mm_store_ps(u, hi);
    gx0 = l[0], gy0 = l[1], gx1 = u[2], gy1 = u[3], size = _mm_cvtss_f32(widest);
  }
#else
  for (uint32_t i = run.begin; i < run.end; ++i) {
    const ChunkMicropolygon& cm = chunkMps[i];
    if (cm.state != LinearState::Draw) continue;
    const MovingBox& b = cm.lb.box;
    const float bx0 = b.x0 + std::min(0.f, b.dx0 - dx) - ec, bx1 = b.x1 + std::max(0.f, b.dx1 - dx) + ec;
    const float by0 = b.y0 + std::min(0.f, b.dy0 - dy) - ec, by1 = b.y1 + std::max(0.f, b.dy1 - dy) + ec;
    compensated[i] = {bx0, by0, bx1, by1};
    gx0 = std::min(gx0, bx0), gy0 = std::min(gy0, by0), gx1 = std::max(gx1, bx1), gy1 = std::max(gy1, by1);
    size = std::max({size, bx1 - bx0, by1 - by0});
  }
#endif
  if (!(size > 0.f) || !std::isfinite(size) || size > 8.f) return;
  const float invSize = 1.f / size;
  const float colsF = std::floor((gx1 - gx0) * invSize) + 1.f, rowsF = std::floor((gy1 - gy0) * invSize) + 1.f;
  if (!(colsF * rowsF <= 4096.f)) return;
  cellGrid = kernels::CellGrid{gx0, gy0, invSize, int(colsF), int(rowsF), dx, dy, box.thetaA, box.invLen};
  // A micropolygon's cells: its compensated box's, computed as sortByCell() places a sample
  // (floor of the offset over the cell size, clamped), so that a sample inside the box lands
  // inside its cell range. Clamping before the floor gives the same cell (the bounds are whole
  // numbers), and a clamped offset is never negative: its floor is its truncation.
  const float lastCol = float(cellGrid.cols - 1), lastRow = float(cellGrid.rows - 1);
#if defined(__SSE2__)
  const __m128 origin = _mm_setr_ps(gx0, gy0, gx0, gy0), scale = _mm_set1_ps(invSize), last = _mm_setr_ps(lastCol, lastRow, lastCol, lastRow);
  for (uint32_t i = run.begin; i < run.end; ++i) {
    ChunkMicropolygon& cm = chunkMps[i];
    if (cm.state != LinearState::Draw) continue;
    const __m128 offset = _mm_mul_ps(_mm_sub_ps(_mm_loadu_ps(compensated[i].data()), origin), scale);
    _mm_storeu_si128(reinterpret_cast<__m128i*>(&cm.cx0), _mm_cvttps_epi32(_mm_min_ps(last, _mm_max_ps(_mm_setzero_ps(), offset))));
  }
#else
  auto cell = [&](float v, float origin, float last) { return int(std::min(last, std::max(0.f, (v - origin) * invSize))); };
  for (uint32_t i = run.begin; i < run.end; ++i) {
    ChunkMicropolygon& cm = chunkMps[i];
    if (cm.state != LinearState::Draw) continue;
    const auto& cb = compensated[i];
    cm.cx0 = cell(cb[0], gx0, lastCol), cm.cy0 = cell(cb[1], gy0, lastRow), cm.cx1 = cell(cb[2], gx0, lastCol), cm.cy1 = cell(cb[3], gy0, lastRow);
  }
#endif
  const kernels::Candidates gathered{chunkIndex.data(), chunkT.data(), chunkX.data(), chunkY.data()};
  size_t n = 0;
  for (int k = 0; k < mt.groups; ++k) {
    const kernels::SampleRows region{st.data(), sx.data(), sy.data(), 0,  size_t(w),   w,    h, multiGroup ? rowGroup.data() : nullptr,
                                     uint8_t(mt.groupOf(k)), N, PS, zbuf.data(), zCull, rowParity};
    const kernels::StrataSpans spans{mt.spanU0(k), mt.spanU1(k), N, x0, y0, w, h, margin + e};
    n += kernels::gatherStrata(isa, region, spans, box, gathered.from(n));
  }
  cellStart.resize(size_t(cellGrid.cols) * size_t(cellGrid.rows) + 1);
  kernels::sortByCell(isa, cellGrid, gathered, n, {sortedIndex.data(), sortedT.data(), sortedX.data(), sortedY.data()}, cellStart.data(), cellScratch.data());
  run.gathered = true;
}

// Micropolygon mi of the chunk prepareLinearChunk() prepared, on the linear path: through its
// run's chunk gather, or on its own (drawLinear()). False (nothing done) when it is unbounded:
// the general path handles it.
inline bool BucketRasterizer::Impl::rasterizeLinearInChunk(const MovingPart& mp, uint32_t mi, const Chunk& ch, const uint32_t* c, bool tri) {
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
  resetSegments();
  const kernels::Candidates sorted{sortedIndex.data(), sortedT.data(), sortedX.data(), sortedY.data()};
  size_t n = 0;
  for (int cy = cm.cy0; cy <= cm.cy1; ++cy) {
    const size_t row = size_t(cy) * size_t(cellGrid.cols);
    n = kernels::filterCandidates(isa, sorted, cellStart[row + size_t(cm.cx0)], cellStart[row + size_t(cm.cx1) + 1], cm.lb.box, candidateList(), n);
  }
  if (n) testCandidates(mp, mi, c, tri, mp.part.flags[mi], n);
  return true;
}

}  // namespace reshutter::resample
