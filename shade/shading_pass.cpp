// The single shading pass: split every primitive into leaves (splitScene), dice and shade
// batches of leaves in parallel (shadeBatch), and hand the grids to the sink in scene order
// (GridSender, the pipeline's last stage). shade/shading_pass.h says what it promises.
#include "shade/shading_pass.h"

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <filesystem>
#include <map>
#include <memory>
#include <span>

#include <glm/matrix.hpp>
#include <tbb/parallel_for.h>
#include <tbb/parallel_pipeline.h>
#include <tbb/task_arena.h>

#include "common/error.h"
#include "common/log.h"
#include "common/progress.h"
#include "common/random.h"
#include "shade/shade_grid.h"

namespace reshutter::shade {

using namespace pass;

namespace {

struct Interval {
  double open, close, shadeAt;
  std::vector<double> times{};  // shading in time: every shading time (times[0] = shadeAt); empty: once
};

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
struct Batch {
  size_t first = 0, count = 0;  // into the flattened leaf list
  std::vector<GridOut> grids;
  uint64_t dropped = 0, trimmed = 0, shadowRays = 0;
  uint64_t timeCandidates = 0, timed = 0, timedMicropolygons = 0, reusedVertices = 0, stillOnlyRays = 0, candidateStillOnlyRays = 0;
  InTimeCounts inTime;
};

using BatchPtr = std::shared_ptr<Batch>;

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
  for (store::Camera& c : m.cameras) c.clipMotion(iv.open, iv.close);  // the cameras over the interval shaded
  m.tileSize = o.tileSize;
  m.schema.attrs = {{"Ci", store::AttrType::Color, store::AttrRate::Vertex, store::AttrCodec::Lossless},
                    {"Oi", store::AttrType::Color, store::AttrRate::Vertex, store::AttrCodec::Lossless}};
  for (const auto& name : scene.options.outputs)
    for (const auto& v : knownOutputVars())
      if (v.name == name) m.schema.attrs.push_back({name, v.type, store::AttrRate::Vertex, store::AttrCodec::Lossless});
  if (o.viewDependent) {
    using VT = store::ViewTerm;
    for (auto [name, type] : {std::pair{VT::kViewIndependent, store::AttrType::Color},
                              {VT::kBackSide, store::AttrType::Color},
                              {VT::kWeight, store::AttrType::Color},
                              {VT::kNormal, store::AttrType::Normal},
                              {VT::kRoughness, store::AttrType::Float}})
      m.schema.attrs.push_back({name, type, store::AttrRate::Vertex, store::AttrCodec::Lossless});
    size_t withVisibility = 0;
    for (size_t li = 0; li < scene.lights.size(); ++li) {
      if (scene.lights[li].kind == LightKind::Ambient) continue;
      if (withVisibility++ == VT::kMaxLights) {
        warn(cat("--view-dependent: the scene has more than ", VT::kMaxLights,
                 " lights; the others' shadows and light links are not kept (other cameras see them unshadowed)"));
        break;
      }
      m.schema.attrs.push_back({VT::visibility(li), store::AttrType::Float, store::AttrRate::Vertex, store::AttrCodec::Lossless});
    }
  }
  if (iv.times.size() > 1) {
    // Colour, opacity and every output variable that can change with time (not the parametric
    // s t u v) at the other shading times, declared as at the first - as many as the store's
    // attribute limit holds (colour and opacity first).
    m.shadingTimes = iv.times;
    const std::vector<store::AttrDecl> first = m.schema.attrs;
    // A surface's opacity is its Os (shade/shaders.h): it changes over the shutter only where an
    // opacity or a shader (a RIS material's presence) is animated. Elsewhere the later times'
    // opacities would repeat the first's, so the store leaves them out.
    const Attributes* seen = nullptr;
    bool opacityMayChange = false;
    for (const Primitive& p : scene.prims) {
      if (p.attrs.get() == seen) continue;
      seen = p.attrs.get();
      opacityMayChange |= p.attrs->opacity.values.size() > 1 || p.attrs->surface.values.size() > 1;
    }
    for (const store::AttrDecl& a : first) {
      if (a.name == "s" || a.name == "t" || a.name == "u" || a.name == "v") continue;
      if (a.name == "Oi" && !opacityMayChange) continue;
      if (varOf(a.name) >= Var::Cvi) continue;  // the view-dependent term's inputs: at the first time
      if (m.schema.attrs.size() + iv.times.size() - 1 > store::Schema::kMaxAttributes) {
        warnOnce(cat("timed-aov:", a.name), cat("output variable '", a.name, "' is stored at the first shading time only (a store holds at most ",
                                                store::Schema::kMaxAttributes, " attributes)"));
        continue;
      }
      for (size_t k = 1; k < iv.times.size(); ++k) m.schema.attrs.push_back({store::StoreMeta::timedName(a.name, k), a.type, a.rate, a.codec});
    }
  }
  std::string prov = cat("reshutter shade: ", scene.source.empty() ? "scene" : scene.source, "; frame ", scene.options.frame,
                         iv.times.size() > 1 ? cat("; shaded in time at ", iv.times.size(), " times from t=", iv.shadeAt) : cat("; shaded at t=", iv.shadeAt),
                         "; interval [", iv.open, ", ", iv.close, "]");
  if (!scene.objectNames.empty()) {
    prov += "; objects:";
    for (size_t i = 0; i < scene.objectNames.size(); ++i) prov += cat(" ", i + 1, "=\"", scene.objectNames[i], "\"");
  }
  m.provenance = prov;
  // The lights, as volumes added at re-sample time will see them.
  for (const Light& light : scene.lights) {
    const LitLight l = resolveLight(light, iv.shadeAt);
    store::StoredLight sl;
    using K = store::StoredLight::Kind;
    sl.kind = l.kind == LightKind::Ambient   ? K::Ambient
              : l.kind == LightKind::Distant ? K::Distant
              : l.kind == LightKind::Spot    ? K::Spot
              : l.kind == LightKind::Face    ? K::Face
                                             : K::Point;
    sl.position = l.position, sl.axis = l.axis, sl.colour = l.Cl0;
    sl.cosOuter = l.cosOuter, sl.cosInner = l.cosInner, sl.beam = l.beam;
    if (l.kind == LightKind::Uber) sl.position = glm::dvec3(glm::inverse(l.toLight) * glm::dvec4(0, 0, 0, 1));
    m.lights.push_back(sl);
  }
  // The scene's volumes, placed in camera space at their transform's times; paths relative to
  // the RIB file's directory become absolute, so the store finds them wherever it is read.
  for (const SceneVolume& v : scene.volumes) {
    store::StoredVolume sv;
    std::filesystem::path path(v.path);
    if (path.is_relative()) path = std::filesystem::path(scene.source).parent_path() / path;
    sv.path = std::filesystem::absolute(path).lexically_normal().string();
    sv.density = v.grid;
    if (v.objectToCamera.moving()) sv.times = v.objectToCamera.times, sv.fileToCamera = v.objectToCamera.mats;
    else sv.times = {iv.open}, sv.fileToCamera = {v.objectToCamera.mats[0]};
    m.volumes.push_back(std::move(sv));
  }
  m.validate("store metadata");
  return m;
}

namespace {

// ---------------------------------------------------------------------------------------------
// 1. Split: knots and leaves per primitive, then every leaf in scene order.

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
      splitPrimitive(scene.prims[i], split.knots[i], cam, scene.options.namedCameras, dice, split.leaves[i], diceStats[i]);
    }
  });
  for (size_t i = 0; i < nPrims; ++i) {
    stats.culledPieces += diceStats[i].culledPieces;
    stats.eyeSplits += diceStats[i].eyeSplits;
    if (!scene.options.namedCameras.empty())
      stats.allCameraDetail += diceStats[i].micropolygons, stats.primaryCameraDetail += diceStats[i].primaryMicropolygons;
    stats.forcedCuts += diceStats[i].forcedCuts;
    stats.overBudgetPrimitives += diceStats[i].overBudget;
    for (const Leaf& l : split.leaves[i]) split.flat.emplace_back(uint32_t(i), &l);
  }
  return split;
}

