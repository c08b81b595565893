// The single shading pass: split → dice → shade → stream, in parallel, in scene order.
#include "shade/shading_pass.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <memory>

#include <tbb/parallel_for.h>
#include <tbb/parallel_pipeline.h>
#include <tbb/task_arena.h>

#include "common/error.h"
#include "common/log.h"
#include "common/progress.h"
#include "shade/shaders.h"

namespace reshutter::shade {

namespace {

struct Interval {
  double open, close, shadeAt;
};

Interval intervalOf(const FrameScene& scene, const ShadeOptions& o) {
  const auto& opt = scene.options;
  Interval iv{opt.shutterOpen, opt.shutterClose, 0};
  if (o.interval) {
    iv.open = o.interval->first, iv.close = o.interval->second;
    if (!std::isfinite(iv.open) || !std::isfinite(iv.close) || iv.close < iv.open)
      fail("--interval", "[", iv.open, ", ", iv.close, "] is not an interval");
  }
  iv.shadeAt = o.shadeAt ? *o.shadeAt : iv.open;
  if (!std::isfinite(iv.shadeAt)) fail("--shade-at", "time is not finite");
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
  uint64_t dropped = 0;
};

using BatchPtr = std::shared_ptr<Batch>;

enum class Var : uint8_t { Ci, Oi, P, N, Ng, s, t, u, v, Cs, Os, depth, specular };

Var varOf(const std::string& name) {
  static const std::pair<const char*, Var> table[] = {{"Ci", Var::Ci}, {"Oi", Var::Oi}, {"P", Var::P},   {"N", Var::N},   {"Ng", Var::Ng},
                                                      {"s", Var::s},   {"t", Var::t},   {"u", Var::u},   {"v", Var::v},   {"Cs", Var::Cs},
                                                      {"Os", Var::Os}, {"depth", Var::depth}, {"specular", Var::specular}};
  for (const auto& [n, v] : table)
    if (name == n) return v;
  fail("schema", "output variable '", name, "' is not computable");
}

void put3(std::vector<float>& dst, size_t i, const glm::dvec3& v) {
  dst[i * 3 + 0] = float(v.x), dst[i * 3 + 1] = float(v.y), dst[i * 3 + 2] = float(v.z);
}

glm::dvec3 bilinear(const std::array<glm::dvec3, 4>& c, double u, double v) {
  return (1 - u) * (1 - v) * c[0] + u * (1 - v) * c[1] + (1 - u) * v * c[2] + u * v * c[3];
}

// A non-finite shading result (a light at the shaded point, an overflow) would poison the store:
// the writer rejects it. Clamp to zero here, where the cause is known.
glm::dvec3 finite(const glm::dvec3& c) {
  return {std::isfinite(c.x) ? c.x : 0.0, std::isfinite(c.y) ? c.y : 0.0, std::isfinite(c.z) ? c.z : 0.0};
}

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
  std::string prov = cat("reshutter shade: ", scene.source.empty() ? "scene" : scene.source, "; frame ", scene.options.frame, "; shaded at t=",
                         iv.shadeAt, "; interval [", iv.open, ", ", iv.close, "]");
  if (!scene.objectNames.empty()) {
    prov += "; objects:";
    for (size_t i = 0; i < scene.objectNames.size(); ++i) prov += cat(" ", i + 1, "=\"", scene.objectNames[i], "\"");
  }
  m.provenance = prov;
  m.validate("store metadata");
  return m;
}

ShadeStats shadeFrame(const FrameScene& scene, const ShadeOptions& o, store::GridSink& sink) {
  const auto start = std::chrono::steady_clock::now();
  const Interval iv = intervalOf(scene, o);
  const store::StoreMeta meta = storeMeta(scene, o);
  const store::Camera& cam = meta.cameras[0];
  const bool perspective = cam.projection == store::Projection::Perspective;
  const size_t nPrims = scene.prims.size();
  ShadeStats stats;
  stats.primitives = nPrims;
  stats.shadeAt = iv.shadeAt;

  // 1. Knots and leaves per primitive (parallel; each primitive's list in dicing order).
  std::vector<std::vector<double>> knots(nPrims);
  std::vector<std::vector<Leaf>> leaves(nPrims);
  std::vector<DiceStats> diceStats(nPrims);
  tbb::parallel_for(tbb::blocked_range<size_t>(0, nPrims, 1), [&](const tbb::blocked_range<size_t>& r) {
    for (size_t i = r.begin(); i != r.end(); ++i) {
      knots[i] = clipKnots(scene.prims[i], iv.open, iv.close);
      splitPrimitive(scene.prims[i], knots[i], cam, o.dice, leaves[i], diceStats[i]);
    }
  });
  std::vector<std::pair<uint32_t, const Leaf*>> flat;
  for (size_t i = 0; i < nPrims; ++i) {
    stats.culledPieces += diceStats[i].culledPieces;
    stats.eyeSplits += diceStats[i].eyeSplits;
    for (const Leaf& l : leaves[i]) flat.emplace_back(uint32_t(i), &l);
  }

  // Lights resolved once, at the shading time.
  std::vector<LitLight> lit;
  lit.reserve(scene.lights.size());
  for (const auto& l : scene.lights) lit.push_back(resolveLight(l, iv.shadeAt));

  std::vector<Var> vars;
  for (const auto& a : meta.schema.attrs) vars.push_back(varOf(a.name));

  auto shadeBatch = [&](Batch& b) {
    DicedGrid g;
    std::vector<LitLight> lights;
    b.grids.resize(b.count);
    for (size_t n = 0; n < b.count; ++n) {
      const auto [pi, leaf] = flat[b.first + n];
      const Primitive& p = scene.prims[pi];
      const Attributes& a = *p.attrs;
      diceLeaf(p, *leaf, knots[pi], iv.shadeAt, cam.nearClip, perspective, g);
      b.dropped += g.droppedMicropolygons;
      lights.clear();
      for (uint32_t li : a.lights)
        if (li < lit.size()) lights.push_back(lit[li]);
      const SurfaceShader shader = a.surface.at(iv.shadeAt);
      const glm::dvec3 Cs0 = a.color.at(iv.shadeAt), Os0 = a.opacity.at(iv.shadeAt);
      std::array<glm::dvec3, 4> cornerCs, cornerOs;
      const bool hasCs = p.mesh && p.corners(p.mesh->Cs, cornerCs);
      const bool hasOs = p.mesh && p.corners(p.mesh->Os, cornerOs);
      const size_t nV = g.numVertices;
      GridOut& out = b.grids[n];
      out.prim = pi;
      out.numVertices = g.numVertices;
      out.positions = std::move(g.positions);
      out.corners = std::move(g.corners);
      out.attrs.resize(vars.size());
      for (size_t ai = 0; ai < vars.size(); ++ai) out.attrs[ai].resize(nV * size_t(store::componentCount(meta.schema.attrs[ai].type)));
      for (size_t i = 0; i < nV; ++i) {
        SurfaceInput in;
        in.P = g.P[i], in.N = g.N[i], in.Ng = g.Ng[i];
        in.I = perspective ? g.P[i] : glm::dvec3(0, 0, 1);
        // Per-vertex colours are given over the primitive's own (u, v) square.
        in.Cs = hasCs ? bilinear(cornerCs, g.u[i], g.v[i]) : Cs0;
        in.Os = hasOs ? bilinear(cornerOs, g.u[i], g.v[i]) : Os0;
        const SurfaceOutput so = shadeSurface(shader, in, lights);
        for (size_t ai = 0; ai < vars.size(); ++ai) {
          auto& dst = out.attrs[ai];
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
          }
        }
      }
      g = DicedGrid{};
    }
  };

