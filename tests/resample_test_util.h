// Scenes for re-sampler tests, built micropolygon by micropolygon in raster terms, and an
// independent reference: a brute-force ray caster that intersects every sample's ray with every
// micropolygon (as two triangles, like the rasterizer) at the sample's own time, in double
// precision, with no bounds, buckets or edge-function tricks.
#pragma once

#include <array>
#include <memory>
#include <string>
#include <utility>
#include <vector>

#include "resample/resampler.h"
#include "store/model.h"
#include "store/reader.h"
#include "store/writer.h"

namespace reshutter::test {

/// One micropolygon as the tests think of it: camera-space corners per knot, constant colour.
struct TestMp {
  std::vector<std::array<glm::dvec3, 4>> knots;  // corners p0 p1 p2 p3 per knot
  bool triangle = false;
  glm::vec3 ci{1, 1, 1}, oi{1, 1, 1};  // Ci premultiplied
  uint32_t objectId = 1, gridId = 0;
  uint8_t flags = 0;
};

struct TestScene {
  store::StoreMeta meta;
  std::vector<double> knotTimes{0.0};  // frame-relative, one schedule for every micropolygon
  std::vector<TestMp> mps;
  /// Raster position (rx, ry) at camera depth z → camera-space point.
  glm::dvec3 cam(double rx, double ry, double z) const;
  /// An axis-aligned raster rectangle at depth z as a quad (corner order p0..p3 around it).
  std::array<glm::dvec3, 4> rect(double x0, double y0, double x1, double y1, double z) const;
};

/// A scene of `width`×`height` with a perspective camera (fov 50, near 0.5), frame 1, shutter
/// [0, 1], schema Ci, Oi (vertex colours) plus a vertex normal "N".
TestScene makeScene(int width, int height, std::vector<double> knotTimes = {0.0, 1.0});

/// 40 random quads and triangles on a 40×28 frame, moving over knots 0, 0.4, 1 (in depth too),
/// some transparent, some mattes, all two-sided, overlapping in depth 3 to 30; with `someStill`
/// every fifth stands still.
TestScene randomQuadScene(uint64_t seed, bool someStill);

/// Writes the scene as a store: each micropolygon its own grid, or (asOneGrid) all of them one
/// grid in scene order with the first one's object id and flags (no shared vertices either way).
std::shared_ptr<const store::StoreReader> writeScene(const TestScene& scene, const std::string& path, bool asOneGrid = false);

/// A render spec for one store over [open, close] (frame-relative), box filter 1×1.
resample::RenderSpec specFor(std::shared_ptr<const store::StoreReader> reader, double open, double close, int nx, int ny, uint64_t seed = 0);

/// Fraction of the unit disk with x <= a: the x marginal of a uniform lens point, so the share of
/// a pixel's lens samples that see past a straight edge a·r away (r the circle of confusion).
double diskBelow(double a);
/// A lens whose circle of confusion for depth z has raster radius r on the scene's camera,
/// focused at d (the spec's overrides).
resample::RenderSpec::LensOverride lensFor(const TestScene& s, double r, double z, double d);

/// The reference alpha per pixel (box filter over the pixel's own samples) of an opaque or
/// transparent scene: per sample, the front-to-back composite of every surface the ray hits at
/// the sample's time, using the same sample positions and times as `spec` - and, with a lens
/// (the camera's or spec.lens), the same lens points, each sample's ray leaving the lens there.
struct Reference {
  std::vector<double> r, g, b, a;  // per pixel of the spec's full image
};
Reference rayCast(const TestScene& scene, const resample::RenderSpec& spec, int width, int height);

/// The same ray caster per sample, over any pixel region - beyond the image too, where the
/// filter's margin reaches: the composite R G B A of sample i of pixel (px, py) at
/// [((py - y0) * width + (px - x0)) * spp + i]. `imageHeight` is the image's (the rolling
/// shutter's rows).
struct SampleReference {
  int x0 = 0, y0 = 0, width = 0, height = 0, spp = 1;
  std::vector<double> r, g, b, a;
  size_t at(int px, int py, int i) const { return (size_t(py - y0) * size_t(width) + size_t(px - x0)) * size_t(spp) + size_t(i); }
};
SampleReference rayCastSamples(const TestScene& scene, const resample::RenderSpec& spec, int imageHeight, int x0, int y0, int width, int height);

/// Exact time-averaged coverage of pixel (px, py) by the raster rectangle
/// [x0 + vx·t, x0 + w + vx·t] × [y0 + vy·t, y0 + h + vy·t] over t ∈ [a, b], weighted by a shutter
/// opening that is linear between `shapeTimes` (absolute, with weights `shapeWeights`; empty: box).
/// The overlap is a product of two piecewise-linear functions of t and the weight is piecewise
/// linear, so Simpson's rule is exact on each piece between the times where an edge crosses a
/// pixel boundary or the weight changes slope.
double analyticCoverage(int px, int py, double x0, double y0, double w, double h, double vx, double vy, double a, double b,
                        const std::vector<double>& shapeTimes = {}, const std::vector<double>& shapeWeights = {});

/// Expects render r of scene s to agree with the ray caster (rayCast()) on the same samples: only
/// samples within float rounding of an edge may differ, a handful in 18 k.
void expectRayCasterAgrees(const TestScene& s, const resample::RenderSpec& spec, const resample::RenderResult& r, int width, int height,
                           const std::string& what);

const resample::ImageChannel& channel(const resample::RenderResult& r, const std::string& name);

/// Renders `spec` with occlusion culling (first) and without (second).
std::pair<resample::RenderResult, resample::RenderResult> renderCulledAndNot(resample::RenderSpec spec);

/// Expects every flat channel and every deep sample of two renders to be the same, bit for bit.
void expectSameOutputs(const resample::RenderResult& got, const resample::RenderResult& want, const std::string& what);

}  // namespace reshutter::test
