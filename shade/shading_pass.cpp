// The single shading pass: split every primitive into leaves (splitScene), dice and shade
// batches of leaves in parallel (shadeBatch), and hand the grids to the sink in scene order
// (GridSender, the pipeline's last stage). shade/shading_pass.h says what it promises.
#include "shade/shading_pass.h"

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <filesystem>
#include <memory>
#include <span>

#include <tbb/parallel_for.h>
#include <tbb/parallel_pipeline.h>
#include <tbb/task_arena.h>

#include "common/error.h"
#include "common/log.h"
#include "common/progress.h"
#include "common/random.h"
#include "shade/shaders.h"
#include "shade/shadows.h"
#include "shade/texture.h"

namespace reshutter::shade {

namespace {

struct Interval {
  double open, close, shadeAt;
  std::vector<double> times{};  // shading in time: every shading time (times[0] = shadeAt); empty: once
};

bool sceneMayShadeInTime(const FrameScene& scene, double open, double close);

Interval intervalOf(const FrameScene& scene, const ShadeOptions& o) {
  const auto& opt = scene.options;
  Interval iv{opt.shutterOpen, opt.shutterClose, 0};
  if (o.interval) {
    iv.open = o.interval->first, iv.close = o.interval->second;
    if (!std::isfinite(iv.open) || !std::isfinite(iv.close) || iv.close < iv.open) fail("--interval", "[", iv.open, ", ", iv.close, "] is not an interval");
  }
  iv.shadeAt = o.shadeAt ? *o.shadeAt : iv.open;
  if (!std::isfinite(iv.shadeAt)) fail("--shade-at", "time is not finite");
  if (o.timeTolerance) {
    if (!(*o.timeTolerance >= 0) || !std::isfinite(*o.timeTolerance)) fail("--shade-in-time", "the tolerance must be a finite number >= 0");
    if (o.shadingTimes < 2 || size_t(o.shadingTimes) > store::StoreMeta::kMaxShadingTimes)
      fail("--shade-times", "must be 2 to ", store::StoreMeta::kMaxShadingTimes);
    if (o.shadeAt && *o.shadeAt != iv.open) fail("--shade-at", "shading in time shades at times spread over the interval from its open; drop --shade-at");
    if (iv.close > iv.open && sceneMayShadeInTime(scene, iv.open, iv.close))
      for (int k = 0; k < o.shadingTimes; ++k)
        iv.times.push_back(k == o.shadingTimes - 1 ? iv.close : iv.open + (iv.close - iv.open) * double(k) / double(o.shadingTimes - 1));
  }
  return iv;
}

// What the pipeline carries: one batch of leaves, shaded into ready-to-send grids.
struct GridOut {
  uint32_t prim = 0;
  uint32_t numVertices = 0;
  std::vector<glm::vec3> positions;
  std::vector<uint32_t> corners;
  std::vector<std::vector<float>> attrs;  // parallel to the schema
};
struct Batch {
  size_t first = 0, count = 0;  // into the flattened leaf list
  std::vector<GridOut> grids;
  uint64_t dropped = 0, trimmed = 0, shadowRays = 0;
  uint64_t timeCandidates = 0, timed = 0, timedMicropolygons = 0;
};

using BatchPtr = std::shared_ptr<Batch>;

// Timed: "Ci@k" / "Oi@k", filled by shading at the other times (shadeInTime()).
enum class Var : uint8_t { Ci, Oi, P, N, Ng, s, t, u, v, Cs, Os, depth, specular, Timed };

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
                                                      {"specular", Var::specular}};
  for (const auto& [n, v] : table)
    if (name == n) return v;
  fail("schema", "output variable '", name, "' is not computable");
}

void put3(std::vector<float>& dst, size_t i, const glm::dvec3& v) { dst[i * 3 + 0] = float(v.x), dst[i * 3 + 1] = float(v.y), dst[i * 3 + 2] = float(v.z); }

