// The rasterizer's vector kernels against their definitions, restated in each test (or, for the
// lens path's set-up, the scalar definition the rasterizer runs): the box gathers, the
// projection, the static path's test areas, a chunk's vertex range and nearest depth, the edge
// test's three outcomes, and the lens path's gather and layer cells. (The renders that hold the kernels' images to the scalar loops'
// are in resample_hard_test.cpp.)
#include <algorithm>
#include <bit>
#include <cmath>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "common/random.h"
#include "resample/bucket_samples.h"
#include "resample/coverage.h"
#include "resample/gather.h"
#include "store/model.h"

using namespace reshutter;
using namespace reshutter::resample;

namespace {

// Four corners for each of `count` micropolygons of a chunk's nV vertices from vBase: mostly a
// small quad of neighbouring vertices, sometimes scattered ones (large boxes), a quarter of them
// triangles (the fourth corner kNoCorner).
std::vector<uint32_t> randomCorners(Rng& rng, uint32_t count, uint32_t nV, uint32_t vBase) {
  std::vector<uint32_t> corners(4 * size_t(count));
  for (uint32_t m = 0; m < count; ++m) {
    const uint32_t first = rng.below(nV - 4), spread = rng.below(8) == 0 ? nV : 4;
    for (int j = 0; j < 4; ++j) corners[4 * m + j] = vBase + (spread == 4 ? first + uint32_t(j) : rng.below(nV));
    if (rng.below(4) == 0) corners[4 * m + 3] = store::kNoCorner;
  }
  return corners;
}

// Candidates [from, n) of a gather: each must carry its sample's time and position; returns
// their sample indices, sorted (the gathers' orders are their own).
std::vector<uint32_t> gatheredSamples(const kernels::Candidates& c, size_t from, size_t n, const std::vector<float>& st, const std::vector<float>& sx,
                                      const std::vector<float>& sy) {
  std::vector<uint32_t> got(c.index + from, c.index + n);
  for (size_t k = from; k < n; ++k) {
    EXPECT_EQ(c.t[k], st[c.index[k]]);
    EXPECT_EQ(c.x[k], sx[c.index[k]]);
    EXPECT_EQ(c.y[k], sy[c.index[k]]);
  }
  std::sort(got.begin(), got.end());
  return got;
}

}  // namespace

// The box gather (kernels::gatherInBox) against its definition, restated here: every sample of
// the rows whose position lies in the box at its own time and whose depth lies beyond zCull,
// each once, with copies of its time and position. Row layouts as the rasterizer makes them:
// stratum planes of short rows, and pixel-major rows (one plane, a pixel's samples side by
// side) long enough for the whole-vector loads; fixed and moving boxes; with and without a
// row-group filter (fields).
TEST(ResampleHard, BoxGathersFindExactlyTheSamplesInTheBox) {
  if (!kernels::available()) GTEST_SKIP() << "this CPU has no AVX2";
  Rng rng(71);
  const size_t slots = 4096;
  std::vector<float> st(slots + 16), sx(slots + 16), sy(slots + 16), depth(slots + 16);
  for (size_t i = 0; i < slots + 16; ++i) {
    st[i] = float(rng.uniform()), sx[i] = float(rng.uniform() * 8), sy[i] = float(rng.uniform() * 8);
    depth[i] = float(1 + rng.uniform());
  }
  const std::vector<uint8_t> groups = {0, 1, 0, 1, 0, 1, 0, 1};
  std::vector<uint32_t> index(slots + 16);
  std::vector<float> ct(slots + 16), cx(slots + 16), cy(slots + 16);
  const kernels::Candidates out{index.data(), ct.data(), cx.data(), cy.data()};
  size_t longRowGathers = 0;
  for (int trial = 0; trial < 400; ++trial) {
    const bool pixelMajor = trial % 2, moving = trial % 4 >= 2, grouped = trial % 8 >= 4;
    kernels::SampleRows r{st.data(), sx.data(), sy.data(), 0, 0, 0, 0};
    r.rows = 1 + int(rng.below(4));
    r.cols = pixelMajor ? 16 * (1 + int(rng.below(3))) - int(rng.below(4)) : 1 + int(rng.below(6));
    r.planes = pixelMajor ? 1 : 1 + int(rng.below(16));
    r.stride = size_t(r.cols) + rng.below(8);
    r.planeStride = r.stride * size_t(r.rows) + rng.below(8);
    r.first = rng.below(64);
    r.depth = depth.data(), r.zCull = float(1 + rng.uniform() * 0.5);
    if (grouped) r.rowGroup = groups.data(), r.group = uint8_t(rng.below(2));
    ASSERT_LE(r.first + size_t(r.planes - 1) * r.planeStride + size_t(r.rows - 1) * r.stride + size_t(r.cols), slots);
    kernels::MovingBox box{float(rng.uniform() * 4), 0, float(4 + rng.uniform() * 4), 0, float(rng.uniform() * 4), 0, float(4 + rng.uniform() * 4), 0};
    if (moving) box.dx0 = box.dx1 = float(rng.uniform() * 2 - 1), box.dy0 = box.dy1 = float(rng.uniform() * 2 - 1), box.thetaA = 0.2f, box.invLen = 1.5f;
    // The definition, in the kernels' float operations.
    std::vector<uint32_t> expected;
    for (int plane = 0; plane < r.planes; ++plane)
      for (int row = 0; row < r.rows; ++row) {
        if (r.rowGroup && r.rowGroup[row] != r.group) continue;
        for (int col = 0; col < r.cols; ++col) {
          const size_t i = r.first + size_t(plane) * r.planeStride + size_t(row) * r.stride + size_t(col);
          const float u = std::min(std::max((st[i] - box.thetaA) * box.invLen, 0.f), 1.f);
          const bool in = sx[i] >= box.x0 + u * box.dx0 && sx[i] <= box.x1 + u * box.dx1 && sy[i] >= box.y0 + u * box.dy0 && sy[i] <= box.y1 + u * box.dy1;
          if (in && depth[i] > r.zCull) expected.push_back(uint32_t(i));
        }
      }
    for (kernels::Isa isa : {kernels::Isa::Avx2, kernels::Isa::Avx512}) {
      if (!kernels::available(isa)) continue;
      SCOPED_TRACE(std::string(isa == kernels::Isa::Avx512 ? "avx512" : "avx2") + " trial " + std::to_string(trial));
      const size_t n = kernels::gatherInBox(isa, r, box, out, 3);  // appended after three entries
      ASSERT_GE(n, 3u);
      EXPECT_EQ(gatheredSamples(out, 3, n, st, sx, sy), expected);
    }
    longRowGathers += pixelMajor && !expected.empty();
  }
  EXPECT_GT(longRowGathers, 100u);  // the long rows' loads found samples
}

