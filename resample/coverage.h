// Coverage: does this sample hit this micropolygon at this time? The one answer every path of
// the bucket rasterizer (resample/raster.h) uses - static, moving, linear and chunk-gathered -
// given here as the scalar reference (inline, below) and as the vector kernels beside it
// (linearEdges / fixedEdges / testLinearEdges: simd_avx2.cpp, simd_avx512.cpp, one dispatch in
// simd_dispatch.cpp), which compute the same values with the same operations in the same order.
//
// Coverage is tested with homogeneous 2D edge functions: for a sample's view ray d and camera-
// space vertices V_j(t), V_k(t), the edge value is e = d · (V_j(t) × V_k(t)). Between knots the
// vertices move linearly, so each edge's cross product is a quadratic in the segment parameter f
// (EdgeQuad); as d is affine in raster position, the edges are kept over raster x, y
// (toRaster()) and the test reads the samples' positions. The normalised edge values are the
// perspective-correct barycentrics of the hit, and the hit depth follows from them, so
// micropolygons crossing the eye plane need no clipping: a hit behind the near plane is simply
// rejected by the caller. Quads are tested as the two triangles (p0 p1 p2) and (p0 p2 p3).
//
// Watertightness: an edge shared by two micropolygons is evaluated from the same vertex values in
// opposite order, which yields exactly the negated value (cross products and sums are computed so
// that negation is exact), and a sample exactly on an edge belongs to the side for which the
// orientation-normalised edge vector is lexicographically positive (ownsTie()) - exactly one of
// the two. The module builds with -ffp-contract=off so no compiler contraction breaks that symmetry.
//
// Edge functions are evaluated in double precision: for a one-pixel micropolygon the cross
// product of two nearly parallel vertex vectors cancels ~3 digits, and in float that moved edges
// by up to 0.01 px near the image corners (measured against the vertex bounds). Double keeps the
// test exact to ~1e-9 px at scalar cost; the exact-negation argument holds in any precision.
#pragma once

#include <cstddef>
#include <cstdint>

#include <glm/vec3.hpp>

#include "resample/simd.h"

