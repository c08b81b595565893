// RIS materials and lights mapped onto the built-in models (shade/shaders.h), with their main
// parameters; docs/shading.md has the table. A RIS scene is shaded by the same standard shaders
// as a classic one, so the mapping keeps what decides a look - diffuse colour and gain, specular
// colour and roughness, presence; light intensity, exposure, colour, shape and shadows - and
// drops the rest with one warning per (node type, parameter kind).
//
// Units: RIS lights give radiance (area lights, dome) or radiance over a solid angle (distant),
// so a light's Cl is irradiance; RIS diffuse materials therefore divide their colour by π (a
// Lambertian surface's radiance is albedo/π × irradiance). Lights follow RenderMan's convention:
// centred at the origin of their space and emitting towards +Z.
#pragma once

#include <span>
#include <string>

#include "shade/scene.h"

namespace reshutter::shade {

/// The built-in surface for a Bxdf node; `patterns` are the nodes declared before it, searched
/// (latest first) for the handles its "reference" parameters name (PxrTexture feeds the diffuse
/// colour). `where` prefixes warnings. Unknown Bxdfs warn once and shade as matte.
SurfaceShader risMaterial(const RisNode& bxdf, std::span<const RisNode> patterns, const std::string& where);

/// The built-in light for a RIS Light node; false (with one warning) for a type not mapped.
bool risLight(const RisNode& node, Light& out, const std::string& where);

}  // namespace reshutter::shade
