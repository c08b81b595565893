// The lens path: depth of field. With a thin lens every micropolygon - still or moving - is drawn
// here. A sample at lens point L sees camera-space point P where the pinhole sees
// P' = P + L (P.z / d - 1) (d the focal distance): a per-sample shear of camera space, which maps a
// micropolygon to a micropolygon, so the exact test is the static path's edge test on the corners
// sheared for the sample's lens point (at the sample's own time, for a moving one). Shared corners
// are sheared by the same arithmetic in both neighbours, so shared edges stay exactly negated and
// the test stays watertight.
//
// Which samples to test: on the raster the shear displaces a point at depth z by a L k(z),
// k(z) = 1/d - 1/z. A sample at raster x with lens point u sees a micropolygon whose pinhole box
// holds x - a u k: for a micropolygon at one depth, the samples to test are those whose sheared
// position x - a u k lies in its pinhole box - a box as small as the pinhole's, whatever the
// circle of confusion. So the bucket's micropolygons are queued, grouped into layers of nearly
// equal k (RasterOptions::lensLayerWidth pixels of displacement per unit of lens), and for each layer the
// bucket's samples are sorted into pixel cells of their position sheared by the layer's middle
// k: a micropolygon then searches the cells of its pinhole box widened by what its own k range
// strays from the layer's (at most half a layer, for a small one) and by its motion, and each
// sample found is held to its own box - the pinhole box displaced by the sample's lens point and
// lerped to its time - before the exact test (the dual-space test of stochastic rasterization,
// Laine et al. 2011, with the lens dimension sorted per layer instead of bounded per stratum).
// Layers are drawn in increasing k, which is increasing depth: nearest first, as chunks are.
#include <algorithm>
#include <cmath>
#include <numeric>

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

// A queued micropolygon's place among the layers (kernels::lensDraw()'s, which the vector kernel
// matches): its
// layer from its k over its knots' depths zkLo..zkHi, the layer's middle kl, how far its own
// displacement per unit of lens, box.cx0..cy1, strays from the layer's (ex, ey), and the rounding
// margin qm of the sheared positions, scaled by the search box over its whole motion (mag: its
// box's and displacements' largest magnitude). q receives that search box widened by qm.
struct LensPlace {
  int32_t layer;
  float kl, ex, ey, qm;
};
LensPlace placeInLayer(const kernels::LensBox& box, float zkLo, float zkHi, float invD, float lensAx, float lensAy, float layerScale, float mag, float kMag,
                       float q[4]) {
  LensPlace p;
  const float kMid = 0.5f * ((invD - 1.f / zkLo) + (invD - 1.f / zkHi));
  const float layerF = std::floor(kMid * layerScale);
  p.layer = std::isfinite(layerF) ? int32_t(std::clamp(layerF, -1e9f, 1e9f)) : 0;
  // The sheared positions a sample must have: x - cxl u lies in the box (over its motion)
  // widened by what the displacement strays from the layer's, |c - cxl| |u| with |u| <= 1.
  p.kl = (float(p.layer) + 0.5f) / layerScale;
  const float cxl = lensAx * p.kl, cyl = lensAy * p.kl;
  p.ex = std::max(std::abs(box.cx0 - cxl), std::abs(box.cx1 - cxl)), p.ey = std::max(std::abs(box.cy0 - cyl), std::abs(box.cy1 - cyl));
  // The rounding of the sheared positions and of the per-sample box, scaled by the search box
  // over the whole motion (no margin yet; a time block's search narrows it).
  box.searchBox(0.f, 1.f, p.ex, p.ey, 0.f, q);
  p.qm = 2e-3f + 1e-5f * std::max({std::abs(q[0]), std::abs(q[1]), std::abs(q[2]), std::abs(q[3]), std::abs(cxl), std::abs(cyl), mag + kMag});
  q[0] -= p.qm, q[1] += p.qm, q[2] -= p.qm, q[3] += p.qm;
  return p;
}

// Whether search box q (placeInLayer()'s) admits any sample's sheared position: x - cxl u within
// the region widened by |cxl| (|u| <= 1), and a pixel more for their rounding.
bool searchReaches(const float q[4], float cxl, float cyl, int x0, int y0, int w, int h) {
  const float reachX = std::abs(cxl) + 1.f, reachY = std::abs(cyl) + 1.f;
  return !(q[1] < float(x0) - reachX || q[0] > float(x0 + w) + reachX || q[3] < float(y0) - reachY || q[2] > float(y0 + h) + reachY);
}

}  // namespace

