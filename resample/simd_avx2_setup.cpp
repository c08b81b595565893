// The AVX2 kernels of a chunk's set-up (resample/gather.h): vertices projected eight at a time,
// the static path's per-micropolygon test areas, and a queued chunk's vertex range and nearest
// depth; the AVX-512 table shares all but the projection. Compiled with -mavx2 -mpopcnt like
// simd_avx2.cpp, whose other kernels it sits beside; see simd_isa.h for what it may include.
#include <cmath>

#include "resample/simd_intrinsics.h"
#include "resample/simd_isa.h"

namespace reshutter::resample::kernels {

namespace {

// Points i .. i + 7 of an xyz-triple array as x, y and z vectors (three loads, blends and lane
// permutes in place of 24 scalar loads).
inline void pointsOf8(const float* p, __m256& x, __m256& y, __m256& z) {
  const __m256 m0 = _mm256_loadu_ps(p), m1 = _mm256_loadu_ps(p + 8), m2 = _mm256_loadu_ps(p + 16);
  // m0 = x0 y0 z0 x1 y1 z1 x2 y2, m1 = z2 x3 y3 z3 x4 y4 z4 x5, m2 = y5 z5 x6 y6 z6 x7 y7 z7
  x = _mm256_permutevar8x32_ps(_mm256_blend_ps(_mm256_blend_ps(m0, m1, 0x92), m2, 0x24), _mm256_setr_epi32(0, 3, 6, 1, 4, 7, 2, 5));
  y = _mm256_permutevar8x32_ps(_mm256_blend_ps(_mm256_blend_ps(m0, m1, 0x24), m2, 0x49), _mm256_setr_epi32(1, 4, 7, 2, 5, 0, 3, 6));
  z = _mm256_permutevar8x32_ps(_mm256_blend_ps(_mm256_blend_ps(m0, m1, 0x49), m2, 0x92), _mm256_setr_epi32(2, 5, 0, 3, 6, 1, 4, 7));
}

// Corner j of micropolygons i .. i + 7 (four corners each from `corners`; `left` of them there)
// as chunk vertices (corner - vBase): a triangle's missing fourth is its third again, and lanes
// past the count take vertex 0.
inline void chunkCornersOf8(const uint32_t* corners, size_t left, uint32_t vBase, __m256i k[4]) {
  const __m256i lane = _mm256_setr_epi32(0, 1, 2, 3, 4, 5, 6, 7), base = _mm256_set1_epi32(int(vBase));
  const __m256i liveMask = _mm256_cmpgt_epi32(_mm256_set1_epi32(left >= 8 ? 8 : int(left)), lane);
  const int* c = reinterpret_cast<const int*>(corners);
  for (int j = 0; j < 4; ++j) k[j] = _mm256_mask_i32gather_epi32(base, c, _mm256_add_epi32(_mm256_slli_epi32(lane, 2), _mm256_set1_epi32(j)), liveMask, 4);
  k[3] = _mm256_blendv_epi8(k[3], k[2], _mm256_cmpeq_epi32(k[3], _mm256_set1_epi32(-1)));
  for (int j = 0; j < 4; ++j) k[j] = _mm256_sub_epi32(k[j], base);
}

}  // namespace

bool avx2::projectLerped(const float* a, const float* b, float f, size_t n, const ProjectionScale& s, float* xo, float* yo, float* zo, float box[4]) {
  const __m128 fv = _mm_set1_ps(f), nearClip = _mm_set1_ps(s.nearClip), inf = _mm_set1_ps(INFINITY), absMask = _mm_castsi128_ps(_mm_set1_epi32(0x7FFFFFFF));
  const __m256d ax = _mm256_set1_pd(s.ax), bx = _mm256_set1_pd(s.bx), ay = _mm256_set1_pd(s.ay), by = _mm256_set1_pd(s.by), one = _mm256_set1_pd(1.0);
  // The same points at both ends (a still chunk): no lerp, so that p is a itself (a + 0 (a - a)
  // would turn -0 into +0).
  const bool lerp = a != b;
  __m128 lo_x = inf, lo_y = inf, hi_x = _mm_set1_ps(-INFINITY), hi_y = hi_x;
  int bad = 0;
  // Four points' projection: stored at i (only the first `count`), and into the box.
  auto project4 = [&](const __m128 p[3], size_t i, size_t count) {
    const __m256d px = _mm256_cvtps_pd(p[0]), py = _mm256_cvtps_pd(p[1]);
    __m128 x, y, ok;
    if (s.perspective) {
      const __m256d iz = _mm256_div_pd(one, _mm256_cvtps_pd(p[2]));
      x = _mm256_cvtpd_ps(_mm256_add_pd(_mm256_mul_pd(ax, _mm256_mul_pd(px, iz)), bx));
      y = _mm256_cvtpd_ps(_mm256_add_pd(_mm256_mul_pd(ay, _mm256_mul_pd(py, iz)), by));
      ok = _mm_cmp_ps(p[2], nearClip, _CMP_GE_OQ);
    } else {
      x = _mm256_cvtpd_ps(_mm256_add_pd(_mm256_mul_pd(ax, px), bx));
      y = _mm256_cvtpd_ps(_mm256_add_pd(_mm256_mul_pd(ay, py), by));
      ok = _mm_castsi128_ps(_mm_set1_epi32(-1));
    }
    ok = _mm_and_ps(ok, _mm_and_ps(_mm_cmp_ps(_mm_and_ps(x, absMask), inf, _CMP_LT_OQ), _mm_cmp_ps(_mm_and_ps(y, absMask), inf, _CMP_LT_OQ)));
    x = _mm_blendv_ps(_mm_set1_ps(NAN), x, ok);
    bad |= _mm_movemask_ps(ok) ^ 0xF;
    lo_x = _mm_min_ps(lo_x, _mm_blendv_ps(inf, x, ok)), hi_x = _mm_max_ps(hi_x, _mm_blendv_ps(_mm_set1_ps(-INFINITY), x, ok));
    lo_y = _mm_min_ps(lo_y, _mm_blendv_ps(inf, y, ok)), hi_y = _mm_max_ps(hi_y, _mm_blendv_ps(_mm_set1_ps(-INFINITY), y, ok));
    if (count == 4) {
      _mm_storeu_ps(xo + i, x), _mm_storeu_ps(yo + i, y), _mm_storeu_ps(zo + i, p[2]);
    } else {
      alignas(16) float tx[4], ty[4], tz[4];
      _mm_store_ps(tx, x), _mm_store_ps(ty, y), _mm_store_ps(tz, p[2]);
      for (size_t l = 0; l < count; ++l) xo[i + l] = tx[l], yo[i + l] = ty[l], zo[i + l] = tz[l];
    }
  };
  size_t i = 0;
  // Eight whole points at a time, read as three vectors of each end.
  for (; i + 8 <= n; i += 8) {
    __m256 p8[3];
    pointsOf8(a + 3 * i, p8[0], p8[1], p8[2]);
    if (lerp) {
      __m256 q8[3];
      pointsOf8(b + 3 * i, q8[0], q8[1], q8[2]);
      for (int k = 0; k < 3; ++k) p8[k] = _mm256_add_ps(p8[k], _mm256_mul_ps(_mm256_set1_ps(f), _mm256_sub_ps(q8[k], p8[k])));  // a + f * (b - a), glm's order
    }
    const __m128 lo[3] = {_mm256_castps256_ps128(p8[0]), _mm256_castps256_ps128(p8[1]), _mm256_castps256_ps128(p8[2])};
    const __m128 hi[3] = {_mm256_extractf128_ps(p8[0], 1), _mm256_extractf128_ps(p8[1], 1), _mm256_extractf128_ps(p8[2], 1)};
    project4(lo, i, 4), project4(hi, i + 4, 4);
  }
  for (; i < n; i += 4) {
    // Lanes past n repeat the last point (harmless to the box) and are not stored.
    size_t at[4];
    for (size_t l = 0; l < 4; ++l) at[l] = 3 * (i + l < n ? i + l : n - 1);
    auto lane = [&](const float* p, int k) { return _mm_setr_ps(p[at[0] + k], p[at[1] + k], p[at[2] + k], p[at[3] + k]); };
    __m128 p[3];
    for (int k = 0; k < 3; ++k) {
      const __m128 pa = lane(a, k);
      p[k] = lerp ? _mm_add_ps(pa, _mm_mul_ps(fv, _mm_sub_ps(lane(b, k), pa))) : pa;  // a + f * (b - a), glm's order
    }
    project4(p, i, std::min<size_t>(4, n - i));
  }
  alignas(16) float r[4][4];
  _mm_store_ps(r[0], lo_x), _mm_store_ps(r[1], lo_y), _mm_store_ps(r[2], hi_x), _mm_store_ps(r[3], hi_y);
  box[0] = lowest(r[0], 4), box[1] = lowest(r[1], 4);
  box[2] = highest(r[2], 4), box[3] = highest(r[3], 4);
  return bad != 0;
}

void avx2::cornerRange(const uint32_t* corners, size_t count, uint32_t& lo, uint32_t& hi) {
  // 0xffffffff is the largest unsigned value, so the min passes over it; the max sees 0 instead.
  const __m256i none = _mm256_set1_epi32(-1);
  __m256i l = none, h = _mm256_setzero_si256();
  const size_t n = 4 * count;
  size_t i = 0;
  for (; i + 8 <= n; i += 8) {
    const __m256i v = _mm256_loadu_si256(reinterpret_cast<const __m256i*>(corners + i));
    l = _mm256_min_epu32(l, v), h = _mm256_max_epu32(h, _mm256_andnot_si256(_mm256_cmpeq_epi32(v, none), v));
  }
  alignas(32) uint32_t ls[8], hs[8];
  _mm256_store_si256(reinterpret_cast<__m256i*>(ls), l), _mm256_store_si256(reinterpret_cast<__m256i*>(hs), h);
  uint32_t a = ~0u, b = 0;
  for (int k = 0; k < 8; ++k) a = ls[k] < a ? ls[k] : a, b = hs[k] > b ? hs[k] : b;
  for (; i < n; ++i)
    if (corners[i] != ~0u) a = corners[i] < a ? corners[i] : a, b = corners[i] > b ? corners[i] : b;
  // No corner at all: lo > hi.
  if (a == ~0u) b = 0;
  lo = a, hi = b;
}

float avx2::nearestDepth(const float* xyz, size_t n, float nearest) {
  // std::min(nearest, z) = z < nearest ? z : nearest lane by lane (a NaN z is passed over); the
  // lanes' minima are exact, so their order does not matter.
  __m256 m = _mm256_set1_ps(nearest);
  size_t i = 0;
  for (; i + 8 <= n; i += 8) {
    __m256 x, y, z;
    pointsOf8(xyz + 3 * i, x, y, z);
    m = _mm256_min_ps(z, m);
  }
  alignas(32) float ms[8];
  _mm256_store_ps(ms, m);
  for (int k = 0; k < 8; ++k) nearest = ms[k] < nearest ? ms[k] : nearest;
  for (; i < n; ++i) nearest = xyz[3 * i + 2] < nearest ? xyz[3 * i + 2] : nearest;
  return nearest;
}

void avx2::stillAreas(const StillAreaSetup& s, size_t count, const StillAreas& out) {
  const __m256 inf = _mm256_set1_ps(INFINITY), ninf = _mm256_set1_ps(-INFINITY), absMask = _mm256_castsi256_ps(_mm256_set1_epi32(0x7FFFFFFF));
  const __m256 rx0 = _mm256_set1_ps(float(s.x0)), ry0 = _mm256_set1_ps(float(s.y0)), rx1 = _mm256_set1_ps(float(s.x0 + s.w)), ry1 = _mm256_set1_ps(float(s.y0 + s.h));
  const __m256 rxm = _mm256_set1_ps(float(s.x0 - 1)), rym = _mm256_set1_ps(float(s.y0 - 1));
  const __m256i lastX = _mm256_set1_epi32(s.x0 + s.w - 1), lastY = _mm256_set1_epi32(s.y0 + s.h - 1);
  // clampTo(v, lo, hi) = v >= lo ? (v <= hi ? v : hi) : lo (NaN: lo), and floorInt(v) = int(v) -
  // (float(int(v)) > v), as pixelRange() computes them.
  auto clampTo = [](__m256 v, __m256 lo, __m256 hi) {
    return _mm256_blendv_ps(lo, _mm256_blendv_ps(hi, v, _mm256_cmp_ps(v, hi, _CMP_LE_OQ)), _mm256_cmp_ps(v, lo, _CMP_GE_OQ));
  };
  auto floorInt = [](__m256 v) {
    const __m256i i = _mm256_cvttps_epi32(v);
    return _mm256_add_epi32(i, _mm256_castps_si256(_mm256_cmp_ps(_mm256_cvtepi32_ps(i), v, _CMP_GT_OQ)));  // -1 where it rounded up
  };
  for (size_t i = 0; i < count; i += 8) {
    __m256i v[4];
    chunkCornersOf8(s.corners + 4 * i, count - i, s.vBase, v);
    __m256 bx0 = inf, by0 = inf, bx1 = ninf, by1 = ninf, zNear = _mm256_setzero_ps(), unbounded = _mm256_setzero_ps();
    for (int j = 0; j < 4; ++j) {
      const __m256i k = v[j];
      const __m256 x = _mm256_i32gather_ps(s.projX, k, 4), y = _mm256_i32gather_ps(s.projY, k, 4);
      const __m256 z = _mm256_i32gather_ps(s.depth, k, 4);
      unbounded = _mm256_or_ps(unbounded, _mm256_cmp_ps(x, x, _CMP_UNORD_Q));
      // std::min(b, x) is x < b ? x : b; a NaN x leaves the box as it was (the lane is unbounded).
      bx0 = _mm256_min_ps(x, bx0), by0 = _mm256_min_ps(y, by0), bx1 = _mm256_max_ps(x, bx1), by1 = _mm256_max_ps(y, by1);
      zNear = j == 0 ? z : _mm256_min_ps(z, zNear);  // *std::min_element: the first of the smallest
    }
    const __m256 zCull = s.occlusionCulling ? _mm256_sub_ps(zNear, _mm256_mul_ps(_mm256_set1_ps(1e-5f), _mm256_and_ps(zNear, absMask))) : ninf;
    // pixelRange() and testArea()'s margin: 1e-3 px plus 1e-6 of the box's largest magnitude.
    const __m256 mag = _mm256_max_ps(_mm256_max_ps(_mm256_and_ps(bx1, absMask), _mm256_and_ps(bx0, absMask)),
                                     _mm256_max_ps(_mm256_and_ps(by1, absMask), _mm256_and_ps(by0, absMask)));
    const __m256 m = _mm256_add_ps(_mm256_set1_ps(1e-3f), _mm256_mul_ps(_mm256_set1_ps(1e-6f), mag));
    const __m256 lx = _mm256_sub_ps(bx0, m), ly = _mm256_sub_ps(by0, m), hx = _mm256_add_ps(bx1, m), hy = _mm256_add_ps(by1, m);
    const __m256i px0 = floorInt(clampTo(lx, rx0, rx1)), py0 = floorInt(clampTo(ly, ry0, ry1));
    const __m256i px1 = _mm256_min_epi32(lastX, floorInt(clampTo(hx, rxm, rx1))), py1 = _mm256_min_epi32(lastY, floorInt(clampTo(hy, rym, ry1)));
    const __m256i inside = _mm256_andnot_si256(_mm256_or_si256(_mm256_cmpgt_epi32(px0, px1), _mm256_cmpgt_epi32(py0, py1)), _mm256_set1_epi32(1));
    const __m256i state = _mm256_blendv_epi8(inside, _mm256_set1_epi32(2), _mm256_castps_si256(unbounded));
    _mm256_storeu_si256(reinterpret_cast<__m256i*>(out.px0 + i), px0), _mm256_storeu_si256(reinterpret_cast<__m256i*>(out.py0 + i), py0);
    _mm256_storeu_si256(reinterpret_cast<__m256i*>(out.px1 + i), px1), _mm256_storeu_si256(reinterpret_cast<__m256i*>(out.py1 + i), py1);
    _mm256_storeu_ps(out.sx0 + i, lx), _mm256_storeu_ps(out.sy0 + i, ly), _mm256_storeu_ps(out.sx1 + i, hx), _mm256_storeu_ps(out.sy1 + i, hy);
    _mm256_storeu_ps(out.zCull + i, zCull);
    const __m128i s16 = _mm_packs_epi32(_mm256_castsi256_si128(state), _mm256_extracti128_si256(state, 1));
    _mm_storel_epi64(reinterpret_cast<__m128i*>(out.state + i), _mm_packus_epi16(s16, s16));
  }
}

void avx2::lensDraws(const LensQueueSetup& s, size_t count, const LensDraws& out) {
  const __m256 inf = _mm256_set1_ps(INFINITY), ninf = _mm256_set1_ps(-INFINITY), absMask = _mm256_castsi256_ps(_mm256_set1_epi32(0x7FFFFFFF));
  const __m256 zero = _mm256_setzero_ps(), one = _mm256_set1_ps(1.f), half = _mm256_set1_ps(0.5f), allOnes = _mm256_castsi256_ps(_mm256_set1_epi32(-1));
  const __m256 invD = _mm256_set1_ps(s.invD), ax = _mm256_set1_ps(s.lensAx), ay = _mm256_set1_ps(s.lensAy), kMag = _mm256_set1_ps(s.kMag);
  const __m256 layerScale = _mm256_set1_ps(s.layerScale), slack = _mm256_set1_ps(s.uErr);
  const __m256 rx0 = _mm256_set1_ps(float(s.x0)), ry0 = _mm256_set1_ps(float(s.y0)), rx1 = _mm256_set1_ps(float(s.x0 + s.w)), ry1 = _mm256_set1_ps(float(s.y0 + s.h));
  auto abs = [&](__m256 v) { return _mm256_and_ps(v, absMask); };
  // std::min(a, b) is b < a ? b : a, std::max(a, b) is a < b ? b : a: min_ps(b, a) and
  // max_ps(b, a), NaNs included; a std::max({...}) folds from the left.
  auto maxOf = [](__m256 first, auto... rest) {
    __m256 r = first;
    ((r = _mm256_max_ps(rest, r)), ...);
    return r;
  };
  const int times = s.lerp ? 2 : s.times;
  for (size_t i = 0; i < count; i += 8) {
    __m256i k[4];
    chunkCornersOf8(s.corners + 4 * i, count - i, s.vBase, k);  // a triangle's fourth is its third, which no min or max minds
    // Each bound time's corner box (e[t]) and the whole draw's, with its depths.
    __m256 e[2][4], zLo = inf, zHi = ninf, unbounded = zero, z0[4], z1[4];
    for (int t = 0; t < times; ++t) {
      const float *xs = s.projX + size_t(t) * s.nV, *ys = s.projY + size_t(t) * s.nV, *zs = s.depth + size_t(t) * s.nV;
      __m256 lx = inf, ly = inf, hx = ninf, hy = ninf;
      for (int j = 0; j < 4; ++j) {
        const __m256 x = _mm256_i32gather_ps(xs, k[j], 4), y = _mm256_i32gather_ps(ys, k[j], 4), z = _mm256_i32gather_ps(zs, k[j], 4);
        unbounded = _mm256_or_ps(unbounded, _mm256_cmp_ps(x, x, _CMP_UNORD_Q));
        lx = _mm256_min_ps(x, lx), ly = _mm256_min_ps(y, ly), hx = _mm256_max_ps(x, hx), hy = _mm256_max_ps(y, hy);
        zLo = _mm256_min_ps(z, zLo), zHi = _mm256_max_ps(z, zHi);
        (t == 0 ? z0 : z1)[j] = z;
      }
      e[t][0] = lx, e[t][1] = ly, e[t][2] = hx, e[t][3] = hy;
    }
    // The fold over both times is the fold of each time's box (min and max are exact).
    __m256 bx0 = e[0][0], by0 = e[0][1], bx1 = e[0][2], by1 = e[0][3];
    if (times == 2) bx0 = _mm256_min_ps(e[1][0], bx0), by0 = _mm256_min_ps(e[1][1], by0), bx1 = _mm256_max_ps(e[1][2], bx1), by1 = _mm256_max_ps(e[1][3], by1);
    const __m256 zCull = s.occlusionCulling ? _mm256_sub_ps(zLo, _mm256_mul_ps(_mm256_set1_ps(1e-5f), abs(zLo))) : ninf;
    // productRange() with l0 = l1: the extremes of l kLo and l kHi.
    const __m256 kLo = _mm256_sub_ps(invD, _mm256_div_ps(one, zLo)), kHi = _mm256_sub_ps(invD, _mm256_div_ps(one, zHi));
    const __m256 ax0 = _mm256_mul_ps(ax, kLo), ax1 = _mm256_mul_ps(ax, kHi), ay0 = _mm256_mul_ps(ay, kLo), ay1 = _mm256_mul_ps(ay, kHi);
    const __m256 cx0 = _mm256_min_ps(ax1, ax0), cx1 = _mm256_max_ps(ax1, ax0), cy0 = _mm256_min_ps(ay1, ay0), cy1 = _mm256_max_ps(ay1, ay0);
    __m256 lag = zero;
    if (s.lerp)
      for (int j = 0; j < 4; ++j) {
        // perspectiveLag(za, zb) = |zb - za| / (4 min(za, zb)) 1.001
        const __m256 pl = _mm256_mul_ps(_mm256_div_ps(abs(_mm256_sub_ps(z1[j], z0[j])), _mm256_mul_ps(_mm256_set1_ps(4.f), _mm256_min_ps(z1[j], z0[j]))),
                                        _mm256_set1_ps(1.001f));
        lag = _mm256_max_ps(pl, lag);
      }
    const __m256 lagScale = _mm256_add_ps(_mm256_add_ps(lag, slack), _mm256_set1_ps(1e-5f));
    const __m256 lagX = _mm256_mul_ps(lagScale, _mm256_sub_ps(bx1, bx0)), lagY = _mm256_mul_ps(lagScale, _mm256_sub_ps(by1, by0));
    const __m256 mag = maxOf(abs(bx0), abs(bx1), abs(by0), abs(by1), abs(cx0), abs(cx1), abs(cy0), abs(cy1));
    const __m256 margin = _mm256_add_ps(_mm256_set1_ps(2e-3f), _mm256_mul_ps(_mm256_set1_ps(4e-6f), _mm256_add_ps(mag, kMag)));
    __m256 x0, x1, y0, y1, mx0 = zero, mx1 = zero, my0 = zero, my1 = zero;
    if (s.lerp) {
      const __m256 wx = _mm256_add_ps(margin, lagX), wy = _mm256_add_ps(margin, lagY);
      x0 = _mm256_sub_ps(e[0][0], wx), y0 = _mm256_sub_ps(e[0][1], wy), x1 = _mm256_add_ps(e[0][2], wx), y1 = _mm256_add_ps(e[0][3], wy);
      mx0 = _mm256_sub_ps(e[1][0], e[0][0]), my0 = _mm256_sub_ps(e[1][1], e[0][1]), mx1 = _mm256_sub_ps(e[1][2], e[0][2]), my1 = _mm256_sub_ps(e[1][3], e[0][3]);
    } else {
      x0 = _mm256_sub_ps(bx0, margin), x1 = _mm256_add_ps(bx1, margin), y0 = _mm256_sub_ps(by0, margin), y1 = _mm256_add_ps(by1, margin);
    }
    // The layer's depths: the knots' (a lane with one before the near plane: lensDraw()'s).
    __m256 zkLo = zLo, zkHi = zHi, fallback = zero;
    if (s.moving) {
      __m256 lo = inf, hi = ninf;
      for (uint32_t kn = 0; kn < s.numKnots; ++kn)
        for (int j = 0; j < 4; ++j) {
          const __m256i at = _mm256_add_epi32(_mm256_add_epi32(k[j], _mm256_add_epi32(k[j], k[j])), _mm256_set1_epi32(2));  // 3 v + 2
          const __m256 z = _mm256_i32gather_ps(s.knotXyz[kn], at, 4);
          lo = _mm256_min_ps(z, lo), hi = _mm256_max_ps(z, hi);
        }
      zkLo = lo, zkHi = hi;
      fallback = _mm256_andnot_ps(_mm256_cmp_ps(lo, _mm256_set1_ps(s.nearClip), _CMP_GE_OQ), allOnes);
    }
    // placeInLayer(): the layer, clamped (v < lo ? lo : hi < v ? hi : v), 0 when not finite.
    const __m256 kMid = _mm256_mul_ps(half, _mm256_add_ps(_mm256_sub_ps(invD, _mm256_div_ps(one, zkLo)), _mm256_sub_ps(invD, _mm256_div_ps(one, zkHi))));
    const __m256 layerF = _mm256_floor_ps(_mm256_mul_ps(kMid, layerScale));
    const __m256 lo = _mm256_set1_ps(-1e9f), hi = _mm256_set1_ps(1e9f);
    const __m256 clamped = _mm256_blendv_ps(_mm256_blendv_ps(layerF, hi, _mm256_cmp_ps(hi, layerF, _CMP_LT_OQ)), lo, _mm256_cmp_ps(layerF, lo, _CMP_LT_OQ));
    const __m256i layer = _mm256_and_si256(_mm256_cvttps_epi32(clamped), _mm256_castps_si256(_mm256_cmp_ps(abs(layerF), inf, _CMP_LT_OQ)));
    const __m256 kl = _mm256_div_ps(_mm256_add_ps(_mm256_cvtepi32_ps(layer), half), layerScale);
    const __m256 cxl = _mm256_mul_ps(ax, kl), cyl = _mm256_mul_ps(ay, kl);
    const __m256 ex = _mm256_max_ps(abs(_mm256_sub_ps(cx1, cxl)), abs(_mm256_sub_ps(cx0, cxl)));
    const __m256 ey = _mm256_max_ps(abs(_mm256_sub_ps(cy1, cyl)), abs(_mm256_sub_ps(cy0, cyl)));
    // The search box over the whole motion, f in [0, 1]: box + min(0 m, 1 m) or + max(0 m, 1 m).
    auto lowEnd = [&](__m256 m) { return _mm256_min_ps(m, _mm256_mul_ps(zero, m)); };
    auto highEnd = [&](__m256 m) { return _mm256_max_ps(m, _mm256_mul_ps(zero, m)); };
    __m256 q0 = _mm256_sub_ps(_mm256_add_ps(x0, lowEnd(mx0)), ex), q1 = _mm256_add_ps(_mm256_add_ps(x1, highEnd(mx1)), ex);
    __m256 q2 = _mm256_sub_ps(_mm256_add_ps(y0, lowEnd(my0)), ey), q3 = _mm256_add_ps(_mm256_add_ps(y1, highEnd(my1)), ey);
    const __m256 qm = _mm256_add_ps(_mm256_set1_ps(2e-3f),
                                    _mm256_mul_ps(_mm256_set1_ps(1e-5f), maxOf(abs(q0), abs(q1), abs(q2), abs(q3), abs(cxl), abs(cyl), _mm256_add_ps(mag, kMag))));
    q0 = _mm256_sub_ps(q0, qm), q1 = _mm256_add_ps(q1, qm), q2 = _mm256_sub_ps(q2, qm), q3 = _mm256_add_ps(q3, qm);
    // searchReaches().
    const __m256 reachX = _mm256_add_ps(abs(cxl), one), reachY = _mm256_add_ps(abs(cyl), one);
    const __m256 misses = _mm256_or_ps(_mm256_or_ps(_mm256_cmp_ps(q1, _mm256_sub_ps(rx0, reachX), _CMP_LT_OQ), _mm256_cmp_ps(q0, _mm256_add_ps(rx1, reachX), _CMP_GT_OQ)),
                                       _mm256_or_ps(_mm256_cmp_ps(q3, _mm256_sub_ps(ry0, reachY), _CMP_LT_OQ), _mm256_cmp_ps(q2, _mm256_add_ps(ry1, reachY), _CMP_GT_OQ)));
    // An unbounded lane keeps only zCull (the rest 0, as lensDraw() leaves them).
    const __m256 keep = _mm256_andnot_ps(unbounded, allOnes);
    auto put = [&](float* to, __m256 value) { _mm256_storeu_ps(to + i, _mm256_and_ps(value, keep)); };
    _mm256_storeu_ps(out.zCull + i, zCull);
    put(out.kl, kl), put(out.x0, x0), put(out.x1, x1), put(out.y0, y0), put(out.y1, y1), put(out.cx0, cx0), put(out.cx1, cx1), put(out.cy0, cy0);
    put(out.cy1, cy1), put(out.ex, ex), put(out.ey, ey), put(out.qm, qm), put(out.mx0, mx0), put(out.mx1, mx1), put(out.my0, my0), put(out.my1, my1);
    _mm256_storeu_si256(reinterpret_cast<__m256i*>(out.layer + i), _mm256_and_si256(layer, _mm256_castps_si256(keep)));
    __m256i state = _mm256_andnot_si256(_mm256_castps_si256(misses), _mm256_set1_epi32(1));
    state = _mm256_blendv_epi8(state, _mm256_set1_epi32(3), _mm256_castps_si256(fallback));
    state = _mm256_blendv_epi8(state, _mm256_set1_epi32(2), _mm256_castps_si256(unbounded));
    const __m128i s16 = _mm_packs_epi32(_mm256_castsi256_si128(state), _mm256_extracti128_si256(state, 1));
    _mm_storel_epi64(reinterpret_cast<__m128i*>(out.state + i), _mm_packus_epi16(s16, s16));
  }
}

}  // namespace reshutter::resample::kernels
