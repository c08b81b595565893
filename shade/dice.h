// Dicing: primitives → parametric grids of micropolygons.
//
// Each primitive is split (REYES style) until every piece dices into at most maxGridSize ×
// maxGridSize micropolygons of about `ShadingRate` square pixels, measured on the primary
// camera's raster at *every* motion knot (the largest size over the shutter wins, so no knot is
// under-sampled). GeometricApproximation "motionfactor" coarsens fast-moving pieces: the shading
// rate is multiplied by 1 + motionfactor · (raster motion length in pixels) / 16 — the idea of
// PRMan's attribute (rate grows with blur length, per 16 pixels) and of mental ray's "motion
// factor" (shading samples divided by a screen-speed term); renderers differ in the exact
// curve, so this one is stated here and measured in bench/RESULTS.md. Pieces that straddle the near plane at some knot are split again (up to
// maxEyeSplits times) and then culled; micropolygons that still straddle it after dicing are
// dropped, so no projection ever divides by a depth at or behind the eye. Pieces that are
// behind the near plane or beyond the far plane at every knot, or far outside the screen
// (beyond cullMargin, a fraction of the resolution kept for re-framing), are culled.
#pragma once

#include <cstdint>
#include <optional>
#include <vector>

#include <glm/mat4x4.hpp>
#include <glm/vec3.hpp>

#include "shade/scene.h"
#include "store/model.h"

namespace reshutter::shade {

struct DiceOptions {
  int maxGridSize = 16;
  double shadingRateScale = 1.0;       // multiplies every ShadingRate (quality knob)
  std::optional<double> motionFactor;  // overrides GeometricApproximation "motionfactor"
  double cullMargin = 0.1;             // kept beyond the screen edges, as a fraction of the resolution
  int maxEyeSplits = 12;
  int maxSplitDepth = 30;
};

/// Object-space position at (u, v) of one shape of `p`.
glm::dvec3 evalP(const Primitive& p, const Shape& s, double u, double v);
/// Object-space surface normal at (u, v), along dPdu × dPdv (outward for quadrics with the
/// usual parameter signs); unnormalised. Triangle patches use their face normal.
glm::dvec3 evalNg(const Primitive& p, const Shape& s, double u, double v);

/// A piece of a primitive's (u, v) square and its dicing rate.
struct Leaf {
  double u0 = 0, u1 = 1, v0 = 0, v1 = 1;
  int nu = 1, nv = 1;
};

struct DiceStats {
  uint64_t leaves = 0, culledPieces = 0, eyeSplits = 0;
};

/// The knot times of `p` inside [open, close]: just `open` for a static primitive, a zero-length
/// interval or motion that does not move inside the interval; otherwise open, every knot
/// strictly inside, and close.
std::vector<double> clipKnots(const Primitive& p, double open, double close);

/// Splits `p` into leaves for `camera` (positions at `knots`, or its only shape when empty).
void splitPrimitive(const Primitive& p, const std::vector<double>& knots, const store::Camera& camera, const DiceOptions& options, std::vector<Leaf>& out,
                    DiceStats& stats);

/// One diced grid: positions at every knot, and the shading-time geometry per vertex.
struct DicedGrid {
  int nu = 0, nv = 0;
  uint32_t numVertices = 0;
  std::vector<glm::vec3> positions;  // knots × vertices, camera space
  std::vector<uint32_t> corners;     // 4 per micropolygon, ring order counter-clockwise around N
  uint64_t droppedMicropolygons = 0;
  // At the shading time, per vertex (camera space):
  std::vector<glm::dvec3> P, N, Ng;  // N, Ng unit
  std::vector<double> u, v, s, t;    // u, v over the whole primitive
};

/// Dices `leaf` of `p`: positions at each of `knots` (one when empty), geometry at `shadeAt`.
void diceLeaf(const Primitive& p, const Leaf& leaf, const std::vector<double>& knots, double shadeAt, double nearClip, bool perspective, DicedGrid& out);

}  // namespace reshutter::shade