namespace kernels {

void lensDraw(const LensQueueSetup& s, size_t m, const LensDraws& out) {
  const uint32_t* c = s.corners + 4 * m;
  const int nc = c[3] == kNoCorner ? 3 : 4;
  float bx0 = INFINITY, by0 = INFINITY, bx1 = -INFINITY, by1 = -INFINITY, zLo = INFINITY, zHi = -INFINITY;
  bool bounded = true;
  for (int ci = 0; ci < s.times; ++ci)
    for (int j = 0; j < nc; ++j) {
      const size_t k = size_t(ci) * s.nV + (c[j] - s.vBase);
      const float x = s.projX[k], y = s.projY[k];
      if (std::isnan(x)) bounded = false;
      bx0 = std::min(bx0, x), by0 = std::min(by0, y), bx1 = std::max(bx1, x), by1 = std::max(by1, y);
      zLo = std::min(zLo, s.depth[k]), zHi = std::max(zHi, s.depth[k]);
    }
  out.zCull[m] = s.occlusionCulling ? zLo - 1e-5f * std::abs(zLo) : -INFINITY;
  if (!bounded) {
    out.state[m] = 2, out.layer[m] = 0;
    for (float* f : {out.kl, out.x0, out.x1, out.y0, out.y1, out.cx0, out.cx1, out.cy0, out.cy1, out.ex, out.ey, out.qm, out.mx0, out.mx1, out.my0, out.my1}) f[m] = 0.f;
    return;
  }
  // Per lens unit the raster displacement lies in [cx0, cx1] (x) and [cy0, cy1] (y) for every
  // depth the micropolygon takes.
  const float kLo = s.invD - 1.f / zLo, kHi = s.invD - 1.f / zHi;
  float cx0, cx1, cy0, cy1;
  productRange(s.lensAx, s.lensAx, kLo, kHi, cx0, cx1);
  productRange(s.lensAy, s.lensAy, kLo, kHi, cy0, cy1);
  // With two bound times: the box at each end, for the per-sample lerp.
  float e0[4] = {0, 0, 0, 0}, e1[4] = {0, 0, 0, 0}, lag = 0;
  if (s.lerp) {
    for (int end = 0; end < 2; ++end) {
      float* e = end ? e1 : e0;
      e[0] = e[1] = INFINITY, e[2] = e[3] = -INFINITY;
      for (int j = 0; j < nc; ++j) {
        const size_t k = size_t(end) * s.nV + (c[j] - s.vBase);
        e[0] = std::min(e[0], s.projX[k]), e[1] = std::min(e[1], s.projY[k]), e[2] = std::max(e[2], s.projX[k]), e[3] = std::max(e[3], s.projY[k]);
      }
    }
    for (int j = 0; j < nc; ++j) {
      const size_t k = c[j] - s.vBase;
      lag = std::max(lag, perspectiveLag(s.depth[k], s.depth[k + s.nV]));
    }
  }
  // What the lerped boxes are widened by (perspective lag, the rounding of the sample's time),
  // and the rounding margin of the projections and of any displacement the lens gives (|lens
  // point| <= 1).
  const float lagX = (lag + s.uErr + 1e-5f) * (bx1 - bx0), lagY = (lag + s.uErr + 1e-5f) * (by1 - by0);
  const float mag = std::max({std::abs(bx0), std::abs(bx1), std::abs(by0), std::abs(by1), std::abs(cx0), std::abs(cx1), std::abs(cy0), std::abs(cy1)});
  const float margin = 2e-3f + 4e-6f * (mag + s.kMag);
  LensBox box{bx0 - margin, bx1 + margin, by0 - margin, by1 + margin, cx0, cx1, cy0, cy1};
  if (s.lerp) {
    box.x0 = e0[0] - (margin + lagX), box.y0 = e0[1] - (margin + lagY), box.x1 = e0[2] + (margin + lagX), box.y1 = e0[3] + (margin + lagY);
    box.mx0 = e1[0] - e0[0], box.my0 = e1[1] - e0[1], box.mx1 = e1[2] - e0[2], box.my1 = e1[3] - e0[3];
  }
  // The layer: from the micropolygon's depths at its knots, which every bucket sees alike (the
  // bound times above are the region's), so that the draw order - and with it which of two
  // surfaces at exactly one depth a sample keeps - does not depend on the bucketing; every knot
  // segment's draw of it takes the same layer.
  float zkLo = zLo, zkHi = zHi;
  if (s.moving) {
    float lo = INFINITY, hi = -INFINITY;
    for (uint32_t k = 0; k < s.numKnots; ++k)
      for (int j = 0; j < nc; ++j) {
        const float z = s.knotXyz[k][3 * size_t(c[j] - s.vBase) + 2];
        lo = std::min(lo, z), hi = std::max(hi, z);
      }
    if (lo >= s.nearClip) {
      zkLo = lo, zkHi = hi;
    } else {  // a knot before the near plane: the depths at the region's bound times
      zkLo = INFINITY, zkHi = -INFINITY;
      for (uint32_t ci = 0; ci < s.allTimes; ++ci)
        for (int j = 0; j < nc; ++j) zkLo = std::min(zkLo, s.allDepth[ci * s.nV + (c[j] - s.vBase)]), zkHi = std::max(zkHi, s.allDepth[ci * s.nV + (c[j] - s.vBase)]);
    }
  }
  float q[4];
  const LensPlace p = placeInLayer(box, zkLo, zkHi, s.invD, s.lensAx, s.lensAy, s.layerScale, mag, s.kMag, q);
  // A search box beyond every sample's sheared position admits none: nothing to draw here.
  out.state[m] = searchReaches(q, s.lensAx * p.kl, s.lensAy * p.kl, s.x0, s.y0, s.w, s.h) ? 1 : 0;
  out.layer[m] = p.layer, out.kl[m] = p.kl, out.ex[m] = p.ex, out.ey[m] = p.ey, out.qm[m] = p.qm;
  out.x0[m] = box.x0, out.x1[m] = box.x1, out.y0[m] = box.y0, out.y1[m] = box.y1;
  out.cx0[m] = cx0, out.cx1[m] = cx1, out.cy0[m] = cy0, out.cy1[m] = cy1;
  out.mx0[m] = box.mx0, out.mx1[m] = box.mx1, out.my0[m] = box.my0, out.my1[m] = box.my1;
}

}  // namespace kernels

