// The re-sampler's hard cases (ctest label `hard`): eye-plane crossings during the shutter,
// geometry behind the camera or 1e7 px off screen, degenerate and bow-tie micropolygons, motion
// of 1e-6 px and 5000 px, knots 1e-7 frames apart, exact depth ties, filters whose weights sum to
// ~0 at the border. Each asserts finite output and agreement with the brute-force ray caster
// (tests/resample_test_util.h) within a stated bound.
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <iostream>
#include <optional>

#include <gtest/gtest.h>
#include <tbb/global_control.h>

#include "common/random.h"
#include "resample/coverage.h"
#include "resample/deep.h"
#include "resample/gather.h"
#include "store/synthetic.h"
#include "store/writer.h"
#include "tests/resample_test_util.h"
#include "tests/test_util.h"

using namespace reshutter;
using namespace reshutter::resample;
using namespace reshutter::test;

namespace {

void expectFinite(const RenderResult& r) {
  for (const auto& c : r.image.channels)
    for (size_t i = 0; i < c.f.size(); ++i) ASSERT_TRUE(std::isfinite(c.f[i])) << c.name << " pixel " << i;
  const auto& A = channel(r, "A").f;
  for (float a : A) {
    ASSERT_GE(a, -1e-6f);
    ASSERT_LE(a, 1 + 1e-6f);
  }
}

// Mean absolute difference per pixel and channel against the ray caster; returns it.
double compareWithRayCaster(const TestScene& s, const std::string& path, double a, double b, int n = 4, int bucket = 0) {
  auto reader = writeScene(s, path);
  RenderSpec spec = specFor(reader, a, b, n, n, 9);
  if (bucket > 0) spec.bucketSize = bucket;
  RenderResult r = render(spec);
  expectFinite(r);
  const int W = s.meta.cameras[0].width, H = s.meta.cameras[0].height;
  Reference ref = rayCast(s, spec, W, H);
  double diff = 0;
  for (size_t p = 0; p < ref.a.size(); ++p) diff += std::abs(channel(r, "A").f[p] - ref.a[p]) + std::abs(channel(r, "R").f[p] - ref.r[p]);
  return diff / (2.0 * ref.a.size());
}

TestMp cameraQuad(std::vector<std::array<glm::dvec3, 4>> knots, glm::vec3 ci = {0.8f, 0.4f, 0.2f}) {
  TestMp mp;
  mp.knots = std::move(knots);
  mp.ci = ci;
  mp.flags = store::kTwoSided;
  return mp;
}

// The synthetic scenes (store/synthetic.h, 160×120, ~2.5 layers deep) that the two-way
// comparisons render: moving with two and three knots, static, and partly transparent.
struct SyntheticCase {
  const char* name;
  int knots;
  double motion, transparent;
};
constexpr SyntheticCase kSyntheticCases[] = {{"two-knots", 2, 40, 0.0}, {"three-knots", 3, 40, 0.0}, {"static", 1, 0, 0.0}, {"transparent", 2, 25, 0.4}};

std::shared_ptr<const store::StoreReader> syntheticStore(const ScratchDir& dir, const SyntheticCase& c, uint64_t micropolygons, uint64_t seed, int width = 160,
                                                         int height = 120) {
  store::SyntheticOptions so;
  so.micropolygons = micropolygons, so.width = width, so.height = height, so.knots = c.knots, so.maxMotionPx = c.motion;
  so.transparentFraction = c.transparent, so.seed = seed;
  const std::string path = dir.path(std::string(c.name) + ".mps");
  {
    store::StoreWriter writer(path, store::syntheticMeta(so));
    store::generateSynthetic(so, writer);
    writer.close();
  }
  return std::make_shared<const store::StoreReader>(path);
}

// A 16 spp gaussian 2×2 render of frame 1 with shutter 0: the full frame; 1: a sub-interval;
// 2: interlaced fields; 3: a zero-length shutter.
RenderSpec comparisonSpec(std::shared_ptr<const store::StoreReader> reader, int shutter) {
  RenderSpec spec = specFor(reader, 0.0, 1.0, 4, 4, 11);
  spec.filter = FilterSpec::parse("gaussian:2x2", "test");
  if (shutter == 1) spec.shutter = ShutterModel::progressive(1.3, 1.55);
  if (shutter == 2) spec.shutter = ShutterModel::fields({1.0, 1.25}, {1.5, 1.75}, 0);
  if (shutter == 3) spec.shutter = ShutterModel::progressive(1.6, 1.6);
  return spec;
}

std::array<glm::dvec3, 4> square(double cx, double cy, double half, double z) {
  return {glm::dvec3(cx - half, cy - half, z), glm::dvec3(cx + half, cy - half, z), glm::dvec3(cx + half, cy + half, z), glm::dvec3(cx - half, cy + half, z)};
}

}  // namespace

TEST(ResampleHard, EyePlaneCrossingDuringTheShutter) {
  ScratchDir dir;
  TestScene s = makeScene(32, 24);
  // A tilted quad flying through the eye plane: behind the camera at open, in front at close.
  s.mps.push_back(cameraQuad({{glm::dvec3(-3, -2, -4), glm::dvec3(3, -2, -3), glm::dvec3(3, 2, -2), glm::dvec3(-3, 2, -3)},
                              {glm::dvec3(-3, -2, 3), glm::dvec3(3, -2, 4), glm::dvec3(3, 2, 5), glm::dvec3(-3, 2, 4)}}));
  // And one crossing sideways, half in front of the near plane at every time.
  s.mps.push_back(cameraQuad({{glm::dvec3(-1, -1, -2), glm::dvec3(1, -1, 6), glm::dvec3(1, 1, 6), glm::dvec3(-1, 1, -2)},
                              {glm::dvec3(-2, -1, -2), glm::dvec3(0, -1, 6), glm::dvec3(0, 1, 6), glm::dvec3(-2, 1, -2)}},
                             {0.1f, 0.9f, 0.1f}));
  for (auto [a, b] : {std::pair{0.0, 1.0}, std::pair{0.4, 0.6}, std::pair{0.55, 0.55}})
    EXPECT_LT(compareWithRayCaster(s, dir.path("eye.mps"), a, b), 3e-3) << a << ":" << b;
}

