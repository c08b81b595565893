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

 private:
  const std::vector<TileEntry>* entries_ = nullptr;
  const std::vector<Schedule>* schedules_ = nullptr;
  Projector projector_;
  std::vector<RasterRect> shutterBounds_;
  std::vector<std::pair<float, float>> depthRange_;  // per part: nearest and farthest camera depth at any knot
};

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

}  // namespace reshutter::store
