// The built-in surface and light shaders, with the formulas of the RenderMan Interface
// Specification 3.2's standard shaders (constant, matte, metal, plastic, defaultsurface;
// ambientlight, distantlight, pointlight, spotlight), evaluated in camera space at one time.
//
// Specular exponent convention: `specular(N, V, roughness)` sums
//   Cl · max(0, N·H)^(1/roughness),  H = normalize(normalize(L) + V),
// over the lights in the hemisphere around N — the RI Spec's and PRMan's definition. Other
// renderers scale the exponent differently (some by 8/roughness, giving tighter highlights for
// the same roughness), so scenes tuned for them can look broader here.
//
// Surfaces use faceforward(normalize(N), I) as the standard shaders do, so that one-sided
// scenes light correctly from either side. The view-dependent part of each result (the
// specular term, or defaultsurface's headlight term) is returned separately as well, so that
// another camera can subtract it from Ci and add its own (the multi-camera reference's
// "view independent color first" rule).
#pragma once

#include <span>
#include <vector>

#include <glm/mat4x4.hpp>
#include <glm/vec3.hpp>

#include "shade/scene.h"

namespace reshutter::shade {

/// A light resolved into camera space at the shading time.
struct LitLight {
  LightKind kind = LightKind::Point;  // Face: a one-sided area light (Light::oneSided), lit as a point with its cosine
  glm::dvec3 position{0.0};           // point, spot
  glm::dvec3 axis{0, 0, 1};           // distant: direction the light travels; spot: cone axis (unit)
  glm::dvec3 Cl0{1.0};                // intensity · lightcolor (area lights: × the emitter's area)
  double cosOuter = 0, cosInner = 0, beam = 2;
  // What shadow rays aim at (shade/shadows.h): the centre, or an emitter around `position`
  // spanned by the half-extent vectors (sphere, disk: radius vectors), or, for a distant light,
  // directions within its angular radius.
  bool shadows = false;
  uint32_t stored = 0;  // its index among the frame's lights (StoreMeta::lights)
  LightShape shape = LightShape::Point;
  glm::dvec3 halfU{0.0}, halfV{0.0};
  double tanHalfAngle = 0;
  // Uber: camera space to the light's own space, and its controls.
  glm::dmat4 toLight{1.0};
  UberLight uber;
};

LitLight resolveLight(const Light& light, double time);

/// Light arriving at P from one light: `L` points from P towards the light (unnormalised for
/// local lights, unit for distant ones), `Cl` is its colour there. False for ambient lights and
/// points outside a spot's cone.
bool illuminate(const LitLight& light, const glm::dvec3& P, glm::dvec3& L, glm::dvec3& Cl);

glm::dvec3 ambient(std::span<const LitLight> lights);
/// Σ Cl · (normalize(L)·Nn) over lights with L in the hemisphere of Nn (unit).
glm::dvec3 diffuse(const glm::dvec3& P, const glm::dvec3& Nn, std::span<const LitLight> lights);
/// Σ Cl · max(0, Nn·H)^(1/roughness), over lights in the hemisphere of Nn; V is the unit vector
/// towards the eye.
glm::dvec3 specular(const glm::dvec3& P, const glm::dvec3& Nn, const glm::dvec3& V, double roughness, std::span<const LitLight> lights);

struct SurfaceInput {
  glm::dvec3 P{0.0}, N{0, 0, -1}, Ng{0, 0, -1}, I{0, 0, 1};
  glm::dvec3 Cs{1.0}, Os{1.0};
};
struct SurfaceOutput {
  glm::dvec3 Ci{0.0}, Oi{1.0};
  glm::dvec3 viewDependent{0.0};  // the part of Ci that depends on I (included in Ci)
  /// What re-evaluating viewDependent for another eye needs: viewDependent = specWeight ·
  /// Σ visible Cl · max(0, Nf·H)^(1/specRoughness) over the lights (specular()), or, for
  /// defaultsurface's headlight (specRoughness -1), specWeight · (V·Nf)²; -2: no such term
  /// (store::ViewTerm).
  glm::dvec3 specWeight{0.0};
  double specRoughness = -2;
};

SurfaceOutput shadeSurface(const SurfaceShader& shader, const SurfaceInput& in, std::span<const LitLight> lights);

/// faceforward(normalize(N), I), the side Ng decides: the normal the shaders light with.
glm::dvec3 facingNormal(const SurfaceInput& in);

/// Whether a surface of this kind has a term that depends on the eye (SurfaceOutput::specWeight).
/// Diffuse terms count: they are lit on the side facing the eye (faceforward).
constexpr bool viewDependentKind(SurfaceKind k) { return k != SurfaceKind::Constant; }

/// Whether a surface of this kind reflects light sources (so their shadows can show on it).
constexpr bool usesLights(SurfaceKind k) { return k != SurfaceKind::Constant && k != SurfaceKind::DefaultSurface; }

}  // namespace reshutter::shade