// The strata gather (kernels::gatherStrata) against its definition, restated here: for each
// stratum s, the pixels its box's path over [u0[s], u1[s]] touches (the box's ends at both times,
// widened by the margin, clamped to the region, floored), and of plane s in those pixels every
// sample inside the box at its own time whose depth lies beyond zCull, each once, with copies of
// its time and position. Small strata (the one-vector paths), wide ones (rows of sixteen and
// more: a run's gather), alternating fields and other row groups, strata counts that are not
// multiples of the vector width.
TEST(ResampleHard, StrataGathersFindExactlyTheSamplesOfTheirStrata) {
  if (!kernels::available()) GTEST_SKIP() << "this CPU has no AVX2";
  Rng rng(29);
  const int x0 = 100, y0 = 50, w = 56, h = 24;
  const size_t PS = size_t(w) * h;
  size_t wideStrata = 0, smallStrata = 0;
  for (int trial = 0; trial < 300; ++trial) {
    const int N = std::vector<int>{4, 9, 16, 23, 64}[rng.below(5)];
    std::vector<float> st(PS * size_t(N) + 16), sx(st.size()), sy(st.size()), depth(st.size());
    const float thetaA = 0.1f, invLen = 1.25f;
    for (int s = 0; s < N; ++s)
      for (int row = 0; row < h; ++row)
        for (int col = 0; col < w; ++col) {
          const size_t i = size_t(s) * PS + size_t(row) * size_t(w) + size_t(col);
          st[i] = thetaA + float((s + rng.uniform()) / N) / invLen;
          sx[i] = float(x0 + col + rng.uniform()), sy[i] = float(y0 + row + rng.uniform());
          depth[i] = float(1 + rng.uniform());
        }
    std::vector<float> u0(static_cast<size_t>(N + 7) / 8 * 8), u1(u0.size());  // read in whole vectors of eight
    for (int s = 0; s < N; ++s) u0[size_t(s)] = float(s) / float(N), u1[size_t(s)] = float(s + 1) / float(N);
    // A box of 1 - 30 pixels moving up to 40 pixels, partly outside the region at times.
    const float bw = float(1 + rng.uniform() * 29), bh = float(1 + rng.uniform() * 6);
    const float bx = float(x0 - 10 + rng.uniform() * (w + 20)), by = float(y0 - 4 + rng.uniform() * (h + 8));
    const float mx = float(rng.uniform(-40, 40)), my = float(rng.uniform(-8, 8));
    const kernels::MovingBox box{bx, mx, bx + bw, mx, by, my, by + bh, my, thetaA, invLen};
    const int grouping = trial % 3;  // 0: none; 1: alternating fields; 2: rows in groups of their own
    std::vector<uint8_t> groups(static_cast<size_t>(h));
    const int parity = int(rng.below(2));
    for (int row = 0; row < h; ++row) groups[size_t(row)] = uint8_t(grouping == 1 ? (row + parity) & 1 : rng.below(2));
    kernels::SampleRows region{st.data(), sx.data(), sy.data(), 0, size_t(w), w, h, grouping ? groups.data() : nullptr, uint8_t(rng.below(2)), N, PS,
                               depth.data(), float(1 + rng.uniform() * 0.5), grouping == 1 ? parity : -1};
    const kernels::StrataSpans spans{u0.data(), u1.data(), N, x0, y0, w, h, 1e-3f};
    // The definition, in the kernels' float operations.
    std::vector<uint32_t> expected;
    for (int s = 0; s < N; ++s) {
      const float a = u0[size_t(s)], b = u1[size_t(s)];
      const float ax0 = std::min(box.x0 + a * box.dx0, box.x0 + b * box.dx0), ax1 = std::max(box.x1 + a * box.dx1, box.x1 + b * box.dx1);
      const float ay0 = std::min(box.y0 + a * box.dy0, box.y0 + b * box.dy0), ay1 = std::max(box.y1 + a * box.dy1, box.y1 + b * box.dy1);
      const int px0 = int(std::floor(std::min(std::max(ax0 - spans.margin, float(x0)), float(x0 + w))));
      const int py0 = int(std::floor(std::min(std::max(ay0 - spans.margin, float(y0)), float(y0 + h))));
      const int px1 = int(std::floor(std::min(std::max(ax1 + spans.margin, float(x0) - 1.f), float(x0 + w) - 1.f)));
      const int py1 = int(std::floor(std::min(std::max(ay1 + spans.margin, float(y0) - 1.f), float(y0 + h) - 1.f)));
      if (px1 < px0 || py1 < py0) continue;
      (px1 - px0 + 1 >= 16 ? wideStrata : smallStrata) += 1;
      for (int py = py0; py <= py1; ++py) {
        if (region.rowGroup && region.rowGroup[py - y0] != region.group) continue;
        for (int px = px0; px <= px1; ++px) {
          const size_t i = size_t(s) * PS + size_t(py - y0) * size_t(w) + size_t(px - x0);
          const float u = std::min(std::max((st[i] - box.thetaA) * box.invLen, 0.f), 1.f);
          const bool in = sx[i] >= box.x0 + u * box.dx0 && sx[i] <= box.x1 + u * box.dx1 && sy[i] >= box.y0 + u * box.dy0 && sy[i] <= box.y1 + u * box.dy1;
          if (in && depth[i] > region.zCull) expected.push_back(uint32_t(i));
        }
      }
    }
    std::sort(expected.begin(), expected.end());
    std::vector<uint32_t> index(st.size() + 16);
    std::vector<float> ct(index.size()), cx(index.size()), cy(index.size());
    for (kernels::Isa isa : {kernels::Isa::Avx2, kernels::Isa::Avx512}) {
      if (!kernels::available(isa)) continue;
      SCOPED_TRACE(std::string(isa == kernels::Isa::Avx512 ? "avx512" : "avx2") + " trial " + std::to_string(trial));
      const kernels::Candidates out{index.data(), ct.data(), cx.data(), cy.data()};
      const size_t n = kernels::gatherStrata(isa, region, spans, box, out);
      ASSERT_EQ(gatheredSamples(out, 0, n, st, sx, sy), expected);
    }
  }
  EXPECT_GT(wideStrata, 500u);   // rows of sixteen and more were gathered
  EXPECT_GT(smallStrata, 500u);
}

