// The vector kernels for AVX-512 (F, VL, BW, DQ, with BMI2): sample gathering (sixteen lanes, as
// four row segments of up to four samples; the lens gather as row segments of sixteen), the exact
// coverage test (eight candidates), the edge set-up and the vertex projection (eight double lanes),
// the AVX2 kernels' operations lane for lane; the chunk set-up kernels are the AVX2 ones
// (simd_avx2_setup.cpp). This file alone is compiled with the AVX-512 flags; simd_dispatch.cpp
// calls it only on CPUs that run it. See simd_isa.h for what it may include.
#include <cmath>

#include "resample/simd_intrinsics.h"
#include "resample/simd_isa.h"

namespace reshutter::resample::kernels {
namespace {

// The moving gather with sixteen lanes, as four row segments of up to four samples. Same box and
// depth tests, same operations in the same order per lane as the AVX2 gathers, so the same
// candidates (in an order of their own); mask registers replace movemask and the permutation
// table, and compress stores need no branch on an empty vector.

struct BoxLanes512 {
  __m512 thetaA, invLen, x0, dx0, x1, dx1, y0, dy0, y1, dy1;
};
inline BoxLanes512 boxLanes512(const MovingBox& b) {
  return {_mm512_set1_ps(b.thetaA), _mm512_set1_ps(b.invLen), _mm512_set1_ps(b.x0),  _mm512_set1_ps(b.dx0), _mm512_set1_ps(b.x1),
          _mm512_set1_ps(b.dx1),    _mm512_set1_ps(b.y0),     _mm512_set1_ps(b.dy0), _mm512_set1_ps(b.y1),  _mm512_set1_ps(b.dy1)};
}
// insideFixed() on sixteen lanes, among the lanes of `live`.
inline __mmask16 insideFixed512(__mmask16 live, const BoxLanes512& b, __m512 x, __m512 y) {
  __mmask16 in = _mm512_mask_cmp_ps_mask(live, x, b.x0, _CMP_GE_OQ);
  in = _mm512_mask_cmp_ps_mask(in, x, b.x1, _CMP_LE_OQ);
  in = _mm512_mask_cmp_ps_mask(in, y, b.y0, _CMP_GE_OQ);
  return _mm512_mask_cmp_ps_mask(in, y, b.y1, _CMP_LE_OQ);
}
// insideAtOwnTime()'s operations on sixteen lanes, among the lanes of `live`.
inline __mmask16 insideAtOwnTime512(__mmask16 live, const BoxLanes512& b, __m512 t, __m512 x, __m512 y) {
  const __m512 u = _mm512_min_ps(_mm512_set1_ps(1.f), _mm512_max_ps(_mm512_setzero_ps(), _mm512_mul_ps(_mm512_sub_ps(t, b.thetaA), b.invLen)));
  __mmask16 in = _mm512_mask_cmp_ps_mask(live, x, _mm512_add_ps(b.x0, _mm512_mul_ps(u, b.dx0)), _CMP_GE_OQ);
  in = _mm512_mask_cmp_ps_mask(in, x, _mm512_add_ps(b.x1, _mm512_mul_ps(u, b.dx1)), _CMP_LE_OQ);
  in = _mm512_mask_cmp_ps_mask(in, y, _mm512_add_ps(b.y0, _mm512_mul_ps(u, b.dy0)), _CMP_GE_OQ);
  return _mm512_mask_cmp_ps_mask(in, y, _mm512_add_ps(b.y1, _mm512_mul_ps(u, b.dy1)), _CMP_LE_OQ);
}

// Appends the lanes of k (index, time, position) to `out` from n, every lane stored whole (a
// compress straight to memory is slow on AMD's cores); returns the new count.
inline size_t appendCompressed512(const Candidates& out, size_t n, __mmask16 k, __m512i idx, __m512 t, __m512 x, __m512 y) {
  _mm512_storeu_si512(out.index + n, _mm512_maskz_compress_epi32(k, idx));
  _mm512_storeu_ps(out.t + n, _mm512_maskz_compress_ps(k, t));
  _mm512_storeu_ps(out.x + n, _mm512_maskz_compress_ps(k, x));
  _mm512_storeu_ps(out.y + n, _mm512_maskz_compress_ps(k, y));
  return n + size_t(__builtin_popcount(unsigned(k)));
}

// Row segments waiting for a vector: segment k covers samples start[k] .. start[k] + 3, of which
// the set bits of bits[k] (at most four) are in the range.
struct Segments {
  static constexpr size_t kCap = 512;     // a multiple of four; 64 strata of four rows fill 256
  alignas(64) uint32_t start[kCap + 16];  // the compresses store sixteen lanes
  alignas(64) uint8_t bits[kCap + 16];
  size_t count = 0;
};

// Tests segments 4g .. 4g + 3 (one vector) and appends the survivors to `out` from n; every
// lane is stored and the count advances by the mask (whether a vector holds a candidate is data
// the predictor cannot learn). `out` needs room for n + 16 entries.
template <bool kFixed = false>
inline size_t appendSegmentVector(const BoxLanes512& b, const SampleRows& r, __m512 zCull, const Segments& seg, size_t g, const Candidates& out, size_t n) {
  const uint32_t* at = seg.start + g;
  auto rows4 = [&](const float* v) {
    __m512 a = _mm512_zextps128_ps512(_mm_loadu_ps(v + at[0]));
    a = _mm512_insertf32x4(a, _mm_loadu_ps(v + at[1]), 1);
    a = _mm512_insertf32x4(a, _mm_loadu_ps(v + at[2]), 2);
    return _mm512_insertf32x4(a, _mm_loadu_ps(v + at[3]), 3);
  };
  uint32_t bytes;
  __builtin_memcpy(&bytes, seg.bits + g, 4);
  const __mmask16 live = __mmask16(_pext_u32(bytes, 0x0F0F0F0Fu));
  const __m512 t = rows4(r.st), x = rows4(r.sx), y = rows4(r.sy);
  const __mmask16 visible = _mm512_mask_cmp_ps_mask(live, rows4(r.depth), zCull, _CMP_GT_OQ);
  const __mmask16 k = kFixed ? insideFixed512(visible, b, x, y) : insideAtOwnTime512(visible, b, t, x, y);
  const __m512i spread = _mm512_setr_epi32(0, 0, 0, 0, 1, 1, 1, 1, 2, 2, 2, 2, 3, 3, 3, 3);
  const __m512i quad = _mm512_setr_epi32(0, 1, 2, 3, 0, 1, 2, 3, 0, 1, 2, 3, 0, 1, 2, 3);
  const __m512i idx = _mm512_add_epi32(_mm512_permutexvar_epi32(spread, _mm512_zextsi128_si512(_mm_load_si128(reinterpret_cast<const __m128i*>(at)))), quad);
  return appendCompressed512(out, n, k, idx, t, x, y);
}

// Tests the consecutive samples at .. at + 15 among the lanes of `live` (kFixed: insideFixed())
// and appends the survivors to `out` from n: a row run's vector, in either gather.
template <bool kFixed = false>
inline size_t appendRun512(const BoxLanes512& b, const SampleRows& r, __m512 zCull, size_t at, __mmask16 live, const Candidates& out, size_t n) {
  const __m512 t = _mm512_maskz_loadu_ps(live, r.st + at), x = _mm512_maskz_loadu_ps(live, r.sx + at), y = _mm512_maskz_loadu_ps(live, r.sy + at);
  const __mmask16 visible = _mm512_mask_cmp_ps_mask(live, _mm512_maskz_loadu_ps(live, r.depth + at), zCull, _CMP_GT_OQ);
  const __mmask16 k = kFixed ? insideFixed512(visible, b, x, y) : insideAtOwnTime512(visible, b, t, x, y);
  const __m512i idx = _mm512_add_epi32(_mm512_set1_epi32(int(uint32_t(at))), _mm512_setr_epi32(0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14, 15));
  return appendCompressed512(out, n, k, idx, t, x, y);
}

// Tests every whole vector of waiting segments; keeps the (at most three) left over, or with
// `all` pads them to a vector and tests them too.
template <bool kFixed = false>
inline size_t flushSegments(const BoxLanes512& b, const SampleRows& r, __m512 zCull, Segments& seg, bool all, const Candidates& out, size_t n) {
  size_t whole = seg.count & ~size_t(3);
  if (all && whole < seg.count) {
    for (size_t k = seg.count; k < whole + 4; ++k) seg.start[k] = 0, seg.bits[k] = 0;  // sample 0 exists; no lane live
    whole += 4;
  }
  for (size_t g = 0; g < whole; g += 4) n = appendSegmentVector<kFixed>(b, r, zCull, seg, g, out, n);
  const size_t left = seg.count > whole ? seg.count - whole : 0;
  for (size_t k = 0; k < left; ++k) seg.start[k] = seg.start[whole + k], seg.bits[k] = seg.bits[whole + k];
  seg.count = left;
  return n;
}

// A fixed box of at most two rows of two pixels (a static micropolygon's, nearly always) over
// four sample planes in one vector: plane q's first row in lanes 4q, 4q+1 and its second row
// (`second` samples further; 0 repeats the first, masked off by `lanes`) in lanes 4q+2, 4q+3.
inline size_t appendPlaneQuad(const BoxLanes512& b, const SampleRows& r, __m512 zCull, size_t first, size_t second, __mmask16 lanes, const Candidates& out,
                              size_t n) {
  const size_t ps = r.planeStride;
  auto quad = [&](const float* v) {
    auto plane = [&](size_t at) {
      return _mm_loadh_pi(_mm_castsi128_ps(_mm_loadl_epi64(reinterpret_cast<const __m128i*>(v + at))), reinterpret_cast<const __m64*>(v + at + second));
    };
    __m512 a = _mm512_zextps128_ps512(plane(first));
    a = _mm512_insertf32x4(a, plane(first + ps), 1);
    a = _mm512_insertf32x4(a, plane(first + 2 * ps), 2);
    return _mm512_insertf32x4(a, plane(first + 3 * ps), 3);
  };
  const __m512 x = quad(r.sx), y = quad(r.sy);
  const __mmask16 visible = _mm512_mask_cmp_ps_mask(lanes, quad(r.depth), zCull, _CMP_GT_OQ);
  const __mmask16 k = insideFixed512(visible, b, x, y);
  const __m512 t = quad(r.st);
  const int s2 = int(second), p1 = int(ps);
  const __m512i idx = _mm512_add_epi32(_mm512_set1_epi32(int(uint32_t(first))),
                                       _mm512_setr_epi32(0, 1, s2, s2 + 1, p1, p1 + 1, p1 + s2, p1 + s2 + 1, 2 * p1, 2 * p1 + 1, 2 * p1 + s2, 2 * p1 + s2 + 1,
                                                         3 * p1, 3 * p1 + 1, 3 * p1 + s2, 3 * p1 + s2 + 1));
  return appendCompressed512(out, n, k, idx, t, x, y);
}

// gatherInBox() with sixteen lanes: the rows of every plane as segments of up to four samples,
// or four planes of a small fixed box at a time.
template <bool kFixed>
size_t gatherRows512(const BoxLanes512& b, const SampleRows& r, const Candidates& out, size_t n) {
  const __m512 zCull = _mm512_set1_ps(r.zCull);
  if constexpr (kFixed) {
    if (r.cols <= 2 && r.rows <= 2 && !r.rowGroup && r.planes >= 4) {
      const unsigned colBits = (1u << r.cols) - 1, planeBits = r.rows == 2 ? colBits | colBits << 2 : colBits;
      const size_t second = r.rows == 2 ? r.stride : 0;
      const __mmask16 all = __mmask16(planeBits * 0x1111u);
      int plane = 0;
      for (; plane + 4 <= r.planes; plane += 4) n = appendPlaneQuad(b, r, zCull, r.first + size_t(plane) * r.planeStride, second, all, out, n);
      if (plane < r.planes) {
        // The last one to three planes: the vector ends at the last plane, its first lanes
        // (planes already taken) masked off.
        const int skip = plane + 4 - r.planes;
        n = appendPlaneQuad(b, r, zCull, r.first + size_t(r.planes - 4) * r.planeStride, second, __mmask16(all & (0xFFFFu << (4 * skip))), out, n);
      }
      return n;
    }
  }
  if (r.planes == 1 && r.cols >= 8) {
    // Long rows (pixel-major samples: a row of pixels is one run of their samples): sixteen
    // consecutive samples a vector, the row's end masked off.
    for (int row = 0; row < r.rows; ++row) {
      if (r.rowGroup && r.rowGroup[row] != r.group) continue;
      const size_t base = r.first + size_t(row) * r.stride;
      for (int c = 0; c < r.cols; c += 16) {
        const __mmask16 live = r.cols - c >= 16 ? __mmask16(0xFFFF) : __mmask16((1u << (r.cols - c)) - 1);
        n = appendRun512<kFixed>(b, r, zCull, base + size_t(c), live, out, n);
      }
    }
    return n;
  }
  Segments seg;
  for (int plane = 0; plane < r.planes; ++plane) {
    const size_t planeBase = r.first + size_t(plane) * r.planeStride;
    for (int row = 0; row < r.rows; ++row) {
      if (r.rowGroup && r.rowGroup[row] != r.group) continue;
      const size_t rowStart = planeBase + size_t(row) * r.stride;
      for (int col = 0; col < r.cols; col += 4) {
        if (seg.count >= Segments::kCap) n = flushSegments<kFixed>(b, r, zCull, seg, false, out, n);
        seg.start[seg.count] = uint32_t(rowStart + size_t(col));
        seg.bits[seg.count] = uint8_t((1u << minInt(4, r.cols - col)) - 1);
        ++seg.count;
      }
    }
  }
  return flushSegments<kFixed>(b, r, zCull, seg, true, out, n);
}

size_t gatherInBoxAvx512(const SampleRows& rows, const MovingBox& box, const Candidates& candidates, size_t n) {
  const SampleRows r = rows;
  const Candidates out = candidates;
  if (box.invLen == 0.f && box.dx0 == 0.f && box.dx1 == 0.f && box.dy0 == 0.f && box.dy1 == 0.f) return gatherRows512<true>(boxLanes512(box), r, out, n);
  return gatherRows512<false>(boxLanes512(box), r, out, n);
}

// filterCandidates() with sixteen lanes.
size_t filterCandidatesAvx512(const Candidates& in, size_t begin, size_t end, const MovingBox& box, const Candidates& out, size_t n) {
  const BoxLanes512 b = boxLanes512(box);
  for (size_t k = begin; k < end; k += 16) {
    const __mmask16 live = end - k >= 16 ? __mmask16(0xFFFF) : __mmask16((1u << (end - k)) - 1);
    const __m512i idx = _mm512_loadu_si512(in.index + k);
    const __m512 t = _mm512_loadu_ps(in.t + k), x = _mm512_loadu_ps(in.x + k), y = _mm512_loadu_ps(in.y + k);
    const __mmask16 keep = insideAtOwnTime512(live, b, t, x, y);
    n = appendCompressed512(out, n, keep, idx, t, x, y);
  }
  return n;
}

size_t gatherStrataAvx512(const SampleRows& region, const StrataSpans& sp, const MovingBox& b, const Candidates& out) {
  // Pixel ranges of every stratum, sixteen at a time: gatherStrataAvx2()'s operations. Strata of
  // at most four rows of four pixels (nearly all, for small micropolygons) become row segments
  // right here, still sixteen at a time: each row's starts packed with a compress.
  alignas(64) int first[64], cols[64], rows[64], rowOffset[64];
  uint64_t wide = 0;
  const int N = sp.strata;
  const __m512 m = _mm512_set1_ps(sp.margin);
  const __m512 lox = _mm512_set1_ps(float(sp.x0)), hix = _mm512_set1_ps(float(sp.x0 + sp.w));
  const __m512 loy = _mm512_set1_ps(float(sp.y0)), hiy = _mm512_set1_ps(float(sp.y0 + sp.h));
  const __m512 one = _mm512_set1_ps(1.f);
  const __m512i ione = _mm512_set1_epi32(1), izero = _mm512_setzero_si512(), four = _mm512_set1_epi32(4);
  const __m512i regionX = _mm512_set1_epi32(sp.x0), regionY = _mm512_set1_epi32(sp.y0);
  const __m512i planeStride = _mm512_set1_epi32(int(region.planeStride)), stride = _mm512_set1_epi32(int(region.stride));
  const __m512i base = _mm512_set1_epi32(int(region.first));
  const BoxLanes512 lanes = boxLanes512(b);
  // Alternating groups (fields): a small stratum's rows of the other group get no segment.
  const bool alternate = region.rowGroup && region.rowParity >= 0;
  const __m512i parity = _mm512_set1_epi32(region.rowParity), group = _mm512_set1_epi32(region.group);
  Segments seg;
  for (int s = 0; s < N; s += 16) {
    const __mmask16 valid = N - s >= 16 ? __mmask16(0xFFFF) : __mmask16((1u << (N - s)) - 1);
    const __m512 u0 = _mm512_maskz_loadu_ps(valid, sp.u0 + s), u1 = _mm512_maskz_loadu_ps(valid, sp.u1 + s);
    const __m512 ax0 = _mm512_min_ps(_mm512_add_ps(lanes.x0, _mm512_mul_ps(u0, lanes.dx0)), _mm512_add_ps(lanes.x0, _mm512_mul_ps(u1, lanes.dx0)));
    const __m512 ax1 = _mm512_max_ps(_mm512_add_ps(lanes.x1, _mm512_mul_ps(u0, lanes.dx1)), _mm512_add_ps(lanes.x1, _mm512_mul_ps(u1, lanes.dx1)));
    const __m512 ay0 = _mm512_min_ps(_mm512_add_ps(lanes.y0, _mm512_mul_ps(u0, lanes.dy0)), _mm512_add_ps(lanes.y0, _mm512_mul_ps(u1, lanes.dy0)));
    const __m512 ay1 = _mm512_max_ps(_mm512_add_ps(lanes.y1, _mm512_mul_ps(u0, lanes.dy1)), _mm512_add_ps(lanes.y1, _mm512_mul_ps(u1, lanes.dy1)));
    const __m512 cx0 = _mm512_min_ps(_mm512_max_ps(_mm512_sub_ps(ax0, m), lox), hix);
    const __m512 cy0 = _mm512_min_ps(_mm512_max_ps(_mm512_sub_ps(ay0, m), loy), hiy);
    const __m512 cx1 = _mm512_min_ps(_mm512_max_ps(_mm512_add_ps(ax1, m), _mm512_sub_ps(lox, one)), _mm512_sub_ps(hix, one));
    const __m512 cy1 = _mm512_min_ps(_mm512_max_ps(_mm512_add_ps(ay1, m), _mm512_sub_ps(loy, one)), _mm512_sub_ps(hiy, one));
    const __m512i px0 = _mm512_cvttps_epi32(_mm512_roundscale_ps(cx0, _MM_FROUND_TO_NEG_INF | _MM_FROUND_NO_EXC));
    const __m512i py0 = _mm512_cvttps_epi32(_mm512_roundscale_ps(cy0, _MM_FROUND_TO_NEG_INF | _MM_FROUND_NO_EXC));
    const __m512i px1 = _mm512_cvttps_epi32(_mm512_roundscale_ps(cx1, _MM_FROUND_TO_NEG_INF | _MM_FROUND_NO_EXC));
    const __m512i py1 = _mm512_cvttps_epi32(_mm512_roundscale_ps(cy1, _MM_FROUND_TO_NEG_INF | _MM_FROUND_NO_EXC));
    const __m512i c = _mm512_add_epi32(_mm512_sub_epi32(px1, px0), ione), r = _mm512_add_epi32(_mm512_sub_epi32(py1, py0), ione);
    const __m512i dy = _mm512_sub_epi32(py0, regionY);
    const __m512i plane = _mm512_add_epi32(_mm512_set1_epi32(s), _mm512_setr_epi32(0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14, 15));
    __m512i at = _mm512_add_epi32(_mm512_add_epi32(base, _mm512_mullo_epi32(plane, planeStride)),
                                  _mm512_add_epi32(_mm512_mullo_epi32(dy, stride), _mm512_sub_epi32(px0, regionX)));
    const __mmask16 live = _mm512_mask_cmpgt_epi32_mask(_mm512_cmpgt_epi32_mask(c, izero) & valid, r, izero);
    // Groups that do not alternate: the loop below skips the other group's rows, so every
    // stratum takes it.
    const __mmask16 fits = region.rowGroup && !alternate ? __mmask16(0) : _mm512_mask_cmple_epi32_mask(_mm512_mask_cmple_epi32_mask(live, c, four), r, four);
    const __mmask16 evenRows = alternate ? _mm512_cmpeq_epi32_mask(_mm512_and_si512(_mm512_add_epi32(dy, parity), ione), group) : __mmask16(0xFFFF);
    const __mmask16 oddRows = alternate ? __mmask16(~evenRows) : __mmask16(0xFFFF);
    wide |= uint64_t(live & ~fits) << s;
    if (live & ~fits) {
      _mm512_store_si512(first + s, at);
      _mm512_store_si512(cols + s, c);
      _mm512_store_si512(rows + s, r);
      _mm512_store_si512(rowOffset + s, dy);
    }
    // Row k of every small stratum that has one: its start and its columns' lane bits.
    const __m512i colBits = _mm512_sub_epi32(_mm512_sllv_epi32(ione, _mm512_min_epi32(c, four)), ione);
    for (int k = 0; k < 4; ++k) {
      const __mmask16 has = _mm512_mask_cmpgt_epi32_mask(fits & (k % 2 ? oddRows : evenRows), r, _mm512_set1_epi32(k));
      _mm512_storeu_si512(seg.start + seg.count, _mm512_maskz_compress_epi32(has, at));
      _mm_storeu_si128(reinterpret_cast<__m128i*>(seg.bits + seg.count), _mm512_cvtepi32_epi8(_mm512_maskz_compress_epi32(has, colBits)));
      seg.count += size_t(__builtin_popcount(unsigned(has)));
      at = _mm512_add_epi32(at, stride);
    }
  }
  const Candidates list = out;
  const SampleRows rr = region;
  const __m512 zCull = _mm512_set1_ps(region.zCull);
  size_t n = 0;
  for (uint64_t left = wide; left; left &= left - 1) {
    const int s = __builtin_ctzll(left);
    for (int row = 0; row < rows[s]; ++row) {
      if (region.rowGroup && region.rowGroup[rowOffset[s] + row] != region.group) continue;
      const uint32_t rowStart = uint32_t(first[s]) + uint32_t(row) * uint32_t(region.stride);
      int col = 0;
      // Rows of sixteen or more (a run's stratum box is often a grid's row of micropolygons
      // wide): whole vectors of consecutive samples, the last few columns as segments.
      for (; cols[s] - col >= 16; col += 16) n = appendRun512(lanes, rr, zCull, rowStart + uint32_t(col), __mmask16(0xFFFF), list, n);
      for (; col < cols[s]; col += 4) {
        if (seg.count >= Segments::kCap) n = flushSegments(lanes, rr, zCull, seg, false, list, n);
        seg.start[seg.count] = rowStart + uint32_t(col);
        seg.bits[seg.count] = uint8_t((1u << minInt(4, cols[s] - col)) - 1);
        ++seg.count;
      }
    }
  }
  return flushSegments(lanes, rr, zCull, seg, true, list, n);
}

// linearEdges() and fixedEdges() in one pass of eight lanes: lanes 0-3 pair corner j with corner
// j + 1 (edges 01 12 23 30), lanes 4-7 with corner j + 2 (lane 4 is edge 02, the rest padding) -
// the two passes of linearEdgesAvx2(), lane for lane.
struct Lanes3x8 {
  __m512d x, y, z;
};
inline Lanes3x8 crossLanes512(const Lanes3x8& a, const Lanes3x8& b) {
  return {_mm512_sub_pd(_mm512_mul_pd(a.y, b.z), _mm512_mul_pd(a.z, b.y)), _mm512_sub_pd(_mm512_mul_pd(a.z, b.x), _mm512_mul_pd(a.x, b.z)),
          _mm512_sub_pd(_mm512_mul_pd(a.x, b.y), _mm512_mul_pd(a.y, b.x))};
}
// Component k of the corners, lane l = corner l mod 4 (first) or the corner it pairs with.
inline __m512d cornerLanes(const float* const p[4], int k, bool partner) {
  const __m128 c = _mm_setr_ps(p[0][k], p[1][k], p[2][k], p[3][k]);
  const __m256 lanes = partner ? _mm256_permutevar8x32_ps(_mm256_castps128_ps256(c), _mm256_setr_epi32(1, 2, 3, 0, 2, 3, 0, 1))
                               : _mm256_permutevar8x32_ps(_mm256_castps128_ps256(c), _mm256_setr_epi32(0, 1, 2, 3, 0, 1, 2, 3));
  return _mm512_cvtps_pd(lanes);
}
template <bool kFixed>
void edgesAvx512(const float* const at[4], const float* const to[4], const RasterScale& m, LinearEdges& out) {
  const __m512d one = _mm512_set1_pd(1.0), zero = _mm512_setzero_pd();
  const Lanes3x8 A{cornerLanes(at, 0, false), cornerLanes(at, 1, false), m.perspective ? cornerLanes(at, 2, false) : one};
  const Lanes3x8 Ab{cornerLanes(at, 0, true), cornerLanes(at, 1, true), m.perspective ? cornerLanes(at, 2, true) : one};
  const __m512d invAx = _mm512_set1_pd(m.invAx), invAy = _mm512_set1_pd(m.invAy), bx = _mm512_set1_pd(m.bx), by = _mm512_set1_pd(m.by);
  Lanes3x8 powers[3];
  powers[0] = crossLanes512(A, Ab);
  if constexpr (!kFixed) {
    const Lanes3x8 D{_mm512_sub_pd(cornerLanes(to, 0, false), A.x), _mm512_sub_pd(cornerLanes(to, 1, false), A.y),
                     m.perspective ? _mm512_sub_pd(cornerLanes(to, 2, false), A.z) : zero};
    const Lanes3x8 Db{_mm512_sub_pd(cornerLanes(to, 0, true), Ab.x), _mm512_sub_pd(cornerLanes(to, 1, true), Ab.y),
                      m.perspective ? _mm512_sub_pd(cornerLanes(to, 2, true), Ab.z) : zero};
    const Lanes3x8 c1a = crossLanes512(A, Db), c1b = crossLanes512(D, Ab);
    powers[1] = {_mm512_add_pd(c1a.x, c1b.x), _mm512_add_pd(c1a.y, c1b.y), _mm512_add_pd(c1a.z, c1b.z)};
    powers[2] = crossLanes512(D, Db);
  }
  for (int p = 0; p < (kFixed ? 1 : 3); ++p) {
    const __m512d ex = _mm512_mul_pd(powers[p].x, invAx), ey = _mm512_mul_pd(powers[p].y, invAy);
    _mm512_storeu_pd(out.c[3 * p], ex);
    _mm512_storeu_pd(out.c[3 * p + 1], ey);
    _mm512_storeu_pd(out.c[3 * p + 2], _mm512_sub_pd(_mm512_sub_pd(powers[p].z, _mm512_mul_pd(ex, bx)), _mm512_mul_pd(ey, by)));
  }
}

// The edge test with eight candidates per iteration: testLinearEdgesAvx2()'s operations, lane
// for lane, in AVX-512 (doubles in zmm, the floats of eight lanes in ymm).
template <int kMode>
inline __m512d edgeValue512(const LinearEdges& E, int e, __m512d f, __m512d g, __m512d rx, __m512d ry) {
  __m512d c[9];
  for (int k = 0; k < (kMode == kFixedEdges ? 3 : 9); ++k) c[k] = _mm512_set1_pd(E.c[k][e]);
  if constexpr (kMode == kFixedEdges) return _mm512_add_pd(_mm512_add_pd(_mm512_mul_pd(rx, c[0]), _mm512_mul_pd(ry, c[1])), c[2]);
  if constexpr (kMode == kLensEdges) {
    const __m512d ex = _mm512_add_pd(_mm512_add_pd(c[0], _mm512_mul_pd(f, c[3])), _mm512_mul_pd(g, c[6]));
    const __m512d ey = _mm512_add_pd(_mm512_add_pd(c[1], _mm512_mul_pd(f, c[4])), _mm512_mul_pd(g, c[7]));
    const __m512d ez = _mm512_add_pd(_mm512_add_pd(c[2], _mm512_mul_pd(f, c[5])), _mm512_mul_pd(g, c[8]));
    return _mm512_add_pd(_mm512_add_pd(_mm512_mul_pd(rx, ex), _mm512_mul_pd(ry, ey)), ez);
  }
  const __m512d ex = _mm512_add_pd(c[0], _mm512_mul_pd(f, _mm512_add_pd(c[3], _mm512_mul_pd(f, c[6]))));
  const __m512d ey = _mm512_add_pd(c[1], _mm512_mul_pd(f, _mm512_add_pd(c[4], _mm512_mul_pd(f, c[7]))));
  const __m512d ez = _mm512_add_pd(c[2], _mm512_mul_pd(f, _mm512_add_pd(c[5], _mm512_mul_pd(f, c[8]))));
  return _mm512_add_pd(_mm512_add_pd(_mm512_mul_pd(rx, ex), _mm512_mul_pd(ry, ey)), ez);
}

struct TriangleMasks512 {
  __mmask8 hit, tie;
  __m256 b[3];
};
// triangleMasks() on eight lanes: innerSide(a, flip) is (a > 0 and not flip) or (a < 0 and flip).
inline TriangleMasks512 triangleMasks512(__m512d a0, __m512d a1, __m512d a2, bool cullBack) {
  const __m512d zero = _mm512_setzero_pd();
  const __m512d S = _mm512_add_pd(_mm512_add_pd(a0, a1), a2);
  __mmask8 counts = _mm512_cmp_pd_mask(S, zero, _CMP_NEQ_UQ);
  if (cullBack) counts &= __mmask8(~_mm512_cmp_pd_mask(S, zero, _CMP_GT_OQ));
  const __mmask8 flip = _mm512_cmp_pd_mask(S, zero, _CMP_LT_OQ);
  auto inner = [&](__m512d a) { return __mmask8((_mm512_cmp_pd_mask(a, zero, _CMP_GT_OQ) & ~flip) | (_mm512_cmp_pd_mask(a, zero, _CMP_LT_OQ) & flip)); };
  const __mmask8 in = inner(a0) & inner(a1) & inner(a2);
  const __mmask8 anyZero = _mm512_cmp_pd_mask(a0, zero, _CMP_EQ_OQ) | _mm512_cmp_pd_mask(a1, zero, _CMP_EQ_OQ) | _mm512_cmp_pd_mask(a2, zero, _CMP_EQ_OQ);
  TriangleMasks512 m;
  m.hit = counts & in;
  m.tie = counts & anyZero;
  const __m512d inv = _mm512_div_pd(_mm512_set1_pd(1.0), S);
  m.b[0] = _mm512_cvtpd_ps(_mm512_mul_pd(a0, inv));
  m.b[1] = _mm512_cvtpd_ps(_mm512_mul_pd(a1, inv));
  m.b[2] = _mm512_cvtpd_ps(_mm512_mul_pd(a2, inv));
  return m;
}

// The rest of an edge test on eight lanes (decideLanes() in simd_avx2.cpp, lane for lane).
template <class EdgeB, class Depths>
inline __attribute__((always_inline)) size_t decideLanes512(__m512d e0, __m512d e1, __m512d e4, EdgeB edgeB, Depths depths, unsigned liveMask, bool triangle,
                                                            bool cullBack, size_t i, EdgeHit* hits, size_t h) {
  const __m512i sign = _mm512_set1_epi64(int64_t(0x8000000000000000ull));
  // Triangle A = (p0 p1 p2) with edges 12, 20 (= -02), 01.
  const TriangleMasks512 A = triangleMasks512(e1, _mm512_castsi512_pd(_mm512_xor_si512(_mm512_castpd_si512(e4), sign)), e0, cullBack);
  unsigned hitA = A.hit & liveMask, undecided = A.tie & liveMask, hitB = 0;
  TriangleMasks512 B{};
  const unsigned needB = liveMask & ~hitA & ~undecided;
  if (!triangle && needB) {
    // Triangle B = (p0 p2 p3) with edges 23, 30, 02.
    B = triangleMasks512(edgeB(2), edgeB(3), e4, cullBack);
    hitB = B.hit & needB;
    undecided |= B.tie & needB;
    hitB &= ~undecided;
  }
  const unsigned any = hitA | hitB | undecided;
  if (!any) return h;
  alignas(32) float bz[2][4][8];
  for (int k = 0; k < 3; ++k) _mm256_store_ps(bz[0][k], A.b[k]), _mm256_store_ps(bz[1][k], B.b[k]);
  __m256 zv[4];
  depths(zv);
  _mm256_store_ps(bz[0][3], _mm256_add_ps(_mm256_add_ps(_mm256_mul_ps(A.b[0], zv[0]), _mm256_mul_ps(A.b[1], zv[1])), _mm256_mul_ps(A.b[2], zv[2])));
  _mm256_store_ps(bz[1][3], _mm256_add_ps(_mm256_add_ps(_mm256_mul_ps(B.b[0], zv[0]), _mm256_mul_ps(B.b[1], zv[2])), _mm256_mul_ps(B.b[2], zv[3])));
  return writeEdgeHits<8>(bz, undecided, hitB, any, i, hits, h);
}

template <int kMode>
size_t testLinearEdgesAvx512(const EdgeTestSetup& s, const LinearEdges& E, size_t n, EdgeHit* hits) {
  const __m256 fOffset = _mm256_set1_ps(s.fOffset), fScale = _mm256_set1_ps(s.fScale), zero = _mm256_setzero_ps(), one = _mm256_set1_ps(1.f);
  const __m512d lensRadius = _mm512_set1_pd(s.lensRadius);
  __m256 zDelta[4], zStart[4];
  for (int j = 0; j < 4; ++j) zStart[j] = _mm256_set1_ps(s.za[j]), zDelta[j] = _mm256_set1_ps(s.zb[j] - s.za[j]);
  size_t h = 0;
  for (size_t i = 0; i < n; i += 8) {
    const size_t live = n - i < 8 ? n - i : 8;  // lanes past n read padding and are masked off
    __m256 f = zero;
    if constexpr (kMode == kMovingEdges) f = _mm256_min_ps(one, _mm256_max_ps(zero, _mm256_mul_ps(_mm256_add_ps(_mm256_loadu_ps(s.st + i), fOffset), fScale)));
    const __m512d fd = kMode == kLensEdges ? _mm512_mul_pd(lensRadius, _mm512_cvtps_pd(_mm256_loadu_ps(s.su + i))) : _mm512_cvtps_pd(f);
    const __m512d gd = kMode == kLensEdges ? _mm512_mul_pd(lensRadius, _mm512_cvtps_pd(_mm256_loadu_ps(s.sv + i))) : fd;
    const __m512d rx = _mm512_cvtps_pd(_mm256_loadu_ps(s.sx + i)), ry = _mm512_cvtps_pd(_mm256_loadu_ps(s.sy + i));
    const __m512d e0 = edgeValue512<kMode>(E, 0, fd, gd, rx, ry), e1 = edgeValue512<kMode>(E, 1, fd, gd, rx, ry), e4 = edgeValue512<kMode>(E, 4, fd, gd, rx, ry);
    auto depths = [&](__m256* zv) {
      for (int j = 0; j < 4; ++j) zv[j] = _mm256_add_ps(zStart[j], _mm256_mul_ps(f, zDelta[j]));
    };
    h = decideLanes512(e0, e1, e4, [&](int e) { return edgeValue512<kMode>(E, e, fd, gd, rx, ry); }, depths, (1u << live) - 1, s.triangle, s.cullBackFaces,
                       i, hits, h);
  }
  return h;
}

// testMovingLens() eight candidates at a time, the AVX2 kernel's operations lane for lane.
size_t testMovingLensAvx512(const MovingLensSetup& s, size_t n, EdgeHit* hits) {
  const __m512d radius = _mm512_set1_pd(s.lensRadius), invD = _mm512_set1_pd(s.invD), one = _mm512_set1_pd(1.0);
  const __m512d invAx = _mm512_set1_pd(s.scale.invAx), invAy = _mm512_set1_pd(s.scale.invAy), bx = _mm512_set1_pd(s.scale.bx), by = _mm512_set1_pd(s.scale.by);
  size_t h = 0;
  for (size_t i = 0; i < n; i += 8) {
    const size_t live = n - i < 8 ? n - i : 8;  // lanes past n read padding and are masked off
    const __m512d fd = _mm512_cvtps_pd(_mm256_loadu_ps(s.f + i));
    const __m512d Lx = _mm512_mul_pd(radius, _mm512_cvtps_pd(_mm256_loadu_ps(s.su + i))), Ly = _mm512_mul_pd(radius, _mm512_cvtps_pd(_mm256_loadu_ps(s.sv + i)));
    __m512d Sx[4], Sy[4], Sz[4];
    for (int j = 0; j < 4; ++j) {
      const __m512d px = _mm512_add_pd(_mm512_set1_pd(s.a[0][j]), _mm512_mul_pd(fd, _mm512_set1_pd(s.d[0][j])));
      const __m512d py = _mm512_add_pd(_mm512_set1_pd(s.a[1][j]), _mm512_mul_pd(fd, _mm512_set1_pd(s.d[1][j])));
      Sz[j] = _mm512_add_pd(_mm512_set1_pd(s.a[2][j]), _mm512_mul_pd(fd, _mm512_set1_pd(s.d[2][j])));
      const __m512d q = _mm512_sub_pd(_mm512_mul_pd(Sz[j], invD), one);
      Sx[j] = _mm512_add_pd(px, _mm512_mul_pd(Lx, q)), Sy[j] = _mm512_add_pd(py, _mm512_mul_pd(Ly, q));
    }
    const __m512d rx = _mm512_cvtps_pd(_mm256_loadu_ps(s.sx + i)), ry = _mm512_cvtps_pd(_mm256_loadu_ps(s.sy + i));
    auto edge = [&](int k) {
      const int a = kEdgeVerts[k][0], b = kEdgeVerts[k][1];
      const __m512d cx = _mm512_sub_pd(_mm512_mul_pd(Sy[a], Sz[b]), _mm512_mul_pd(Sz[a], Sy[b]));
      const __m512d cy = _mm512_sub_pd(_mm512_mul_pd(Sz[a], Sx[b]), _mm512_mul_pd(Sx[a], Sz[b]));
      const __m512d cz = _mm512_sub_pd(_mm512_mul_pd(Sx[a], Sy[b]), _mm512_mul_pd(Sy[a], Sx[b]));
      const __m512d ex = _mm512_mul_pd(cx, invAx), ey = _mm512_mul_pd(cy, invAy);
      const __m512d ez = _mm512_sub_pd(_mm512_sub_pd(cz, _mm512_mul_pd(ex, bx)), _mm512_mul_pd(ey, by));
      return _mm512_add_pd(_mm512_add_pd(_mm512_mul_pd(rx, ex), _mm512_mul_pd(ry, ey)), ez);
    };
    auto depths = [&](__m256* zv) {
      for (int j = 0; j < 4; ++j) zv[j] = _mm512_cvtpd_ps(Sz[j]);
    };
    h = decideLanes512(edge(0), edge(1), edge(4), edge, depths, (1u << live) - 1, s.triangle, s.cullBackFaces, i, hits, h);
  }
  return h;
}

void cellsOfAvx512(const CellGrid& g, const float* t, const float* x, const float* y, size_t n, uint16_t* cellOf) {
  const __m512 thetaA = _mm512_set1_ps(g.thetaA), invLen = _mm512_set1_ps(g.invLen), one = _mm512_set1_ps(1.f), zero = _mm512_setzero_ps();
  const __m512 dx = _mm512_set1_ps(g.dx), dy = _mm512_set1_ps(g.dy), gx = _mm512_set1_ps(g.x0), gy = _mm512_set1_ps(g.y0), inv = _mm512_set1_ps(g.invSize);
  const __m512 maxCol = _mm512_set1_ps(float(g.cols - 1)), maxRow = _mm512_set1_ps(float(g.rows - 1)), cols = _mm512_set1_ps(float(g.cols));
  constexpr int kFloor = _MM_FROUND_TO_NEG_INF | _MM_FROUND_NO_EXC;
  for (size_t i = 0; i < n; i += 16) {
    const __m512 u = _mm512_min_ps(one, _mm512_max_ps(zero, _mm512_mul_ps(_mm512_sub_ps(_mm512_loadu_ps(t + i), thetaA), invLen)));
    const __m512 cx = _mm512_min_ps(
        _mm512_max_ps(_mm512_roundscale_ps(_mm512_mul_ps(_mm512_sub_ps(_mm512_sub_ps(_mm512_loadu_ps(x + i), _mm512_mul_ps(u, dx)), gx), inv), kFloor), zero),
        maxCol);
    const __m512 cy = _mm512_min_ps(
        _mm512_max_ps(_mm512_roundscale_ps(_mm512_mul_ps(_mm512_sub_ps(_mm512_sub_ps(_mm512_loadu_ps(y + i), _mm512_mul_ps(u, dy)), gy), inv), kFloor), zero),
        maxRow);
    _mm256_storeu_si256(reinterpret_cast<__m256i*>(cellOf + i), _mm512_cvtepi32_epi16(_mm512_cvttps_epi32(_mm512_add_ps(_mm512_mul_ps(cy, cols), cx))));
  }
}

// LensBox::admits() sixteen sorted samples at a time, one masked load per run segment (no read
// past a run's end), the AVX2 kernel's operations lane for lane, and the admitted ones appended
// by compresses.
size_t gatherLensCellsAvx512(const LensCells& cells, size_t stride, const LensSearch* searches, size_t count, const LensBox& box, uint32_t* positions, size_t n) {
  const __m512 x0 = _mm512_set1_ps(box.x0), x1 = _mm512_set1_ps(box.x1), y0 = _mm512_set1_ps(box.y0), y1 = _mm512_set1_ps(box.y1);
  const __m512 cx0 = _mm512_set1_ps(box.cx0), cx1 = _mm512_set1_ps(box.cx1), cy0 = _mm512_set1_ps(box.cy0), cy1 = _mm512_set1_ps(box.cy1);
  const __m512 thetaA = _mm512_set1_ps(box.thetaA), invLen = _mm512_set1_ps(box.invLen), one = _mm512_set1_ps(1.f), zero = _mm512_setzero_ps();
  const __m512 mx0 = _mm512_set1_ps(box.mx0), mx1 = _mm512_set1_ps(box.mx1), my0 = _mm512_set1_ps(box.my0), my1 = _mm512_set1_ps(box.my1);
  // A box that does not lerp (invLen 0) has f = +0 for every sample, as the AVX2 kernel computes
  // it.
  const bool timed = box.invLen != 0.f;
  const __m512i lane = _mm512_setr_epi32(0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14, 15);
  *cells.examined += forEachLensRow(searches, count, stride, [&](uint32_t first, uint32_t last) {
    for (uint32_t at = first; at < last; at += 16) {
      const __mmask16 live = last - at >= 16 ? __mmask16(0xFFFF) : __mmask16((1u << (last - at)) - 1);
      const __m512 x = _mm512_maskz_loadu_ps(live, cells.x + at), y = _mm512_maskz_loadu_ps(live, cells.y + at);
      const __m512 u = _mm512_maskz_loadu_ps(live, cells.u + at), v = _mm512_maskz_loadu_ps(live, cells.v + at);
      const __m512 t = _mm512_maskz_loadu_ps(live, cells.t + at);
      __m512 f = zero;
      if (timed) f = _mm512_min_ps(_mm512_max_ps(_mm512_mul_ps(_mm512_sub_ps(t, thetaA), invLen), zero), one);
      const __m512 dx0 = _mm512_mul_ps(u, cx0), dx1 = _mm512_mul_ps(u, cx1), dy0 = _mm512_mul_ps(v, cy0), dy1 = _mm512_mul_ps(v, cy1);
      const __m512 xLo = _mm512_add_ps(_mm512_add_ps(x0, _mm512_mul_ps(f, mx0)), _mm512_min_ps(dx1, dx0));
      const __m512 xHi = _mm512_add_ps(_mm512_add_ps(x1, _mm512_mul_ps(f, mx1)), _mm512_max_ps(dx1, dx0));
      const __m512 yLo = _mm512_add_ps(_mm512_add_ps(y0, _mm512_mul_ps(f, my0)), _mm512_min_ps(dy1, dy0));
      const __m512 yHi = _mm512_add_ps(_mm512_add_ps(y1, _mm512_mul_ps(f, my1)), _mm512_max_ps(dy1, dy0));
      __mmask16 in = _mm512_mask_cmp_ps_mask(live, x, xLo, _CMP_GE_OQ);
      in = _mm512_mask_cmp_ps_mask(in, x, xHi, _CMP_LE_OQ);
      in = _mm512_mask_cmp_ps_mask(in, y, yLo, _CMP_GE_OQ);
      in = _mm512_mask_cmp_ps_mask(in, y, yHi, _CMP_LE_OQ);
      _mm512_storeu_si512(positions + n, _mm512_maskz_compress_epi32(in, _mm512_add_epi32(_mm512_set1_epi32(int(at)), lane)));
      n += size_t(__builtin_popcount(unsigned(in)));
    }
  });
  return n;
}

void fixedEdgesAvx512(const float* const at[4], const RasterScale& m, LinearEdges& out) { edgesAvx512<true>(at, at, m, out); }

// lensLayerCells() sixteen slots at a time, the AVX2 kernel's operations lane for lane; the
// kept lanes compressed in registers, then stored whole.
template <bool kTiles>
size_t lensLayerCellsAvx512T(const LensShear& s, const float* xs, const float* ys, const float* us, const float* vs, const float* depth, const LensRuns& runs,
                             uint32_t key, uint32_t* slot, uint32_t* cell, size_t n) {
  const __m512 cx = _mm512_set1_ps(s.cx), cy = _mm512_set1_ps(s.cy), gx = _mm512_set1_ps(s.x0), gy = _mm512_set1_ps(s.y0);
  const __m512 maxCol = _mm512_set1_ps(s.maxCol), maxRow = _mm512_set1_ps(s.maxRow), zero = _mm512_setzero_ps(), zMin = _mm512_set1_ps(s.zMin);
  const __m512 rowScale = _mm512_set1_ps(s.rowScale);
  const __m512i cols = _mm512_set1_epi32(int(s.cols)), tileCols = _mm512_set1_epi32(int(s.tileCols)), keys = _mm512_set1_epi32(int(key));
  const __m512i lane = _mm512_setr_epi32(0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14, 15), lowByte = _mm512_set1_epi32(0xFF);
  for (size_t r = 0; r < runs.n; ++r)  // each run, a vector at a time
  for (size_t first = runs.first[r], count = runs.count[r], i = 0; i < count; i += 16) {
    const size_t j = first + i;
    prefetchLensRuns(runs, r, i, count, xs, ys, us, vs, depth);
    const __mmask16 in = count - i >= 16 ? __mmask16(0xFFFF) : __mmask16((1u << (count - i)) - 1);
    const __m512 x = _mm512_maskz_loadu_ps(in, xs + j), y = _mm512_maskz_loadu_ps(in, ys + j), u = _mm512_maskz_loadu_ps(in, us + j);
    const __m512 v = _mm512_maskz_loadu_ps(in, vs + j), z = _mm512_maskz_loadu_ps(in, depth + j);
    const __m512i col = _mm512_cvttps_epi32(_mm512_min_ps(_mm512_max_ps(_mm512_sub_ps(_mm512_sub_ps(x, _mm512_mul_ps(cx, u)), gx), zero), maxCol));
    const __m512i row = _mm512_cvttps_epi32(_mm512_min_ps(_mm512_max_ps(_mm512_mul_ps(_mm512_sub_ps(_mm512_sub_ps(y, _mm512_mul_ps(cy, v)), gy), rowScale), zero), maxRow));
    __mmask16 keep = _mm512_mask_cmp_ps_mask(in, z, zMin, _CMP_GT_OQ);
    if constexpr (kTiles) {
      const __m512i tile = _mm512_add_epi32(_mm512_mullo_epi32(_mm512_srli_epi32(row, kLensTileShift), tileCols), _mm512_srli_epi32(col, kLensTileShift));
      const __m512i mark = _mm512_mask_i32gather_epi32(_mm512_setzero_si512(), keep, tile, s.tileUsed, 1);
      keep = _mm512_mask_test_epi32_mask(keep, mark, lowByte);
    }
    if (!keep) continue;
    const __m512i c = _mm512_add_epi32(keys, _mm512_add_epi32(_mm512_mullo_epi32(row, cols), col));
    _mm512_storeu_si512(slot + n, _mm512_maskz_compress_epi32(keep, _mm512_add_epi32(_mm512_set1_epi32(int(uint32_t(j))), lane)));
    _mm512_storeu_si512(cell + n, _mm512_maskz_compress_epi32(keep, c));
    n += size_t(__builtin_popcount(unsigned(keep)));
  }
  return n;
}
size_t lensLayerCellsAvx512(const LensShear& s, const float* x, const float* y, const float* u, const float* v, const float* depth, const LensRuns& runs,
                          uint32_t key, uint32_t* slot, uint32_t* cell, size_t n) {
  return s.tileUsed ? lensLayerCellsAvx512T<true>(s, x, y, u, v, depth, runs, key, slot, cell, n)
                    : lensLayerCellsAvx512T<false>(s, x, y, u, v, depth, runs, key, slot, cell, n);
}

// projectLerped() eight points at a time: the points read with two permutes of three vector
// loads (masked at the tail, so nothing past the last point is read), the projection in eight
// double lanes; the AVX2 kernel's operations lane for lane.
bool projectLerpedAvx512(const float* a, const float* b, float f, size_t n, const ProjectionScale& s, float* xo, float* yo, float* zo, float box[4]) {
  const __m256 fv = _mm256_set1_ps(f), nearClip = _mm256_set1_ps(s.nearClip), inf = _mm256_set1_ps(INFINITY), ninf = _mm256_set1_ps(-INFINITY);
  const __m512d ax = _mm512_set1_pd(s.ax), bx = _mm512_set1_pd(s.bx), ay = _mm512_set1_pd(s.ay), by = _mm512_set1_pd(s.by), one = _mm512_set1_pd(1.0);
  const __m512i ix = _mm512_setr_epi32(0, 3, 6, 9, 12, 15, 18, 21, 0, 0, 0, 0, 0, 0, 0, 0), iy = _mm512_add_epi32(ix, _mm512_set1_epi32(1)),
                iz = _mm512_add_epi32(ix, _mm512_set1_epi32(2));
  const bool lerp = a != b;  // b == a: p is a itself, as the AVX2 kernel leaves it
  __m256 lo_x = inf, lo_y = inf, hi_x = ninf, hi_y = ninf;
  unsigned bad = 0;
  for (size_t i = 0; i < n; i += 8) {
    const size_t count = n - i < 8 ? n - i : 8, floats = 3 * count;
    const __mmask8 live = __mmask8((1u << count) - 1);
    const __mmask16 first = floats >= 16 ? __mmask16(0xFFFF) : __mmask16((1u << floats) - 1);
    const __mmask16 rest = floats > 16 ? __mmask16((1u << (floats - 16)) - 1) : __mmask16(0);
    auto points = [&](const float* p, __m256 q[3]) {
      const __m512 lo = _mm512_maskz_loadu_ps(first, p + 3 * i), hi = _mm512_maskz_loadu_ps(rest, p + 3 * i + 16);
      q[0] = _mm512_castps512_ps256(_mm512_permutex2var_ps(lo, ix, hi));
      q[1] = _mm512_castps512_ps256(_mm512_permutex2var_ps(lo, iy, hi));
      q[2] = _mm512_castps512_ps256(_mm512_permutex2var_ps(lo, iz, hi));
    };
    __m256 p[3];
    points(a, p);
    if (lerp) {
      __m256 q[3];
      points(b, q);
      for (int k = 0; k < 3; ++k) p[k] = _mm256_add_ps(p[k], _mm256_mul_ps(fv, _mm256_sub_ps(q[k], p[k])));  // a + f * (b - a), glm's order
    }
    const __m512d px = _mm512_cvtps_pd(p[0]), py = _mm512_cvtps_pd(p[1]);
    __m256 x, y;
    __mmask8 ok = live;
    if (s.perspective) {
      const __m512d inv = _mm512_div_pd(one, _mm512_cvtps_pd(p[2]));
      x = _mm512_cvtpd_ps(_mm512_add_pd(_mm512_mul_pd(ax, _mm512_mul_pd(px, inv)), bx));
      y = _mm512_cvtpd_ps(_mm512_add_pd(_mm512_mul_pd(ay, _mm512_mul_pd(py, inv)), by));
      ok = _mm256_mask_cmp_ps_mask(ok, p[2], nearClip, _CMP_GE_OQ);
    } else {
      x = _mm512_cvtpd_ps(_mm512_add_pd(_mm512_mul_pd(ax, px), bx));
      y = _mm512_cvtpd_ps(_mm512_add_pd(_mm512_mul_pd(ay, py), by));
    }
    ok = _mm256_mask_cmp_ps_mask(ok, _mm256_andnot_ps(_mm256_set1_ps(-0.f), x), inf, _CMP_LT_OQ);
    ok = _mm256_mask_cmp_ps_mask(ok, _mm256_andnot_ps(_mm256_set1_ps(-0.f), y), inf, _CMP_LT_OQ);
    x = _mm256_mask_blend_ps(ok, _mm256_set1_ps(NAN), x);
    bad |= unsigned(live & ~ok);
    lo_x = _mm256_mask_min_ps(lo_x, ok, lo_x, x), hi_x = _mm256_mask_max_ps(hi_x, ok, hi_x, x);
    lo_y = _mm256_mask_min_ps(lo_y, ok, lo_y, y), hi_y = _mm256_mask_max_ps(hi_y, ok, hi_y, y);
    _mm256_mask_storeu_ps(xo + i, live, x), _mm256_mask_storeu_ps(yo + i, live, y), _mm256_mask_storeu_ps(zo + i, live, p[2]);
  }
  alignas(32) float r[4][8];
  _mm256_store_ps(r[0], lo_x), _mm256_store_ps(r[1], lo_y), _mm256_store_ps(r[2], hi_x), _mm256_store_ps(r[3], hi_y);
  box[0] = lowest(r[0], 8), box[1] = lowest(r[1], 8);
  box[2] = highest(r[2], 8), box[3] = highest(r[3], 8);
  return bad != 0;
}

}  // namespace

const IsaKernels kAvx512Kernels = {gatherInBoxAvx512, gatherStrataAvx512,           filterCandidatesAvx512,
                                   cellsOfAvx512,     projectLerpedAvx512,          avx2::stillAreas,  avx2::lensDraws, avx2::cornerRange, avx2::nearestDepth,          edgesAvx512<false>,
                                   fixedEdgesAvx512,  avx2::stillLensEdges, testLinearEdgesAvx512<kMovingEdges>, testLinearEdgesAvx512<kFixedEdges>,
                                   testLinearEdgesAvx512<kLensEdges>, gatherLensCellsAvx512, testMovingLensAvx512, lensLayerCellsAvx512};

}  // namespace reshutter::resample::kernels