// ---------------------------------------------------------------------------------------------
// 2. Dice and shade, a batch of leaves at a time (in parallel).

/// Dices and shades the batch's leaves into b.grids.
void shadeBatch(const ShadeContext& c, Batch& b) {
  DicedGrid g;
  std::vector<LitLight> lights;
  std::vector<uint32_t> lightIdx;  // the frame's lights that light the primitive
  const Attributes* lightsOf = nullptr;
  RayCounts rays;
  std::vector<uint8_t> movingShadows;  // per light of the grid's: may a moving caster shadow it (shading in time)
  std::vector<float> firstBias;        // the grid's shadow-ray lifts at the first time, for its later times
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
    // Shading in time: whether the grid is a candidate is known from its positions, before it is
    // shaded, so that a grid only shadows change records its rays (ShadowReuse).
    bool candidate = false, moves = false;
    movingShadows.assign(c.times.size() > 1 ? lightIdx.size() : 0, 0);  // empty, shading once: every light's rays trace the one BVH
    if (c.times.size() > 1 && !g.corners.empty()) {
      moves = c.split.knots[pi].size() > 1 && !store::verticesStandStill(g.positions, g.numVertices, 0, g.numVertices);
      candidate = mayShadeDifferently(c, pi, g.positions, g.numVertices, moves, lightIdx, movingShadows);
    }
    ShadowReuse reuse;
    ShadowReuse* reusing = candidate && c.shadows && onlyShadowsChange(c, pi, moves, lightIdx) ? &reuse : nullptr;
    out.positions = std::move(g.positions);
    out.corners = std::move(g.corners);
    // Shading in time: the moving micropolygons are a BVH of their own, with motion blur, which a
    // grid's rays need not trace from a light no moving caster can shadow it from - any light,
    // for a grid that is not a candidate (mayShadeDifferently() tells).
    const uint64_t stillOnlyBefore = rays.stillOnly;
    firstBias.clear();
    shadeVertices(c, p, g, out.corners, lights, c.shadeAt, 0, b.first + n, out.attrs, rays, reusing, movingShadows, {}, firstBias);
    if (c.times.size() > 1 && !candidate) b.stillOnlyRays += rays.stillOnly - stillOnlyBefore;
    if (candidate) {
      ++b.timeCandidates;
      const bool kept = shadeInTime(c, pi, *leaf, g, moves, lightIdx, movingShadows, firstBias, b.first + n, out, rays, reusing, b.inTime);
      b.candidateStillOnlyRays += rays.stillOnly - stillOnlyBefore;
      if (kept)
        ++b.timed, b.timedMicropolygons += out.corners.size() / 4;
      b.reusedVertices += reuse.reusedVertices;
    }
    g = DicedGrid{};
  }
  b.shadowRays = rays.traced;
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
    stats_.reusedVertices += b.reusedVertices;
    stats_.blendedTimes += b.inTime.blendedTimes;
    stats_.carriedTimes += b.inTime.carriedTimes;
    stats_.laterVertices += b.inTime.laterVertices;
    stats_.interpolatedVertices += b.inTime.interpolatedVertices;
    stats_.steadyShadings += b.inTime.steadyShadings;
    stats_.stillOnlyRays += b.stillOnlyRays;
    stats_.candidateStillOnlyRays += b.candidateStillOnlyRays;
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

