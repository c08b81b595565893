// RIS nodes onto the built-in shaders and lights (what is kept and why: shade/ris.h).
#include "shade/ris.h"

#include <algorithm>
#include <cmath>
#include <numbers>

#include "common/error.h"
#include "common/log.h"

namespace reshutter::shade {

namespace {

double number(const RisNode& n, const char* name, double fallback) {
  auto it = n.numbers.find(name);
  return it == n.numbers.end() || it->second.empty() ? fallback : it->second[0];
}
glm::dvec3 colour(const RisNode& n, const char* name, glm::dvec3 fallback) {
  auto it = n.numbers.find(name);
  if (it == n.numbers.end() || it->second.empty()) return fallback;
  const auto& v = it->second;
  return v.size() >= 3 ? glm::dvec3(v[0], v[1], v[2]) : glm::dvec3(v[0]);
}
std::string string(const RisNode& n, const char* name) {
  auto it = n.strings.find(name);
  return it == n.strings.end() || it->second.empty() ? std::string() : it->second[0];
}

/// The node a "handle:output" reference names, latest first; null when none has that handle.
const RisNode* referenced(const std::string& ref, std::span<const RisNode> patterns) {
  const std::string handle = ref.substr(0, ref.find(':'));
  for (auto it = patterns.rbegin(); it != patterns.rend(); ++it)
    if (it->request == "Pattern" && it->handle == handle) return &*it;
  return nullptr;
}

/// A diffuse colour parameter: its value, or the texture a PxrTexture connected to it reads
/// (the colour is then white and the texture multiplies it).
glm::dvec3 diffuseColour(const RisNode& bxdf, const char* name, glm::dvec3 fallback, std::span<const RisNode> patterns, SurfaceShader& s,
                         const std::string& where) {
  auto ref = bxdf.references.find(name);
  if (ref == bxdf.references.end()) return colour(bxdf, name, fallback);
  const RisNode* node = referenced(ref->second, patterns);
  if (node && node->type == "PxrTexture" && !string(*node, "filename").empty()) {
    s.textureName = string(*node, "filename");
    s.textureFlipT = number(*node, "invertT", 1) != 0;
    return glm::dvec3(1.0);
  }
  warnOnce(cat("ris-pattern:", node ? node->type : ref->second),
           cat(where, ": ", bxdf.type, " \"", name, "\" is connected to ",
               node ? cat("a ", node->type, " pattern, which the built-in shading does not evaluate") : cat("'", ref->second, "', which no Pattern declared"),
               "; its own value is used"));
  return colour(bxdf, name, fallback);
}

// RenderMan's perceptual roughness is carried over as the RI Spec's roughness (1/exponent):
// the same number gives a broader highlight than RIS's microfacet lobe, but stays a visible one
// at the shading rate, where an energy-preserving sharp lobe would alias.
double roughness(double r) { return std::clamp(r, 1e-3, 1.0); }

}  // namespace

SurfaceShader risMaterial(const RisNode& bxdf, std::span<const RisNode> patterns, const std::string& where) {
  constexpr double invPi = 1.0 / std::numbers::pi;
  SurfaceShader s;
  s.Ka = 1;  // a dome light's radiance L gives albedo × L, as RIS does
  const std::string& t = bxdf.type;
  double presence = number(bxdf, "presence", 1);
  if (t == "PxrConstant") {
    s.kind = SurfaceKind::Constant;
    s.color = colour(bxdf, "emitColor", glm::dvec3(1.0));
  } else if (t == "PxrDiffuse" || t == "PxrLMDiffuse") {
    s.kind = SurfaceKind::Matte, s.Kd = invPi;
    s.color = t == "PxrDiffuse" ? diffuseColour(bxdf, "diffuseColor", glm::dvec3(0.5), patterns, s, where)
                                : diffuseColour(bxdf, "frontColor", glm::dvec3(0.5), patterns, s, where);
  } else if (t == "PxrSurface" || t == "PxrLMPlastic") {
    const double gain = number(bxdf, "diffuseGain", 1);
    const glm::dvec3 base = diffuseColour(bxdf, "diffuseColor", glm::dvec3(0.18), patterns, s, where);
    const glm::dvec3 spec = t == "PxrSurface" ? colour(bxdf, "specularFaceColor", glm::dvec3(0.0)) : colour(bxdf, "specularColor", glm::dvec3(0.5));
    const bool hasSpec = spec.x > 0 || spec.y > 0 || spec.z > 0;
    if (gain <= 0 && hasSpec) {  // all specular: a metal tinted by the face colour
      s.kind = SurfaceKind::Metal, s.Ks = 1, s.color = spec;
    } else {
      s.kind = hasSpec ? SurfaceKind::Plastic : SurfaceKind::Matte;
      s.Kd = gain * invPi, s.Ks = 1, s.specularColor = spec, s.color = base;
    }
    s.roughness = roughness(number(bxdf, "specularRoughness", 0.2));
  } else if (t == "PxrDisney") {
    const glm::dvec3 base = diffuseColour(bxdf, "baseColor", glm::dvec3(0.2), patterns, s, where);
    const double metallic = number(bxdf, "metallic", 0), specular = number(bxdf, "specular", 0.5);
    s.roughness = roughness(number(bxdf, "roughness", 0.25));
    s.color = base;
    if (metallic >= 0.5) s.kind = SurfaceKind::Metal, s.Ks = 1;
    else s.kind = SurfaceKind::Plastic, s.Kd = (1 - metallic) * invPi, s.Ks = specular, s.specularColor = glm::dvec3(1.0);
  } else {
    warnOnce(cat("ris-bxdf:", t), cat(where, ": Bxdf \"", t, "\" is not mapped onto a built-in shader; shaded as matte with its diffuseColor"));
    s.kind = SurfaceKind::Matte, s.Kd = invPi;
    s.color = colour(bxdf, "diffuseColor", glm::dvec3(0.5));
  }
  if (presence < 1) s.opacity = glm::dvec3(std::clamp(presence, 0.0, 1.0));
  return s;
}

bool risLight(const RisNode& n, Light& l, const std::string& where) {
  l = Light{};
  l.name = n.type;
  l.from = glm::dvec3(0.0), l.to = glm::dvec3(0, 0, 1);  // RenderMan's lights face +Z
  l.shadows = number(n, "enableShadows", 1) != 0;
  const glm::dvec3 colourOf = colour(n, "lightColor", glm::dvec3(1.0));
  const double exposure = std::exp2(number(n, "exposure", 0));
  const bool normalize = number(n, "areaNormalize", 0) != 0;
  const std::string& t = n.type;
  if (t == "PxrDistantLight") {
    l.kind = LightKind::Distant;
    l.angle = std::clamp(number(n, "angleExtent", 0.53), 0.0, 180.0) * std::numbers::pi / 180.0;
    // Radiance over the source's solid angle is the irradiance it gives (areaNormalize: the
    // intensity is the irradiance).
    const double solidAngle = 2 * std::numbers::pi * (1 - std::cos(l.angle / 2));
    l.intensity = number(n, "intensity", 50000) * exposure * (normalize || l.angle == 0 ? 1.0 : solidAngle);
  } else if (t == "PxrSphereLight" || t == "PxrDiskLight" || t == "PxrRectLight") {
    l.kind = LightKind::Point;
    l.shape = t == "PxrSphereLight" ? LightShape::Sphere : t == "PxrDiskLight" ? LightShape::Disk : LightShape::Rect;
    l.width = l.height = 1;  // unit sphere and disk diameter, unit square, scaled by the transform
    l.oneSided = l.shape != LightShape::Sphere;
    l.intensity = number(n, "intensity", 1) * exposure;
    l.radiance = !normalize;  // radiance × the emitter's area in camera space (resolveLight)
  } else if (t == "PxrDomeLight" || t == "PxrEnvDayLight") {
    // An environment of radiance L, unshadowed: the ambient term (Ka × Cs × L).
    l.kind = LightKind::Ambient;
    l.intensity = number(n, "intensity", 1) * exposure;
    l.shadows = false;
    if (!string(n, "lightColorMap").empty())
      warnOnce(cat("ris-light-map:", t), cat(where, ": ", t, " \"lightColorMap\" is not read; the light is its constant colour"));
  } else {
    warnOnce(cat("ris-light:", t), cat(where, ": Light \"", t, "\" is not mapped onto a built-in light; skipped"));
    return false;
  }
  l.color = colourOf;
  return true;
}

}  // namespace reshutter::shade
