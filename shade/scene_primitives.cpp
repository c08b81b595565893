// The scene builder's primitives (shade/scene.h): each RenderMan geometric request checked and
// made into Primitives - quadrics, bilinear and bicubic patches and meshes, NURBS spans,
// subdivision faces, curve segments, points and polygons - that addPrims() files under the
// current state. The graphics state itself is scene.cpp's.
#include <algorithm>
#include <cmath>
#include <span>

#include "common/error.h"
#include "common/log.h"
#include "shade/scene.h"
#include "shade/triangulate.h"

namespace reshutter::shade {

namespace {
void checkFinite(const Scene& s, std::span<const double> v) {
  for (double x : v)
    if (!std::isfinite(x)) fail(s.where, "primitive parameter is not finite");
}
void checkFinite(const Scene& s, std::initializer_list<double> v) { checkFinite(s, std::span<const double>(v.begin(), v.size())); }
}  // namespace

void Scene::quadric(PrimKind kind, const std::array<double, 5>& q, size_t used) {
  checkFinite(*this, std::span<const double>(q.data(), used));
  Primitive p = basePrim(kind);
  Shape s;
  s.q = q;
  p.keys = {s};
  addPrims({std::move(p)});
}
void Scene::sphere(double radius, double zmin, double zmax, double thetamax) { quadric(PrimKind::Sphere, {radius, zmin, zmax, thetamax, 0}, 4); }
void Scene::cylinder(double radius, double zmin, double zmax, double thetamax) { quadric(PrimKind::Cylinder, {radius, zmin, zmax, thetamax, 0}, 4); }
void Scene::cone(double height, double radius, double thetamax) { quadric(PrimKind::Cone, {height, radius, thetamax, 0, 0}, 3); }
void Scene::disk(double height, double radius, double thetamax) { quadric(PrimKind::Disk, {height, radius, thetamax, 0, 0}, 3); }
void Scene::torus(double rmajor, double rminor, double phimin, double phimax, double thetamax) {
  quadric(PrimKind::Torus, {rmajor, rminor, phimin, phimax, thetamax}, 5);
}

void Scene::hyperboloid(const glm::dvec3& point1, const glm::dvec3& point2, double thetamax) {
  checkFinite(*this, {point1.x, point1.y, point1.z, point2.x, point2.y, point2.z, thetamax});
  Primitive p = basePrim(PrimKind::Hyperboloid);
  Shape s;
  s.q[0] = thetamax;
  s.P[0] = point1, s.P[1] = point2;
  p.keys = {s};
  addPrims({std::move(p)});
}
void Scene::paraboloid(double rmax, double zmin, double zmax, double thetamax) {
  if (!(zmax != 0)) error("a paraboloid needs zmax != 0");
  quadric(PrimKind::Paraboloid, {rmax, zmin, zmax, thetamax, 0}, 4);
}

void Scene::patch(const std::array<glm::dvec3, 4>& P, const VertexData& vd) {
  for (const auto& c : P) checkFinite(*this, {c.x, c.y, c.z});
  Primitive p = basePrim(PrimKind::Patch);
  Shape s;
  s.P = P;
  p.keys = {s};
  if (!vd.N.empty() || !vd.Cs.empty() || !vd.Os.empty() || !vd.st.empty()) {
    auto mesh = std::make_shared<MeshData>();
    mesh->N = vd.N, mesh->Cs = vd.Cs, mesh->Os = vd.Os, mesh->st = vd.st;
    mesh->points = 4, mesh->faces = 1;
    p.mesh = std::move(mesh);
    p.meshPoint = {0, 1, 2, 3};
  }
  addPrims({std::move(p)});
}

void Scene::basis(const CubicBasis& u, const CubicBasis& v) {
  for (const CubicBasis* b : {&u, &v}) {
    for (double x : b->m)
      if (!std::isfinite(x)) error("basis matrix element is not finite");
    if (b->step < 1 || b->step > 64) error(cat("basis step ", b->step, " must be 1 to 64"));
  }
  mutableAttrs().basis = std::make_shared<const std::array<CubicBasis, 2>>(std::array<CubicBasis, 2>{u, v});
}

const std::array<CubicBasis, 2>& cubicBases(const std::shared_ptr<const std::array<CubicBasis, 2>>& basis) {
  static const std::array<CubicBasis, 2> bezier{};
  return basis ? *basis : bezier;
}

std::shared_ptr<const MeshData> Scene::cornerData(const VertexData& vd, size_t varying, size_t uniform, const char* what, bool withN) const {
  auto m = std::make_shared<MeshData>();
  m->points = varying, m->faces = uniform;
  auto take = [&](const auto& in, auto& out, const char* name, bool uniformToo) {
    if (in.empty()) return;
    if (in.size() == varying || (uniformToo && in.size() == uniform)) out = in;
    else
      warnOnce(cat(what, "-var:", name), cat(where, ": \"", name, "\" has ", in.size(), " values; a ", what, " takes ", varying, " (varying)",
                                              uniformToo ? cat(" or ", uniform, " (uniform)") : std::string(), "; ignored"));
  };
  if (withN) take(vd.N, m->N, "N", true);
  take(vd.Cs, m->Cs, "Cs", true), take(vd.Os, m->Os, "Os", true), take(vd.st, m->st, "st", false);
  if (m->N.empty() && m->Cs.empty() && m->Os.empty() && m->st.empty()) return nullptr;
  return m;
}

namespace {
/// Patches along one direction of a patch mesh, or 0 when the count does not fit the step.
int patchCount(bool bicubic, int n, bool periodic, int step) {
  if (!bicubic) return periodic ? n : n - 1;
  if (periodic) return n % step == 0 ? n / step : 0;
  return n >= 4 && (n - 4) % step == 0 ? (n - 4) / step + 1 : 0;
}
}  // namespace

void Scene::patchMesh(bool bicubic, int nu, bool uPeriodic, int nv, bool vPeriodic, const std::vector<glm::dvec3>& P, const VertexData& vd) {
  const auto& bases = cubicBases(cur_.attrs->basis);
  if (nu < 1 || nv < 1 || size_t(nu) * size_t(nv) != P.size())
    error(cat("a ", nu, " x ", nv, " patch mesh needs ", int64_t(nu) * nv, " control points, has ", P.size()));
  for (const auto& c : P) checkFinite(*this, {c.x, c.y, c.z});
  const int su = bicubic ? bases[0].step : 1, sv = bicubic ? bases[1].step : 1;
  const int npu = patchCount(bicubic, nu, uPeriodic, su), npv = patchCount(bicubic, nv, vPeriodic, sv);
  if (npu < 1) error(cat("nu = ", nu, " does not make whole ", uPeriodic ? "periodic " : "", bicubic ? "bicubic" : "bilinear", " patches with a u step of ", su));
  if (npv < 1) error(cat("nv = ", nv, " does not make whole ", vPeriodic ? "periodic " : "", bicubic ? "bicubic" : "bilinear", " patches with a v step of ", sv));
  // Varying values sit at patch corners, uniform ones on patches.
  const int nvu = uPeriodic ? npu : npu + 1, nvv = vPeriodic ? npv : npv + 1;
  const size_t varying = size_t(nvu) * size_t(nvv), uniform = size_t(npu) * size_t(npv);
  const std::shared_ptr<const MeshData> mesh = cornerData(vd, varying, uniform, "patch mesh", true);
  std::vector<Primitive> out;
  out.reserve(uniform);
  for (int pv = 0; pv < npv; ++pv)
    for (int pu = 0; pu < npu; ++pu) {
      Primitive p = basePrim(bicubic ? PrimKind::Bicubic : PrimKind::Patch);
      Shape s;
      auto point = [&](int i, int j) { return P[size_t((j % nv) * nu + (i % nu))]; };
      if (bicubic) {
        p.basis = cur_.attrs->basis;
        s.cv.resize(16);
        for (int l = 0; l < 4; ++l)
          for (int k = 0; k < 4; ++k) s.cv[size_t(l * 4 + k)] = point(pu * su + k, pv * sv + l);
      } else {
        s.P = {point(pu, pv), point(pu + 1, pv), point(pu, pv + 1), point(pu + 1, pv + 1)};
      }
      p.keys = {s};
      if (mesh) {
        p.mesh = mesh;
        auto corner = [&](int i, int j) { return uint32_t((j % nvv) * nvu + (i % nvu)); };
        p.meshPoint = {corner(pu, pv), corner(pu + 1, pv), corner(pu, pv + 1), corner(pu + 1, pv + 1)};
        p.meshFace = uint32_t(pv * npu + pu);
      }
      out.push_back(std::move(p));
    }
  addPrims(std::move(out));
}

void Scene::subdivisionMesh(SubdivScheme scheme, const std::vector<int>& nverts, const std::vector<int>& verts, const SubdivTags& tags,
                            const std::vector<glm::dvec3>& P, const VertexData& vd) {
  auto surface = std::make_shared<const SubdivSurface>(scheme, nverts, verts, tags, std::vector<std::vector<glm::dvec3>>{P}, where);
  const int n = surface->ptexFaces();
  std::vector<size_t> firstVertex(nverts.size() + 1, 0);
  for (size_t f = 0; f < nverts.size(); ++f) firstVertex[f + 1] = firstVertex[f] + size_t(nverts[f]);
  // Varying data as corner values per ptex face: a quad's own, an n-gon sub-face's (its vertex,
  // the two edge midpoints, the centroid), a triangle's with its apex repeated.
  // Face-varying data (one value per face vertex) is taken per face vertex the same way.
  auto cornersOf = [&](int ptex, const auto& data, auto zero) {
    const auto [f, corner] = surface->baseFace(ptex);
    const size_t first = firstVertex[size_t(f)], nv = size_t(nverts[size_t(f)]);
    const bool perFaceVertex = data.size() != P.size();
    auto at = [&](size_t i) { return data[perFaceVertex ? first + (i % nv) : size_t(verts[first + (i % nv)])]; };
    if (nv == 3 && scheme == SubdivScheme::Loop) return std::array<decltype(zero), 4>{at(0), at(1), at(2), at(2)};
    if (nv == 4) return std::array<decltype(zero), 4>{at(0), at(1), at(3), at(2)};
    auto centroid = zero;
    for (size_t i = 0; i < nv; ++i) centroid += at(i);
    centroid /= double(nv);
    const size_t c = size_t(corner);
    return std::array<decltype(zero), 4>{at(c), (at(c) + at(c + 1)) * 0.5, (at(c) + at(c + nv - 1)) * 0.5, centroid};
  };
  std::shared_ptr<MeshData> mesh;
  if (!vd.N.empty() || !vd.Cs.empty() || !vd.Os.empty() || !vd.st.empty()) {
    mesh = std::make_shared<MeshData>();
    mesh->points = size_t(n) * 4, mesh->faces = size_t(n);
    auto expand = [&](const std::vector<glm::dvec3>& in, std::vector<glm::dvec3>& out, const char* name) {
      if (in.empty()) return;
      if (in.size() == P.size() || in.size() == verts.size()) {
        for (int i = 0; i < n; ++i)
          for (const auto& c : cornersOf(i, in, glm::dvec3(0.0))) out.push_back(c);
      } else if (in.size() == nverts.size()) {
        for (int i = 0; i < n; ++i) out.push_back(in[size_t(surface->baseFace(i).first)]);
      } else {
        warnOnce(cat("subdiv-var:", name), cat(where, ": \"", name, "\" has ", in.size(), " values; a subdivision mesh takes ", P.size(), ", ", verts.size(),
                                               " or ", nverts.size(), "; ignored"));
      }
    };
    expand(vd.Cs, mesh->Cs, "Cs"), expand(vd.Os, mesh->Os, "Os");
    if (vd.st.size() == P.size() || vd.st.size() == verts.size())
      for (int i = 0; i < n; ++i)
        for (const auto& c : cornersOf(i, vd.st, glm::dvec2(0.0))) mesh->st.push_back(c);
  }
  std::vector<Primitive> out;
  for (int i = 0; i < n; ++i) {
    if (!surface->hasSurface(i)) continue;
    Primitive p = basePrim(PrimKind::Subdiv);
    p.subdiv = surface;
    p.ptexFace = i;
    p.triangle = scheme == SubdivScheme::Loop;
    p.keys = {Shape{}};
    if (mesh) {
      p.mesh = mesh;
      p.meshPoint = {uint32_t(4 * i), uint32_t(4 * i + 1), uint32_t(4 * i + 2), uint32_t(4 * i + 3)};
      p.meshFace = uint32_t(i);
    }
    out.push_back(std::move(p));
  }
  addPrims(std::move(out));
}

void Scene::curves(bool cubic, const std::vector<int>& nvertices, bool periodic, const std::vector<glm::dvec3>& P, const std::vector<double>& width,
                   const std::vector<glm::dvec3>& N, const VertexData& vd) {
  const CubicBasis& basis = cubicBases(cur_.attrs->basis)[1];
  const int step = cubic ? basis.step : 1;
  for (const auto& c : P) checkFinite(*this, {c.x, c.y, c.z});
  // Segments and varying values per curve.
  std::vector<int> segments;
  size_t totalVertices = 0, totalVarying = 0;
  for (size_t c = 0; c < nvertices.size(); ++c) {
    const int n = nvertices[c];
    const int seg = patchCount(cubic, n, periodic, step);
    if (n < (cubic ? 4 : 2) || seg < 1) error(cat("curve ", c, " has ", n, " vertices: not whole ", periodic ? "periodic " : "", cubic ? "cubic" : "linear", " segments with a step of ", step));
    segments.push_back(seg);
    totalVertices += size_t(n);
    totalVarying += size_t(periodic ? seg : seg + 1);
  }
  if (totalVertices != P.size()) error(cat("curves name ", totalVertices, " vertices, \"P\" has ", P.size()));
  if (!(width.size() == 1 || width.size() == totalVarying)) error(cat("\"width\" has ", width.size(), " values; the curves take 1 or ", totalVarying, " (varying)"));
  for (double w : width)
    if (!(w >= 0) || !std::isfinite(w)) error(cat("curve width ", w, " must be a finite non-negative number"));
  if (!N.empty() && N.size() != totalVarying) error(cat("\"N\" has ", N.size(), " values; the curves take ", totalVarying, " (varying)"));
  const std::shared_ptr<const MeshData> mesh = cornerData(vd, totalVarying, nvertices.size(), "curve", false);
  const bool ortho = options_.camera.projection == store::Projection::Orthographic;
  std::vector<Primitive> out;
  size_t firstVertex = 0, firstVarying = 0;
  for (size_t c = 0; c < nvertices.size(); ++c) {
    const int n = nvertices[c], seg = segments[c], nVarying = periodic ? seg : seg + 1;
    for (int k = 0; k < seg; ++k) {
      Primitive p = basePrim(PrimKind::Curve);
      p.orthographicView = ortho;
      if (cubic) p.basis = cur_.attrs->basis;
      Shape s;
      for (int i = 0; i < (cubic ? 4 : 2); ++i) s.cv.push_back(P[firstVertex + size_t((k * step + i) % n)]);
      const size_t v0 = firstVarying + size_t(k), v1 = firstVarying + size_t((k + 1) % nVarying);
      s.q[0] = width.size() == 1 ? width[0] : width[v0];
      s.q[1] = width.size() == 1 ? width[0] : width[v1];
      if (!N.empty()) s.q[2] = 1, s.P[0] = N[v0], s.P[1] = N[v1];
      p.keys = {s};
      if (mesh) {
        p.mesh = mesh;
        p.meshPoint = {uint32_t(v0), uint32_t(v0), uint32_t(v1), uint32_t(v1)};  // colour varies along v
        p.meshFace = uint32_t(c);
      }
      out.push_back(std::move(p));
    }
    firstVertex += size_t(n), firstVarying += size_t(nVarying);
  }
  addPrims(std::move(out));
}

void Scene::nuPatch(int nu, int uorder, const std::vector<double>& uknot, double umin, double umax, int nv, int vorder, const std::vector<double>& vknot,
                    double vmin, double vmax, const std::vector<glm::dvec4>& Pw, const VertexData& vd) {
  // The checks RenderMan's definition implies, each a one-line error.
  auto direction = [&](const char* d, int n, int order, const std::vector<double>& knot, double lo, double hi) {
    if (order < 1 || order > 32) error(cat(d, "order ", order, " (1 to 32)"));
    if (n < order) error(cat(d, "order ", order, " is above its ", n, " control points"));
    if (knot.size() != size_t(n + order)) error(cat(d, "knot vector has ", knot.size(), " values; ", n, " points of order ", order, " need ", n + order));
    for (size_t i = 0; i < knot.size(); ++i) {
      if (!std::isfinite(knot[i])) error(cat(d, "knot ", i, " is not finite"));
      if (i && knot[i] < knot[i - 1]) error(cat(d, "knot vector decreases at knot ", i, " (", knot[i - 1], " then ", knot[i], ")"));
    }
    const double first = knot[size_t(order - 1)], last = knot[size_t(n)];
    if (!(lo < hi) || lo < first || hi > last) error(cat(d, "parameter range [", lo, ", ", hi, "] is not inside [", first, ", ", last, "]"));
  };
  direction("u ", nu, uorder, uknot, umin, umax);
  direction("v ", nv, vorder, vknot, vmin, vmax);
  if (Pw.size() != size_t(nu) * size_t(nv)) error(cat("a ", nu, " x ", nv, " NuPatch needs ", int64_t(nu) * nv, " control points, has ", Pw.size()));
  for (const auto& c : Pw) {
    checkFinite(*this, {c.x, c.y, c.z, c.w});
    if (!(c.w > 0)) error(cat("control point weight ", c.w, " must be positive"));
  }
  const int spansU = nu - uorder + 1, spansV = nv - vorder + 1;
  const size_t varying = size_t(spansU + 1) * size_t(spansV + 1), uniform = size_t(spansU) * size_t(spansV);
  const std::shared_ptr<const MeshData> mesh = cornerData(vd, varying, uniform, "NuPatch", false);
  std::vector<Primitive> out;
  for (int sv = 0; sv < spansV; ++sv)
    for (int su = 0; su < spansU; ++su) {
      const int iu = su + uorder - 1, iv = sv + vorder - 1;  // the span [knot[i], knot[i+1]]
      const double a = std::max(uknot[size_t(iu)], umin), b = std::min(uknot[size_t(iu + 1)], umax);
      const double c = std::max(vknot[size_t(iv)], vmin), d = std::min(vknot[size_t(iv + 1)], vmax);
      if (!(a < b) || !(c < d)) continue;  // an empty span, or outside the range drawn
      auto span = std::make_shared<NurbsSpan>();
      span->orderU = uorder, span->orderV = vorder;
      span->knotsU.assign(uknot.begin() + (iu - uorder + 1), uknot.begin() + (iu + uorder + 1));
      span->knotsV.assign(vknot.begin() + (iv - vorder + 1), vknot.begin() + (iv + vorder + 1));
      span->u0 = a, span->u1 = b, span->v0 = c, span->v1 = d;
      Primitive p = basePrim(PrimKind::Nurbs);
      p.nurbs = std::move(span);
      Shape s;
      for (int l = 0; l < vorder; ++l)
        for (int k = 0; k < uorder; ++k) {
          const glm::dvec4& c4 = Pw[size_t((sv + l) * nu + su + k)];
          s.cv.emplace_back(c4.x, c4.y, c4.z);
          s.cw.push_back(c4.w);
        }
      p.keys = {s};
      if (mesh) {
        p.mesh = mesh;
        auto corner = [&](int i, int j) { return uint32_t(j * (spansU + 1) + i); };
        p.meshPoint = {corner(su, sv), corner(su + 1, sv), corner(su, sv + 1), corner(su + 1, sv + 1)};
        p.meshFace = uint32_t(sv * spansU + su);
      }
      out.push_back(std::move(p));
    }
  addPrims(std::move(out));
}

void Scene::points(const std::vector<glm::dvec3>& P, const std::vector<double>& width, const VertexData& vd) {
  for (const auto& c : P) checkFinite(*this, {c.x, c.y, c.z});
  if (!(width.size() == 1 || width.size() == P.size())) error(cat("\"width\" has ", width.size(), " values; the points take 1 or ", P.size()));
  for (double w : width)
    if (!(w >= 0) || !std::isfinite(w)) error(cat("point width ", w, " must be a finite non-negative number"));
  std::shared_ptr<MeshData> mesh;
  if (!vd.Cs.empty() || !vd.Os.empty()) {
    mesh = std::make_shared<MeshData>();
    mesh->points = P.size(), mesh->faces = P.size();
    if (vd.Cs.size() == P.size()) mesh->Cs = vd.Cs;
    if (vd.Os.size() == P.size()) mesh->Os = vd.Os;
  }
  const bool ortho = options_.camera.projection == store::Projection::Orthographic;
  std::vector<Primitive> out;
  out.reserve(P.size());
  for (size_t i = 0; i < P.size(); ++i) {
    Primitive p = basePrim(PrimKind::Point);
    p.orthographicView = ortho;
    Shape s;
    s.P[0] = P[i];
    s.q[0] = width.size() == 1 ? width[0] : width[i];
    p.keys = {s};
    if (mesh) {
      p.mesh = mesh;
      p.meshPoint = {uint32_t(i), uint32_t(i), uint32_t(i), uint32_t(i)};
      p.meshFace = uint32_t(i);
    }
    out.push_back(std::move(p));
  }
  addPrims(std::move(out));
}

void Scene::checkIndices(const std::vector<int>& counts, const std::vector<int>& indices, size_t points, const char* what) const {
  size_t total = 0;
  for (int n : counts) {
    if (n < 0) error("negative vertex count");
    total += size_t(n);
  }
  if (total != indices.size()) error(cat(what, " name ", indices.size(), " vertex indices; their counts add up to ", total));
  for (int v : indices)
    if (v < 0 || size_t(v) >= points) error(cat("vertex index ", v, " out of range (", points, " points)"));
}

void Scene::emitFaces(const std::vector<int>& nverts, const std::vector<int>& verts, const std::vector<glm::dvec3>& P, const VertexData& vd,
                      std::vector<Primitive>& out) {
  checkIndices(nverts, verts, P.size(), "polygons");
  for (const auto& c : P) checkFinite(*this, {c.x, c.y, c.z});
  const size_t nFaces = nverts.size();
  // Face-varying data (one value per face vertex; RenderMan's facevarying) makes every face
  // vertex a data point of its own, and vertex/varying arrays are spread onto face vertices too.
  auto faceVarying = [&](size_t n) { return n == verts.size() && n != P.size(); };
  const bool perFaceVertex = faceVarying(vd.N.size()) || faceVarying(vd.Cs.size()) || faceVarying(vd.Os.size()) || faceVarying(vd.st.size());
  std::shared_ptr<const MeshData> mesh;
  if (!vd.N.empty() || !vd.Cs.empty() || !vd.Os.empty() || !vd.st.empty()) {
    auto m = std::make_shared<MeshData>();
    m->N = vd.N, m->Cs = vd.Cs, m->Os = vd.Os, m->st = vd.st;
    m->points = P.size(), m->faces = nFaces;
    if (perFaceVertex) {
      auto spread = [&](auto& data) {
        if (data.size() != P.size()) return;
        std::remove_reference_t<decltype(data)> out;
        for (int v : verts) out.push_back(data[size_t(v)]);
        data = std::move(out);
      };
      spread(m->N), spread(m->Cs), spread(m->Os), spread(m->st);
      m->points = verts.size();
    }
    mesh = std::move(m);
  }
  size_t first = 0;
  for (size_t f = 0; f < nFaces; ++f) {
    const int n = nverts[f];
    const int* idx = verts.data() + first;
    if (n < 3) {
      first += size_t(n);
      continue;
    }
    // A fan of quads (and a closing triangle) from vertex 0; exact for convex planar polygons.
    for (int i = 1; i + 1 < n; i += 2) {
      const bool tri = i + 2 >= n;
      const int ring[4] = {0, i, i + 1, tri ? i + 1 : i + 2};   // face vertices
      const int rib[4] = {ring[0], ring[1], ring[3], ring[2]};  // ring → P00 P10 P01 P11
      Primitive p = basePrim(PrimKind::Patch);
      p.triangle = tri;
      Shape s;
      for (int c = 0; c < 4; ++c) s.P[c] = P[size_t(idx[rib[c]])];
      p.keys = {s};
      if (mesh) {
        p.mesh = mesh;
        for (int c = 0; c < 4; ++c) p.meshPoint[size_t(c)] = uint32_t(perFaceVertex ? first + size_t(rib[c]) : size_t(idx[rib[c]]));
        p.meshFace = uint32_t(f);
      }
      out.push_back(std::move(p));
    }
    first += size_t(n);
  }
}

void Scene::pointsPolygons(const std::vector<int>& nverts, const std::vector<int>& verts, const std::vector<glm::dvec3>& P, const VertexData& vd) {
  std::vector<Primitive> out;
  emitFaces(nverts, verts, P, vd, out);
  addPrims(std::move(out));
}

void Scene::polygon(const std::vector<glm::dvec3>& P, const VertexData& vd) {
  std::vector<int> idx(P.size());
  for (size_t i = 0; i < P.size(); ++i) idx[i] = int(i);
  pointsPolygons({int(P.size())}, idx, P, vd);
}

void Scene::generalPolygons(const std::vector<int>& nloops, const std::vector<int>& nverts, const std::vector<int>& verts, const std::vector<glm::dvec3>& P,
                            const VertexData& vd) {
  size_t loopsTotal = 0;
  for (int l : nloops) {
    if (l < 1) error("a polygon needs at least one loop");
    loopsTotal += size_t(l);
  }
  if (loopsTotal != nverts.size()) error(cat("polygons have ", loopsTotal, " loops; ", nverts.size(), " loop vertex counts given"));
  checkIndices(nverts, verts, P.size(), "loops");
  // One face list for emitFaces: one-loop polygons as given, holed ones as their triangles.
  std::vector<int> faceVerts, faceIndices;
  std::vector<size_t> source;     // the polygon each face comes from (for uniform data)
  std::vector<size_t> faceVertex;  // each face index's loop vertex (for face-varying data)
  size_t loop = 0, at = 0;
  std::vector<std::array<int, 3>> tris;
  for (size_t poly = 0; poly < nloops.size(); ++poly) {
    std::vector<std::vector<int>> loops;
    const size_t polyFirst = at;
    for (int l = 0; l < nloops[poly]; ++l, ++loop) {
      loops.emplace_back(verts.begin() + std::ptrdiff_t(at), verts.begin() + std::ptrdiff_t(at + size_t(nverts[loop])));
      at += size_t(nverts[loop]);
    }
    if (loops.size() == 1) {
      faceVerts.push_back(int(loops[0].size()));
      faceIndices.insert(faceIndices.end(), loops[0].begin(), loops[0].end());
      for (size_t i = polyFirst; i < at; ++i) faceVertex.push_back(i);
      source.push_back(poly);
      continue;
    }
    tris.clear();
    if (!triangulateLoops(P, loops, tris)) error(cat("polygon ", poly, " with holes cannot be triangulated (crossing edges, or a hole outside its outline)"));
    for (const auto& t : tris) {
      faceVerts.push_back(3);
      faceIndices.insert(faceIndices.end(), t.begin(), t.end());
      for (int v : t) faceVertex.push_back(size_t(std::find(verts.begin() + std::ptrdiff_t(polyFirst), verts.begin() + std::ptrdiff_t(at), v) - verts.begin()));
      source.push_back(poly);
    }
  }
  // Uniform (per polygon) data follows its polygon to every face made of it.
  VertexData faces = vd;
  auto perFace = [&](std::vector<glm::dvec3>& data) {
    if (data.size() != nloops.size() || data.size() == P.size()) return;
    std::vector<glm::dvec3> out;
    for (size_t f : source) out.push_back(data[f]);
    data = std::move(out);
  };
  perFace(faces.N), perFace(faces.Cs), perFace(faces.Os);
  // Face-varying data follows its loop vertex to the faces' vertices.
  auto perFaceVertex = [&](auto& data) {
    if (data.size() != verts.size() || data.size() == P.size()) return;
    std::remove_reference_t<decltype(data)> out;
    for (size_t i : faceVertex) out.push_back(data[i]);
    data = std::move(out);
  };
  perFaceVertex(faces.N), perFaceVertex(faces.Cs), perFaceVertex(faces.Os), perFaceVertex(faces.st);
  std::vector<Primitive> out;
  emitFaces(faceVerts, faceIndices, P, faces, out);
  addPrims(std::move(out));
}

}  // namespace reshutter::shade
