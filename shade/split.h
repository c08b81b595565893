// Splitting: a primitive's (u, v) square → leaves, each small enough to dice into one grid, whose
// shared sides dice to the same points (no cracks).
//
// Size: each primitive is split (REYES style) until every piece dices into at most maxGridSize ×
// maxGridSize micropolygons of about `ShadingRate` square pixels, measured on the primary
// camera's raster at *every* motion knot (the largest size over the shutter wins, so no knot is
// under-sampled). GeometricApproximation "motionfactor" coarsens fast-moving pieces: the shading
// rate is multiplied by 1 + motionfactor · (raster motion length in pixels) / 16 — the idea of
// PRMan's attribute (rate grows with blur length, per 16 pixels) and of mental ray's "motion
// factor" (shading samples divided by a screen-speed term); renderers differ in the exact curve,
// so this one is stated here and measured in bench/RESULTS.md.
//
// Eye plane and culling: pieces that straddle the near plane at some knot are split again (up to
// maxEyeSplits times) and then culled; micropolygons that still straddle it after dicing are
// dropped (dice.h), so no projection ever divides by a depth at or behind the eye. Pieces behind
// the near plane or beyond the far plane at every knot, or far outside the screen (beyond
// cullMargin, a fraction of the resolution kept for re-framing), are culled.
//
// Cracks: every decision about a side is taken from that side alone, never from the pieces on
// either side of it (DiagSplit: Fisher, Fatahalian, Boulos, Akeley, Mark & Hanrahan, "DiagSplit:
// parallel, crack-free, adaptive tessellation for micropolygon rendering", SIGGRAPH Asia 2009).
// A side's step count is measured along the side itself; a side of at most maxGridSize steps is
// *final*: it keeps that count for good, and a split that crosses it cuts it at one of its own
// points, so a piece is a quadrilateral of the (u, v) square, not always a rectangle. A longer
// side is cut at its middle. So the two pieces sharing a side, in one primitive or in two whose
// surfaces meet there (a patch mesh, a subdivision mesh, a polygon mesh), dice it to the same
// points whatever rates their interiors need: no T-junction. The grid's rim is then snapped onto
// its sides' points (diceLeaf). Sides are named in an order taken from their end points in space,
// so two primitives that run along a shared side in opposite directions still agree.
// Only a piece left unfinished by maxSplitDepth or the micropolygon budget can still leave a
// T-junction; those are counted.
#pragma once

#include <array>
#include <cstdint>
#include <optional>
#include <vector>

#include "shade/scene.h"
#include "store/model.h"

namespace reshutter::shade {

struct DiceOptions {
  int maxGridSize = 16;
  double shadingRateScale = 1.0;       // multiplies every ShadingRate (quality knob)
  std::optional<double> motionFactor;  // overrides GeometricApproximation "motionfactor"
  double cullMargin = 0.1;             // kept beyond the screen edges, as a fraction of the resolution
  int maxEyeSplits = 12;
  int maxSplitDepth = 60;  // halvings; a side 2^20 steps long needs 20
  /// A primitive that needs more micropolygons than this (a surface seen edge-on under an
  /// extreme shear, weights near zero: work without bound for what covers a few pixels) has its
  /// remaining pieces diced a grid each, coarser than the shading rate, and is counted; so has
  /// one whose splitting visits more than a quarter as many pieces.
  uint64_t maxMicropolygonsPerPrimitive = uint64_t(1) << 24;
};

/// A point of a primitive's (u, v) square.
struct UV {
  double u = 0, v = 0;
  bool operator==(const UV&) const = default;
};

/// The k-th of the n + 1 evenly spaced points from a to b: exactly a at 0 and b at n.
UV pointOnSegment(const UV& a, const UV& b, int k, int n);

/// A side of a leaf: points k0 … k1 of the n-step tessellation of the straight (u, v) segment
/// from a to b. (a, b) is in the side's own order, the same for the leaves on both sides of it;
/// k1 < k0 when this leaf runs the other way.
struct LeafSide {
  UV a, b;
  int n = 1, k0 = 0, k1 = 1;
  bool collapsed = false;  // every point of it is one point in space (a triangle's apex, a tip, no length)
  int steps() const { return k1 > k0 ? k1 - k0 : k0 - k1; }
  /// The i-th point from this leaf's start of the side.
  UV at(int i) const { return pointOnSegment(a, b, k1 > k0 ? k0 + i : k0 - i, n); }
};

/// A piece of a primitive's (u, v) square: a quadrilateral with sides bottom (corner 0 → 1),
/// right (1 → 2), top (2 → 3) and left (3 → 0), counter-clockwise in (u, v); its grid has nu × nv
/// cells, at least as many as any of its sides has steps.
struct Leaf {
  std::array<LeafSide, 4> sides;
  int nu = 1, nv = 1;
  UV corner(int i) const { return sides[size_t(i)].at(0); }
};

struct DiceStats {
  uint64_t leaves = 0, culledPieces = 0, eyeSplits = 0;
  uint64_t forcedCuts = 0;  // sides maxSplitDepth left unfinished: a possible T-junction
  uint64_t overBudget = 0;  // primitives past maxMicropolygonsPerPrimitive (diced coarser)
  /// Micropolygons in the leaves, and (with other cameras) what the primary camera alone would
  /// have diced of the same pieces: their ratio is the geometry detail expansion.
  uint64_t micropolygons = 0, primaryMicropolygons = 0;
};

/// The knot times of `p` inside [open, close]: just `open` for a static primitive, a zero-length
/// interval or motion that does not move inside the interval; otherwise open, every knot
/// strictly inside, and close.
std::vector<double> clipKnots(const Primitive& p, double open, double close);

/// Splits `p` into leaves for `camera` (positions at `knots`, or its only shape when empty), and
/// for `others` too (cameras of the same world the store records): a piece is kept when any
/// camera sees it and diced for the finest rate any camera needs.
void splitPrimitive(const Primitive& p, const std::vector<double>& knots, const store::Camera& camera, const std::vector<store::Camera>& others,
                    const DiceOptions& options, std::vector<Leaf>& out, DiceStats& stats);

}  // namespace reshutter::shade