void BucketRasterizer::Impl::rasterizeLens(const Source& src, const store::TileEntry& entry, const TilePart& part, const HitContext& hc, const Chunk& ch) {
  const auto& knots = src.knots(entry.schedule);
  const bool moving = (entry.effects & store::kEffectMoving) && part.numKnots > 1 && !ch.still;
  const uint32_t vBase = ch.vLo, nV = ch.vHi - ch.vLo + 1;
  const double F = double(src.frame);
  // Local times to bound at, in order: the region's first sample time, the knots inside the
  // region's times and its last sample time (a corner's screen path is straight between them); a
  // still chunk has one position.
  lensTimes.clear();
  if (moving && tMax > tMin) {
    lensTimes.push_back(tMin - F);
    for (double k : knots)
      if (k > tMin - F && k < tMax - F) lensTimes.push_back(k);
    lensTimes.push_back(tMax - F);
  } else {
    lensTimes.push_back(moving ? tMin - F : 0.0);  // an instant, or no motion
  }
  const size_t C = lensTimes.size();
  cullX.resize(C * nV), cullY.resize(C * nV), cullZ.resize(C * nV);
  segmentBounded.assign(C, 1);
  // Per bound time whose positions are all bounded (then none is NaN, and min and max are exact in
  // any order): their box and depth range.
  timeRange.resize(C);
  if (vectorKernels) {
    // project(positionAt()) eight vertices at a time, with their box.
    for (size_t ci = 0; ci < C; ++ci) {
      uint32_t ka = 0, kb = 0;
      float f = 0.f;
      if (moving) knotsAt(part, knots, lensTimes[ci], ka, kb, f);
      float* r = timeRange[ci].data();
      if (kernels::projectLerped(isa, &part.position(ka, vBase).x, &part.position(kb, vBase).x, f, nV, projectionScale, cullX.data() + ci * nV,
                                 cullY.data() + ci * nV, cullZ.data() + ci * nV, r))
        segmentBounded[ci] = 0;
      else
        floatRange(cullZ.data() + ci * nV, nV, r[4], r[5]);
    }
  } else {
    for (size_t ci = 0; ci < C; ++ci) {
      for (uint32_t i = 0; i < nV; ++i) {
        const glm::vec3 p = moving ? positionAt(part, knots, vBase + i, lensTimes[ci]) : part.position(0, vBase + i);
        float x = 0, y = 0;
        if (!project(p, x, y)) x = NAN, segmentBounded[ci] = 0;
        cullX[ci * nV + i] = x, cullY[ci * nV + i] = y, cullZ[ci * nV + i] = p.z;
      }
      float* r = timeRange[ci].data();
      if (segmentBounded[ci])
        floatRange(cullX.data() + ci * nV, nV, r[0], r[2]), floatRange(cullY.data() + ci * nV, nV, r[1], r[3]), floatRange(cullZ.data() + ci * nV, nV, r[4], r[5]);
    }
  }
  const float lensAx = float(view.ax * view.lensRadius), lensAy = float(view.ay * view.lensRadius);
  const float invD = float(1.0 / view.focalDistance);
  // The box over bound times [b0, b1] (their corners' paths lie in it: a straight path projects
  // to a straight one), widened by the largest displacement the whole aperture gives its depths;
  // false if it misses the region.
  auto touchesRegion = [&](size_t b0, size_t b1) {
    float bx0 = INFINITY, by0 = INFINITY, bx1 = -INFINITY, by1 = -INFINITY, zLo = INFINITY, zHi = -INFINITY;
    for (size_t ci = b0; ci <= b1; ++ci) {
      if (!segmentBounded[ci]) return true;
      const auto& r = timeRange[ci];
      bx0 = std::min(bx0, r[0]), by0 = std::min(by0, r[1]), bx1 = std::max(bx1, r[2]), by1 = std::max(by1, r[3]);
      zLo = std::min(zLo, r[4]), zHi = std::max(zHi, r[5]);
    }
    float sxLo, sxHi, syLo, syHi;
    const float kLo = invD - 1.f / zLo, kHi = invD - 1.f / zHi;
    productRange(-lensAx, lensAx, kLo, kHi, sxLo, sxHi);
    productRange(-lensAy, lensAy, kLo, kHi, syLo, syHi);
    return !boxMissesRegion(bx0 + sxLo, by0 + syLo, bx1 + sxHi, by1 + syHi, 2.f);
  };
  // Which knot segments' boxes reach the region (a still chunk or an instant: its one
  // position); a chunk none of whose segments does is dropped whole.
  const size_t segments = C > 1 ? C - 1 : 1;
  segmentTouches.resize(segments);
  bool touches = false;
  for (size_t seg = 0; seg < segments; ++seg) touches |= (segmentTouches[seg] = touchesRegion(seg, std::min(seg + 1, C - 1)));
  if (!touches) {
    stats.chunkCulledMicropolygons += ch.m1 - ch.m0;
    return;
  }
  stats.lensMicropolygons += ch.m1 - ch.m0;
  const double covLo = src.coverStart(), covHi = src.coverEnd();
  const Coverage cover{!Source::covers(tMin, covLo, covHi, src.endShared) || !Source::covers(tMax, covLo, covHi, src.endShared), covLo - tBase, covHi - tBase,
                       src.endShared};
  // The displacement coefficients' own rounding: k = 1/d - 1/z cancels near the focal plane.
  const float zNear = *std::min_element(cullZ.begin(), cullZ.begin() + ptrdiff_t(C * nV));
  const float kMag = std::max(std::abs(lensAx), std::abs(lensAy)) * (invD + (zNear > 0 ? 1.f / zNear : 0.f));
  const double toLocal = tBase - F;
  // A moving chunk is drawn once per knot segment of the region's times: over one segment each
  // corner moves along a straight screen line, so a sample is held to the lerp of the segment's
  // end boxes at its own time (MovingBox's idea), widened by the perspective lag and the rounding
  // of its time; a micropolygon's box over its whole path would hold every sample near any part
  // of a curved path. Each sample belongs to one segment (segLo <= its time < segHi, in st
  // units, the knots' times rounded once), so it tests the micropolygon once.
  const int blocks = lensTimeBlocks, perBlock = N / blocks;
  for (size_t seg = 0; seg < segments; ++seg) {
    if (!segmentTouches[seg]) continue;
    float thetaA = 0, invLen = 0, uErr = 0;
    const uint32_t blockF = uint32_t(lensBlockF.size());
    if (C > 1) {
      const double len = lensTimes[seg + 1] - lensTimes[seg];
      thetaA = float(lensTimes[seg] - toLocal), invLen = float(1.0 / len);
      uErr = float(5e-7 * std::max({1.0, std::abs(lensTimes[seg]), std::abs(lensTimes[seg + 1]), std::abs(toLocal)}) / len);
      // Each time block's span of the lerp parameter (its planes' times over the region's
      // groups), widened for the rounding of a sample's parameter: its samples search that part
      // of the path; a block wholly outside the segment is not searched (f0 > f1).
      for (int b = 0; b < blocks; ++b) {
        float f0 = 1.f, f1 = 0.f;
        for (size_t g = 0; g < groupPresent.size(); ++g) {
          if (!groupPresent[g]) continue;
          const size_t gs = g * size_t(N) + size_t(b * perBlock);
          const double lo = (stratumLo[gs] - F - lensTimes[seg]) / len, hi = (stratumHi[gs] - F - lensTimes[seg]) / len;
          const double slack = 1e-6 + double(uErr);
          if (hi < -slack || lo > 1.0 + slack) continue;
          f0 = std::min(f0, std::clamp(float(lo) - 1e-6f, 0.f, 1.f)), f1 = std::max(f1, std::clamp(float(hi) + 1e-6f, 0.f, 1.f));
        }
        lensBlockF.push_back(f0), lensBlockF.push_back(f1);
      }
    }
    LensChunk lc{&part, &knots, hc, &src, &entry, moving, vBase, nV, size_t(C > 1 ? 2 : 1), uint32_t(seg), uint32_t(C), lensAx, lensAy, invD,
                 std::isfinite(kMag) ? kMag : 0.f, cover, toLocal, thetaA, invLen, uErr, invLen > 0 ? blockF : ~0u};
    lc.segLo = seg > 0 ? float(lensTimes[seg] - toLocal) : -INFINITY;
    lc.segHi = seg + 1 < segments ? float(lensTimes[seg + 1] - toLocal) : INFINITY;
    lensChunks.push_back(lc);
    if (segments > 1) stats.lensSegmentDraws += ch.m1 - ch.m0;
    queueLensDraws(lensChunks.back(), uint32_t(lensChunks.size() - 1), ch.m0, ch.m1);
  }
}

