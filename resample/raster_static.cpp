// The static path: micropolygons with one set of positions for every sample time - parts that do
// not move, chunks of a moving part that stand still, and every part at an exact instant (a
// zero-length shutter) - tested against every stratum's samples with fixed edges.
#include <algorithm>
#include <cmath>

#include "resample/raster_impl.h"

namespace reshutter::resample {

using store::kNoCorner;
using store::TilePart;

// Micropolygons [ch.m0, ch.m1) at the positions chunkPos (the chunk's vertices: vertex v at
// chunkPos[v - ch.vLo]), for every sample or only group onlyGroup's (>= 0).
void BucketRasterizer::Impl::rasterizeStatic(const Source& src, const TilePart& part, const HitContext& hc, const glm::vec3* chunkPos, int onlyGroup,
                                             const Chunk& ch) {
  const double covLo = src.coverStart(), covHi = src.coverEnd();
  const bool checkCover = !Source::covers(tMin, covLo, covHi, src.endShared) || !Source::covers(tMax, covLo, covHi, src.endShared);
  const uint32_t vBase = ch.vLo, nV = ch.vHi - ch.vLo + 1;
  projX.resize(nV), projY.resize(nV);
  // Each vertex is projected once, not once per micropolygon that shares it (about four). A
  // chunk wholly outside the region (a part's edge beyond the bucket, usually) is dropped whole:
  // its box and margin bound every micropolygon's, so testArea() would reject each.
  bool missesRegion;
  if (vectorKernels) {
    // project()'s values eight at a time, with the chunk's box (pointsMissRegion()'s, over
    // the same points).
    projZ.resize(nV);
    float box[4];
    const bool unbounded = kernels::projectLerped(isa, &chunkPos[0].x, &chunkPos[0].x, 0.f, nV, projectionScale, projX.data(), projY.data(), projZ.data(), box);
    missesRegion = !unbounded && boxMissesRegion(box[0], box[1], box[2], box[3], 1.f);
  } else {
    for (size_t i = 0; i < nV; ++i)
      if (!project(chunkPos[i], projX[i], projY[i])) projX[i] = NAN;
    missesRegion = pointsMissRegion(projX.data(), projY.data(), nV, 1.f);
  }
  if (missesRegion) {
    stats.chunkCulledMicropolygons += ch.m1 - ch.m0;
    return;
  }
  if (vectorKernels && !checkCover) {
    rasterizeStaticVector(part, hc, chunkPos, onlyGroup, ch);
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
      const glm::vec3* p[4];
      for (int j = 0; j < 4; ++j) p[j] = &chunkPos[c[tri && j == 3 ? 2 : j] - vBase];
      fixedEdges(p, tri, rasterScale, E);
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
    makeEdges();
    for (int py = py0; py <= py1; ++py) {
      if (onlyGroup >= 0 && rowGroup[size_t(py - y0)] != onlyGroup) continue;
      for (int px = px0; px <= px1; ++px) {
        const size_t p = size_t(py - y0) * w + size_t(px - x0);
        for (int s = 0; s < N; ++s) {
          const size_t idx = slot(s, p);
          if (sx[idx] < sbx0 || sx[idx] > sbx1 || sy[idx] < sby0 || sy[idx] > sby1) continue;
          if (checkCover && !Source::covers(tBase + st[idx], covLo, covHi, src.endShared)) continue;
          if (!(zbuf[idx] > zCull)) continue;  // the early depth test
          ++stats.sampleTests;
          testStatic(hc, m, c, tri, E, zv, uint32_t(idx));
        }
      }
    }
  }
}

// rasterizeStatic() with the vector kernels, for a chunk that reaches the region and a source that
// covers every sample's time: the micropolygons' boxes, test areas and cull depths eight at a
// time (stillAreas(), the scalar loop's values), then for each one that reaches a sample every
// stratum's samples in its box that pass the early depth test, and the vector edge test with
// fixed edges.
void BucketRasterizer::Impl::rasterizeStaticVector(const TilePart& part, const HitContext& hc, const glm::vec3* chunkPos, int onlyGroup, const Chunk& ch) {
  const uint32_t vBase = ch.vLo, count = ch.m1 - ch.m0;
  StillScratch& a = stillScratch;
  const kernels::StillAreas areas{a.px0, a.py0, a.px1, a.py1, a.sx0, a.sy0, a.sx1, a.sy1, a.zCull, a.state};
  // The vertices' depths as the projection left them in projZ (a still chunk's, not lerped).
  const kernels::StillAreaSetup setup{&part.corners[size_t(ch.m0) * 4], vBase, projX.data(), projY.data(), projZ.data(), x0, y0, w, h, opt.occlusionCulling};
  kernels::stillAreas(isa, setup, count, areas);
  for (uint32_t i = 0; i < count; ++i) {
    if (!a.state[i]) continue;
    const uint32_t m = ch.m0 + i;
    const uint32_t* c = &part.corners[size_t(m) * 4];
    const bool tri = c[3] == kNoCorner;
    // Unbounded (a corner before the near plane): testArea()'s whole region and every sample.
    TestArea ta{x0, y0, x0 + w - 1, y0 + h - 1};
    if (a.state[i] == 1) ta = TestArea{a.px0[i], a.py0[i], a.px1[i], a.py1[i], a.sx0[i], a.sy0[i], a.sx1[i], a.sy1[i]};
    ++stats.staticMicropolygons;
    const MovingBox box{ta.sx0, 0.f, ta.sx1, 0.f, ta.sy0, 0.f, ta.sy1, 0.f, 0.f, 0.f};
    const size_t n = gatherCandidates(0, N, onlyGroup, ta.px0, ta.py0, ta.px1, ta.py1, box, Coverage{false, 0, 0}, a.zCull[i], 0);
    if (!n) continue;
    stats.sampleTests += n;
    // fixedEdges()' values, four edges at a time; the scalar tie test makes its own.
    const float* at[4];
    const glm::vec3* p[4];
    float zv[4];
    for (int j = 0; j < 4; ++j) p[j] = &chunkPos[c[tri && j == 3 ? 2 : j] - vBase], at[j] = &p[j]->x, zv[j] = p[j]->z;
    kernels::LinearEdges edges;
    kernels::fixedEdges(isa, at, rasterScale, edges);
    kernels::EdgeTestSetup test{candT.data(), candX.data(), candY.data(), 0.f, 0.f, tri, opt.backfaceCull && !(part.flags[m] & store::kTwoSided), true};
    std::copy(zv, zv + 4, test.za), std::copy(zv, zv + 4, test.zb);
    bool edgesMade = false;
    glm::dvec3 E[5];
    recordKernelHits(hc, m, c, test, edges, n, [&](uint32_t idx) {
      if (!edgesMade) fixedEdges(p, tri, rasterScale, E), edgesMade = true;
      testStatic(hc, m, c, tri, E, zv, idx);
    });
  }
}

// Exact coverage test of static micropolygon m (edge vectors E, corner depths zv) against one sample.
void BucketRasterizer::Impl::testStatic(const HitContext& hc, uint32_t m, const uint32_t* c, bool tri, const glm::dvec3 E[5], const float zv[4], uint32_t idx) {
  float b[3];
  int t;
  if (!coversFixed(E, tri, opt.backfaceCull && !(hc.part->flags[m] & store::kTwoSided), sx[idx], sy[idx], t, b)) return;
  const float z = t == 0 ? b[0] * zv[0] + b[1] * zv[1] + b[2] * zv[2] : b[0] * zv[0] + b[1] * zv[2] + b[2] * zv[3];
  if (!(z >= view.nearClip && z <= view.farClip)) return;
  const uint32_t tv[3] = {c[0], c[t == 0 ? 1 : 2], c[t == 0 ? 2 : 3]};
  recordHit(hc, idx, m, tv, b, z);
}

}  // namespace reshutter::resample