glm::dvec3 bilinear(const std::array<glm::dvec3, 4>& c, double u, double v) {
  return (1 - u) * (1 - v) * c[0] + u * (1 - v) * c[1] + (1 - u) * v * c[2] + u * v * c[3];
}

// A non-finite shading result (a light at the shaded point, an overflow) would poison the store:
// the writer rejects it. Clamp to zero here, where the cause is known.
glm::dvec3 finite(const glm::dvec3& c) { return {std::isfinite(c.x) ? c.x : 0.0, std::isfinite(c.y) ? c.y : 0.0, std::isfinite(c.z) ? c.z : 0.0}; }

}  // namespace

store::StoreMeta storeMeta(const FrameScene& scene, const ShadeOptions& o) {
  const Interval iv = intervalOf(scene, o);
  store::StoreMeta m;
  m.frame = scene.options.frame;
  m.fps = o.fps;
  m.shutterOpen = iv.open, m.shutterClose = iv.close;
  m.cameras = {scene.options.camera};
  m.cameras[0].name = "world";
  for (const auto& c : scene.options.namedCameras) m.cameras.push_back(c);
  m.tileSize = o.tileSize;
  m.schema.attrs = {{"Ci", store::AttrType::Color, store::AttrRate::Vertex, store::AttrCodec::Lossless},
                    {"Oi", store::AttrType::Color, store::AttrRate::Vertex, store::AttrCodec::Lossless}};
  for (const auto& name : scene.options.outputs)
    for (const auto& v : knownOutputVars())
      if (v.name == name) m.schema.attrs.push_back({name, v.type, store::AttrRate::Vertex, store::AttrCodec::Lossless});
  if (iv.times.size() > 1) {
    m.shadingTimes = iv.times;
    for (size_t k = 1; k < iv.times.size(); ++k)
      for (const char* base : {"Ci", "Oi"})
        m.schema.attrs.push_back({store::StoreMeta::timedName(base, k), store::AttrType::Color, store::AttrRate::Vertex, store::AttrCodec::Lossless});
  }
  std::string prov = cat("reshutter shade: ", scene.source.empty() ? "scene" : scene.source, "; frame ", scene.options.frame, iv.times.size() > 1 ? cat("; shaded in time at ", iv.times.size(), " times from t=", iv.shadeAt) : cat("; shaded at t=", iv.shadeAt),
                         "; interval [", iv.open, ", ", iv.close, "]");
  if (!scene.objectNames.empty()) {
    prov += "; objects:";
    for (size_t i = 0; i < scene.objectNames.size(); ++i) prov += cat(" ", i + 1, "=\"", scene.objectNames[i], "\"");
  }
  m.provenance = prov;
  m.validate("store metadata");
  return m;
}