// Micropolygons [m0, m1) of a lens chunk (one knot segment's draw, for a moving one) queued with
// their boxes for the per-sample test and their layers, from the chunk's bound positions
// (cullX/Y/Z): kernels::lensDraw(), or eight at a time the vector kernel that matches it. They
// wait until the bucket's chunks are all in (drawLensQueued()).
void BucketRasterizer::Impl::queueLensDraws(const LensChunk& lc, uint32_t chunk, uint32_t m0, uint32_t m1) {
  const TilePart& part = *lc.part;
  const size_t count = m1 - m0, room = (count + 7) & ~size_t(7);
  lensDrawFields.resize(kernels::LensDraws::kFloatFields * room), lensDrawLayer.resize(room), lensDrawState.resize(room);
  float* f = lensDrawFields.data();
  auto field = [&](int i) { return f + size_t(i) * room; };
  const kernels::LensDraws out{field(0),  field(1),  field(2),  field(3),  field(4),  field(5),  field(6),  field(7),  field(8),
                               field(9),  field(10), field(11), field(12), field(13), field(14), field(15), field(16), lensDrawLayer.data(),
                               lensDrawState.data()};
  knotXyz.resize(part.numKnots);
  for (uint32_t k = 0; k < part.numKnots; ++k) knotXyz[k] = &part.position(k, lc.vBase).x;
  const size_t base = size_t(lc.cullBase) * lc.nV;
  kernels::LensQueueSetup setup{};
  setup.corners = &part.corners[size_t(m0) * 4], setup.vBase = lc.vBase, setup.nV = lc.nV;
  setup.projX = cullX.data() + base, setup.projY = cullY.data() + base, setup.depth = cullZ.data() + base;
  setup.times = int(lc.C), setup.lerp = lc.invLen > 0, setup.uErr = lc.uErr;
  setup.moving = lc.moving, setup.knotXyz = knotXyz.data(), setup.numKnots = part.numKnots, setup.nearClip = view.nearClip;
  setup.allDepth = cullZ.data(), setup.allTimes = lc.cullTimes;
  setup.lensAx = lc.lensAx, setup.lensAy = lc.lensAy, setup.invD = lc.invD, setup.kMag = lc.kMag;
  setup.layerScale = std::max(std::abs(lc.lensAx), std::abs(lc.lensAy)) / (opt.lensLayerWidth > 0.f ? opt.lensLayerWidth : 2.f);
  setup.x0 = x0, setup.y0 = y0, setup.w = w, setup.h = h, setup.occlusionCulling = opt.occlusionCulling;
  if (vectorKernels) kernels::lensDraws(isa, setup, count, out);
  else
    for (size_t i = 0; i < count; ++i) kernels::lensDraw(setup, i, out);
  for (size_t i = 0; i < count; ++i) {
    if (out.state[i] == 3) kernels::lensDraw(setup, i, out);  // a knot before the near plane
    const uint8_t state = out.state[i];
    if (state == 0) {
      ++stats.lensCulledMicropolygons;
      continue;
    }
    LensDraw& d = lensDraws.emplace_back();
    d.chunk = chunk, d.m = m0 + uint32_t(i), d.zCull = out.zCull[i];
    if (state == 2) {  // a corner before the near plane: every sample is tested, in the layer drawn first
      d.layer = INT32_MIN, d.kl = d.ex = d.ey = d.qm = 0.f;
      d.box = kernels::LensBox{-INFINITY, INFINITY, -INFINITY, INFINITY, 0.f, 0.f, 0.f, 0.f};
      continue;
    }
    d.layer = out.layer[i], d.kl = out.kl[i], d.ex = out.ex[i], d.ey = out.ey[i], d.qm = out.qm[i];
    d.box = kernels::LensBox{out.x0[i], out.x1[i], out.y0[i], out.y1[i], out.cx0[i], out.cx1[i], out.cy0[i], out.cy1[i]};
    if (setup.lerp) {
      d.box.mx0 = out.mx0[i], d.box.mx1 = out.mx1[i], d.box.my0 = out.my0[i], d.box.my1 = out.my1[i];
      d.box.thetaA = lc.thetaA, d.box.invLen = lc.invLen;
    }
  }
}