// A motion-free wall from behind the camera to depth 20: its two corners in front project into
// one 8-pixel bucket, yet it covers every bucket to their right. A bucket must not drop it because
// its projected corners miss the bucket (the static path's chunk cull).
TEST(ResampleHard, StaticWallThroughTheEyePlaneInSmallBuckets) {
  ScratchDir dir;
  TestScene s = makeScene(32, 24, {0.0});
  const glm::dvec3 top = s.cam(17, -4, 20), bottom = s.cam(17, 28, 20);
  s.mps.push_back(cameraQuad({{glm::dvec3(top.x, top.y, -3), glm::dvec3(top.x, top.y, 20), glm::dvec3(top.x, bottom.y, 20), glm::dvec3(top.x, bottom.y, -3)}}));
  EXPECT_LT(compareWithRayCaster(s, dir.path("wall.mps"), 0, 1, 4, 8), 3e-3);
  EXPECT_LT(compareWithRayCaster(s, dir.path("wall.mps"), 0.5, 0.5, 4, 8), 3e-3);
}

TEST(ResampleHard, BehindTheCameraAndFarOffScreen) {
  ScratchDir dir;
  TestScene s = makeScene(24, 16);
  s.mps.push_back(cameraQuad({square(0, 0, 5, -3), square(1, 0, 5, -1)}));  // always behind
  const double far = 1e7;                                                   // pixels off screen
  s.mps.push_back(cameraQuad({{s.cam(far, far, 10), s.cam(far + 3, far, 10), s.cam(far + 3, far + 3, 10), s.cam(far, far + 3, 10)},
                              {s.cam(far, far, 10), s.cam(far + 3, far, 10), s.cam(far + 3, far + 3, 10), s.cam(far, far + 3, 10)}}));
  auto reader = writeScene(s, dir.path("away.mps"));
  RenderResult r = render(specFor(reader, 0, 1, 3, 3));
  expectFinite(r);
  for (float a : channel(r, "A").f) EXPECT_EQ(a, 0.f);
  // A quad whose corners are 1e7 px away in every direction covers the whole screen exactly.
  TestScene big = makeScene(24, 16);
  big.mps.push_back(cameraQuad({big.rect(-far, -far, far, far, 50), big.rect(-far + 7, -far, far + 7, far, 50)}));
  auto bigReader = writeScene(big, dir.path("big.mps"));
  RenderResult rb = render(specFor(bigReader, 0, 1, 3, 3));
  expectFinite(rb);
  for (float a : channel(rb, "A").f) EXPECT_EQ(a, 1.f);
}

TEST(ResampleHard, DegenerateAndBowTieMicropolygons) {
  ScratchDir dir;
  TestScene s = makeScene(24, 16);
  const auto p = s.cam(5, 5, 10);
  s.mps.push_back(cameraQuad({{p, p, p, p}, {p, p, p, p}}));                                             // a point
  s.mps.push_back(cameraQuad({{s.cam(2, 2, 10), s.cam(8, 8, 10), s.cam(14, 14, 10), s.cam(20, 20, 10)},  // collinear
                              {s.cam(3, 2, 10), s.cam(9, 8, 10), s.cam(15, 14, 10), s.cam(21, 20, 10)}}));
  auto degenerate = writeScene(s, dir.path("degenerate.mps"));
  RenderResult r = render(specFor(degenerate, 0, 1, 4, 4));
  expectFinite(r);
  for (float a : channel(r, "A").f) EXPECT_EQ(a, 0.f);
  // A bow-tie (non-planar, self-crossing) quad is rendered as the triangles (p0 p1 p2), (p0 p2 p3).
  TestScene bow = makeScene(24, 16);
  bow.mps.push_back(cameraQuad({{bow.cam(3, 3, 8), bow.cam(20, 13, 12), bow.cam(20, 3, 9), bow.cam(3, 13, 15)},
                                {bow.cam(4, 3, 8), bow.cam(21, 13, 10), bow.cam(21, 3, 9), bow.cam(4, 13, 18)}}));
  EXPECT_LT(compareWithRayCaster(bow, dir.path("bow.mps"), 0, 1), 3e-3);
}

// A square, and a bar 2000 px off screen, both moving 1e-6 px or 5000 px over the shutter. At
// 5000 px the square leaves the frame within 1/170 of the shutter and the bar streaks through it,
// covering each pixel for 1/250: ~130 of the frame's 30 000 samples, so a frame-wide mean
// difference would pass an empty image. Count the samples and pixels that disagree with the ray
// caster instead, against how many it covers, and hold the covered total to the exact
// time-averaged coverage.
TEST(ResampleHard, TinyAndHugeMotion) {
  ScratchDir dir;
  const int W = 40, H = 30, n = 5, N = n * n;
  for (double motion : {1e-6, 5000.0}) {
    TestScene s = makeScene(W, H);
    s.mps.push_back(cameraQuad({s.rect(10.3, 8.2, 22.7, 19.9, 12), s.rect(10.3 + motion, 8.2 + motion * 0.3, 22.7 + motion, 19.9 + motion * 0.3, 12)}));
    s.mps.push_back(cameraQuad({s.rect(-2000, 0, -1980, 30, 9), s.rect(-2000 + motion, 0, -1980 + motion, 30, 9)}, {0.2f, 0.2f, 0.9f}));
    auto reader = writeScene(s, dir.path("motion.mps"));
    const RenderSpec spec = specFor(reader, 0, 1, n, n, 9);
    const RenderResult r = render(spec);
    expectFinite(r);
    const Reference ref = rayCast(s, spec, W, H);
    const auto &A = channel(r, "A").f, &R = channel(r, "R").f, &B = channel(r, "B").f;
    // Box filter 1×1, opaque surfaces: a pixel's alpha is its covered samples / N, so N·|ΔA| counts
    // the samples one side covers and the other misses (at least); R and B tell the two apart.
    double covered = 0, refCovered = 0, disagreeing = 0, analytic = 0;
    int coveredPixels = 0, disagreeingPixels = 0;
    for (int py = 0; py < H; ++py)
      for (int px = 0; px < W; ++px) {
        const size_t p = size_t(py) * W + px;
        covered += A[p] * N, refCovered += ref.a[p] * N;
        disagreeing += std::round(std::abs(A[p] - ref.a[p]) * N);
        coveredPixels += ref.a[p] > 0;
        disagreeingPixels += std::max({std::abs(A[p] - ref.a[p]), std::abs(R[p] - ref.r[p]), std::abs(B[p] - ref.b[p])}) > 1e-5;
        analytic +=
            N * (analyticCoverage(px, py, 10.3, 8.2, 12.4, 11.7, motion, motion * 0.3, 0, 1) + analyticCoverage(px, py, -2000, 0, 20, 30, motion, 0, 0, 1));
      }
    std::printf("motion %g px: %.0f samples covered (ray caster %.0f, exact %.1f) in %d pixels; %.0f samples, %d pixels disagree\n", motion, covered,
                refCovered, analytic, coveredPixels, disagreeing, disagreeingPixels);
    // Both quads are seen (they never overlap in time): ~3600 samples at 1e-6 px, ~130 at 5000 px,
    // within four standard deviations of a Poisson count of the exact coverage.
    EXPECT_GT(refCovered, motion > 1 ? 60.0 : 3000.0) << motion;
    EXPECT_NEAR(covered, analytic, 4 * std::sqrt(analytic)) << motion;
    // At most 2 % of the covered samples and pixels disagree (none do today).
    EXPECT_LE(disagreeing, 0.02 * refCovered) << motion;
    EXPECT_LE(disagreeingPixels, 0.02 * coveredPixels) << motion;
  }
}