// The projection kernel (kernels::projectLerped) against the rasterizer's project(), restated:
// p = a + f (b - a) (or a itself when b is a), then raster x = float(ax (x / z) + bx) in double,
// NaN before the near plane or where x or y is not finite; the box over the others. Counts that
// are not multiples of eight (the kernels' whole-vector loop and their tail), points behind the
// eye, at infinity and NaN, both projections.
TEST(ResampleHard, ProjectionKernelIsProjectBitForBit) {
  if (!kernels::available()) GTEST_SKIP() << "this CPU has no AVX2";
  Rng rng(5);
  for (int trial = 0; trial < 200; ++trial) {
    const bool perspective = trial % 4 != 3, still = trial % 2;
    const kernels::ProjectionScale scale{1000.0 + rng.uniform() * 500, 960.0, -1000.0 - rng.uniform() * 500, 540.0, 0.1f, perspective};
    const size_t n = 1 + rng.below(40);
    std::vector<float> a(3 * n), b(3 * n);
    for (size_t i = 0; i < 3 * n; ++i) {
      a[i] = float(rng.uniform(-2, 2)), b[i] = float(rng.uniform(-2, 2));
      if (i % 3 == 2) a[i] = float(rng.uniform(-0.5, 6)), b[i] = float(rng.uniform(-0.5, 6));  // some behind the near plane
    }
    if (trial % 5 == 0) a[3 * rng.below(uint32_t(n))] = INFINITY;
    if (trial % 7 == 0) a[3 * rng.below(uint32_t(n)) + 1] = NAN;
    if (trial % 3 == 0) a[3 * rng.below(uint32_t(n))] = -0.f;
    const float f = float(rng.uniform());
    const float* to = still ? a.data() : b.data();
    // The definition.
    std::vector<float> ex(n), ey(n), ez(n);
    bool expectBad = false;
    float lo[2] = {INFINITY, INFINITY}, hi[2] = {-INFINITY, -INFINITY};
    for (size_t i = 0; i < n; ++i) {
      float p[3];
      for (int k = 0; k < 3; ++k) p[k] = still ? a[3 * i + k] : a[3 * i + k] + f * (to[3 * i + k] - a[3 * i + k]);
      ez[i] = p[2];
      double px = p[0], py = p[1];
      if (perspective) {
        const double iz = 1.0 / double(p[2]);
        px *= iz, py *= iz;
      }
      const float x = float(scale.ax * px + scale.bx), y = float(scale.ay * py + scale.by);
      const bool ok = (!perspective || p[2] >= scale.nearClip) && std::isfinite(x) && std::isfinite(y);
      ex[i] = ok ? x : NAN, ey[i] = y;
      expectBad |= !ok;
      if (ok) lo[0] = std::min(lo[0], x), lo[1] = std::min(lo[1], y), hi[0] = std::max(hi[0], x), hi[1] = std::max(hi[1], y);
    }
    for (kernels::Isa isa : {kernels::Isa::Avx2, kernels::Isa::Avx512}) {
      if (!kernels::available(isa)) continue;
      SCOPED_TRACE(std::string(isa == kernels::Isa::Avx512 ? "avx512" : "avx2") + " trial " + std::to_string(trial));
      std::vector<float> x(n + 8, 7.f), y(n + 8, 7.f), z(n + 8, 7.f);
      float box[4];
      const bool bad = kernels::projectLerped(isa, a.data(), to, f, n, scale, x.data(), y.data(), z.data(), box);
      EXPECT_EQ(bad, expectBad);
      for (size_t i = 0; i < n; ++i) {
        EXPECT_EQ(std::isnan(x[i]), std::isnan(ex[i])) << i;
        if (!std::isnan(ex[i])) {
          EXPECT_EQ(std::bit_cast<uint32_t>(x[i]), std::bit_cast<uint32_t>(ex[i])) << i;
          EXPECT_EQ(std::bit_cast<uint32_t>(y[i]), std::bit_cast<uint32_t>(ey[i])) << i;
        }
        if (!std::isnan(ez[i])) {
          EXPECT_EQ(std::bit_cast<uint32_t>(z[i]), std::bit_cast<uint32_t>(ez[i])) << i;
        }
      }
      EXPECT_EQ(x[n], 7.f);  // nothing written past n
      if (lo[0] <= hi[0]) {
        EXPECT_EQ(box[0], lo[0]);
        EXPECT_EQ(box[1], lo[1]);
        EXPECT_EQ(box[2], hi[0]);
        EXPECT_EQ(box[3], hi[1]);
      }
    }
  }
}