// Draws the queued micropolygons layer by layer (nearest first; queue order - chunks nearest
// first - within a layer).
void BucketRasterizer::Impl::drawLensQueued() {
  if (lensDraws.empty()) return;
  // Stably by layer: a counting sort over the layers' range (a bucket's layers are a few dozen
  // consecutive numbers; the unbounded ones, INT32_MIN, first), a comparison sort if it is wide.
  lensOrder.resize(lensDraws.size());
  int32_t lo = INT32_MAX, hi = INT32_MIN;
  for (const LensDraw& d : lensDraws)
    if (d.layer != INT32_MIN) lo = std::min(lo, d.layer), hi = std::max(hi, d.layer);
  if (lo > hi) lo = hi = 0;
  const bool counted = int64_t(hi) - int64_t(lo) < (int64_t(1) << 16);
  if (counted) {
    auto slotOf = [lo](int32_t layer) { return layer == INT32_MIN ? size_t(0) : size_t(int64_t(layer) - lo) + 1; };
    lensLayerStart.assign(size_t(hi - lo) + 3, 0);
    for (const LensDraw& d : lensDraws) ++lensLayerStart[slotOf(d.layer) + 1];
    std::partial_sum(lensLayerStart.begin(), lensLayerStart.end(), lensLayerStart.begin());
    for (uint32_t i = 0; i < uint32_t(lensDraws.size()); ++i) lensOrder[lensLayerStart[slotOf(lensDraws[i].layer)]++] = i;
  } else {
    std::iota(lensOrder.begin(), lensOrder.end(), 0u);
    std::stable_sort(lensOrder.begin(), lensOrder.end(), [&](uint32_t a, uint32_t b) { return lensDraws[a].layer < lensDraws[b].layer; });
  }
  uint32_t currentChunk = ~0u;
  HitContext hc{};
  int32_t sortedLayer = INT32_MIN;
  size_t sortedFirst = 0;  // the sorted layer's first place in lensOrder
  for (size_t oi = 0; oi < lensOrder.size(); ++oi) {
    const LensDraw& d = lensDraws[lensOrder[oi]];
    const LensChunk& lc = lensChunks[d.chunk];
    if (d.chunk != currentChunk) {
      currentChunk = d.chunk;
      // A context that points at per-store scratch is made afresh: the chunks of other stores
      // may have replaced it since this one was queued.
      hc = lc.hc.timedAov ? hitContext(lc.src->store->meta(), *lc.entry, *lc.part, st.data(), lc.hc.toLocal) : lc.hc;
    }
    // Draws go by layer, so parts interleave and a draw's corners are rarely in cache: fetched
    // now, read after the search.
    __builtin_prefetch(&lc.part->corners[size_t(d.m) * 4], 0, 3);
    size_t n = 0;
    const kernels::LensCandidates cand{candidates.data(), candT.data(), candX.data(), candY.data(), candU.data(), candV.data()};
    // A sample the box admits becomes a candidate when it passes the early depth test, lies in
    // the store's times (the coverage) and in this draw's knot segment: copied to the candidates
    // (slot, time, position, lens point) for the exact test. No sample is admitted twice (blocks
    // and cells partition the samples), so testing them all before any is drawn is the same as
    // testing each as it is drawn.
    auto addCandidate = [&](uint32_t idx, float t, float x, float y, float u, float v) {
      if (!(zbuf[idx] > d.zCull)) return;  // the early depth test
      // The sample's colour record, which a hit writes after the exact test: a line of a random
      // plane, fetched now while the exact test runs.
      __builtin_prefetch(&colour[idx], 1, 3);
      if (lc.cover.check && !Source::covers(double(t), lc.cover.lo, lc.cover.hi, lc.cover.openEnd)) return;
      if (!(t >= lc.segLo && t < lc.segHi)) return;  // another knot segment's sample
      cand.index[n] = idx, cand.t[n] = t, cand.x[n] = x, cand.y[n] = y, cand.u[n] = u, cand.v[n] = v;
      ++n;
    };
    if (d.layer == INT32_MIN) {
      // Unbounded: every sample of the region.
      for (int s = 0; s < N; ++s)
        for (size_t p = 0; p < size_t(P); ++p) {
          const size_t j = size_t(s) * PS + p;
          addCandidate(uint32_t(j), st[j], sx[j], sy[j], lx[j], ly[j]);
        }
      stats.lensScanned += size_t(N) * size_t(P);
    } else {
      if (d.layer != sortedLayer) {
        // The layer's end: where the counting sort's scatter left the layer's slot (the next
        // slot's start), else found along the order (each step a random read of a draw).
        size_t last = oi + 1;
        if (counted) last = lensLayerStart[size_t(int64_t(d.layer) - lo) + 1];
        else
          while (last < lensOrder.size() && lensDraws[lensOrder[last]].layer == d.layer) ++last;
        sortLensLayer(oi, last, lc.lensAx * d.kl, lc.lensAy * d.kl);
        sortedLayer = d.layer, sortedFirst = oi;
        ++stats.lensLayers;
      }
      const LensGrid& g = lensGrid;
      // The cells the sheared box touches, time block by time block (for a micropolygon that
      // lerps, over that block's part of its path; a box beyond the grid's edge takes the edge
      // cells, which hold every sample sheared beyond it): made by the layer's sort.
      const kernels::LensBox& box = d.box;
      uint32_t* __restrict at = lensCandPos.data();
      size_t admitted = 0, searches = 0;
      const LensCellRect* rect = &lensDrawCells[(oi - sortedFirst) * size_t(lensTimeBlocks)];
      for (int b = 0; b < lensTimeBlocks; ++b)
        if (rect[b].r0 <= rect[b].r1)
          lensSearches[searches++] = kernels::LensSearch{lensCellStart.data() + size_t(b) * g.cells, rect[b].c0, rect[b].r0, rect[b].c1, rect[b].r1};
      // Every block's search in one kernel call, or the scalar walk of the same rows.
      if (vectorKernels) {
        const kernels::LensCells cells{lensSortedT.data(), lensSortedX.data(), lensSortedY.data(), lensSortedU.data(), lensSortedV.data(), &stats.lensScanned};
        admitted = kernels::gatherLensCells(isa, cells, size_t(g.cols), lensSearches.data(), searches, box, at, admitted);
      } else {
        stats.lensScanned += kernels::forEachLensRow(lensSearches.data(), searches, size_t(g.cols), [&](uint32_t first, uint32_t last) {
          for (uint32_t i = first; i < last; ++i) {
            at[admitted] = i;
            admitted += box.admits(lensSortedT[i], lensSortedX[i], lensSortedY[i], lensSortedU[i], lensSortedV[i]);
          }
        });
      }
      for (size_t i = 0; i < admitted; ++i) {
        const uint32_t p = at[i];
        addCandidate(lensSortedIndex[p], lensSortedT[p], lensSortedX[p], lensSortedY[p], lensSortedU[p], lensSortedV[p]);
      }
    }
    if (!n) continue;
    stats.sampleTests += n;
    const TilePart& part = *lc.part;
    const uint32_t* c = &part.corners[size_t(d.m) * 4];
    const bool tri = c[3] == kNoCorner;
    const uint8_t flags = part.flags[d.m];
    // The corners' colours, which each hit interpolates: fetched while the exact test runs.
    if (hc.colour)
      for (int j = 0; j < (tri ? 3 : 4); ++j) __builtin_prefetch(hc.colour + size_t(c[j]) * 3, 0, 3);
    if (lc.moving && vectorKernels) {
      drawMovingLens(lc, hc, d, c, tri, flags, n);
      continue;
    }
    if (lc.moving || !vectorKernels) {
      if (!lc.moving) lensEdges(part, c, tri);
      for (size_t i = 0; i < n; ++i) {
        const LensSample ls{cand.index[i], cand.t[i], cand.x[i], cand.y[i], cand.u[i], cand.v[i]};
        if (lc.moving) testLens(lc, hc, d.m, c, tri, flags, ls);
        else testStillLens(hc, d.m, c, tri, flags, ls);
      }
      continue;
    }
    // A still micropolygon with the vector kernels: the edge test eight at a time, exact ties
    // (undecided) in the scalar test - the same hits, in the same order, as the loop above.
    lensEdges(part, c, tri);
    kernels::EdgeTestSetup setup{cand.t, cand.x, cand.y, 0.f, 0.f, tri, opt.backfaceCull && !(flags & store::kTwoSided), true};
    for (int j = 0; j < 4; ++j) setup.za[j] = setup.zb[j] = stillLens.z[j];
    setup.su = cand.u, setup.sv = cand.v, setup.lensRadius = view.lensRadius;
    recordKernelHits(hc, d.m, c, setup, stillLens.edges, n,
                     [&](uint32_t idx) { testStillLens(hc, d.m, c, tri, flags, LensSample{idx, st[idx], sx[idx], sy[idx], lx[idx], ly[idx]}); });
  }
  lensDraws.clear(), lensChunks.clear(), lensBlockF.clear();
}

