// Shading one diced grid's vertices at one time (shade/shade_grid.h).
#include <algorithm>
#include <array>
#include <cmath>

#include "common/error.h"
#include "common/random.h"
#include "shade/shade_grid.h"

namespace reshutter::shade::pass {

Var varOf(const std::string& name) {
  if (store::StoreMeta::timedIndex(name)) return Var::Timed;
  static const std::pair<const char*, Var> table[] = {{"Ci", Var::Ci},
                                                      {"Oi", Var::Oi},
                                                      {"P", Var::P},
                                                      {"N", Var::N},
                                                      {"Ng", Var::Ng},
                                                      {"s", Var::s},
                                                      {"t", Var::t},
                                                      {"u", Var::u},
                                                      {"v", Var::v},
                                                      {"Cs", Var::Cs},
                                                      {"Os", Var::Os},
                                                      {"depth", Var::depth},
                                                      {"specular", Var::specular},
                                                      {store::ViewTerm::kViewIndependent, Var::Cvi},
                                                      {store::ViewTerm::kBackSide, Var::CviBack},
                                                      {store::ViewTerm::kWeight, Var::Kspec},
                                                      {store::ViewTerm::kNormal, Var::Nspec},
                                                      {store::ViewTerm::kRoughness, Var::roughness}};
  for (const auto& [n, v] : table)
    if (name == n) return v;
  if (name.rfind("Lvis.", 0) == 0) return Var::Lvis;
  fail("schema", "output variable '", name, "' is not computable");
}

namespace {

void put3(std::vector<float>& dst, size_t i, const glm::dvec3& v) { dst[i * 3 + 0] = float(v.x), dst[i * 3 + 1] = float(v.y), dst[i * 3 + 2] = float(v.z); }

// A non-finite shading result (a light at the shaded point, an overflow) would poison the store:
// the writer rejects it. Clamp to zero here, where the cause is known.
glm::dvec3 finite(const glm::dvec3& c) { return {std::isfinite(c.x) ? c.x : 0.0, std::isfinite(c.y) ? c.y : 0.0, std::isfinite(c.z) ? c.z : 0.0}; }

/// What the view-dependent terms' inputs need beyond the shading itself: the unit shading normal,
/// the rest of Ci lit on each side of it, and per stored light its share reaching the vertex.
struct ViewInputs {
  glm::dvec3 N{0, 0, -1}, front{0.0}, back{0.0};
  std::span<const float> visibility;
};

/// The rest of Ci (less its view-dependent term) lit on the side of `in` that unit normal N points
/// to: the shader run with the eye placed on that side.
glm::dvec3 litOnSide(const SurfaceShader& shader, SurfaceInput in, const glm::dvec3& N, std::span<const LitLight> lights) {
  in.Ng = N, in.N = N, in.I = -N;
  const SurfaceOutput so = shadeSurface(shader, in, lights);
  return so.Ci - so.viewDependent;
}

/// Vertex i's output variables into `attrs` (parallel to the schema), but for the view-dependent
/// terms' inputs (storeViewInputs).
void storeOutputs(const std::vector<Var>& vars, const DicedGrid& g, size_t i, const SurfaceInput& in, const SurfaceOutput& so,
                  std::vector<std::vector<float>>& attrs) {
  for (size_t ai = 0; ai < vars.size(); ++ai) {
    auto& dst = attrs[ai];
    switch (vars[ai]) {
      case Var::Ci: put3(dst, i, finite(so.Ci)); break;
      case Var::Oi: put3(dst, i, finite(so.Oi)); break;
      case Var::P: put3(dst, i, g.P[i]); break;
      case Var::N: put3(dst, i, g.N[i]); break;
      case Var::Ng: put3(dst, i, g.Ng[i]); break;
      case Var::s: dst[i] = float(g.s[i]); break;
      case Var::t: dst[i] = float(g.t[i]); break;
      case Var::u: dst[i] = float(g.u[i]); break;
      case Var::v: dst[i] = float(g.v[i]); break;
      case Var::Cs: put3(dst, i, in.Cs); break;
      case Var::Os: put3(dst, i, in.Os); break;
      case Var::depth: dst[i] = float(g.P[i].z); break;
      case Var::specular: put3(dst, i, finite(so.viewDependent)); break;
      default: break;  // Timed: shade_in_time.cpp fills it; the view-dependent inputs: storeViewInputs
    }
  }
}

/// Vertex i's view-dependent terms' inputs into `attrs`, on a grid that has them.
void storeViewInputs(const ShadeContext& c, size_t i, const SurfaceOutput& so, const ViewInputs& view, std::vector<std::vector<float>>& attrs) {
  for (size_t ai = 0; ai < c.vars.size(); ++ai) {
    auto& dst = attrs[ai];
    switch (c.vars[ai]) {
      case Var::Cvi: put3(dst, i, finite(view.front)); break;
      case Var::CviBack: put3(dst, i, finite(view.back)); break;
      case Var::Kspec: put3(dst, i, finite(so.specWeight)); break;
      case Var::Nspec: put3(dst, i, finite(view.N)); break;
      case Var::roughness: dst[i] = float(so.specRoughness); break;
      case Var::Lvis: dst[i] = view.visibility[size_t(c.varLight[ai])]; break;
      default: break;
    }
  }
}

}  // namespace

void shadowBias(const DicedGrid& g, std::span<const uint32_t> corners, std::vector<float>& bias) {
  const size_t nV = g.numVertices;
  bias.assign(nV, 0.f);
  for (size_t m = 0; m + 4 <= corners.size(); m += 4) {
    const uint32_t* q = &corners[m];
    const int n = q[3] == store::kNoCorner ? 3 : 4;
    for (int j = 0; j < n; ++j) {
      const uint32_t v = q[j], w = q[(j + 1) % n];
      if (v >= nV || w >= nV) continue;
      const float half = float(0.5 * glm::length(g.P[w] - g.P[v]));
      bias[v] = std::max(bias[v], half), bias[w] = std::max(bias[w], half);
    }
  }
}

void shadeVertices(const ShadeContext& c, const Primitive& p, const DicedGrid& g, std::span<const uint32_t> corners, std::span<const LitLight> lights,
                   double time, size_t k, uint64_t leafIndex, std::vector<std::vector<float>>& attrs, RayCounts& rayCounts, ShadowReuse* reuse,
                   std::span<const uint8_t> movingShadows, std::span<const uint32_t> only, std::vector<float>& bias) {
  const Attributes& a = *p.attrs;
  const SurfaceShader shader = a.surface.at(time);
  // A RIS material's own colour and presence replace the primitive's.
  const glm::dvec3 Cs0 = shader.color ? *shader.color : a.color.at(time), Os0 = shader.opacity ? *shader.opacity : a.opacity.at(time);
  std::array<glm::dvec3, 4> cornerCs, cornerOs;
  const bool hasCs = !shader.color && p.mesh && p.corners(p.mesh->Cs, cornerCs);
  const bool hasOs = !shader.opacity && p.mesh && p.corners(p.mesh->Os, cornerOs);
  const bool traces = c.shadows && usesLights(shader.kind) && std::any_of(lights.begin(), lights.end(), [](const LitLight& l) { return l.shadows; });
  const size_t nV = g.numVertices;
  // A textured surface filters each vertex's lookup over the st span of a micropolygon it
  // corners: its two sides from that corner (the shading rate's footprint).
  struct Footprint {
    float dsdx = 0, dtdx = 0, dsdy = 0, dtdy = 0;
  };
  std::vector<Footprint> footprint;
  TextureLookup::Map map;
  // Shading some vertices only: what the others would need is not made.
  std::vector<uint8_t> wanted;
  if (!only.empty()) {
    wanted.assign(nV, 0);
    for (uint32_t i : only) wanted[i] = 1;
  }
  auto unwanted = [&](uint32_t v) { return !wanted.empty() && !wanted[v]; };
  // A later time reusing the first time's rays lifts none; the lifts of one time serve every call
  // at that time (the coarse lattice, then its refinement).
  const bool reusing = reuse && !reuse->recording;
  if (traces && !reusing && bias.empty()) shadowBias(g, corners, bias);
  std::vector<LitLight> shadowed;
  if (traces) shadowed.assign(lights.begin(), lights.end());
  if (c.textures && !shader.textureName.empty()) {
    map = c.textures->find(shader.textureName);
    footprint.resize(nV);
    std::vector<uint8_t> set(nV, 0);
    // The grid's corners have moved to its GridOut already (shadeBatch).
    for (size_t m = 0; m + 4 <= corners.size(); m += 4) {
      const uint32_t* q = &corners[m];
      const int n = q[3] == store::kNoCorner ? 3 : 4;
      for (int j = 0; j < n; ++j) {
        const uint32_t v = q[j], a = q[(j + 1) % n], b = q[(j + n - 1) % n];
        if (v >= nV || a >= nV || b >= nV || set[v] || unwanted(v)) continue;
        footprint[v] = {float(g.s[a] - g.s[v]), float(g.t[a] - g.t[v]), float(g.s[b] - g.s[v]), float(g.t[b] - g.t[v])};
        set[v] = 1;
      }
    }
  }
  attrs.resize(c.vars.size());
  // The view-dependent term's inputs only where the shader has such a term (absent elsewhere).
  const bool viewTerm = viewDependentKind(shader.kind), keepView = viewTerm && c.viewInputs;
  for (size_t ai = 0; ai < c.vars.size(); ++ai)
    if (c.vars[ai] != Var::Timed && (viewTerm || c.vars[ai] < Var::Cvi)) attrs[ai].resize(nV * size_t(store::componentCount(c.schema.attrs[ai].type)));
  // Per stored light, its share reaching the vertex: 1 for the grid's lights until a shadow ray
  // says less, 0 for the others (kept only for the view-dependent terms' inputs).
  std::vector<float> visibility(keepView ? c.lit.size() : 0, 0.f);
  if (reuse && reuse->recording) reuse->visibility.assign(nV * lights.size(), 1.f), reuse->traced.assign(nV * lights.size(), {}), reuse->open.clear();
  std::vector<ShadowRay> rays;
  const bool anyMoves = c.shadows && c.shadows->moves();
  auto movingMayShadow = [&](size_t li) { return anyMoves && (movingShadows.empty() || (li < movingShadows.size() && movingShadows[li])); };
  const size_t count = only.empty() ? nV : only.size();
  for (size_t n = 0; n < count; ++n) {
    const size_t i = only.empty() ? n : only[n];
    if (keepView)
      for (const LitLight& l : lights)
        if (l.stored < visibility.size()) visibility[l.stored] = 1.f;
    SurfaceInput in;
    in.P = g.P[i], in.N = g.N[i], in.Ng = g.Ng[i];
    in.I = c.perspective ? g.P[i] : glm::dvec3(0, 0, 1);
    std::span<const LitLight> vertexLights = lights;
    if (traces) {
      // Each shadowed light's Cl scaled by the share of it that reaches this point; lights
      // behind the point's shading hemisphere add nothing and trace nothing.
      glm::dvec3 Nf(0), Ng(0);
      double floorBias = 0;
      if (!reusing) {
        Nf = facingNormal(in);
        Ng = glm::dot(in.Ng, in.Ng) > 0 ? glm::normalize(in.Ng) : Nf;
        floorBias = 1e-6 * std::max({std::abs(in.P.x), std::abs(in.P.y), std::abs(in.P.z), 1.0});
      }
      bool asFirst = reusing;
      for (size_t li = 0; li < lights.size(); ++li) {
        shadowed[li].Cl0 = lights[li].Cl0;  // the previous vertex scaled it
        size_t n = 0, visible = 0;
        if (reusing) {
          // The first time's rays that no still micropolygon blocked, against the moving ones.
          const ShadowReuse::Traced& t = reuse->traced[i * lights.size() + li];
          if (t.n == 0) continue;
          n = t.n;
          if (movingMayShadow(li)) {
            for (size_t r = t.first; r < size_t(t.first) + t.open; ++r) {
              const ShadowRay& ray = reuse->open[r];
              visible += !c.shadows->occludedByMoving(ray.origin, ray.dir, ray.tfar, time);
            }
          } else {
            visible = t.open, rayCounts.stillOnly += t.open;
          }
          rayCounts.traced += t.open;
        } else {
          glm::dvec3 L, Cl;
          if (!lights[li].shadows || !illuminate(lights[li], in.P, L, Cl) || !(glm::dot(L, Nf) > 0)) continue;
          uint64_t seed = hashCombine(hashCombine(leafIndex, i), li);
          if (k > 0 && !reuse) seed = hashCombine(seed, k);
          n = shade::shadowRays(lights[li], in.P, Ng, std::max(double(bias[i]), floorBias), c.shadowSamples, seed, rays);
          if (n == 0) continue;
          ShadowReuse::Traced* t = reuse ? &reuse->traced[i * lights.size() + li] : nullptr;
          if (t) t->n = uint32_t(n), t->first = uint32_t(reuse->open.size());
          const bool moving = movingMayShadow(li), together = moving && !t;  // no rays to keep for later times: one traversal of both
          for (const ShadowRay& r : rays) {
            if (together) {
              visible += !c.shadows->occluded(r.origin, r.dir, r.tfar, time);
              continue;
            }
            if (c.shadows->occludedByStill(r.origin, r.dir, r.tfar)) continue;
            if (t) reuse->open.push_back(r), ++t->open;
            visible += !moving || !c.shadows->occludedByMoving(r.origin, r.dir, r.tfar, time);
          }
          rayCounts.traced += rays.size();
          if (!moving) rayCounts.stillOnly += rays.size();
        }
        const double share = double(visible) / double(n);
        shadowed[li].Cl0 *= share;
        if (lights[li].stored < visibility.size()) visibility[lights[li].stored] = float(share);
        if (!reuse) continue;
        float& firstShare = reuse->visibility[i * lights.size() + li];
        if (reuse->recording) firstShare = float(share);
        else asFirst &= float(share) == firstShare;
      }
      if (asFirst) {  // every light as visible as at the first time: the first time's outputs
        for (size_t ai = 0; ai < c.vars.size(); ++ai) {
          if (c.vars[ai] == Var::Timed || attrs[ai].empty()) continue;
          const size_t comps = size_t(store::componentCount(c.schema.attrs[ai].type));
          std::copy_n(&(*reuse->first)[ai][i * comps], comps, &attrs[ai][i * comps]);
        }
        ++reuse->reusedVertices;
        continue;
      }
      vertexLights = shadowed;
    }
    // Per-vertex colours are given over the primitive's own (u, v) square.
    in.Cs = hasCs ? bilinear(cornerCs, g.u[i], g.v[i]) : Cs0;
    in.Os = hasOs ? bilinear(cornerOs, g.u[i], g.v[i]) : Os0;
    if (!footprint.empty()) {
      const Footprint& f = footprint[i];
      const float t = shader.textureFlipT ? 1.f - float(g.t[i]) : float(g.t[i]);
      in.Cs *= c.textures->rgb(map, float(g.s[i]), t, f.dsdx, shader.textureFlipT ? -f.dtdx : f.dtdx, f.dsdy, shader.textureFlipT ? -f.dtdy : f.dtdy);
    }
    const SurfaceOutput so = shadeSurface(shader, in, vertexLights);
    storeOutputs(c.vars, g, i, in, so, attrs);
    if (!keepView) continue;
    ViewInputs view;
    const double nl = glm::length(in.N);
    view.N = nl > 0 ? in.N / nl : glm::dvec3(0, 0, -1);
    view.front = litOnSide(shader, in, view.N, vertexLights), view.back = litOnSide(shader, in, -view.N, vertexLights);
    view.visibility = visibility;
    storeViewInputs(c, i, so, view, attrs);
  }
}

}  // namespace reshutter::shade::pass
