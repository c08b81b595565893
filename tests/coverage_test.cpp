// The coverage module on its own (resample/coverage.h): the scalar reference's edges and
// barycentrics against analytic truths, watertight shared edges on meshes whose vertices and
// samples are exact in binary (so samples fall exactly on edges and corners), degenerate and
// back-facing micropolygons, and the vector kernels against the scalar reference bit for bit.
#include <gtest/gtest.h>

#include <algorithm>
#include <bit>
#include <cmath>
#include <random>
#include <vector>

#include <glm/vec2.hpp>

#include "resample/coverage.h"

namespace reshutter::resample {
namespace {

// Raster = camera x, y (orthographic, unit scale): edges through integer vertices are exact.
const kernels::RasterScale kOrtho{1.0, 1.0, 0.0, 0.0, false};
// A perspective camera: raster = 100 x / z + 50.
const kernels::RasterScale kPersp{1.0 / 100.0, 1.0 / 100.0, 50.0, 50.0, true};

struct Quad {
  glm::vec3 p[4];
  bool triangle = false;
};

// The vector kernels' instruction sets this CPU runs.
std::vector<kernels::Isa> vectorIsas() {
  std::vector<kernels::Isa> isas;
  for (kernels::Isa isa : {kernels::Isa::Avx2, kernels::Isa::Avx512})
    if (kernels::available(isa)) isas.push_back(isa);
  return isas;
}

// A decided hit against the scalar test's: its triangle, barycentrics and depth (from corner
// depths zv, the scalar paths' float arithmetic), bit for bit.
void expectSameHit(const kernels::EdgeHit& vh, int tri, const float bary[3], const float zv[4]) {
  EXPECT_EQ(int(vh.triangle), tri);
  for (int k = 0; k < 3; ++k) EXPECT_EQ(vh.b[k], bary[k]);
  const float z = tri == 0 ? bary[0] * zv[0] + bary[1] * zv[1] + bary[2] * zv[2] : bary[0] * zv[0] + bary[1] * zv[2] + bary[2] * zv[3];
  EXPECT_EQ(vh.z, z);
}

bool fixedHit(const Quad& q, const kernels::RasterScale& s, bool cullBack, double x, double y, int& tri, float b[3]) {
  const glm::vec3* p[4] = {&q.p[0], &q.p[1], &q.p[2], &q.p[q.triangle ? 2 : 3]};
  glm::dvec3 E[5];
  fixedEdges(p, q.triangle, s, E);
  return coversFixed(E, q.triangle, cullBack, x, y, tri, b);
}

bool movingHit(const Quad& a, const Quad& b, const kernels::RasterScale& s, bool cullBack, double x, double y, double f, int& tri, float bary[3]) {
  const glm::vec3* at[4] = {&a.p[0], &a.p[1], &a.p[2], &a.p[a.triangle ? 2 : 3]};
  const glm::vec3* to[4] = {&b.p[0], &b.p[1], &b.p[2], &b.p[b.triangle ? 2 : 3]};
  EdgeQuad q[5];
  linearEdges(at, to, a.triangle, s, q);
  return coversMoving(q, a.triangle, cullBack, x, y, f, tri, bary);
}

TEST(Coverage, InsideOutsideAndBarycentricsOfATriangle) {
  const Quad t{{{0, 0, 1}, {4, 0, 1}, {0, 4, 1}, {}}, true};
  int tri;
  float b[3];
  for (auto [x, y] : {std::pair{1.0, 1.0}, std::pair{0.5, 2.5}, std::pair{3.0, 0.25}}) {
    ASSERT_TRUE(fixedHit(t, kOrtho, false, x, y, tri, b)) << x << " " << y;
    EXPECT_EQ(tri, 0);
    // Triangle A is (p0 p1 p2); the barycentrics reproduce the sample: sum b_j p_j.
    EXPECT_NEAR(b[0] + b[1] + b[2], 1.f, 1e-6f);
    EXPECT_NEAR(b[1] * 4.0, x, 1e-6);
    EXPECT_NEAR(b[2] * 4.0, y, 1e-6);
  }
  for (auto [x, y] : {std::pair{5.0, 5.0}, std::pair{-0.1, 1.0}, std::pair{2.1, 2.1}, std::pair{1.0, -1e-9}})
    EXPECT_FALSE(fixedHit(t, kOrtho, false, x, y, tri, b)) << x << " " << y;
}

TEST(Coverage, PerspectiveBarycentricsAreThoseOfTheSurfacePoint) {
  // A triangle slanted in depth: the hit's barycentrics, applied to the camera-space corners, give
  // a point on the sample's view ray (perspective-correct, not screen-space, interpolation).
  const Quad t{{{-1, -1, 2}, {1, -1, 4}, {-1, 1, 3}, {}}, true};
  int tri;
  float b[3];
  const double x = 40.0, y = 45.0;  // raster: x' = (x - 50) / 100
  ASSERT_TRUE(fixedHit(t, kPersp, false, x, y, tri, b));
  glm::dvec3 p(0.0);
  for (int j = 0; j < 3; ++j) p += double(b[j]) * glm::dvec3(t.p[j]);
  EXPECT_NEAR(p.x / p.z, (x - 50.0) / 100.0, 1e-6);
  EXPECT_NEAR(p.y / p.z, (y - 50.0) / 100.0, 1e-6);
}

// A lattice of n × n unit quads with integer corners, shifted by `offset` (at a knot segment's
// end: moved), each quad split on the diagonal 02 alternately in both directions so both diagonals
// occur. Every sample strictly inside the lattice's hull is covered exactly once, whatever edges
// or corners it lies on.
std::vector<Quad> lattice(int n, glm::vec2 offset) {
  std::vector<Quad> quads;
  for (int j = 0; j < n; ++j)
    for (int i = 0; i < n; ++i) {
      const glm::vec3 c[4] = {
          {i + offset.x, j + offset.y, 1}, {i + 1 + offset.x, j + offset.y, 1}, {i + 1 + offset.x, j + 1 + offset.y, 1}, {i + offset.x, j + 1 + offset.y, 1}};
      Quad q;
      const int r = (i + j) % 2;  // rotate the corners: the diagonal 02 alternates
      for (int k = 0; k < 4; ++k) q.p[k] = c[(k + r) % 4];
      quads.push_back(q);
    }
  return quads;
}

TEST(Coverage, SharedEdgesAreWatertightOnExactTies) {
  const int n = 6;
  const std::vector<Quad> quads = lattice(n, {0, 0});
  int samples = 0, ties = 0;
  // Quarter-pixel samples: a third of them lie exactly on an edge or a corner.
  for (int sy = 1; sy < 4 * n; ++sy)
    for (int sx = 1; sx < 4 * n; ++sx) {
      const double x = sx / 4.0, y = sy / 4.0;
      int count = 0, tri;
      float b[3];
      for (const Quad& q : quads) count += fixedHit(q, kOrtho, false, x, y, tri, b);
      ASSERT_EQ(count, 1) << "sample (" << x << ", " << y << ")";
      ++samples;
      ties += (sx % 4 == 0) || (sy % 4 == 0) || (sx == sy) || ((sx + sy) % 4 == 0);
    }
  EXPECT_GT(ties, samples / 3);  // the ties were really tested
}

TEST(Coverage, MovingSharedEdgesAreWatertightOnExactTies) {
  // The lattice moves by (3, 1) over the segment; at f = 1/2 its corners sit on half-integers and
  // the quarter-pixel samples again fall on edges and corners, through the quadratic expansion.
  const int n = 6;
  const std::vector<Quad> from = lattice(n, {0, 0}), to = lattice(n, {3, 1});
  for (double f : {0.0, 0.5, 1.0}) {
    int ties = 0;
    for (int sy = 1; sy < 4 * n; ++sy)
      for (int sx = 1; sx < 4 * n; ++sx) {
        const double x = sx / 4.0 + 3.0 * f, y = sy / 4.0 + 1.0 * f;
        int count = 0, tri;
        float b[3];
        for (size_t k = 0; k < from.size(); ++k) count += movingHit(from[k], to[k], kOrtho, false, x, y, f, tri, b);
        ASSERT_EQ(count, 1) << "f " << f << " sample (" << x << ", " << y << ")";
        ties += sx % 4 == 0 || sy % 4 == 0;
      }
    EXPECT_GT(ties, 100);
  }
}

TEST(Coverage, PerspectiveMeshIsWatertightForRandomSamples) {
  // A jittered 8 × 8 grid in depth under perspective, moving: every random sample inside the
  // grid's interior is covered once - no cracks, no double hits - at random times.
  std::mt19937 rng(7);
  std::uniform_real_distribution<float> jitter(-0.3f, 0.3f);
  const int n = 8;
  std::vector<glm::vec3> a((n + 1) * (n + 1)), b((n + 1) * (n + 1));
  for (int j = 0; j <= n; ++j)
    for (int i = 0; i <= n; ++i) {
      const bool border = i == 0 || j == 0 || i == n || j == n;
      const float z = 5.f + 0.4f * float(i) + (border ? 0.f : jitter(rng));
      a[j * (n + 1) + i] = {(float(i) - 4.f + (border ? 0.f : jitter(rng))) * z / 10.f, (float(j) - 4.f + (border ? 0.f : jitter(rng))) * z / 10.f, z};
      b[j * (n + 1) + i] = a[j * (n + 1) + i] + glm::vec3(0.3f, -0.2f, border ? 0.f : jitter(rng));
    }
  std::vector<Quad> qa, qb;
  for (int j = 0; j < n; ++j)
    for (int i = 0; i < n; ++i) {
      const int v[4] = {j * (n + 1) + i, j * (n + 1) + i + 1, (j + 1) * (n + 1) + i + 1, (j + 1) * (n + 1) + i};
      qa.push_back({{a[v[0]], a[v[1]], a[v[2]], a[v[3]]}}), qb.push_back({{b[v[0]], b[v[1]], b[v[2]], b[v[3]]}});
    }
  std::uniform_real_distribution<double> unit(0.0, 1.0);
  int tested = 0;
  for (int s = 0; s < 4000; ++s) {
    const double f = unit(rng);
    // A point inside the grid's interior at time f, projected: its raster position is the sample.
    const int i = 1 + int(unit(rng) * (n - 2)), j = 1 + int(unit(rng) * (n - 2));
    const Quad& q = qa[size_t(j * n + i)];
    const Quad& r = qb[size_t(j * n + i)];
    const double u = unit(rng), w = unit(rng);
    glm::dvec3 p(0.0);
    for (int k = 0; k < 4; ++k) {
      const double wk = (k == 0 ? (1 - u) * (1 - w) : k == 1 ? u * (1 - w) : k == 2 ? u * w : (1 - u) * w);
      p += wk * (glm::dvec3(q.p[k]) + f * (glm::dvec3(r.p[k]) - glm::dvec3(q.p[k])));
    }
    const double x = 100.0 * p.x / p.z + 50.0, y = 100.0 * p.y / p.z + 50.0;
    int count = 0, tri;
    float bary[3];
    for (size_t k = 0; k < qa.size(); ++k) count += movingHit(qa[k], qb[k], kPersp, false, x, y, f, tri, bary);
    ASSERT_EQ(count, 1) << "sample " << s << " (" << x << ", " << y << ") at f " << f;
    ++tested;
  }
  EXPECT_EQ(tested, 4000);
}

TEST(Coverage, DegenerateQuadsCoverNothingOrTheirTriangle) {
  int tri;
  float b[3];
  // Every corner in one point, or all on one line: zero area, no sample covered (and no NaN).
  const Quad point{{{1, 1, 1}, {1, 1, 1}, {1, 1, 1}, {1, 1, 1}}};
  const Quad line{{{0, 0, 1}, {1, 1, 1}, {2, 2, 1}, {3, 3, 1}}};
  for (double x = -0.5; x <= 3.5; x += 0.25)
    for (double y = -0.5; y <= 3.5; y += 0.25) {
      EXPECT_FALSE(fixedHit(point, kOrtho, false, x, y, tri, b));
      EXPECT_FALSE(fixedHit(line, kOrtho, false, x, y, tri, b));
    }
  // Two corners in one point: the quad is the triangle of the three others, its area exactly.
  const Quad collapsed{{{0, 0, 1}, {4, 0, 1}, {4, 0, 1}, {0, 4, 1}}};
  int covered = 0, inTriangle = 0;
  for (int sy = 0; sy < 40; ++sy)
    for (int sx = 0; sx < 40; ++sx) {
      const double x = (sx + 0.5) / 10.0, y = (sy + 0.5) / 10.0;
      const bool hit = fixedHit(collapsed, kOrtho, false, x, y, tri, b);
      const bool inside = x + y < 4.0;
      covered += hit, inTriangle += inside;
      EXPECT_EQ(hit, inside) << x << " " << y;
      if (hit) {
        EXPECT_TRUE(std::isfinite(b[0]) && std::isfinite(b[1]) && std::isfinite(b[2]));
      }
    }
  EXPECT_GT(covered, 0);
  EXPECT_EQ(covered, inTriangle);
}

TEST(Coverage, BackFacesAreKnockedOutOnlyWhenAsked) {
  const Quad front{{{0, 0, 1}, {0, 4, 1}, {4, 4, 1}, {4, 0, 1}}};  // clockwise on screen
  const Quad back{{{0, 0, 1}, {4, 0, 1}, {4, 4, 1}, {0, 4, 1}}};   // the same square, counter-clockwise
  int tri;
  float b[3];
  EXPECT_TRUE(fixedHit(front, kOrtho, true, 1.0, 2.0, tri, b));
  EXPECT_TRUE(fixedHit(back, kOrtho, false, 1.0, 2.0, tri, b));
  EXPECT_FALSE(fixedHit(back, kOrtho, true, 1.0, 2.0, tri, b));
}

// The vector kernels give the scalar reference's edges bit for bit (and the lens path's still
// edges), and its decisions, barycentrics and depths for every candidate they decide (the rest
// are exact ties they hand to it).
TEST(Coverage, VectorKernelsMatchTheScalarReference) {
  const std::vector<kernels::Isa> isas = vectorIsas();
  if (isas.empty()) GTEST_SKIP() << "this CPU runs no vector kernels";
  std::mt19937 rng(3);
  std::uniform_real_distribution<float> pos(-1.f, 1.f), depth(2.f, 6.f), step(-0.2f, 0.2f);
  const size_t n = 61;  // not a multiple of any lane count
  std::vector<float> st(n + 16), sx(n + 16), sy(n + 16);
  std::vector<kernels::EdgeHit> hits(n + 16);
  size_t decided = 0, hitsFound = 0, nonZeroLensCoefficients = 0;
  for (int trial = 0; trial < 300; ++trial) {
    for (const kernels::RasterScale& scale : {kPersp, kOrtho}) {
      const bool fixed = trial % 3 == 0, triangle = trial % 5 == 0, cullBack = trial % 7 == 0;
      Quad a, b;
      const glm::vec3 centre{pos(rng), pos(rng), depth(rng)};
      for (int k = 0; k < 4; ++k) {
        const float ang = float(k) * 1.5708f + 0.3f * pos(rng);
        a.p[k] = centre + glm::vec3(0.6f * std::cos(ang), 0.6f * std::sin(ang), 0.3f * pos(rng));
        b.p[k] = fixed ? a.p[k] : a.p[k] + glm::vec3(step(rng), step(rng), step(rng));
      }
      a.triangle = b.triangle = triangle;
      if (triangle) a.p[3] = a.p[2], b.p[3] = b.p[2];
      const float* at[4] = {&a.p[0].x, &a.p[1].x, &a.p[2].x, &a.p[3].x};
      const float* to[4] = {&b.p[0].x, &b.p[1].x, &b.p[2].x, &b.p[3].x};
      const glm::vec3* atv[4] = {&a.p[0], &a.p[1], &a.p[2], &a.p[3]};
      const glm::vec3* tov[4] = {&b.p[0], &b.p[1], &b.p[2], &b.p[3]};
      EdgeQuad q[5];
      glm::dvec3 E[5];
      linearEdges(atv, tov, triangle, scale, q);
      fixedEdges(atv, triangle, scale, E);
      // Candidates around the micropolygon's raster box, at random times.
      for (size_t i = 0; i < n; ++i) {
        const glm::vec3 c = centre + glm::vec3(0.8f * pos(rng), 0.8f * pos(rng), 0.f);
        sx[i] = float(scale.perspective ? c.x / c.z / scale.invAx + scale.bx : c.x);
        sy[i] = float(scale.perspective ? c.y / c.z / scale.invAy + scale.by : c.y);
        st[i] = 0.5f * (pos(rng) + 1.f);
      }
      kernels::EdgeTestSetup setup{st.data(), sx.data(), sy.data(), 0.f, 1.f, triangle, cullBack, fixed};
      for (int j = 0; j < 4; ++j) setup.za[j] = a.p[j].z, setup.zb[j] = fixed ? a.p[j].z : b.p[j].z;
      for (kernels::Isa isa : isas) {
        SCOPED_TRACE(isa == kernels::Isa::Avx512 ? "avx512" : "avx2");
        kernels::LinearEdges edges{};
        if (fixed) kernels::fixedEdges(isa, at, scale, edges);
        else kernels::linearEdges(isa, at, to, scale, edges);
        for (int e = 0; e < 5; ++e) {
          if (triangle && (e == 2 || e == 3)) continue;
          const glm::dvec3 powers[3] = {fixed ? E[e] : q[e].e0, q[e].e1, q[e].e2};
          for (int p = 0; p < (fixed ? 1 : 3); ++p)
            for (int k = 0; k < 3; ++k) EXPECT_EQ(edges.c[3 * p + k][e], powers[p][k]) << "edge " << e << " power " << p;
        }
        if (scale.perspective) {
          // The still lens edges (the lens path's) against their definition, for a focal
          // distance on either side of the corners' depths or exactly at one of them (q = 0).
          const double invD = trial % 11 == 0 ? 1.0 / double(a.p[1].z) : 1.0 / (1.0 + 7.0 * double(trial % 13) / 12.0);
          kernels::LinearEdges want{}, got{};
          kernels::stillLensEdges(atv, triangle, invD, scale, want);
          kernels::stillLensEdges(isa, at, triangle, invD, scale, got);
          for (int e = 0; e < 5; ++e)
            for (int r = 0; r < 9; ++r) {
              ASSERT_EQ(std::bit_cast<uint64_t>(got.c[r][e]), std::bit_cast<uint64_t>(want.c[r][e])) << "lens edge " << e << " row " << r;
              nonZeroLensCoefficients += r >= 3 && want.c[r][e] != 0.0;
            }
        }
        const size_t count = kernels::testLinearEdges(isa, setup, edges, n, hits.data());
        std::vector<const kernels::EdgeHit*> byCandidate(n, nullptr);
        for (size_t h = 0; h < count; ++h) byCandidate[hits[h].candidate] = &hits[h];
        for (size_t i = 0; i < n; ++i) {
          const float f = fixed ? 0.f : std::clamp(st[i], 0.f, 1.f);
          int tri;
          float bary[3];
          const bool hit =
              fixed ? coversFixed(E, triangle, cullBack, sx[i], sy[i], tri, bary) : coversMoving(q, triangle, cullBack, sx[i], sy[i], f, tri, bary);
          const kernels::EdgeHit* vh = byCandidate[i];
          if (vh && vh->undecided) continue;  // an exact zero: the scalar tie rule decides
          ++decided;
          ASSERT_EQ(hit, vh != nullptr) << "trial " << trial << " candidate " << i;
          if (!hit) continue;
          ++hitsFound;
          float zv[4];
          for (int j = 0; j < 4; ++j) zv[j] = setup.za[j] + f * (setup.zb[j] - setup.za[j]);
          expectSameHit(*vh, tri, bary, zv);
        }
      }
    }
  }
  EXPECT_GT(decided, 10000u);
  EXPECT_GT(hitsFound, 2000u);  // both outcomes were compared many times
  EXPECT_GT(nonZeroLensCoefficients, 10000u);  // how many non-zero coefficients were compared
}

// The moving lens kernel (testMovingLens) against raster_lens.cpp's scalar testLens(), restated
// here: corners lerped in double, sheared for the lens point, edges toRaster(S_a × S_b),
// coversFixed(). Random moving micropolygons through a lens, and a square in the focal plane
// (no shear) with corners and samples on integers, so that samples fall exactly on its edges: the
// kernel must hand exactly those to the scalar tie rule.
TEST(Coverage, MovingLensKernelMatchesTheScalarTest) {
  const std::vector<kernels::Isa> isas = vectorIsas();
  if (isas.empty()) GTEST_SKIP() << "this CPU runs no vector kernels";
  std::mt19937 rng(5);
  std::uniform_real_distribution<float> pos(-1.f, 1.f), depth(2.f, 6.f), step(-0.2f, 0.2f), unit(0.f, 1.f);
  const size_t n = 61;
  std::vector<float> fs(n + 16), su(n + 16), sv(n + 16), sx(n + 16), sy(n + 16);
  std::vector<kernels::EdgeHit> hits(n + 16);
  size_t decided = 0, hitsFound = 0, ties = 0;
  for (int trial = 0; trial < 400; ++trial) {
    const bool onGrid = trial % 4 == 3, triangle = trial % 5 == 0, cullBack = trial % 7 == 0;
    Quad a, b;
    double lensRadius = 0.05, focal = 4.0;
    kernels::RasterScale scale = kPersp;
    if (onGrid) {
      // In the focal plane (q = 0), raster = camera x, y: integer corners, edges exact.
      lensRadius = 0.5, focal = 1.0, scale = kOrtho;
      const float ox = float(trial % 3), oy = float(trial % 2);
      const glm::vec3 sq[4] = {{ox, oy, 1}, {ox + 2, oy, 1}, {ox + 2, oy + 2, 1}, {ox, oy + 2, 1}};
      for (int k = 0; k < 4; ++k) a.p[k] = b.p[k] = sq[k];
    } else {
      const glm::vec3 centre{pos(rng), pos(rng), depth(rng)};
      for (int k = 0; k < 4; ++k) {
        const float ang = float(k) * 1.5708f + 0.3f * pos(rng);
        a.p[k] = centre + glm::vec3(0.6f * std::cos(ang), 0.6f * std::sin(ang), 0.3f * pos(rng));
        b.p[k] = a.p[k] + glm::vec3(step(rng), step(rng), step(rng));
      }
    }
    a.triangle = b.triangle = triangle;
    if (triangle) a.p[3] = a.p[2], b.p[3] = b.p[2];
    for (size_t i = 0; i < n; ++i) {
      fs[i] = unit(rng), su[i] = 2.f * unit(rng) - 1.f, sv[i] = 2.f * unit(rng) - 1.f;
      if (onGrid) {
        sx[i] = float(trial % 3) + 0.5f * float(rng() % 7) - 0.5f, sy[i] = float(trial % 2) + 0.5f * float(rng() % 7) - 0.5f;
      } else {
        const glm::vec3 c = (a.p[0] + a.p[2]) * 0.5f + glm::vec3(0.8f * pos(rng), 0.8f * pos(rng), 0.f);
        sx[i] = float(c.x / c.z / scale.invAx + scale.bx), sy[i] = float(c.y / c.z / scale.invAy + scale.by);
      }
    }
    kernels::MovingLensSetup setup{fs.data(), su.data(), sv.data(), sx.data(), sy.data(), {}, {}, lensRadius, 1.0 / focal, scale, triangle, cullBack};
    for (int j = 0; j < 4; ++j)
      for (int axis = 0; axis < 3; ++axis) setup.a[axis][j] = double(a.p[j][axis]), setup.d[axis][j] = double(b.p[j][axis]) - double(a.p[j][axis]);
    for (kernels::Isa isa : isas) {
      SCOPED_TRACE(isa == kernels::Isa::Avx512 ? "avx512" : "avx2");
      const size_t count = kernels::testMovingLens(isa, setup, n, hits.data());
      std::vector<const kernels::EdgeHit*> byCandidate(n, nullptr);
      for (size_t h = 0; h < count; ++h) byCandidate[hits[h].candidate] = &hits[h];
      for (size_t i = 0; i < n; ++i) {
        glm::dvec3 P[4], S[4], E[5];
        const double Lx = lensRadius * double(su[i]), Ly = lensRadius * double(sv[i]), invD = 1.0 / focal;
        for (int j = 0; j < 4; ++j) {
          const glm::dvec3 pa(a.p[j]), pb(b.p[j]);
          P[j] = pa + double(fs[i]) * (pb - pa);
          const double q = P[j].z * invD - 1.0;
          S[j] = {P[j].x + Lx * q, P[j].y + Ly * q, P[j].z};
        }
        for (int k = 0; k < 5; ++k) E[k] = triangle && (k == 2 || k == 3) ? glm::dvec3(0.0) : toRaster(cross(S[kEdgeVerts[k][0]], S[kEdgeVerts[k][1]]), scale);
        int tri;
        float bary[3];
        const bool hit = coversFixed(E, triangle, cullBack, sx[i], sy[i], tri, bary);
        const kernels::EdgeHit* vh = byCandidate[i];
        if (vh && vh->undecided) {
          // Only an exact zero edge value may be handed on.
          bool zero = false;
          for (int k = 0; k < 5; ++k) zero |= !(triangle && (k == 2 || k == 3)) && edgeAt(sx[i], sy[i], E[k]) == 0.0;
          EXPECT_TRUE(zero) << "trial " << trial << " candidate " << i;
          ++ties;
          continue;
        }
        ++decided;
        ASSERT_EQ(hit, vh != nullptr) << "trial " << trial << " candidate " << i;
        if (!hit) continue;
        ++hitsFound;
        const float zv[4] = {float(P[0].z), float(P[1].z), float(P[2].z), float(P[3].z)};
        expectSameHit(*vh, tri, bary, zv);
      }
    }
  }
  EXPECT_GT(decided, 15000u);
  EXPECT_GT(hitsFound, 3000u);
  EXPECT_GT(ties, 500u);  // samples on the grid square's edges reached the tie rule
}

}  // namespace
}  // namespace reshutter::resample