// A moving micropolygon's n candidates with the vector kernels (each past the early depth test,
// the coverage and the draw's time range): their segment parameters, then testMovingLens() on
// them - testLens()' hits. A candidate whose time falls in another knot segment than the first
// one's (a time on a knot, rounded) takes testLens() itself.
void BucketRasterizer::Impl::drawMovingLens(const LensChunk& lc, const HitContext& hc, const LensDraw& d, const uint32_t* c, bool tri, uint8_t flags,
                                            size_t n) {
  uint32_t* __restrict index = candidates.data();
  float* __restrict t = candT.data();
  float* __restrict x = candX.data();
  float* __restrict y = candY.data();
  float* __restrict u = candU.data();
  float* __restrict v = candV.data();
  float* __restrict fs = candF.data();
  size_t kept = 0;
  uint32_t segment = ~0u;
  for (size_t i = 0; i < n; ++i) {
    const uint32_t idx = index[i];
    uint32_t k;
    float f;
    segmentAt(*lc.knots, double(t[i]) + lc.toLocal, k, f);
    if (segment == ~0u) segment = k;
    if (k != segment) {
      testLens(lc, hc, d.m, c, tri, flags, LensSample{idx, t[i], x[i], y[i], u[i], v[i]});
      continue;
    }
    index[kept] = idx, x[kept] = x[i], y[kept] = y[i], u[kept] = u[i], v[kept] = v[i], fs[kept] = f;
    ++kept;
  }
  if (!kept) return;
  const TilePart& part = *lc.part;
  // Every field set (a value-initialised set-up would clear its corner arrays first, per draw).
  kernels::MovingLensSetup setup;
  setup.f = fs, setup.su = u, setup.sv = v, setup.sx = x, setup.sy = y;
  setup.lensRadius = view.lensRadius, setup.invD = 1.0 / view.focalDistance, setup.scale = rasterScale, setup.triangle = tri;
  setup.cullBackFaces = opt.backfaceCull && !(flags & store::kTwoSided);
  for (int j = 0; j < 4; ++j) {
    const uint32_t corner = c[tri && j == 3 ? 2 : j];
    const glm::dvec3 a(part.position(segment, corner)), b(part.position(segment + 1, corner)), delta = b - a;
    for (int axis = 0; axis < 3; ++axis) setup.a[axis][j] = a[axis], setup.d[axis][j] = delta[axis];
  }
  recordEdgeHits(hc, d.m, c, kernels::testMovingLens(isa, setup, kept, edgeHits.data()),
                 [&](uint32_t idx) { testLens(lc, hc, d.m, c, tri, flags, LensSample{idx, st[idx], sx[idx], sy[idx], lx[idx], ly[idx]}); });
}

