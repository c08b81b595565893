// Triangulating a planar polygon with holes (GeneralPolygon, PointsGeneralPolygons): each hole is
// bridged into the outline at a vertex it can see (D. Eberly, "Triangulation by Ear Clipping"),
// and the one simple loop that makes is ear-clipped in the plane of the outline. Written by hand:
// no Debian package triangulates polygons with holes without pulling in a geometry kernel.
#pragma once

#include <array>
#include <vector>

#include <glm/vec3.hpp>

namespace reshutter::shade {

/// Triangles (indices into P, wound like the outline) of loops[0] minus the holes loops[1..];
/// each loop lists indices into P. False when the loops are degenerate or not simple enough to
/// clip (crossing edges, a hole outside its outline).
bool triangulateLoops(const std::vector<glm::dvec3>& P, const std::vector<std::vector<int>>& loops, std::vector<std::array<int, 3>>& triangles);

}  // namespace reshutter::shade
