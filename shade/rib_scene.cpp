// RIB requests → Scene builder calls (the subset and its policy are in rib_scene.h).
#include "shade/rib_scene.h"

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <optional>

#include <glm/gtc/type_ptr.hpp>

#include "common/error.h"
#include "common/log.h"
#include "shade/rib_state.h"
#include "store/view_bounds.h"

namespace reshutter::shade {

namespace {

using rib::Args;
using rib::Param;
using rib::ParamType;
using rib::StorageClass;
using rib::Value;

ParamMap numericParams(const std::vector<Param>& params) {
  ParamMap m;
  for (const Param& p : params) {
    if (!p.value) continue;
    if (p.value->kind == Value::Kind::Number) m[p.decl.name] = {p.value->number};
    else if (p.value->kind == Value::Kind::NumberArray) m[p.decl.name] = p.value->numbers;
  }
  return m;
}

/// String parameters by bare name (the first string of an array).
std::map<std::string, std::string> stringParams(const std::vector<Param>& params) {
  std::map<std::string, std::string> m;
  for (const Param& p : params)
    if (p.value && !p.decl.reference && p.value->kind == Value::Kind::String) m[p.decl.name] = p.value->string;
    else if (p.value && !p.decl.reference && p.value->kind == Value::Kind::StringArray && !p.value->strings.empty()) m[p.decl.name] = p.value->strings.front();
  return m;
}

const std::vector<double>* numbersOf(const Param& p) {
  if (!p.value || p.value->kind != Value::Kind::NumberArray) return nullptr;
  return &p.value->numbers;
}

// A point-like parameter as dvec3s ("P", "N", "Cs", "Os"; "Pw" divides by w).
std::vector<glm::dvec3> triples(const Args& args, const Param& p) {
  const auto* v = numbersOf(p);
  std::vector<glm::dvec3> out;
  if (!v) {
    if (p.value && p.value->kind == Value::Kind::Number && p.decl.components() == 1) return out;
    args.fail(cat("parameter '", p.decl.name, "' must be an array of numbers"));
  }
  const int n = p.decl.type == ParamType::HPoint ? 4 : 3;
  if (v->size() % size_t(n)) args.fail(cat("parameter '", p.decl.name, "' has ", v->size(), " numbers, not a multiple of ", n));
  for (size_t i = 0; i + size_t(n) <= v->size(); i += size_t(n)) {
    glm::dvec3 q((*v)[i], (*v)[i + 1], (*v)[i + 2]);
    if (n == 4) {
      const double w = (*v)[i + 3];
      if (w == 0) args.fail(cat("parameter '", p.decl.name, "' has w = 0"));
      q /= w;
    }
    out.push_back(q);
  }
  return out;
}

struct Geometry {
  std::vector<glm::dvec3> P;
  Scene::VertexData vd;
};

/// The vertex data of a primitive's parameter list. `heightField` (columns, rows, periodic u and
/// v) is given for patches and patch meshes, where "Pz" makes points (x, y) on the mesh's
/// parametric grid (RenderMan: a height field over the patch's parameters).
struct HeightField {
  int nu = 0, nv = 0;
  bool uPeriodic = false, vPeriodic = false;
};

Geometry geometry(const Args& args, size_t first, std::initializer_list<std::string_view> own = {}, const HeightField& heightField = {}) {
  Geometry g;
  std::vector<double> s, t;
  for (const Param& p : args.params(first)) {
    const std::string& n = p.decl.name;
    if (std::find(own.begin(), own.end(), n) != own.end()) continue;  // the request reads it itself
    if (n == "P" || n == "Pw") g.P = triples(args, p);
    else if (n == "N") g.vd.N = triples(args, p);
    else if (n == "Cs") g.vd.Cs = triples(args, p);
    else if (n == "Os") g.vd.Os = triples(args, p);
    else if (n == "st" && numbersOf(p)) {
      const auto& v = *numbersOf(p);
      for (size_t i = 0; i + 1 < v.size(); i += 2) g.vd.st.emplace_back(v[i], v[i + 1]);
    } else if (n == "s" && numbersOf(p)) s = *numbersOf(p);
    else if (n == "t" && numbersOf(p)) t = *numbersOf(p);
    else if (n == "Pz") {
      const HeightField& h = heightField;
      if (!h.nu) args.fail("\"Pz\" height fields are given for patches and patch meshes only");
      const auto* z = numbersOf(p);
      if (!z || z->size() != size_t(h.nu) * size_t(h.nv)) args.fail(cat("\"Pz\" needs ", size_t(h.nu) * size_t(h.nv), " numbers, has ", z ? z->size() : 1));
      const double du = h.uPeriodic || h.nu == 1 ? h.nu : h.nu - 1, dv = h.vPeriodic || h.nv == 1 ? h.nv : h.nv - 1;
      g.P.clear();
      for (int j = 0; j < h.nv; ++j)
        for (int i = 0; i < h.nu; ++i) g.P.emplace_back(i / du, j / dv, (*z)[size_t(j) * size_t(h.nu) + size_t(i)]);
    } else warnOnce(cat("rib-primvar:", n), cat("primitive variable '", n, "' is not used by the built-in shaders; ignored"));
  }
  if (g.vd.st.empty() && !s.empty() && s.size() == t.size())
    for (size_t i = 0; i < s.size(); ++i) g.vd.st.emplace_back(s[i], t[i]);
  if (g.P.empty() && std::find(own.begin(), own.end(), "P") == own.end()) args.fail("primitive has no \"P\"");
  return g;
}

std::string handleArg(const rib::Request& r, size_t i) {
  if (i >= r.values.size()) return {};
  const Value& v = r.values[i];
  if (v.kind == Value::Kind::String) return v.string;
  if (v.kind == Value::Kind::Number) return cat(v.number);
  if (v.kind == Value::Kind::NumberArray && v.numbers.size() == 1) return cat(v.numbers[0]);
  if (v.kind == Value::Kind::StringArray && v.strings.size() == 1) return v.strings[0];
  return {};
}

RisNode risNode(const rib::Request& r, const Args& a, size_t first) {
  RisNode node;
  node.request = std::string(r.name);
  node.type = a.string(0);
  if (first > 1) node.handle = handleArg(r, 1);
  const std::vector<Param> params = a.params(first);
  node.numbers = numericParams(params);
  for (const Param& p : params) {
    if (!p.value) continue;
    if (p.decl.reference) {
      const std::string ref = p.value->kind == Value::Kind::String ? p.value->string : p.value->strings.empty() ? "" : p.value->strings[0];
      if (!ref.empty()) node.references[p.decl.name] = ref;
    } else if (p.value->kind == Value::Kind::String) node.strings[p.decl.name] = {p.value->string};
    else if (p.value->kind == Value::Kind::StringArray) node.strings[p.decl.name] = p.value->strings;
  }
  return node;
}

/// A patch mesh's or curves' wrap mode: true for "periodic".
bool periodicArg(const Args& a, size_t i) {
  const std::string& w = a.string(i);
  if (w != "periodic" && w != "nonperiodic") a.fail(cat("wrap mode '", w, "' (periodic or nonperiodic)"));
  return w == "periodic";
}

/// SubdivisionMesh scheme nvertices vertices [tags nargs intargs floatargs] parameters...
void subdivisionMesh(Scene& s, const rib::Request& r, const Args& a) {
  const std::string& name = a.string(0);
  SubdivScheme scheme;
  if (name == "catmull-clark") scheme = SubdivScheme::CatmullClark;
  else if (name == "loop") scheme = SubdivScheme::Loop;
  else if (name == "bilinear") scheme = SubdivScheme::Bilinear;
  else a.fail(cat("subdivision scheme '", name, "' (catmull-clark, loop or bilinear)"));
  const auto nverts = intArray(a, 1, 0, 1 << 20);
  const auto verts = intArray(a, 2, 0, 2e9);
  SubdivTags tags;
  size_t first = 3;
  // The tag arrays are optional: a parameter name (a plain string) may follow the vertices.
  if (r.values.size() > 3 && r.values[3].kind != Value::Kind::String) {
    if (r.values.size() < 7) a.fail("expects tags, their argument counts, integer and float arguments");
    std::vector<std::string> names;
    if (r.values[3].kind == Value::Kind::StringArray) names = r.values[3].strings;
    else if (!a.numbers(3).empty()) a.fail("argument 4 must be the tag names");
    const auto nargs = intArray(a, 4, 0, 1 << 24);
    const auto ints = intArray(a, 5);
    const auto& floats = a.numbers(6);
    if (nargs.size() != 2 * names.size()) a.fail(cat(names.size(), " tags need ", 2 * names.size(), " argument counts, have ", nargs.size()));
    size_t ii = 0, fi = 0;
    for (size_t t = 0; t < names.size(); ++t) {
      const size_t ni = size_t(nargs[2 * t]), nf = size_t(nargs[2 * t + 1]);
      if (ii + ni > ints.size() || fi + nf > floats.size()) a.fail(cat("tag '", names[t], "' needs more arguments than given"));
      const std::vector<int> iv(ints.begin() + std::ptrdiff_t(ii), ints.begin() + std::ptrdiff_t(ii + ni));
      const std::vector<double> fv(floats.begin() + std::ptrdiff_t(fi), floats.begin() + std::ptrdiff_t(fi + nf));
      ii += ni, fi += nf;
      const std::string& tag = names[t];
      if (tag == "crease") {
        if (iv.size() < 2 || fv.empty()) a.fail("a crease needs at least two vertices and a sharpness");
        tags.creases.emplace_back(iv, fv[0]);
      } else if (tag == "corner") {
        if (fv.empty()) a.fail("a corner needs a sharpness");
        for (size_t k = 0; k < iv.size(); ++k) tags.corners.emplace_back(iv[k], fv[std::min(k, fv.size() - 1)]);
      } else if (tag == "hole") {
        tags.holes.insert(tags.holes.end(), iv.begin(), iv.end());
      } else if (tag == "interpolateboundary") {
        tags.interpolateBoundary = iv.empty() ? 1 : iv[0];
        if (tags.interpolateBoundary < 0 || tags.interpolateBoundary > 2) a.fail(cat("interpolateboundary ", tags.interpolateBoundary, " (0, 1 or 2)"));
      } else if (tag == "facevaryinginterpolateboundary" || tag == "facevaryingpropagatecorners" || tag == "creasemethod") {
        // Face-varying data is interpolated linearly here; Chaikin creases are OpenSubdiv's default.
      } else {
        warnOnce(cat("subdiv-tag:", tag), cat(s.where, ": subdivision tag '", tag, "' is not supported; ignored"));
      }
    }
    first = 7;
  }
  Geometry g = geometry(a, first);
  s.subdivisionMesh(scheme, nverts, verts, tags, g.P, g.vd);
}

/// The RenderMan Interface's geometric primitives: a frame counts those it could not make.
bool isPrimitiveRequest(std::string_view n) {
  static const char* const kinds[] = {"Polygon",
                                      "GeneralPolygon",
                                      "PointsPolygons",
                                      "PointsGeneralPolygons",
                                      "Patch",
                                      "PatchMesh",
                                      "NuPatch",
                                      "SubdivisionMesh",
                                      "HierarchicalSubdivisionMesh",
                                      "Sphere",
                                      "Cone",
                                      "Cylinder",
                                      "Hyperboloid",
                                      "Paraboloid",
                                      "Disk",
                                      "Torus",
                                      "Points",
                                      "Curves",
                                      "Blobby",
                                      "Procedural",
                                      "Geometry",
                                      "ObjectInstance",
                                      "Volume"};
  return std::find(std::begin(kinds), std::end(kinds), n) != std::end(kinds);
}

}  // namespace

bool RibSceneHandler::handle(const rib::Request& r, const Args& a) {
  Scene& s = scene_;
  const std::string_view n = r.name;

  if (applyStateRequest(s, r, a)) return true;

  // Options and attributes of the shading pass
  if (n == "PixelSamples") {
    // RtFloats; the shading pass only needs a rough rate, so they are rounded and bounded.
    auto count = [&](size_t i) { return int(std::clamp(std::isfinite(a.number(i)) ? std::round(a.number(i)) : 1.0, 1.0, 4096.0)); };
    return s.pixelSamples(count(0), count(1)), true;
  }
  if (n == "PixelFilter") return true;  // a re-sampling choice: `reshutter resample --filter`
  if (n == "ShadingRate") return s.shadingRate(a.number(0)), true;
  if (n == "Display") {
    if (a.count() >= 3) s.display(a.string(0), a.string(2));
    return true;
  }
  if (n == "DisplayChannel") return true;  // declarations only; Display's mode selects variables
  if (n == "Surface") {
    const std::vector<Param> params = a.params(1);
    return s.surface(a.string(0), numericParams(params), stringParams(params)), true;
  }
  if (n == "LightSource") {
    // The handle is a number (RI 3.2) or a string (3.3+); the parameter list follows it.
    const std::vector<Param> params = a.params(2);
    return s.lightSource(a.string(0), handleArg(r, 1), numericParams(params), stringParams(params)), true;
  }
  if (n == "Illuminate") return s.illuminate(handleArg(r, 0), a.number(1) != 0), true;
  if (n == "GeometricApproximation") {
    const std::string& type = a.string(0);
    if (type == "motionfactor") return s.motionFactor(a.number(1)), true;
    warnOnce(cat("geomapprox:", type), cat(s.where, ": GeometricApproximation '", type, "' is not supported; ignored"));
    return true;
  }
  if (n == "Attribute") {
    const std::string& cls = a.string(0);
    if (cls == "identifier") {
      for (const Param& p : a.params(1))
        if (p.decl.name == "name" && p.value) {
          if (p.value->kind == Value::Kind::String) s.identifier(p.value->string);
          else if (p.value->kind == Value::Kind::StringArray && !p.value->strings.empty()) s.identifier(p.value->strings[0]);
        }
      return true;
    }
    if (cls == "visibility" || cls == "light") {
      // "visibility" "transmission": 0/1 (RenderMan 21+) or "opaque"/"Os"/"shader"/"transparent"
      // (earlier); "light" "shadows" "on" (BMRT, PRMan's ray-traced shadows for lights below).
      for (const Param& p : a.params(1)) {
        if (!p.value) continue;
        const bool isString = p.value->kind == Value::Kind::String || p.value->kind == Value::Kind::StringArray;
        const std::string str = p.value->kind == Value::Kind::String ? p.value->string : isString && !p.value->strings.empty() ? p.value->strings[0] : "";
        bool on;
        if (isString) on = !str.empty() && str != "transparent" && str != "off";
        else on = p.value->kind == Value::Kind::Number ? p.value->number != 0 : !p.value->numbers.empty() && p.value->numbers[0] != 0;
        if (cls == "visibility" && p.decl.name == "transmission") s.transmission(on);
        if (cls == "light" && p.decl.name == "shadows") s.lightShadows(on);
      }
      return true;
    }
    if (cls == "trimcurve") {
      for (const Param& p : a.params(1))
        if (p.decl.name == "sense" && p.value) {
          const std::string sense = p.value->kind == Value::Kind::StringArray && !p.value->strings.empty() ? p.value->strings[0] : p.value->string;
          if (sense != "inside" && sense != "outside") a.fail(cat("trimcurve sense '", sense, "' (inside or outside)"));
          s.trimSense(sense == "outside");
        }
      return true;
    }
    warnOnce(cat("attribute:", cls), cat(s.where, ": Attribute \"", cls, "\" has no effect on the shading pass; ignored"));
    return true;
  }
  if (n == "Bxdf" || n == "Light" || n == "Pattern" || n == "Integrator" || n == "DisplayFilter" || n == "SampleFilter" || n == "Hider") {
    // RIS requests are kept for the shading pass, never a reason to stop (Hider: the
    // re-sampler is the hider; its type and settings are kept with the options).
    const size_t first = n == "Hider" ? 1 : 2;
    // Bxdf and Light map onto the built-in shaders and lights (shade/ris.h), which warn for
    // types they do not know; a Pattern is read where a Bxdf connects to it.
    s.ris(risNode(r, a, first));
    return true;
  }
  if (n == "Option") {
    // Renderer settings: the texture search path is used; limits and the rest are a renderer's,
    // "user" options are the reader's conditions.
    if (a.string(0) == "searchpath")
      for (const Param& p : a.params(1))
        if (p.decl.name == "texture" && p.value) {
          if (p.value->kind == Value::Kind::String) s.textureSearchPath(p.value->string);
          else if (p.value->kind == Value::Kind::StringArray && !p.value->strings.empty()) s.textureSearchPath(p.value->strings.front());
        }
    return true;
  }
  if (n == "ShadingInterpolation") return true;  // grids are shaded per vertex and interpolated ("smooth")
  if (n == "SolidBegin" || n == "SolidEnd") {
    warnOnce("rib-csg", cat(s.where, ": solid modelling (CSG) is not supported; the solids' primitives are shaded as a union"));
    return true;
  }

  // Primitives
  if (n == "Volume" && a.count() >= 1 && a.string(0) == "blobbydso:impl_openvdb") {
    // Volume "blobbydso:impl_openvdb" [bounds] [nx ny nz] "constant string[2] blobbydso:stringargs"
    // ["file.vdb" "density"]: the bounds and voxel counts are the file's own business.
    std::string file, grid = "density";
    for (const Param& p : a.params(3))
      if (p.decl.name == "blobbydso:stringargs" && p.value && p.value->kind == Value::Kind::StringArray) {
        if (!p.value->strings.empty()) file = p.value->strings[0];
        if (p.value->strings.size() > 1 && !p.value->strings[1].empty()) grid = p.value->strings[1];
      }
    if (file.empty()) a.fail("an OpenVDB Volume needs \"blobbydso:stringargs\" [\"file.vdb\" \"grid\"]");
    return s.volume(file, grid), true;
  }
  if (n == "Sphere") return s.sphere(a.number(0), a.number(1), a.number(2), a.number(3)), true;
  if (n == "Cylinder") return s.cylinder(a.number(0), a.number(1), a.number(2), a.number(3)), true;
  if (n == "Cone") return s.cone(a.number(0), a.number(1), a.number(2)), true;
  if (n == "Disk") return s.disk(a.number(0), a.number(1), a.number(2)), true;
  if (n == "Hyperboloid") {
    if (a.count() == 7) return s.hyperboloid({a.number(0), a.number(1), a.number(2)}, {a.number(3), a.number(4), a.number(5)}, a.number(6)), true;
    const auto& p1 = a.numbers(0);
    const auto& p2 = a.numbers(1);
    if (p1.size() != 3 || p2.size() != 3) a.fail("expects two points and thetamax");
    return s.hyperboloid({p1[0], p1[1], p1[2]}, {p2[0], p2[1], p2[2]}, a.number(2)), true;
  }
  if (n == "Paraboloid") return s.paraboloid(a.number(0), a.number(1), a.number(2), a.number(3)), true;
  if (n == "Torus") return s.torus(a.number(0), a.number(1), a.number(2), a.number(3), a.number(4)), true;
  if (n == "Patch") {
    const std::string& type = a.string(0);
    if (type == "bicubic") {
      Geometry g = geometry(a, 1, {}, {4, 4});
      if (g.P.size() != 16) a.fail(cat("bicubic patch needs 16 points, has ", g.P.size()));
      return s.patchMesh(true, 4, false, 4, false, g.P, g.vd), true;
    }
    if (type != "bilinear") a.fail(cat("patch type '", type, "' (bilinear or bicubic)"));
    Geometry g = geometry(a, 1, {}, {2, 2});
    if (g.P.size() != 4) a.fail(cat("bilinear patch needs 4 points, has ", g.P.size()));
    return s.patch({g.P[0], g.P[1], g.P[2], g.P[3]}, g.vd), true;
  }
  if (n == "Basis") {
    auto basisAt = [&](size_t i) {
      CubicBasis b;
      if (i >= r.values.size()) a.fail("expects a u basis, a u step, a v basis and a v step");
      const Value& v = r.values[i];
      if (v.kind == Value::Kind::String || v.kind == Value::Kind::StringArray) {
        if (!CubicBasis::named(a.string(i), b)) a.fail(cat("unknown basis '", a.string(i), "' (bezier, b-spline, catmull-rom, hermite, power or 16 numbers)"));
      } else {
        const auto& m = a.numbers(i);
        if (m.size() != 16) a.fail(cat("a basis matrix has 16 numbers, not ", m.size()));
        std::copy(m.begin(), m.end(), b.m.begin());
      }
      b.step = int(integerArg(a, i + 1, 1, 64));
      return b;
    };
    return s.basis(basisAt(0), basisAt(2)), true;
  }
  if (n == "PatchMesh") {
    const std::string& type = a.string(0);
    if (type != "bilinear" && type != "bicubic") a.fail(cat("patch type '", type, "' (bilinear or bicubic)"));
    const int nu = int(integerArg(a, 1, 1, 1 << 24)), nv = int(integerArg(a, 3, 1, 1 << 24));
    const bool uPeriodic = periodicArg(a, 2), vPeriodic = periodicArg(a, 4);
    Geometry g = geometry(a, 5, {}, {nu, nv, uPeriodic, vPeriodic});
    return s.patchMesh(type == "bicubic", nu, uPeriodic, nv, vPeriodic, g.P, g.vd), true;
  }
  if (n == "ObjectBegin") return s.objectBegin(handleArg(r, 0)), true;
  if (n == "ObjectEnd") return s.objectEnd(), true;
  if (n == "ObjectInstance") return s.objectInstance(handleArg(r, 0)), true;
  if (n == "GeneralPolygon") {
    const auto nverts = intArray(a, 0, 0, 1 << 24);
    Geometry g = geometry(a, 1);
    std::vector<int> verts(g.P.size());
    for (size_t i = 0; i < verts.size(); ++i) verts[i] = int(i);
    return s.generalPolygons({int(nverts.size())}, nverts, verts, g.P, g.vd), true;
  }
  if (n == "PointsGeneralPolygons") {
    const auto nloops = intArray(a, 0, 1, 1 << 24);
    const auto nverts = intArray(a, 1, 0, 1 << 24);
    const auto verts = intArray(a, 2, 0, 2e9);
    Geometry g = geometry(a, 3);
    return s.generalPolygons(nloops, nverts, verts, g.P, g.vd), true;
  }
  if (n == "SubdivisionMesh") return subdivisionMesh(s, r, a), true;
  if (n == "NuPatch") {
    const int nu = int(integerArg(a, 0, 1, 1 << 20)), uorder = int(integerArg(a, 1, 1, 32));
    const int nv = int(integerArg(a, 5, 1, 1 << 20)), vorder = int(integerArg(a, 6, 1, 32));
    // The control points as given: "Pw" homogeneous, "P" with w = 1.
    std::vector<glm::dvec4> Pw;
    for (const Param& p : a.params(10)) {
      const auto* v = numbersOf(p);
      if (!v || (p.decl.name != "P" && p.decl.name != "Pw")) continue;
      const size_t c = p.decl.name == "Pw" ? 4 : 3;
      if (v->size() % c) a.fail(cat("\"", p.decl.name, "\" has ", v->size(), " numbers, not a multiple of ", c));
      Pw.clear();
      for (size_t i = 0; i + c <= v->size(); i += c) Pw.emplace_back((*v)[i], (*v)[i + 1], (*v)[i + 2], c == 4 ? (*v)[i + 3] : 1.0);
    }
    if (Pw.empty()) a.fail("NuPatch has no \"P\" or \"Pw\"");
    Geometry g = geometry(a, 10, {"P", "Pw"});
    return s.nuPatch(nu, uorder, a.numbers(2), a.number(3), a.number(4), nv, vorder, a.numbers(7), a.number(8), a.number(9), Pw, g.vd), true;
  }
  if (n == "Procedural" || n == "Procedural2") {
    // DelayedReadArchive never gets here (the reader reads it in place); programs and plug-ins
    // named by a scene file are never run.
    const std::string kind = r.values.empty() || !r.values[0].isString() ? std::string("?") : r.values[0].string;
    warnOnce(cat("procedural:", kind), cat(s.where, ": procedural '", kind, "' is not run from a scene file; skipped"));
    s.skippedPrimitive(n);
    return true;
  }
  if (n == "TrimCurve") {
    try {
      auto loops = std::make_shared<const TrimLoops>(intArray(a, 0, 0, 1 << 24), intArray(a, 1, 0, 1 << 24), a.numbers(2), a.numbers(3), a.numbers(4),
                                                     intArray(a, 5, 0, 1 << 24), a.numbers(6), a.numbers(7), a.numbers(8));
      return s.trimCurve(loops->loops().empty() ? nullptr : std::move(loops)), true;
    } catch (const Error& e) {
      a.fail(e.problem());
    }
  }
  if (n == "Curves" || n == "Points") {
    const bool curves = n == "Curves";
    size_t first = 0;
    bool cubic = false, periodic = false;
    std::vector<int> nvertices;
    if (curves) {
      const std::string& type = a.string(0);
      if (type != "linear" && type != "cubic") a.fail(cat("curve type '", type, "' (linear or cubic)"));
      cubic = type == "cubic";
      nvertices = intArray(a, 1, 1, 1 << 24);
      periodic = periodicArg(a, 2);
      first = 3;
    }
    // Widths and ribbon normals are the curves' own; the rest is the usual vertex data.
    std::vector<double> width{1.0};
    std::vector<glm::dvec3> N;
    for (const Param& p : a.params(first)) {
      if ((p.decl.name == "width" || p.decl.name == "constantwidth") && p.value) {
        if (p.value->kind == Value::Kind::Number) width = {p.value->number};
        else if (numbersOf(p)) width = *numbersOf(p);
      }
      if (p.decl.name == "N" && curves) N = triples(a, p);
    }
    // Curves read N themselves (it orients their ribbons); points have no use for it.
    Geometry g = curves ? geometry(a, first, {"width", "constantwidth", "N"}) : geometry(a, first, {"width", "constantwidth"});
    if (curves) return s.curves(cubic, nvertices, periodic, g.P, width, N, g.vd), true;
    return s.points(g.P, width, g.vd), true;
  }
  if (n == "Polygon") {
    Geometry g = geometry(a, 0);
    return s.polygon(g.P, g.vd), true;
  }
  if (n == "PointsPolygons") {
    const auto nverts = intArray(a, 0);
    const auto verts = intArray(a, 1);
    Geometry g = geometry(a, 2);
    return s.pointsPolygons(nverts, verts, g.P, g.vd), true;
  }
  if (isPrimitiveRequest(n)) s.skippedPrimitive(n);
  return false;
}

namespace {

// Whether camera `cam` cannot see the object-space box `b` under the transform `ctm` (object →
// `primary`'s camera space) at any of its knots, nor - when the camera moves against the primary -
// at any of its motion times.
bool boundOutOfView(const std::array<double, 6>& b, const MotionXform& ctm, const store::Camera& cam, const store::Camera& primary, double cullMargin) {
  const std::vector<double> moves = &cam == &primary ? std::vector<double>{} : store::carryTimes(primary, cam);
  const glm::dmat4 fixed = &cam == &primary ? glm::dmat4(1.0) : store::primaryToView(primary, cam);
  const store::Projector proj(cam);
  const bool perspective = cam.projection == store::Projection::Perspective;
  const double mx = cullMargin * cam.width, my = cullMargin * cam.height;
  // Per knot, where the box's eight corners lie; culled only where one reason holds at every
  // knot (between knots the box moves linearly, so it stays on that side).
  bool behind = true, beyond = true, left = true, right = true, above = true, below = true;
  std::vector<double> times = store::unionTimes(ctm.times, moves);
  if (times.empty()) times.push_back(0.0);
  for (double t : times) {
    const glm::dmat4 m = (moves.empty() ? fixed : store::primaryToView(primary, cam, t)) * ctm.at(t);
    bool allBehind = true, anyBehind = false, allBeyond = true;
    double box[4] = {1e300, -1e300, 1e300, -1e300}, zLo = 1e300, zHi = -1e300;
    for (int i = 0; i < 8; ++i) {
      const glm::dvec3 c(m * glm::dvec4(b[i & 1 ? 1 : 0], b[i & 2 ? 3 : 2], b[i & 4 ? 5 : 4], 1.0));
      const bool eyeSide = perspective && c.z < cam.nearClip;
      allBehind = allBehind && eyeSide, anyBehind = anyBehind || eyeSide;
      allBeyond = allBeyond && c.z > cam.farClip;
      if (!eyeSide) {
        const glm::dvec2 r = proj.project(c);
        box[0] = std::min(box[0], r.x), box[1] = std::max(box[1], r.x), box[2] = std::min(box[2], r.y), box[3] = std::max(box[3], r.y);
        zLo = std::min(zLo, c.z), zHi = std::max(zHi, c.z);
      }
    }
    // A lens blurs into view what lies within a circle of confusion of the frame.
    if (const double coc = store::circleOfConfusion(cam, zLo, zHi); coc > 0 && !anyBehind) {
      const double wx = coc * std::abs(proj.ax), wy = coc * std::abs(proj.ay);
      box[0] -= wx, box[1] += wx, box[2] -= wy, box[3] += wy;
    }
    behind = behind && allBehind, beyond = beyond && allBeyond;
    const bool sides = !anyBehind;  // a box reaching behind the eye projects without bound
    left = left && sides && box[1] < -mx, right = right && sides && box[0] > cam.width + mx;
    above = above && sides && box[3] < -my, below = below && sides && box[2] > cam.height + my;
  }
  return behind || beyond || left || right || above || below;
}

}  // namespace

bool RibSceneHandler::cullsBound(const std::array<double, 6>& b) {
  if (!scene_.inWorld()) return false;
  const auto& options = scene_.world().options;
  const MotionXform& ctm = scene_.currentTransform();
  // Culled only when no camera the store records can see it.
  if (!boundOutOfView(b, ctm, options.camera, options.camera, cullMargin_)) return false;
  for (const store::Camera& other : options.namedCameras)
    if (!boundOutOfView(b, ctm, other, options.camera, cullMargin_)) return false;
  scene_.archiveCulled();
  return true;
}

void readRibScene(const std::string& path, Scene& scene, double cullMargin) {
  RibSceneHandler handler(scene, cullMargin);
  rib::Reader reader;
  reader.parseFile(path, handler);
}

store::Camera readRibCamera(const std::string& path) {
  std::optional<store::Camera> camera;
  Scene scene([&](FrameScene& frame) {
    if (!camera) {
      camera = frame.options.camera;
      // Given after the fact, for a store whose shutter this file need not know: its whole motion.
      recordCameraMotion(*camera, frame.worldToCamera);
    }
  });
  readRibScene(path, scene);
  if (!camera) {
    if (scene.inWorld()) fail(path, "WorldBegin without WorldEnd");
    scene.worldBegin();
    scene.worldEnd();
  }
  if (!camera) fail(path, "no camera: the file describes none");
  camera->name = std::filesystem::path(path).stem().string();
  return *camera;
}

}  // namespace reshutter::shade