namespace reshutter::resample {
namespace kernels {

/// The camera's map from homogeneous camera space to raster edges, as toRaster() applies it to a
/// cross product e: (e.x invAx, e.y invAy, (e.z - ex bx) - ey by).
struct RasterScale {
  double invAx, invAy, bx, by;
  bool perspective;  // homogeneous point (x, y, z); otherwise (x, y, 1)
};

}  // namespace kernels

// ------------------------------------------------------------------------------------------
// The scalar reference

/// Edge order of a quad: 01 12 23 30 and the diagonal 02. A triangle uses 01 12 02.
inline constexpr int kEdgeVerts[5][2] = {{0, 1}, {1, 2}, {2, 3}, {3, 0}, {0, 2}};

inline glm::dvec3 cross(const glm::dvec3& a, const glm::dvec3& b) { return {a.y * b.z - a.z * b.y, a.z * b.x - a.x * b.z, a.x * b.y - a.y * b.x}; }

/// A camera-space point as the edge functions see it: (x, y, z) under perspective, (x, y, 1) for
/// an orthographic camera (the edge through two points is then the line through them).
inline glm::dvec3 homogeneous(const glm::vec3& p, bool perspective) { return perspective ? glm::dvec3(p) : glm::dvec3(p.x, p.y, 1.0); }

/// An edge (the plane through the eye and two vertices, or the line through two orthographic
/// vertices) as a function of raster position: E · (x', y', 1) with x' = (x - bx) / ax equals
/// (E.x / ax) x + (E.y / ay) y + (E.z - bx E.x / ax - by E.y / ay). Every operation is odd in E,
/// so the neighbour's exactly negated edge stays exactly negated (watertight ties). It is linear,
/// so it commutes with the quadratic time expansion of EdgeQuad.
inline glm::dvec3 toRaster(const glm::dvec3& e, const kernels::RasterScale& s) {
  const double ex = e.x * s.invAx, ey = e.y * s.invAy;  // reciprocals: 30 divisions per micropolygon otherwise
  return {ex, ey, (e.z - ex * s.bx) - ey * s.by};
}

/// Quadratic coefficients of one edge's cross product over a knot segment: E(f) = e0 + f(e1 + f e2).
struct EdgeQuad {
  glm::dvec3 e0, e1, e2;
  glm::dvec3 at(double f) const { return e0 + f * (e1 + f * e2); }
};

/// An edge's value at raster sample (x, y).
inline double edgeAt(double x, double y, const glm::dvec3& e) { return x * e.x + y * e.y + e.z; }

/// A sample exactly on an edge belongs to the triangle for which the orientation-normalised edge
/// vector is lexicographically positive; the neighbour sees the exact negation and declines.
inline bool ownsTie(const glm::dvec3& e, bool flip) {
  glm::dvec3 v = flip ? -e : e;
  if (v.x != 0) return v.x > 0;
  if (v.y != 0) return v.y > 0;
  return v.z > 0;
}

/// One triangle's coverage from its three edge values, oriented around it, and - for exact zeros
/// only, so they may be computed on demand - its edge vectors vecOf(0..2). A zero-area triangle
/// covers nothing; cullBack knocks out a back-facing one (positive orientation). On a hit, the
/// perspective-correct barycentrics of its three vertices.
template <class EdgeVector>
inline bool triangleCovers(double a0, double a1, double a2, EdgeVector vecOf, bool cullBack, float bOut[3]) {
  const double S = a0 + a1 + a2;
  if (S == 0.0 || (cullBack && S > 0.0)) return false;
  const bool flip = S < 0.0;
  const bool in0 = a0 == 0.0 ? ownsTie(vecOf(0), flip) : (flip ? a0 < 0.0 : a0 > 0.0);
  const bool in1 = a1 == 0.0 ? ownsTie(vecOf(1), flip) : (flip ? a1 < 0.0 : a1 > 0.0);
  const bool in2 = a2 == 0.0 ? ownsTie(vecOf(2), flip) : (flip ? a2 < 0.0 : a2 > 0.0);
  if (!(in0 && in1 && in2)) return false;
  const double inv = 1.0 / S;
  bOut[0] = float(a0 * inv), bOut[1] = float(a1 * inv), bOut[2] = float(a2 * inv);
  return true;
}

/// The edges of a micropolygon that does not move (corners p[0..3]; a triangle's p[3] is unused and
/// its edges 23 and 30 are zero), in raster form.
inline void fixedEdges(const glm::vec3* const p[4], bool triangle, const kernels::RasterScale& s, glm::dvec3 E[5]) {
  for (int k = 0; k < 5; ++k)
    E[k] = triangle && (k == 2 || k == 3)
               ? glm::dvec3(0.0)
               : toRaster(cross(homogeneous(*p[kEdgeVerts[k][0]], s.perspective), homogeneous(*p[kEdgeVerts[k][1]], s.perspective)), s);
}

/// The edges of a micropolygon moving linearly from corners at[j] to to[j] over a knot segment, as
/// quadratics in the segment parameter: A_a × A_b + f (A_a × D_b + D_a × A_b) + f² D_a × D_b with
/// D = to - at (no depth motion for an orthographic camera). A triangle's edges 23 and 30 are left alone.
inline void linearEdges(const glm::vec3* const at[4], const glm::vec3* const to[4], bool triangle, const kernels::RasterScale& s, EdgeQuad q[5]) {
  glm::dvec3 A[4], D[4];
  const int nc = triangle ? 3 : 4;
  for (int j = 0; j < nc; ++j) {
    A[j] = homogeneous(*at[j], s.perspective);
    D[j] = homogeneous(*to[j], s.perspective) - A[j];
    if (!s.perspective) D[j].z = 0.0;
  }
  for (int e = 0; e < 5; ++e) {
    if (triangle && (e == 2 || e == 3)) continue;
    const int a = kEdgeVerts[e][0], b = kEdgeVerts[e][1];
    q[e].e0 = toRaster(cross(A[a], A[b]), s);
    q[e].e1 = toRaster(cross(A[a], D[b]) + cross(D[a], A[b]), s);
    q[e].e2 = toRaster(cross(D[a], D[b]), s);
  }
}

/// Coverage of raster sample (x, y) by a micropolygon with fixed edges E (fixedEdges()): triangle A
/// (p0 p1 p2) first, then B (p0 p2 p3). On a hit, which triangle (0 or 1) and its barycentrics.
inline bool coversFixed(const glm::dvec3 E[5], bool triangle, bool cullBack, double x, double y, int& triOut, float bOut[3]) {
  double e[5] = {0, 0, 0, 0, 0};
  for (int k = 0; k < 5; ++k)
    if (!triangle || k == 0 || k == 1 || k == 4) e[k] = edgeAt(x, y, E[k]);
  triOut = 0;
  if (triangleCovers(
          e[1], -e[4], e[0], [&](int i) { return i == 0   ? E[1]
                                                 : i == 1 ? -E[4]
                                                          : E[0]; }, cullBack, bOut))
    return true;
  triOut = 1;
  return !triangle && triangleCovers(
                          e[2], e[3], e[4], [&](int i) { return E[2 + i]; }, cullBack, bOut);
}

/// Coverage of raster sample (x, y) at segment parameter f by a micropolygon moving with edges q
/// (linearEdges()): triangle A's edges first, B's two others only if A misses, edge vectors only
/// for exact ties. On a hit, which triangle (0 or 1) and its barycentrics.
inline bool coversMoving(const EdgeQuad q[5], bool triangle, bool cullBack, double x, double y, double f, int& triOut, float bOut[3]) {
  auto edgeValue = [&](int ei) { return edgeAt(x, y, q[ei].at(f)); };
  const double e0 = edgeValue(0), e1 = edgeValue(1), e4 = edgeValue(4);
  triOut = 0;
  if (triangleCovers(
          e1, -e4, e0, [&](int i) { return i == 0   ? q[1].at(f)
                                           : i == 1 ? -q[4].at(f)
                                                    : q[0].at(f); }, cullBack, bOut))
    return true;
  triOut = 1;
  return !triangle && triangleCovers(
                          edgeValue(2), edgeValue(3), e4, [&](int i) { return q[2 + i].at(f); }, cullBack, bOut);
}

// ------------------------------------------------------------------------------------------
// The vector kernels: many candidate samples against one micropolygon

namespace kernels {

/// A micropolygon's edges over one knot segment, component-major: edge e's cross product is
/// c[0..2][e] + f (c[3..5][e] + f c[6..8][e]) at segment parameter f (edges 01 12 23 30 02;
/// lanes 5-7 are padding).
struct LinearEdges {
  double c[9][8];
};

/// A still micropolygon's edges through a thin lens of focal distance 1 / invD, as functions of
/// the lens point (perspective only). With corners P_j sheared to S_j = P_j + L q_j (L = (Lx, Ly,
/// 0), q_j = P_j.z invD - 1), an edge's cross product is S_a × S_b = P_a × P_b + L × D with
/// D = q_a P_b - q_b P_a, affine in L: E0 + Lx (0, -Dz, Dy) + Ly (Dz, 0, -Dx). c[0..2][e] is E0's
/// raster form, c[3..5][e] its Lx coefficient's, c[6..8][e] its Ly coefficient's (edges 01 12 23
/// 30 02; a triangle, corner 3 = corner 2, has edges 23 and 30 zero). A shared edge seen from the
/// other side has every term exactly negated, so the test stays watertight. This is the
/// definition; stillLensEdges(isa, ...) computes it bit for bit.
inline void stillLensEdges(const glm::vec3* const p[4], bool triangle, double invD, const RasterScale& s, LinearEdges& out) {
  glm::dvec3 P[4];
  double q[4];
  for (int j = 0; j < 4; ++j) P[j] = glm::dvec3(*p[triangle && j == 3 ? 2 : j]), q[j] = P[j].z * invD - 1.0;
  for (int k = 0; k < 5; ++k) {
    glm::dvec3 E[3]{glm::dvec3(0.0), glm::dvec3(0.0), glm::dvec3(0.0)};  // E0, its Lx and its Ly coefficients
    if (!triangle || (k != 2 && k != 3)) {
      const int a = kEdgeVerts[k][0], b = kEdgeVerts[k][1];
      const glm::dvec3 D = q[a] * P[b] - q[b] * P[a];
      E[0] = toRaster(cross(P[a], P[b]), s);
      E[1] = toRaster(glm::dvec3(0.0, -D.z, D.y), s);
      E[2] = toRaster(glm::dvec3(D.z, 0.0, -D.x), s);
    }
    for (int i = 0; i < 3; ++i)
      for (int axis = 0; axis < 3; ++axis) out.c[3 * i + axis][k] = E[i][axis];
  }
}
void stillLensEdges(Isa isa, const float* const at[4], bool triangle, double invD, const RasterScale& scale, LinearEdges& out);

/// The edges of the micropolygon with corners at[j] at a knot segment's start and to[j] at its end
/// (camera-space xyz; a triangle passes corner 2 as corner 3, and edges 23 and 30 are then
/// meaningless): E = A_a × A_b + f (A_a × D_b + D_a × A_b) + f² D_a × D_b with D = to - at, in
/// the scalar linearEdges()' operations and order, so bit-identical to it.
void linearEdges(Isa isa, const float* const at[4], const float* const to[4], const RasterScale& scale, LinearEdges& out);
/// A static micropolygon's edges: c[0..2] only (A_a × A_b), the scalar fixedEdges()' operations
/// and order.
void fixedEdges(Isa isa, const float* const at[4], const RasterScale& scale, LinearEdges& out);

struct EdgeTestSetup {
  const float* st;  // the candidates' times and raster positions (Candidates::t, x, y)
  const float* sx;
  const float* sy;
  float fOffset, fScale;         // f = clamp((st + fOffset) fScale, 0, 1)
  bool triangle;                 // edges 23 and 30 unused
  bool cullBackFaces;            // back-face knock-out applies to this micropolygon
  bool fixed = false;            // a static micropolygon: the edges are c[e][0..2] at any time (f = 0)
  float za[4] = {}, zb[4] = {};  // corner depths at the segment's two ends (equal when fixed)
  // A still micropolygon through a lens (fixed, su set): the edges are (c[0..2] + Lx c[3..5]) +
  // Ly c[6..8] at the candidate's lens point (Lx, Ly) = lensRadius (su, sv), as the lens path's
  // scalar test makes them.
  const float* su = nullptr;
  const float* sv = nullptr;
  double lensRadius = 0;
};

/// One decided candidate: which triangle it hit (0: p0 p1 p2, 1: p0 p2 p3), its barycentrics
/// and depth; `undecided` when an edge value was exactly zero and the tie rule (which needs the
/// edge vectors) must decide in scalar code. The depth is the scalar paths' float arithmetic at
/// the segment parameter f: zv_j = za_j + f (zb_j - za_j), z = (b0 zv_0 + b1 zv_j1) + b2 zv_j2.
struct EdgeHit {
  uint32_t candidate;  // position in the candidate list
  uint8_t triangle;
  bool undecided;
  float b[3];
  float z;
};

/// Tests candidates 0..n) and appends the hits and undecided ones, in candidate order, to `hits`;
/// returns how many. The list needs room for n + 7 entries, the candidate arrays 7 readable
/// entries past n.
size_t testLinearEdges(Isa isa, const EdgeTestSetup& setup, const LinearEdges& edges, size_t n, EdgeHit* hits);

/// A moving micropolygon through a lens, raster_lens.cpp's testLens() lane for lane: corner j at
/// a candidate's segment parameter f is P_j = a_j + f d_j (double; d = end - start of the knot
/// segment), sheared for its lens point (Lx, Ly) = lensRadius (u, v) to S_j = (P_j.x + Lx q_j,
/// P_j.y + Ly q_j, P_j.z) with q_j = P_j.z invD - 1; its edges toRaster(S_a × S_b) tested as
/// coversFixed() tests them, and the depth from float(P_j.z). A triangle passes corner 2 as
/// corner 3.
struct MovingLensSetup {
  const float* f;  // per candidate: segment parameter, lens point, raster position
  const float* su;
  const float* sv;
  const float* sx;
  const float* sy;
  double a[3][4], d[3][4];  // [axis][corner]
  double lensRadius, invD;
  RasterScale scale;
  bool triangle, cullBackFaces;
};

/// testLinearEdges() for MovingLensSetup's micropolygon: the same hits, undecided ones and list.
size_t testMovingLens(Isa isa, const MovingLensSetup& setup, size_t n, EdgeHit* hits);

}  // namespace kernels
}  // namespace reshutter::resample
