// The moving path: micropolygons of moving parts, one shutter group at a time. A chunk's vertices
// are projected at the group's cull times and the chunk dropped if its path misses the region;
// then each micropolygon is bounded per time stratum (Pixar's INTERVAL idea) and tested only
// against the one sample per pixel whose time falls in that stratum. Inside one knot segment the
// bound comes from the corners' projections at the interval's two ends (a perspective-widened
// lerp: the linear path, raster_linear.cpp); otherwise vertices are projected at every stratum
// boundary (drawMoving() here). The exact test of a candidate is coverage.h's, in scalar code or
// through the vector kernels.
#include <algorithm>
#include <cmath>

#include "resample/raster_impl.h"

namespace reshutter::resample {

using store::kNoCorner;
using store::TilePart;

// g = -1: every shutter group at once, over the interval from the first group's opening to the
// last one's closing (used only when that interval lies inside one knot segment: linearPath).
const BucketRasterizer::Impl::MovingTimes& BucketRasterizer::Impl::timesFor(const Source& src, uint32_t schedule, const store::Schedule& knots, int g) {
  for (const auto& t : movingTimes)
    if (t->src == &src && t->schedule == schedule && t->g == g) return *t;
  movingTimes.push_back(std::make_unique<MovingTimes>());
  MovingTimes& mt = *movingTimes.back();
  mt.src = &src, mt.schedule = schedule, mt.g = g;
  mt.groups = g >= 0 ? 1 : int(shutter.groups().size());
  const uint32_t K = uint32_t(knots.size());
  const double F = double(src.frame);
  const double toLocal = tBase - F;  // local time = st + toLocal
  const double covLo = src.coverStart(), covHi = src.coverEnd();
  mt.cover = {!Source::covers(tMin, covLo, covHi, src.endShared) || !Source::covers(tMax, covLo, covHi, src.endShared), covLo - tBase, covHi - tBase,
              src.endShared};
  // Group block k's strata bounds, absolute frames.
  auto lo = [&](int k) { return &stratumLo[size_t(mt.groupOf(k)) * N]; };
  auto hi = [&](int k) { return &stratumHi[size_t(mt.groupOf(k)) * N]; };
  double first = INFINITY, last = -INFINITY;
  for (int k = 0; k < mt.groups; ++k) first = std::min(first, lo(k)[0] - F), last = std::max(last, hi(k)[N - 1] - F);

  // Distinct local times to project vertices at: strata boundaries and the knots between them.
  auto& thetaTimes = mt.thetaTimes;
  for (int k = 0; k < mt.groups; ++k)
    for (int s = 0; s < N; ++s) thetaTimes.push_back(lo(k)[s] - F), thetaTimes.push_back(hi(k)[s] - F);
  for (uint32_t k = 0; k < K; ++k)
    if (knots[k] > first && knots[k] < last) thetaTimes.push_back(knots[k]);
  std::sort(thetaTimes.begin(), thetaTimes.end());
  thetaTimes.erase(std::unique(thetaTimes.begin(), thetaTimes.end()), thetaTimes.end());
  const size_t T = thetaTimes.size();
  mt.stratumFirst.resize(size_t(N)), mt.stratumLast.resize(size_t(N));
  for (int s = 0; s < N; ++s) {
    mt.stratumFirst[size_t(s)] = int(std::lower_bound(thetaTimes.begin(), thetaTimes.end(), lo(0)[s] - F) - thetaTimes.begin());
    mt.stratumLast[size_t(s)] = int(std::upper_bound(thetaTimes.begin(), thetaTimes.end(), hi(0)[s] - F) - thetaTimes.begin()) - 1;
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
    mt.spanStride = size_t(N + 7) / 8 * 8;
    mt.stratumU0.assign(mt.spanStride * size_t(mt.groups), 0.f), mt.stratumU1.assign(mt.spanStride * size_t(mt.groups), 0.f);
    for (int k = 0; k < mt.groups; ++k)
      for (int s = 0; s < N; ++s) {
        const size_t i = size_t(k) * mt.spanStride + size_t(s);
        mt.stratumU0[i] = std::clamp(float((lo(k)[s] - F - th0) / len) - 1e-6f, 0.f, 1.f);
        mt.stratumU1[i] = std::clamp(float((hi(k)[s] - F - th0) / len) + 1e-6f, 0.f, 1.f);
        mt.widestSpan = std::max(mt.widestSpan, mt.stratumU1[i] - mt.stratumU0[i]);
      }
  }
  return mt;
}

// Micropolygons [ch.m0, ch.m1) of a moving part in shutter group mt.g (every group, g = -1).
// Per-vertex work covers the chunk's vertices [ch.vLo, ch.vHi] only. False, with nothing drawn,
// when the times serve every group and a micropolygon needs the general path, which bounds one
// group at a time: the caller then draws the chunk group by group.
bool BucketRasterizer::Impl::rasterizeMoving(const MovingTimes& mt, const TilePart& part, const store::Schedule& knots, const HitContext& hc, const Chunk& ch) {
  const uint32_t K = part.numKnots, vBase = ch.vLo, nV = ch.vHi - ch.vLo + 1;
  const size_t T = mt.thetaTimes.size(), C = mt.cullTheta.size();
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
    return true;
  }
  projX.resize(T * nV), projY.resize(T * nV), projRho.resize(T * nV), depthScratch.resize(T);
  thetaBox.resize(4 * T);
  vertexStamp.assign(nV, 0u);