// Strong depth motion under perspective: a corner's screen position is not linear in time (it lags
// or leads by up to |dx| |dz| / 4 z_min), so bounds lerped between the interval's ends must be
// widened by that much. Here the lag reaches ~100 px; a bound without it drops whole regions.
// Every pixel must agree with the ray caster to within one sample of its 16.
TEST(ResampleHard, StrongDepthMotionUnderPerspective) {
  ScratchDir dir;
  TestScene s = makeScene(48, 32);
  // Rushing at the camera while sliding across the frame, and receding the other way.
  s.mps.push_back(cameraQuad(
      {{s.cam(2, 4, 20), s.cam(14, 4, 20), s.cam(14, 16, 20), s.cam(2, 16, 20)}, {s.cam(20, 6, 1), s.cam(46, 6, 1), s.cam(46, 30, 1), s.cam(20, 30, 1)}}));
  s.mps.push_back(cameraQuad({{s.cam(40, 2, 1.2), s.cam(47, 2, 1.2), s.cam(47, 12, 1.5), s.cam(40, 12, 1.5)},
                              {s.cam(5, 20, 25), s.cam(9, 20, 25), s.cam(9, 28, 25), s.cam(5, 28, 25)}},
                             {0.1f, 0.3f, 0.9f}));
  auto reader = writeScene(s, dir.path("depth.mps"));
  for (auto [a, b] : {std::pair{0.0, 1.0}, std::pair{0.2, 0.45}}) {
    RenderSpec spec = specFor(reader, a, b, 4, 4, 3);
    RenderResult r = render(spec);
    expectFinite(r);
    Reference ref = rayCast(s, spec, 48, 32);
    const auto& A = channel(r, "A").f;
    double worst = 0, covered = 0;
    for (size_t p = 0; p < ref.a.size(); ++p) worst = std::max(worst, std::abs(A[p] - ref.a[p])), covered += ref.a[p];
    EXPECT_GT(covered, 50.0) << "the scene must cover a good part of the frame";
    EXPECT_LE(worst, 1.0 / 16 + 1e-4) << a << ":" << b;
  }
}

TEST(ResampleHard, KnotsATenMillionthOfAFrameApart) {
  ScratchDir dir;
  TestScene s = makeScene(32, 24, {0.5, 0.5 + 1e-7});
  // The square jumps 9 px in 1e-7 frames: samples before the jump see it left, after it right.
  s.mps.push_back(cameraQuad({s.rect(4, 4, 14, 18, 10), s.rect(13, 4, 23, 18, 10)}));
  for (auto [a, b] : {std::pair{0.0, 1.0}, std::pair{0.5, 0.5 + 1e-7}, std::pair{0.5, 0.5}})
    EXPECT_LT(compareWithRayCaster(s, dir.path("knots.mps"), a, b), 3e-3) << a << ":" << b;
}

TEST(ResampleHard, ExactDepthTiesResolveDeterministically) {
  ScratchDir dir;
  TestScene s = makeScene(32, 24, {0.0});
  TestMp red = cameraQuad({s.rect(0, 0, 32, 24, 10)}, {1, 0, 0}), blue = cameraQuad({s.rect(0, 0, 32, 24, 10)}, {0, 0, 1});
  s.mps = {red, blue};
  auto reader = writeScene(s, dir.path("ties.mps"));
  resample::PixelVector<float> first;
  for (auto [threads, bucket] : {std::pair{1, 32}, std::pair{2, 8}, std::pair{2, 13}}) {
    tbb::global_control limit(tbb::global_control::max_allowed_parallelism, size_t(threads));
    RenderSpec spec = specFor(reader, 0, 0, 4, 4);
    spec.bucketSize = bucket;
    RenderResult r = render(spec);
    expectFinite(r);
    const auto& R = channel(r, "R").f;
    const auto& B = channel(r, "B").f;
    // Every sample takes one surface whole: the earlier in store order (equal nearest depths).
    for (size_t p = 0; p < R.size(); ++p) {
      EXPECT_FLOAT_EQ(R[p], 1.f);
      EXPECT_EQ(B[p], 0.f);
    }
    if (first.empty()) first = R;
    EXPECT_EQ(R, first);
  }
}