/// The rigid motions of the primitives that move rigidly over the shading times, shared by the
/// primitives under one transform (the same knots): (for each primitive, its motion's index or
/// -1; the motions relative to the first knot, ShadowScene::RigidMotion). A primitive whose
/// shape deforms, whose transform stands still, or whose transform cannot be inverted well at a
/// knot or a shading time has none.
std::vector<int> rigidMotions(const ShadeContext& c, const SplitScene& split, std::vector<ShadowScene::RigidMotion>& motions) {
  std::vector<int> of(c.scene.prims.size(), -1);
  if (c.times.size() <= 1) return of;
  std::map<std::pair<const MotionXform*, std::vector<double>>, int> seen;
  for (size_t pi = 0; pi < of.size(); ++pi) {
    const Primitive& p = c.scene.prims[pi];
    const std::vector<double>& knots = split.knots[pi];
    if (knots.size() <= 1 || p.times.size() > 1 || !p.xform->moving() || !p.attrs->transmission) continue;
    if (p.kind == PrimKind::Curve || p.kind == PrimKind::Point) continue;  // they turn to face the eye
    const auto [at, fresh] = seen.try_emplace({p.xform.get(), knots}, int(motions.size()));
    if (fresh) {
      const glm::dmat4 first = p.xform->at(knots[0]);
      // Rays enter the BVH through the motion's inverse at their time: it must exist at every
      // shading time and knot (a half turn between two knots blends through a flat matrix).
      bool invertible = wellInvertible(first);
      for (double t : c.times) invertible = invertible && wellInvertible(p.xform->at(t));
      for (double t : knots) invertible = invertible && wellInvertible(p.xform->at(t));
      if (!invertible) {
        at->second = -1;
      } else {
        std::vector<glm::dmat4> mats;
        const glm::dmat4 back = glm::inverse(first);
        for (double t : knots) mats.push_back(p.xform->at(t) * back);
        motions.emplace_back(knots, std::move(mats));
      }
    }
    of[pi] = at->second;
  }
  return of;
}

