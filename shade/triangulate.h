// Triangulating a planar polygon with holes (GeneralPolygon, PointsGeneralPolygons): each hole is
// bridged into the outline at a vertex it can see (D. Eberly, "Triangulation by Ear Clipping"),
// and the one simple loop that makes is ear-clipped in the plane of the outline. Written by hand:
// no Debian package triangulates polygons with holes without pulling in a geometry kernel.
#pragma once

#include <array>
#include <vector>

#include <glm/vec2.hpp>
#include <glm/vec3.hpp>

namespace reshutter::shade {

/// Ear clipping of one simple loop of 2-D points (`loop` lists indices into q), either winding:
/// the triangles keep the loop's winding. A point at a corner's own position never blocks that
/// corner's ear (hole bridges repeat positions). False when no ear is left to clip (a
/// self-intersecting or degenerate loop); `triangles` is then as it was.
bool earClipLoop(const std::vector<glm::dvec2>& q, const std::vector<int>& loop, std::vector<std::array<int, 3>>& triangles);

/// Triangles (indices into P, wound like the outline) of loops[0] minus the holes loops[1..];
/// each loop lists indices into P. False when the loops are degenerate or not simple enough to
/// clip (crossing edges, a hole outside its outline).
bool triangulateLoops(const std::vector<glm::dvec3>& P, const std::vector<std::vector<int>>& loops, std::vector<std::array<int, 3>>& triangles);

}  // namespace reshutter::shade