// Filters whose weights nearly cancel at the image border (negative lobes reaching past it). At one
// sample per pixel each pixel is exactly Σ w·v / Σ w over the samples its support reaches - past
// the image edge too - or, where the weights cancel (|Σ w| < 1e-6), its own sample: the ray
// caster gives every sample's value, the filter's definition every weight, and the pixel must
// match to float rounding, scaled by how much the weights cancel (Σ |w| / |Σ w|).
TEST(ResampleHard, NegativeLobesAtTheBorderStayFinite) {
  ScratchDir dir;
  TestScene s = makeScene(5, 4, {0.0, 1.0});
  s.mps.push_back(cameraQuad({s.rect(1.5, 0.5, 3.5, 3.5, 10), s.rect(2.5, 0.5, 4.5, 3.5, 10)}));
  auto reader = writeScene(s, dir.path("small.mps"));
  const int M = 8;  // past every filter's radius here
  for (const char* f : {"sinc:8", "catmull-rom:6", "mitchell:5x2", "blackman-harris:7", "sinc:3x9"}) {
    RenderSpec spec = specFor(reader, 0, 1, 1, 1);
    spec.filter = FilterSpec::parse(f, "test");
    spec.cropX0 = 4, spec.cropX1 = 5, spec.cropY0 = 0, spec.cropY1 = 4;
    RenderResult r = render(spec);
    for (const auto& c : r.image.channels)
      for (float v : c.f) ASSERT_TRUE(std::isfinite(v)) << f << " " << c.name;
    const SampleReference ref = rayCastSamples(s, spec, 4, 4 - M, -M, 1 + 2 * M, 4 + 2 * M);
    const SamplePattern pattern(1, 1, spec.seed);
    int covered = 0;
    for (int py = 0; py < 4; ++py) {
      const int px = 4;
      double sum[4] = {0, 0, 0, 0}, w = 0, wAbs = 0;
      for (int qy = py - M; qy <= py + M; ++qy)
        for (int qx = px - M; qx <= px + M; ++qx) {
          const glm::vec2 o = pattern.offset(pattern.patternOf(qx, qy), 0);
          const double wq = double(filter1D(spec.filter.kind, float(qx - px) + o.x - 0.5f, spec.filter.width) *
                                   filter1D(spec.filter.kind, float(qy - py) + o.y - 0.5f, spec.filter.height));
          const size_t k = ref.at(qx, qy, 0);
          w += wq, wAbs += std::abs(wq);
          sum[0] += wq * ref.r[k], sum[1] += wq * ref.g[k], sum[2] += wq * ref.b[k], sum[3] += wq * ref.a[k];
          covered += wq != 0 && ref.a[k] > 0;
        }
      ASSERT_FALSE(std::abs(w) > 0.5e-6 && std::abs(w) < 2e-6) << f << " row " << py << ": too close to the renderer's cut-off to tell";
      const size_t own = ref.at(px, py, 0);
      const bool fallBack = std::abs(w) < 1e-6;
      const double want[4] = {fallBack ? ref.r[own] : sum[0] / w, fallBack ? ref.g[own] : sum[1] / w, fallBack ? ref.b[own] : sum[2] / w,
                              fallBack ? ref.a[own] : sum[3] / w};
      const double tolerance = fallBack ? 1e-6 : 1e-5 * wAbs / std::abs(w) + 1e-6;
      const char* names[4] = {"R", "G", "B", "A"};
      for (int c = 0; c < 4; ++c)
        EXPECT_NEAR(channel(r, names[c]).f[size_t(py)], want[c], tolerance) << f << " " << names[c] << " row " << py << ", Σw " << w << ", Σ|w| " << wAbs;
    }
    EXPECT_GT(covered, 0) << f << ": the quad must reach the column's filter support";
  }
}

// Cases the accuracy study found missing from issue 8's list for the flat re-sampler: alpha within
// 1e-7 of 0 and 1, 10 000 fragments in one pixel (the deep path has its own), and non-finite
// attribute values (positions are covered by StoreBadInputHard).
TEST(ResampleHard, AlphaWithinATenMillionthOfZeroAndOne) {
  ScratchDir dir;
  TestScene s = makeScene(24, 16);
  TestMp clear = cameraQuad({s.rect(2, 2, 14, 12, 8), s.rect(4, 2, 16, 12, 8)}, glm::vec3(1e-7f));
  clear.oi = glm::vec3(1e-7f);
  TestMp opaque = cameraQuad({s.rect(8, 4, 22, 14, 12), s.rect(6, 4, 20, 14, 12)}, glm::vec3(1 - 1e-7f));
  opaque.oi = glm::vec3(1 - 1e-7f);
  s.mps = {clear, opaque};
  EXPECT_LT(compareWithRayCaster(s, dir.path("alpha.mps"), 0, 1), 3e-3);
  RenderResult r = render(specFor(writeScene(s, dir.path("alpha2.mps")), 0, 1, 4, 4));
  expectFinite(r);
  const auto& A = channel(r, "A").f;
  EXPECT_GT(A[5 * 24 + 5], 0.f);  // only the nearly clear surface: 1e-7, not 0
  EXPECT_NEAR(A[5 * 24 + 5], 1e-7, 1e-9);
  EXPECT_NEAR(A[8 * 24 + 10], 1 - 1e-7, 2e-7);  // 1e-7 + (1 - 1e-7)²: never above 1
  EXPECT_LE(A[8 * 24 + 10], 1.f);
}

TEST(ResampleHard, TenThousandFragmentsInOnePixelFlat) {
  ScratchDir dir;
  TestScene s = makeScene(4, 4, {0.0});
  for (int i = 0; i < 10000; ++i) {  // each 1e-4 opaque: 1 - e^-1 in all, the threshold never stops it
    TestMp mp = cameraQuad({s.rect(0.5, 0.5, 3.5, 3.5, 5 + i * 1e-3)}, glm::vec3(0.5e-4f));
    mp.oi = glm::vec3(1e-4f);
    s.mps.push_back(mp);
  }
  EXPECT_LT(compareWithRayCaster(s, dir.path("layers.mps"), 0, 1), 1e-4);
  RenderResult r = render(specFor(writeScene(s, dir.path("layers2.mps")), 0, 1, 2, 2));
  expectFinite(r);
  const double exact = 1 - std::pow(1 - 1e-4, 10000);
  for (int p : {5, 6, 9, 10}) {
    EXPECT_NEAR(channel(r, "A").f[size_t(p)], exact, 1e-4) << p;
    EXPECT_NEAR(channel(r, "R").f[size_t(p)], 0.5 * exact, 1e-4) << p;
  }
}

TEST(ResampleHard, NonFiniteAttributesAreRejectedNamingGridAndAttribute) {
  ScratchDir dir;
  for (float bad : {NAN, INFINITY, -INFINITY})
    for (bool opacity : {false, true}) {
      TestScene s = makeScene(8, 8);
      TestMp mp = cameraQuad({s.rect(1, 1, 5, 5, 5), s.rect(2, 1, 6, 5, 5)});
      (opacity ? mp.oi : mp.ci).y = bad;
      mp.gridId = 23;
      s.mps.push_back(mp);
      const std::string path = dir.path("bad.mps");
      try {
        writeScene(s, path);
        ADD_FAILURE() << "non-finite " << (opacity ? "Oi" : "Ci") << " accepted";
      } catch (const std::exception& e) {
        const std::string what = e.what();
        EXPECT_NE(what.find(opacity ? "'Oi'" : "'Ci'"), std::string::npos) << what;
        EXPECT_NE(what.find("not finite"), std::string::npos) << what;
        EXPECT_NE(what.find("23"), std::string::npos) << what;
      }
      EXPECT_FALSE(std::filesystem::exists(path));
    }
}