/// Whether the knot positions of a piece (knot-major, nV vertices each) are mats[k] · its first
/// knot's, within float rounding - the promise a rigid motion makes to ShadowScene.
bool movesBy(const std::vector<glm::vec3>& positions, size_t nV, const ShadowScene::RigidMotion& m) {
  float scale = 0;
  for (const glm::vec3& q : positions) scale = std::max({scale, std::abs(q.x), std::abs(q.y), std::abs(q.z)});
  const double eps = 1e-6 * double(scale);
  for (size_t k = 1; k < m.mats.size(); ++k)
    for (size_t v = 0; v < nV; ++v) {
      const glm::dvec3 d = glm::dvec3(m.mats[k] * glm::dvec4(glm::dvec3(positions[v]), 1.0)) - glm::dvec3(positions[k * nV + v]);
      if (!(std::abs(d.x) <= eps && std::abs(d.y) <= eps && std::abs(d.z) <= eps)) return false;
    }
  return true;
}

/// The frame's micropolygons at the shading time, every leaf of a primitive that casts shadows
/// diced again (the shading pass's grids stream out; keeping them all would hold the frame) -
/// from `split`, the frame's own leaves, or leaves split at a coarser shadow rate.
std::unique_ptr<ShadowScene> buildShadowScene(const ShadeContext& c, const SplitScene& split, MovingCasters* movingCasters = nullptr) {
  std::vector<ShadowScene::Piece> pieces(split.flat.size());
  std::vector<ShadowScene::RigidMotion> motions;
  const std::vector<int> rigidOf = rigidMotions(c, split, motions);
  std::vector<ShadowBox> moved(pieces.size());  // a moving piece's box over the interval
  tbb::parallel_for(tbb::blocked_range<size_t>(0, pieces.size(), 8), [&](const tbb::blocked_range<size_t>& r) {
    DicedGrid g;
    for (size_t i = r.begin(); i != r.end(); ++i) {
      const auto [pi, leaf] = split.flat[i];
      const Primitive& p = c.scene.prims[pi];
      if (!p.attrs->transmission) continue;
      diceLeaf(p, *leaf, split.knots[pi], c.shadeAt, c.nearClip, c.perspective, g);
      const size_t K = split.knots[pi].size();
      if (c.times.size() > 1 && K > 1) {
        // Shading in time: the micropolygons move over the interval (their positions at the knots).
        const bool moves = !store::verticesStandStill(g.positions, g.numVertices, 0, g.numVertices);
        if (moves)
          for (const glm::vec3& q : g.positions) moved[i].add(q);
        const int rigid = rigidOf[pi];
        if (moves && (rigid < 0 || !movesBy(g.positions, g.numVertices, motions[size_t(rigid)]))) {
          pieces[i].P = std::move(g.positions);
          pieces[i].knots = split.knots[pi];
        } else {
          // Standing still, or moving rigidly: one set of vertices, its first knot's.
          pieces[i].P.assign(g.positions.begin(), g.positions.begin() + g.numVertices);
          if (moves) pieces[i].rigid = rigid;
        }
      } else {
        pieces[i].P.assign(g.P.begin(), g.P.end());
      }
      pieces[i].corners = std::move(g.corners);
      g = DicedGrid{};
    }
  });
  if (movingCasters) {
    // One box per moving primitive, over its pieces at every knot.
    std::vector<ShadowBox> boxes;
    uint32_t last = UINT32_MAX;
    for (size_t i = 0; i < pieces.size(); ++i) {
      if (!(moved[i].lo.x <= moved[i].hi.x)) continue;
      if (split.flat[i].first != last) boxes.emplace_back(), last = split.flat[i].first;
      boxes.back().lo = glm::min(boxes.back().lo, moved[i].lo), boxes.back().hi = glm::max(boxes.back().hi, moved[i].hi);
    }
    if (!boxes.empty()) *movingCasters = MovingCasters(c.lit, std::move(boxes));
  }
  return c.times.size() > 1 ? std::make_unique<ShadowScene>(pieces, c.times.front(), c.times.back(), motions, c.times) : std::make_unique<ShadowScene>(pieces);
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
  ShadeContext context{scene, split, meta.schema, {}, {}, {}, iv.shadeAt, cam.nearClip, cam.projection == store::Projection::Perspective};
  context.lit.reserve(scene.lights.size());
  for (const auto& l : scene.lights) context.lit.push_back(resolveLight(l, iv.shadeAt)), context.lit.back().stored = uint32_t(context.lit.size() - 1);
  for (const auto& a : meta.schema.attrs) {
    context.vars.push_back(varOf(a.name));
    context.varLight.push_back(context.vars.back() == Var::Lvis ? std::stoi(a.name.substr(a.name.find('.') + 1)) : -1);
    context.viewInputs = context.viewInputs || context.vars.back() == Var::Cvi;
  }
  if (iv.times.size() > 1) {
    context.times = iv.times;
    context.tolerance = *o.timeTolerance;
    context.timeStride = o.timeStride;
    context.ci = meta.schema.ci(), context.oi = meta.schema.oi();
    context.litAt.resize(iv.times.size());
    for (size_t k = 1; k < iv.times.size(); ++k)
      for (const auto& l : scene.lights) context.litAt[k].push_back(resolveLight(l, iv.times[k])), context.litAt[k].back().stored = uint32_t(context.litAt[k].size() - 1);
    for (size_t ai = 0; ai < meta.schema.attrs.size(); ++ai) {
      const std::string& name = meta.schema.attrs[ai].name;
      if (store::StoreMeta::timedIndex(name) || meta.schema.find(store::StoreMeta::timedName(name, 1)) < 0) continue;
      std::vector<int> slots{int(ai)};
      for (size_t k = 1; k < iv.times.size(); ++k) slots.push_back(meta.schema.find(store::StoreMeta::timedName(name, k)));
      if (int(ai) == context.ci || int(ai) == context.oi) context.changeSlots.push_back(int(ai));
      context.timedSlots.push_back(std::move(slots));
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
    stats.rigidCasters = shadows->rigidInstances(), stats.rigidMicropolygons = shadows->rigidMicropolygons();
    stats.fixedCasterInstants = shadows->fixedInstants();
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
