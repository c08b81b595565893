// Dump ingest, polygon requests (shade/ingest_handler.h): PointsPolygons, PointsGeneralPolygons,
// Polygon and GeneralPolygon read into a Prim - counts, positions (P, Pw, blurP), faces, motion
// copies, variables checked against the primitive's size - then split into quads and triangles
// (fans for convex polygons, ear clipping for the others) and its variables entered in the
// schema. Sending the Prim as a grid is ingest_grids.cpp's.
#include <algorithm>
#include <array>
#include <cmath>

#include "common/error.h"
#include "common/log.h"
#include "shade/ingest_handler.h"
#include "shade/triangulate.h"

namespace reshutter::shade::ingest {

using namespace store;
using rib::Args;
using rib::ParamDecl;
using rib::ParamType;
using rib::Request;
using rib::StorageClass;

std::vector<OutAttr> outputsFor(const ParamDecl& d) {
  AttrType t;
  switch (d.type) {
    case ParamType::Float:
    case ParamType::Integer: t = AttrType::Float; break;
    case ParamType::Point: t = AttrType::Point; break;
    case ParamType::Vector: t = AttrType::Vector; break;
    case ParamType::Normal: t = AttrType::Normal; break;
    case ParamType::Color: t = AttrType::Color; break;
    default: return {};
  }
  std::string name = d.name == "Cs" ? "Ci" : d.name == "Os" ? "Oi" : d.name;
  std::vector<OutAttr> out;
  if (d.arraySize == 1) {
    out.push_back({name, t, 0});
  } else {
    for (int i = 0; i < d.arraySize; ++i) out.push_back({cat(name, "[", i, "]"), t, i});
  }
  return out;
}

namespace {

// ---------------------------------------------------------------------------------------------
// Polygon splitting

using Vec2 = glm::dvec2;

double cross2(Vec2 o, Vec2 a, Vec2 b) { return (a.x - o.x) * (b.y - o.y) - (a.y - o.y) * (b.x - o.x); }

/// Projects a polygon onto the plane that keeps most of its area.
std::vector<Vec2> project(const std::vector<glm::dvec3>& p) {
  glm::dvec3 n(0);
  for (size_t i = 0; i < p.size(); ++i) {  // Newell's normal
    const auto& a = p[i];
    const auto& b = p[(i + 1) % p.size()];
    n.x += (a.y - b.y) * (a.z + b.z), n.y += (a.z - b.z) * (a.x + b.x), n.z += (a.x - b.x) * (a.y + b.y);
  }
  int drop = std::fabs(n.x) >= std::fabs(n.y) && std::fabs(n.x) >= std::fabs(n.z) ? 0 : std::fabs(n.y) >= std::fabs(n.z) ? 1 : 2;
  std::vector<Vec2> q;
  for (const auto& v : p) q.push_back(drop == 0 ? Vec2{v.y, v.z} : drop == 1 ? Vec2{v.z, v.x} : Vec2{v.x, v.y});
  return q;
}

/// Convex and simple: every turn the same way (collinear corners allowed), turning once around.
bool convex(const std::vector<Vec2>& q) {
  const size_t n = q.size();
  int sign = 0;
  double turning = 0;
  for (size_t i = 0; i < n; ++i) {
    Vec2 a = q[i], b = q[(i + 1) % n], c = q[(i + 2) % n];
    double cr = cross2(a, b, c);
    int s = cr > 0 ? 1 : cr < 0 ? -1 : 0;
    if (s && sign && s != sign) return false;
    if (s) sign = s;
    double a1 = std::atan2(b.y - a.y, b.x - a.x), a2 = std::atan2(c.y - b.y, c.x - b.x);
    double d = a2 - a1;
    while (d > M_PI) d -= 2 * M_PI;
    while (d < -M_PI) d += 2 * M_PI;
    turning += d;
  }
  return sign != 0 && std::fabs(std::fabs(turning) - 2 * M_PI) < 1e-6;
}

bool segmentsCross(Vec2 a, Vec2 b, Vec2 c, Vec2 d) {
  double d1 = cross2(a, b, c), d2 = cross2(a, b, d), d3 = cross2(c, d, a), d4 = cross2(c, d, b);
  return ((d1 > 0 && d2 < 0) || (d1 < 0 && d2 > 0)) && ((d3 > 0 && d4 < 0) || (d3 < 0 && d4 > 0));
}

/// No two non-adjacent edges cross (ear clipping would make garbage of a polygon that does).
bool simple(const std::vector<Vec2>& q) {
  const size_t n = q.size();
  for (size_t i = 0; i < n; ++i)
    for (size_t j = i + 2; j < n; ++j) {
      if (i == 0 && j == n - 1) continue;
      if (segmentsCross(q[i], q[(i + 1) % n], q[j], q[(j + 1) % n])) return false;
    }
  return true;
}

// ---------------------------------------------------------------------------------------------
// Reading a polygon request

/// A count or index argument: a non-negative integer that fits 32 bits.
uint32_t countArg(const Args& a, double v, const char* what) {
  if (!(v >= 0) || v > 4294967295.0 || v != std::trunc(v)) a.fail(cat(what, " must be non-negative integers (found ", v, ")"));
  return uint32_t(v);
}

/// The request's loop and vertex counts and, where it gives them, the vertex indices (into p.verts).
PolygonCounts readCounts(const Args& a, Prim& p) {
  PolygonCounts c;
  if (p.request == "Polygon") {
    c.firstParam = 0;
  } else if (p.request == "GeneralPolygon") {
    for (double v : a.numbers(0)) c.nverts.push_back(countArg(a, v, "loop vertex counts"));
    c.loops.push_back(uint32_t(c.nverts.size()));
    c.firstParam = 1;
  } else if (p.request == "PointsPolygons") {
    for (double v : a.numbers(0)) c.nverts.push_back(countArg(a, v, "vertex counts")), c.loops.push_back(1);
    for (double v : a.numbers(1)) p.verts.push_back(countArg(a, v, "vertex indices"));
    c.explicitVerts = true;
    c.firstParam = 2;
  } else {  // PointsGeneralPolygons
    for (double v : a.numbers(0)) c.loops.push_back(countArg(a, v, "loop counts"));
    for (double v : a.numbers(1)) c.nverts.push_back(countArg(a, v, "loop vertex counts"));
    for (double v : a.numbers(2)) p.verts.push_back(countArg(a, v, "vertex indices"));
    c.explicitVerts = true;
    c.firstParam = 3;
  }
  return c;
}

std::vector<double> numbersOf(const rib::Param& q) { return q.value->isNumber() ? std::vector<double>{q.value->number} : q.value->numbers; }

/// The parameter named `name` (the last, if given twice); null when absent.
const rib::Param* findParam(const std::vector<rib::Param>& params, const char* name) {
  const rib::Param* found = nullptr;
  for (const auto& q : params)
    if (q.decl.name == name) found = &q;
  return found;
}

/// Object-space positions from "P" or, failing that, "Pw" (divided by w).
std::vector<float> readPositions(const Args& a, const std::vector<rib::Param>& params) {
  const rib::Param* P = findParam(params, "P");
  const rib::Param* Pw = findParam(params, "Pw");
  if (!P && !Pw) a.fail("needs positions \"P\"");
  std::vector<float> pos;
  if (P) {
    if (P->decl.type != ParamType::Point) a.fail("\"P\" must be declared as a point");
    for (double v : numbersOf(*P)) pos.push_back(float(v));
  } else {
    if (Pw->decl.type != ParamType::HPoint) a.fail("\"Pw\" must be declared as an hpoint");
    auto v = numbersOf(*Pw);
    for (size_t i = 0; i + 3 < v.size(); i += 4) {
      if (v[i + 3] == 0) a.fail(cat("\"Pw\" vertex ", i / 4, " has w = 0"));
      for (int c = 0; c < 3; ++c) pos.push_back(float(v[i + size_t(c)] / v[i + 3]));
    }
  }
  return pos;
}

/// Faces (p.faceStart, p.faceCount) from the counts, every index checked against p.nP; the
/// implicit vertex list of Polygon and GeneralPolygon. A face with holes spans all its loops.
void buildFaces(const Args& a, PolygonCounts& c, Prim& p) {
  if (!c.explicitVerts) {
    if (p.request == "Polygon") c.nverts = {p.nP}, c.loops = {1};
    uint32_t total = 0;
    for (uint32_t n : c.nverts) total += n;
    if (total != p.nP) a.fail(cat("loops name ", total, " vertices but \"P\" has ", p.nP));
    for (uint32_t i = 0; i < p.nP; ++i) p.verts.push_back(i);
  }
  size_t loop = 0, corner = 0;
  bool holes = false;
  for (size_t f = 0; f < c.loops.size(); ++f) {
    if (c.loops[f] < 1) a.fail(cat("polygon ", f, " has no loop"));
    holes = holes || c.loops[f] > 1;
    p.faceLoops.push_back(uint32_t(p.loopSizes.size()));
    uint32_t n = 0;
    for (uint32_t l = 0; l < c.loops[f]; ++l) {
      if (loop >= c.nverts.size()) a.fail(cat("loop counts name more loops than the ", c.nverts.size(), " vertex counts"));
      const uint32_t m = c.nverts[loop++];
      if (m < 3) a.fail(cat("polygon ", f, " has a loop of ", m, " vertices (at least 3)"));
      p.loopSizes.push_back(m);
      n += m;
    }
    if (corner + n > p.verts.size()) a.fail(cat("vertex counts need ", corner + n, " indices, there are ", p.verts.size()));
    p.faceStart.push_back(uint32_t(corner));
    p.faceCount.push_back(n);
    corner += n;
  }
  if (holes) {
    p.faceLoops.push_back(uint32_t(p.loopSizes.size()));
  } else {
    p.faceLoops.clear(), p.loopSizes.clear();
  }
  if (loop != c.nverts.size()) a.fail(cat(c.nverts.size(), " vertex counts but ", loop, " loops"));
  if (corner != p.verts.size()) a.fail(cat("vertex counts sum to ", corner, " but there are ", p.verts.size(), " indices"));
  for (uint32_t v : p.verts)
    if (v >= p.nP) a.fail(cat("vertex index ", v, " but \"P\" has ", p.nP, " vertices"));
}

/// "blurP": P at shutter close, the second of the primitive's two copies.
void readBlurP(const Args& a, const rib::Param& blurP, bool inMotion, double open, double close, Prim& p) {
  if (inMotion) a.fail("\"blurP\" inside a motion block (give either blurP or motion copies)");
  if (blurP.decl.type != ParamType::Point) a.fail("\"blurP\" must be declared as a point");
  auto v = numbersOf(blurP);
  if (v.size() != size_t(p.nP) * 3) a.fail(cat("\"blurP\" has ", v.size() / 3, " points, \"P\" has ", p.nP));
  std::vector<float> b(v.size());
  for (size_t i = 0; i < v.size(); ++i) b[i] = float(v[i]);
  p.P.push_back(std::move(b));
  p.times = {open, close};
}

}  // namespace

// ---------------------------------------------------------------------------------------------

/// A polygon request outside a motion block is a primitive; inside, the first copy is the
/// primitive and later copies add their positions (same topology; appearance of the first).
bool DumpHandler::polygons(const Request& r, const Args& a) {
  if (!inMotion_) {
    Prim p;
    readPolygons(r, a, p, true);
    if (emit_) emitPrim(p);
    return true;
  }
  const size_t k = motionCount_++;
  if (k >= motionTimes_.size()) a.fail(cat("more copies than the ", motionTimes_.size(), " motion knots"));
  if (k == 0) {
    readPolygons(r, a, prim_, true);
    return true;
  }
  Prim copy;
  readPolygons(r, a, copy, false);
  if (copy.verts != prim_.verts || copy.faceCount != prim_.faceCount || copy.nP != prim_.nP)
    a.fail(cat("motion copy ", k + 1, " has a different topology from the first"));
  // Appearance per knot: colour and opacity per copy (shading in time, as the RenderMan
  // motion-blur reference allows); of the other variables the first copy's are kept.
  bool differs = copy.vars.size() != prim_.vars.size();
  for (size_t i = 0; !differs && i < copy.vars.size(); ++i) {
    const Var& first = prim_.vars[i];
    if (copy.vars[i].decl.name != first.decl.name || copy.vars[i].values.size() != first.values.size()) differs = true;
    else if (copy.vars[i].values == first.values) continue;
    else if (first.decl.name == "Cs" || first.decl.name == "Os") {
      auto& knots = first.decl.name == "Cs" ? prim_.knotCs : prim_.knotOs;
      if (knots.empty()) knots.assign(k, first.values);  // the copies so far were the first's
      knots.resize(k);
    } else differs = true;
  }
  for (auto* knots : {&prim_.knotCs, &prim_.knotOs})
    if (!knots->empty()) {
      const std::string name = knots == &prim_.knotCs ? "Cs" : "Os";
      const auto v = std::find_if(copy.vars.begin(), copy.vars.end(), [&](const Var& x) { return x.decl.name == name; });
      knots->resize(k);
      knots->push_back(v != copy.vars.end() ? v->values : knots->front());
    }
  if (differs && collect_)
    warnOnce("ingest-appearance-knots",
             cat(r.where.str(), " (", r.name, "): variables other than P, Cs and Os change between motion copies; ingest keeps the first knot's"));
  prim_.P.push_back(std::move(copy.P[0]));
  return true;
}

/// Reads one request into `p`; for a primitive's `first` copy also splits its faces and enters
/// its variables in the schema.
void DumpHandler::readPolygons(const Request& r, const Args& a, Prim& p, bool first) {
  p.request = std::string(r.name);
  PolygonCounts counts = readCounts(a, p);
  const std::vector<rib::Param> params = a.params(counts.firstParam);
  std::vector<float> pos = readPositions(a, params);
  p.nP = uint32_t(pos.size() / 3);
  if (p.nP == 0) a.fail("has no vertices");
  buildFaces(a, counts, p);
  p.P.push_back(std::move(pos));
  if (const rib::Param* blurP = findParam(params, "blurP")) readBlurP(a, *blurP, inMotion_, scene_.options().shutterOpen, scene_.options().shutterClose, p);
  readVariables(r, a, params, p);
  if (!first) return;
  split(a, p);
  registerVars(a, p);
  if (stats_) {
    ++stats_->primitives;
    stats_->polygons += p.faceStart.size();
  }
}

/// Every variable but the positions, its value count checked against its storage class; those
/// of a type a store cannot hold are skipped with a warning.
void DumpHandler::readVariables(const Request& r, const Args& a, const std::vector<rib::Param>& params, Prim& p) {
  const size_t nFaces = p.faceStart.size(), nCorners = p.verts.size();
  for (const auto& q : params) {
    const std::string& name = q.decl.name;
    if (name == "P" || name == "Pw" || name == "blurP") continue;
    const size_t per = size_t(q.decl.components()) * size_t(q.decl.arraySize);
    const size_t have = q.value->size() / std::max<size_t>(per, 1);
    size_t want = 0;
    switch (q.decl.storage) {
      case StorageClass::Constant: want = 1; break;
      case StorageClass::Uniform: want = nFaces; break;
      case StorageClass::Varying:
      case StorageClass::Vertex: want = p.nP; break;
      case StorageClass::FaceVarying:
      case StorageClass::FaceVertex: want = nCorners; break;
    }
    if (have != want) a.fail(cat("\"", name, "\" has ", have, " values; a ", p.request, " with ", nFaces, " faces and ", p.nP, " vertices needs ", want));
    if (outputsFor(q.decl).empty()) {
      if (collect_) warnOnce(cat("ingest-skip:", name), cat(r.where.str(), " (", r.name, "): variable \"", name, "\" of this type is not stored"));
      continue;
    }
    Var v;
    v.decl = q.decl;
    for (double x : numbersOf(q)) v.values.push_back(float(x));
    p.vars.push_back(std::move(v));
  }
}

/// Faces into micropolygons (p.mpCorners, p.mpFace): triangles and quads as given, convex
/// polygons fanned into quads, the others ear-clipped into triangles.
void DumpHandler::split(const Args& a, Prim& p) {
  const Attrs& s = cur();
  // Ring order: front-facing in camera space for the orientation in force (see ingest.h).
  const bool reverse = s.reverse;
  auto add = [&](uint32_t f, std::initializer_list<uint32_t> fc) {
    uint32_t c[4] = {kNoCorner, kNoCorner, kNoCorner, kNoCorner};
    size_t i = 0;
    for (uint32_t x : fc) c[i++] = x;
    if (reverse) {
      if (i == 4) std::swap(c[1], c[3]);
      else std::swap(c[1], c[2]);
    }
    p.mpCorners.insert(p.mpCorners.end(), c, c + 4);
    p.mpFace.push_back(f);
    if (stats_) ++(i == 4 ? stats_->quads : stats_->triangles);
  };
  std::vector<glm::dvec3> ring;
  for (uint32_t f = 0; f < p.faceStart.size(); ++f) {
    const uint32_t b = p.faceStart[f], n = p.faceCount[f];
    if (!p.faceLoops.empty() && p.faceLoops[f + 1] - p.faceLoops[f] > 1) {
      // Loops one after another from b: the outline, then the holes.
      ring.clear();
      for (uint32_t i = 0; i < n; ++i) {
        const float* v = &p.P[0][size_t(p.verts[b + i]) * 3];
        ring.push_back({v[0], v[1], v[2]});
      }
      std::vector<std::vector<int>> loops;
      int at = 0;
      for (uint32_t l = p.faceLoops[f]; l < p.faceLoops[f + 1]; ++l) {
        std::vector<int>& loop = loops.emplace_back();
        for (uint32_t i = 0; i < p.loopSizes[l]; ++i) loop.push_back(at++);
      }
      std::vector<std::array<int, 3>> tris;
      if (n > 4096) a.fail(cat("polygon ", f, " has holes and ", n, " vertices; ingest triangulates up to 4096"));
      if (!triangulateLoops(ring, loops, tris))
        a.fail(cat("polygon ", f, " with holes cannot be triangulated (crossing edges, or a hole outside its outline)"));
      for (auto& t : tris) add(f, {b + uint32_t(t[0]), b + uint32_t(t[1]), b + uint32_t(t[2])});
      if (stats_) ++stats_->earClippedPolygons;
      continue;
    }
    if (n == 3) {
      add(f, {b, b + 1, b + 2});
      continue;
    }
    if (n == 4) {
      add(f, {b, b + 1, b + 2, b + 3});
      continue;
    }
    ring.clear();
    for (uint32_t i = 0; i < n; ++i) {
      const float* v = &p.P[0][size_t(p.verts[b + i]) * 3];
      ring.push_back({v[0], v[1], v[2]});
    }
    auto q = project(ring);
    if (convex(q)) {
      uint32_t i = 1;
      for (; i + 2 < n; i += 2) add(f, {b, b + i, b + i + 1, b + i + 2});
      if (i + 1 < n) add(f, {b, b + i, b + i + 1});
      if (stats_) ++stats_->fannedPolygons;
    } else {
      std::vector<std::array<int, 3>> tris;
      // Ear clipping is cubic in the worst case; dumps hold grids of small polygons.
      if (n > 4096) a.fail(cat("polygon ", f, " is not convex and has ", n, " vertices; ingest triangulates up to 4096"));
      std::vector<int> loop(q.size());
      for (size_t i = 0; i < q.size(); ++i) loop[i] = int(i);
      if (!simple(q) || !earClipLoop(q, loop, tris))
        a.fail(cat("polygon ", f, " (", n, " vertices) is self-intersecting or degenerate; ingest cannot triangulate it"));
      for (auto& t : tris) add(f, {b + uint32_t(t[0]), b + uint32_t(t[1]), b + uint32_t(t[2])});
      if (stats_) ++stats_->earClippedPolygons;
    }
  }
}

/// Enters the primitive's variables in the schema (scan and optimistic passes); opens the sink
/// at the first primitive of an optimistic pass, or gives up on it if the schema grew; decides
/// whether the grid needs a vertex per face corner.
void DumpHandler::registerVars(const Args& a, Prim& p) {
  const bool grew = collect_ && collectSchema(a, p);
  if (!emit_) return;
  if (optimistic_) {
    if (!sink_) {
      ownMeta_ = scannedMeta(file_);
      meta_ = &ownMeta_;
      sink_ = openSink(ownMeta_);
    } else if (grew) {
      throw SchemaGrew{};
    }
  }
  p.unshare = needsVertexPerCorner(p);
}

/// Adds the primitive's variables (and Ci, Oi) to the schema; true when that added an attribute
/// or made one per vertex.
bool DumpHandler::collectSchema(const Args& a, const Prim& p) {
  bool grew = false;
  for (const auto& v : p.vars) {
    for (const auto& o : outputsFor(v.decl)) {
      const bool perVertex = perVertexClass(v.decl.storage);
      auto it = schema_.find(o.name);
      if (it == schema_.end()) {
        schema_.emplace(o.name, SchemaEntry{o.type, perVertex});
        schemaOrder_.push_back(o.name);
        grew = true;
      } else {
        if (it->second.type != o.type) a.fail(cat("\"", v.decl.name, "\" is a ", toString(o.type), " here and a ", toString(it->second.type), " elsewhere"));
        grew |= perVertex && !it->second.perVertex;
        it->second.perVertex |= perVertex;
      }
    }
  }
  // Ci/Oi from Color/Opacity are constant: per micropolygon unless a primitive gives them per vertex.
  for (const char* n : {"Ci", "Oi"})
    if (!schema_.count(n)) {
      schema_.emplace(n, SchemaEntry{AttrType::Color, false});
      schemaOrder_.push_back(n);
      grew = true;
    }
  return grew;
}

/// Per-vertex storage of per-face values needs a vertex per face corner.
bool DumpHandler::needsVertexPerCorner(const Prim& p) const {
  bool unshare = false;
  for (const auto& v : p.vars) {
    if (faceVaryingClass(v.decl.storage)) unshare = true;
    if (v.decl.storage == StorageClass::Uniform)
      for (const auto& o : outputsFor(v.decl)) {
        int i = meta_->schema.find(o.name);
        unshare = unshare || (i >= 0 && meta_->schema.attrs[size_t(i)].rate == AttrRate::Vertex);
      }
  }
  return unshare;
}

}  // namespace reshutter::shade::ingest