// The static path's set-up kernel (kernels::stillAreas) against the scalar loop it replaces: each
// micropolygon's corner box from its corners' projections (a NaN x makes it unbounded), the
// region's BucketSamples::testArea() of that box, and the cull depth (nearest corner, less 1e-5
// of it). Random chunks of quads and triangles, some corners without a projection, some with a
// NaN y, boxes inside, across and outside the region, counts that are not multiples of eight.
TEST(ResampleHard, StillAreaKernelIsTheScalarTestArea) {
  if (!kernels::available()) GTEST_SKIP() << "this CPU has no AVX2";
  const SamplePattern pattern(4, 4, 1);
  const ShutterModel shutter = ShutterModel::progressive(0.0, 1.0);
  BucketSamples region(pattern, shutter);
  Rng rng(17);
  size_t drawn = 0, unbounded = 0, missed = 0;
  for (int trial = 0; trial < 300; ++trial) {
    const int rx0 = int(rng.below(200)) - 100, ry0 = int(rng.below(200)) - 100;
    region.prepare(rx0, ry0, 8 + int(rng.below(60)), 8 + int(rng.below(60)));
    const uint32_t nV = 20 + rng.below(60), count = 1 + rng.below(64), vBase = 1000 + rng.below(1000);
    std::vector<float> px(nV), py(nV), depth(nV);
    for (uint32_t v = 0; v < nV; ++v) {
      px[v] = float(rx0 + rng.uniform(-20, 90)), py[v] = float(ry0 + rng.uniform(-20, 90));
      if (rng.below(40) == 0) px[v] = NAN;
      if (rng.below(60) == 0) py[v] = NAN;
      depth[v] = float(rng.uniform(0.5, 50));
    }
    const std::vector<uint32_t> corners = randomCorners(rng, count, nV, vBase);
    for (bool occlusion : {true, false}) {
      const kernels::StillAreaSetup setup{corners.data(), vBase, px.data(), py.data(), depth.data(), region.x0, region.y0, region.w, region.h, occlusion};
      for (kernels::Isa isa : {kernels::Isa::Avx2, kernels::Isa::Avx512}) {
        if (!kernels::available(isa)) continue;
        SCOPED_TRACE(std::string(isa == kernels::Isa::Avx512 ? "avx512" : "avx2") + " trial " + std::to_string(trial));
        std::vector<int32_t> x0(72), y0(72), x1(72), y1(72);
        std::vector<float> sx0(72), sy0(72), sx1(72), sy1(72), zc(72);
        std::vector<uint8_t> state(72);
        kernels::stillAreas(isa, setup, count, {x0.data(), y0.data(), x1.data(), y1.data(), sx0.data(), sy0.data(), sx1.data(), sy1.data(), zc.data(), state.data()});
        for (uint32_t m = 0; m < count; ++m) {
          // The scalar loop's values.
          const uint32_t* c = &corners[4 * m];
          const int nc = c[3] == store::kNoCorner ? 3 : 4;
          float bx0 = INFINITY, by0 = INFINITY, bx1 = -INFINITY, by1 = -INFINITY, zv[4];
          bool bounded = true;
          for (int j = 0; j < nc; ++j) {
            const uint32_t v = c[j] - vBase;
            zv[j] = depth[v];
            if (std::isnan(px[v])) bounded = false;
            else bx0 = std::min(bx0, px[v]), by0 = std::min(by0, py[v]), bx1 = std::max(bx1, px[v]), by1 = std::max(by1, py[v]);
          }
          const float zNear = *std::min_element(zv, zv + nc);
          EXPECT_EQ(zc[m], occlusion ? zNear - 1e-5f * std::abs(zNear) : -INFINITY) << m;
          BucketSamples::TestArea ta;
          const bool reaches = region.testArea(bounded, bx0, by0, bx1, by1, ta);
          ASSERT_EQ(int(state[m]), !bounded ? 2 : reaches ? 1 : 0) << m;
          if (state[m] != 1) continue;
          EXPECT_EQ(x0[m], ta.px0) << m;
          EXPECT_EQ(y0[m], ta.py0) << m;
          EXPECT_EQ(x1[m], ta.px1) << m;
          EXPECT_EQ(y1[m], ta.py1) << m;
          EXPECT_EQ(sx0[m], ta.sx0) << m;
          EXPECT_EQ(sy0[m], ta.sy0) << m;
          EXPECT_EQ(sx1[m], ta.sx1) << m;
          EXPECT_EQ(sy1[m], ta.sy1) << m;
        }
        for (uint32_t m = 0; m < count; ++m) drawn += state[m] == 1, unbounded += state[m] == 2, missed += state[m] == 0;
      }
    }
  }
  // Every outcome taken, many times.
  EXPECT_GT(drawn, 1000u);
  EXPECT_GT(unbounded, 100u);
  EXPECT_GT(missed, 1000u);
}

