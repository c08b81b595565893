// The lens path: depth of field. With a thin lens every micropolygon - still or moving - is drawn
// here. A sample at lens point L sees camera-space point P where the pinhole sees
// P' = P + L (P.z / d - 1) (d the focal distance): a per-sample shear of camera space, which maps a
// micropolygon to a micropolygon, so the exact test is the static path's edge test on the corners
// sheared for the sample's lens point (at the sample's own time, for a moving one). Shared corners
// are sheared by the same arithmetic in both neighbours, so shared edges stay exactly negated and
// the test stays watertight.
//
// Bounds: on the raster the shear displaces a point at depth z by a L (1/d - 1/z), which over a
// micropolygon's depths [z0, z1] lies between a L k(z0) and a L k(z1), k(z) = 1/d - 1/z rising with
// z. The bucket's planes are lens strata (BucketSamples::lensPlanes), so each plane's lens points
// lie in one cell of the aperture: the micropolygon's pinhole box (over the render's times)
// widened by that cell's displacement is the plane's search box, and each sample in it is then
// held to the box displaced by its own lens point before the exact test (the dual-space test of
// stochastic rasterization, in x-u and y-v).
#include <algorithm>
#include <cmath>

#include "resample/raster_impl.h"

namespace reshutter::resample {

using store::kNoCorner;
using store::TilePart;

namespace {

// Extremes of l k over l in [l0, l1] and k in [k0, k1].
void productRange(float l0, float l1, float k0, float k1, float& lo, float& hi) {
  const float a = l0 * k0, b = l0 * k1, c = l1 * k0, d = l1 * k1;
  lo = std::min(std::min(a, b), std::min(c, d));
  hi = std::max(std::max(a, b), std::max(c, d));
}

}  // namespace

void BucketRasterizer::Impl::rasterizeLens(const Source& src, const store::TileEntry& entry, const TilePart& part, const HitContext& hc, const Chunk& ch) {
  const auto& knots = src.knots(entry.schedule);
  const bool moving = (entry.effects & store::kEffectMoving) && part.numKnots > 1 && !ch.still;
  const uint32_t vBase = ch.vLo, nV = ch.vHi - ch.vLo + 1;
  const double F = double(src.frame);
  // Local times to bound at: the region's first and last sample times and the knots between
  // (a corner's screen path is straight between them); a still chunk has one position.
  lensTimes.clear();
  if (moving && tMax > tMin) {
    lensTimes.push_back(tMin - F), lensTimes.push_back(tMax - F);
    for (double k : knots)
      if (k > tMin - F && k < tMax - F) lensTimes.push_back(k);
  } else {
    lensTimes.push_back(moving ? tMin - F : 0.0);  // an instant, or no motion
  }
  const size_t C = lensTimes.size();
  cullX.resize(C * nV), cullY.resize(C * nV), cullZ.resize(C * nV);
  float zLo = INFINITY, zHi = -INFINITY;
  bool unbounded = false;
  for (size_t ci = 0; ci < C; ++ci)
    for (uint32_t i = 0; i < nV; ++i) {
      const glm::vec3 p = moving ? positionAt(part, knots, vBase + i, lensTimes[ci]) : part.position(0, vBase + i);
      float x = 0, y = 0;
      if (!project(p, x, y)) x = NAN, unbounded = true;
      cullX[ci * nV + i] = x, cullY[ci * nV + i] = y, cullZ[ci * nV + i] = p.z;
      zLo = std::min(zLo, p.z), zHi = std::max(zHi, p.z);
    }
  const float lensAx = float(view.ax * view.lensRadius), lensAy = float(view.ay * view.lensRadius);
  const float invD = float(1.0 / view.focalDistance);
  // The chunk's box over every time, widened by the largest displacement the whole aperture
  // gives its depths: a chunk that misses the region with it is dropped whole.
  if (!unbounded) {
    float kLo, kHi, sxLo, sxHi, syLo, syHi;
    kLo = invD - 1.f / zLo, kHi = invD - 1.f / zHi;
    productRange(-lensAx, lensAx, kLo, kHi, sxLo, sxHi);
    productRange(-lensAy, lensAy, kLo, kHi, syLo, syHi);
    const float* xs = cullX.data();
    const float* ys = cullY.data();
    const float bx0 = *std::min_element(xs, xs + C * nV), bx1 = *std::max_element(xs, xs + C * nV);
    const float by0 = *std::min_element(ys, ys + C * nV), by1 = *std::max_element(ys, ys + C * nV);
    if (boxMissesRegion(bx0 + sxLo, by0 + syLo, bx1 + sxHi, by1 + syHi, 2.f)) {
      stats.chunkCulledMicropolygons += ch.m1 - ch.m0;
      return;
    }
  }
  // One knot segment over the render's times: each corner moves along a straight screen line, so
  // a sample is held to the lerp of the end boxes at its own time (MovingBox's idea), widened by
  // the perspective lag and the rounding of its time.
  float thetaA = 0, invLen = 0, uErr = 0;
  if (moving && C == 2) {
    const double len = lensTimes[1] - lensTimes[0], toLocal = tBase - F;
    thetaA = float(lensTimes[0] - toLocal), invLen = float(1.0 / len);
    uErr = float(5e-7 * std::max({1.0, std::abs(lensTimes[0]), std::abs(lensTimes[1]), std::abs(toLocal)}) / len);
    // Each plane's times (a block of the shutter when planes pair time and lens), as the span of
    // the lerp parameter its samples take: the plane's search box covers that part of the path.
    lensPlaneF0.assign(size_t(N), 1.f), lensPlaneF1.assign(size_t(N), 0.f);
    for (int s = 0; s < N; ++s)
      for (size_t g = 0; g < groupPresent.size(); ++g) {
        if (!groupPresent[g]) continue;
        const double f0 = (stratumLo[g * N + size_t(s)] - F - lensTimes[0]) / len, f1 = (stratumHi[g * N + size_t(s)] - F - lensTimes[0]) / len;
        lensPlaneF0[size_t(s)] = std::min(lensPlaneF0[size_t(s)], std::clamp(float(f0) - 1e-6f, 0.f, 1.f));
        lensPlaneF1[size_t(s)] = std::max(lensPlaneF1[size_t(s)], std::clamp(float(f1) + 1e-6f, 0.f, 1.f));
      }
  }
  const double covLo = src.coverStart(), covHi = src.coverEnd();
  // The displacement coefficients' own rounding: k = 1/d - 1/z cancels near the focal plane.
  const float kMag = std::max(std::abs(lensAx), std::abs(lensAy)) * (invD + (zLo > 0 ? 1.f / zLo : 0.f));
  const LensChunk lc{part,
                     knots,
                     hc,
                     moving,
                     vBase,
                     nV,
                     C,
                     lensAx,
                     lensAy,
                     invD,
                     std::isfinite(kMag) ? kMag : 0.f,
                     {!Source::covers(tMin, covLo, covHi, src.endShared) || !Source::covers(tMax, covLo, covHi, src.endShared), covLo - tBase, covHi - tBase,
                      src.endShared},
                     tBase - F,
                     thetaA,
                     invLen,
                     uErr};
  for (uint32_t m = ch.m0; m < ch.m1; ++m) drawLens(lc, m);
}

void BucketRasterizer::Impl::drawLens(const LensChunk& lc, uint32_t m) {
  const TilePart& part = lc.part;
  const uint32_t* c = &part.corners[size_t(m) * 4];
  const bool tri = c[3] == kNoCorner;
  const int nc = tri ? 3 : 4;
  float bx0 = INFINITY, by0 = INFINITY, bx1 = -INFINITY, by1 = -INFINITY, zLo = INFINITY, zHi = -INFINITY;
  bool bounded = true;
  for (size_t ci = 0; ci < lc.C; ++ci)
    for (int j = 0; j < nc; ++j) {
      const size_t k = ci * lc.nV + (c[j] - lc.vBase);
      const float x = cullX[k], y = cullY[k];
      if (std::isnan(x)) bounded = false;
      bx0 = std::min(bx0, x), by0 = std::min(by0, y), bx1 = std::max(bx1, x), by1 = std::max(by1, y);
      zLo = std::min(zLo, cullZ[k]), zHi = std::max(zHi, cullZ[k]);
    }
  ++stats.lensMicropolygons;
  const float zCull = cullDepth(zLo);
  // Per lens unit the raster displacement lies in [cx0, cx1] (x) and [cy0, cy1] (y) for every
  // depth the micropolygon takes.
  float kLo = 0, kHi = 0;
  if (bounded) kLo = lc.invD - 1.f / zLo, kHi = lc.invD - 1.f / zHi;
  float cx0, cx1, cy0, cy1;
  productRange(lc.lensAx, lc.lensAx, kLo, kHi, cx0, cx1);
  productRange(lc.lensAy, lc.lensAy, kLo, kHi, cy0, cy1);
  const uint8_t flags = part.flags[m];
  // With two bound times: the box at each end, for the per-sample lerp.
  float e0[4] = {0, 0, 0, 0}, e1[4] = {0, 0, 0, 0}, lag = 0;
  const bool lerp = bounded && lc.invLen > 0;
  if (lerp) {
    for (int end = 0; end < 2; ++end) {
      float* e = end ? e1 : e0;
      e[0] = e[1] = INFINITY, e[2] = e[3] = -INFINITY;
      for (int j = 0; j < nc; ++j) {
        const size_t k = size_t(end) * lc.nV + (c[j] - lc.vBase);
        e[0] = std::min(e[0], cullX[k]), e[1] = std::min(e[1], cullY[k]), e[2] = std::max(e[2], cullX[k]), e[3] = std::max(e[3], cullY[k]);
      }
    }
    for (int j = 0; j < nc; ++j) lag = std::max(lag, perspectiveLag(cullZ[c[j] - lc.vBase], cullZ[lc.nV + (c[j] - lc.vBase)]));
  }
  // What the lerped boxes are widened by (perspective lag, the rounding of the sample's time),
  // and the rounding margin of the projections and of any displacement the lens gives (|lens
  // point| <= 1 bounds every plane's): the same for every plane.
  const float lagX = (lag + lc.uErr + 1e-5f) * (bx1 - bx0), lagY = (lag + lc.uErr + 1e-5f) * (by1 - by0);
  const float mag = std::max({std::abs(bx0), std::abs(bx1), std::abs(by0), std::abs(by1), std::abs(cx0), std::abs(cx1), std::abs(cy0), std::abs(cy1)});
  const float margin = 2e-3f + 4e-6f * (mag + lc.kMag);
  kernels::LensBox box = bounded ? kernels::LensBox{bx0 - margin, bx1 + margin, by0 - margin, by1 + margin, cx0, cx1, cy0, cy1}
                                 : kernels::LensBox{-INFINITY, INFINITY, -INFINITY, INFINITY, 0.f, 0.f, 0.f, 0.f};
  if (lerp) {
    box.x0 = e0[0] - (margin + lagX), box.y0 = e0[1] - (margin + lagY), box.x1 = e0[2] + (margin + lagX), box.y1 = e0[3] + (margin + lagY);
    box.mx0 = e1[0] - e0[0], box.my0 = e1[1] - e0[1], box.mx1 = e1[2] - e0[2], box.my1 = e1[3] - e0[3];
    box.thetaA = lc.thetaA, box.invLen = lc.invLen;
  }
  for (int s = 0; s < N; ++s) {
    TestArea ta;
    float shxLo = 0, shxHi = 0, shyLo = 0, shyHi = 0;
    if (bounded) {
      productRange(lensLoX[size_t(s)], lensHiX[size_t(s)], cx0, cx1, shxLo, shxHi);
      productRange(lensLoY[size_t(s)], lensHiY[size_t(s)], cy0, cy1, shyLo, shyHi);
    }
    // The pinhole box over the plane's times: the lerped boxes at its first and last (their
    // union bounds the lerp between), widened as the per-sample test is.
    float px0 = bx0, py0 = by0, px1 = bx1, py1 = by1;
    if (lerp) {
      const float f0 = lensPlaneF0[size_t(s)], f1 = lensPlaneF1[size_t(s)];
      if (f0 > f1) continue;  // no sample of this plane in the region's groups
      auto at = [](float a, float b, float f) { return a + f * (b - a); };
      px0 = std::min(at(e0[0], e1[0], f0), at(e0[0], e1[0], f1)) - lagX, px1 = std::max(at(e0[2], e1[2], f0), at(e0[2], e1[2], f1)) + lagX;
      py0 = std::min(at(e0[1], e1[1], f0), at(e0[1], e1[1], f1)) - lagY, py1 = std::max(at(e0[3], e1[3], f0), at(e0[3], e1[3], f1)) + lagY;
    }
    // The plane's search box; each sample in it is then held to `box` displaced by its own lens point.
    if (!testArea(bounded, px0 + shxLo, py0 + shyLo, px1 + shxHi, py1 + shyHi, ta)) continue;
    const size_t first = size_t(s) * PS + size_t(ta.py0 - y0) * w + size_t(ta.px0 - x0);
    const int cols = ta.px1 - ta.px0 + 1, rows = ta.py1 - ta.py0 + 1;
    stats.lensScanned += uint64_t(cols) * uint64_t(rows);
    size_t n = 0;
    if (vectorKernels) {
      const kernels::SampleRows sr{st.data(), sx.data(), sy.data(), first, size_t(w), cols, rows, nullptr, 0, 1, PS, zbuf.data(), zCull};
      n = kernels::gatherLens(isa, sr, lx.data(), ly.data(), box, candidateList(), 0);
    } else {
      uint32_t* __restrict cand = candidates.data();
      for (int row = 0; row < rows; ++row)
        for (int col = 0; col < cols; ++col) {
          const uint32_t idx = uint32_t(first + size_t(row) * w + size_t(col));
          cand[n] = idx;
          n += (zbuf[idx] > zCull) & box.admits(st[idx], sx[idx], sy[idx], lx[idx], ly[idx]);  // the early depth test, then the lens box
        }
    }
    const uint32_t* cand = candidates.data();
    for (size_t i = 0; i < n; ++i) {
      const uint32_t idx = cand[i];
      if (lc.cover.check && !Source::covers(double(st[idx]), lc.cover.lo, lc.cover.hi, lc.cover.openEnd)) continue;
      ++stats.sampleTests;
      testLens(lc, m, c, tri, flags, idx);
    }
  }
}

// Exact coverage of micropolygon m for one sample: its corners at the sample's time, sheared for
// its lens point, through the static path's edge test.
void BucketRasterizer::Impl::testLens(const LensChunk& lc, uint32_t m, const uint32_t* c, bool tri, uint8_t flags, uint32_t idx) {
  const TilePart& part = lc.part;
  glm::dvec3 P[4];
  const int nc = tri ? 3 : 4;
  if (lc.moving) {
    uint32_t k;
    float f;
    segmentAt(lc.knots, double(st[idx]) + lc.toLocal, k, f);
    for (int j = 0; j < nc; ++j) {
      const glm::dvec3 a(part.position(k, c[j])), b(part.position(k + 1, c[j]));
      P[j] = a + double(f) * (b - a);
    }
  } else {
    for (int j = 0; j < nc; ++j) P[j] = glm::dvec3(part.position(0, c[j]));
  }
  if (tri) P[3] = P[2];
  const double Lx = view.lensRadius * double(lx[idx]), Ly = view.lensRadius * double(ly[idx]), invD = 1.0 / view.focalDistance;
  glm::dvec3 S[4];
  for (int j = 0; j < 4; ++j) {
    const double q = P[j].z * invD - 1.0;
    S[j] = {P[j].x + Lx * q, P[j].y + Ly * q, P[j].z};
  }
  glm::dvec3 E[5];
  for (int k = 0; k < 5; ++k)
    E[k] = tri && (k == 2 || k == 3) ? glm::dvec3(0.0) : toRaster(cross(S[kEdgeVerts[k][0]], S[kEdgeVerts[k][1]]), rasterScale);
  float b[3];
  int t;
  if (!coversFixed(E, tri, opt.backfaceCull && !(flags & store::kTwoSided), sx[idx], sy[idx], t, b)) return;
  const float zv[4] = {float(P[0].z), float(P[1].z), float(P[2].z), float(P[3].z)};
  const float z = t == 0 ? b[0] * zv[0] + b[1] * zv[1] + b[2] * zv[2] : b[0] * zv[0] + b[1] * zv[2] + b[2] * zv[3];
  if (!(z >= view.nearClip && z <= view.farClip)) return;
  const uint32_t tv[3] = {c[0], c[t == 0 ? 1 : 2], c[t == 0 ? 2 : 3]};
  recordHit(lc.hc, idx, m, tv, b, z);
}

}  // namespace reshutter::resample
