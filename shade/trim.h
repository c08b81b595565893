// Trim curves (RenderMan TrimCurve): closed loops of rational B-spline curves in the parameter
// space of the NuPatches that follow, flattened to polylines, and which points of that space they
// cut away.
//
// Which side goes: a point is *inside* the loops when a ray from it crosses them an odd number of
// times (RenderMan's odd winding rule; the loops' directions do not matter). Attribute
// "trimcurve" "sense" "inside", the default, cuts away what is inside; "outside" keeps only that
// (PRMan's reading; exporters that give an outer boundary loop write "outside").
//
// Trimming is done per micropolygon at dicing: a micropolygon whose (u, v) centre is cut away is
// dropped, so a trimmed edge is exact to within half a micropolygon (about half a pixel at
// ShadingRate 1); grids that no loop crosses are kept or dropped whole.
#pragma once

#include <vector>

#include <glm/vec2.hpp>
#include <glm/vec4.hpp>

namespace reshutter::shade {

class TrimLoops {
 public:
  /// RiTrimCurve's arrays: per loop its curve count; per curve its order, knots (n + order of
  /// them), parameter range [min, max] and n homogeneous control points (u, v, w). Curves are
  /// flattened to `segmentsPerSpan` straight pieces per knot span. Throws reshutter::Error with a
  /// one-line message naming what is wrong.
  TrimLoops(const std::vector<int>& ncurves, const std::vector<int>& order, const std::vector<double>& knot, const std::vector<double>& min,
            const std::vector<double>& max, const std::vector<int>& n, const std::vector<double>& u, const std::vector<double>& v, const std::vector<double>& w,
            int segmentsPerSpan = 32);

  /// Whether (u, v) is inside by the odd winding rule.
  bool encloses(double u, double v) const;
  /// Whether a loop may pass through the box [u0, u1] × [v0, v1] (when none can, every point of
  /// the box is on the same side).
  bool crosses(double u0, double u1, double v0, double v1) const;
  const std::vector<std::vector<glm::dvec2>>& loops() const { return loops_; }

 private:
  std::vector<std::vector<glm::dvec2>> loops_;  // closed polylines (the last point repeats the first)
  std::vector<glm::dvec4> bounds_;              // per loop: u0 v0 u1 v1
};

}  // namespace reshutter::shade