namespace {

// ---------------------------------------------------------------------------------------------
// 1. Split: knots and leaves per primitive, then every leaf in scene order.

struct SplitScene {
  std::vector<std::vector<double>> knots;              // per primitive: its knots inside the interval
  std::vector<std::vector<Leaf>> leaves;               // per primitive, in dicing order
  std::vector<std::pair<uint32_t, const Leaf*>> flat;  // (primitive, leaf): primitive order, then dicing order
};

/// Splits every primitive (in parallel; each primitive's list in dicing order) and counts culled
/// pieces and eye splits into `stats`.
SplitScene splitScene(const FrameScene& scene, const Interval& iv, const store::Camera& cam, const DiceOptions& dice, ShadeStats& stats) {
  const size_t nPrims = scene.prims.size();
  SplitScene split;
  split.knots.resize(nPrims), split.leaves.resize(nPrims);
  std::vector<DiceStats> diceStats(nPrims);
  tbb::parallel_for(tbb::blocked_range<size_t>(0, nPrims, 1), [&](const tbb::blocked_range<size_t>& r) {
    for (size_t i = r.begin(); i != r.end(); ++i) {
      split.knots[i] = clipKnots(scene.prims[i], iv.open, iv.close);
      splitPrimitive(scene.prims[i], split.knots[i], cam, dice, split.leaves[i], diceStats[i]);
    }
  });
  for (size_t i = 0; i < nPrims; ++i) {
    stats.culledPieces += diceStats[i].culledPieces;
    stats.eyeSplits += diceStats[i].eyeSplits;
    stats.forcedCuts += diceStats[i].forcedCuts;
    stats.overBudgetPrimitives += diceStats[i].overBudget;
    for (const Leaf& l : split.leaves[i]) split.flat.emplace_back(uint32_t(i), &l);
  }
  return split;
}

// ---------------------------------------------------------------------------------------------
// 2. Dice and shade, a batch of leaves at a time (in parallel).

/// What shading any leaf needs, fixed for the frame.
struct ShadeContext {
  const FrameScene& scene;
  const SplitScene& split;
  const store::Schema& schema;
  std::vector<Var> vars;      // what each schema attribute holds
  std::vector<LitLight> lit;  // every light, resolved once at the shading time
  double shadeAt;
  double nearClip;
  bool perspective;
  const TextureLookup* textures = nullptr;  // only when some surface has a texture
  const ShadowScene* shadows = nullptr;     // only when a light asks for shadows
  int shadowSamples = 16;
  // Shading in time (times.size() > 1): the other times' lights, and what may change.
  std::vector<double> times{};
  std::vector<std::vector<LitLight>> litAt{};  // [k][light], k >= 1
  std::vector<uint8_t> lightMoves{};           // per light: moves (in camera space) over the interval
  // The camera-space box, over the interval, of each moving primitive that casts shadows: a
  // receiver whose shadows they cannot reach keeps one colour.
  std::vector<ShadowBox> movingCasters{};
  double tolerance = 0;
  int ci = -1, oi = -1;
  std::vector<int> timedCi{}, timedOi{};  // schema slots of "Ci@k" / "Oi@k" ([0] unused)
};

/// Vertex i's output variables into `attrs` (parallel to the schema).
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
      case Var::Timed: break;
    }
  }
}