// The kernel sets this CPU runs, widest first: AVX-512 (where present), AVX2, the scalar loops.
struct KernelSet {
  const char* name;
  bool vector, avx512;
};
std::vector<KernelSet> kernelSets() {
  std::vector<KernelSet> sets;
  if (kernels::available(kernels::Isa::Avx512)) sets.push_back({"avx512", true, true});
  sets.push_back({"avx2", true, false});
  sets.push_back({"scalar", false, false});
  return sets;
}

// The vector kernels (resample/simd.h: AVX2, and AVX-512 where the CPU has it) and the
// scalar loops are implementations of one computation: every channel must come out identical,
// for moving (two and three knots), static, transparent and interlaced renders, whatever the
// bucket size.
TEST(ResampleHard, VectorAndScalarKernelsAgree) {
  if (!kernels::available()) GTEST_SKIP() << "this CPU has no AVX2: only the scalar loops run";
  if (!kernels::available(kernels::Isa::Avx512)) std::cout << "note: this CPU has no AVX-512; comparing AVX2 with the scalar loops only\n";
  ScratchDir dir;
  for (const SyntheticCase& c : kSyntheticCases) {
    auto reader = syntheticStore(dir, c, 40000, 7);
    for (int shutter = 0; shutter < 3; ++shutter) {
      RenderSpec spec = comparisonSpec(reader, shutter);
      std::vector<RenderResult> results;
      for (const KernelSet& k : kernelSets())
        for (int bucket : {16, 96}) {
          spec.raster.vectorKernels = k.vector;
          spec.raster.avx512Kernels = k.avx512;
          spec.bucketSize = bucket;
          results.push_back(render(spec));
        }
      double coverage = 0;
      for (float a : channel(results[0], "A").f) coverage += a;
      EXPECT_GT(coverage, 0.5 * 160 * 120) << c.name << ": the scene must cover most of the frame";
      EXPECT_GT(results[0].stats.raster.hits, 100000u) << c.name;
      for (size_t i = 1; i < results.size(); ++i)
        for (const char* ch : {"R", "G", "B", "A", "Z"})
          EXPECT_EQ(channel(results[i], ch).f, channel(results[0], ch).f) << c.name << " shutter " << shutter << " run " << i << " " << ch;
    }
  }
}

// The same agreement through an orthographic camera, whose homogeneous corners are (x, y, 1)
// with no depth in the edge functions: random quads and triangles, some tilted in depth, moving
// (over the whole shutter and a sub-interval) and static.
TEST(ResampleHard, VectorAndScalarKernelsAgreeOrthographic) {
  if (!kernels::available()) GTEST_SKIP() << "this CPU has no AVX2: only the scalar loops run";
  ScratchDir dir;
  for (bool moving : {true, false}) {
    TestScene s = moving ? makeScene(48, 32) : makeScene(48, 32, {0.0});
    s.meta.cameras[0].projection = store::Projection::Orthographic;
    reshutter::Rng rng(17);
    for (int i = 0; i < 400; ++i) {
      const double x = rng.uniform(-4, 52), y = rng.uniform(-4, 36), size = rng.uniform(0.3, 3), z = rng.uniform(2, 20);
      const double mx = rng.uniform(-8, 8), my = rng.uniform(-8, 8), tilt = rng.uniform(-1, 1);
      TestMp mp;
      for (double u : moving ? std::vector<double>{0.0, 1.0} : std::vector<double>{0.0}) {
        const double ox = x + u * mx, oy = y + u * my;
        mp.knots.push_back(
            {s.cam(ox, oy, z), s.cam(ox + size, oy + 0.2 * size, z + tilt), s.cam(ox + size, oy + size, z), s.cam(ox - 0.1 * size, oy + size, z - tilt)});
      }
      mp.triangle = i % 3 == 0;
      mp.ci = {float(rng.uniform()), float(rng.uniform()), float(rng.uniform())};
      s.mps.push_back(mp);
    }
    auto reader = writeScene(s, dir.path(moving ? "ortho-moving.mps" : "ortho-static.mps"));
    // 3×3: an odd number of sample planes, so that the static gather's plane pairs leave one over.
    for (auto [open, close, grid] : {std::tuple{0.0, 1.0, 4}, std::tuple{0.3, 0.45, 4}, std::tuple{0.0, 1.0, 3}}) {
      RenderSpec spec = specFor(reader, open, close, grid, grid, 3);
      std::vector<RenderResult> results;
      for (const KernelSet& k : kernelSets()) {
        spec.raster.vectorKernels = k.vector;
        spec.raster.avx512Kernels = k.avx512;
        results.push_back(render(spec));
      }
      const std::string what =
          std::string(moving ? "moving " : "static ") + std::to_string(open) + ":" + std::to_string(close) + " " + std::to_string(grid * grid) + " spp";
      EXPECT_GT(results[0].stats.raster.hits, size_t(300 * grid * grid)) << what;
      if (!moving) {
        EXPECT_GT(results[0].stats.raster.staticMicropolygons, 100u) << what;
      }
      for (size_t i = 1; i < results.size(); ++i)
        for (const char* ch : {"R", "G", "B", "A", "Z"})
          EXPECT_EQ(channel(results[i], ch).f, channel(results[0], ch).f) << what << " " << kernelSets()[i].name << " " << ch;
    }
  }
}

