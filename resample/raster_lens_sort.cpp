// The lens path's layer sort (see raster_lens.cpp for the path): for each depth layer, the
// bucket's samples sorted into cells of their lens-sheared positions - only those some search of
// the layer can reach, and only those a nearer surface does not already hide - and each queued
// draw's search, time block by time block, in those cells.
#include <algorithm>
#include <cmath>
#include <numeric>
#include <type_traits>

#include "resample/raster_impl.h"

namespace reshutter::resample {

namespace {

// The cell of coordinate v among `count` cells, clamped into them (a NaN takes cell 0): as
// v >= 0 ? (v < count ? int(v) : count - 1) : 0, by a max and a min instead of branches, which
// searches near the grid's edge made unpredictable.
int clampedCell(float v, int count) { return int(std::min(std::max(0.f, v), float(count - 1))); }

}  // namespace

namespace kernels {

void lensSearchCells(const LensBox& box, float ex, float ey, float qm, float f0, float f1, const LensCellGrid& g, int out[4]) {
  float q[4];
  box.searchBox(f0, f1, ex, ey, qm, q);
  out[0] = clampedCell(q[0] - g.x0, g.cols), out[1] = clampedCell((q[2] - g.y0) * g.rowScale, g.rows);
  out[2] = clampedCell(q[1] - g.x0, g.cols), out[3] = clampedCell((q[3] - g.y0) * g.rowScale, g.rows);
}

#if defined(__SSE2__)
LensCellLanes::LensCellLanes(const LensCellGrid& g)
    : origin(_mm_setr_ps(g.x0, g.y0, g.x0, g.y0)),
      scale(_mm_setr_ps(1.f, g.rowScale, 1.f, g.rowScale)),
      maxCell(_mm_setr_ps(float(g.cols - 1), float(g.rows - 1), float(g.cols - 1), float(g.rows - 1))),
      lowLanes(_mm_castsi128_ps(_mm_setr_epi32(-1, -1, 0, 0))),
      lowSign(_mm_setr_ps(-0.f, -0.f, 0.f, 0.f)) {}

// Lane k computes out[k]: lanes 0 and 1 the low edges (a min over the path, margins taken off),
// 2 and 3 the high ones. x - e is x + (-e) in IEEE arithmetic; std::min(a0, a1) is
// (a1 < a0 ? a1 : a0), as minps(a1, a0), and std::max(a0, a1) is (a0 < a1 ? a1 : a0), as
// maxps(a1, a0); clampedCell's std::max(0, v) is (0 < v ? v : 0), as maxps(v, 0), and its
// std::min(w, c), w never NaN or -0, is minps(w, c). So every lane picks what the definition does.
void LensCellLanes::operator()(const LensBox& box, float ex, float ey, float qm, float f0, float f1, int out[4]) const {
  const __m128 edges = _mm_setr_ps(box.x0, box.y0, box.x1, box.y1), path = _mm_setr_ps(box.mx0, box.my0, box.mx1, box.my1);
  const __m128 a0 = _mm_mul_ps(_mm_set1_ps(f0), path), a1 = _mm_mul_ps(_mm_set1_ps(f1), path);
  const __m128 reach = _mm_or_ps(_mm_and_ps(lowLanes, _mm_min_ps(a1, a0)), _mm_andnot_ps(lowLanes, _mm_max_ps(a1, a0)));
  const __m128 e = _mm_xor_ps(_mm_setr_ps(ex, ey, ex, ey), lowSign), margin = _mm_xor_ps(_mm_set1_ps(qm), lowSign);
  const __m128 q = _mm_add_ps(_mm_add_ps(_mm_add_ps(edges, reach), e), margin);
  const __m128 v = _mm_mul_ps(_mm_sub_ps(q, origin), scale);
  _mm_storeu_si128(reinterpret_cast<__m128i*>(out), _mm_cvttps_epi32(_mm_min_ps(_mm_max_ps(v, _mm_setzero_ps()), maxCell)));
}
#else
LensCellLanes::LensCellLanes(const LensCellGrid& g) : grid(g) {}
void LensCellLanes::operator()(const LensBox& box, float ex, float ey, float qm, float f0, float f1, int out[4]) const {
  lensSearchCells(box, ex, ey, qm, f0, f1, grid, out);
}
#endif

}  // namespace kernels

// Sorts the bucket's samples into pixel cells of their positions sheared by displacement
// (cxl, cyl) per unit of lens (the middle of the layer of lensDraws[lensOrder[first..last)]),
// stably (slot order within a cell). Left out, exactly: samples whose nearest opaque surface so
// far is no farther than the layer's nearest micropolygon can come (every one of them would fail
// its early depth test), and samples sheared into a tile of cells no micropolygon of the layer
// searches (a sparse layer sorts little). Sample times are copied only where some micropolygon of
// the layer reads them (it moves, or its store covers part of the render's times); elsewhere the
// sorted times are stale - the gathers read them, but nothing uses what they give.
void BucketRasterizer::Impl::sortLensLayer(size_t first, size_t last, float cxl, float cyl) {
  // A layer's shear moves samples by up to |cxl| (|lens point| <= 1); beyond a region's size
  // they pile into the edge cells instead of growing the grid.
  const float maxPad = float(std::max(w, h));
  const int padX = int(std::ceil(std::min(std::abs(cxl), maxPad))) + 2, padY = int(std::ceil(std::min(std::abs(cyl), maxPad))) + 2;
  LensGrid& g = lensGrid;
  const int rowSpan = lensRowSpan();  // pixels per cell row
  const float rowScale = 1.f / float(rowSpan);
  g.x0 = x0 - padX, g.y0 = y0 - padY, g.cols = w + 2 * padX, g.rows = (h + 2 * padY + rowSpan - 1) / rowSpan;
  const size_t cells = size_t(g.cols) * size_t(g.rows), blocks = size_t(lensTimeBlocks), perBlock = size_t(N) / blocks;
  g.cells = cells;
  float zMin = INFINITY;
  bool times = false;
  // Each draw's search, block by block: the cells of its search box over the block's part of its
  // path (drawLensQueued() reads them back; r1 < r0 for a block it does not search). The tiles of
  // kLensTile × kLensTile cells those searches touch are marked per block, so that a block's
  // samples are kept only where that block's searches read - a moving micropolygon's streaks,
  // not its whole path's box.
  const int tileCols = kernels::lensTiles(g.cols), tileRows = kernels::lensTiles(g.rows);
  const size_t tiles = size_t(tileCols) * size_t(tileRows);
  lensTileUsed.resize(blocks * tiles + 3);  // the vector kernels read the marks 32 bits at a time
  lensDrawCells.resize((last - first) * blocks);
  // The marks are counted first, as a difference array (each search box four corner updates, a
  // running sum over the tiles afterwards): no loops over each box's tiles, whose trip counts
  // the branch predictor guessed wrong.
  const size_t diffCols = size_t(tileCols) + 1, diffTiles = diffCols * (size_t(tileRows) + 1);
  lensTileDiff.assign(blocks * diffTiles, 0);
  const kernels::LensCellLanes searchCells(kernels::LensCellGrid{float(g.x0), float(g.y0), rowScale, g.cols, g.rows});
  for (size_t i = first; i < last; ++i) {
    const LensDraw& e = lensDraws[lensOrder[i]];
    const LensChunk& ec = lensChunks[e.chunk];
    zMin = std::min(zMin, e.zCull);
    times = times || ec.moving || ec.cover.check;
    LensCellRect* rect = &lensDrawCells[(i - first) * blocks];
    for (size_t b = 0; b < blocks; ++b) {
      float f0 = 0.f, f1 = 1.f;
      if (ec.blockF != ~0u) {
        f0 = lensBlockF[ec.blockF + 2 * b], f1 = lensBlockF[ec.blockF + 2 * b + 1];
        if (f0 > f1) {  // no sample of this block in the region's groups
          rect[b] = {0, 0, 0, -1};
          continue;
        }
      }
      static_assert(sizeof(LensCellRect) == 4 * sizeof(int), "a rect is c0 r0 c1 r1");
      if (b == 0 || ec.blockF != ~0u) searchCells(e.box, e.ex, e.ey, e.qm, f0, f1, &rect[b].c0);
      else rect[b] = rect[0];  // no lerp: every block the same box
      const LensCellRect& r = rect[b];
      const int tx0 = r.c0 >> kernels::kLensTileShift, tx1 = (r.c1 >> kernels::kLensTileShift) + 1;
      const int ty0 = r.r0 >> kernels::kLensTileShift, ty1 = (r.r1 >> kernels::kLensTileShift) + 1;
      if (tx0 >= tx1 || ty0 >= ty1) continue;  // an inverted box: no tiles
      int32_t* d = lensTileDiff.data() + b * diffTiles;
      const size_t c0 = size_t(tx0), c1 = size_t(tx1), r0 = size_t(ty0) * diffCols, r1 = size_t(ty1) * diffCols;
      ++d[r0 + c0], --d[r0 + c1], --d[r1 + c0], ++d[r1 + c1];
    }
  }
  // The running sums: a tile is marked where some box covers it. The same pass keeps, per block
  // and tile row, its first and last marked tile column (first > last: none), and whether every
  // tile is marked.
  lensTileRowSpan.resize(blocks * size_t(tileRows));
  bool allMarked = true;
  for (size_t b = 0; b < blocks; ++b) {
    int32_t* d = lensTileDiff.data() + b * diffTiles;
    uint8_t* m = lensTileUsed.data() + b * tiles;
    for (size_t ty = 0; ty < size_t(tileRows); ++ty) {
      int32_t* row = d + ty * diffCols;
      int32_t* next = row + diffCols;
      int32_t across = 0;
      int firstMarked = tileCols, lastMarked = -1, marks = 0;
      for (size_t tx = 0; tx < size_t(tileCols); ++tx) {
        across += row[tx];
        next[tx] += row[tx];  // what this row starts carries down to the next
        const bool marked = across > 0;
        m[ty * size_t(tileCols) + tx] = marked;
        if (marked) firstMarked = std::min(firstMarked, int(tx)), lastMarked = int(tx), ++marks;
      }
      lensTileRowSpan[b * size_t(tileRows) + ty] = {firstMarked, lastMarked};
      allMarked = allMarked && marks == tileCols;
    }
  }
  // No marks to read when the layer searches every tile (a dense layer), or when asked to sort
  // every sample.
  const bool everyTile = !opt.lensSortReached || allMarked;
  const uint8_t* used = everyTile ? nullptr : lensTileUsed.data();
  stats.lensSparseLayers += !everyTile;
  // Keyed by time block, then cell: block b's cells are [b cells, (b + 1) cells).
  // One array is counts, cursors and starts: cell c's count goes to start[c + 2], whose running
  // sum makes start[c + 1] cell c's first place; the scatter advances start[c + 1] to its end,
  // which is cell c + 1's first place - so afterwards start[c] is cell c's first place and
  // start[c + 1] its end, with no cursors to copy or keep in cache beside the starts.
  lensCellStart.assign(blocks * cells + 2, 0);
  // Locals the compiler knows do not alias the arrays written.
  uint32_t* __restrict start = lensCellStart.data();
  uint32_t* __restrict keptSlot = lensKeptSlot.data();
  uint32_t* __restrict keptCell = lensKeptCell.data();
  const float* __restrict xs = sx.data();
  const float* __restrict ys = sy.data();
  const float* __restrict ts = st.data();
  const float* __restrict us = lx.data();
  const float* __restrict vs = ly.data();
  const float* __restrict depth = zbuf.data();
  uint32_t* __restrict outIndex = lensSortedIndex.data();
  float* __restrict outT = lensSortedT.data();
  float* __restrict outX = lensSortedX.data();
  float* __restrict outY = lensSortedY.data();
  float* __restrict outU = lensSortedU.data();
  float* __restrict outV = lensSortedV.data();
  const size_t planeStride = PS, planes = size_t(N);
  // Clamped into the grid (a NaN goes to its first cell): every sample has a cell, and a search
  // that reaches the grid's edge (or lies beyond it) finds it there.
  kernels::LensShear shear{cxl, cyl, float(g.x0), float(g.y0), float(g.cols - 1), float(g.rows - 1), uint32_t(g.cols), uint32_t(tileCols), used, zMin,
                           rowScale};
  // The kept samples, in slot order, each with its cell.
  size_t kept = 0;
  // Runs of slots of one plane, in order.
  auto visit = [&](const kernels::LensRuns& runs, uint32_t key) {
    if (vectorKernels) {
      kept = kernels::lensLayerCells(isa, shear, xs, ys, us, vs, depth, runs, key, keptSlot, keptCell, kept);
      return;
    }
    for (size_t r = 0; r < runs.n; ++r)
      for (size_t j = runs.first[r]; j < size_t(runs.first[r]) + runs.count[r]; ++j) {
        const uint32_t col = uint32_t(clampedCell(xs[j] - shear.cx * us[j] - shear.x0, g.cols));
        const uint32_t row = uint32_t(clampedCell((ys[j] - shear.cy * vs[j] - shear.y0) * shear.rowScale, g.rows));
        keptSlot[kept] = uint32_t(j), keptCell[kept] = key + row * shear.cols + col;
        kept += depth[j] > zMin && (!shear.tileUsed || shear.tileUsed[(row >> kernels::kLensTileShift) * shear.tileCols + (col >> kernels::kLensTileShift)]);
      }
  };
  for (size_t s = 0; s < planes; ++s) {
    const size_t block = s / perBlock;
    const uint32_t key = uint32_t(block * cells);
    const size_t plane = s * planeStride;
    lensRunFirst.clear(), lensRunCount.clear();
    if (!used) {
      lensRunFirst.push_back(uint32_t(plane)), lensRunCount.push_back(uint32_t(P));
    } else {
      shear.tileUsed = used + block * tiles;
      lensPlaneRuns(s, cxl, cyl, g, rowScale, &lensTileRowSpan[block * size_t(tileRows)]);
    }
    for (uint32_t c : lensRunCount) stats.lensSortVisited += c;
    visit(kernels::LensRuns{lensRunFirst.data(), lensRunCount.data(), lensRunFirst.size()}, key);
  }
  for (size_t i = 0; i < kept; ++i) ++start[keptCell[i] + 2];
  std::partial_sum(start + 2, start + blocks * cells + 2, start + 2);
  // Scatter: each cell's samples in slot order, with the copies the gather reads.
  uint32_t* __restrict cursor = start + 1;
  auto scatter = [&](auto withTimes) {
    for (size_t i = 0; i < kept; ++i) {
      const uint32_t j = keptSlot[i], at = cursor[keptCell[i]]++;
      outIndex[at] = j;
      if constexpr (decltype(withTimes)::value) outT[at] = ts[j];
      outX[at] = xs[j], outY[at] = ys[j], outU[at] = us[j], outV[at] = vs[j];
    }
  };
  if (times) scatter(std::true_type{});
  else scatter(std::false_type{});
}

// The runs of plane s's slots (lensRunFirst, lensRunCount) whose samples a layer's sort with
// shear (cxl, cyl) can keep: in each pixel row, the pixels from which a sample - anywhere in its
// pixel, its lens point within the plane's range (BucketSamples::lensRange) - can be sheared into
// a marked tile (lensTileRowSpan, the marked columns' span over the tile rows it can reach; the
// grid's clamp takes a sample sheared beyond the grid into its edge tiles). A cell of margin on
// each side for the rounding of the sheared positions. Whole runs that meet are merged.
void BucketRasterizer::Impl::lensPlaneRuns(size_t s, float cxl, float cyl, const LensGrid& g, float rowScale, const std::array<int, 2>* rowSpan) {
  const auto& r = lensRange[s];  // u0 u1 v0 v1
  const float dxLo = std::min(-cxl * r[0], -cxl * r[1]) - 1.f, dxHi = std::max(-cxl * r[0], -cxl * r[1]) + 1.f;
  const float dyLo = std::min(-cyl * r[2], -cyl * r[3]) - 1.f, dyHi = std::max(-cyl * r[2], -cyl * r[3]) + 1.f;
  const size_t plane = s * PS;
  if (!(std::isfinite(dxLo) && std::isfinite(dxHi) && std::isfinite(dyLo) && std::isfinite(dyHi))) {  // a shear beyond float: every slot
    lensRunFirst.push_back(uint32_t(plane)), lensRunCount.push_back(uint32_t(P));
    return;
  }
  const float gx = float(g.x0), gy = float(g.y0);
  // Consecutive pixel rows mostly reach the same tile rows: their pixel span is kept.
  int tr0Was = -1, tr1Was = -1, lo = 0, hi = -1;
  for (int py = 0; py < h; ++py) {
    const float fy = float(y0 + py);
    const int tr0 = clampedCell((fy + dyLo - gy) * rowScale, g.rows) >> kernels::kLensTileShift;
    const int tr1 = clampedCell((fy + 1.f + dyHi - gy) * rowScale, g.rows) >> kernels::kLensTileShift;
    if (tr0 != tr0Was || tr1 != tr1Was) {
      tr0Was = tr0, tr1Was = tr1;
      int first = INT32_MAX, last = -1;
      for (int tr = tr0; tr <= tr1; ++tr) {
        const auto& span = rowSpan[tr];
        if (span[0] <= span[1]) first = std::min(first, span[0]), last = std::max(last, span[1]);
      }
      // A pixel px reaches the marked columns [T first, T (last + 1) - 1] (T = kLensTile) when
      // its sheared cells [px + dxLo - gx, px + 1 + dxHi - gx] (clamped) meet them.
      lo = x0, hi = last < 0 ? x0 - 1 : x0 + w - 1;
      constexpr int T = kernels::kLensTile;
      if (last >= 0 && first > 0) lo = std::max(lo, int(std::floor(std::max(float(T * first) - 1.f - dxHi + gx, float(x0 - 1)))));
      if (last >= 0 && T * (last + 1) - 1 < g.cols - 1) hi = std::min(hi, int(std::ceil(std::min(float(T * (last + 1)) - dxLo + gx, float(x0 + w)))));
    }
    if (lo > hi) continue;
    const uint32_t begin = uint32_t(plane + size_t(py) * size_t(w) + size_t(lo - x0)), count = uint32_t(hi - lo + 1);
    if (!lensRunFirst.empty() && lensRunFirst.back() + lensRunCount.back() == begin) lensRunCount.back() += count;
    else lensRunFirst.push_back(begin), lensRunCount.push_back(count);
  }
}

}  // namespace reshutter::resample
