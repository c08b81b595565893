// Built-in RenderMan standard shaders and lights (formulas and conventions in shaders.h).
#include "shade/shaders.h"

#include <algorithm>
#include <cmath>

#include <glm/geometric.hpp>
#include <glm/mat3x3.hpp>
#include <glm/matrix.hpp>

namespace reshutter::shade {

namespace {
double smoothstep(double e0, double e1, double x) {
  if (e0 == e1) return x < e0 ? 0.0 : 1.0;
  double t = std::clamp((x - e0) / (e1 - e0), 0.0, 1.0);
  return t * t * (3 - 2 * t);
}
}  // namespace

LitLight resolveLight(const Light& l, double time) {
  LitLight r;
  r.kind = l.kind;
  r.Cl0 = l.intensity * l.color;
  const glm::dmat4 m = l.xform.at(time);
  const glm::dvec3 from = glm::dvec3(m * glm::dvec4(l.from, 1.0));
  const glm::dvec3 to = glm::dvec3(m * glm::dvec4(l.to, 1.0));
  r.position = from;
  glm::dvec3 axis = to - from;
  double len = glm::length(axis);
  r.axis = len > 0 ? axis / len : glm::dvec3(0, 0, 1);
  r.cosOuter = std::cos(l.coneAngle);
  r.cosInner = std::cos(l.coneAngle - l.coneDeltaAngle);
  r.beam = l.beamDistribution;
  if (l.kind == LightKind::Point && l.oneSided) r.kind = LightKind::Face;
  r.shadows = l.shadows;
  r.shape = l.shape;
  r.tanHalfAngle = std::tan(std::clamp(l.angle, 0.0, 3.0) / 2);
  if (l.kind == LightKind::Uber) {
    r.toLight = glm::inverse(m);
    r.uber = l.uber;
  }
  if (l.shape != LightShape::Point) {
    r.halfU = glm::dvec3(m * glm::dvec4(l.width / 2, 0, 0, 0));
    r.halfV = glm::dvec3(m * glm::dvec4(0, (l.shape == LightShape::Rect ? l.height : l.width) / 2, 0, 0));
    if (l.radiance) {
      // The emitter's area in camera space (a sphere's: its projected disc).
      const double cross = glm::length(glm::cross(r.halfU, r.halfV));
      const double pi = 3.14159265358979323846;
      r.Cl0 *= l.shape == LightShape::Rect ? 4 * cross : l.shape == LightShape::Disk ? pi * cross : pi * glm::dot(r.halfU, r.halfU);
    }
  }
  return r;
}

namespace {
// uberlight apart, and never inlined: illuminate() stays small enough to inline into the
// diffuse and specular loops, where every other light is evaluated.
[[gnu::noinline]] bool illuminateUber(const LitLight& l, const glm::dvec3& P, glm::dvec3& L, glm::dvec3& Cl) {
  const UberLight& u = l.uber;
  const glm::dvec3 Pl(l.toLight * glm::dvec4(P, 1.0));
  const double len = glm::length(Pl);
  if (u.parallel) L = -l.axis;
  else L = l.position - P;
  if (!(len > 0) || !(glm::dot(L, L) > 0)) return false;
  // Cut on and off along the beam, each with a soft edge.
  double atten = smoothstep(u.cuton - u.nearedge, u.cuton, Pl.z) * (1 - smoothstep(u.cutoff, u.cutoff + u.faredge, Pl.z));
  if (u.falloff != 0) {  // beyond falloffdist 1/d^falloff; nearer, rising smoothly to maxintensity
    if (len > u.falloffdist) {
      atten *= std::pow(u.falloffdist / len, u.falloff);
    } else if (u.maxintensity > 0) {
      const double s = std::log(1 / u.maxintensity);
      atten *= s == 0 ? u.maxintensity : u.maxintensity * std::exp(s * std::pow(len / u.falloffdist, -u.falloff / s));
    }
  }
  if (!u.omni) {
    if (!u.parallel && !(Pl.z > 0)) return false;
    // The beam's cross-section: a superellipse of half-sizes width × height, its soft edge
    // out to (width + wedge) × (height + hedge), at unit distance (or on the plane, parallel).
    const double x = std::abs((u.parallel ? Pl.x : Pl.x / Pl.z) - u.shearx), y = std::abs((u.parallel ? Pl.y : Pl.y / Pl.z) - u.sheary);
    double clipped = 0;
    if (x != 0 || y != 0) {
      const double a = u.width, b = u.height, A = u.width + u.wedge, B = u.height + u.hedge;
      if (u.roundness < 1e-6) {
        clipped = 1 - (1 - smoothstep(a, A, x)) * (1 - smoothstep(b, B, y));
      } else {
        const double re = 2 / u.roundness;
        const double inner = a * b * std::pow(std::pow(b * x, re) + std::pow(a * y, re), -1 / re);
        const double outer = A * B * std::pow(std::pow(B * x, re) + std::pow(A * y, re), -1 / re);
        clipped = smoothstep(inner, outer, 1);
      }
    }
    atten *= 1 - clipped;
    if (u.beamdistribution != 0) atten *= std::pow(std::abs(Pl.z) / len, u.beamdistribution);
  }
  if (!(atten > 0)) return false;
  Cl = l.Cl0 * atten;
  return true;
}
}  // namespace

bool illuminate(const LitLight& l, const glm::dvec3& P, glm::dvec3& L, glm::dvec3& Cl) {
  // The common lights first, by comparison: a switch over every kind compiles to an indirect
  // jump that cost scenes of point lights 0.3 % of their shading (cachegrind).
  if (l.kind == LightKind::Point) {
    L = l.position - P;
    double d2 = glm::dot(L, L);
    if (!(d2 > 0)) return false;
    Cl = l.Cl0 / d2;
    return true;
  }
  if (l.kind == LightKind::Distant) {
    L = -l.axis;
    Cl = l.Cl0;
    return true;
  }
  switch (l.kind) {
    case LightKind::Ambient:
    case LightKind::Point:
    case LightKind::Distant: return false;
    case LightKind::Face: {  // an area light's face: a point with the emitter's cosine towards P
      L = l.position - P;
      const double d2 = glm::dot(L, L);
      const double emit = -glm::dot(L, l.axis) / std::sqrt(d2);
      if (!(d2 > 0) || !(emit > 0)) return false;
      Cl = l.Cl0 * (emit / d2);
      return true;
    }
    case LightKind::Spot: {
      L = l.position - P;
      double d2 = glm::dot(L, L);
      if (!(d2 > 0)) return false;
      // spotlight.sl: illuminate(from, A, coneangle) with cosangle = (P - from)·A / |P - from|.
      double cosangle = glm::dot(-L, l.axis) / std::sqrt(d2);
      if (cosangle < l.cosOuter) return false;
      const double c = std::max(cosangle, 0.0);
      double atten = (l.beam == 2 ? c * c : std::pow(c, l.beam)) / d2 * smoothstep(l.cosOuter, l.cosInner, cosangle);
      Cl = l.Cl0 * atten;
      return true;
    }
    case LightKind::Uber: return illuminateUber(l, P, L, Cl);
  }
  return false;
}

glm::dvec3 ambient(std::span<const LitLight> lights) {
  glm::dvec3 c(0.0);
  for (const auto& l : lights)
    if (l.kind == LightKind::Ambient) c += l.Cl0;
  return c;
}

glm::dvec3 diffuse(const glm::dvec3& P, const glm::dvec3& Nn, std::span<const LitLight> lights) {
  glm::dvec3 c(0.0), L, Cl;
  for (const auto& l : lights) {
    if (!illuminate(l, P, L, Cl)) continue;
    double cosine = glm::dot(glm::normalize(L), Nn);
    if (cosine > 0) c += Cl * cosine;
  }
  return c;
}

glm::dvec3 specular(const glm::dvec3& P, const glm::dvec3& Nn, const glm::dvec3& V, double roughness, std::span<const LitLight> lights) {
  glm::dvec3 c(0.0), L, Cl;
  const double exponent = 1.0 / std::max(roughness, 1e-6);
  for (const auto& l : lights) {
    if (!illuminate(l, P, L, Cl)) continue;
    glm::dvec3 Ln = glm::normalize(L);
    if (glm::dot(Ln, Nn) <= 0) continue;  // illuminance cone: the hemisphere around Nn
    glm::dvec3 H = Ln + V;
    double hl = glm::length(H);
    if (!(hl > 0)) continue;
    double nh = glm::dot(Nn, H / hl);
    if (nh > 0) c += Cl * std::pow(nh, exponent);
  }
  return c;
}

namespace {
// diffuse() and specular() in one pass over the lights: each light is evaluated once.
void diffuseSpecular(const glm::dvec3& P, const glm::dvec3& Nn, const glm::dvec3& V, double roughness, std::span<const LitLight> lights, glm::dvec3& diff,
                     glm::dvec3& spec) {
  glm::dvec3 L, Cl;
  diff = spec = glm::dvec3(0.0);
  const double exponent = 1.0 / std::max(roughness, 1e-6);
  for (const auto& l : lights) {
    if (!illuminate(l, P, L, Cl)) continue;
    const glm::dvec3 Ln = glm::normalize(L);
    const double cosine = glm::dot(Ln, Nn);
    if (cosine <= 0) continue;
    diff += Cl * cosine;
    glm::dvec3 H = Ln + V;
    const double hl = glm::length(H);
    if (!(hl > 0)) continue;
    const double nh = glm::dot(Nn, H / hl);
    if (nh > 0) spec += Cl * std::pow(nh, exponent);
  }
}
}  // namespace

glm::dvec3 facingNormal(const SurfaceInput& in) {
  const double nl = glm::length(in.N);
  const glm::dvec3 Nn = nl > 0 ? in.N / nl : glm::dvec3(0, 0, -1);
  return glm::dot(in.I, in.Ng) > 0 ? -Nn : Nn;
}

SurfaceOutput shadeSurface(const SurfaceShader& s, const SurfaceInput& in, std::span<const LitLight> lights) {
  SurfaceOutput out;
  out.Oi = in.Os;
  const glm::dvec3 Nf = facingNormal(in);
  const double il = glm::length(in.I);
  const glm::dvec3 V = il > 0 ? -in.I / il : glm::dvec3(0, 0, -1);
  switch (s.kind) {
    case SurfaceKind::Constant: out.Ci = in.Os * in.Cs; break;
    case SurfaceKind::Matte: out.Ci = in.Os * in.Cs * (s.Ka * ambient(lights) + s.Kd * diffuse(in.P, Nf, lights)); break;
    case SurfaceKind::Metal: {
      glm::dvec3 spec = in.Os * in.Cs * s.Ks * specular(in.P, Nf, V, s.roughness, lights);
      out.Ci = in.Os * in.Cs * s.Ka * ambient(lights) + spec;
      out.viewDependent = spec;
      out.specWeight = in.Os * in.Cs * s.Ks, out.specRoughness = std::max(s.roughness, 1e-6);
      break;
    }
    case SurfaceKind::Plastic:
    case SurfaceKind::PaintedPlastic: {  // the texture is already in Cs (the shading pass looks it up)
      glm::dvec3 diff, specular;
      diffuseSpecular(in.P, Nf, V, s.roughness, lights, diff, specular);
      glm::dvec3 spec = in.Os * s.specularColor * s.Ks * specular;
      out.Ci = in.Os * in.Cs * (s.Ka * ambient(lights) + s.Kd * diff) + spec;
      out.viewDependent = spec;
      out.specWeight = in.Os * s.specularColor * s.Ks, out.specRoughness = std::max(s.roughness, 1e-6);
      break;
    }
    case SurfaceKind::DefaultSurface: {
      // defaultsurface.sl: a headlight, (I·N)² / (I·I · N·N).
      double in2 = glm::dot(in.I, in.I) * glm::dot(in.N, in.N);
      double d = in2 > 0 ? glm::dot(in.I, in.N) * glm::dot(in.I, in.N) / in2 : 0.0;
      glm::dvec3 head = in.Os * in.Cs * s.Kd * d;
      out.Ci = in.Os * in.Cs * s.Ka + head;
      out.viewDependent = head;
      out.specWeight = in.Os * in.Cs * s.Kd, out.specRoughness = -1;
      break;
    }
  }
  return out;
}

}  // namespace reshutter::shade