/// Shades every vertex of the diced grid `g` (its corners: `corners`) of primitive `p` at `time`,
/// shading time k of the pass (0: the first), into `attrs` (parallel to the schema).
void shadeVertices(const ShadeContext& c, const Primitive& p, const DicedGrid& g, std::span<const uint32_t> corners, std::span<const LitLight> lights, double time,
                   size_t k, uint64_t leafIndex, std::vector<std::vector<float>>& attrs, uint64_t& shadowRays) {
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
  // A shadow ray starts half a micropolygon off the surface (the diced surface cuts corners of
  // the true one by about that much).
  std::vector<float> bias;
  if (traces) {
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
        if (v >= nV || a >= nV || b >= nV || set[v]) continue;
        footprint[v] = {float(g.s[a] - g.s[v]), float(g.t[a] - g.t[v]), float(g.s[b] - g.s[v]), float(g.t[b] - g.t[v])};
        set[v] = 1;
      }
    }
  }
  attrs.resize(c.vars.size());
  for (size_t ai = 0; ai < c.vars.size(); ++ai)
    if (c.vars[ai] != Var::Timed) attrs[ai].resize(nV * size_t(store::componentCount(c.schema.attrs[ai].type)));
  for (size_t i = 0; i < nV; ++i) {
    SurfaceInput in;
    in.P = g.P[i], in.N = g.N[i], in.Ng = g.Ng[i];
    in.I = c.perspective ? g.P[i] : glm::dvec3(0, 0, 1);
    // Per-vertex colours are given over the primitive's own (u, v) square.
    in.Cs = hasCs ? bilinear(cornerCs, g.u[i], g.v[i]) : Cs0;
    in.Os = hasOs ? bilinear(cornerOs, g.u[i], g.v[i]) : Os0;
    if (!footprint.empty()) {
      const Footprint& f = footprint[i];
      const float t = shader.textureFlipT ? 1.f - float(g.t[i]) : float(g.t[i]);
      in.Cs *= c.textures->rgb(map, float(g.s[i]), t, f.dsdx, shader.textureFlipT ? -f.dtdx : f.dtdx, f.dsdy, shader.textureFlipT ? -f.dtdy : f.dtdy);
    }
    std::span<const LitLight> vertexLights = lights;
    if (traces) {
      // Each shadowed light's Cl scaled by the share of it that reaches this point; lights
      // behind the point's shading hemisphere add nothing and trace nothing.
      const glm::dvec3 Nf = facingNormal(in);
      const glm::dvec3 Ng = glm::dot(in.Ng, in.Ng) > 0 ? glm::normalize(in.Ng) : Nf;
      const double floorBias = 1e-6 * std::max({std::abs(in.P.x), std::abs(in.P.y), std::abs(in.P.z), 1.0});
      for (size_t li = 0; li < lights.size(); ++li) {
        shadowed[li].Cl0 = lights[li].Cl0;  // the previous vertex scaled it
        glm::dvec3 L, Cl;
        if (!lights[li].shadows || !illuminate(lights[li], in.P, L, Cl) || !(glm::dot(L, Nf) > 0)) continue;
        uint64_t seed = hashCombine(hashCombine(leafIndex, i), li);
        if (k > 0) seed = hashCombine(seed, k);
        shadowed[li].Cl0 *= lightVisibility(*c.shadows, lights[li], in.P, Ng, std::max(double(bias[i]), floorBias), c.shadowSamples, seed, shadowRays, time);
      }
      vertexLights = shadowed;
    }
    const SurfaceOutput so = shadeSurface(shader, in, vertexLights);
    storeOutputs(c.vars, g, i, in, so, attrs);
  }
}

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

/// Whether a primitive's colour, opacity or shader is given at several times (a motion block).
bool animated(const Attributes& a) { return a.color.values.size() > 1 || a.opacity.values.size() > 1 || a.surface.values.size() > 1; }

/// Whether a light is somewhere else (in camera space) at the interval's close than at its open.
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
      if (li < c.lit.size() && c.lit[li].shadows)
        for (const ShadowBox& caster : c.movingCasters)
          if (mayShadow(c.lit[li], caster, recv)) return true;
  }
  if (!moves) return false;
  if (sh.kind != SurfaceKind::Matte) return true;  // view-dependent terms (or defaultsurface's headlight)
  return shadowed || local || !translatesRigidly(positions, nV, c.split.knots[pi].size());
}

/// Shading in time for one grid already shaded at the first time into `out` (`moves`: its
/// positions differ between knots): shades it at the other times and keeps them ("Ci@k",
/// "Oi@k") when the colour or opacity changes by more than the tolerance. Returns whether it
/// kept them.
bool shadeInTime(const ShadeContext& c, uint32_t pi, const Leaf& leaf, const DicedGrid& g, bool moves, std::span<const uint32_t> lightIdx, uint64_t leafIndex,
                 GridOut& out, uint64_t& shadowRays) {
  const Primitive& p = c.scene.prims[pi];
  const size_t T = c.times.size();
  std::vector<std::vector<std::vector<float>>> at(T);
  DicedGrid gk;
  std::vector<LitLight> lights;
  float change = 0;
  for (size_t k = 1; k < T; ++k) {
    // A grid that stands still has the same shading geometry at every time (only its lights,
    // shadows and shader can differ): no second dicing.
    const DicedGrid* geometry = &g;
    if (moves) {
      diceLeaf(p, leaf, c.split.knots[pi], c.times[k], c.nearClip, c.perspective, gk);
      if (gk.numVertices != g.numVertices || gk.corners != out.corners) return false;  // the same grid, or no blend
      geometry = &gk;
    }
    lights.clear();
    for (uint32_t li : lightIdx)
      if (li < c.lit.size()) lights.push_back(c.litAt[k][li]);
    shadeVertices(c, p, *geometry, out.corners, lights, c.times[k], k, leafIndex, at[k], shadowRays);
    for (int slot : {c.ci, c.oi}) {
      const std::vector<float>& a = out.attrs[size_t(slot)];
      const std::vector<float>& b = at[k][size_t(slot)];
      for (size_t i = 0; i < a.size(); ++i) change = std::max(change, std::abs(b[i] - a[i]));
    }
  }
  if (!(change > c.tolerance) && c.tolerance > 0) return false;
  for (size_t k = 1; k < T; ++k) {
    out.attrs[size_t(c.timedCi[k])] = std::move(at[k][size_t(c.ci)]);
    out.attrs[size_t(c.timedOi[k])] = std::move(at[k][size_t(c.oi)]);
  }
  return true;
}

