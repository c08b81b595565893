// The single shading pass: every primitive of a FrameScene is split, diced, shaded once at one
// time and streamed as grids into a GridSink (the store writer), positions at every motion knot.
//
// Parallel with TBB: splitting runs per primitive, dicing and shading per batch of grids in a
// pipeline whose last stage hands grids to the sink in scene order (primitive order, then
// dicing order), so the output is identical for any thread count and the memory in flight is
// bounded by the pipeline's token count, not by the scene.
#pragma once

#include <cstdint>
#include <optional>
#include <string>
#include <utility>

#include "shade/dice.h"
#include "shade/scene.h"
#include "store/model.h"
#include "store/writer.h"

namespace reshutter::shade {

struct ShadeOptions {
  /// Time at which every vertex is shaded; default: the store interval's open (the reference
  /// workflow shades at shutter open). Outside a primitive's motion it sees the nearest knot.
  std::optional<double> shadeAt;
  /// Restricts the store to [first, second] instead of the scene's Shutter (reference mode:
  /// "shade again at the target interval"); positions at its ends are interpolated exactly.
  std::optional<std::pair<double, double>> interval;
  DiceOptions dice;
  store::Rational fps{24, 1};
  int tileSize = 32;
  /// Ray-traced shadows for the lights that ask for them (false: every light unshadowed).
  bool shadows = true;
  /// Rays per shaded point towards an area light or a distant light with an angular size: the
  /// soft-shadow quality knob (docs/accuracy.md has its error against time).
  int shadowSamples = 16;
  /// The shadow scene's micropolygons at this many times the shading rate (area): 1 is the
  /// frame's own micropolygons; 4 has about a quarter as many, cheaper to build, with
  /// shadow edges traced against a coarser surface (docs/accuracy.md has the trade).
  double shadowRate = 1;
  /// Shading in time: unset shades every point once (at shadeAt). Set, each grid whose shading
  /// can change over the interval (it moves or deforms under lights or a view-dependent shader,
  /// a light moves, a colour or shader is animated) is also shaded at the other of `shadingTimes`
  /// times spread evenly over the interval (the first at its open), and keeps them when its colour
  /// or opacity changes by more than this tolerance somewhere (0: whenever it may change). The
  /// re-sampler then blends each sample's colour at its own time.
  std::optional<double> timeTolerance;
  int shadingTimes = 5;
  /// Shading in time: later times are shaded at every timeStride-th vertex of a grid's lattice
  /// (and its last), then in full wherever the change since the first time is not smooth there
  /// (a coarse lattice point's second difference, or a lone span's difference, above twice the
  /// tolerance at either end of a span); the other vertices take the change interpolated from
  /// their cell's corners. 1: every vertex at every time. A change narrower than a cell that
  /// touches none of its corners (a shadow thinner than timeStride micropolygons) is missed there.
  int timeStride = 2;
  /// Keep what re-evaluating the view-dependent term for another eye needs (store::ViewTerm),
  /// on the grids whose shader has one: a render from another camera then lights speculars and
  /// headlights for its own eye. Off: other cameras see the primary camera's shading.
  bool viewDependent = false;
};

struct ShadeStats {
  uint64_t primitives = 0, grids = 0, micropolygons = 0, vertices = 0, movingGrids = 0, movingMicropolygons = 0;
  uint64_t culledPieces = 0, droppedMicropolygons = 0, eyeSplits = 0;
  /// With cameras besides the primary (RIB Camera requests): micropolygons split for every camera,
  /// and what the primary alone would have split of the same pieces. Their ratio is the multi-camera
  /// reference's "geometry detail expansion" (1 with one camera).
  uint64_t allCameraDetail = 0, primaryCameraDetail = 0;
  double detailExpansion() const { return primaryCameraDetail ? double(allCameraDetail) / double(primaryCameraDetail) : 1.0; }
  uint64_t trimmedMicropolygons = 0;                // cut away by trim curves
  uint64_t forcedCuts = 0;                          // leaf sides the split depth limit left unfinished (split.h): possible cracks
  uint64_t overBudgetPrimitives = 0;                // diced coarser for needing more than DiceOptions::maxMicropolygonsPerPrimitive
  uint64_t textureLookups = 0;                      // filtered texture lookups (shade/texture.h), one per textured vertex
  uint64_t missingTextures = 0;                     // textures that could not be read (shown magenta)
  uint64_t shadowMicropolygons = 0;                 // in the shadow scene (0: no light asked for shadows)
  uint64_t rigidCasters = 0, rigidMicropolygons = 0;  // shading in time: the rigid motions instanced in it, and the micropolygons moved so
  uint64_t fixedCasterInstants = 0;                 // shading in time: how many shading instants those instances are also fixed at (ShadowScene)
  uint64_t shadowRays = 0;                          // traced towards lights
  double shadowBuildSeconds = 0;                    // dicing the frame for the shadow scene and building its BVH
  uint64_t timeCandidateGrids = 0;                  // shading in time: grids whose shading could change, shaded at every time
  uint64_t timedGrids = 0, timedMicropolygons = 0;  // of them, those that changed enough to keep every time
  uint64_t blendedTimes = 0;                        // candidates' later times blended between shaded ones (their middle lay within the tolerance of the blend)
  uint64_t carriedTimes = 0;         // moving candidates' later times carried by their rigid motion from the first, not diced again
  uint64_t laterVertices = 0;        // vertex shadings at candidates' later times (blended times shade none)
  uint64_t interpolatedVertices = 0;  // of candidates' later times, vertices whose change was interpolated on the coarse lattice (timeStride)
  uint64_t steadyShadings = 0;       // candidates' later shadings on the coarse lattice whose coarse points all kept their first values (the rest copied)
  uint64_t reusedVertices = 0;       // vertex shadings at later times that kept the first time's outputs (only shadows could change, and did not)
  uint64_t stillOnlyRays = 0;        // rays of grids no moving caster can shadow, traced against the still micropolygons only
  uint64_t candidateStillOnlyRays = 0;  // the same for candidates' rays towards a light no moving caster can shadow them from
  std::vector<double> shadingTimes;  // empty: shaded once
  double shadeAt = 0;
  double seconds = 0;
};

/// The store metadata for `scene` under `options`: frame, shutter (or interval), cameras, and
/// the schema (Ci, Oi and the requested output variables).
store::StoreMeta storeMeta(const FrameScene& scene, const ShadeOptions& options);

/// Runs the pass. Grids go to `sink` from the calling thread only.
ShadeStats shadeFrame(const FrameScene& scene, const ShadeOptions& options, store::GridSink& sink);

struct StoreResult {
  ShadeStats shade;
  store::WriteStats write;
};
/// Shades `scene` into a new store at `path` (written atomically: nothing appears there unless
/// the whole pass succeeds).
StoreResult shadeToStore(const FrameScene& scene, const ShadeOptions& options, const std::string& path);

}  // namespace reshutter::shade