  const uint32_t segments = K - 1;
  segEdges.resize(size_t(segments) * 5);
  segReady.resize(segments);
  const float m = 1e-3f;
  const float rx0 = float(x0) - m, ry0 = float(y0) - m, rx1 = float(x0 + w) + m, ry1 = float(y0 + h) + m;
  const MovingPart mp{part, knots, hc, mt, mt.g, nV, vBase, rx0, ry0, rx1, ry1};

  if (mt.linearPath) return drawLinearChunk(mp, ch);
  for (uint32_t mi = ch.m0; mi < ch.m1; ++mi) drawMoving(mp, mi);
  return true;
}

// Micropolygon mi of a moving chunk on the general path: bounded per time stratum from its corners'
// projections at every theta time (strata boundaries and knots), each stratum's samples gathered
// and tested.
void BucketRasterizer::Impl::drawMoving(const MovingPart& mp, uint32_t mi) {
  const MovingTimes& mt = mp.times;
  const TilePart& part = mp.part;
  const uint32_t vBase = mp.vBase, nV = mp.nV;
  const int g = mp.g;
  const auto& thetaTimes = mt.thetaTimes;
  const auto& stratumFirst = mt.stratumFirst;
  const auto& stratumLast = mt.stratumLast;
  const double toLocal = mt.seg.toLocal;
  const Coverage& cover = mt.cover;
  const size_t T = thetaTimes.size(), C = mt.cullTheta.size();
  const float rx0 = mp.rx0, ry0 = mp.ry0, rx1 = mp.rx1, ry1 = mp.ry1;
  const uint32_t* c = &part.corners[size_t(mi) * 4];
  const bool tri = c[3] == kNoCorner;
  const int nc = tri ? 3 : 4;
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
    if (bounded && boxMissesRegion(bx0, by0, bx1, by1, 1.f)) return;
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
  resetSegments();
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
      box = {tx0[first] - mx,
             tx0[last] - tx0[first],
             tx1[first] + mx,
             tx1[last] - tx1[first],
             ty0[first] - my,
             ty0[last] - ty0[first],
             ty1[first] + my,
             ty1[last] - ty1[first],
             float(thetaTimes[size_t(first)] - toLocal),
             float(1.0 / (thetaTimes[size_t(last)] - thetaTimes[size_t(first)]))};
    const size_t n = gatherCandidates(s, s + 1, g, ta.px0, ta.py0, ta.px1, ta.py1, box, cover, zCull, 0);
    if (n) testCandidates(mp, mi, c, tri, flags, n);
  }
}

// Raster positions of the chunk's vertex vi (vBase + vi) at every theta time (projX/projY
// [vi * T + ti]); NaN x marks a position before the near plane. Float arithmetic: pixelRange()
// widens by the relative error.
void BucketRasterizer::Impl::projectVertexPath(const MovingTimes& mt, const TilePart& part, uint32_t vBase, uint32_t vi) {
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

}  // namespace reshutter::resample