/// Dices and shades the batch's leaves into b.grids.
void shadeBatch(const ShadeContext& c, Batch& b) {
  DicedGrid g;
  std::vector<LitLight> lights;
  std::vector<uint32_t> lightIdx;  // the frame's lights that light the primitive
  const Attributes* lightsOf = nullptr;
  uint64_t shadowRays = 0;
  b.grids.resize(b.count);
  for (size_t n = 0; n < b.count; ++n) {
    const auto [pi, leaf] = c.split.flat[b.first + n];
    const Primitive& p = c.scene.prims[pi];
    diceLeaf(p, *leaf, c.split.knots[pi], c.shadeAt, c.nearClip, c.perspective, g);
    b.dropped += g.droppedMicropolygons;
    b.trimmed += g.trimmedMicropolygons;
    if (p.attrs.get() != lightsOf) {  // a primitive's grids come in runs: copy its lights once a run
      lightsOf = p.attrs.get();
      lights.clear(), lightIdx.clear();
      for (uint32_t li : p.attrs->lights)
        if (li < c.lit.size()) lightIdx.push_back(li);
      for (uint32_t li : c.scene.globalLights)
        if (li < c.lit.size()) lightIdx.push_back(li);
      for (uint32_t li : lightIdx) lights.push_back(c.lit[li]);
    }
    GridOut& out = b.grids[n];
    out.prim = pi;
    out.numVertices = g.numVertices;
    out.positions = std::move(g.positions);
    out.corners = std::move(g.corners);
    shadeVertices(c, p, g, out.corners, lights, c.shadeAt, 0, b.first + n, out.attrs, shadowRays);
    if (c.times.size() > 1 && !out.corners.empty()) {
      const bool moves = c.split.knots[pi].size() > 1 && !store::verticesStandStill(out.positions, out.numVertices, 0, out.numVertices);
      if (mayShadeDifferently(c, pi, out.positions, out.numVertices, moves, lightIdx)) {
        ++b.timeCandidates;
        if (shadeInTime(c, pi, *leaf, g, moves, lightIdx, b.first + n, out, shadowRays)) ++b.timed, b.timedMicropolygons += out.corners.size() / 4;
      }
    }
    g = DicedGrid{};
  }
  b.shadowRays = shadowRays;
}

// ---------------------------------------------------------------------------------------------
// 3. Send: the grids to the sink, in scene order (the pipeline's last, serial stage).

class GridSender {
 public:
  GridSender(const FrameScene& scene, const SplitScene& split, size_t numVars, store::GridSink& sink, ShadeStats& stats)
      : scene_(scene), split_(split), sink_(sink), stats_(stats), values_(numVars) {}