// A still micropolygon's edges as functions of the lens point (kernels::stillLensEdges(), its
// definition or the vector kernel that matches it), and its corner depths.
void BucketRasterizer::Impl::lensEdges(const TilePart& part, const uint32_t* c, bool tri) {
  const glm::vec3* p[4];
  for (int j = 0; j < 4; ++j) p[j] = &part.position(0, c[tri && j == 3 ? 2 : j]);
  const double invD = 1.0 / view.focalDistance;
  if (vectorKernels) {
    const float* at[4] = {&p[0]->x, &p[1]->x, &p[2]->x, &p[3]->x};
    kernels::stillLensEdges(isa, at, tri, invD, rasterScale, stillLens.edges);
  } else {
    kernels::stillLensEdges(p, tri, invD, rasterScale, stillLens.edges);
  }
  for (int j = 0; j < 4; ++j) stillLens.z[j] = p[j]->z;
}

// Exact coverage of a still micropolygon (lensEdges() made for it) for one sample: its edges at
// the sample's lens point, through the static path's edge test.
void BucketRasterizer::Impl::testStillLens(const HitContext& hc, uint32_t m, const uint32_t* c, bool tri, uint8_t flags, const LensSample& ls) {
  const double Lx = view.lensRadius * double(ls.u), Ly = view.lensRadius * double(ls.v);
  const auto& e = stillLens.edges.c;
  auto edge = [&](int k) {
    return (glm::dvec3(e[0][k], e[1][k], e[2][k]) + Lx * glm::dvec3(e[3][k], e[4][k], e[5][k])) + Ly * glm::dvec3(e[6][k], e[7][k], e[8][k]);
  };
  // Triangle A's edges (01, 12, 02) first; B's two others only if A misses (coversFixed()'s test
  // and order, its edges made as they are needed).
  glm::dvec3 E[5];
  E[0] = edge(0), E[1] = edge(1), E[4] = edge(4);
  const bool cullBack = opt.backfaceCull && !(flags & store::kTwoSided);
  const double x = ls.x, y = ls.y;
  float b[3];
  int t = 0;
  if (!triangleCovers(
          edgeAt(x, y, E[1]), -edgeAt(x, y, E[4]), edgeAt(x, y, E[0]), [&](int i) { return i == 0 ? E[1] : i == 1 ? -E[4] : E[0]; }, cullBack, b)) {
    if (tri) return;
    E[2] = edge(2), E[3] = edge(3);
    t = 1;
    if (!triangleCovers(edgeAt(x, y, E[2]), edgeAt(x, y, E[3]), edgeAt(x, y, E[4]), [&](int i) { return E[2 + i]; }, cullBack, b)) return;
  }
  const float* zv = stillLens.z;
  const float z = t == 0 ? b[0] * zv[0] + b[1] * zv[1] + b[2] * zv[2] : b[0] * zv[0] + b[1] * zv[2] + b[2] * zv[3];
  if (!(z >= view.nearClip && z <= view.farClip)) return;
  const uint32_t tv[3] = {c[0], c[t == 0 ? 1 : 2], c[t == 0 ? 2 : 3]};
  recordHit(hc, ls.slot, m, tv, b, z);
}

