// Rendering from a camera other than the one a store was shaded from (the reference's multi-camera
// output): cameras given after the fact (look-from / look-at, a stereo pair around a camera), and
// what a render needs to draw a store through one - the transform from the store's primary camera
// space into it, the parts' bounds carried there (store/view_bounds.h), the store's lights and
// volumes carried with them. The rasterizer is the same: it only ever sees camera-space parts.
#pragma once

#include <memory>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include <glm/mat4x4.hpp>
#include <glm/vec3.hpp>

#include "store/reader.h"
#include "store/view_bounds.h"

namespace reshutter::resample {

/// A camera like `base` (projection, resolution, screen window, clipping, lens) looking from
/// `from` at `to` in `base`'s world, `up` towards the top of the image, with `fovDegrees` when
/// given. It keeps the handedness of base's world-to-camera transform (a RIB camera transform often
/// mirrors z), so that a look-at placed where base is gives base's image, not its mirror. Throws
/// Error naming the option when from == to or up is parallel to the view direction.
store::Camera lookAtCamera(const store::Camera& base, const glm::dvec3& from, const glm::dvec3& to, const glm::dvec3& up, std::optional<double> fovDegrees);

/// A look-at camera that moves over [open, close]: from `from[0]` looking at `to[0]` at the open
/// to `from[1]` looking at `to[1]` at the close, eye and target moving linearly. A camera that
/// only translates keeps its two ends (exact: a translation is linear); one that turns is sampled
/// every kTurnStepDegrees of its turn, each time a true look-at. Between them positions are linear
/// in camera space, as in every store: a chord of a point's arc about the eye projects onto the
/// arc's own raster path, so a pan's image is off only in timing: at most 0.005 degrees in a
/// 10-degree step (0.12 px for the bench's 1080p camera), falling as the step's cube. Throws as
/// lookAtCamera() does.
store::Camera movingLookAtCamera(const store::Camera& base, const glm::dvec3 from[2], const glm::dvec3 to[2], const glm::dvec3& up, std::optional<double> fovDegrees,
                                 double open, double close);
constexpr double kTurnStepDegrees = 10.0;

/// The two eyes of a stereo pair around `centre`, named "left" and "right": each moved half of
/// `baseline` (camera-space units) along centre's x axis, axes parallel. A finite `convergence`
/// (camera depth, > 0) shifts each eye's screen window so that points at that depth land where the
/// centre camera puts them (zero parallax: the off-axis stereo rig); infinite = parallel.
std::vector<store::Camera> stereoPair(const store::Camera& centre, double baseline, double convergence);
/// stereoPair() from "BASELINE" or "BASELINE:CONVERGENCE" (the --stereo option); throws Error
/// naming `where`.
std::vector<store::Camera> stereoPair(const store::Camera& centre, const std::string& rig, const std::string& where);

/// The times within [open, close] at which the carry from `primary`'s space into `view`'s is
/// evaluated - the shutter's ends and both cameras' motion times between - or empty when it is
/// one transform over the whole shutter (store::carryTimes()).
std::vector<double> carryTimes(const store::Camera& primary, const store::Camera& view, double open, double close);

/// Whether `view` sees what `primary` does: the same world-to-camera transform, projection, field
/// of view, screen window and near plane, so that the store's own bounds serve it (its resolution
/// and lens may differ).
bool sameView(const store::Camera& primary, const store::Camera& view);

/// Re-lights a part's view-dependent terms for another eye (store::ViewTerm): each vertex that
/// carries their inputs gets the colour of the side it shows the view's eye plus Kspec · S(V), V
/// towards that eye, and its colours at later shading times ("Ci@k") the same change.
class ViewRelighting {
 public:
  /// Inactive when the store carries no view-dependent inputs.
  ViewRelighting(const store::StoreMeta& meta, const glm::dmat4& toView, bool perspective);
  bool active() const { return cvi_ >= 0; }
  /// `carried` is `primary` carried into the view's space; returns the vertices re-lit.
  uint64_t apply(const store::TilePart& primary, store::TilePart& carried) const;

 private:
  const store::StoreMeta& meta_;
  int cvi_ = -1, back_ = -1, weight_ = -1, normal_ = -1, roughness_ = -1, ci_ = -1;
  std::vector<int> visibility_;  // per stored light: its Lvis attribute (-1: none, counted visible)
  std::vector<int> timedCi_;     // "Ci@k" slots
  bool perspective_ = true;
  glm::dvec3 eye_{0.0}, towardsEye_{0.0};  // in the primary camera's space: the view's eye, or (orthographic) the direction to it
};

/// One store as another camera sees it: its index carried into the camera's space and bounded in
/// its raster (`projector`: the output resolution), its view-dependent shading re-lit for the
/// camera's eye when asked and the store carries what that needs.
class CarriedStore {
 public:
  CarriedStore(const store::StoreReader& reader, const store::Camera& view, const store::Projector& projector, bool relight);
  /// The carry at the shutter's open (lights, volumes and the re-lit eye use it).
  const glm::dmat4& toView() const { return toView_; }
  const store::ViewBounds& bounds() const { return bounds_; }
  /// Part `entry`'s index entry as carried: its knots (and schedule) are the view's.
  const store::TileEntry& entry(size_t entry) const { return entries_[entry]; }
  /// The carried knot schedules the entries refer to: the store's own, or - when a camera moves -
  /// each with the carry's times added.
  const std::vector<store::Schedule>& schedules() const { return schedules_; }
  bool moving() const { return !carried_.empty(); }
  /// The decoded part `entry` carried into the view's space; `relit` counts the vertices whose
  /// view-dependent term was re-evaluated.
  std::shared_ptr<const store::TilePart> part(size_t entry, uint64_t& relit) const;

 private:
  const store::StoreReader& reader_;
  glm::dmat4 toView_;
  std::vector<store::CarriedSchedule> carried_;  // per store schedule, when a camera moves
  std::vector<store::Schedule> schedules_;
  std::vector<store::TileEntry> entries_;
  store::ViewBounds bounds_;
  ViewRelighting relighting_;
  bool relight_;
};

/// Per pixel of a `width` × `height` image from `view` (at that resolution; `toView` carries the
/// store's primary camera space into it): 1 where the pixel's centre ray, between the depths the
/// store's parts reach, never enters the frame of a camera the store records nor the raster
/// bounds of what it kept - no shading camera looked there, so the store cannot hold what is
/// there. Orthographic views: all 0 (not judged).
std::vector<uint8_t> unseenPixels(const store::StoreReader& reader, const store::Camera& view, const glm::dmat4& toView, int width, int height);

/// A light the shading pass recorded (primary camera space) in the view camera's space.
store::StoredLight carriedLight(const store::StoredLight& light, const glm::dmat4& toView);

}  // namespace reshutter::resample
