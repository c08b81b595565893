// Dicing: a leaf (split.h) → one grid of micropolygons: positions at every motion knot and the
// geometry the shaders need at the shading time. The grid's rim is snapped onto the points of
// the leaf's sides, so grids that share a side share its points whatever their own step counts
// (the cells along a coarser side become triangles); a side that is one point in space (a
// triangle's apex) makes triangles. Micropolygons that straddle the near plane at some knot are
// dropped, so no projection ever divides by a depth at or behind the eye.
#pragma once

#include <array>
#include <cstdint>
#include <optional>
#include <vector>

#include <glm/mat4x4.hpp>
#include <glm/vec3.hpp>

#include "shade/scene.h"
#include "shade/split.h"
#include "store/model.h"

namespace reshutter::shade {

/// The `order` B-spline basis functions that are non-zero on the span [t[order-1], t[order]) of
/// the 2 · order local knots t, at x (order ≤ 32).
void nurbsBasis(const double* t, int order, double x, double* N);

/// Object-space position at (u, v) of one shape of `p`.
glm::dvec3 evalP(const Primitive& p, const Shape& s, double u, double v);
/// Object-space surface normal at (u, v), along dPdu × dPdv (outward for quadrics with the
/// usual parameter signs); unnormalised. Triangle patches use their face normal.
glm::dvec3 evalNg(const Primitive& p, const Shape& s, double u, double v);

/// One diced grid: positions at every knot, and the shading-time geometry per vertex.
struct DicedGrid {
  int nu = 0, nv = 0;
  uint32_t numVertices = 0;
  std::vector<glm::vec3> positions;  // knots × vertices, camera space
  std::vector<uint32_t> corners;     // 4 per micropolygon, ring order counter-clockwise around N
  // The vertex at each of the (nu + 1) × (nv + 1) lattice points, u fastest (several points share
  // one vertex along a collapsed or snapped side): shading in time shades later times on a
  // coarser lattice (ShadeOptions::timeStride).
  std::vector<uint32_t> lattice;
  uint64_t droppedMicropolygons = 0;
  uint64_t trimmedMicropolygons = 0;  // cut away by trim curves (trim.h)
  // At the shading time, per vertex (camera space):
  std::vector<glm::dvec3> P, N, Ng;  // N, Ng unit
  std::vector<double> u, v, s, t;    // u, v over the whole primitive
};

/// Dices `leaf` of `p`: positions at each of `knots` (one when empty), geometry at `shadeAt`.
void diceLeaf(const Primitive& p, const Leaf& leaf, const std::vector<double>& knots, double shadeAt, double nearClip, bool perspective, DicedGrid& out);

/// The bilinear blend of four corner values (c[0] at u = v = 0, c[1] at u = 1, c[2] at v = 1).
glm::dvec3 bilinear(const std::array<glm::dvec3, 4>& c, double u, double v);

}  // namespace reshutter::shade