// Exact coverage of a moving micropolygon m for one sample: its corners at the sample's time,
// sheared for its lens point, through the static path's edge test.
void BucketRasterizer::Impl::testLens(const LensChunk& lc, const HitContext& hc, uint32_t m, const uint32_t* c, bool tri, uint8_t flags, const LensSample& ls) {
  const TilePart& part = *lc.part;
  glm::dvec3 P[4];
  const int nc = tri ? 3 : 4;
  uint32_t k;
  float f;
  segmentAt(*lc.knots, double(ls.t) + lc.toLocal, k, f);
  for (int j = 0; j < nc; ++j) {
    const glm::dvec3 a(part.position(k, c[j])), b(part.position(k + 1, c[j]));
    P[j] = a + double(f) * (b - a);
  }
  if (tri) P[3] = P[2];
  const double Lx = view.lensRadius * double(ls.u), Ly = view.lensRadius * double(ls.v), invD = 1.0 / view.focalDistance;
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
  if (!coversFixed(E, tri, opt.backfaceCull && !(flags & store::kTwoSided), ls.x, ls.y, t, b)) return;
  const float zv[4] = {float(P[0].z), float(P[1].z), float(P[2].z), float(P[3].z)};
  const float z = t == 0 ? b[0] * zv[0] + b[1] * zv[1] + b[2] * zv[2] : b[0] * zv[0] + b[1] * zv[2] + b[2] * zv[3];
  if (!(z >= view.nearClip && z <= view.farClip)) return;
  const uint32_t tv[3] = {c[0], c[t == 0 ? 1 : 2], c[t == 0 ? 2 : 3]};
  recordHit(hc, ls.slot, m, tv, b, z);
}

}  // namespace reshutter::resample
