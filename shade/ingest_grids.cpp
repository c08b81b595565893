// Dump ingest, a primitive sent as a grid (shade/ingest_handler.h): its knots (the primitive's
// and its transform's times, clipped to the shutter), camera-space positions at each knot,
// corners, and each schema attribute from the primitive's variables (or Color / Opacity) at the
// rate the schema stores it.
#include <set>

#include <glm/mat3x3.hpp>

#include "shade/ingest_handler.h"

namespace reshutter::shade::ingest {

using namespace store;
using rib::StorageClass;

namespace {

/// The primitive's and its transform's times, clipped to the shutter [open, close].
std::vector<double> knotsOf(const Prim& p, const MotionXform& ctm, double open, double close) {
  std::vector<double> knots;
  std::set<double> ts(p.times.begin(), p.times.end());
  ts.insert(ctm.times.begin(), ctm.times.end());
  if (ts.empty() || !(close > open)) {
    knots = {ts.empty() ? open : std::clamp(open, *ts.begin(), *ts.rbegin())};
  } else {
    const double lo = std::clamp(*ts.begin(), open, close), hi = std::clamp(*ts.rbegin(), open, close);
    knots.push_back(lo);
    for (double t : ts)
      if (t > lo && t < hi) knots.push_back(t);
    if (hi > lo) knots.push_back(hi);
  }
  return knots;
}

/// The grid's vertices: the primitive's, or one per face corner when it is unshared.
struct GridVertices {
  const Prim& p;
  uint32_t count;
  explicit GridVertices(const Prim& prim) : p(prim), count(prim.unshare ? uint32_t(prim.verts.size()) : prim.nP) {}
  uint32_t source(uint32_t v) const { return p.unshare ? p.verts[v] : v; }  // the primitive's vertex
};

/// Positions at every knot, knot-major: the geometry at t (linear between copies, exact at the
/// copies' times), then the CTM at t.
void positionsAtKnots(const GridVertices& gv, const MotionXform& ctm, const std::vector<double>& knots, std::vector<glm::vec3>& out) {
  const Prim& p = gv.p;
  const uint32_t nV = gv.count;
  out.resize(knots.size() * nV);
  for (size_t k = 0; k < knots.size(); ++k) {
    const double t = knots[k];
    // The copies around t and the weight of the later one.
    size_t i0 = 0, i1 = 0;
    double u = 0;
    if (p.P.size() > 1) {
      if (t <= p.times.front()) {
        i0 = i1 = 0;
      } else if (t >= p.times.back()) {
        i0 = i1 = p.P.size() - 1;
      } else {
        i0 = size_t(std::upper_bound(p.times.begin(), p.times.end(), t) - p.times.begin()) - 1;
        i1 = i0 + 1;
        u = (t - p.times[i0]) / (p.times[i1] - p.times[i0]);
      }
    }
    const glm::dmat4 M = ctm.at(t);
    const bool identity = isIdentity(M);
    const float* a = p.P[i0].data();
    const float* b = p.P[i1].data();
    for (uint32_t v = 0; v < nV; ++v) {
      const size_t sv = size_t(gv.source(v)) * 3;
      glm::dvec3 q(a[sv], a[sv + 1], a[sv + 2]);
      if (u > 0) q = q * (1 - u) + glm::dvec3(b[sv], b[sv + 1], b[sv + 2]) * u;
      out[k * nV + v] = identity ? glm::vec3(q) : glm::vec3(glm::dvec3(M * glm::dvec4(q, 1.0)));
    }
  }
}

/// Micropolygon corners as grid vertices.
void cornersOf(const Prim& p, std::vector<uint32_t>& out) {
  const size_t nMp = p.mpFace.size();
  out.resize(nMp * 4);
  for (size_t i = 0; i < nMp * 4; ++i) {
    uint32_t c = p.mpCorners[i];
    out[i] = c == kNoCorner ? kNoCorner : p.unshare ? c : p.verts[c];
  }
}

/// The variable of `p` that becomes the store attribute `name`, and its array element; null
/// when the primitive has none.
const Var* sourceOf(const Prim& p, const std::string& name, int& element) {
  const Var* var = nullptr;
  for (const auto& v : p.vars) {
    for (const auto& o : outputsFor(v.decl))
      if (o.name == name) var = &v, element = o.element;
    if (var) break;
  }
  return var;
}

/// Object → camera at the first knot, for points, vectors and normals.
struct AttrTransform {
  explicit AttrTransform(const glm::dmat4& m) : M0(m), identity(isIdentity(m)), L(m), Ninv(glm::transpose(glm::inverse(glm::dmat3(m)))) {}
  glm::dmat4 M0;
  bool identity;
  glm::dmat3 L, Ninv;
};

/// Attribute `ad` of `count` elements from `var` (array element `element`), in camera space.
void convertAttribute(const AttrDecl& ad, const Var& var, int element, size_t count, const GridVertices& gv, const std::vector<uint32_t>& cornerFace,
                      const AttrTransform& xf, std::vector<float>& out) {
  const Prim& p = gv.p;
  const int nc = componentCount(ad.type);
  const StorageClass sc = var.decl.storage;
  const size_t stride = size_t(var.decl.components()) * size_t(var.decl.arraySize);
  out.resize(count * size_t(nc));
  for (size_t i = 0; i < count; ++i) {
    size_t idx;
    if (sc == StorageClass::Constant) idx = 0;
    else if (ad.rate == AttrRate::Micropolygon) idx = p.mpFace[i];
    else if (faceVaryingClass(sc)) idx = i;
    else if (sc == StorageClass::Uniform) idx = cornerFace[i];
    else idx = gv.source(uint32_t(i));
    const float* src = &var.values[idx * stride + size_t(element) * size_t(nc)];
    float* dst = &out[i * size_t(nc)];
    if (xf.identity || nc != 3 || ad.type == AttrType::Color) {
      std::copy(src, src + nc, dst);
    } else {
      glm::dvec3 v(src[0], src[1], src[2]);
      v = ad.type == AttrType::Point ? glm::dvec3(xf.M0 * glm::dvec4(v, 1.0)) : ad.type == AttrType::Normal ? xf.Ninv * v : xf.L * v;
      dst[0] = float(v.x), dst[1] = float(v.y), dst[2] = float(v.z);
    }
  }
}

}  // namespace

void DumpHandler::emitPrim(const Prim& p) {
  const Attrs& s = cur();
  const std::vector<double> knots = knotsOf(p, s.ctm, meta_->shutterOpen, meta_->shutterClose);
  const GridVertices gv(p);
  positionsAtKnots(gv, s.ctm, knots, positions_);
  cornersOf(p, corners_);
  GridInput g;
  g.schedule = scheduleFor(knots);
  gridAttributes(p, s, knots[0], g);
  g.numVertices = gv.count;
  g.positions = positions_;
  g.corners = corners_;
  g.gridId = gridId_++;
  g.flags = uint8_t((s.twoSided ? kTwoSided : 0) | (s.matte ? kMatte : 0));
  sink_->addGrid(g);
  if (stats_) {
    const size_t nMp = p.mpFace.size();
    stats_->micropolygons += nMp;
    if (knots.size() > 1 && !g.standsStill()) stats_->movingMicropolygons += nMp;  // the writer stores a still grid static
  }
}

/// The sink's schedule for `knots` (0: static); consecutive grids with the same knots share one.
uint32_t DumpHandler::scheduleFor(const std::vector<double>& knots) {
  if (knots.size() <= 1) return 0;
  if (knots != lastSchedule_) lastSchedule_ = knots, lastScheduleIndex_ = sink_->addSchedule(knots);
  return lastScheduleIndex_;
}

/// Every schema attribute the grid has, in schema order, into attrData_ and g.attrs; Ci and Oi
/// from Color and Opacity where the primitive gives no Cs or Os.
void DumpHandler::gridAttributes(const Prim& p, const Attrs& s, double firstKnot, GridInput& g) {
  const GridVertices gv(p);
  const size_t nMp = p.mpFace.size();
  // Face of each face-corner (for uniform values stored per vertex).
  std::vector<uint32_t> cornerFace;
  if (p.unshare) {
    cornerFace.resize(p.verts.size());
    for (uint32_t f = 0; f < p.faceStart.size(); ++f)
      for (uint32_t i = 0; i < p.faceCount[f]; ++i) cornerFace[p.faceStart[f] + i] = f;
  }
  const AttrTransform xf(s.ctm.at(firstKnot));
  const auto& attrs = meta_->schema.attrs;
  attrData_.resize(attrs.size());
  g.attrs.resize(attrs.size());
  for (size_t ai = 0; ai < attrs.size(); ++ai) {
    const AttrDecl& ad = attrs[ai];
    auto& out = attrData_[ai];
    out.clear();
    int element = 0;
    // Shading per knot: "Ci@k" / "Oi@k" (and "Ci" / "Oi" at the first shading time) blend the
    // copies' Cs / Os at the store's shading time k; a primitive without shading per knot
    // leaves the times absent (one colour).
    const size_t k = StoreMeta::timedIndex(ad.name);  // 0: not a shading time's colour
    const bool timed = !p.knotCs.empty() || !p.knotOs.empty();
    if (k && !timed) continue;
    const std::string base = StoreMeta::timedBase(ad.name);
    const Var* var = sourceOf(p, base, element);
    Var blended;
    if (timed && (base == "Ci" || base == "Oi") && var) {
      const auto& knots = base == "Ci" ? p.knotCs : p.knotOs;
      if (!knots.empty() && k < meta_->shadingTimes.size() && p.times.size() == knots.size() && knots.size() > 1) {
        size_t i;
        double w;
        locate(p.times, meta_->shadingTimes[k], i, w);
        blended.decl = var->decl;
        blended.values.resize(var->values.size());
        for (size_t j = 0; j < blended.values.size(); ++j)
          blended.values[j] = float((1 - w) * knots[i][j] + w * knots[i + 1][j]);
        var = &blended;
      }
    }
    const size_t count = ad.rate == AttrRate::Vertex ? gv.count : nMp;
    if (!var) {
      if (base != "Ci" && base != "Oi") continue;  // absent in this grid
      const glm::vec3 c = base == "Ci" ? s.color : s.opacity;
      for (size_t i = 0; i < count; ++i) out.insert(out.end(), {c.x, c.y, c.z});
    } else {
      if (ad.rate == AttrRate::Micropolygon && perVertexClass(var->decl.storage)) continue;  // cannot happen with one file
      convertAttribute(ad, *var, element, count, gv, cornerFace, xf, out);
    }
    g.attrs[ai].f = out;
  }
}

}  // namespace reshutter::shade::ingest