// The lens path's set-up kernel (kernels::lensDraws) against its definition, the scalar
// kernels::lensDraw() that the rasterizer runs without vector kernels: every field bit for bit,
// for still micropolygons, moving ones at one bound time (an instant) and a knot segment's draw
// between two (the box lerped, its perspective lag), with two or three knots; quads and
// triangles at depths on both sides of the focal plane (k of either sign, and k = 0 exactly at
// the focal distance), corners before the near plane (NaN x) or with a NaN y, knots before the
// near plane (the kernel leaves those to the definition: state 3), raster y flipped (a negative
// lensAy), huge coordinates, regions the search misses, and counts with tails past the
// eight-wide loop.
TEST(ResampleHard, LensSetUpKernelIsItsDefinition) {
  if (!kernels::available()) GTEST_SKIP() << "this CPU has no AVX2";
  Rng rng(29);
  size_t drawn = 0, unbounded = 0, missed = 0, nearFocus = 0, behindKnots = 0, lerped = 0;
  for (int trial = 0; trial < 600; ++trial) {
    const int kind = trial % 3;  // 0 still, 1 an instant of a moving chunk, 2 a knot segment's draw
    const uint32_t nV = 20 + rng.below(60), count = 1 + rng.below(64), vBase = 1000 + rng.below(1000), times = kind == 2 ? 2 : 1;
    const uint32_t knots = kind == 0 ? 1 : 2 + rng.below(2), allTimes = times + rng.below(3);
    const float focus = float(rng.uniform(1, 20)), scale = rng.below(10) == 0 ? 1e6f : 1.f, nearClip = 0.1f;
    const int rx0 = int(rng.below(400)) - 200, ry0 = int(rng.below(400)) - 200, rw = 8 + int(rng.below(120)), rh = 8 + int(rng.below(120));
    // Bound positions at every time of the chunk (the draw's are its first `times`).
    std::vector<float> px(allTimes * nV), py(allTimes * nV), depth(allTimes * nV);
    for (uint32_t v = 0; v < allTimes * nV; ++v) {
      px[v] = float(rx0 + rng.uniform(-150, 250)) * scale, py[v] = float(ry0 + rng.uniform(-150, 250)) * scale;
      if (rng.below(40) == 0) px[v] = NAN;
      if (rng.below(60) == 0) py[v] = NAN;
      depth[v] = rng.below(8) == 0 ? focus : float(rng.uniform(0.2, 60));
    }
    std::vector<std::vector<float>> xyz(knots, std::vector<float>(3 * size_t(nV)));
    for (auto& k : xyz)
      for (uint32_t v = 0; v < nV; ++v) k[3 * v + 2] = rng.below(50) == 0 ? -1.f : float(rng.uniform(0.2, 60));
    std::vector<const float*> knotXyz;
    for (auto& k : xyz) knotXyz.push_back(k.data());
    const std::vector<uint32_t> corners = randomCorners(rng, count, nV, vBase);
    const float lensAx = float(rng.uniform(1, 400)), lensAy = float(rng.uniform(1, 400)) * (rng.below(2) ? -1.f : 1.f);
    const float kMag = std::max(lensAx, std::abs(lensAy)) * float(1 / focus + 1 / 0.2);
    for (bool occlusion : {true, false}) {
      kernels::LensQueueSetup setup{};
      setup.corners = corners.data(), setup.vBase = vBase, setup.nV = nV, setup.projX = px.data(), setup.projY = py.data(), setup.depth = depth.data();
      setup.times = int(times), setup.lerp = kind == 2, setup.uErr = kind == 2 ? float(rng.uniform(0, 1e-4)) : 0.f;
      setup.moving = kind != 0, setup.knotXyz = knotXyz.data(), setup.numKnots = knots, setup.nearClip = nearClip;
      setup.allDepth = depth.data(), setup.allTimes = allTimes;
      setup.lensAx = lensAx, setup.lensAy = lensAy, setup.invD = 1.f / focus, setup.kMag = kMag, setup.layerScale = std::max(lensAx, std::abs(lensAy)) / 2.f;
      setup.x0 = rx0, setup.y0 = ry0, setup.w = rw, setup.h = rh, setup.occlusionCulling = occlusion;
      struct Fields {
        std::vector<float> f = std::vector<float>(kernels::LensDraws::kFloatFields * 64, -1.f);
        std::vector<int32_t> layer = std::vector<int32_t>(64, -1);
        std::vector<uint8_t> state = std::vector<uint8_t>(64, 9);
        kernels::LensDraws out() {
          float* p = f.data();
          return {p,       p + 64,  p + 128, p + 192, p + 256, p + 320, p + 384,      p + 448,      p + 512,
                  p + 576, p + 640, p + 704, p + 768, p + 832, p + 896, p + 960, p + 1024, layer.data(), state.data()};
        }
      };
      Fields want;
      for (uint32_t m = 0; m < count; ++m) kernels::lensDraw(setup, m, want.out());
      for (kernels::Isa isa : {kernels::Isa::Avx2, kernels::Isa::Avx512}) {
        if (!kernels::available(isa)) continue;
        SCOPED_TRACE(std::string(isa == kernels::Isa::Avx512 ? "avx512" : "avx2") + " trial " + std::to_string(trial));
        Fields got;
        kernels::lensDraws(isa, setup, count, got.out());
        for (uint32_t m = 0; m < count; ++m) {
          if (got.state[m] == 3) {
            // A knot before the near plane: the definition's, which the rasterizer runs for it.
            const uint32_t* c = &corners[4 * m];
            bool behind = false;
            for (const auto& k : xyz)
              for (int j = 0; j < (c[3] == store::kNoCorner ? 3 : 4); ++j) behind |= !(k[3 * (c[j] - vBase) + 2] >= nearClip);
            EXPECT_TRUE(behind && want.state[m] != 2) << m;
            behindKnots += isa == kernels::Isa::Avx2;
            continue;
          }
          ASSERT_EQ(int(got.state[m]), int(want.state[m])) << m;
          ASSERT_EQ(got.layer[m], want.layer[m]) << m;
          for (int k = 0; k < kernels::LensDraws::kFloatFields; ++k)
            ASSERT_EQ(std::bit_cast<uint32_t>(got.f[64 * size_t(k) + m]), std::bit_cast<uint32_t>(want.f[64 * size_t(k) + m])) << "field " << k << " of " << m;
        }
      }
      for (uint32_t m = 0; m < count; ++m) {
        drawn += want.state[m] == 1, unbounded += want.state[m] == 2, missed += want.state[m] == 0;
        nearFocus += want.state[m] == 1 && want.layer[m] == 0;
        lerped += want.state[m] == 1 && want.f[64 * 13 + m] != 0.f;  // mx0: the box moves
      }
    }
  }
  // Every outcome taken, many times.
  EXPECT_GT(drawn, 1000u);
  EXPECT_GT(unbounded, 100u);
  EXPECT_GT(missed, 1000u);
  EXPECT_GT(nearFocus, 100u);
  EXPECT_GT(behindKnots, 50u);
  EXPECT_GT(lerped, 500u);
}

