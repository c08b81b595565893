// The one RIB interpreter of the graphics state: options and camera, frame and world blocks,
// transforms and coordinate systems, the attributes every primitive carries (Color, Opacity,
// Orientation, Sides, Matte, identifier) and motion blocks, all turned into calls on one
// shade::Scene. The scene reader (rib_scene.h) and dump ingest (ingest_handler.h) both send
// every request here first, so the two cannot disagree about RenderMan semantics; each keeps only
// what is its own (shading and primitives; shaded dump polygons).
#pragma once

#include <cstdint>
#include <vector>

#include <glm/mat4x4.hpp>

#include "rib/rib.h"
#include "shade/scene.h"

namespace reshutter::shade {

/// Takes `r` when it sets graphics state (above) and returns true; false for any other request.
/// Sets `scene.where` to the request's location for the builder's messages.
bool applyStateRequest(Scene& scene, const rib::Request& r, const rib::Args& a);

/// Argument helpers with errors naming the request.
/// An integer argument in [lo, hi] (converting an out-of-range double to an int is undefined).
int64_t integerArg(const rib::Args& a, size_t i, double lo, double hi);
/// Integers of a number array (vertex counts, indices), each in [lo, hi].
std::vector<int> intArray(const rib::Args& a, size_t i, double lo = -2e9, double hi = 2e9);
/// A 4x4 matrix given as one array or 16 numbers.
glm::dmat4 matrixArg(const rib::Args& a);

}  // namespace reshutter::shade