// Chunk gathers (one gather for micropolygons that move together, sorted into cells of
// compensated position) must find every sample each micropolygon's own gather finds, and more
// only where its own early depth test would have dropped them (samples covered since the run's
// gather by the run's earlier micropolygons, which the chunk filter leaves to the depth compare
// of the hit): a few more sample tests and hidden hits, never fewer, and every channel and deep
// sample the same - for motion from none to fast (one knot segment: the linear path), a
// sub-interval, interlaced fields, a rolling read-out, with both instruction sets; and most
// micropolygons must take the chunk gathers.
// Which samples a micropolygon's own gather finds does not depend on the instruction set (the
// kernels agree to the bit and in their counts), so each store and shutter renders that
// reference once, with the widest set, and the chunk gathers of every set are held to it.
TEST(ResampleHard, ChunkGathersFindEveryMicropolygonsSamples) {
  if (!kernels::available()) GTEST_SKIP() << "chunk gathers run with the vector kernels only";
  ScratchDir dir;
  for (double motion : {0.5, 8.0, 40.0}) {
    const SyntheticCase c{"chunks", 2, motion, 0.2};
    auto reader = syntheticStore(dir, c, 25000, 9);
    for (int shutter = 0; shutter < 4; ++shutter) {
      // Shutters 0-2 as comparisonSpec(); 3: a rolling read-out over the sub-interval.
      RenderSpec spec = comparisonSpec(reader, shutter == 3 ? 1 : shutter);
      if (shutter == 3) spec.shutter.setRolling(RollingShutter{0.2, false, 120});
      spec.aovs = {AovRequest::parse("id", "test")};
      spec.deep = true;
      std::optional<RenderResult> alone;  // each micropolygon gathered on its own: the reference
      for (const KernelSet& k : kernelSets()) {
        if (!k.vector) continue;
        spec.raster.avx512Kernels = k.avx512;
        if (!alone) {
          spec.raster.chunkGathers = false;
          alone = render(spec);
          EXPECT_EQ(alone->stats.raster.chunkGatheredMicropolygons, 0u) << k.name;
        }
        spec.raster.chunkGathers = true;
        const RenderResult chunked = render(spec);
        const std::string what = std::string(k.name) + " motion " + std::to_string(motion) + " shutter " + std::to_string(shutter);
        EXPECT_GT(chunked.stats.raster.chunkGatheredMicropolygons, chunked.stats.raster.linearMicropolygons / 2) << what;
        const RasterStats &cs = chunked.stats.raster, &as = alone->stats.raster;
        EXPECT_GE(cs.sampleTests, as.sampleTests) << what;
        EXPECT_GE(cs.hits, as.hits) << what;
        EXPECT_LE(cs.hits - as.hits, cs.sampleTests - as.sampleTests) << what;  // each extra hit is an extra test
        EXPECT_LE(cs.sampleTests - as.sampleTests, as.sampleTests / 200) << what;
        expectSameOutputs(chunked, *alone, what);
      }
    }
  }
}

// A render where nothing reads a sample's time - motion-free stores, no volume - or where every
// sample's time is the same (an instant) skips drawing the times: every output (colour, depth,
// ids, deep samples) must be what drawn times give, for progressive, sub-interval, fields and
// instant shutters, a rolling read-out and a lens, with both instruction sets and the scalar
// loops. A moving store, or a store covering only part of the shutter, draws them.
// Drawing every time is the reference (off only to measure what skipping saves), and the kernel
// sets agree to the bit: each case renders it once, with the widest set, and holds the skipped
// render of every set to it.
TEST(ResampleHard, UntimedSamplesGiveTheImageOfDrawnTimes) {
  ScratchDir dir;
  const SyntheticCase still{"still", 1, 0, 0.4};
  auto reader = syntheticStore(dir, still, 8000, 4);
  for (int shutter = 0; shutter < 6; ++shutter) {
    // Shutters 0-3 as comparisonSpec(); 4: a rolling read-out over the sub-interval; 5: through
    // a lens.
    RenderSpec spec = comparisonSpec(reader, shutter == 4 ? 1 : shutter == 5 ? 0 : shutter);
    if (shutter == 4) spec.shutter.setRolling(RollingShutter{0.3, false, 120});
    if (shutter == 5) spec.lens.fstop = 1, spec.lens.focalLength = 1, spec.lens.focalDistance = 20;
    spec.aovs = {AovRequest::parse("id", "test"), AovRequest::parse("z", "test")};
    spec.deep = true;
    std::optional<RenderResult> drawn;
    for (const KernelSet& k : kernelSets()) {
      spec.raster.vectorKernels = k.vector, spec.raster.avx512Kernels = k.avx512;
      const std::string what = std::string(k.name) + " shutter " + std::to_string(shutter);
      if (!drawn) {
        spec.raster.skipUnreadTimes = false;
        drawn = render(spec);
        spec.raster.skipUnreadTimes = true;
        EXPECT_EQ(drawn->stats.raster.midIntervalSamples, 0u) << what;
        EXPECT_EQ(drawn->stats.raster.pixelMajorSamples, 0u) << what;
        ASSERT_GT(drawn->stats.raster.hits, 0u) << what;
      }
      const RenderResult skipped = render(spec);
      EXPECT_GE(skipped.stats.raster.midIntervalSamples, skipped.stats.samples) << what;  // every sample, margins included
      if (shutter == 5) {
        EXPECT_GT(skipped.stats.raster.lensMicropolygons, 0u) << what;
        EXPECT_EQ(skipped.stats.raster.pixelMajorSamples, 0u) << what;  // lens planes
      } else {
        // Without a lens the skipped render's samples are pixel-major: the layout the drawn
        // render's stratum planes are held to.
        EXPECT_EQ(skipped.stats.raster.pixelMajorSamples, skipped.stats.raster.midIntervalSamples) << what;
      }
      // The bucket size chosen for each layout (the spec leaves it to the render); through a lens
      // by the circle of confusion (lensBucketSize()), larger with sample times.
      EXPECT_EQ(spec.bucketSize, kAutoBucketSize);
      if (shutter == 5) {
        EXPECT_TRUE(skipped.stats.bucketSize >= 48 && skipped.stats.bucketSize < drawn->stats.bucketSize) << what;
        EXPECT_GE(drawn->stats.bucketSize, kBucketSize) << what;
      } else {
        EXPECT_EQ(skipped.stats.bucketSize, skipped.stats.raster.pixelMajorSamples ? kStillBucketSize : kBucketSize) << what;
        EXPECT_EQ(drawn->stats.bucketSize, kBucketSize) << what;
      }
      expectSameOutputs(skipped, *drawn, what);
    }
    // Colour alone (no output variable): the resolve's branch-free loop, which reads pixel-major
    // samples four at a time.
    RenderSpec plain = spec;
    plain.aovs.clear(), plain.deep = false;
    plain.raster.skipUnreadTimes = false;
    const RenderResult plainDrawn = render(plain);
    plain.raster.skipUnreadTimes = true;
    const RenderResult plainSkipped = render(plain);
    if (shutter != 5) {
      EXPECT_GT(plainSkipped.stats.raster.pixelMajorSamples, 0u);
    }
    expectSameOutputs(plainSkipped, plainDrawn, "colour alone, shutter " + std::to_string(shutter));
  }
  // A moving store reads the times; but at an instant every sample's time is the same, drawn or
  // not, and so is the moving image.
  auto moving = syntheticStore(dir, SyntheticCase{"moving", 3, 8, 0.2}, 4000, 5);
  EXPECT_EQ(render(comparisonSpec(moving, 0)).stats.raster.midIntervalSamples, 0u);
  // Two instants as interlaced fields too: each field's rows drawn at its own instant.
  for (int fields = 0; fields < 2; ++fields) {
    RenderSpec instant = comparisonSpec(moving, 3);
    if (fields) instant.shutter = ShutterModel::fields({1.6, 1.6}, {1.7, 1.7}, 0);
    instant.deep = true;
    std::optional<RenderResult> drawn;
    for (const KernelSet& k : kernelSets()) {
      const std::string what = std::string(fields ? "moving at two field instants, " : "moving at an instant, ") + k.name;
      instant.raster.vectorKernels = k.vector, instant.raster.avx512Kernels = k.avx512;
      if (!drawn) {
        instant.raster.skipUnreadTimes = false;
        drawn = render(instant);
        instant.raster.skipUnreadTimes = true;
        EXPECT_EQ(drawn->stats.raster.midIntervalSamples, 0u) << what;
      }
      const RenderResult skipped = render(instant);
      EXPECT_GT(skipped.stats.raster.midIntervalSamples, 0u) << what;
      EXPECT_EQ(skipped.stats.raster.pixelMajorSamples, skipped.stats.raster.midIntervalSamples) << what;
      // One instant: some are culled; two: each field draws them at its own instant.
      if (fields) EXPECT_GT(skipped.stats.raster.staticMicropolygons, skipped.stats.raster.micropolygons) << what;
      else EXPECT_LT(skipped.stats.raster.staticMicropolygons, skipped.stats.raster.micropolygons) << what;
      expectSameOutputs(skipped, *drawn, what);
    }
  }
  // So does a render where a store covers only part of the shutter.
  RenderSpec beyond = comparisonSpec(reader, 0);
  beyond.shutter = ShutterModel::progressive(1.5, 2.5);
  beyond.sources.push_back(Source{reader, 2});
  EXPECT_EQ(render(beyond).stats.raster.midIntervalSamples, 0u);
}