// A chunk's vertex range and nearest depth (kernels::cornerRange, nearestDepth) against the
// scalar loops of BucketRasterizer's add(): triangles' missing corners are no vertex, a chunk of
// triangles with no corner at all has an empty range, NaN depths are passed over, and counts
// leave tails past the eight-wide loops.
TEST(ResampleHard, ChunkRangeKernelsAreTheScalarLoops) {
  if (!kernels::available()) GTEST_SKIP() << "this CPU has no AVX2";
  Rng rng(23);
  for (int trial = 0; trial < 500; ++trial) {
    const size_t count = 1 + rng.below(64);
    std::vector<uint32_t> corners(4 * count);
    const uint32_t base = rng.below(1u << 20);
    for (uint32_t& c : corners) c = rng.below(5) == 0 ? store::kNoCorner : base + rng.below(200);
    if (trial % 50 == 0) std::fill(corners.begin(), corners.end(), store::kNoCorner);
    uint32_t lo = ~0u, hi = 0;
    for (uint32_t c : corners)
      if (c != store::kNoCorner) lo = std::min(lo, c), hi = std::max(hi, c);
    const size_t n = 1 + rng.below(90);
    std::vector<float> xyz(3 * n);
    for (float& v : xyz) v = float(rng.uniform(-5, 50));
    if (trial % 3 == 0) xyz[3 * rng.below(uint32_t(n)) + 2] = NAN;
    const float start = trial % 4 == 0 ? INFINITY : float(rng.uniform(0, 60));
    float nearest = start;
    for (size_t i = 0; i < n; ++i) nearest = std::min(nearest, xyz[3 * i + 2]);
    for (kernels::Isa isa : {kernels::Isa::Avx2, kernels::Isa::Avx512}) {
      if (!kernels::available(isa)) continue;
      SCOPED_TRACE(std::string(isa == kernels::Isa::Avx512 ? "avx512" : "avx2") + " trial " + std::to_string(trial));
      uint32_t klo = 7, khi = 7;
      kernels::cornerRange(isa, corners.data(), count, klo, khi);
      EXPECT_EQ(klo, lo);
      EXPECT_EQ(khi, hi);
      EXPECT_EQ(kernels::nearestDepth(isa, xyz.data(), n, start), nearest);
    }
  }
}

// The vector edge test's three outcomes on a hand-made triangle: a sample inside is a hit with
// barycentrics summing to one, one outside is dropped, and one exactly on an edge is left to the
// scalar tie rule.
TEST(ResampleHard, VectorEdgeTestHitsMissesAndDefersTies) {
  if (!kernels::available()) GTEST_SKIP() << "this CPU has no AVX2";
  // Orthographic-style homogeneous vertices (x, y, 1) of the triangle (0,0) (4,0) (0,4), fixed in
  // time: edge (j,k) = V_j × V_k, evaluated as d · E with d = (x, y, 1).
  const glm::dvec3 V[3] = {{0, 0, 1}, {4, 0, 1}, {0, 4, 1}};
  auto cross = [](glm::dvec3 a, glm::dvec3 b) { return glm::cross(a, b); };
  kernels::LinearEdges edges{};
  const glm::dvec3 E[5] = {cross(V[0], V[1]), cross(V[1], V[2]), {}, {}, cross(V[0], V[2])};
  for (int e = 0; e < 5; ++e) edges.c[0][e] = E[e].x, edges.c[1][e] = E[e].y, edges.c[2][e] = E[e].z;
  // Samples: inside (1, 1), outside (5, 5), exactly on edge 01 (2, 0), inside (0.5, 2.5).
  std::vector<float> st(16, 0.f), rx = {1, 5, 2, 0.5f}, ry = {1, 5, 0, 2.5f};
  rx.resize(16), ry.resize(16);
  const kernels::EdgeTestSetup setup{st.data(), rx.data(), ry.data(), 0.f, 0.f, true, false, true};
  for (kernels::Isa isa : {kernels::Isa::Avx2, kernels::Isa::Avx512}) {
    if (!kernels::available(isa)) continue;
    SCOPED_TRACE(isa == kernels::Isa::Avx512 ? "avx512" : "avx2");
    std::vector<kernels::EdgeHit> hits(16);
    const size_t n = kernels::testLinearEdges(isa, setup, edges, 4, hits.data());
    ASSERT_EQ(n, 3u);
    EXPECT_EQ(hits[0].candidate, 0u);
    EXPECT_FALSE(hits[0].undecided);
    EXPECT_EQ(hits[1].candidate, 2u);
    EXPECT_TRUE(hits[1].undecided);
    EXPECT_EQ(hits[2].candidate, 3u);
    EXPECT_FALSE(hits[2].undecided);
    for (size_t h : {size_t(0), size_t(2)}) {
      EXPECT_NEAR(hits[h].b[0] + hits[h].b[1] + hits[h].b[2], 1.f, 1e-6f);
      // Barycentrics reproduce the sample position: sum b_j V_j.
      const double x = hits[h].b[1] * 4.0, y = hits[h].b[2] * 4.0;
      EXPECT_NEAR(x, rx[hits[h].candidate], 1e-5);
      EXPECT_NEAR(y, ry[hits[h].candidate], 1e-5);
    }
  }
}

