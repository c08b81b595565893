// Subdivision surfaces: OpenSubdiv's adaptive refinement and limit-patch evaluation (subdivision.h).
#include "shade/subdivision.h"

#include <cmath>
#include <mutex>

#include <opensubdiv/far/error.h>
#include <opensubdiv/far/patchMap.h>
#include <opensubdiv/far/patchTable.h>
#include <opensubdiv/far/patchTableFactory.h>
#include <opensubdiv/far/primvarRefiner.h>
#include <opensubdiv/far/ptexIndices.h>
#include <opensubdiv/far/topologyDescriptor.h>

#include "common/error.h"

namespace reshutter::shade {

namespace Far = OpenSubdiv::Far;
namespace Sdc = OpenSubdiv::Sdc;

namespace {

// OpenSubdiv reports topology problems through a global callback: collect them per thread and
// turn them into one Error naming the request.
thread_local std::string* osdErrors = nullptr;
void collectOsdError(Far::ErrorType, const char* message) {
  if (osdErrors && osdErrors->size() < 400) *osdErrors += cat(osdErrors->empty() ? "" : "; ", message);
}

struct Point {
  glm::dvec3 p{0.0};
  void Clear(void* = nullptr) { p = glm::dvec3(0.0); }
  void AddWithWeight(const Point& s, double w) { p += w * s.p; }
};

// Deeper isolation of extraordinary features makes the Gregory end caps smaller, at a cost in
// patches; 4 is what OpenSubdiv's own viewers default to for stills.
constexpr int kIsolation = 4;

}  // namespace

struct SubdivSurface::Osd {
  std::unique_ptr<Far::TopologyRefiner> refiner;
  std::unique_ptr<Far::PatchTable> patches;
  std::unique_ptr<Far::PatchMap> map;
};

SubdivSurface::SubdivSurface(SubdivScheme scheme, const std::vector<int>& nverts, const std::vector<int>& verts, const SubdivTags& tags,
                             std::vector<std::vector<glm::dvec3>> keys, const std::string& where)
    : scheme_(scheme) {
  if (keys.empty() || keys[0].empty()) fail(where, "subdivision mesh has no points");
  const size_t nPoints = keys[0].size();
  for (const auto& k : keys)
    if (k.size() != nPoints) fail(where, "the deformation keys of a subdivision mesh have different point counts");
  size_t total = 0;
  for (size_t f = 0; f < nverts.size(); ++f) {
    const int n = nverts[f];
    if (n < 3) fail(where, cat("face ", f, " has ", n, " vertices (at least 3)"));
    if (scheme == SubdivScheme::Loop && n != 3) fail(where, cat("face ", f, " has ", n, " vertices; a loop mesh is made of triangles"));
    total += size_t(n);
  }
  if (total != verts.size()) fail(where, cat("faces name ", verts.size(), " vertex indices; their counts add up to ", total));
  for (int v : verts)
    if (v < 0 || size_t(v) >= nPoints) fail(where, cat("vertex index ", v, " out of range (", nPoints, " points)"));
  for (const auto& k : keys)
    for (const auto& p : k)
      if (!std::isfinite(p.x) || !std::isfinite(p.y) || !std::isfinite(p.z)) fail(where, "a subdivision mesh point is not finite");

  std::vector<int> creasePairs, cornerVerts;
  std::vector<float> creaseWeights, cornerWeights;
  for (const auto& [chain, sharpness] : tags.creases) {
    for (size_t i = 0; i + 1 < chain.size(); ++i) {
      for (int v : {chain[i], chain[i + 1]})
        if (v < 0 || size_t(v) >= nPoints) fail(where, cat("crease vertex ", v, " out of range (", nPoints, " points)"));
      creasePairs.push_back(chain[i]), creasePairs.push_back(chain[i + 1]);
      creaseWeights.push_back(float(sharpness));
    }
  }
  for (const auto& [v, sharpness] : tags.corners) {
    if (v < 0 || size_t(v) >= nPoints) fail(where, cat("corner vertex ", v, " out of range (", nPoints, " points)"));
    cornerVerts.push_back(v), cornerWeights.push_back(float(sharpness));
  }
  for (int h : tags.holes)
    if (h < 0 || size_t(h) >= nverts.size()) fail(where, cat("hole face ", h, " out of range (", nverts.size(), " faces)"));

  Far::TopologyDescriptor desc;
  desc.numVertices = int(nPoints);
  desc.numFaces = int(nverts.size());
  desc.numVertsPerFace = nverts.data();
  desc.vertIndicesPerFace = verts.data();
  desc.numCreases = int(creaseWeights.size());
  desc.creaseVertexIndexPairs = creasePairs.data();
  desc.creaseWeights = creaseWeights.data();
  desc.numCorners = int(cornerWeights.size());
  desc.cornerVertexIndices = cornerVerts.data();
  desc.cornerWeights = cornerWeights.data();
  desc.numHoles = int(tags.holes.size());
  desc.holeIndices = tags.holes.data();

  Sdc::Options options;
  options.SetVtxBoundaryInterpolation(tags.interpolateBoundary == 1   ? Sdc::Options::VTX_BOUNDARY_EDGE_AND_CORNER
                                      : tags.interpolateBoundary == 2 ? Sdc::Options::VTX_BOUNDARY_EDGE_ONLY
                                                                      : Sdc::Options::VTX_BOUNDARY_NONE);
  options.SetFVarLinearInterpolation(Sdc::Options::FVAR_LINEAR_ALL);
  const Sdc::SchemeType type = scheme == SubdivScheme::Loop ? Sdc::SCHEME_LOOP : scheme == SubdivScheme::Bilinear ? Sdc::SCHEME_BILINEAR : Sdc::SCHEME_CATMARK;

  auto osd = std::make_shared<Osd>();
  std::string errors;
  {
    static std::once_flag installed;
    std::call_once(installed, [] { Far::SetErrorCallback(collectOsdError); });
    osdErrors = &errors;
    struct Reset {
      ~Reset() { osdErrors = nullptr; }
    } reset;
    using Factory = Far::TopologyRefinerFactory<Far::TopologyDescriptor>;
    osd->refiner.reset(Factory::Create(desc, Factory::Options(type, options)));
    if (!osd->refiner) fail(where, cat("OpenSubdiv rejects the mesh: ", errors.empty() ? "invalid topology" : errors));
    // Infinitely sharp creases and corners get exact patches, not an approximation at the
    // isolation level.
    Far::TopologyRefiner::AdaptiveOptions adaptive(kIsolation);
    adaptive.useInfSharpPatch = true;
    osd->refiner->RefineAdaptive(adaptive);
    Far::PatchTableFactory::Options po(kIsolation);
    po.useInfSharpPatch = true;
    po.SetPatchPrecision<double>();
    po.SetEndCapType(Far::PatchTableFactory::Options::ENDCAP_GREGORY_BASIS);
    osd->patches.reset(Far::PatchTableFactory::Create(*osd->refiner, po));
    if (!osd->patches) fail(where, cat("OpenSubdiv could not make limit patches: ", errors));
    osd->map = std::make_unique<Far::PatchMap>(*osd->patches);
  }
  osd_ = osd;
  baseVertices_ = nPoints;

  Far::PtexIndices ptex(*osd->refiner);
  const auto& base = osd->refiner->GetLevel(0);
  ptexToFace_.resize(size_t(ptex.GetNumFaces()));
  ptexCorner_.resize(ptexToFace_.size());
  for (int f = 0; f < base.GetNumFaces(); ++f) {
    const int first = ptex.GetFaceId(f);
    const int n = base.GetFaceVertices(f).size();
    const int count = (scheme == SubdivScheme::Loop || n == 4) ? 1 : n;
    for (int i = 0; i < count; ++i) ptexToFace_[size_t(first + i)] = f, ptexCorner_[size_t(first + i)] = i;
  }
  for (auto& k : keys) points_.push_back(refine(k));
}

SubdivSurface::~SubdivSurface() = default;

std::vector<glm::dvec3> SubdivSurface::refine(const std::vector<glm::dvec3>& base) const {
  const Far::TopologyRefiner& r = *osd_->refiner;
  const int nRefined = r.GetNumVerticesTotal(), nLocal = osd_->patches->GetNumLocalPoints();
  std::vector<Point> all(size_t(nRefined + nLocal));
  for (size_t i = 0; i < base.size(); ++i) all[i].p = base[i];
  Far::PrimvarRefinerReal<double> refiner(r);
  Point* src = all.data();
  for (int level = 1; level <= r.GetMaxLevel(); ++level) {
    Point* dst = src + r.GetLevel(level - 1).GetNumVertices();
    refiner.Interpolate(level, src, dst);
    src = dst;
  }
  // The patches are double precision, so are their local-point stencils (ComputeLocalPointValues
  // would read them as float).
  if (nLocal) osd_->patches->GetLocalPointStencilTable<double>()->UpdateValues(all.data(), all.data() + nRefined);
  std::vector<glm::dvec3> out(all.size());
  for (size_t i = 0; i < all.size(); ++i) out[i] = all[i].p;
  return out;
}

std::shared_ptr<const SubdivSurface> SubdivSurface::withKeys(const std::vector<std::vector<glm::dvec3>>& more) const {
  std::shared_ptr<SubdivSurface> s(new SubdivSurface());
  s->scheme_ = scheme_, s->osd_ = osd_, s->points_ = points_, s->ptexToFace_ = ptexToFace_, s->ptexCorner_ = ptexCorner_, s->baseVertices_ = baseVertices_;
  for (const auto& k : more) {
    if (k.size() != baseVertices_) throw Error("subdivision mesh", "deformation keys differ in their point counts");
    s->points_.push_back(refine(k));
  }
  return s;
}

int SubdivSurface::ptexFaces() const { return int(ptexToFace_.size()); }

bool SubdivSurface::hasSurface(int face) const {
  const double c = scheme_ == SubdivScheme::Loop ? 1.0 / 3.0 : 0.5;
  return osd_->map->FindPatch(face, c, c) != nullptr;
}

std::pair<int, int> SubdivSurface::baseFace(int face) const { return {ptexToFace_[size_t(face)], ptexCorner_[size_t(face)]}; }

void SubdivSurface::evaluate(int face, double u, double v, double key, glm::dvec3& P, glm::dvec3* dPdu, glm::dvec3* dPdv) const {
  const Far::PatchTable::PatchHandle* h = osd_->map->FindPatch(face, u, v);
  P = glm::dvec3(0.0);
  if (dPdu) *dPdu = glm::dvec3(0.0);
  if (dPdv) *dPdv = glm::dvec3(0.0);
  if (!h) return;
  double w[20], wu[20], wv[20];
  osd_->patches->EvaluateBasis(*h, u, v, w, wu, wv);
  const Far::ConstIndexArray cvs = osd_->patches->GetPatchVertices(*h);
  const size_t k0 = std::min(size_t(std::max(0.0, std::floor(key))), points_.size() - 1), k1 = std::min(k0 + 1, points_.size() - 1);
  const double t = k1 == k0 ? 0.0 : key - double(k0);
  for (int i = 0; i < cvs.size(); ++i) {
    const glm::dvec3 c = t == 0 ? points_[k0][size_t(cvs[i])] : points_[k0][size_t(cvs[i])] * (1 - t) + points_[k1][size_t(cvs[i])] * t;
    P += w[i] * c;
    if (dPdu) *dPdu += wu[i] * c;
    if (dPdv) *dPdv += wv[i] * c;
  }
}

}  // namespace reshutter::shade