// Interlaced fields drawn in one pass - each moving micropolygon bounded, gathered and tested once
// for both fields, over the interval that spans them - against field by field: every output the
// same (colour, depth, ids, deep samples), with both instruction sets and the scalar loops, and
// most micropolygons drawn together. Three knots put a knot between the fields, and a quad
// through the eye plane needs the general path: those are drawn field by field.
// Field by field is the reference (off only to measure what drawing together saves), and the
// kernel sets agree to the bit: each store renders it once, with the widest set, and holds the
// render drawn together by every set to it.
TEST(ResampleHard, FieldsDrawnTogetherMatchFieldByField) {
  ScratchDir dir;
  for (const SyntheticCase& c : kSyntheticCases) {
    if (c.knots == 1) continue;  // nothing moves: the static path serves both fields already
    auto reader = syntheticStore(dir, c, 20000, 13);
    RenderSpec spec = comparisonSpec(reader, 2);
    spec.aovs = {AovRequest::parse("id", "test")};
    spec.deep = true;
    std::optional<RenderResult> apart;
    for (const KernelSet& k : kernelSets()) {
      spec.raster.vectorKernels = k.vector;
      spec.raster.avx512Kernels = k.avx512;
      if (!apart) {
        spec.raster.groupsTogether = false;
        apart = render(spec);
        spec.raster.groupsTogether = true;
      }
      const RenderResult together = render(spec);
      const std::string what = std::string(c.name) + " " + k.name;
      const RasterStats &t = together.stats.raster, &a = apart->stats.raster;
      EXPECT_EQ(a.groupsTogetherMicropolygons, 0u) << what;
      if (c.knots == 2) {
        EXPECT_GT(t.groupsTogetherMicropolygons, t.micropolygons / 2) << what;
        // Each micropolygon drawn once instead of once per field.
        EXPECT_LT(double(t.linearMicropolygons), 0.7 * double(a.linearMicropolygons)) << what;
        if (k.vector) {
          EXPECT_GT(t.chunkGatheredMicropolygons, t.linearMicropolygons / 2) << what;
        }
      } else {
        EXPECT_EQ(t.groupsTogetherMicropolygons, 0u) << what;
      }
      EXPECT_GT(a.hits, 100000u) << what;
      expectSameOutputs(together, *apart, what);
    }
  }
  // A quad flying through the eye plane beside one that does not: the chunks are drawn apart.
  TestScene s = makeScene(32, 24);
  s.mps.push_back(cameraQuad({{glm::dvec3(-3, -2, -4), glm::dvec3(3, -2, -3), glm::dvec3(3, 2, -2), glm::dvec3(-3, 2, -3)},
                              {glm::dvec3(-3, -2, 3), glm::dvec3(3, -2, 4), glm::dvec3(3, 2, 5), glm::dvec3(-3, 2, 4)}}));
  auto reader = writeScene(s, dir.path("eye.mps"));
  RenderSpec spec = specFor(reader, 0, 1, 4, 4);
  spec.shutter = ShutterModel::fields({1.0, 1.25}, {1.5, 1.75}, 0);
  const RenderResult together = render(spec);
  spec.raster.groupsTogether = false;
  const RenderResult apart = render(spec);
  EXPECT_EQ(together.stats.raster.groupsTogetherMicropolygons, 0u);
  EXPECT_GT(apart.stats.raster.hits, 100u);
  expectSameOutputs(together, apart, "eye plane");
}