// The lens path's two sort-and-search kernels against their definitions, restated: the gather
// (kernels::gatherLensCells) appends, search by search and row by row in order, the place of
// every sorted sample of the searched cells that LensBox::admits(); the layer's cell kernel
// (kernels::lensLayerCells) appends, run by run in slot order, every slot whose depth lies
// beyond zMin and, with tile marks, whose cell's tile is marked, each with its cell - the clamped
// sheared position, a NaN in cell 0. Rows longer than a vector and empty ones, several searches
// over blocks of one sorted array, boxes that lerp and boxes that do not; runs of every length.
TEST(ResampleHard, LensGatherAndCellKernelsAreTheirDefinitions) {
  if (!kernels::available()) GTEST_SKIP() << "this CPU has no AVX2";
  Rng rng(404);
  // Values on a grid of eighths, so that the boxes' sums are exact and samples land on their
  // edges (and depths on zMin) often: the kernels' comparisons are held at equality too.
  auto q = [&](double scale, double offset = 0) { return float(std::round((rng.uniform() * scale + offset) * 8) / 8); };
  const int cols = 9, rows = 7, blocks = 3;
  const size_t cells = size_t(cols) * size_t(rows);
  size_t longRows = 0, emptyRows = 0, admittedAll = 0, keptAll = 0, nanCells = 0, onEdges = 0, onZMin = 0;
  for (int trial = 0; trial < 300; ++trial) {
    SCOPED_TRACE("trial " + std::to_string(trial));
    // Sorted samples: cell counts 0-20 (rows of up to 180 samples, some empty).
    std::vector<uint32_t> start(blocks * cells + 1, 0);
    for (size_t c = 0; c < blocks * cells; ++c) start[c + 1] = start[c] + (rng.below(3) == 0 ? 0u : uint32_t(rng.below(21)));
    const size_t S = start.back();
    std::vector<float> t(S + 16), x(S + 16), y(S + 16), u(S + 16), v(S + 16);
    for (size_t i = 0; i < S + 16; ++i) {
      t[i] = q(1), x[i] = q(cols), y[i] = q(rows), u[i] = q(2, -1), v[i] = q(2, -1);
    }
    kernels::LensBox box{q(6), 0, q(5), 0, q(2, -1), 0, q(2, -1), 0};
    box.x1 = box.x0 + q(3), box.y1 = box.y0 + q(3), box.cx1 = box.cx0 + q(1), box.cy1 = box.cy0 + q(1);
    if (trial % 2) {
      box.thetaA = 0.25f, box.invLen = 2.f;
      box.mx0 = q(4, -2), box.mx1 = box.mx0 + q(1), box.my0 = q(4, -2), box.my1 = box.my0 + q(1);
    }
    std::vector<kernels::LensSearch> searches(1 + rng.below(4));
    std::vector<uint32_t> expected;
    uint64_t expectedExamined = 0;
    for (kernels::LensSearch& s : searches) {
      s.start = start.data() + rng.below(blocks) * cells;
      s.c0 = int(rng.below(cols)), s.c1 = s.c0 + int(rng.below(uint32_t(cols - s.c0)));
      s.r0 = int(rng.below(rows)), s.r1 = s.r0 + int(rng.below(uint32_t(rows - s.r0)));
      for (int r = s.r0; r <= s.r1; ++r) {
        const uint32_t first = s.start[size_t(r) * cols + size_t(s.c0)], last = s.start[size_t(r) * cols + size_t(s.c1) + 1];
        expectedExamined += last - first, longRows += last - first > 16, emptyRows += last == first;
        for (uint32_t i = first; i < last; ++i) {
          if (box.admits(t[i], x[i], y[i], u[i], v[i])) expected.push_back(i);
          onEdges += y[i] == box.y1 + (trial % 2 ? std::min(std::max((t[i] - box.thetaA) * box.invLen, 0.f), 1.f) * box.my1 : 0.f) + std::max(v[i] * box.cy0, v[i] * box.cy1);
        }
      }
    }
    admittedAll += expected.size();
    std::vector<uint32_t> positions(S + 32);
    for (kernels::Isa isa : {kernels::Isa::Avx2, kernels::Isa::Avx512}) {
      if (!kernels::available(isa)) continue;
      SCOPED_TRACE(isa == kernels::Isa::Avx512 ? "avx512" : "avx2");
      uint64_t examined = 0;
      const kernels::LensCells sorted{t.data(), x.data(), y.data(), u.data(), v.data(), &examined};
      const size_t n = kernels::gatherLensCells(isa, sorted, size_t(cols), searches.data(), searches.size(), box, positions.data(), 3);
      ASSERT_EQ(n, 3 + expected.size());
      EXPECT_TRUE(std::equal(expected.begin(), expected.end(), positions.begin() + 3));
      EXPECT_EQ(examined, expectedExamined);
    }

    // The cell kernel over runs of the same samples as slots (u NaN now and then).
    if (rng.below(4) == 0) u[rng.below(uint32_t(S + 1))] = NAN;
    std::vector<float> depth(S + 16);
    for (float& d : depth) d = q(1);
    const int tileCols = kernels::lensTiles(cols), tileRows = kernels::lensTiles(rows);
    std::vector<uint8_t> marks(size_t(tileCols) * size_t(tileRows) + 3);
    for (uint8_t& m : marks) m = uint8_t(rng.below(2));
    kernels::LensShear shear{float(rng.uniform() * 40 - 20), float(rng.uniform() * 40 - 20), float(rng.uniform() * 4 - 2), float(rng.uniform() * 4 - 2),
                             float(cols - 1), float(rows - 1), uint32_t(cols), uint32_t(tileCols), trial % 3 ? marks.data() : nullptr,
                             q(0.5), trial % 4 < 2 ? 1.f : 0.5f};
    std::vector<uint32_t> runFirst, runCount;
    for (uint32_t at = uint32_t(rng.below(5)); at < S; at += uint32_t(rng.below(40))) {
      runFirst.push_back(at), runCount.push_back(std::min(uint32_t(S) - at, uint32_t(rng.below(40))));
      at += runCount.back();
    }
    const uint32_t key = uint32_t(rng.below(blocks) * cells);
    std::vector<uint32_t> wantSlot, wantCell;
    auto clampTo = [](float f, float hi) { return f >= 0.f ? (f <= hi ? f : hi) : 0.f; };
    for (size_t r = 0; r < runFirst.size(); ++r)
      for (size_t j = runFirst[r]; j < size_t(runFirst[r]) + runCount[r]; ++j) {
        const uint32_t col = uint32_t(clampTo(x[j] - shear.cx * u[j] - shear.x0, shear.maxCol));
        const uint32_t row = uint32_t(clampTo((y[j] - shear.cy * v[j] - shear.y0) * shear.rowScale, shear.maxRow));
        onZMin += depth[j] == shear.zMin;
        if (!(depth[j] > shear.zMin)) continue;
        if (shear.tileUsed && !shear.tileUsed[(row >> kernels::kLensTileShift) * shear.tileCols + (col >> kernels::kLensTileShift)]) continue;
        wantSlot.push_back(uint32_t(j)), wantCell.push_back(key + row * shear.cols + col);
        nanCells += std::isnan(u[j]);
      }
    keptAll += wantSlot.size();
    std::vector<uint32_t> slot(S + 32), cell(S + 32);
    for (kernels::Isa isa : {kernels::Isa::Avx2, kernels::Isa::Avx512}) {
      if (!kernels::available(isa)) continue;
      SCOPED_TRACE(isa == kernels::Isa::Avx512 ? "avx512 cells" : "avx2 cells");
      const size_t n = kernels::lensLayerCells(isa, shear, x.data(), y.data(), u.data(), v.data(), depth.data(),
                                               kernels::LensRuns{runFirst.data(), runCount.data(), runFirst.size()}, key, slot.data(), cell.data(), 2);
      ASSERT_EQ(n, 2 + wantSlot.size());
      EXPECT_TRUE(std::equal(wantSlot.begin(), wantSlot.end(), slot.begin() + 2));
      EXPECT_TRUE(std::equal(wantCell.begin(), wantCell.end(), cell.begin() + 2));
    }
  }
  // The cases the test means to reach were reached.
  EXPECT_GT(longRows, 100u);
  EXPECT_GT(emptyRows, 100u);
  EXPECT_GT(admittedAll, 1000u);
  EXPECT_GT(keptAll, 1000u);
  EXPECT_GT(nanCells, 0u);
  EXPECT_GT(onEdges, 100u);
  EXPECT_GT(onZMin, 100u);
}

