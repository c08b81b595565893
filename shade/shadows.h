// Ray-traced shadows for the shading pass: the frame's own micropolygons, in one Embree scene
// (Embree: the ray-tracing kernels the field uses, BVH build and traversal included) - at the
// shading time, or, when the pass shades in time, moving over the store's interval with
// Embree's own motion blur - and the share of a light that reaches a shaded point through them.
//
// A light's Cl at a point is multiplied by its visibility: 1 or 0 for a point, spot or sharp
// distant light (one ray to its centre), the fraction of `samples` rays that reach points spread
// over an area light's emitter (or, for a distant light with an angular size, directions within
// it) - so the penumbra follows the emitter's shape while the unshadowed light stays the same
// formula (shade/shaders.h). The pattern is a Hammersley set rotated per point by a hash of
// the point's identity, so images are the same for any thread count.
#pragma once

#include <cmath>
#include <cstdint>
#include <memory>
#include <span>
#include <vector>

#include <glm/common.hpp>
#include <glm/vec3.hpp>

#include "shade/shaders.h"

namespace reshutter::shade {

class ShadowScene {
 public:
  /// One diced grid: vertices in camera space (knot-major: `knots` × vertices, or one set) and 4
  /// corners per micropolygon in ring order (store::kNoCorner as the fourth: a triangle).
  struct Piece {
    std::vector<glm::vec3> P;
    std::vector<uint32_t> corners;
    std::vector<double> knots;  // the positions' times (empty or one: fixed)
    int rigid = -1;             // >= 0: P is one set of vertices moved by that RigidMotion (knots then empty)
  };
  /// How pieces move when they move rigidly (one primitive's, or several under one transform):
  /// their vertices at knot time k are mats[k] · P. Such pieces go into one still BVH of their
  /// own, instanced with Embree's motion-blurred transforms - a BVH without time steps builds
  /// several times faster than one over the moving vertices, and the linear blend of the matrices
  /// between knots (MotionXform::at) moves each vertex exactly as the blend of its positions does.
  using RigidMotion = MotionXform;
  /// Builds the BVH over every piece's micropolygons (watertight traversal: a ray cannot slip
  /// between two micropolygons that share an edge). With `open` < `close`, moving pieces move
  /// over that interval (their knots inside it; Embree's time steps are even, so uneven knots
  /// are resampled onto 2 × knots even steps) and occludedByMoving() takes a time. Still and
  /// moving micropolygons go to separate BVHs: rays at a still point need only the moving ones
  /// at later times, and the still one carries no time steps. At each of `fixAt` (the
  /// shading times) the rigid motions are also instanced with their transforms fixed at that
  /// time, which occludedByMoving() at exactly that time traces instead: the same positions,
  /// without Embree blending and inverting a matrix per instance per ray.
  explicit ShadowScene(std::span<const Piece> pieces, double open = 0, double close = 0, std::span<const RigidMotion> rigid = {},
                       std::span<const double> fixAt = {});
  ~ShadowScene();
  ShadowScene(const ShadowScene&) = delete;
  ShadowScene& operator=(const ShadowScene&) = delete;

  /// True when a micropolygon that stands still lies on the ray from `origin` along unit `dir`
  /// within (0, tfar); occludedByMoving(): one that moves, at `time` (frames; clamped to the
  /// interval). A ray is blocked when either says so. Thread-safe.
  bool occludedByStill(const glm::dvec3& origin, const glm::dvec3& dir, double tfar) const;
  bool occludedByMoving(const glm::dvec3& origin, const glm::dvec3& dir, double tfar, double time) const;
  /// occludedByStill() || occludedByMoving(), in one traversal of every micropolygon at a time
  /// the rigid motions are fixed at (for a ray whose two answers are not needed apart).
  bool occluded(const glm::dvec3& origin, const glm::dvec3& dir, double tfar, double time) const;
  uint64_t micropolygons() const { return micropolygons_; }
  /// The rigid motions instanced, and the micropolygons moving that way.
  uint64_t rigidInstances() const { return rigidInstances_; }
  uint64_t rigidMicropolygons() const { return rigidMicropolygons_; }
  /// How many shutter instants the rigid motions are also instanced fixed at (0 without rigid
  /// motions): a count of instants, not a duration.
  size_t fixedInstants() const;
  /// Whether any micropolygon moves (occludedByMoving() can say true).
  bool moves() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
  uint64_t micropolygons_ = 0, rigidInstances_ = 0, rigidMicropolygons_ = 0;
};

/// A camera-space box (the bounds of moving casters and receivers over an interval).
struct ShadowBox {
  glm::dvec3 lo{INFINITY}, hi{-INFINITY};
  void add(const glm::vec3& p) { lo = glm::min(lo, glm::dvec3(p)), hi = glm::max(hi, glm::dvec3(p)); }
};

/// The boxes of the frame's moving casters, seen from each light once: whether any of them can
/// shadow a point inside a receiver's box, conservatively (false only when none can). Along a
/// distant light's direction, widened by its cone; for a local light, inside its cone around the
/// caster's bounding sphere, grown by the emitter's size.
class MovingCasters {
 public:
  MovingCasters() = default;
  MovingCasters(std::span<const LitLight> lights, std::vector<ShadowBox> casters);
  bool empty() const { return casters_.empty(); }
  /// Whether a caster can shadow `receiver` from light `li` (an index into the lights given).
  bool mayShadow(size_t li, const ShadowBox& receiver) const;

 private:
  struct Seen {                                      // one caster from one light
    double lo[3], hi[3];                             // distant: its extent along the light's frame (e1, e2, d)
    double radius = 0, distance = 0, halfAngle = 0;  // local: its sphere grown by the emitter, seen from the light
    double cosHalf = 1, sinHalf = 0;                 // of halfAngle
    glm::dvec3 toCaster{0};
  };
  struct FromLight {
    bool shadows = false, directional = false;
    glm::dvec3 e1{0}, e2{0}, d{0};
    std::vector<Seen> casters;
  };
  std::vector<ShadowBox> casters_;
  std::vector<FromLight> lights_;
  std::span<const LitLight> lit_;
};

/// One ray towards a light: from `origin` along unit `dir`, blocked by anything within (0, tfar).
struct ShadowRay {
  glm::dvec3 origin, dir;
  double tfar;
};

/// The rays that sample the share of `light` reaching P, into `rays` (replaced); the share is
/// the fraction of them that nothing blocks (ShadowScene::occludedByStill / occludedByMoving). `Ng` is the surface's unit geometric normal
/// (either side), `bias` how far ray origins are lifted off the surface towards the light
/// (about half a micropolygon: the diced surface is not the true one), `samples` the rays of an
/// area or soft distant light, `seed` the point's identity. Empty when the light casts no
/// shadows (its share is 1); a degenerate ray towards a local light is left out of the rays but
/// still counts as blocked - the returned count is the share's denominator.
size_t shadowRays(const LitLight& light, const glm::dvec3& P, const glm::dvec3& Ng, double bias, int samples, uint64_t seed, std::vector<ShadowRay>& rays);

}  // namespace reshutter::shade
