// Inside the shading pass (shade/shading_pass.h says what it promises): what shading one diced
// grid needs and does. The frame's shading context, a grid's outputs, shading a grid's vertices
// at one time (shade_grid.cpp), and shading in time - which grids may shade differently over
// the shutter, and shading them at the other times (shade_in_time.cpp). shading_pass.cpp runs
// the pipeline around them. Only those files include this one.
#pragma once

#include <cstdint>
#include <span>
#include <string>
#include <utility>
#include <vector>

#include <glm/vec3.hpp>

#include "shade/dice.h"
#include "shade/scene.h"
#include "shade/shaders.h"
#include "shade/shadows.h"
#include "shade/texture.h"
#include "store/model.h"

namespace reshutter::shade::pass {

// Timed: "Ci@k" / "Oi@k", filled by shading at the other times (shadeInTime()).
/// What a schema attribute holds. Cvi .. Lvis: the view-dependent term's inputs
/// (ShadeOptions::viewDependent; store/model.h names them), on grids whose shader has one.
enum class Var : uint8_t { Ci, Oi, P, N, Ng, s, t, u, v, Cs, Os, depth, specular, Timed, Cvi, CviBack, Kspec, Nspec, roughness, Lvis };
Var varOf(const std::string& name);

// What the pipeline carries: grids shaded and ready to send.
struct GridOut {
  uint32_t prim = 0;
  uint32_t numVertices = 0;
  std::vector<glm::vec3> positions;
  std::vector<uint32_t> corners;
  std::vector<std::vector<float>> attrs;  // parallel to the schema
};

struct SplitScene {
  std::vector<std::vector<double>> knots;              // per primitive: its knots inside the interval
  std::vector<std::vector<Leaf>> leaves;               // per primitive, in dicing order
  std::vector<std::pair<uint32_t, const Leaf*>> flat;  // (primitive, leaf): primitive order, then dicing order
};

/// What shading any leaf needs, fixed for the frame.
struct ShadeContext {
  const FrameScene& scene;
  const SplitScene& split;
  const store::Schema& schema;
  std::vector<Var> vars;      // what each schema attribute holds
  std::vector<int> varLight;  // per schema attribute: for Var::Lvis, the stored light it is the visibility of
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
  MovingCasters movingCasters{};
  double tolerance = 0;
  int timeStride = 1;  // ShadeOptions::timeStride
  int ci = -1, oi = -1;
  // Per attribute carried in time (Ci, Oi, output variables): its schema slot at each shading
  // time ([0]: the attribute itself, [k]: "name@k").
  std::vector<std::vector<int>> timedSlots{};
  // Of Ci and Oi, the slots carried in time: what decides whether a grid's shading changed
  // (Oi only where an opacity can change; elsewhere its later values are never kept).
  std::vector<int> changeSlots{};
  bool viewInputs = false;  // the schema holds the view-dependent terms' inputs (Var::Cvi ...)
};

/// Shading in time for a grid whose shading can change only through moving casters' shadows (it
/// stands still, its lights stand still, nothing of it is animated): its shadow rays are the same
/// at every time, so the first time keeps the ones no still micropolygon blocks, later times
/// trace those (not made again) against the moving micropolygons only, and a vertex whose every
/// light comes out as visible as at the first time keeps that time's outputs (nothing else can
/// differ).
struct ShadowReuse {
  bool recording = true;  // the first time: record; later: reuse
  struct Traced {         // one light at one vertex
    uint32_t n = 0;       // the share's denominator (0: not traced - the light is behind, or casts no shadows)
    uint32_t first = 0, open = 0;  // its rays that no still micropolygon blocks, in `open`
  };
  std::vector<Traced> traced;                              // [vertex * lights + light]
  std::vector<ShadowRay> open;                             // the rays later times trace (against the moving micropolygons only)
  std::vector<float> visibility;                           // [vertex * lights + light] at the first time (1: not traced)
  const std::vector<std::vector<float>>* first = nullptr;  // the first time's outputs (reusing)
  uint64_t reusedVertices = 0;
};

/// Shadow rays a grid's shading counted.
struct RayCounts {
  uint64_t traced = 0;     // towards lights (a grid only shadows change: its first time's, again at each later time)
  uint64_t stillOnly = 0;  // of them, against the still micropolygons only: no moving caster can shadow the grid from their light
};

/// Shades every vertex of the diced grid `g` (its corners: `corners`) of primitive `p` at `time`,
/// shading time k of the pass (0: the first), into `attrs` (parallel to the schema); `reuse`
/// (shading in time, a grid only shadows change): the first time records its rays, later times
/// reuse them; `movingShadows` (shading in time): per light of `lights`, whether a moving caster
/// may shadow the grid from it (MovingCasters) - where none can, its rays skip the moving
/// micropolygons; empty: every light's rays trace them; `only`: shade just these vertices (a
/// later time on a coarser lattice), leaving the others' outputs as they are; `bias`: the shadow
/// rays' lifts off the surface at this time (shadowBias()), made by the first call that needs
/// them when empty and read by the later calls at the same time.
void shadeVertices(const ShadeContext& c, const Primitive& p, const DicedGrid& g, std::span<const uint32_t> corners, std::span<const LitLight> lights,
                   double time, size_t k, uint64_t leafIndex, std::vector<std::vector<float>>& attrs, RayCounts& rays, ShadowReuse* reuse,
                   std::span<const uint8_t> movingShadows, std::span<const uint32_t> only, std::vector<float>& bias);

/// How far each vertex's shadow rays start off the surface: half its longest micropolygon edge
/// (the diced surface cuts corners of the true one by about that much).
void shadowBias(const DicedGrid& g, std::span<const uint32_t> corners, std::vector<float>& bias);

/// Whether the affine part of `m` can be inverted without losing most of its digits: its
/// determinant against the cube of its longest column (1 for a rotation at any scale; a column
/// collapsed against the others, as a half turn blended at its middle, is not).
bool wellInvertible(const glm::dmat4& m);
/// Whether a primitive's colour, opacity or shader is given at several times (a motion block).
bool animated(const Attributes& a);
/// Whether a light is somewhere else (in camera space) at the interval's close than at its open.
bool lightMoves(const Light& l, double open, double close);
/// Whether anything in the scene can make shading differ over [open, close].
bool sceneMayShadeInTime(const FrameScene& scene, double open, double close);
/// Whether grid `g` of primitive `pi` can shade differently at another time of the interval;
/// `movingShadows`: per light, whether a moving caster may shadow the grid from it.
bool mayShadeDifferently(const ShadeContext& c, uint32_t pi, std::span<const glm::vec3> positions, uint32_t nV, bool moves, std::span<const uint32_t> lights,
                         std::vector<uint8_t>& movingShadows);
/// Whether only moving casters' shadows can change a grid's shading (ShadowReuse applies).
bool onlyShadowsChange(const ShadeContext& c, uint32_t pi, bool moves, std::span<const uint32_t> lights);
/// What shading candidates at the other times did (ShadeStats says what each counts).
struct InTimeCounts {
  uint64_t blendedTimes = 0, carriedTimes = 0;
  uint64_t laterVertices = 0, interpolatedVertices = 0;
  uint64_t steadyShadings = 0;  // later shadings of a grid whose coarse points all kept their first values
};
/// Shades a candidate at the other times (`firstBias`: its shadow rays' lifts at the first time,
/// empty when none were made); whether it kept them (shade_in_time.cpp).
bool shadeInTime(const ShadeContext& c, uint32_t pi, const Leaf& leaf, const DicedGrid& g, bool moves, std::span<const uint32_t> lightIdx,
                 std::span<const uint8_t> movingShadows, std::span<const float> firstBias, uint64_t leafIndex, GridOut& out, RayCounts& rays,
                 ShadowReuse* reuse, InTimeCounts& counts);

}  // namespace reshutter::shade::pass