  void send(Batch& b) {
    stats_.droppedMicropolygons += b.dropped;
    stats_.trimmedMicropolygons += b.trimmed;
    stats_.shadowRays += b.shadowRays;
    stats_.timeCandidateGrids += b.timeCandidates;
    stats_.timedGrids += b.timed;
    stats_.timedMicropolygons += b.timedMicropolygons;
    for (GridOut& go : b.grids)
      if (!go.corners.empty()) sendGrid(go);
  }

 private:
  const FrameScene& scene_;
  const SplitScene& split_;
  store::GridSink& sink_;
  ShadeStats& stats_;
  uint32_t lastPrim_ = UINT32_MAX, schedule_ = 0;
  uint32_t gridId_ = 0;
  std::vector<store::AttrValues> values_;

  void sendGrid(const GridOut& go) {
    // A primitive's knots are registered once, at its first grid.
    if (go.prim != lastPrim_) {
      lastPrim_ = go.prim;
      schedule_ = split_.knots[go.prim].size() > 1 ? sink_.addSchedule(split_.knots[go.prim]) : 0;
    }
    const Primitive& p = scene_.prims[go.prim];
    store::GridInput in;
    in.schedule = schedule_;
    in.numVertices = go.numVertices;
    in.positions = go.positions;
    in.corners = go.corners;
    in.objectId = p.attrs->objectId;
    in.gridId = gridId_++;
    in.flags = uint8_t((p.attrs->matte ? store::kMatte : 0) | (p.attrs->twoSided ? store::kTwoSided : 0));
    for (size_t ai = 0; ai < values_.size(); ++ai) values_[ai] = store::AttrValues{go.attrs[ai], {}};
    in.attrs = values_;
    sink_.addGrid(in);
    stats_.grids += 1;
    stats_.micropolygons += in.numMicropolygons();
    stats_.vertices += go.numVertices;
    const bool moves = schedule_ != 0 && !in.standsStill();  // the writer stores a still grid static
    stats_.movingGrids += moves;
    stats_.movingMicropolygons += moves ? in.numMicropolygons() : 0;
  }
};

/// Batches of leaves go through dice-and-shade in parallel and reach `sender` in order; the
/// pipeline's token count bounds the grids in flight.
void shadeAndSend(const ShadeContext& c, GridSender& sender, Progress& progress) {
  constexpr size_t kBatch = 8;
  const size_t numLeaves = c.split.flat.size();
  size_t next = 0;
  auto nextBatch = [&](tbb::flow_control& fc) -> BatchPtr {
    if (next >= numLeaves) {
      fc.stop();
      return nullptr;
    }
    auto b = std::make_shared<Batch>();
    b->first = next;
    b->count = std::min(kBatch, numLeaves - next);
    next += b->count;
    return b;
  };
  auto shade = [&](BatchPtr b) {
    shadeBatch(c, *b);
    return b;
  };
  auto sendInOrder = [&](BatchPtr b) {
    progress.advance(b->count);
    sender.send(*b);
  };
  const size_t tokens = size_t(2 * tbb::this_task_arena::max_concurrency() + 2);
  tbb::parallel_pipeline(tokens, tbb::make_filter<void, BatchPtr>(tbb::filter_mode::serial_in_order, nextBatch) &
                                     tbb::make_filter<BatchPtr, BatchPtr>(tbb::filter_mode::parallel, shade) &
                                     tbb::make_filter<BatchPtr, void>(tbb::filter_mode::serial_in_order, sendInOrder));
}

/// Whether some lit surface is illuminated by a light that asks for shadows.
bool wantsShadows(const FrameScene& scene, std::span<const LitLight> lit, double shadeAt) {
  if (std::none_of(lit.begin(), lit.end(), [](const LitLight& l) { return l.shadows; })) return false;  // the common case, at no cost per primitive
  auto shadowing = [&](uint32_t li) { return li < lit.size() && lit[li].shadows; };
  const bool global = std::any_of(scene.globalLights.begin(), scene.globalLights.end(), shadowing);
  const Attributes* seen = nullptr;
  for (const Primitive& p : scene.prims) {
    if (p.attrs.get() == seen) continue;  // primitives share attributes in runs
    seen = p.attrs.get();
    if (!usesLights(p.attrs->surface.at(shadeAt).kind)) continue;
    if (global || std::any_of(p.attrs->lights.begin(), p.attrs->lights.end(), shadowing)) return true;
  }
  return false;
}