  // 2. Dice and shade in parallel; hand grids to the sink in order.
  constexpr size_t kBatch = 8;
  size_t next = 0;
  uint32_t lastPrim = UINT32_MAX, schedule = 0;
  uint32_t gridId = 0;
  std::vector<store::AttrValues> values(vars.size());
  const size_t tokens = size_t(2 * tbb::this_task_arena::max_concurrency() + 2);
  Progress progress(cat("shading ", scene.source.empty() ? "frame" : scene.source), flat.size());
  tbb::parallel_pipeline(
      tokens,
      tbb::make_filter<void, BatchPtr>(tbb::filter_mode::serial_in_order,
                                     [&](tbb::flow_control& fc) -> BatchPtr {
                                       if (next >= flat.size()) {
                                         fc.stop();
                                         return nullptr;
                                       }
                                       auto b = std::make_shared<Batch>();
                                       b->first = next;
                                       b->count = std::min(kBatch, flat.size() - next);
                                       next += b->count;
                                       return b;
                                     }) &
          tbb::make_filter<BatchPtr, BatchPtr>(tbb::filter_mode::parallel,
                                           [&](BatchPtr b) {
                                             shadeBatch(*b);
                                             return b;
                                           }) &
          tbb::make_filter<BatchPtr, void>(tbb::filter_mode::serial_in_order, [&](BatchPtr b) {
            stats.droppedMicropolygons += b->dropped;
            progress.advance(b->count);
            for (GridOut& go : b->grids) {
              if (go.corners.empty()) continue;
              if (go.prim != lastPrim) {
                lastPrim = go.prim;
                schedule = knots[go.prim].size() > 1 ? sink.addSchedule(knots[go.prim]) : 0;
              }
              const Primitive& p = scene.prims[go.prim];
              store::GridInput in;
              in.schedule = schedule;
              in.numVertices = go.numVertices;
              in.positions = go.positions;
              in.corners = go.corners;
              in.objectId = p.attrs->objectId;
              in.gridId = gridId++;
              in.flags = uint8_t((p.attrs->matte ? store::kMatte : 0) | (p.attrs->twoSided ? store::kTwoSided : 0));
              for (size_t ai = 0; ai < vars.size(); ++ai) values[ai] = store::AttrValues{go.attrs[ai], {}};
              in.attrs = values;
              sink.addGrid(in);
              stats.grids += 1;
              stats.micropolygons += in.numMicropolygons();
              stats.vertices += go.numVertices;
              const bool moves = schedule != 0 && !in.standsStill();  // the writer stores a still grid static
              stats.movingGrids += moves;
              stats.movingMicropolygons += moves ? in.numMicropolygons() : 0;
            }
          }));
  progress.finish();
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
