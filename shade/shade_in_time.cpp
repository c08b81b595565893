// Shading in time (shade/shade_grid.h): which grids may shade differently over the shutter,
// decided from what the scene says changes, and shading them at the other times.
#include <algorithm>
#include <cmath>

#include <glm/gtc/matrix_inverse.hpp>
#include <glm/matrix.hpp>

#include "shade/shade_grid.h"

namespace reshutter::shade::pass {

namespace {

/// Whether every vertex moves by the same offset (a rigid translation in camera space).
bool translatesRigidly(std::span<const glm::vec3> P, size_t nV, size_t K) {
  float scale = 0;
  for (const glm::vec3& p : P) scale = std::max({scale, std::abs(p.x), std::abs(p.y), std::abs(p.z)});
  const float eps = 1e-5f * scale;
  for (size_t k = 1; k < K; ++k) {
    const glm::vec3 d = P[k * nV] - P[0];
    for (size_t v = 1; v < nV; ++v) {
      const glm::vec3 e = P[k * nV + v] - P[v] - d;
      if (std::abs(e.x) > eps || std::abs(e.y) > eps || std::abs(e.z) > eps) return false;
    }
  }
  return true;
}

/// Grid `g`, diced at the shading time `shadeAt`, as diceLeaf() would dice it at time `t` when
/// its primitive moves rigidly: its shading geometry carried by M(t) · M(shadeAt)^-1, the same up
/// to rounding without evaluating the surface again. False when the primitive's shape changes
/// over time (deformation keys, a camera-facing kind), a transform is nearly singular, or the
/// motion turns it inside out (the dicing's winding changes, so the grid is diced again and
/// found to differ).
bool carryRigidly(const Primitive& p, const DicedGrid& g, double shadeAt, double t, DicedGrid& out) {
  if (p.times.size() > 1 || p.kind == PrimKind::Curve || p.kind == PrimKind::Point) return false;
  const glm::dmat4 from = p.xform->at(shadeAt), to = p.xform->at(t);
  if (!wellInvertible(from) || !wellInvertible(to) || (glm::determinant(from) < 0) != (glm::determinant(to) < 0)) return false;
  const glm::dmat4 R = to * glm::inverse(from);
  const glm::dmat3 normals = glm::inverseTranspose(glm::dmat3(R));
  const size_t nV = g.numVertices;
  out.nu = g.nu, out.nv = g.nv, out.numVertices = g.numVertices;
  out.positions.clear(), out.corners.clear();
  out.P.resize(nV), out.N.resize(nV), out.Ng.resize(nV);
  auto carryNormal = [&](const glm::dvec3& n) {
    const glm::dvec3 m = normals * n;
    const double len = glm::length(m);
    return len > 0 ? m / len : n;
  };
  for (size_t i = 0; i < nV; ++i) {
    out.P[i] = glm::dvec3(R * glm::dvec4(g.P[i], 1.0));
    out.N[i] = carryNormal(g.N[i]), out.Ng[i] = carryNormal(g.Ng[i]);
  }
  out.u = g.u, out.v = g.v, out.s = g.s, out.t = g.t;
  return true;
}

}  // namespace

bool wellInvertible(const glm::dmat4& m) {
  const double det = glm::determinant(glm::dmat3(m));
  const double longest = std::max({glm::length(glm::dvec3(m[0])), glm::length(glm::dvec3(m[1])), glm::length(glm::dvec3(m[2]))});
  return std::isfinite(det) && std::isfinite(longest) && std::abs(det) > 1e-9 * longest * longest * longest;
}

bool animated(const Attributes& a) { return a.color.values.size() > 1 || a.opacity.values.size() > 1 || a.surface.values.size() > 1; }

bool lightMoves(const Light& l, double open, double close) { return l.xform.moving() && l.xform.at(open) != l.xform.at(close); }

/// Whether grid `g` of primitive `pi` (lights: the indices into the frame's lights that light
/// it) can shade differently at another time of the interval - decided from what the scene says
/// moves or changes, conservatively: shading at the other times then confirms it. A grid that
/// stands still under fixed lights, an unlit constant one, and a matte one translating rigidly
/// under fixed distant lights that cast no shadows cannot.
bool mayShadeDifferently(const ShadeContext& c, uint32_t pi, std::span<const glm::vec3> positions, uint32_t nV, bool moves, std::span<const uint32_t> lights) {
  const Attributes& a = *c.scene.prims[pi].attrs;
  if (animated(a)) return true;
  const SurfaceShader& sh = a.surface.values[0];
  if (sh.kind == SurfaceKind::Constant) return false;
  const bool lit = usesLights(sh.kind);
  bool shadowed = false, local = false;
  if (lit)
    for (uint32_t li : lights) {
      if (li >= c.lit.size()) continue;
      if (c.lightMoves[li]) return true;
      shadowed |= c.shadows && c.lit[li].shadows;
      local |= c.lit[li].kind != LightKind::Distant && c.lit[li].kind != LightKind::Ambient;
    }
  if (shadowed && !c.movingCasters.empty()) {  // a moving caster's shadow may move over it
    ShadowBox recv;
    for (const glm::vec3& q : positions) recv.add(q);
    for (uint32_t li : lights)
      if (c.movingCasters.mayShadow(li, recv)) return true;
  }
  if (!moves) return false;
  if (sh.kind != SurfaceKind::Matte) return true;  // view-dependent terms (or defaultsurface's headlight)
  return shadowed || local || !translatesRigidly(positions, nV, c.split.knots[pi].size());
}

/// Whether grid-level shading can change only through moving casters' shadows: the grid stands
/// still, nothing of its primitive is animated and none of its lights moves (ShadowReuse).
bool onlyShadowsChange(const ShadeContext& c, uint32_t pi, bool moves, std::span<const uint32_t> lights) {
  if (moves || animated(*c.scene.prims[pi].attrs)) return false;
  return std::none_of(lights.begin(), lights.end(), [&](uint32_t li) { return li < c.lightMoves.size() && c.lightMoves[li]; });
}

/// Shading in time for one grid already shaded at the first time into `out` (`moves`: its
/// positions differ between knots; `reuse`: the first time's shadow rays, for a grid that only
/// shadows change): shades it at the other times and keeps them ("Ci@k", "Oi@k", and "name@k"
/// for the output variables carried in time) when the colour or opacity changes by more than the
/// tolerance. Returns whether it kept them.
///
/// The times are refined by bisection: the close first, then the middle of each span whose
/// ends are shaded; where the middle's colour lies within the tolerance of the blend of its
/// ends, the span's other times are blended too rather than shaded (linear between the shaded
/// times, as the re-sampler blends them). Tolerance 0 shades every time.
bool shadeInTime(const ShadeContext& c, uint32_t pi, const Leaf& leaf, const DicedGrid& g, bool moves, std::span<const uint32_t> lightIdx, uint64_t leafIndex,
                 GridOut& out, uint64_t& shadowRays, ShadowReuse* reuse, uint64_t& blendedTimes, uint64_t& carriedTimes) {
  const Primitive& p = c.scene.prims[pi];
  const size_t T = c.times.size();
  std::vector<std::vector<std::vector<float>>> at(T);
  DicedGrid gk;
  std::vector<LitLight> lights;
  float change = 0;
  if (reuse) reuse->recording = false, reuse->first = &out.attrs;
  const int slots[2] = {c.ci, c.oi};
  auto values = [&](size_t k, int slot) -> std::vector<float>& { return k == 0 ? out.attrs[size_t(slot)] : at[k][size_t(slot)]; };
  // Shades time k into at[k]; false when the grid dices differently there (no blend).
  auto shadeTime = [&](size_t k) {
    // A grid that stands still has the same shading geometry at every time (only its lights,
    // shadows and shader can differ): no second dicing.
    const DicedGrid* geometry = &g;
    if (moves) {
      if (carryRigidly(p, g, c.shadeAt, c.times[k], gk)) {
        ++carriedTimes;
      } else {
        diceLeaf(p, leaf, c.split.knots[pi], c.times[k], c.nearClip, c.perspective, gk);
        if (gk.numVertices != g.numVertices || gk.corners != out.corners) return false;
      }
      geometry = &gk;
    }
    lights.clear();
    for (uint32_t li : lightIdx)  // reusing: the lights stand still, and the first time's rays need the first time's lights
      if (li < c.lit.size()) lights.push_back(reuse ? c.lit[li] : c.litAt[k][li]);
    shadeVertices(c, p, *geometry, out.corners, lights, c.times[k], k, leafIndex, at[k], shadowRays, reuse);
    for (int slot : slots) {
      const std::vector<float>& a = values(0, slot);
      const std::vector<float>& b = values(k, slot);
      for (size_t i = 0; i < a.size(); ++i) change = std::max(change, std::abs(b[i] - a[i]));
    }
    return true;
  };
  // Times lo < k < hi blended between lo and hi (every attribute carried in time).
  auto blend = [&](size_t lo, size_t hi) {
    for (size_t k = lo + 1; k < hi; ++k) {
      const float w = float((c.times[k] - c.times[lo]) / (c.times[hi] - c.times[lo]));
      at[k].resize(out.attrs.size());
      for (const std::vector<int>& timed : c.timedSlots) {
        const int slot = timed[0];
        const std::vector<float>& a = values(lo, slot);
        const std::vector<float>& b = values(hi, slot);
        std::vector<float>& v = at[k][size_t(slot)];
        v.resize(a.size());
        for (size_t i = 0; i < a.size(); ++i) v[i] = a[i] + w * (b[i] - a[i]);
      }
      ++blendedTimes;
    }
  };
  // Refines span [lo, hi] (both shaded); false as shadeTime().
  auto refine = [&](auto&& self, size_t lo, size_t hi) -> bool {
    if (hi - lo < 2) return true;
    const size_t mid = (lo + hi) / 2;
    if (!shadeTime(mid)) return false;
    if (c.tolerance > 0) {
      const float w = float((c.times[mid] - c.times[lo]) / (c.times[hi] - c.times[lo]));
      float off = 0;
      for (int slot : slots) {
        const std::vector<float>& a = values(lo, slot);
        const std::vector<float>& b = values(hi, slot);
        const std::vector<float>& m = values(mid, slot);
        for (size_t i = 0; i < a.size(); ++i) off = std::max(off, std::abs(m[i] - (a[i] + w * (b[i] - a[i]))));
      }
      if (off <= c.tolerance) {
        blend(lo, mid), blend(mid, hi);
        return true;
      }
    }
    return self(self, lo, mid) && self(self, mid, hi);
  };
  if (!shadeTime(T - 1) || !refine(refine, 0, T - 1)) return false;
  if (!(change > c.tolerance) && c.tolerance > 0) return false;
  for (size_t k = 1; k < T; ++k)
    for (const std::vector<int>& timed : c.timedSlots) out.attrs[size_t(timed[k])] = std::move(at[k][size_t(timed[0])]);
  return true;
}

/// Whether anything in the scene can make shading differ over [open, close]: a light that moves
/// in camera space, an animated colour, opacity or shader, or a primitive that moves or deforms
/// under a shader that is not constant.
bool sceneMayShadeInTime(const FrameScene& scene, double open, double close) {
  for (const Light& l : scene.lights)
    if (lightMoves(l, open, close)) return true;
  const Attributes* seen = nullptr;
  for (const Primitive& p : scene.prims) {
    const Attributes& a = *p.attrs;
    if (&a != seen) {
      seen = &a;
      if (animated(a)) return true;
    }
    if (a.surface.values[0].kind != SurfaceKind::Constant && !p.knotTimes().empty() && clipKnots(p, open, close).size() > 1) return true;
  }
  return false;
}

}  // namespace reshutter::shade::pass