/// The frame's micropolygons at the shading time, every leaf of a primitive that casts shadows
/// diced again (the shading pass's grids stream out; keeping them all would hold the frame) -
/// from `split`, the frame's own leaves, or leaves split at a coarser shadow rate.
std::unique_ptr<ShadowScene> buildShadowScene(const ShadeContext& c, const SplitScene& split, std::vector<ShadowBox>* movingCasters = nullptr) {
  std::vector<ShadowScene::Piece> pieces(split.flat.size());
  tbb::parallel_for(tbb::blocked_range<size_t>(0, pieces.size(), 8), [&](const tbb::blocked_range<size_t>& r) {
    DicedGrid g;
    for (size_t i = r.begin(); i != r.end(); ++i) {
      const auto [pi, leaf] = split.flat[i];
      const Primitive& p = c.scene.prims[pi];
      if (!p.attrs->transmission) continue;
      diceLeaf(p, *leaf, split.knots[pi], c.shadeAt, c.nearClip, c.perspective, g);
      if (c.times.size() > 1 && split.knots[pi].size() > 1) {
        // Shading in time: the micropolygons move over the interval (their positions at the knots).
        pieces[i].P = std::move(g.positions);
        pieces[i].knots = split.knots[pi];
      } else {
        pieces[i].P.assign(g.P.begin(), g.P.end());
      }
      pieces[i].corners = std::move(g.corners);
      g = DicedGrid{};
    }
  });
  if (movingCasters) {
    // One box per moving primitive, over its pieces at every knot.
    uint32_t last = UINT32_MAX;
    for (size_t i = 0; i < pieces.size(); ++i) {
      if (pieces[i].knots.size() <= 1) continue;
      const size_t nV = pieces[i].P.size() / pieces[i].knots.size();
      if (store::verticesStandStill(pieces[i].P, nV, 0, nV)) continue;
      if (split.flat[i].first != last) movingCasters->emplace_back(), last = split.flat[i].first;
      for (const glm::vec3& q : pieces[i].P) movingCasters->back().add(q);
    }
  }
  return c.times.size() > 1 ? std::make_unique<ShadowScene>(pieces, c.times.front(), c.times.back()) : std::make_unique<ShadowScene>(pieces);
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

// The texture search path with relative entries taken from the RIB file's directory, which is
// also searched when the scene gives no path.
std::string textureSearchPath(const FrameScene& scene) {
  const std::filesystem::path base = std::filesystem::path(scene.source).parent_path();
  const std::string dir = base.empty() ? "." : base.string();
  const std::string& given = scene.options.textureSearchPath;
  if (given.empty()) return dir;
  std::string out;
  size_t from = 0;
  while (from <= given.size()) {
    size_t to = given.find(':', from);
    if (to == std::string::npos) to = given.size();
    std::string entry = given.substr(from, to - from);
    if (entry == "@" || entry.empty()) entry = dir;  // "@": the default path
    else if (entry.front() != '/') entry = (std::filesystem::path(dir) / entry).string();
    out += (out.empty() ? "" : ":") + entry;
    from = to + 1;
  }
  return out;
}

}  // namespace

