// The vector kernels for AVX2 (with POPCNT): sample gathering (resample/gather.h) and the exact
// coverage test (resample/coverage.h), eight float or four double lanes. This file alone is
// compiled with -mavx2 -mpopcnt; simd_dispatch.cpp calls it only on CPUs that run it. See
// simd_isa.h for what it may include.
#include <cmath>

#include "resample/simd_intrinsics.h"
#include "resample/simd_isa.h"

namespace reshutter::resample::kernels {
namespace {

// For each 8-bit lane mask, the lanes that are set, in order: the permutation that packs the
// selected indices to the front of a vector (AVX2 has no compress instruction).
struct CompressTable {
  alignas(32) uint32_t perm[256][8];
};
constexpr CompressTable makeCompressTable() {
  CompressTable t{};
  for (uint32_t m = 0; m < 256; ++m) {
    uint32_t k = 0;
    for (uint32_t lane = 0; lane < 8; ++lane)
      if (m & (1u << lane)) t.perm[m][k++] = lane;
    for (; k < 8; ++k) t.perm[m][k] = 0;
  }
  return t;
}
constexpr CompressTable kCompress = makeCompressTable();

// A MovingBox in vector registers, and its test: which of eight samples (time, x, y) lie inside
// the box at their own time.
struct BoxLanes {
  __m256 thetaA, invLen, x0, dx0, x1, dx1, y0, dy0, y1, dy1;
};
inline BoxLanes boxLanes(const MovingBox& b) {
  return {_mm256_set1_ps(b.thetaA), _mm256_set1_ps(b.invLen), _mm256_set1_ps(b.x0),  _mm256_set1_ps(b.dx0), _mm256_set1_ps(b.x1),
          _mm256_set1_ps(b.dx1),    _mm256_set1_ps(b.y0),     _mm256_set1_ps(b.dy0), _mm256_set1_ps(b.y1),  _mm256_set1_ps(b.dy1)};
}
// A fixed box (no motion, invLen 0, as the static path builds it): the same answer as
// insideAtOwnTime() for any finite time, as x0 + u * 0 is x0, with no time at all.
inline __m256 insideFixed(const BoxLanes& b, __m256 x, __m256 y) {
  __m256 in = _mm256_cmp_ps(x, b.x0, _CMP_GE_OQ);
  in = _mm256_and_ps(in, _mm256_cmp_ps(x, b.x1, _CMP_LE_OQ));
  in = _mm256_and_ps(in, _mm256_cmp_ps(y, b.y0, _CMP_GE_OQ));
  return _mm256_and_ps(in, _mm256_cmp_ps(y, b.y1, _CMP_LE_OQ));
}
inline __m256 insideAtOwnTime(const BoxLanes& b, __m256 t, __m256 x, __m256 y) {
  // u = min(max((t - thetaA) invLen, 0), 1), operand order as std::max / std::min.
  const __m256 u = _mm256_min_ps(_mm256_set1_ps(1.f), _mm256_max_ps(_mm256_setzero_ps(), _mm256_mul_ps(_mm256_sub_ps(t, b.thetaA), b.invLen)));
  __m256 in = _mm256_cmp_ps(x, _mm256_add_ps(b.x0, _mm256_mul_ps(u, b.dx0)), _CMP_GE_OQ);
  in = _mm256_and_ps(in, _mm256_cmp_ps(x, _mm256_add_ps(b.x1, _mm256_mul_ps(u, b.dx1)), _CMP_LE_OQ));
  in = _mm256_and_ps(in, _mm256_cmp_ps(y, _mm256_add_ps(b.y0, _mm256_mul_ps(u, b.dy0)), _CMP_GE_OQ));
  return _mm256_and_ps(in, _mm256_cmp_ps(y, _mm256_add_ps(b.y1, _mm256_mul_ps(u, b.dy1)), _CMP_LE_OQ));
}
// Appends the lanes that are in and live to out from position n; returns the new count.
inline size_t appendMasked(unsigned mask, __m256i idx, __m256 t, __m256 x, __m256 y, const Candidates& out, size_t n) {
  if (!mask) return n;
  const __m256i perm = _mm256_load_si256(reinterpret_cast<const __m256i*>(kCompress.perm[mask]));
  _mm256_storeu_si256(reinterpret_cast<__m256i*>(out.index + n), _mm256_permutevar8x32_epi32(idx, perm));
  _mm256_storeu_ps(out.t + n, _mm256_permutevar8x32_ps(t, perm));
  _mm256_storeu_ps(out.x + n, _mm256_permutevar8x32_ps(x, perm));
  _mm256_storeu_ps(out.y + n, _mm256_permutevar8x32_ps(y, perm));
  return n + size_t(__builtin_popcount(mask));
}
inline size_t appendLanes(__m256 in, __m256i live, __m256i idx, __m256 t, __m256 x, __m256 y, const Candidates& out, size_t n) {
  return appendMasked(unsigned(_mm256_movemask_ps(_mm256_and_ps(in, _mm256_castsi256_ps(live)))), idx, t, x, y, out, n);
}

// Samples lo..lo+3 in lanes 0-3 and hi..hi+3 in lanes 4-7 against box `b` (kFixed:
// insideFixed()) and the early depth test; appends those among lanesLive. The two-row step of
// every narrow gather.
template <bool kFixed = false>
__attribute__((always_inline)) inline size_t appendRowPair(const BoxLanes& b, const SampleRows& r, __m256 zCull, size_t lo, size_t hi, unsigned lanesLive,
                                                           const Candidates& out, size_t n) {
  const __m256 t = _mm256_loadu2_m128(r.st + hi, r.st + lo), x = _mm256_loadu2_m128(r.sx + hi, r.sx + lo), y = _mm256_loadu2_m128(r.sy + hi, r.sy + lo);
  const __m256 visible = _mm256_cmp_ps(_mm256_loadu2_m128(r.depth + hi, r.depth + lo), zCull, _CMP_GT_OQ);
  const __m256 in = kFixed ? insideFixed(b, x, y) : insideAtOwnTime(b, t, x, y);
  const unsigned mask = unsigned(_mm256_movemask_ps(_mm256_and_ps(in, visible))) & lanesLive;
  if (!mask) return n;
  const __m256i quad = _mm256_setr_epi32(0, 1, 2, 3, 0, 1, 2, 3);
  const __m256i idx = _mm256_add_epi32(_mm256_setr_m128i(_mm_set1_epi32(int(uint32_t(lo))), _mm_set1_epi32(int(uint32_t(hi)))), quad);
  return appendMasked(mask, idx, t, x, y, out, n);
}

// Two small strata (or planes) a and b of at most two rows of at most two pixels in one vector:
// a's rows (starting at alo, ahi) in lanes 0-1 and 4-5, b's (blo, bhi) in lanes 2-3 and 6-7;
// tested as appendRowPair() does and appended among lanesLive.
template <bool kFixed = false>
__attribute__((always_inline)) inline size_t appendPlanePair(const BoxLanes& b, const SampleRows& r, __m256 zCull, size_t alo, size_t ahi, size_t blo,
                                                             size_t bhi, unsigned lanesLive, const Candidates& out, size_t n) {
  auto pairedRows = [&](const float* v) {
    const __m128 lo = _mm_loadh_pi(_mm_castsi128_ps(_mm_loadl_epi64(reinterpret_cast<const __m128i*>(v + alo))), reinterpret_cast<const __m64*>(v + blo));
    const __m128 hi = _mm_loadh_pi(_mm_castsi128_ps(_mm_loadl_epi64(reinterpret_cast<const __m128i*>(v + ahi))), reinterpret_cast<const __m64*>(v + bhi));
    return _mm256_set_m128(hi, lo);
  };
  const __m256 t = pairedRows(r.st), x = pairedRows(r.sx), y = pairedRows(r.sy);
  const __m256 visible = _mm256_cmp_ps(pairedRows(r.depth), zCull, _CMP_GT_OQ);
  const __m256 in = kFixed ? insideFixed(b, x, y) : insideAtOwnTime(b, t, x, y);
  const unsigned mask = unsigned(_mm256_movemask_ps(_mm256_and_ps(in, visible))) & lanesLive;
  if (!mask) return n;
  const __m256i rowStarts = _mm256_castsi128_si256(_mm_setr_epi32(int(uint32_t(alo)), int(uint32_t(blo)), int(uint32_t(ahi)), int(uint32_t(bhi))));
  const __m256i spread = _mm256_setr_epi32(0, 0, 1, 1, 2, 2, 3, 3), step = _mm256_setr_epi32(0, 1, 0, 1, 0, 1, 0, 1);
  return appendMasked(mask, _mm256_add_epi32(_mm256_permutevar8x32_epi32(rowStarts, spread), step), t, x, y, out, n);
}

// The rows of `rows` against box `b`: the body of both gathers, inlined so that the box is
// broadcast once per micropolygon, not once per stratum.
// kFixed: the box does not move (insideFixed()). The candidates still carry their times: a
// moving micropolygon that crosses the near plane is gathered with a fixed box.
template <bool kFixed = false>
__attribute__((always_inline)) inline size_t gatherRows(const BoxLanes& b, const SampleRows& r, const Candidates& out, size_t n) {
  const __m256 zCull = _mm256_set1_ps(r.zCull);
  if constexpr (kFixed) {
    if (r.cols <= 2 && r.rows <= 2 && !r.rowGroup) {
      // A static micropolygon's box (one or two pixels each way, usually): two planes per
      // vector (appendPlanePair()), rows 0 and 1 (or row 0 twice, masked off).
      const unsigned colBits = (1u << r.cols) - 1, planeBits = colBits | colBits << 2;
      const unsigned lanes = r.rows == 2 ? planeBits | planeBits << 4 : planeBits;
      const size_t second = r.rows == 2 ? r.stride : 0;
      int plane = 0;
      for (; plane + 1 < r.planes; plane += 2) {
        const size_t pa = r.first + size_t(plane) * r.planeStride, pb = pa + r.planeStride;
        n = appendPlanePair<true>(b, r, zCull, pa, pa + second, pb, pb + second, lanes, out, n);
      }
      if (plane < r.planes) {
        const size_t lo = r.first + size_t(plane) * r.planeStride;
        n = appendRowPair<true>(b, r, zCull, lo, lo + second, r.rows == 2 ? colBits | colBits << 4 : colBits, out, n);
      }
      return n;
    }
  }
  if (r.cols <= 4) {
    // Narrow boxes (a small micropolygon's stratum box is 2 - 4 pixels wide): two rows per
    // vector, four lanes each, so that half the lanes are not idle.
    const unsigned colBits = (1u << r.cols) - 1;
    auto rowPair = [&](size_t lo, size_t hi, bool pair) { n = appendRowPair<kFixed>(b, r, zCull, lo, hi, pair ? colBits | colBits << 4 : colBits, out, n); };
    for (int plane = 0; plane < r.planes; ++plane) {
      const size_t planeBase = r.first + size_t(plane) * r.planeStride;
      if (!r.rowGroup) {
        for (int row = 0; row < r.rows; row += 2) {
          const size_t lo = planeBase + size_t(row) * r.stride;
          const bool pair = row + 1 < r.rows;
          rowPair(lo, pair ? lo + r.stride : lo, pair);
        }
        continue;
      }
      // Fields: pairs of this group's rows.
      int row = 0;
      while (true) {
        while (row < r.rows && r.rowGroup[row] != r.group) ++row;
        if (row >= r.rows) break;
        int second = row + 1;
        while (second < r.rows && r.rowGroup[second] != r.group) ++second;
        const bool pair = second < r.rows;
        const size_t lo = planeBase + size_t(row) * r.stride;
        rowPair(lo, pair ? planeBase + size_t(second) * r.stride : lo, pair);
        row = pair ? second + 1 : r.rows;
      }
    }
    return n;
  }
  const __m256i lane = _mm256_setr_epi32(0, 1, 2, 3, 4, 5, 6, 7);
  for (int plane = 0; plane < r.planes; ++plane)
    for (int row = 0; row < r.rows; ++row) {
      if (r.rowGroup && r.rowGroup[row] != r.group) continue;
      const size_t base = r.first + size_t(plane) * r.planeStride + size_t(row) * r.stride;
      for (int c = 0; c < r.cols; c += 8) {
        const size_t at = base + size_t(c);
        const __m256 t = _mm256_loadu_ps(r.st + at), x = _mm256_loadu_ps(r.sx + at), y = _mm256_loadu_ps(r.sy + at);
        const __m256 visible = _mm256_cmp_ps(_mm256_loadu_ps(r.depth + at), zCull, _CMP_GT_OQ);
        const __m256i live = _mm256_cmpgt_epi32(_mm256_set1_epi32(r.cols - c), lane);
        const __m256 in = kFixed ? insideFixed(b, x, y) : insideAtOwnTime(b, t, x, y);
        n = appendLanes(_mm256_and_ps(in, visible), live, _mm256_add_epi32(_mm256_set1_epi32(int(uint32_t(at))), lane), t, x, y, out, n);
      }
    }
  return n;
}

size_t gatherInBoxAvx2(const SampleRows& rows, const MovingBox& box, const Candidates& candidates, size_t n) {
  const SampleRows r = rows;  // locals: the stores below may alias anything
  const Candidates out = candidates;
  if (box.invLen == 0.f && box.dx0 == 0.f && box.dx1 == 0.f && box.dy0 == 0.f && box.dy1 == 0.f) return gatherRows<true>(boxLanes(box), r, out, n);
  return gatherRows(boxLanes(box), r, out, n);
}

size_t gatherStrataAvx2(const SampleRows& region, const StrataSpans& sp, const MovingBox& b, const Candidates& out) {
  // Pixel ranges of every stratum, eight at a time: the box over [u0, u1] (min / max of its two
  // ends, as the corners move linearly), widened, clamped to the region and floored; then each
  // range's first sample, size and whether it is empty, still eight at a time.
  alignas(32) int first[64], cols[64], rows[64], rowOffset[64], second[64], third[64], fourth[64], laneMask[64], laneMask2[64];
  uint64_t nonEmpty = 0, oneVector = 0, halfVector = 0, twoVectors = 0;
  const int N = sp.strata;
  const __m256 m = _mm256_set1_ps(sp.margin);
  const __m256 lox = _mm256_set1_ps(float(sp.x0)), hix = _mm256_set1_ps(float(sp.x0 + sp.w));
  const __m256 loy = _mm256_set1_ps(float(sp.y0)), hiy = _mm256_set1_ps(float(sp.y0 + sp.h));
  const __m256 one = _mm256_set1_ps(1.f);
  const __m256i ione = _mm256_set1_epi32(1), izero = _mm256_setzero_si256();
  const __m256i regionX = _mm256_set1_epi32(sp.x0), regionY = _mm256_set1_epi32(sp.y0);
  // Sample indices fit 32 bits: the rasterizer stores them as uint32.
  const __m256i planeStride = _mm256_set1_epi32(int(region.planeStride)), stride = _mm256_set1_epi32(int(region.stride));
  const __m256i base = _mm256_set1_epi32(int(region.first));
  const BoxLanes lanes = boxLanes(b);
  const __m256 x0 = lanes.x0, dx0 = lanes.dx0, x1 = lanes.x1, dx1 = lanes.dx1, y0 = lanes.y0, dy0 = lanes.dy0, y1 = lanes.y1, dy1 = lanes.dy1;
  const bool alternate = region.rowGroup && region.rowParity >= 0;
  const __m256i parity = _mm256_set1_epi32(region.rowParity), group = _mm256_set1_epi32(region.group);
  for (int s = 0; s < N; s += 8) {
    const __m256 u0 = _mm256_loadu_ps(sp.u0 + s), u1 = _mm256_loadu_ps(sp.u1 + s);
    const __m256 ax0 = _mm256_min_ps(_mm256_add_ps(x0, _mm256_mul_ps(u0, dx0)), _mm256_add_ps(x0, _mm256_mul_ps(u1, dx0)));
    const __m256 ax1 = _mm256_max_ps(_mm256_add_ps(x1, _mm256_mul_ps(u0, dx1)), _mm256_add_ps(x1, _mm256_mul_ps(u1, dx1)));
    const __m256 ay0 = _mm256_min_ps(_mm256_add_ps(y0, _mm256_mul_ps(u0, dy0)), _mm256_add_ps(y0, _mm256_mul_ps(u1, dy0)));
    const __m256 ay1 = _mm256_max_ps(_mm256_add_ps(y1, _mm256_mul_ps(u0, dy1)), _mm256_add_ps(y1, _mm256_mul_ps(u1, dy1)));
    // A NaN bound clamps to the region (max/min return their second operand for NaN).
    const __m256 cx0 = _mm256_min_ps(_mm256_max_ps(_mm256_sub_ps(ax0, m), lox), hix);
    const __m256 cy0 = _mm256_min_ps(_mm256_max_ps(_mm256_sub_ps(ay0, m), loy), hiy);
    const __m256 cx1 = _mm256_min_ps(_mm256_max_ps(_mm256_add_ps(ax1, m), _mm256_sub_ps(lox, one)), _mm256_sub_ps(hix, one));
    const __m256 cy1 = _mm256_min_ps(_mm256_max_ps(_mm256_add_ps(ay1, m), _mm256_sub_ps(loy, one)), _mm256_sub_ps(hiy, one));
    const __m256i px0 = _mm256_cvttps_epi32(_mm256_floor_ps(cx0)), py0 = _mm256_cvttps_epi32(_mm256_floor_ps(cy0));
    const __m256i px1 = _mm256_cvttps_epi32(_mm256_floor_ps(cx1)), py1 = _mm256_cvttps_epi32(_mm256_floor_ps(cy1));
    const __m256i c = _mm256_add_epi32(_mm256_sub_epi32(px1, px0), ione), r = _mm256_add_epi32(_mm256_sub_epi32(py1, py0), ione);
    const __m256i dy = _mm256_sub_epi32(py0, regionY);
    const __m256i plane = _mm256_add_epi32(_mm256_set1_epi32(s), _mm256_setr_epi32(0, 1, 2, 3, 4, 5, 6, 7));
    const __m256i at = _mm256_add_epi32(_mm256_add_epi32(base, _mm256_mullo_epi32(plane, planeStride)),
                                        _mm256_add_epi32(_mm256_mullo_epi32(dy, stride), _mm256_sub_epi32(px0, regionX)));
    _mm256_store_si256(reinterpret_cast<__m256i*>(first + s), at);
    _mm256_store_si256(reinterpret_cast<__m256i*>(cols + s), c);
    _mm256_store_si256(reinterpret_cast<__m256i*>(rows + s), r);
    _mm256_store_si256(reinterpret_cast<__m256i*>(rowOffset + s), dy);
    const __m256i live = _mm256_and_si256(_mm256_cmpgt_epi32(c, izero), _mm256_cmpgt_epi32(r, izero));
    nonEmpty |= uint64_t(unsigned(_mm256_movemask_ps(_mm256_castsi256_ps(live)))) << s;
    // Strata of at most four rows of at most four pixels (nearly all of them, for small
    // micropolygons) fill one or two vectors: rows 0 and 1 in the first one's lanes 0-3 and 4-7,
    // rows 2 and 3 in the second's; a missing row repeats the one before, masked off. The rows'
    // starts and the lane masks, eight strata at a time too.
    const __m256i twoRows = _mm256_cmpgt_epi32(r, ione), threeRows = _mm256_cmpgt_epi32(r, _mm256_set1_epi32(2)),
                  fourRows = _mm256_cmpgt_epi32(r, _mm256_set1_epi32(3));
    const __m256i fits = _mm256_andnot_si256(_mm256_or_si256(_mm256_cmpgt_epi32(c, _mm256_set1_epi32(4)), _mm256_cmpgt_epi32(r, _mm256_set1_epi32(4))), live);
    oneVector |= uint64_t(unsigned(_mm256_movemask_ps(_mm256_castsi256_ps(fits)))) << s;
    twoVectors |= uint64_t(unsigned(_mm256_movemask_ps(_mm256_castsi256_ps(_mm256_and_si256(threeRows, fits))))) << s;
    const __m256i two = _mm256_set1_epi32(2);
    const __m256i halfFits = _mm256_andnot_si256(_mm256_or_si256(_mm256_cmpgt_epi32(c, two), _mm256_cmpgt_epi32(r, two)), live);
    halfVector |= uint64_t(unsigned(_mm256_movemask_ps(_mm256_castsi256_ps(halfFits)))) << s;
    const __m256i row2 = _mm256_add_epi32(at, _mm256_and_si256(threeRows, _mm256_add_epi32(stride, stride)));
    _mm256_store_si256(reinterpret_cast<__m256i*>(second + s), _mm256_add_epi32(at, _mm256_and_si256(twoRows, stride)));
    _mm256_store_si256(reinterpret_cast<__m256i*>(third + s), row2);
    _mm256_store_si256(reinterpret_cast<__m256i*>(fourth + s), _mm256_add_epi32(row2, _mm256_and_si256(fourRows, stride)));
    const __m256i colBits = _mm256_sub_epi32(_mm256_sllv_epi32(ione, _mm256_min_epi32(c, _mm256_set1_epi32(4))), ione);
    // Alternating groups: rows 0 and 2 are the group's when the first row is, rows 1 and 3 when
    // it is not; the other group's rows get no lanes.
    __m256i evenRows = _mm256_set1_epi32(-1), oddRows = evenRows;
    if (alternate) {
      evenRows = _mm256_cmpeq_epi32(_mm256_and_si256(_mm256_add_epi32(dy, parity), ione), group);
      oddRows = _mm256_xor_si256(evenRows, _mm256_set1_epi32(-1));
    }
    const __m256i evenBits = _mm256_and_si256(evenRows, colBits), oddBits = _mm256_and_si256(oddRows, _mm256_slli_epi32(colBits, 4));
    _mm256_store_si256(reinterpret_cast<__m256i*>(laneMask + s), _mm256_or_si256(evenBits, _mm256_and_si256(twoRows, oddBits)));
    _mm256_store_si256(reinterpret_cast<__m256i*>(laneMask2 + s), _mm256_or_si256(_mm256_and_si256(threeRows, evenBits), _mm256_and_si256(fourRows, oddBits)));
  }
  if (N < 64) nonEmpty &= (uint64_t(1) << N) - 1, halfVector &= (uint64_t(1) << N) - 1;  // the padding lanes past the last stratum
  if (region.rowGroup && !alternate) oneVector = 0, halfVector = 0;                      // gatherRows() skips the other group's rows
  // Locals, so that the candidate stores (which may alias anything) do not force reloads.
  const Candidates list = out;
  SampleRows rr = region;
  rr.planes = 1;
  const uint8_t* rowGroup = region.rowGroup;
  size_t n = 0;
  const __m256 zCull = _mm256_set1_ps(region.zCull);
  // Strata of at most two rows of at most two pixels (most of them when the box moves less than a
  // pixel per stratum, as over a short shutter) go two to a vector: stratum a's rows in lanes
  // 0-1 and 4-5, stratum b's in lanes 2-3 and 6-7. The candidates then come in another order
  // than stratum by stratum; each sample still comes once, and what a hit does depends only on
  // its own sample.
  uint64_t halves = halfVector;
  while (halves & (halves - 1)) {
    const int a = __builtin_ctzll(halves);
    halves &= halves - 1;
    const int b = __builtin_ctzll(halves);
    halves &= halves - 1;
    n = appendPlanePair(lanes, rr, zCull, size_t(uint32_t(first[a])), size_t(uint32_t(second[a])), size_t(uint32_t(first[b])), size_t(uint32_t(second[b])),
                        unsigned(laneMask[a] | laneMask[b] << 2), list, n);
  }
  // An unpaired one is left to the loops below.
  nonEmpty &= ~(halfVector & ~halves);
  // gatherRows()' row pairs, with each stratum's lanes known in advance: every one-vector
  // stratum's first vector, then the second vectors of those with three or four rows, then the
  // wider strata; loops over bit sets rather than branches on each stratum's kind, which the
  // predictor would lose.
  auto rowPair = [&](size_t lo, size_t hi, unsigned lanesLive) { n = appendRowPair(lanes, rr, zCull, lo, hi, lanesLive, list, n); };
  const uint64_t single = nonEmpty & oneVector;
  for (uint64_t left = single; left; left &= left - 1) {
    const int s = __builtin_ctzll(left);
    rowPair(size_t(uint32_t(first[s])), size_t(uint32_t(second[s])), unsigned(laneMask[s]));
  }
  for (uint64_t left = single & twoVectors; left; left &= left - 1) {
    const int s = __builtin_ctzll(left);
    rowPair(size_t(uint32_t(third[s])), size_t(uint32_t(fourth[s])), unsigned(laneMask2[s]));
  }
  for (uint64_t left = nonEmpty & ~oneVector; left; left &= left - 1) {
    const int s = __builtin_ctzll(left);
    rr.first = size_t(uint32_t(first[s]));
    rr.cols = cols[s], rr.rows = rows[s];
    if (rowGroup) rr.rowGroup = rowGroup + rowOffset[s];
    n = gatherRows(lanes, rr, list, n);
  }
  return n;
}

// filterCandidates() with eight lanes, the survivors packed with the permutation table.
size_t filterCandidatesAvx2(const Candidates& in, size_t begin, size_t end, const MovingBox& box, const Candidates& out, size_t n) {
  const BoxLanes b = boxLanes(box);
  const __m256i lane = _mm256_setr_epi32(0, 1, 2, 3, 4, 5, 6, 7);
  for (size_t k = begin; k < end; k += 8) {
    const __m256i live = _mm256_cmpgt_epi32(_mm256_set1_epi32(int(end - k)), lane);
    const __m256i idx = _mm256_loadu_si256(reinterpret_cast<const __m256i*>(in.index + k));
    const __m256 t = _mm256_loadu_ps(in.t + k), x = _mm256_loadu_ps(in.x + k), y = _mm256_loadu_ps(in.y + k);
    n = appendLanes(insideAtOwnTime(b, t, x, y), live, idx, t, x, y, out, n);
  }
  return n;
}

// One edge's value at four samples: E(f) = c0 + f (c3 + f c6) per component, then
// (x Ex + y Ey) + Ez at raster position (x, y), as edgeAt() and EdgeQuad::at() compute it; for a
// still micropolygon through a lens (kLensEdges), E = (c[0..2] + Lx c[3..5]) + Ly c[6..8] with
// the sample's lens point in f (Lx) and g (Ly), as the lens path's scalar test makes it.
template <int kMode>
inline __m256d edgeValue(const LinearEdges& E, int e, __m256d f, __m256d g, __m256d rx, __m256d ry) {
  __m256d c[9];
  for (int k = 0; k < (kMode == kFixedEdges ? 3 : 9); ++k) c[k] = _mm256_set1_pd(E.c[k][e]);
  if constexpr (kMode == kFixedEdges) return _mm256_add_pd(_mm256_add_pd(_mm256_mul_pd(rx, c[0]), _mm256_mul_pd(ry, c[1])), c[2]);
  if constexpr (kMode == kLensEdges) {
    const __m256d ex = _mm256_add_pd(_mm256_add_pd(c[0], _mm256_mul_pd(f, c[3])), _mm256_mul_pd(g, c[6]));
    const __m256d ey = _mm256_add_pd(_mm256_add_pd(c[1], _mm256_mul_pd(f, c[4])), _mm256_mul_pd(g, c[7]));
    const __m256d ez = _mm256_add_pd(_mm256_add_pd(c[2], _mm256_mul_pd(f, c[5])), _mm256_mul_pd(g, c[8]));
    return _mm256_add_pd(_mm256_add_pd(_mm256_mul_pd(rx, ex), _mm256_mul_pd(ry, ey)), ez);
  }
  const __m256d ex = _mm256_add_pd(c[0], _mm256_mul_pd(f, _mm256_add_pd(c[3], _mm256_mul_pd(f, c[6]))));
  const __m256d ey = _mm256_add_pd(c[1], _mm256_mul_pd(f, _mm256_add_pd(c[4], _mm256_mul_pd(f, c[7]))));
  const __m256d ez = _mm256_add_pd(c[2], _mm256_mul_pd(f, _mm256_add_pd(c[5], _mm256_mul_pd(f, c[8]))));
  return _mm256_add_pd(_mm256_add_pd(_mm256_mul_pd(rx, ex), _mm256_mul_pd(ry, ey)), ez);
}

// Cross products of four corner pairs at once (lane = pair), glm::cross's operations.
struct Lanes3 {
  __m256d x, y, z;
};
inline Lanes3 crossLanes(const Lanes3& a, const Lanes3& b) {
  return {_mm256_sub_pd(_mm256_mul_pd(a.y, b.z), _mm256_mul_pd(a.z, b.y)), _mm256_sub_pd(_mm256_mul_pd(a.z, b.x), _mm256_mul_pd(a.x, b.z)),
          _mm256_sub_pd(_mm256_mul_pd(a.x, b.y), _mm256_mul_pd(a.y, b.x))};
}

// Edges (a_e, b_e) of four lanes: the three raster coefficient vectors of each power of f,
// stored to lanes [lane0, lane0 + 4) of out.
// kFixed: the constant term only (D unused).
template <bool kFixed = false>
inline void edgeLanes(const Lanes3& A, const Lanes3& D, const Lanes3& Ab, const Lanes3& Db, const RasterScale& m, LinearEdges& out, int lane0) {
  const __m256d invAx = _mm256_set1_pd(m.invAx), invAy = _mm256_set1_pd(m.invAy), bx = _mm256_set1_pd(m.bx), by = _mm256_set1_pd(m.by);
  const Lanes3 c0 = crossLanes(A, Ab);
  Lanes3 c1{}, c2{};
  if constexpr (!kFixed) {
    const Lanes3 c1a = crossLanes(A, Db), c1b = crossLanes(D, Ab);
    c1 = {_mm256_add_pd(c1a.x, c1b.x), _mm256_add_pd(c1a.y, c1b.y), _mm256_add_pd(c1a.z, c1b.z)};
    c2 = crossLanes(D, Db);
  }
  const Lanes3* powers[3] = {&c0, &c1, &c2};
  for (int p = 0; p < (kFixed ? 1 : 3); ++p) {
    const __m256d ex = _mm256_mul_pd(powers[p]->x, invAx), ey = _mm256_mul_pd(powers[p]->y, invAy);
    _mm256_storeu_pd(&out.c[3 * p][lane0], ex);
    _mm256_storeu_pd(&out.c[3 * p + 1][lane0], ey);
    _mm256_storeu_pd(&out.c[3 * p + 2][lane0], _mm256_sub_pd(_mm256_sub_pd(powers[p]->z, _mm256_mul_pd(ex, bx)), _mm256_mul_pd(ey, by)));
  }
}

// Component k of four corners, lane j = corner j.
inline __m256d cornerColumn(const float* const p[4], int k) { return _mm256_cvtps_pd(_mm_setr_ps(p[0][k], p[1][k], p[2][k], p[3][k])); }
// Lanes rotated: lane j takes lane j + 1 (0x39) or j + 2 (0x4E), mod 4.
template <int kImm>
inline Lanes3 rotateLanes(const Lanes3& v) {
  return {_mm256_permute4x64_pd(v.x, kImm), _mm256_permute4x64_pd(v.y, kImm), _mm256_permute4x64_pd(v.z, kImm)};
}

void linearEdgesAvx2(const float* const at[4], const float* const to[4], const RasterScale& m, LinearEdges& out) {
  const __m256d one = _mm256_set1_pd(1.0);
  // Lane j = corner j: A = homogeneous(at), D = homogeneous(to) - A (z motion 0 without perspective).
  const Lanes3 A{cornerColumn(at, 0), cornerColumn(at, 1), m.perspective ? cornerColumn(at, 2) : one};
  const Lanes3 D{_mm256_sub_pd(cornerColumn(to, 0), A.x), _mm256_sub_pd(cornerColumn(to, 1), A.y),
                 m.perspective ? _mm256_sub_pd(cornerColumn(to, 2), A.z) : _mm256_setzero_pd()};
  // Edges 01 12 23 30: corner j with corner j + 1.
  edgeLanes(A, D, rotateLanes<0x39>(A), rotateLanes<0x39>(D), m, out, 0);
  // Edge 02 in lane 4: corner 0 with corner 2 (lanes 5-7 are padding).
  edgeLanes(A, D, rotateLanes<0x4E>(A), rotateLanes<0x4E>(D), m, out, 4);
}

void fixedEdgesAvx2(const float* const at[4], const RasterScale& m, LinearEdges& out) {
  const Lanes3 A{cornerColumn(at, 0), cornerColumn(at, 1), m.perspective ? cornerColumn(at, 2) : _mm256_set1_pd(1.0)};
  edgeLanes<true>(A, A, rotateLanes<0x39>(A), A, m, out, 0);
  edgeLanes<true>(A, A, rotateLanes<0x4E>(A), A, m, out, 4);
}

}  // namespace

void avx2::stillLensEdges(const float* const at[4], bool triangle, double invD, const RasterScale& m, LinearEdges& out) {
  // Lane j = corner j (a triangle passes corner 2 as corner 3): P and q = P.z invD - 1.
  const Lanes3 P{cornerColumn(at, 0), cornerColumn(at, 1), cornerColumn(at, 2)};
  const __m256d q = _mm256_sub_pd(_mm256_mul_pd(P.z, _mm256_set1_pd(invD)), _mm256_set1_pd(1.0));
  const __m256d invAx = _mm256_set1_pd(m.invAx), invAy = _mm256_set1_pd(m.invAy), bx = _mm256_set1_pd(m.bx), by = _mm256_set1_pd(m.by);
  const __m256d zero = _mm256_setzero_pd(), sign = _mm256_set1_pd(-0.0);
  // Edges (a, b) of four lanes, b's corners Pb and qb: E0 = P_a × P_b and the lens
  // coefficients from D = q_a P_b - q_b P_a, each through toRaster(), to lanes [lane0, lane0 + 4).
  auto edges = [&](const Lanes3& Pb, __m256d qb, int lane0) {
    const Lanes3 D{_mm256_sub_pd(_mm256_mul_pd(q, Pb.x), _mm256_mul_pd(qb, P.x)), _mm256_sub_pd(_mm256_mul_pd(q, Pb.y), _mm256_mul_pd(qb, P.y)),
                   _mm256_sub_pd(_mm256_mul_pd(q, Pb.z), _mm256_mul_pd(qb, P.z))};
    const Lanes3 terms[3] = {crossLanes(P, Pb), {zero, _mm256_xor_pd(D.z, sign), D.y}, {D.z, zero, _mm256_xor_pd(D.x, sign)}};
    for (int i = 0; i < 3; ++i) {
      const __m256d ex = _mm256_mul_pd(terms[i].x, invAx), ey = _mm256_mul_pd(terms[i].y, invAy);
      _mm256_storeu_pd(&out.c[3 * i][lane0], ex);
      _mm256_storeu_pd(&out.c[3 * i + 1][lane0], ey);
      _mm256_storeu_pd(&out.c[3 * i + 2][lane0], _mm256_sub_pd(_mm256_sub_pd(terms[i].z, _mm256_mul_pd(ex, bx)), _mm256_mul_pd(ey, by)));
    }
  };
  // Edges 01 12 23 30: corner j with corner j + 1; edge 02 in lane 4 (lanes 5-7 are padding).
  edges(rotateLanes<0x39>(P), _mm256_permute4x64_pd(q, 0x39), 0);
  edges(rotateLanes<0x4E>(P), _mm256_permute4x64_pd(q, 0x4E), 4);
  if (triangle)
    for (auto& row : out.c) row[2] = row[3] = 0.0;
}

namespace {

// Coverage of one triangle from its oriented edge values, as triangleCovers() decides it:
// `hit` where every edge is strictly on the inner side, `tie` where the triangle counts (non-zero,
// not culled) and an edge value is exactly zero, so the scalar tie rule must decide. Also the
// barycentrics a_k / S.
// Strictly on the inner side of an edge: a > 0, or a < 0 for a clockwise (flipped) triangle.
inline __m256d innerSide(__m256d a, __m256d flip) {
  const __m256d zero = _mm256_setzero_pd();
  return _mm256_blendv_pd(_mm256_cmp_pd(a, zero, _CMP_GT_OQ), _mm256_cmp_pd(a, zero, _CMP_LT_OQ), flip);
}

struct TriangleMasks {
  int hit, tie;
  __m128 b[3];
};
inline TriangleMasks triangleMasks(__m256d a0, __m256d a1, __m256d a2, bool cullBack) {
  const __m256d zero = _mm256_setzero_pd();
  const __m256d S = _mm256_add_pd(_mm256_add_pd(a0, a1), a2);
  __m256d counts = _mm256_cmp_pd(S, zero, _CMP_NEQ_UQ);  // S == 0 is degenerate; NaN goes on (and misses)
  if (cullBack) counts = _mm256_andnot_pd(_mm256_cmp_pd(S, zero, _CMP_GT_OQ), counts);
  const __m256d flip = _mm256_cmp_pd(S, zero, _CMP_LT_OQ);
  const __m256d in = _mm256_and_pd(_mm256_and_pd(innerSide(a0, flip), innerSide(a1, flip)), innerSide(a2, flip));
  const __m256d anyZero =
      _mm256_or_pd(_mm256_or_pd(_mm256_cmp_pd(a0, zero, _CMP_EQ_OQ), _mm256_cmp_pd(a1, zero, _CMP_EQ_OQ)), _mm256_cmp_pd(a2, zero, _CMP_EQ_OQ));
  TriangleMasks m;
  m.hit = _mm256_movemask_pd(_mm256_and_pd(counts, in));
  m.tie = _mm256_movemask_pd(_mm256_and_pd(counts, anyZero));
  const __m256d inv = _mm256_div_pd(_mm256_set1_pd(1.0), S);
  m.b[0] = _mm256_cvtpd_ps(_mm256_mul_pd(a0, inv));
  m.b[1] = _mm256_cvtpd_ps(_mm256_mul_pd(a1, inv));
  m.b[2] = _mm256_cvtpd_ps(_mm256_mul_pd(a2, inv));
  return m;
}

// The rest of an edge test on four lanes, given edges 01 (e0), 12 (e1) and 02 (e4): triangle A
// (p0 p1 p2, edges 12, 20 = -02, 01), then B (p0 p2 p3, edges 23, 30, 02 - edgeB(2), edgeB(3))
// where A neither hits nor ties, the depths from the corner depths depths(zv) gives, and the
// outcome appended to hits. Shared by the kernels that make their edges differently.
template <class EdgeB, class Depths>
inline __attribute__((always_inline)) size_t decideLanes(__m256d e0, __m256d e1, __m256d e4, EdgeB edgeB, Depths depths, int liveMask, bool triangle,
                                                         bool cullBack, size_t i, EdgeHit* hits, size_t h) {
  const TriangleMasks A = triangleMasks(e1, _mm256_xor_pd(e4, _mm256_set1_pd(-0.0)), e0, cullBack);
  int hitA = A.hit & liveMask, undecided = A.tie & liveMask, hitB = 0;
  TriangleMasks B{};
  const int needB = liveMask & ~hitA & ~undecided;
  if (!triangle && needB) {
    B = triangleMasks(edgeB(2), edgeB(3), e4, cullBack);
    hitB = B.hit & needB;
    undecided |= B.tie & needB;
    hitB &= ~undecided;
  }
  const int any = hitA | hitB | undecided;
  if (!any) return h;
  // Per triangle (A, B): barycentrics b0 b1 b2 and depth, by lane. Which triangle a sample hit
  // is a coin toss, so the copy below indexes by it rather than branching on it.
  alignas(16) float bz[2][4][4];
  for (int k = 0; k < 3; ++k) _mm_store_ps(bz[0][k], A.b[k]), _mm_store_ps(bz[1][k], B.b[k]);
  __m128 zv[4];
  depths(zv);
  _mm_store_ps(bz[0][3], _mm_add_ps(_mm_add_ps(_mm_mul_ps(A.b[0], zv[0]), _mm_mul_ps(A.b[1], zv[1])), _mm_mul_ps(A.b[2], zv[2])));
  _mm_store_ps(bz[1][3], _mm_add_ps(_mm_add_ps(_mm_mul_ps(B.b[0], zv[0]), _mm_mul_ps(B.b[1], zv[2])), _mm_mul_ps(B.b[2], zv[3])));
  return writeEdgeHits<4>(bz, unsigned(undecided), unsigned(hitB), unsigned(any), i, hits, h);
}

template <int kMode>
size_t testLinearEdgesAvx2(const EdgeTestSetup& s, const LinearEdges& E, size_t n, EdgeHit* hits) {
  const __m128 fOffset = _mm_set1_ps(s.fOffset), fScale = _mm_set1_ps(s.fScale), zero = _mm_setzero_ps(), one = _mm_set1_ps(1.f);
  const __m256d lensRadius = _mm256_set1_pd(s.lensRadius);
  size_t h = 0;
  for (size_t i = 0; i < n; i += 4) {
    const size_t live = n - i < 4 ? n - i : 4;  // lanes past n read padding and are masked off
    // f = clamp((t + fOffset) fScale, 0, 1), operand order as std::clamp; still edges need no time.
    __m128 f = zero;
    if constexpr (kMode == kMovingEdges) f = _mm_min_ps(one, _mm_max_ps(zero, _mm_mul_ps(_mm_add_ps(_mm_loadu_ps(s.st + i), fOffset), fScale)));
    // Through a lens, the edges' parameters are the lens point (Lx, Ly) = lensRadius (u, v).
    const __m256d fd = kMode == kLensEdges ? _mm256_mul_pd(lensRadius, _mm256_cvtps_pd(_mm_loadu_ps(s.su + i))) : _mm256_cvtps_pd(f);
    const __m256d gd = kMode == kLensEdges ? _mm256_mul_pd(lensRadius, _mm256_cvtps_pd(_mm_loadu_ps(s.sv + i))) : fd;
    const __m256d rx = _mm256_cvtps_pd(_mm_loadu_ps(s.sx + i)), ry = _mm256_cvtps_pd(_mm_loadu_ps(s.sy + i));
    const __m256d e0 = edgeValue<kMode>(E, 0, fd, gd, rx, ry), e1 = edgeValue<kMode>(E, 1, fd, gd, rx, ry), e4 = edgeValue<kMode>(E, 4, fd, gd, rx, ry);
    // Depths, as recordKernelHits() and the scalar tests compute them (operand order kept).
    auto depths = [&](__m128* zv) {
      for (int j = 0; j < 4; ++j) zv[j] = _mm_add_ps(_mm_set1_ps(s.za[j]), _mm_mul_ps(f, _mm_set1_ps(s.zb[j] - s.za[j])));
    };
    h = decideLanes(e0, e1, e4, [&](int e) { return edgeValue<kMode>(E, e, fd, gd, rx, ry); }, depths, (1 << live) - 1, s.triangle, s.cullBackFaces, i,
                    hits, h);
  }
  return h;
}

// testMovingLens() four candidates at a time, testLens()'s operations lane for lane.
size_t testMovingLensAvx2(const MovingLensSetup& s, size_t n, EdgeHit* hits) {
  const __m256d radius = _mm256_set1_pd(s.lensRadius), invD = _mm256_set1_pd(s.invD), one = _mm256_set1_pd(1.0);
  const __m256d invAx = _mm256_set1_pd(s.scale.invAx), invAy = _mm256_set1_pd(s.scale.invAy), bx = _mm256_set1_pd(s.scale.bx), by = _mm256_set1_pd(s.scale.by);
  size_t h = 0;
  for (size_t i = 0; i < n; i += 4) {
    const size_t live = n - i < 4 ? n - i : 4;  // lanes past n read padding and are masked off
    const __m256d fd = _mm256_cvtps_pd(_mm_loadu_ps(s.f + i));
    const __m256d Lx = _mm256_mul_pd(radius, _mm256_cvtps_pd(_mm_loadu_ps(s.su + i))), Ly = _mm256_mul_pd(radius, _mm256_cvtps_pd(_mm_loadu_ps(s.sv + i)));
    __m256d Sx[4], Sy[4], Sz[4];
    for (int j = 0; j < 4; ++j) {
      const __m256d px = _mm256_add_pd(_mm256_set1_pd(s.a[0][j]), _mm256_mul_pd(fd, _mm256_set1_pd(s.d[0][j])));
      const __m256d py = _mm256_add_pd(_mm256_set1_pd(s.a[1][j]), _mm256_mul_pd(fd, _mm256_set1_pd(s.d[1][j])));
      Sz[j] = _mm256_add_pd(_mm256_set1_pd(s.a[2][j]), _mm256_mul_pd(fd, _mm256_set1_pd(s.d[2][j])));
      const __m256d q = _mm256_sub_pd(_mm256_mul_pd(Sz[j], invD), one);
      Sx[j] = _mm256_add_pd(px, _mm256_mul_pd(Lx, q)), Sy[j] = _mm256_add_pd(py, _mm256_mul_pd(Ly, q));
    }
    const __m256d rx = _mm256_cvtps_pd(_mm_loadu_ps(s.sx + i)), ry = _mm256_cvtps_pd(_mm_loadu_ps(s.sy + i));
    // Edge k's value at the sample: toRaster(S_a × S_b), then edgeAt().
    auto edge = [&](int k) {
      const int a = kEdgeVerts[k][0], b = kEdgeVerts[k][1];
      const __m256d cx = _mm256_sub_pd(_mm256_mul_pd(Sy[a], Sz[b]), _mm256_mul_pd(Sz[a], Sy[b]));
      const __m256d cy = _mm256_sub_pd(_mm256_mul_pd(Sz[a], Sx[b]), _mm256_mul_pd(Sx[a], Sz[b]));
      const __m256d cz = _mm256_sub_pd(_mm256_mul_pd(Sx[a], Sy[b]), _mm256_mul_pd(Sy[a], Sx[b]));
      const __m256d ex = _mm256_mul_pd(cx, invAx), ey = _mm256_mul_pd(cy, invAy);
      const __m256d ez = _mm256_sub_pd(_mm256_sub_pd(cz, _mm256_mul_pd(ex, bx)), _mm256_mul_pd(ey, by));
      return _mm256_add_pd(_mm256_add_pd(_mm256_mul_pd(rx, ex), _mm256_mul_pd(ry, ey)), ez);
    };
    auto depths = [&](__m128* zv) {
      for (int j = 0; j < 4; ++j) zv[j] = _mm256_cvtpd_ps(Sz[j]);
    };
    h = decideLanes(edge(0), edge(1), edge(4), edge, depths, (1 << live) - 1, s.triangle, s.cullBackFaces, i, hits, h);
  }
  return h;
}

}  // namespace

namespace {

size_t gatherLensCellsAvx2(const LensCells& cells, size_t stride, const LensSearch* searches, size_t count, const LensBox& box, uint32_t* positions, size_t n) {
  // LensBox::admits() eight sorted samples at a time (min / max as its conditionals: b < a ? b : a).
  const __m256 x0 = _mm256_set1_ps(box.x0), x1 = _mm256_set1_ps(box.x1), y0 = _mm256_set1_ps(box.y0), y1 = _mm256_set1_ps(box.y1);
  const __m256 cx0 = _mm256_set1_ps(box.cx0), cx1 = _mm256_set1_ps(box.cx1), cy0 = _mm256_set1_ps(box.cy0), cy1 = _mm256_set1_ps(box.cy1);
  const __m256 thetaA = _mm256_set1_ps(box.thetaA), invLen = _mm256_set1_ps(box.invLen), one = _mm256_set1_ps(1.f), zero = _mm256_setzero_ps();
  const __m256 mx0 = _mm256_set1_ps(box.mx0), mx1 = _mm256_set1_ps(box.mx1), my0 = _mm256_set1_ps(box.my0), my1 = _mm256_set1_ps(box.my1);
  const __m256i lane = _mm256_setr_epi32(0, 1, 2, 3, 4, 5, 6, 7);
  *cells.examined += forEachLensRow(searches, count, stride, [&](uint32_t first, uint32_t last) {
    for (uint32_t at = first; at < last; at += 8) {
      // Lanes past the run read the next cells' samples (or the arrays' room) and are masked off.
      const unsigned live = last - at >= 8 ? 0xFFu : (1u << (last - at)) - 1;
      const __m256 u = _mm256_loadu_ps(cells.u + at), v = _mm256_loadu_ps(cells.v + at);
      const __m256 t = _mm256_loadu_ps(cells.t + at), x = _mm256_loadu_ps(cells.x + at), y = _mm256_loadu_ps(cells.y + at);
      // f = a < 1 ? (a > 0 ? a : 0) : 1: min(max(a, 0), 1) in _mm256 operand order (min/max
      // return the second operand unless the comparison holds).
      const __m256 f = _mm256_min_ps(_mm256_max_ps(_mm256_mul_ps(_mm256_sub_ps(t, thetaA), invLen), zero), one);
      const __m256 dx0 = _mm256_mul_ps(u, cx0), dx1 = _mm256_mul_ps(u, cx1), dy0 = _mm256_mul_ps(v, cy0), dy1 = _mm256_mul_ps(v, cy1);
      // _mm256_min_ps(a, b) is a < b ? a : b: operands swapped to give admits()' b < a ? b : a.
      const __m256 xLo = _mm256_add_ps(_mm256_add_ps(x0, _mm256_mul_ps(f, mx0)), _mm256_min_ps(dx1, dx0));
      const __m256 xHi = _mm256_add_ps(_mm256_add_ps(x1, _mm256_mul_ps(f, mx1)), _mm256_max_ps(dx1, dx0));
      const __m256 yLo = _mm256_add_ps(_mm256_add_ps(y0, _mm256_mul_ps(f, my0)), _mm256_min_ps(dy1, dy0));
      const __m256 yHi = _mm256_add_ps(_mm256_add_ps(y1, _mm256_mul_ps(f, my1)), _mm256_max_ps(dy1, dy0));
      __m256 in = _mm256_and_ps(_mm256_cmp_ps(x, xLo, _CMP_GE_OQ), _mm256_cmp_ps(x, xHi, _CMP_LE_OQ));
      in = _mm256_and_ps(in, _mm256_and_ps(_mm256_cmp_ps(y, yLo, _CMP_GE_OQ), _mm256_cmp_ps(y, yHi, _CMP_LE_OQ)));
      const unsigned mask = unsigned(_mm256_movemask_ps(in)) & live;
      const __m256i perm = _mm256_load_si256(reinterpret_cast<const __m256i*>(kCompress.perm[mask]));
      _mm256_storeu_si256(reinterpret_cast<__m256i*>(positions + n), _mm256_permutevar8x32_epi32(_mm256_add_epi32(_mm256_set1_epi32(int(at)), lane), perm));
      n += size_t(__builtin_popcount(mask));
    }
  });
  return n;
}

// lensLayerCells() eight slots at a time: the clamps as max then min (max(v, 0) gives 0 for a
// NaN, as the scalar `v >= 0` does; min(a, hi) is a < hi ? a : hi), the tile marks gathered as
// 32-bit words whose low byte is the mark. Lanes past the count load nothing and are dropped.
template <bool kTiles>
size_t lensLayerCellsAvx2T(const LensShear& s, const float* xs, const float* ys, const float* us, const float* vs, const float* depth, const LensRuns& runs,
                             uint32_t key, uint32_t* slot, uint32_t* cell, size_t n) {
  const __m256 cx = _mm256_set1_ps(s.cx), cy = _mm256_set1_ps(s.cy), gx = _mm256_set1_ps(s.x0), gy = _mm256_set1_ps(s.y0);
  const __m256 maxCol = _mm256_set1_ps(s.maxCol), maxRow = _mm256_set1_ps(s.maxRow), zero = _mm256_setzero_ps(), zMin = _mm256_set1_ps(s.zMin);
  const __m256 rowScale = _mm256_set1_ps(s.rowScale);
  const __m256i cols = _mm256_set1_epi32(int(s.cols)), tileCols = _mm256_set1_epi32(int(s.tileCols)), keys = _mm256_set1_epi32(int(key));
  const __m256i lane = _mm256_setr_epi32(0, 1, 2, 3, 4, 5, 6, 7), lowByte = _mm256_set1_epi32(0xFF);
  for (size_t r = 0; r < runs.n; ++r)  // each run, a vector at a time
  for (size_t first = runs.first[r], count = runs.count[r], i = 0; i < count; i += 8) {
    const size_t j = first + i;
    if (!(i & 8)) prefetchLensRuns(runs, r, i, count, xs, ys, us, vs, depth);  // a line a stream for every two vectors
    const bool whole = count - i >= 8;
    const __m256i in = _mm256_cmpgt_epi32(_mm256_set1_epi32(int(whole ? 8 : count - i)), lane);
    auto load = [&](const float* a) { return whole ? _mm256_loadu_ps(a + j) : _mm256_maskload_ps(a + j, in); };
    const __m256 x = load(xs), y = load(ys), u = load(us), v = load(vs), z = load(depth);
    const __m256i col = _mm256_cvttps_epi32(_mm256_min_ps(_mm256_max_ps(_mm256_sub_ps(_mm256_sub_ps(x, _mm256_mul_ps(cx, u)), gx), zero), maxCol));
    const __m256i row = _mm256_cvttps_epi32(_mm256_min_ps(_mm256_max_ps(_mm256_mul_ps(_mm256_sub_ps(_mm256_sub_ps(y, _mm256_mul_ps(cy, v)), gy), rowScale), zero), maxRow));
    __m256i keep = _mm256_and_si256(in, _mm256_castps_si256(_mm256_cmp_ps(z, zMin, _CMP_GT_OQ)));
    if constexpr (kTiles) {
      const __m256i tile = _mm256_add_epi32(_mm256_mullo_epi32(_mm256_srli_epi32(row, kLensTileShift), tileCols), _mm256_srli_epi32(col, kLensTileShift));
      const __m256i mark = _mm256_and_si256(_mm256_i32gather_epi32(reinterpret_cast<const int*>(s.tileUsed), tile, 1), lowByte);
      keep = _mm256_andnot_si256(_mm256_cmpeq_epi32(mark, _mm256_setzero_si256()), keep);
    }
    const unsigned mask = unsigned(_mm256_movemask_ps(_mm256_castsi256_ps(keep)));
    if (!mask) continue;
    const __m256i perm = _mm256_load_si256(reinterpret_cast<const __m256i*>(kCompress.perm[mask]));
    const __m256i c = _mm256_add_epi32(keys, _mm256_add_epi32(_mm256_mullo_epi32(row, cols), col));
    _mm256_storeu_si256(reinterpret_cast<__m256i*>(slot + n), _mm256_permutevar8x32_epi32(_mm256_add_epi32(_mm256_set1_epi32(int(uint32_t(j))), lane), perm));
    _mm256_storeu_si256(reinterpret_cast<__m256i*>(cell + n), _mm256_permutevar8x32_epi32(c, perm));
    n += size_t(__builtin_popcount(mask));
  }
  return n;
}
size_t lensLayerCellsAvx2(const LensShear& s, const float* x, const float* y, const float* u, const float* v, const float* depth, const LensRuns& runs,
                          uint32_t key, uint32_t* slot, uint32_t* cell, size_t n) {
  return s.tileUsed ? lensLayerCellsAvx2T<true>(s, x, y, u, v, depth, runs, key, slot, cell, n)
                    : lensLayerCellsAvx2T<false>(s, x, y, u, v, depth, runs, key, slot, cell, n);
}

// sortByCell()'s cell of every candidate: MovingBox's u (insideAtOwnTime()'s operations), then
// the compensated position's cell, clamped to the grid (a NaN clamps to the last cell: max and
// min return their second operand). Eight and sixteen at a time.
void cellsOfAvx2(const CellGrid& g, const float* t, const float* x, const float* y, size_t n, uint16_t* cellOf) {
  const __m256 thetaA = _mm256_set1_ps(g.thetaA), invLen = _mm256_set1_ps(g.invLen), one = _mm256_set1_ps(1.f), zero = _mm256_setzero_ps();
  const __m256 dx = _mm256_set1_ps(g.dx), dy = _mm256_set1_ps(g.dy), gx = _mm256_set1_ps(g.x0), gy = _mm256_set1_ps(g.y0), inv = _mm256_set1_ps(g.invSize);
  const __m256 maxCol = _mm256_set1_ps(float(g.cols - 1)), maxRow = _mm256_set1_ps(float(g.rows - 1)), cols = _mm256_set1_ps(float(g.cols));
  for (size_t i = 0; i < n; i += 8) {
    const __m256 u = _mm256_min_ps(one, _mm256_max_ps(zero, _mm256_mul_ps(_mm256_sub_ps(_mm256_loadu_ps(t + i), thetaA), invLen)));
    const __m256 cx = _mm256_min_ps(
        _mm256_max_ps(_mm256_floor_ps(_mm256_mul_ps(_mm256_sub_ps(_mm256_sub_ps(_mm256_loadu_ps(x + i), _mm256_mul_ps(u, dx)), gx), inv)), zero), maxCol);
    const __m256 cy = _mm256_min_ps(
        _mm256_max_ps(_mm256_floor_ps(_mm256_mul_ps(_mm256_sub_ps(_mm256_sub_ps(_mm256_loadu_ps(y + i), _mm256_mul_ps(u, dy)), gy), inv)), zero), maxRow);
    const __m256i cell = _mm256_cvttps_epi32(_mm256_add_ps(_mm256_mul_ps(cy, cols), cx));  // exact: cells < 2^16
    const __m128i packed = _mm_packus_epi32(_mm256_castsi256_si128(cell), _mm256_extracti128_si256(cell, 1));
    _mm_storeu_si128(reinterpret_cast<__m128i*>(cellOf + i), packed);
  }
}

}  // namespace

const IsaKernels kAvx2Kernels = {gatherInBoxAvx2, gatherStrataAvx2,           filterCandidatesAvx2,     cellsOfAvx2, avx2::projectLerped, avx2::stillAreas, avx2::lensDraws, avx2::cornerRange, avx2::nearestDepth, linearEdgesAvx2,
                                 fixedEdgesAvx2,  avx2::stillLensEdges, testLinearEdgesAvx2<kMovingEdges>, testLinearEdgesAvx2<kFixedEdges>, testLinearEdgesAvx2<kLensEdges>,
                                 gatherLensCellsAvx2, testMovingLensAvx2, lensLayerCellsAvx2};

}  // namespace reshutter::resample::kernels
