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

glm::dvec3 bilinear(const std::array<glm::dvec3, 4>& c, double u, double v) {
  return (1 - u) * (1 - v) * c[0] + u * (1 - v) * c[1] + (1 - u) * v * c[2] + u * v * c[3];
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
// Cox-de Boor (The NURBS Book, A2.2): the `order` B-spline basis functions that are non-zero on
// the span [t[order-1], t[order]) of the local knots t, at x.
void nurbsBasis(const std::vector<double>& t, int order, double x, double* N) {
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

// A NURBS span at the primitive's (u, v): the rational combination of its control points.
glm::dvec3 nurbsAt(const Primitive& p, const Shape& s, double u, double v) {
  const NurbsSpan& n = *p.nurbs;
  double Nu[32], Nv[32];
  nurbsBasis(n.knotsU, n.orderU, n.u0 + u * (n.u1 - n.u0), Nu);
  nurbsBasis(n.knotsV, n.orderV, n.v0 + v * (n.v1 - n.v0), Nv);
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

std::vector<double> clipKnots(const Primitive& p, double open, double close) {
  std::vector<double> all = p.knotTimes();
  if (all.empty() || !(close > open)) return {open};
  std::vector<double> out{open};
  for (double t : all)
    if (t > open && t < close) out.push_back(t);
  out.push_back(close);
  // Motion that stands still inside the interval (identical keys, or moving only outside it) is
  // static: one knot, schedule 0, and no motion cost downstream.
  const glm::dmat4 m0 = p.xform->at(open);
  const Shape s0 = p.shapeAt(open);
  for (double t : out) {
    if (p.xform->at(t) != m0) return out;
    const Shape s = p.shapeAt(t);
    if (s.q != s0.q || s.P != s0.P || s.cv != s0.cv || s.cw != s0.cw || s.key != s0.key) return out;
  }
  return {open};
}

namespace {

struct Estimate {
  bool allBehind = true, straddle = false, offscreen = false, beyondFar = true;
  double lu = 0, lv = 0, motion = 0;  // raster lengths in pixels
  double cu = 0, cv = 0;              // camera-space lengths (for eye splits)
};

class Splitter {
 public:
  Splitter(const Primitive& p, const std::vector<double>& knots, const store::Camera& cam, const DiceOptions& o, std::vector<Leaf>& out, DiceStats& stats)
      : p_(p), proj_(cam), cam_(cam), o_(o), out_(out), stats_(stats) {
    for (double t : knots) {
      shapes_.push_back(p.shapeAt(t));
      mats_.push_back(p.xform->at(t));
    }
    const Attributes& a = *p.attrs;
    const double mf = o.motionFactor ? *o.motionFactor : a.motionFactor;
    motionFactor_ = mf;
    rate_ = a.shadingRate * o.shadingRateScale;
    const double mx = o.cullMargin * cam.width, my = o.cullMargin * cam.height;
    window_[0] = -mx, window_[1] = cam.width + mx, window_[2] = -my, window_[3] = cam.height + my;
  }

  void run() { split(0, 1, 0, 1, 0, 0); }

 private:
  static constexpr int kTest = 5;

  Estimate estimate(double u0, double u1, double v0, double v1) const {
    Estimate e;
    const size_t K = shapes_.size();
    glm::dvec2 r[kTest][kTest], prev[kTest][kTest];
    bool fr[kTest][kTest], prevFront[kTest][kTest];
    double bb[4] = {1e300, -1e300, 1e300, -1e300};
    for (size_t k = 0; k < K; ++k) {
      glm::dvec3 c[kTest][kTest];
      int nFront = 0;
      for (int j = 0; j < kTest; ++j)
        for (int i = 0; i < kTest; ++i) {
          const double u = u0 + (u1 - u0) * i / (kTest - 1), v = v0 + (v1 - v0) * j / (kTest - 1);
          c[j][i] = glm::dvec3(mats_[k] * glm::dvec4(evalP(p_, shapes_[k], u, v), 1.0));
          fr[j][i] = !proj_.perspective || c[j][i].z >= proj_.nearClip;
          if (c[j][i].z <= cam_.farClip) e.beyondFar = false;
          r[j][i] = glm::dvec2(0.0);
          if (fr[j][i]) {
            ++nFront;
            r[j][i] = proj_.project(c[j][i]);
            bb[0] = std::min(bb[0], r[j][i].x), bb[1] = std::max(bb[1], r[j][i].x);
            bb[2] = std::min(bb[2], r[j][i].y), bb[3] = std::max(bb[3], r[j][i].y);
          }
        }
      if (nFront) e.allBehind = false;
      if (nFront && nFront < kTest * kTest) e.straddle = true;
      // The longest test segment times the segment count: dicing steps are uniform in the
      // parameter, so the fastest-moving stretch (near a silhouette fold, say) sets the step.
      for (int j = 0; j < kTest; ++j) {
        double lu = 0, lv = 0, cu = 0, cv = 0;
        for (int i = 0; i + 1 < kTest; ++i) {
          if (fr[j][i] && fr[j][i + 1]) lu = std::max(lu, (kTest - 1) * glm::length(r[j][i + 1] - r[j][i]));
          if (fr[i][j] && fr[i + 1][j]) lv = std::max(lv, (kTest - 1) * glm::length(r[i + 1][j] - r[i][j]));
          cu += glm::length(c[j][i + 1] - c[j][i]);
          cv += glm::length(c[i + 1][j] - c[i][j]);
        }
        e.lu = std::max(e.lu, lu), e.lv = std::max(e.lv, lv);
        e.cu = std::max(e.cu, cu), e.cv = std::max(e.cv, cv);
      }
      if (k > 0)
        for (int j = 0; j < kTest; ++j)
          for (int i = 0; i < kTest; ++i)
            if (fr[j][i] && prevFront[j][i]) e.motion = std::max(e.motion, glm::length(r[j][i] - prev[j][i]));
      for (int j = 0; j < kTest; ++j)
        for (int i = 0; i < kTest; ++i) prev[j][i] = r[j][i], prevFront[j][i] = fr[j][i];
    }
    if (!e.allBehind) {
      // Curved pieces bulge between test points: pad the bound by a tenth of its size.
      const double px = 0.1 * (bb[1] - bb[0]) + 1, py = 0.1 * (bb[3] - bb[2]) + 1;
      e.offscreen = bb[1] + px < window_[0] || bb[0] - px > window_[1] || bb[3] + py < window_[2] || bb[2] - py > window_[3];
    }
    return e;
  }

  void split(double u0, double u1, double v0, double v1, int depth, int eyeDepth) {
    const Estimate e = estimate(u0, u1, v0, v1);
    if (e.allBehind || e.beyondFar || e.offscreen) {
      ++stats_.culledPieces;
      return;
    }
    if (e.straddle) {
      if (eyeDepth >= o_.maxEyeSplits || depth >= o_.maxSplitDepth) {
        ++stats_.culledPieces;
        return;
      }
      ++stats_.eyeSplits;
      if (e.cu >= e.cv) {
        const double um = 0.5 * (u0 + u1);
        split(u0, um, v0, v1, depth + 1, eyeDepth + 1);
        split(um, u1, v0, v1, depth + 1, eyeDepth + 1);
      } else {
        const double vm = 0.5 * (v0 + v1);
        split(u0, u1, v0, vm, depth + 1, eyeDepth + 1);
        split(u0, u1, vm, v1, depth + 1, eyeDepth + 1);
      }
      return;
    }
    const double rate = rate_ * (1.0 + motionFactor_ * e.motion / 16.0);
    const double edge = std::sqrt(rate);
    const double G = o_.maxGridSize;
    const double nu = std::max(1.0, std::ceil(e.lu / edge)), nv = std::max(1.0, std::ceil(e.lv / edge));
    if ((nu > G || nv > G) && depth < o_.maxSplitDepth) {
      // Cut the dimension that overflows most into pieces of at most G (re-measured below).
      if (nu / G >= nv / G) {
        const int k = int(std::min(64.0, std::ceil(nu / G)));
        for (int i = 0; i < k; ++i) split(u0 + (u1 - u0) * i / k, i + 1 == k ? u1 : u0 + (u1 - u0) * (i + 1) / k, v0, v1, depth + 1, eyeDepth);
      } else {
        const int k = int(std::min(64.0, std::ceil(nv / G)));
        for (int i = 0; i < k; ++i) split(u0, u1, v0 + (v1 - v0) * i / k, i + 1 == k ? v1 : v0 + (v1 - v0) * (i + 1) / k, depth + 1, eyeDepth);
      }
      return;
    }
    // A disc needs a few steps around to have an area at all.
    const double minU = p_.kind == PrimKind::Point ? 8 : 1;
    Leaf leaf{u0, u1, v0, v1, int(std::min(std::max(nu, minU), G)), int(std::min(nv, G))};
    out_.push_back(leaf);
    ++stats_.leaves;
  }

  const Primitive& p_;
  store::Projector proj_;
  const store::Camera& cam_;
  const DiceOptions& o_;
  std::vector<Leaf>& out_;
  DiceStats& stats_;
  std::vector<Shape> shapes_;
  std::vector<glm::dmat4> mats_;
  double rate_ = 1, motionFactor_ = 0;
  double window_[4];
};

}  // namespace

void splitPrimitive(const Primitive& p, const std::vector<double>& knots, const store::Camera& camera, const DiceOptions& options, std::vector<Leaf>& out,
                    DiceStats& stats) {
  Splitter(p, knots, camera, options, out, stats).run();
}

void diceLeaf(const Primitive& p, const Leaf& leaf, const std::vector<double>& knots, double shadeAt, double nearClip, bool perspective, DicedGrid& g) {
  const int nu = leaf.nu, nv = leaf.nv, row = nu + 1;
  const uint32_t nV = uint32_t(row * (nv + 1));
  const size_t K = knots.size();
  g.nu = nu, g.nv = nv, g.numVertices = nV;
  g.positions.resize(K * nV);
  // Parameters at the grid lines; the last is the piece's edge exactly, so neighbouring grids
  // evaluate identical points on their shared edge.
  std::vector<double> us(size_t(nu) + 1), vs(size_t(nv) + 1);
  for (int i = 0; i <= nu; ++i) us[size_t(i)] = i == nu ? leaf.u1 : leaf.u0 + (leaf.u1 - leaf.u0) * i / nu;
  for (int j = 0; j <= nv; ++j) vs[size_t(j)] = j == nv ? leaf.v1 : leaf.v0 + (leaf.v1 - leaf.v0) * j / nv;

  for (size_t k = 0; k < K; ++k) {
    const Shape s = p.shapeAt(knots[k]);
    const glm::dmat4 m = p.xform->at(knots[k]);
    glm::vec3* out = g.positions.data() + k * nV;
    for (int j = 0; j <= nv; ++j)
      for (int i = 0; i <= nu; ++i) out[j * row + i] = glm::vec3(m * glm::dvec4(evalP(p, s, us[size_t(i)], vs[size_t(j)]), 1.0));
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
  for (int j = 0; j <= nv; ++j)
    for (int i = 0; i <= nu; ++i) {
      const size_t idx = size_t(j * row + i);
      const double u = us[size_t(i)], v = vs[size_t(j)];
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
  // handedness and the orientation is not flipped, reversed otherwise.
  const bool reverse = (glm::determinant(m) < 0) != p.flipNormals;
  g.corners.clear();
  g.corners.reserve(size_t(nu) * nv * 4);
  g.droppedMicropolygons = 0;
  for (int j = 0; j < nv; ++j)
    for (int i = 0; i < nu; ++i) {
      const uint32_t p0 = uint32_t(j * row + i), p1 = p0 + 1, p2 = p0 + 1 + uint32_t(row), p3 = p0 + uint32_t(row);
      uint32_t c[4];
      const bool tri = p.triangle && j == nv - 1 && leaf.v1 == 1.0;  // the collapsed last row of a triangle
      if (tri) {
        c[0] = p0, c[1] = reverse ? p3 : p1, c[2] = reverse ? p1 : p2, c[3] = store::kNoCorner;
      } else if (reverse) {
        c[0] = p0, c[1] = p3, c[2] = p2, c[3] = p1;
      } else {
        c[0] = p0, c[1] = p1, c[2] = p2, c[3] = p3;
      }
      if (perspective) {
        const int nc = tri ? 3 : 4;
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