// A draw's search cells in the layer sort (kernels::lensSearchCells) against their definition,
// restated - the search box LensBox::searchBox() gives, each edge's cell clamped into the grid
// (a NaN in cell 0) - and the four-lane version (kernels::LensCellLanes, what the sort runs on
// x86-64) against it: the same cells, edges exactly on cell borders, beyond the grid on either
// side, NaN and infinite boxes included.
TEST(ResampleHard, LensSearchCellsAreTheirDefinition) {
  Rng rng(26);
  auto q = [&](double scale, double offset = 0) { return float(std::round((rng.uniform() * scale + offset) * 8) / 8); };
  auto clampedCell = [](float v, int count) { return v >= 0.f ? (v < float(count) ? int(v) : count - 1) : 0; };
  size_t onBorder = 0, clampedLow = 0, clampedHigh = 0, nanEdges = 0;
  const float odd[] = {NAN, INFINITY, -INFINITY, 1e30f, -1e30f, 0.f, -0.f};
  for (int trial = 0; trial < 20000; ++trial) {
    SCOPED_TRACE("trial " + std::to_string(trial));
    const kernels::LensCellGrid g{q(8, -4), q(8, -4), trial % 2 ? 1.f : 0.5f, 1 + int(rng.below(40)), 1 + int(rng.below(30))};
    kernels::LensBox box{q(60, -10), 0, q(50, -10), 0, q(2, -1), 0, q(2, -1), 0};
    box.x1 = box.x0 + q(6), box.y1 = box.y0 + q(6), box.cx1 = box.cx0 + q(1), box.cy1 = box.cy0 + q(1);
    box.mx0 = q(30, -15), box.mx1 = box.mx0 + q(2), box.my0 = q(30, -15), box.my1 = box.my0 + q(2);
    float ex = q(2), ey = q(2), qm = trial % 3 ? q(0.25) : 0.f;
    float f0 = q(1), f1 = std::min(1.f, f0 + q(1));
    if (trial % 50 == 0) {  // something odd in one field
      float* fields[] = {&box.x0, &box.x1, &box.y0, &box.y1, &box.mx0, &box.mx1, &box.my0, &box.my1, &ex, &ey, &qm, &f0};
      *fields[rng.below(12)] = odd[rng.below(7)];
    }
    float sb[4];
    box.searchBox(f0, f1, ex, ey, qm, sb);
    const int want[4] = {clampedCell(sb[0] - g.x0, g.cols), clampedCell((sb[2] - g.y0) * g.rowScale, g.rows), clampedCell(sb[1] - g.x0, g.cols),
                         clampedCell((sb[3] - g.y0) * g.rowScale, g.rows)};
    for (int k = 0; k < 4; ++k) {
      const float v = k % 2 ? (sb[k == 1 ? 2 : 3] - g.y0) * g.rowScale : sb[k == 0 ? 0 : 1] - g.x0;
      onBorder += v == std::floor(v) && v > 0.f && v < float(k % 2 ? g.rows : g.cols);
      clampedLow += v < 0.f, clampedHigh += v >= float(k % 2 ? g.rows : g.cols), nanEdges += std::isnan(v);
    }
    int got[4];
    kernels::lensSearchCells(box, ex, ey, qm, f0, f1, g, got);
    EXPECT_TRUE(std::equal(want, want + 4, got)) << got[0] << " " << got[1] << " " << got[2] << " " << got[3];
#if defined(__SSE2__)
    int lanes[4];
    const kernels::LensCellLanes inLanes(g);
    inLanes(box, ex, ey, qm, f0, f1, lanes);
    EXPECT_TRUE(std::equal(want, want + 4, lanes)) << lanes[0] << " " << lanes[1] << " " << lanes[2] << " " << lanes[3];
#endif
  }
  // The cases the test means to reach were reached.
  EXPECT_GT(onBorder, 1000u);
  EXPECT_GT(clampedLow, 1000u);
  EXPECT_GT(clampedHigh, 1000u);
  EXPECT_GT(nanEdges, 10u);
}
