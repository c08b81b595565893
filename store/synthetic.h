// A synthetic micropolygon scene for benchmarks and tests: N roughly one-pixel quads emitted grid
// by grid (16×16 micropolygons sharing 17×17 vertices, as a REYES dicer produces them), placed at
// random over the screen at random depths, each grid translating by up to `maxMotionPx` pixels
// over the shutter, with smooth per-vertex Ci and Oi. Deterministic for a given seed.
#pragma once

#include <cstdint>

#include "store/model.h"
#include "store/writer.h"

namespace reshutter::store {

struct SyntheticOptions {
  uint64_t micropolygons = 2'000'000;
  int width = 1920, height = 1080;
  int gridSize = 16;
  double maxMotionPx = 50.0;
  int knots = 2;                     // 1 = static
  double transparentFraction = 0.0;  // share of grids with Oi < 1
  /// Share of grids that stand still yet carry every knot, as a P + blurP dump writes its
  /// static objects (blurP = P): the case the writer stores as static.
  double stillFraction = 0.0;
  /// Relative amplitude of per-vertex colour noise standing in for texture detail: shaded colours
  /// of real scenes are not smooth down to the last mantissa bit, and compression must not be
  /// measured on data that is.
  double texture = 0.05;
  uint64_t seed = 1;
  AttrCodec colorCodec = AttrCodec::Lossless;
  AttrCodec opacityCodec = AttrCodec::Lossless;
};

StoreMeta syntheticMeta(const SyntheticOptions& options);
/// Emits the grids into `sink` (a StoreWriter opened with syntheticMeta, say); returns the
/// micropolygon count.
uint64_t generateSynthetic(const SyntheticOptions& options, GridSink& sink);

}  // namespace reshutter::store
