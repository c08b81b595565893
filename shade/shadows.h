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
  };
  /// Builds the BVH over every piece's micropolygons (watertight traversal: a ray cannot slip
  /// between two micropolygons that share an edge). With `open` < `close`, moving pieces move
  /// over that interval (their knots inside it; Embree's time steps are even, so uneven knots
  /// are resampled onto 2 × knots even steps) and occluded() takes a time.
  explicit ShadowScene(std::span<const Piece> pieces, double open = 0, double close = 0);
  ~ShadowScene();
  ShadowScene(const ShadowScene&) = delete;
  ShadowScene& operator=(const ShadowScene&) = delete;

  /// True when anything lies on the ray from `origin` along unit `dir` within (0, tfar), at
  /// `time` (frames; clamped to the interval). Thread-safe.
  bool occluded(const glm::dvec3& origin, const glm::dvec3& dir, double tfar, double time = 0) const;
  uint64_t micropolygons() const { return micropolygons_; }

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
  uint64_t micropolygons_ = 0;
};

/// A camera-space box (the bounds of moving casters and receivers over an interval).
struct ShadowBox {
  glm::dvec3 lo{INFINITY}, hi{-INFINITY};
  void add(const glm::vec3& p) { lo = glm::min(lo, glm::dvec3(p)), hi = glm::max(hi, glm::dvec3(p)); }
};

/// Whether anything inside `caster` can shadow a point inside `receiver` from `light`,
/// conservatively (false only when it cannot): along a distant light's direction, widened by
/// its cone; for a local light, inside its cone around the caster's bounding sphere, grown by
/// the emitter's size.
bool mayShadow(const LitLight& light, const ShadowBox& caster, const ShadowBox& receiver);

/// The share of `light` (0..1) that reaches P: `Ng` is the surface's unit geometric normal
/// (either side), `bias` how far ray origins are lifted off the surface towards the light
/// (about half a micropolygon: the diced surface is not the true one), `samples` the rays of an
/// area or soft distant light, `seed` the point's identity. Counts the rays traced into `rays`.
double lightVisibility(const ShadowScene& scene, const LitLight& light, const glm::dvec3& P, const glm::dvec3& Ng, double bias, int samples, uint64_t seed,
                       uint64_t& rays, double time = 0);

}  // namespace reshutter::shade