ShadeStats shadeFrame(const FrameScene& scene, const ShadeOptions& o, store::GridSink& sink) {
  const auto start = std::chrono::steady_clock::now();
  const Interval iv = intervalOf(scene, o);
  const store::StoreMeta meta = storeMeta(scene, o);
  const store::Camera& cam = meta.cameras[0];
  ShadeStats stats;
  stats.primitives = scene.prims.size();
  stats.shadeAt = iv.shadeAt;

  const SplitScene split = splitScene(scene, iv, cam, o.dice, stats);
  ShadeContext context{scene, split, meta.schema, {}, {}, iv.shadeAt, cam.nearClip, cam.projection == store::Projection::Perspective};
  context.lit.reserve(scene.lights.size());
  for (const auto& l : scene.lights) context.lit.push_back(resolveLight(l, iv.shadeAt));
  for (const auto& a : meta.schema.attrs) context.vars.push_back(varOf(a.name));
  if (iv.times.size() > 1) {
    context.times = iv.times;
    context.tolerance = *o.timeTolerance;
    context.ci = meta.schema.ci(), context.oi = meta.schema.oi();
    context.litAt.resize(iv.times.size());
    context.timedCi.assign(iv.times.size(), -1), context.timedOi.assign(iv.times.size(), -1);
    for (size_t k = 1; k < iv.times.size(); ++k) {
      for (const auto& l : scene.lights) context.litAt[k].push_back(resolveLight(l, iv.times[k]));
      context.timedCi[k] = meta.schema.find(store::StoreMeta::timedName("Ci", k));
      context.timedOi[k] = meta.schema.find(store::StoreMeta::timedName("Oi", k));
    }
    for (const auto& l : scene.lights) context.lightMoves.push_back(lightMoves(l, iv.open, iv.close));
    stats.shadingTimes = iv.times;
  }
  // Textures only when a surface asks for one (no texture system otherwise).
  std::unique_ptr<TextureLookup> textures;
  // (Primitives share attributes in runs; a texture at any key of an animated surface counts.)
  const Attributes* seen = nullptr;
  for (const auto& p : scene.prims) {
    if (p.attrs.get() == seen) continue;
    seen = p.attrs.get();
    const auto& keys = p.attrs->surface.values;
    if (std::any_of(keys.begin(), keys.end(), [](const SurfaceShader& sh) { return !sh.textureName.empty(); })) {
      textures = std::make_unique<TextureLookup>(textureSearchPath(scene));
      break;
    }
  }
  context.textures = textures.get();
  // Shadows only when a light asks for them and lights something that reflects it.
  std::unique_ptr<ShadowScene> shadows;
  if (!(o.shadowRate >= 1) || !std::isfinite(o.shadowRate)) fail("--shadow-rate", "must be at least 1");
  if (o.shadows && wantsShadows(scene, context.lit, iv.shadeAt)) {
    const auto t0 = std::chrono::steady_clock::now();
    if (o.shadowRate == 1) {
      shadows = buildShadowScene(context, split, &context.movingCasters);
    } else {
      // Coarser micropolygons for the shadow rays: the same split, every shading rate scaled.
      DiceOptions coarse = o.dice;
      coarse.shadingRateScale *= o.shadowRate;
      ShadeStats ignored;
      shadows = buildShadowScene(context, splitScene(scene, iv, cam, coarse, ignored), &context.movingCasters);
    }
    stats.shadowMicropolygons = shadows->micropolygons();
    stats.shadowBuildSeconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  }
  context.shadows = shadows.get();
  context.shadowSamples = std::max(o.shadowSamples, 1);

  GridSender sender(scene, split, context.vars.size(), sink, stats);
  Progress progress(cat("shading ", scene.source.empty() ? "frame" : scene.source), split.flat.size());
  shadeAndSend(context, sender, progress);
  progress.finish();
  if (textures) stats.textureLookups = textures->lookups(), stats.missingTextures = textures->missing().size();
  stats.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  return stats;
}

StoreResult shadeToStore(const FrameScene& scene, const ShadeOptions& options, const std::string& path) {
  StoreResult r;
  store::StoreWriter writer(path, storeMeta(scene, options));
  r.shade = shadeFrame(scene, options, writer);
  r.write = writer.close();
  return r;
}

}  // namespace reshutter::shade
