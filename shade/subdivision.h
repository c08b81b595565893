// Subdivision surfaces through OpenSubdiv: a SubdivisionMesh's topology and tags (crease, corner,
// hole, interpolateboundary) refined adaptively into limit patches (Far::PatchTable) and
// evaluated exactly on the limit surface. Each ptex face (a quad face, or one of the quads an
// n-gon splits into; a triangle under Loop) is one primitive the dicer splits like any other.
// Deformation keys share one topology: the surface keeps the control points of every key and
// evaluates between two keys linearly (evaluation is linear in the control points).
#pragma once

#include <memory>
#include <string>
#include <utility>
#include <vector>

#include <glm/vec3.hpp>

namespace reshutter::shade {

enum class SubdivScheme : uint8_t { CatmullClark, Loop, Bilinear };

/// RenderMan's SubdivisionMesh tags, read.
struct SubdivTags {
  std::vector<std::pair<std::vector<int>, double>> creases;  // a vertex chain and its sharpness
  std::vector<std::pair<int, double>> corners;               // a vertex and its sharpness
  std::vector<int> holes;                                    // faces
  int interpolateBoundary = 0;                               // 0 none, 1 edges and corners, 2 edges
};

class SubdivSurface {
 public:
  /// Refines the mesh; `keys` holds the control points of each deformation key. Throws Error
  /// naming `where` for topology OpenSubdiv rejects.
  SubdivSurface(SubdivScheme scheme, const std::vector<int>& nverts, const std::vector<int>& verts, const SubdivTags& tags,
                std::vector<std::vector<glm::dvec3>> keys, const std::string& where);
  ~SubdivSurface();
  SubdivSurface(const SubdivSurface&) = delete;
  SubdivSurface& operator=(const SubdivSurface&) = delete;

  /// The same surface with the control points of more keys appended (motion blocks).
  std::shared_ptr<const SubdivSurface> withKeys(const std::vector<std::vector<glm::dvec3>>& more) const;

  SubdivScheme scheme() const { return scheme_; }
  int ptexFaces() const;
  /// False for ptex faces with no limit surface (holes; boundary faces without interpolateboundary).
  bool hasSurface(int ptexFace) const;
  /// The base face of a ptex face and, for an n-gon's sub-face, which of its corners (0 for a quad).
  std::pair<int, int> baseFace(int ptexFace) const;
  size_t numKeys() const { return points_.size(); }
  /// The control points of key `k` as given.
  std::vector<glm::dvec3> basePoints(size_t k) const {
    return {points_[k].begin(), points_[k].begin() + std::ptrdiff_t(baseVertices_)};
  }

  /// Limit position and first derivatives at (u, v) of ptex face `face` (a triangle's (u, v)
  /// with u + v <= 1 under Loop), deformation key position `key` (fractional: between keys).
  void evaluate(int face, double u, double v, double key, glm::dvec3& P, glm::dvec3* dPdu, glm::dvec3* dPdv) const;

 private:
  struct Osd;
  SubdivSurface() = default;
  std::vector<glm::dvec3> refine(const std::vector<glm::dvec3>& base) const;
  SubdivScheme scheme_ = SubdivScheme::CatmullClark;
  std::shared_ptr<const Osd> osd_;                // refiner, patch table, patch map (shared by withKeys copies)
  std::vector<std::vector<glm::dvec3>> points_;   // per key: refined vertices then local points
  std::vector<int> ptexToFace_, ptexCorner_;
  size_t baseVertices_ = 0;
};

}  // namespace reshutter::shade