// Occlusion culling (nearest chunks first, early depth test) must change no bit of any output -
// colour, depth, an output variable and the deep samples' surface ids - while skipping most
// hidden surfaces of a scene ~2.5 layers deep: moving (two and three knots), static, transparent,
// a sub-interval, interlaced fields and a zero-length shutter.
// 120×90 rather than the comparisons' 160×120: the same depth (grids are placed over the frame
// grown by a grid's 16 px, so 36 000 one-pixel micropolygons over 136×106 are the ~2.5 layers
// that 60 000 were over 176×136), still two buckets of the default 96 px, and ~0.6x the pixels.
TEST(ResampleHard, OcclusionCullingIsExact) {
  ScratchDir dir;
  for (const SyntheticCase& c : kSyntheticCases) {
    auto reader = syntheticStore(dir, c, 36000, 5, 120, 90);
    for (int shutter = 0; shutter < 4; ++shutter) {
      RenderSpec spec = comparisonSpec(reader, shutter);
      spec.aovs = {AovRequest::parse("z", "test"), AovRequest::parse("id", "test")};
      spec.deep = true;
      const auto [culled, all] = renderCulledAndNot(spec);
      const std::string what = std::string(c.name) + " shutter " + std::to_string(shutter);
      expectSameOutputs(culled, all, what);
      // Hidden surfaces were skipped, not drawn and then lost.
      EXPECT_GT(all.stats.raster.hits, 100000u) << what;
      EXPECT_LT(double(culled.stats.raster.hits), 0.8 * double(all.stats.raster.hits)) << what;
    }
  }
}

// Layers written farthest first (the worst order for a depth buffer), overlapping in depth,
// moving across each other, one flying through the eye plane: the culled render must still agree
// with the ray caster, which knows nothing of draw order. With knots 1e-7 frames apart a sample's
// rounded time can land anywhere in the jump, which the early depth test must allow for.
TEST(ResampleHard, OcclusionKeepsNearerSurfacesDrawnLast) {
  ScratchDir dir;
  for (std::vector<double> knots : {std::vector<double>{0.0, 1.0}, std::vector<double>{0.5, 0.5 + 1e-7}}) {
    TestScene s = makeScene(40, 30, knots);
    for (int layer = 0; layer < 6; ++layer) {
      const double z = 30.0 - 4.0 * layer, x = 2.0 + 3.0 * layer;
      const glm::vec3 ci(0.15f * float(layer), 0.9f - 0.12f * float(layer), 0.5f);
      // Tilted in depth by more than the spacing, so neighbouring layers' depth ranges overlap.
      s.mps.push_back(cameraQuad({{s.cam(x, 3, z), s.cam(x + 16, 3, z + 5), s.cam(x + 16, 25, z + 5), s.cam(x, 25, z)},
                                  {s.cam(x + 9, 4, z - 3), s.cam(x + 25, 4, z + 2), s.cam(x + 25, 26, z + 2), s.cam(x + 9, 26, z - 3)}},
                                 ci));
    }
    s.mps.push_back(cameraQuad({{glm::dvec3(-3, -2, -4), glm::dvec3(3, -2, -3), glm::dvec3(3, 2, -2), glm::dvec3(-3, 2, -3)},
                                {glm::dvec3(-3, -2, 3), glm::dvec3(3, -2, 4), glm::dvec3(3, 2, 5), glm::dvec3(-3, 2, 4)}},
                               {0.1f, 0.1f, 0.9f}));
    for (auto [a, b] : {std::pair{0.0, 1.0}, std::pair{0.3, 0.55}, std::pair{0.5, 0.5 + 1e-7}, std::pair{0.5 + 3e-8, 0.5 + 6e-8}})
      EXPECT_LT(compareWithRayCaster(s, dir.path("layers.mps"), a, b), 3e-3) << knots[1] << " " << a << ":" << b;
  }
}

// At an exact instant a moving store is the still store of its positions at that time: each
// corner a + f (b - a) in float between the knots around the instant (f = (tau - t_k) / (t_k+1 -
// t_k), rounded to float), the first or last knot's position outside them. So the instant's render
// must be, bit for bit, the render of a still store written with those positions - at the knots,
// between them, before the first and after the last, with the vector kernels and the scalar
// loops. (The instant path finds the segment once per chunk and lerps its coordinates as one
// array.)
TEST(ResampleHard, AnInstantIsTheStillStoreOfItsPositions) {
  ScratchDir dir;
  TestScene moving = randomQuadScene(7, true);
  moving.knotTimes = {0.2, 0.5, 0.8};  // the same positions at knots inside the frame
  const auto movingReader = writeScene(moving, dir.path("moving.mps"));
  const std::vector<double>& knots = moving.knotTimes;
  for (double tau : {0.1, 0.2, 0.33, 0.5, 0.71, 0.8, 0.95}) {
    TestScene still = moving;
    still.knotTimes = {0.0};
    for (size_t i = 0; i < moving.mps.size(); ++i) {
      const TestMp& mp = moving.mps[i];
      TestMp& out = still.mps[i];
      out.knots.assign(1, {});
      for (int j = 0; j < 4; ++j) {
        glm::vec3 p;
        if (tau <= knots.front() || mp.knots.size() == 1) p = glm::vec3(mp.knots.front()[size_t(j)]);
        else if (tau >= knots.back()) p = glm::vec3(mp.knots.back()[size_t(j)]);
        else {
          size_t k = 0;
          while (k + 2 < knots.size() && knots[k + 1] <= tau) ++k;
          const float f = float((tau - knots[k]) / (knots[k + 1] - knots[k]));
          const glm::vec3 a(mp.knots[k][size_t(j)]), b(mp.knots[k + 1][size_t(j)]);
          for (int c = 0; c < 3; ++c) p[c] = a[c] + f * (b[c] - a[c]);
        }
        out.knots[0][size_t(j)] = glm::dvec3(p);
      }
    }
    const auto stillReader = writeScene(still, dir.path("still.mps"));
    for (const KernelSet& k : kernelSets()) {
      const std::string what = std::string(k.name) + " at " + std::to_string(tau);
      RenderSpec atInstant = specFor(movingReader, tau, tau, 4, 4, 5);
      RenderSpec ofStill = specFor(stillReader, tau, tau, 4, 4, 5);
      for (RenderSpec* spec : {&atInstant, &ofStill}) spec->raster.vectorKernels = k.vector, spec->raster.avx512Kernels = k.avx512;
      const RenderResult a = render(atInstant), b = render(ofStill);
      ASSERT_GT(a.stats.raster.hits, 0u) << what;
      EXPECT_GT(a.stats.raster.staticMicropolygons, 0u) << what;  // the instant took the static path
      expectSameOutputs(a, b, what);
    }
  }
}

