// The tile parts' bounds as one camera sees them: per part, its raster bound over any time interval
// and over the whole shutter, and its depth range (for the lens's reach). The store reader keeps
// one for the camera the frame was shaded from; a render from another camera makes one from the
// same index carried into that camera's space (carriedEntries), and carries each part it draws
// (carriedPart), so that every camera is rendered by the same rasterizer from the same store.
#pragma once

#include <functional>
#include <utility>
#include <vector>

#include <glm/mat4x4.hpp>

#include "store/format.h"
#include "store/model.h"

namespace reshutter::store {

class ViewBounds {
 public:
  ViewBounds() = default;
  /// Bounds of `entries` (knot bounds in the camera `projector` projects for) over the store's
  /// shutter [open, close]. Keeps pointers to `entries` and `schedules`: they must outlive it.
  ViewBounds(const std::vector<TileEntry>& entries, const std::vector<Schedule>& schedules, const Projector& projector, double open, double close);

  /// Bound of part `i` over [t0, t1] in this camera's raster.
  RasterRect bounds(size_t i, double t0, double t1) const;
  /// Calls fn(i) for every part whose bound over [t0, t1] overlaps `rect`, in index order. With a
  /// lens each bound is first widened by the largest circle of confusion the part's depths take.
  void visit(const RasterRect& rect, double t0, double t1, const std::function<void(size_t)>& fn, const Lens& lens = {}) const;
  const Projector& projector() const { return projector_; }
  /// The union of every part's bound over the shutter (empty for an empty store).
  RasterRect extent() const;
  /// The nearest and farthest camera depth a part reaches at any knot (infinities when empty).
  std::pair<float, float> depths() const;
  /// Each part's largest circle of confusion through `lens` (circleOfConfusion() over its depths,
  /// in units of the projection's scale) times its micropolygons, summed, and those micropolygons:
  /// their ratio is the circle a micropolygon typically takes. Parts that reach the eye plane are
  /// left out; without a lens both are 0.
  struct CircleTotals {
    double weighted = 0, micropolygons = 0;
  };
  CircleTotals circleTotals(const Lens& lens) const;

 private:
  const std::vector<TileEntry>* entries_ = nullptr;
  const std::vector<Schedule>* schedules_ = nullptr;
  Projector projector_;
  std::vector<RasterRect> shutterBounds_;
  std::vector<std::pair<float, float>> depthRange_;  // per part: nearest and farthest camera depth at any knot
};

/// The transform from `primary`'s camera space to `view`'s (two cameras of one world): where they
/// stand at the shutter's open, or at frame-relative time t (the two differ when one moves).
glm::dmat4 primaryToView(const Camera& primary, const Camera& view);
glm::dmat4 primaryToView(const Camera& primary, const Camera& view, double t);

/// The times at which the carry from `primary`'s space into `view`'s changes slope - every motion
/// time of either camera - or empty when it is one transform at all times (neither moves, or
/// they move as one rig, as a stereo pair of a moving camera does).
std::vector<double> carryTimes(const Camera& primary, const Camera& view);

/// `entries` (bounded for the camera `primary` projects for) with their knot bounds carried by
/// `primaryToView` (primary camera space → another camera's space, affine) and projected by that
/// camera's `projector`. A knot's points lie in its camera box and, where its primary raster bound
/// is finite, in the slab of the primary's frustum over that bound between the box's depths: each
/// carried bound is the intersection of both hulls' (their eight corners carried, padded for the
/// float rounding of carried positions; a perspective projection maps a hull in front of the eye
/// to the hull of its projected corners), and not finite where the box reaches the near plane.
std::vector<TileEntry> carriedEntries(const std::vector<TileEntry>& entries, const glm::dmat4& primaryToView, const Projector& primary, const Projector& projector);

/// A copy of `part` in another camera's space: positions and every point-typed attribute carried
/// by `primaryToView`, vectors by its linear part, normals by that part's inverse transpose (a
/// rigid camera change keeps their lengths).
TilePart carriedPart(const TilePart& part, const glm::dmat4& primaryToView, const Schema& schema);

/// A schedule carried into a camera whose carry changes over the shutter (one of the two cameras
/// moves): the part's own knots and the carry's times together, the carry at each, and where each
/// lies among the part's own knots (between knot `segment` and the next, `weight` of the way).
/// Between its times the carried positions are linear in the view's camera space, as every
/// store's are in its own; at the part's knots and the carry's times they are exact.
struct CarriedSchedule {
  Schedule times;
  std::vector<glm::dmat4> toView;  // primary camera space at each time → the view's
  std::vector<uint32_t> segment;
  std::vector<double> weight;
};

/// `schedule` (a store's; store schedule 0 is a part that stands still) carried through
/// `carry(t)`: its own knots and every time of `carryTimes` (increasing, within the shutter).
CarriedSchedule carriedSchedule(const Schedule& schedule, bool stillSchedule, const std::vector<double>& carryTimes, const std::function<glm::dmat4(double)>& carry);

/// `entries` carried through moving carries: entry e's knots become those of
/// `schedules[e.schedule]` (the carried schedule of the store's schedule of the same index), each
/// bound as carriedEntries() bounds a knot, from the part's bound at that time; a part that stood
/// still moves.
std::vector<TileEntry> carriedEntries(const std::vector<TileEntry>& entries, const std::vector<CarriedSchedule>& schedules, const Projector& primary,
                                      const Projector& projector);

/// A copy of `part` carried through `schedule`: positions at each of its times; point, vector and
/// normal attributes by its first time's carry (the shutter's open).
TilePart carriedPart(const TilePart& part, const CarriedSchedule& schedule, const Schema& schema);

}  // namespace reshutter::store
