// Dicing: surface evaluation, screen-size driven splitting, eye-plane handling, grid building.
#include "shade/dice.h"

#include <algorithm>
#include <cmath>

#include <glm/geometric.hpp>
#include <glm/gtc/matrix_inverse.hpp>
#include <glm/mat3x3.hpp>

#include "common/log.h"

namespace reshutter::shade {

namespace {
constexpr double kDeg = M_PI / 180.0;
double sgn(double x) { return x < 0 ? -1.0 : 1.0; }

double sphereLat(double r, double z) { return std::asin(std::clamp(z / r, -1.0, 1.0)); }

// A sphere's (u, v) as longitude phi and latitude lat, with the latitude range [lat0, lat1].
struct SphereAngles {
  double phi, lat, lat0, lat1;
};
SphereAngles sphereAngles(const std::array<double, 5>& q, double u, double v) {
  const double lat0 = sphereLat(q[0], q[1]), lat1 = sphereLat(q[0], q[2]);
  return {u * q[3] * kDeg, lat0 + v * (lat1 - lat0), lat0, lat1};
}

const std::array<CubicBasis, 2>& basesOf(const Primitive& p) { return cubicBases(p.basis); }

// A bicubic patch (or a derivative along u or v) at (u, v): rows of control points weighted
// along u, then the rows along v, always in index order, so a weight of exactly 0 drops a term
// exactly and two patches sharing control points agree bit for bit on their shared edge.
glm::dvec3 bicubic(const Primitive& p, const Shape& s, double u, double v, bool dU, bool dV) {
  const auto& b = basesOf(p);
  double wu[4], wv[4];
  dU ? b[0].derivatives(u, wu) : b[0].weights(u, wu);
  dV ? b[1].derivatives(v, wv) : b[1].weights(v, wv);
  glm::dvec3 sum(0.0);
  for (size_t l = 0; l < 4; ++l) {
    glm::dvec3 row(0.0);
    for (size_t k = 0; k < 4; ++k) row += wu[k] * s.cv[l * 4 + k];
    sum += wv[l] * row;
  }
  return sum;
}
// A NURBS span at the primitive's (u, v): the rational combination of its control points.
glm::dvec3 nurbsAt(const Primitive& p, const Shape& s, double u, double v) {
  const NurbsSpan& n = *p.nurbs;
  double Nu[32], Nv[32];
  nurbsBasis(n.knotsU.data(), n.orderU, n.u0 + u * (n.u1 - n.u0), Nu);
  nurbsBasis(n.knotsV.data(), n.orderV, n.v0 + v * (n.v1 - n.v0), Nv);
  glm::dvec3 sum(0.0);
  double w = 0;
  for (int l = 0; l < n.orderV; ++l)
    for (int k = 0; k < n.orderU; ++k) {
      const double b = Nu[k] * Nv[l];
      const size_t i = size_t(l * n.orderU + k);
      sum += b * s.cv[i];
      w += b * s.cw[i];
    }
  return sum / w;
}

// normal(u, v), or where it vanishes (a pole, an apex, a collapsed edge) the limit from inside:
// taken ever further towards the middle of the parameter square until it exists.
template <class NormalAt>
glm::dvec3 nudged(const NormalAt& normal, double u, double v, double firstStep) {
  glm::dvec3 n = normal(u, v);
  for (double step = firstStep; (glm::dot(n, n) == 0 || !std::isfinite(glm::dot(n, n))) && step <= 0.1; step *= 10)
    n = normal(u + (0.5 - u) * step, v + (0.5 - v) * step);
  return n;
}

// A unit vector perpendicular to d (any, for a degenerate frame).
glm::dvec3 perpendicular(const glm::dvec3& d) {
  const glm::dvec3 a = std::abs(d.x) < 0.9 * glm::length(d) ? glm::dvec3(1, 0, 0) : glm::dvec3(0, 1, 0);
  const glm::dvec3 c = glm::cross(d, a);
  const double l = glm::length(c);
  return l > 0 ? c / l : glm::dvec3(1, 0, 0);
}

// From the camera-facing shape's eye to `at`: the direction of view.
glm::dvec3 viewAt(const Shape& s, const glm::dvec3& at) { return s.eye.w != 0 ? at - glm::dvec3(s.eye) / s.eye.w : glm::dvec3(s.eye); }

// A curve segment at v: centre, tangent, width and the unit vector across the ribbon.
struct CurveFrame {
  glm::dvec3 C, T, side;
  double width;
};
CurveFrame curveAt(const Primitive& p, const Shape& s, double v) {
  CurveFrame f;
  if (s.cv.size() == 2) {
    f.C = s.cv[0] + v * (s.cv[1] - s.cv[0]), f.T = s.cv[1] - s.cv[0];
  } else {
    const CubicBasis& b = basesOf(p)[1];
    double w[4], d[4];
    b.weights(v, w), b.derivatives(v, d);
    f.C = f.T = glm::dvec3(0.0);
    for (size_t k = 0; k < 4; ++k) f.C += w[k] * s.cv[k], f.T += d[k] * s.cv[k];
  }
  f.width = s.q[0] + v * (s.q[1] - s.q[0]);
  // Across the ribbon: perpendicular to the tangent and to the view (or to the given normal).
  glm::dvec3 side = glm::cross(f.T, s.q[2] != 0 ? s.P[0] + v * (s.P[1] - s.P[0]) : viewAt(s, f.C));
  const double l = glm::length(side);
  f.side = l > 1e-300 && std::isfinite(l) ? side / l : perpendicular(glm::dot(f.T, f.T) > 0 ? f.T : viewAt(s, f.C));
  return f;
}

// A camera-facing disc's two in-plane axes.
void discAxes(const Shape& s, glm::dvec3& a, glm::dvec3& b) {
  const glm::dvec3 view = viewAt(s, s.P[0]);
  a = perpendicular(glm::dot(view, view) > 0 ? view : glm::dvec3(0, 0, 1));
  b = glm::normalize(glm::cross(view, a));
  if (!std::isfinite(b.x)) b = glm::normalize(glm::cross(glm::dvec3(0, 0, 1), a));
}
}  // namespace

glm::dvec3 bilinear(const std::array<glm::dvec3, 4>& c, double u, double v) {
  return (1 - u) * (1 - v) * c[0] + u * (1 - v) * c[1] + (1 - u) * v * c[2] + u * v * c[3];
}

// Cox-de Boor (The NURBS Book, A2.2).
void nurbsBasis(const double* t, int order, double x, double* N) {
  const int deg = order - 1;
  double left[33], right[33];
  N[0] = 1;
  for (int j = 1; j <= deg; ++j) {
    left[j] = x - t[size_t(deg + 1 - j)];
    right[j] = t[size_t(deg + j)] - x;
    double saved = 0;
    for (int r = 0; r < j; ++r) {
      const double denom = right[r + 1] + left[j - r];
      const double temp = denom != 0 ? N[r] / denom : 0;
      N[r] = saved + right[r + 1] * temp;
      saved = left[j - r] * temp;
    }
    N[j] = saved;
  }
}

void CubicBasis::weights(double u, double w[4]) const {
  for (size_t k = 0; k < 4; ++k) w[k] = scale * (((m[k] * u + m[4 + k]) * u + m[8 + k]) * u + m[12 + k]);
}

void CubicBasis::derivatives(double u, double d[4]) const {
  for (size_t k = 0; k < 4; ++k) d[k] = scale * ((3 * m[k] * u + 2 * m[4 + k]) * u + m[8 + k]);
}

glm::dvec3 evalP(const Primitive& p, const Shape& s, double u, double v) {
  const auto& q = s.q;
  switch (p.kind) {
    case PrimKind::Sphere: {
      const double r = q[0];
      const auto [phi, lat, lat0, lat1] = sphereAngles(q, u, v);
      return {r * std::cos(lat) * std::cos(phi), r * std::cos(lat) * std::sin(phi), r * std::sin(lat)};
    }
    case PrimKind::Cylinder: {
      const double phi = u * q[3] * kDeg;
      return {q[0] * std::cos(phi), q[0] * std::sin(phi), q[1] + v * (q[2] - q[1])};
    }
    case PrimKind::Cone: {
      const double phi = u * q[2] * kDeg, r = q[1] * (1 - v);
      return {r * std::cos(phi), r * std::sin(phi), v * q[0]};
    }
    case PrimKind::Disk: {
      const double phi = u * q[2] * kDeg, r = q[1] * (1 - v);
      return {r * std::cos(phi), r * std::sin(phi), q[0]};
    }
    case PrimKind::Torus: {
      const double theta = u * q[4] * kDeg, phi = (q[2] + v * (q[3] - q[2])) * kDeg;
      const double ring = q[0] + q[1] * std::cos(phi);
      return {ring * std::cos(theta), ring * std::sin(theta), q[1] * std::sin(phi)};
    }
    case PrimKind::Hyperboloid: {
      const double phi = u * q[0] * kDeg;
      const glm::dvec3 l = s.P[0] + v * (s.P[1] - s.P[0]);
      return {l.x * std::cos(phi) - l.y * std::sin(phi), l.x * std::sin(phi) + l.y * std::cos(phi), l.z};
    }
    case PrimKind::Paraboloid: {
      const double phi = u * q[3] * kDeg, z = q[1] + v * (q[2] - q[1]), r = q[0] * std::sqrt(std::max(0.0, z / q[2]));
      return {r * std::cos(phi), r * std::sin(phi), z};
    }
    case PrimKind::Curve: {
      const CurveFrame f = curveAt(p, s, v);
      return f.C + (u - 0.5) * f.width * f.side;
    }
    case PrimKind::Point: {
      glm::dvec3 a, b;
      discAxes(s, a, b);
      const double angle = 2 * M_PI * u, r = 0.5 * q[0] * (1 - v);
      return s.P[0] + r * (std::cos(angle) * a + std::sin(angle) * b);
    }
    case PrimKind::Nurbs: return nurbsAt(p, s, u, v);
    case PrimKind::Patch: return bilinear(s.P, u, v);
    case PrimKind::Bicubic: return bicubic(p, s, u, v, false, false);
    case PrimKind::Subdiv: {
      glm::dvec3 P;
      if (p.triangle) u *= 1 - v;  // the square's last row collapses onto the triangle's apex
      p.subdiv->evaluate(p.ptexFace, u, v, s.key, P, nullptr, nullptr);
      return P;
    }
  }
  return glm::dvec3(0.0);
}

glm::dvec3 evalNg(const Primitive& p, const Shape& s, double u, double v) {
  const auto& q = s.q;
  const bool triangle = p.triangle;
  switch (p.kind) {
    case PrimKind::Sphere: {
      const auto [phi, lat, lat0, lat1] = sphereAngles(q, u, v);
      const double k = sgn(q[3]) * sgn(lat1 - lat0);
      return k * glm::dvec3(std::cos(lat) * std::cos(phi), std::cos(lat) * std::sin(phi), std::sin(lat));
    }
    case PrimKind::Cylinder: {
      const double phi = u * q[3] * kDeg, k = sgn(q[3]) * sgn(q[0]) * sgn(q[2] - q[1]);
      return k * glm::dvec3(std::cos(phi), std::sin(phi), 0.0);
    }
    case PrimKind::Cone: {
      const double phi = u * q[2] * kDeg, k = sgn(q[2]) * sgn(q[1]);
      return k * glm::dvec3(q[0] * std::cos(phi), q[0] * std::sin(phi), q[1]);
    }
    case PrimKind::Disk: return glm::dvec3(0.0, 0.0, sgn(q[2]));
    case PrimKind::Torus: {
      const double theta = u * q[4] * kDeg, phi = (q[2] + v * (q[3] - q[2])) * kDeg;
      const double k = sgn(q[4]) * sgn(q[3] - q[2]) * sgn(q[1]) * sgn(q[0] + q[1] * std::cos(phi));
      return k * glm::dvec3(std::cos(phi) * std::cos(theta), std::cos(phi) * std::sin(theta), std::sin(phi));
    }
    case PrimKind::Patch: {
      const auto& P = s.P;
      if (triangle) return glm::cross(P[1] - P[0], P[2] - P[0]);
      const glm::dvec3 dPdu = (1 - v) * (P[1] - P[0]) + v * (P[3] - P[2]);
      const glm::dvec3 dPdv = (1 - u) * (P[2] - P[0]) + u * (P[3] - P[1]);
      glm::dvec3 n = glm::cross(dPdu, dPdv);
      const double scale = glm::length(P[3] - P[0]) + glm::length(P[2] - P[1]);
      if (glm::length(n) <= 1e-12 * scale * scale) n = glm::cross(P[3] - P[0], P[2] - P[1]);  // collapsed corner
      return n;
    }
    case PrimKind::Curve: {
      // Facing the camera (or along the given normals).
      const CurveFrame f = curveAt(p, s, v);
      if (s.q[2] != 0) return s.P[0] + v * (s.P[1] - s.P[0]);
      glm::dvec3 n = glm::cross(f.side, f.T);
      if (glm::dot(n, n) == 0) n = -viewAt(s, f.C);
      return glm::dot(n, viewAt(s, f.C)) > 0 ? -n : n;
    }
    case PrimKind::Point: return -viewAt(s, s.P[0]);
    case PrimKind::Nurbs: {
      // Central differences inside the span (one-sided at its edges).
      auto normal = [&](double uu, double vv) {
        const double h = 1e-5;
        const double ua = std::max(0.0, uu - h), ub = std::min(1.0, uu + h), va = std::max(0.0, vv - h), vb = std::min(1.0, vv + h);
        const glm::dvec3 du = (nurbsAt(p, s, ub, vv) - nurbsAt(p, s, ua, vv)) / (ub - ua);
        const glm::dvec3 dv = (nurbsAt(p, s, uu, vb) - nurbsAt(p, s, uu, va)) / (vb - va);
        return glm::cross(du, dv);
      };
      return nudged(normal, u, v, 1e-3);
    }
    case PrimKind::Hyperboloid:
    case PrimKind::Paraboloid: {
      // Surfaces of revolution: dP/du x dP/dv, by the tangent of the profile (outward when
      // thetamax > 0 and the profile rises, as for the other quadrics); at an apex where the
      // profile's slope is infinite, the limit from a little way in.
      const double theta = (p.kind == PrimKind::Hyperboloid ? q[0] : q[3]) * kDeg;
      auto normal = [&](double uu, double vv) {
        const double phi = uu * theta, c = std::cos(phi), sn = std::sin(phi);
        glm::dvec3 prof, dprof;  // the profile point (before rotation) and its v derivative
        if (p.kind == PrimKind::Hyperboloid) {
          prof = s.P[0] + vv * (s.P[1] - s.P[0]), dprof = s.P[1] - s.P[0];
        } else {
          const double z = q[1] + vv * (q[2] - q[1]), zr = std::max(0.0, z / q[2]), r = q[0] * std::sqrt(zr);
          prof = glm::dvec3(r, 0, z);
          dprof = glm::dvec3(zr > 0 ? q[0] * (q[2] - q[1]) / (2 * q[2] * std::sqrt(zr)) : INFINITY, 0, q[2] - q[1]);
        }
        const glm::dvec3 dPdu = theta * glm::dvec3(-prof.x * sn - prof.y * c, prof.x * c - prof.y * sn, 0.0);
        const glm::dvec3 dPdv(dprof.x * c - dprof.y * sn, dprof.x * sn + dprof.y * c, dprof.z);
        return glm::cross(dPdu, dPdv);
      };
      return nudged(normal, u, v, 1e-4);
    }
    case PrimKind::Subdiv: {
      auto normal = [&](double uu, double vv) {
        glm::dvec3 P, du, dv;
        if (p.triangle) uu *= 1 - vv;
        p.subdiv->evaluate(p.ptexFace, uu, vv, s.key, P, &du, &dv);
        return glm::cross(du, dv);
      };
      return nudged(normal, u, v, 1e-4);
    }
    case PrimKind::Bicubic: {
      // A collapsed edge (the pole of a teapot's lid) has no tangent along it: the normal is
      // the limit from inside the patch, taken a little way in.
      return nudged([&](double uu, double vv) { return glm::cross(bicubic(p, s, uu, vv, true, false), bicubic(p, s, uu, vv, false, true)); }, u, v, 1e-4);
    }
  }
  return glm::dvec3(0, 0, 1);
}

namespace {

// The vertices of a leaf's grid: the rim's from its sides' points (shared with the neighbours),
// the interior's bilinear over the corners in (u, v). A collapsed side's points are all one
// vertex (its first corner's), so a grid has one vertex per point in space.
struct GridVertices {
  std::vector<UV> uv;
  std::vector<uint32_t> id;  // per grid position (i, j), row-major: index into uv
};

// The point of a side of `steps` steps that rim position i of n snaps onto: the nearest, ties
// upwards; monotone, 0 → 0 and n → steps.
int snap(int i, int n, int steps) { return (2 * i * steps + n) / (2 * n); }

void gridVertices(const Leaf& leaf, GridVertices& g) {
  const int nu = leaf.nu, nv = leaf.nv, row = nu + 1;
  g.uv.clear();
  g.id.assign(size_t(row) * size_t(nv + 1), 0);
  // Corners, each merged into the one before it along a collapsed side.
  int rep[4] = {0, 1, 2, 3};
  auto find = [&](int c) {
    while (rep[c] != c) c = rep[c];
    return c;
  };
  for (int c = 0; c < 4; ++c)
    if (leaf.sides[size_t(c)].collapsed) rep[find((c + 1) % 4)] = find(c);
  uint32_t corner[4];
  for (int c = 0; c < 4; ++c)
    if (find(c) == c) corner[c] = uint32_t(g.uv.size()), g.uv.push_back(leaf.corner(c));
  for (int c = 0; c < 4; ++c) corner[c] = corner[find(c)];
  // The points inside each side that is not collapsed.
  uint32_t first[4];
  for (size_t c = 0; c < 4; ++c) {
    const LeafSide& s = leaf.sides[c];
    first[c] = uint32_t(g.uv.size());
    if (!s.collapsed)
      for (int i = 1; i < s.steps(); ++i) g.uv.push_back(s.at(i));
  }
  auto sidePoint = [&](int c, int i) -> uint32_t {
    const LeafSide& s = leaf.sides[size_t(c)];
    if (s.collapsed || i == 0) return corner[c];
    return i == s.steps() ? corner[(c + 1) % 4] : first[c] + uint32_t(i - 1);
  };
  auto at = [&](int i, int j) -> uint32_t& { return g.id[size_t(j) * size_t(row) + size_t(i)]; };
  const UV c0 = leaf.corner(0), c1 = leaf.corner(1), c2 = leaf.corner(2), c3 = leaf.corner(3);
  for (int j = 1; j < nv; ++j)
    for (int i = 1; i < nu; ++i) {
      const double x = double(i) / nu, y = double(j) / nv;
      const double w0 = (1 - x) * (1 - y), w1 = x * (1 - y), w2 = x * y, w3 = (1 - x) * y;
      at(i, j) = uint32_t(g.uv.size());
      g.uv.push_back({w0 * c0.u + w1 * c1.u + w2 * c2.u + w3 * c3.u, w0 * c0.v + w1 * c1.v + w2 * c2.v + w3 * c3.v});
    }
  // The rim, side by side in running order (bottom left to right, right upwards, top right to
  // left, left downwards); the corners last, as sides of no length snap everything to their start.
  for (int i = 0; i <= nu; ++i) at(i, 0) = sidePoint(0, snap(i, nu, leaf.sides[0].steps()));
  for (int j = 0; j <= nv; ++j) at(nu, j) = sidePoint(1, snap(j, nv, leaf.sides[1].steps()));
  for (int i = 0; i <= nu; ++i) at(nu - i, nv) = sidePoint(2, snap(i, nu, leaf.sides[2].steps()));
  for (int j = 0; j <= nv; ++j) at(0, nv - j) = sidePoint(3, snap(j, nv, leaf.sides[3].steps()));
  at(0, 0) = corner[0], at(nu, 0) = corner[1], at(nu, nv) = corner[2], at(0, nv) = corner[3];
}

}  // namespace

void diceLeaf(const Primitive& p, const Leaf& leaf, const std::vector<double>& knots, double shadeAt, double nearClip, bool perspective, DicedGrid& g) {
  const int nu = leaf.nu, nv = leaf.nv, row = nu + 1;
  thread_local GridVertices gv;
  gridVertices(leaf, gv);
  // Trim curves (trim.h) are given in the NuPatch's knot space: the span's (u, v) maps onto it.
  // A grid no loop crosses is kept or cut away whole, before anything is evaluated.
  g.trimmedMicropolygons = 0;
  const TrimLoops* trim = p.kind == PrimKind::Nurbs ? p.attrs->trim.get() : nullptr;
  auto knotSpace = [&](const UV& q) { return UV{p.nurbs->u0 + q.u * (p.nurbs->u1 - p.nurbs->u0), p.nurbs->v0 + q.v * (p.nurbs->v1 - p.nurbs->v0)}; };
  auto cutAway = [&](const UV& q) {
    const UV k = knotSpace(q);
    return trim->encloses(k.u, k.v) != p.attrs->trimKeepsInside;
  };
  bool trimEach = false;
  if (trim) {
    UV lo{1e300, 1e300}, hi{-1e300, -1e300};
    for (const UV& q : gv.uv) lo = {std::min(lo.u, q.u), std::min(lo.v, q.v)}, hi = {std::max(hi.u, q.u), std::max(hi.v, q.v)};
    const UV a = knotSpace(lo), b = knotSpace(hi);
    trimEach = trim->crosses(a.u, b.u, a.v, b.v);
    if (!trimEach && cutAway({0.5 * (lo.u + hi.u), 0.5 * (lo.v + hi.v)})) {
      g = DicedGrid{};
      g.nu = nu, g.nv = nv;
      g.trimmedMicropolygons = uint64_t(nu) * uint64_t(nv);
      return;
    }
  }
  const uint32_t nV = uint32_t(gv.uv.size());
  const size_t K = knots.size();
  g.nu = nu, g.nv = nv, g.numVertices = nV;
  g.lattice.assign(gv.id.begin(), gv.id.end());
  g.positions.resize(K * nV);
  for (size_t k = 0; k < K; ++k) {
    const Shape s = p.shapeAt(knots[k]);
    const glm::dmat4 m = p.xform->at(knots[k]);
    glm::vec3* out = g.positions.data() + k * nV;
    for (uint32_t i = 0; i < nV; ++i) out[i] = glm::vec3(m * glm::dvec4(evalP(p, s, gv.uv[i].u, gv.uv[i].v), 1.0));
  }

  // Geometry at the shading time.
  const Shape s = p.shapeAt(shadeAt);
  const glm::dmat4 m = p.xform->at(shadeAt);
  const glm::dmat3 nm = glm::inverseTranspose(glm::dmat3(m));
  const double flip = p.flipNormals ? -1.0 : 1.0;
  g.P.resize(nV), g.N.resize(nV), g.Ng.resize(nV), g.u.resize(nV), g.v.resize(nV), g.s.resize(nV), g.t.resize(nV);
  std::array<glm::dvec3, 4> cornerN;
  std::array<glm::dvec2, 4> st;
  const bool hasN = p.mesh && p.corners(p.mesh->N, cornerN);
  const bool hasST = p.cornerST(st);
  for (uint32_t idx = 0; idx < nV; ++idx) {
    const double u = gv.uv[idx].u, v = gv.uv[idx].v;
    g.P[idx] = glm::dvec3(m * glm::dvec4(evalP(p, s, u, v), 1.0));
    glm::dvec3 ng = nm * evalNg(p, s, u, v);
    double len = glm::length(ng);
    ng = len > 0 ? flip * ng / len : glm::dvec3(0, 0, -1);
    g.Ng[idx] = ng;
    if (hasN) {
      glm::dvec3 n = nm * bilinear(cornerN, u, v);
      double l = glm::length(n);
      g.N[idx] = l > 0 ? n / l : ng;
    } else {
      g.N[idx] = ng;
    }
    g.u[idx] = u, g.v[idx] = v;
    if (hasST) {
      g.s[idx] = (1 - u) * (1 - v) * st[0].x + u * (1 - v) * st[1].x + (1 - u) * v * st[2].x + u * v * st[3].x;
      g.t[idx] = (1 - u) * (1 - v) * st[0].y + u * (1 - v) * st[1].y + (1 - u) * v * st[2].y + u * v * st[3].y;
    } else {
      g.s[idx] = u, g.t[idx] = v;
    }
  }

  // Ring order counter-clockwise around N: the parametric order when the transform keeps
  // handedness and the orientation is not flipped, reversed otherwise. Corners that are one
  // point (snapped onto one point of a coarser side, or on a collapsed side) are kept once: such
  // cells are triangles, or nothing.
  const bool reverse = (glm::determinant(m) < 0) != p.flipNormals;
  g.corners.clear();
  g.corners.reserve(size_t(nu) * nv * 4);
  g.droppedMicropolygons = 0;
  for (int j = 0; j < nv; ++j)
    for (int i = 0; i < nu; ++i) {
      const size_t p0 = size_t(j * row + i);
      uint32_t ring[4] = {gv.id[p0], gv.id[p0 + 1], gv.id[p0 + 1 + size_t(row)], gv.id[p0 + size_t(row)]};
      if (reverse) std::swap(ring[1], ring[3]);
      uint32_t c[4] = {store::kNoCorner, store::kNoCorner, store::kNoCorner, store::kNoCorner};
      int nc = 0;
      for (uint32_t v : ring)
        if (nc == 0 || v != c[nc - 1]) c[nc++] = v;
      if (nc > 1 && c[nc - 1] == c[0]) --nc;
      if (nc < 3) continue;
      if (nc == 3) c[3] = store::kNoCorner;
      if (trimEach) {
        UV centre;
        for (int n = 0; n < nc; ++n) centre.u += gv.uv[c[n]].u / nc, centre.v += gv.uv[c[n]].v / nc;
        if (cutAway(centre)) {
          ++g.trimmedMicropolygons;
          continue;
        }
      }
      if (perspective) {
        bool straddles = false, everInFront = false;
        for (size_t k = 0; k < K && !straddles; ++k) {
          int behind = 0;
          for (int n = 0; n < nc; ++n) behind += g.positions[k * nV + c[n]].z < nearClip;
          straddles = behind > 0 && behind < nc;
          everInFront = everInFront || behind == 0;
        }
        if (straddles || !everInFront) {
          ++g.droppedMicropolygons;
          continue;
        }
      }
      g.corners.insert(g.corners.end(), c, c + 4);
    }
}

}  // namespace reshutter::shade
