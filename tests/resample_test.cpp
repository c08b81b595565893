// Re-sampler: analytic coverage of moving squares, exact instants, watertight shared edges,
// compositing, mattes, filters, determinism across threads and buckets, and agreement with an
// independent brute-force ray caster (tests/resample_test_util.h).
#include <algorithm>
#include <cmath>
#include <filesystem>
#include <numeric>
#include <tuple>

#include <gtest/gtest.h>
#include <tbb/global_control.h>

#include "common/error.h"
#include "common/random.h"
#include "resample/coverage.h"
#include "resample/gather.h"
#include "tests/resample_test_util.h"
#include "tests/test_util.h"

using namespace reshutter;
using namespace reshutter::resample;
using namespace reshutter::test;

namespace {

struct MovingSquare {
  double x0 = 9.3, y0 = 7.6, w = 13.45, h = 9.8, vx = 17.7, vy = 6.35, z = 10;
};

TestScene movingSquareScene(const MovingSquare& sq, int W = 48, int H = 32) {
  TestScene s = makeScene(W, H);
  TestMp mp;
  mp.knots = {s.rect(sq.x0, sq.y0, sq.x0 + sq.w, sq.y0 + sq.h, sq.z), s.rect(sq.x0 + sq.vx, sq.y0 + sq.vy, sq.x0 + sq.w + sq.vx, sq.y0 + sq.h + sq.vy, sq.z)};
  mp.ci = {0.25f, 0.5f, 0.75f};
  s.mps.push_back(mp);
  return s;
}

struct ErrorStats {
  double rms = 0, mean = 0, max = 0;
};

ErrorStats alphaError(const RenderResult& r, const MovingSquare& sq, double a, double b) {
  const auto& A = channel(r, "A").f;
  ErrorStats e;
  const int W = r.image.width, H = r.image.height;
  for (int py = 0; py < H; ++py)
    for (int px = 0; px < W; ++px) {
      const double d = A[size_t(py) * W + px] - analyticCoverage(px, py, sq.x0, sq.y0, sq.w, sq.h, sq.vx, sq.vy, a, b);
      e.rms += d * d, e.mean += d, e.max = std::max(e.max, std::abs(d));
    }
  e.rms = std::sqrt(e.rms / (W * H)), e.mean /= W * H;
  return e;
}

/// A synthetic store (`reshutter generate ARGS`) written to path, opened.
std::shared_ptr<const store::StoreReader> generatedStore(const std::string& path, const std::string& args) {
  const CommandResult gen = runReshutter("generate " + args + " -o " + path);
  if (gen.exitCode != 0) ADD_FAILURE() << gen.err;
  return std::make_shared<const store::StoreReader>(path);
}

}  // namespace

TEST(ResampleAnalytic, MovingSquareCoverageConvergesWithoutBias) {
  ScratchDir dir;
  const MovingSquare sq;
  auto reader = writeScene(movingSquareScene(sq), dir.path("square.mps"));
  for (auto [a, b] : {std::pair{0.0, 1.0}, std::pair{0.25, 0.5}, std::pair{0.6, 0.95}}) {
    std::vector<double> rms;
    double bias = 0;
    for (int n : {2, 4, 8, 16}) {
      double sum = 0;
      const int seeds = 4;
      for (int seed = 0; seed < seeds; ++seed) {
        RenderResult r = render(specFor(reader, a, b, n, n, uint64_t(seed)));
        ErrorStats e = alphaError(r, sq, a, b);
        sum += e.rms * e.rms;
        if (n == 16) bias += e.mean / seeds;
        // No pixel is far off either: at 256 samples the worst pixel is off by 0.025-0.052
        // (measured); an edge displaced by a tenth of a pixel would put its pixels 0.1 off.
        if (n == 16) {
          EXPECT_LT(e.max, 0.1) << "interval " << a << ":" << b << " seed " << seed;
        }
      }
      rms.push_back(std::sqrt(sum / seeds));
    }
    // 4 → 256 samples per pixel: a Monte Carlo rate (N^-1/2) would give 1/8; stratification in
    // (x, y, t) must do at least that well.
    EXPECT_LT(rms.back(), rms.front() / 8) << "interval " << a << ":" << b << " rms 4 spp " << rms.front() << ", 256 spp " << rms.back();
    for (size_t i = 1; i < rms.size(); ++i) EXPECT_LT(rms[i], rms[i - 1]) << "error did not fall at step " << i;
    // No bias: the mean signed error over the image vanishes at high counts.
    EXPECT_LT(std::abs(bias), 2e-4) << "interval " << a << ":" << b;
    EXPECT_LT(rms.back(), 0.01);
  }
}

TEST(ResampleAnalytic, ColourFollowsCoverage) {
  ScratchDir dir;
  const MovingSquare sq;
  auto reader = writeScene(movingSquareScene(sq), dir.path("square.mps"));
  RenderResult r = render(specFor(reader, 0.1, 0.7, 8, 8));
  const auto &A = channel(r, "A").f, &R = channel(r, "R").f, &G = channel(r, "G").f, &B = channel(r, "B").f;
  for (size_t i = 0; i < A.size(); ++i) {
    EXPECT_FLOAT_EQ(R[i], 0.25f * A[i]);
    EXPECT_FLOAT_EQ(G[i], 0.5f * A[i]);
    EXPECT_FLOAT_EQ(B[i], 0.75f * A[i]);
  }
  // An empty image would meet that too: the square stays in the frame over [0.1, 0.7], so the
  // alphas sum to its area, up to the sampling error of its edges.
  const double alpha = std::accumulate(A.begin(), A.end(), 0.0);
  EXPECT_NEAR(alpha, sq.w * sq.h, 0.01 * sq.w * sq.h);
}

TEST(ResampleAnalytic, ZeroLengthIntervalIsTheExactInstant) {
  ScratchDir dir;
  const MovingSquare sq;
  TestScene scene = movingSquareScene(sq);
  auto reader = writeScene(scene, dir.path("square.mps"));
  for (double t : {0.0, 0.37, 1.0}) {
    RenderSpec spec = specFor(reader, t, t, 4, 4, 7);
    RenderResult r = render(spec);
    // Point sampling of the square at t: the sample positions alone decide, no time sampling.
    SamplePattern pattern(4, 4, 7);
    const auto& A = channel(r, "A").f;
    const double X0 = sq.x0 + sq.vx * t, Y0 = sq.y0 + sq.vy * t;
    int mismatches = 0;
    for (int py = 0; py < r.image.height; ++py)
      for (int px = 0; px < r.image.width; ++px) {
        int inside = 0;
        for (int i = 0; i < 16; ++i) {
          glm::vec2 o = pattern.offset(pattern.patternOf(px, py), i);
          const double x = px + double(o.x), y = py + double(o.y);
          inside += x > X0 && x < X0 + sq.w && y > Y0 && y < Y0 + sq.h;
        }
        if (std::abs(A[size_t(py) * r.image.width + px] - inside / 16.0) > 1e-6) ++mismatches;
      }
    EXPECT_EQ(mismatches, 0) << "t = " << t;
  }
}

TEST(ResampleWatertight, SharedEdgesNeitherDropNorDoubleCount) {
  // A jittered 24×16 grid of micropolygons sharing vertices (quads and triangles), moving, each
  // with opacity 0.5: a sample that fell through would show alpha 0, one counted twice 0.75.
  ScratchDir dir;
  TestScene scene = makeScene(40, 30);
  const int nu = 24, nv = 16;
  Rng rng(3);
  std::vector<glm::dvec2> v0((nu + 1) * (nv + 1)), v1(v0.size());
  std::vector<double> z0(v0.size()), z1(v0.size());
  for (int j = 0; j <= nv; ++j)
    for (int i = 0; i <= nu; ++i) {
      const bool border = i == 0 || j == 0 || i == nu || j == nv;
      const size_t k = size_t(j) * (nu + 1) + i;
      const double jx = border ? 0 : rng.uniform(-0.4, 0.4), jy = border ? 0 : rng.uniform(-0.4, 0.4);
      v0[k] = {2.0 + i * 1.4 + jx, 3.0 + j * 1.5 + jy};
      v1[k] = v0[k] + glm::dvec2(3.3, -1.7);
      z0[k] = 8 + 0.05 * i + rng.uniform(0, 0.2), z1[k] = z0[k] + 1.5;
    }
  auto at = [&](int i, int j, int knot) {
    const size_t k = size_t(j) * (nu + 1) + i;
    return knot == 0 ? scene.cam(v0[k].x, v0[k].y, z0[k]) : scene.cam(v1[k].x, v1[k].y, z1[k]);
  };
  for (int j = 0; j < nv; ++j)
    for (int i = 0; i < nu; ++i) {
      if ((i + j) % 5 == 0) {  // split this cell into two triangles along the other diagonal
        for (int half = 0; half < 2; ++half) {
          TestMp mp;
          mp.triangle = true;
          mp.oi = {0.5f, 0.5f, 0.5f}, mp.ci = {0.5f, 0.5f, 0.5f};
          mp.gridId = 1;
          for (int k = 0; k < 2; ++k)
            mp.knots.push_back(half == 0 ? std::array{at(i, j, k), at(i + 1, j, k), at(i, j + 1, k), glm::dvec3(0)}
                                         : std::array{at(i + 1, j, k), at(i + 1, j + 1, k), at(i, j + 1, k), glm::dvec3(0)});
          scene.mps.push_back(mp);
        }
        continue;
      }
      TestMp mp;
      mp.oi = {0.5f, 0.5f, 0.5f}, mp.ci = {0.5f, 0.5f, 0.5f};
      mp.gridId = 1;
      for (int k = 0; k < 2; ++k) mp.knots.push_back({at(i, j, k), at(i + 1, j, k), at(i + 1, j + 1, k), at(i, j + 1, k)});
      scene.mps.push_back(mp);
    }
  auto reader = writeScene(scene, dir.path("grid.mps"));
  for (auto [a, b] : {std::pair{0.0, 0.0}, std::pair{0.5, 0.5}, std::pair{0.0, 1.0}}) {
    RenderResult r = render(specFor(reader, a, b, 6, 6, 11));
    const auto& A = channel(r, "A").f;
    // Pixels well inside the grid's outline at every time of the interval.
    int checked = 0;
    for (int py = 6; py <= 25; ++py)
      for (int px = 7; px <= 34; ++px) {
        const double lo = 3.0 + 3.3 * b, hi = 2.0 + nu * 1.4 + 3.3 * a;
        const double ylo = 3.0 + 0 - 1.7 * a, yhi = 3.0 + nv * 1.5 - 1.7 * b;
        if (px < lo + 1 || px + 1 > hi - 1 || py < ylo + 1 || py + 1 > yhi - 1) continue;
        EXPECT_EQ(A[size_t(py) * 40 + px], 0.5f) << "pixel " << px << "," << py << " interval " << a << ":" << b;
        ++checked;
      }
    EXPECT_GT(checked, 100);
  }
}

TEST(ResampleCompositing, TransparentLayersOverAnOpaqueOne) {
  ScratchDir dir;
  TestScene s = makeScene(16, 16, {0.0});
  auto layer = [&](double z, glm::vec3 ci, glm::vec3 oi, uint8_t flags = 0) {
    TestMp mp;
    mp.knots = {s.rect(-4, -4, 20, 20, z)};
    mp.ci = ci, mp.oi = oi, mp.flags = flags;
    s.mps.push_back(mp);
  };
  // Store order deliberately not depth order.
  layer(20, {0.1f, 0.2f, 0.3f}, {1, 1, 1});
  layer(5, {0.2f, 0.1f, 0.05f}, {0.4f, 0.2f, 0.1f});
  layer(10, {0.3f, 0.3f, 0.0f}, {0.5f, 0.6f, 0.7f});
  auto reader = writeScene(s, dir.path("layers.mps"));
  RenderResult r = render(specFor(reader, 0, 0, 2, 2));
  const double o1[3] = {0.4, 0.2, 0.1}, c1[3] = {0.2, 0.1, 0.05}, o2[3] = {0.5, 0.6, 0.7}, c2[3] = {0.3, 0.3, 0.0}, c3[3] = {0.1, 0.2, 0.3};
  const char* names[3] = {"R", "G", "B"};
  double alpha = 0;
  for (int k = 0; k < 3; ++k) {
    const double expect = c1[k] + (1 - o1[k]) * (c2[k] + (1 - o2[k]) * c3[k]);
    EXPECT_NEAR(channel(r, names[k]).f[8 * 16 + 8], expect, 1e-6) << names[k];
    alpha += 1.0 / 3;
  }
  EXPECT_NEAR(channel(r, "A").f[8 * 16 + 8], alpha, 1e-6);
  // Z follows RenderMan's zthreshold: the nearest surface opaque beyond the threshold.
  EXPECT_NEAR(channel(r, "Z").f[8 * 16 + 8], 20.0, 1e-4);
  EXPECT_GT(r.stats.raster.fragments, 0u);
  EXPECT_EQ(r.stats.raster.generalHits, 0u);  // per-vertex colour and opacity: the direct path
}

// Transparent parts with per-vertex colour and opacity and no output variables take the direct
// hit path (HitBuffer::recordColourHit); an output variable sends every hit through the general
// attribute lookup. Both composite the same surfaces: R G B A Z are the same to the bit.
TEST(ResampleCompositing, DirectAndGeneralHitPathsAgree) {
  ScratchDir dir;
  auto reader = generatedStore(dir.path("gen.mps"), "-n 30000 --width 160 --height 120 --transparent 0.5 --motion 15");
  RenderSpec spec = specFor(reader, 0.1, 0.8, 3, 3, 5);
  const RenderResult direct = render(spec);
  spec.aovs = {AovRequest::parse("id", "t")};
  const RenderResult general = render(spec);
  EXPECT_GT(direct.stats.raster.fragments, 1000u);
  EXPECT_EQ(direct.stats.raster.generalHits, 0u);
  EXPECT_EQ(general.stats.raster.generalHits, general.stats.raster.hits);
  EXPECT_EQ(direct.stats.raster.fragments, general.stats.raster.fragments);
  for (const char* c : {"R", "G", "B", "A", "Z"}) {
    const auto &a = channel(direct, c).f, &b = channel(general, c).f;
    ASSERT_EQ(a.size(), b.size());
    EXPECT_EQ(std::memcmp(a.data(), b.data(), a.size() * sizeof(float)), 0) << c;
  }
}

namespace {

// A 32×16 static scene: an opaque background (0.9, 0.8, 0.7) at depth 30 and a matte over
// x 8..24, y 4..12 at depth 10.
TestScene matteOverBackground() {
  TestScene s = makeScene(32, 16, {0.0});
  TestMp bg;
  bg.knots = {s.rect(-2, -2, 34, 18, 30)};
  bg.ci = {0.9f, 0.8f, 0.7f};
  s.mps.push_back(bg);
  TestMp matte;
  matte.knots = {s.rect(8, 4, 24, 12, 10)};
  matte.flags = store::kMatte;
  s.mps.push_back(matte);
  return s;
}

}  // namespace

TEST(ResampleCompositing, MatteCutsOutAndHidesWhatIsBehind) {
  ScratchDir dir;
  TestScene s = matteOverBackground();
  TestMp glass;  // a semi-transparent surface in front of the matte still shows
  glass.knots = {s.rect(20, 0, 28, 16, 5)};
  glass.ci = {0.2f, 0.2f, 0.2f}, glass.oi = {0.5f, 0.5f, 0.5f};
  s.mps.push_back(glass);
  auto reader = writeScene(s, dir.path("matte.mps"));
  RenderResult r = render(specFor(reader, 0, 0, 3, 3));
  auto px = [&](const char* c, int x, int y) { return channel(r, c).f[size_t(y) * 32 + x]; };
  EXPECT_EQ(px("A", 12, 8), 0.f);
  EXPECT_EQ(px("R", 12, 8), 0.f);
  EXPECT_NEAR(px("R", 4, 8), 0.9, 1e-6);
  EXPECT_NEAR(px("A", 4, 8), 1.0, 1e-6);
  // Glass over matte: glass colour, glass alpha; glass over background: composite.
  EXPECT_NEAR(px("R", 22, 8), 0.2, 1e-6);
  EXPECT_NEAR(px("A", 22, 8), 0.5, 1e-6);
  EXPECT_NEAR(px("R", 26, 8), 0.2 + 0.5 * 0.9, 1e-6);
  EXPECT_NEAR(px("A", 26, 8), 1.0, 1e-6);
}

// Opaque surfaces only: the resolve takes its fast path without output variables and the
// general one with them; both cut the matte out and keep its depth.
TEST(ResampleCompositing, OpaqueMatteCutsOutWithAndWithoutOutputVariables) {
  ScratchDir dir;
  auto reader = writeScene(matteOverBackground(), dir.path("matte.mps"));
  for (bool withAov : {false, true}) {
    RenderSpec spec = specFor(reader, 0, 0, 3, 3);
    if (withAov) spec.aovs = {AovRequest::parse("id", "test")};
    RenderResult r = render(spec);
    auto px = [&](const char* c, int x, int y) { return channel(r, c).f[size_t(y) * 32 + x]; };
    for (const char* c : {"R", "G", "B", "A"}) EXPECT_EQ(px(c, 12, 8), 0.f) << c << (withAov ? " with id" : "");
    EXPECT_NEAR(px("Z", 12, 8), 10.0, 1e-4) << (withAov ? "with id" : "");
    EXPECT_NEAR(px("R", 4, 8), 0.9, 1e-6);
    EXPECT_NEAR(px("A", 4, 8), 1.0, 1e-6);
    EXPECT_NEAR(px("Z", 4, 8), 30.0, 1e-4);
  }
}

TEST(ResampleCompositing, BackfaceCullingKnocksOutUnlessTwoSided) {
  ScratchDir dir;
  TestScene s = makeScene(16, 16, {0.0});
  TestMp front, back;
  front.knots = {s.rect(0, 0, 8, 16, 10)};
  auto r = s.rect(8, 0, 16, 16, 10);
  back.knots = {{r[3], r[2], r[1], r[0]}};  // reversed winding
  s.mps = {front, back};
  auto reader = writeScene(s, dir.path("faces.mps"));
  RenderSpec spec = specFor(reader, 0, 0, 2, 2);
  RenderResult both = render(spec);
  spec.raster.backfaceCull = true;
  RenderResult culled = render(spec);
  const float aLeft = channel(culled, "A").f[8 * 16 + 3], aRight = channel(culled, "A").f[8 * 16 + 12];
  EXPECT_EQ(channel(both, "A").f[8 * 16 + 3], 1.f);
  EXPECT_EQ(channel(both, "A").f[8 * 16 + 12], 1.f);
  // Exactly one of the two windings faces the camera.
  EXPECT_EQ(aLeft + aRight, 1.f);
  s.mps[0].flags = s.mps[1].flags = store::kTwoSided;
  auto reader2 = writeScene(s, dir.path("faces2.mps"));
  RenderSpec spec2 = specFor(reader2, 0, 0, 2, 2);
  spec2.raster.backfaceCull = true;
  RenderResult twoSided = render(spec2);
  EXPECT_EQ(channel(twoSided, "A").f[8 * 16 + 3] + channel(twoSided, "A").f[8 * 16 + 12], 2.f);
}

TEST(ResampleReference, AgreesWithABruteForceRayCaster) {
  // Random moving quads and triangles, some transparent, some mattes, overlapping in depth.
  ScratchDir dir;
  const TestScene s = randomQuadScene(17, false);
  auto reader = writeScene(s, dir.path("random.mps"));
  for (auto [a, b] : {std::pair{0.0, 1.0}, std::pair{0.3, 0.55}, std::pair{0.8, 0.8}}) {
    RenderSpec spec = specFor(reader, a, b, 4, 4, 5);
    RenderResult r = render(spec);
    expectRayCasterAgrees(s, spec, r, 40, 28, cat("interval ", a, ":", b));
  }
}

TEST(ResampleDeterminism, BitIdenticalForAnyThreadCountAndBucketSize) {
  ScratchDir dir;
  auto reader = generatedStore(dir.path("gen.mps"), "-n 60000 --width 160 --height 120 --transparent 0.3 --motion 20 --knots 3");
  std::vector<std::vector<float>> images;
  for (auto [threads, bucket] : {std::pair{1, 32}, std::pair{2, 16}, std::pair{2, 57}, std::pair{1, 8}}) {
    tbb::global_control limit(tbb::global_control::max_allowed_parallelism, size_t(threads));
    RenderSpec spec = specFor(reader, 0.1, 0.9, 3, 3, 42);
    spec.filter = FilterSpec::parse("gaussian:2x2", "test");
    spec.bucketSize = bucket;
    spec.aovs = {AovRequest::parse("id", "t"), AovRequest::parse("z:zmin", "t")};
    RenderResult r = render(spec);
    std::vector<float> all;
    for (const auto& c : r.image.channels) {
      all.insert(all.end(), c.f.begin(), c.f.end());
      for (uint32_t u : c.u) all.push_back(float(u));
    }
    images.push_back(all);
  }
  for (size_t i = 1; i < images.size(); ++i) {
    ASSERT_EQ(images[i].size(), images[0].size());
    EXPECT_EQ(std::memcmp(images[i].data(), images[0].data(), images[0].size() * sizeof(float)), 0) << "variant " << i;
  }
}

// A decoded part stays in the store's cache only until the last bucket that needs it is done
// with it: each part is decoded once, and the cache's peak is the buckets' wavefront, not the
// whole decoded store (which a plain LRU cache with room for it would hold to the end).
TEST(ResampleMemory, EachPartDecodedOnceAndReleasedAfterItsLastBucket) {
  ScratchDir dir;
  const std::string path = dir.path("gen.mps");
  auto reader = generatedStore(path, "-n 60000 --width 640 --height 480 --motion 20");
  size_t decodedBytes = 0;
  for (size_t e = 0; e < reader->entries().size(); ++e) decodedBytes += reader->decode(e).memoryBytes();
  for (const char* shutter : {"box", "rolling"}) {
    SCOPED_TRACE(shutter);
    auto fresh = std::make_shared<const store::StoreReader>(path);  // its cache starts empty
    tbb::global_control limit(tbb::global_control::max_allowed_parallelism, 2);
    const bool rolling = std::string(shutter) == "rolling";
    RenderSpec spec = specFor(fresh, 0.0, rolling ? 0.5 : 1.0, 2, 2, 7);
    spec.bucketSize = 16;
    if (rolling) spec.shutter.setRolling({0.5, false, 1});  // rows read out over [0, 0.5] more
    const RenderResult r = render(spec);
    const store::CacheStats cs = fresh->cacheStats();
    EXPECT_GT(r.stats.partsFetched, 2 * r.stats.partsDecoded);  // parts are shared by buckets...
    EXPECT_LE(r.stats.partsDecoded, fresh->entries().size());   // ...and decoded once each
    EXPECT_EQ(cs.evictions, 0u);
    EXPECT_GT(cs.releases, r.stats.partsDecoded * 9 / 10);
    EXPECT_LT(cs.peakBytes, decodedBytes / 2) << "of " << decodedBytes;
  }
  // A store the caller renders from again (RenderSpec::keepDecoded) is left to its LRU cache:
  // nothing released, and the next render decodes nothing.
  auto kept = std::make_shared<const store::StoreReader>(path);
  RenderSpec spec = specFor(kept, 0.0, 1.0, 2, 2, 7);
  spec.bucketSize = 16;
  spec.keepDecoded = {kept.get()};
  const RenderResult first = render(spec);
  EXPECT_GT(first.stats.partsDecoded, 0u);
  EXPECT_EQ(kept->cacheStats().releases, 0u);
  const RenderResult again = render(spec);
  EXPECT_GT(again.stats.partsFetched, 0u);
  EXPECT_EQ(again.stats.partsDecoded, 0u);
}

// The motion path with (almost) no motion draws what the static path draws. Two equal knots would
// not do: the store writer stores such a grid static, and both renders would take the static
// path. So the moving scene's second knot moves one corner of each quad by one float ulp - a
// moving grid to the writer and the rasterizer (their "stands still" test is exact), nothing any
// sample can see - and the stats say which path each render took.
TEST(ResampleStatic, StaticPathMatchesMotionPathWithZeroMotion) {
  ScratchDir dir;
  TestScene moving = makeScene(32, 24, {0.0, 1.0}), still = makeScene(32, 24, {0.0});
  Rng rng(5);
  for (int i = 0; i < 12; ++i) {
    TestMp mp;
    auto q = moving.rect(rng.uniform(0, 24), rng.uniform(0, 16), rng.uniform(24, 32), rng.uniform(16, 24), rng.uniform(4, 20));
    for (auto& c : q) c = glm::dvec3(glm::vec3(c));  // the float positions the store keeps
    auto nudged = q;
    nudged[0].x = double(std::nextafter(float(q[0].x), INFINITY));  // one ulp
    mp.knots = {q, nudged};
    mp.ci = {float(rng.uniform()), 0.5f, 0.5f};
    if (i % 2) mp.oi = {0.5f, 0.5f, 0.5f};
    moving.mps.push_back(mp);
    mp.knots = {q};
    still.mps.push_back(mp);
  }
  auto rm = writeScene(moving, dir.path("moving.mps")), rs = writeScene(still, dir.path("still.mps"));
  for (const auto& e : rm->entries()) ASSERT_TRUE(e.effects & store::kEffectMoving) << "the writer stored a nudged grid static";
  RenderResult a = render(specFor(rm, 0, 1, 4, 4, 3)), b = render(specFor(rs, 0, 1, 4, 4, 3));
  // The first render took the motion path (one knot segment: the linear path), every micropolygon.
  EXPECT_GT(a.stats.raster.micropolygons, 0u);
  EXPECT_EQ(a.stats.raster.staticMicropolygons, 0u);
  EXPECT_GT(a.stats.raster.linearMicropolygons, 0u);
  // The second the static path, every micropolygon; both drew the same micropolygons.
  EXPECT_EQ(b.stats.raster.staticMicropolygons, b.stats.raster.micropolygons);
  EXPECT_EQ(b.stats.raster.linearMicropolygons, 0u);
  EXPECT_EQ(a.stats.raster.micropolygons, b.stats.raster.micropolygons);
  EXPECT_EQ(a.stats.raster.linearMicropolygons, b.stats.raster.staticMicropolygons);
  EXPECT_GT(a.stats.raster.hits, 12u * 16u);
  double covered = 0;
  for (float v : channel(b, "A").f) covered += v;
  EXPECT_GT(covered, 0.5 * 32 * 24) << "the quads must cover most of the frame";
  // Not bit for bit (the two paths round differently: ~2 % of values differ in the last bits), but
  // a sample one path covers and the other misses would move a value by 1/16 of a colour.
  for (const char* c : {"R", "G", "B", "A"})
    for (size_t p = 0; p < channel(a, c).f.size(); ++p) EXPECT_NEAR(channel(a, c).f[p], channel(b, c).f[p], 1e-6) << c << " " << p;
}

TEST(ResampleStatic, StillMicropolygonsAmongMovingOnesTakeTheStaticPath) {
  // A P + blurP dump gives static objects two equal knots, in the same tiles as moving ones. They
  // must be drawn on the static path (the store keeps them static), and the frame must still be
  // what a brute-force ray caster sees, over the whole shutter, a sub-interval and an instant.
  ScratchDir dir;
  TestScene s = makeScene(40, 28, {0.0, 1.0});
  Rng rng(23);
  const int still = 14;
  for (int i = 0; i < 2 * still; ++i) {
    TestMp mp;
    const double x = rng.uniform(0, 32), y = rng.uniform(0, 20), size = rng.uniform(2, 10), z = rng.uniform(3, 30);
    const auto q = s.rect(x, y, x + size, y + size * 0.7, z);
    const double vx = rng.uniform(-8, 8), vy = rng.uniform(-8, 8), dz = rng.uniform(-1, 1);
    mp.knots = {q, i < still ? q : s.rect(x + vx, y + vy, x + vx + size, y + vy + size * 0.7, z + dz)};
    mp.ci = {float(rng.uniform()), float(rng.uniform()), float(rng.uniform())};
    if (i % 4 == 3) mp.oi = {0.4f, 0.6f, 0.5f}, mp.ci *= 0.5f;
    mp.flags = store::kTwoSided;
    s.mps.push_back(mp);
  }
  auto reader = writeScene(s, dir.path("mixed.mps"));
  for (auto [a, b] : {std::pair{0.0, 1.0}, std::pair{0.3, 0.55}, std::pair{0.7, 0.7}}) {
    RenderSpec spec = specFor(reader, a, b, 4, 4, 9);
    RenderResult r = render(spec);
    if (a != b) {
      EXPECT_EQ(r.stats.raster.staticMicropolygons, uint64_t(still)) << "interval " << a << ":" << b;
    }
    expectRayCasterAgrees(s, spec, r, 40, 28, cat("interval ", a, ":", b));
  }
}

TEST(ResampleStatic, StillRowsOfAMovingGridTakeTheStaticPath) {
  // One grid whose first 64 micropolygons (one chunk) stand still and whose next 64 move, in one
  // tile: one moving part. The still chunk is drawn on the static path, and the frame is what the
  // ray caster sees.
  ScratchDir dir;
  TestScene s = makeScene(32, 24, {0.0, 1.0});
  s.meta.tileSize = 32;  // the whole image one tile
  Rng rng(29);
  for (int i = 0; i < 128; ++i) {
    TestMp mp;
    const double x = rng.uniform(0, 24), y = rng.uniform(0, 16), size = rng.uniform(1, 8), z = rng.uniform(3, 30);
    const auto q = s.rect(x, y, x + size, y + size * 0.8, z);
    const double vx = rng.uniform(-6, 6), vy = rng.uniform(-6, 6);
    mp.knots = {q, i < 64 ? q : s.rect(x + vx, y + vy, x + vx + size, y + vy + size * 0.8, z)};
    mp.ci = {float(rng.uniform()), float(rng.uniform()), float(rng.uniform())};
    mp.flags = store::kTwoSided;
    s.mps.push_back(mp);
  }
  auto reader = writeScene(s, dir.path("rows.mps"), true);
  ASSERT_EQ(reader->entries().size(), 1u);
  ASSERT_TRUE(reader->entries()[0].effects & store::kEffectMoving);
  for (auto [a, b] : {std::pair{0.0, 1.0}, std::pair{0.2, 0.45}}) {
    RenderSpec spec = specFor(reader, a, b, 4, 4, 3);
    RenderResult r = render(spec);
    EXPECT_EQ(r.stats.raster.staticMicropolygons, 64u) << "interval " << a << ":" << b;
    expectRayCasterAgrees(s, spec, r, 32, 24, cat("interval ", a, ":", b));
  }
}

TEST(ResampleFilters, ConstantImageStaysConstantForEveryFilter) {
  // A screen-filling opaque plane: every normalised filter must give exactly its colour, at the
  // borders too (samples exist beyond the image edge), with no NaN from negative lobes.
  ScratchDir dir;
  TestScene s = makeScene(24, 18, {0.0});
  TestMp mp;
  mp.knots = {s.rect(-40, -40, 64, 58, 10)};
  mp.ci = {0.3f, 0.6f, 0.9f};
  s.mps.push_back(mp);
  auto reader = writeScene(s, dir.path("plane.mps"));
  for (const char* f : {"box:1", "box:3", "triangle:2", "gaussian:2x3", "catmull-rom:4", "sinc:4", "sinc:6x2", "blackman-harris:3", "mitchell:4"}) {
    RenderSpec spec = specFor(reader, 0, 0, 3, 3);
    spec.filter = FilterSpec::parse(f, "test");
    RenderResult r = render(spec);
    for (size_t p = 0; p < channel(r, "R").f.size(); ++p) {
      ASSERT_NEAR(channel(r, "R").f[p], 0.3f, 1e-5) << f << " pixel " << p;
      ASSERT_NEAR(channel(r, "A").f[p], 1.0f, 1e-5) << f << " pixel " << p;
    }
  }
}

TEST(ResampleFilters, FilterShapesAreWhatTheyClaim) {
  for (FilterKind k : {FilterKind::Box, FilterKind::Triangle, FilterKind::Gaussian, FilterKind::CatmullRom, FilterKind::Sinc, FilterKind::BlackmanHarris,
                       FilterKind::Mitchell}) {
    const float w = defaultFilterWidth(k);
    EXPECT_GT(filter1D(k, 0.f, w), 0.f) << filterName(k);
    EXPECT_EQ(filter1D(k, w / 2 + 0.01f, w), 0.f) << filterName(k);
    for (float x = 0; x <= w / 2; x += 0.05f) EXPECT_FLOAT_EQ(filter1D(k, x, w), filter1D(k, -x, w)) << filterName(k);
  }
  EXPECT_LT(filter1D(FilterKind::CatmullRom, 1.5f, 4.f), 0.f);  // the negative lobe exists
  EXPECT_FLOAT_EQ(filter1D(FilterKind::Triangle, 0.5f, 2.f), 0.5f * filter1D(FilterKind::Triangle, 0.f, 2.f));
}

// The filter's dot products (whichever of the baseline and AVX2 builds runs, and whichever of
// its channel- and sample-count specialisations): each lane and the tail hold exactly the
// documented running sums, in neighbour order, and the total is the weighted sum of the samples.
TEST(ResampleFilters, TapSumsAreTheWeightedSamples) {
  Rng rng(11);
  for (auto [n, nc, taps] : {std::tuple{16, 4, 9}, std::tuple{16, 3, 25}, std::tuple{9, 4, 9}, std::tuple{4, 1, 49}, std::tuple{64, 4, 9}, std::tuple{17, 6, 9},
                             std::tuple{16, 8, 4}, std::tuple{24, 2, 1}}) {
    std::vector<std::vector<float>> values(static_cast<size_t>(nc), std::vector<float>(static_cast<size_t>(n * taps * 2)));
    for (auto& v : values)
      for (float& x : v) x = float(rng.uniform(0.0, 10.0));
    std::vector<std::vector<float>> weights(static_cast<size_t>(taps), std::vector<float>(static_cast<size_t>(n)));
    for (auto& wt : weights)
      for (float& x : wt) x = float(rng.uniform(-0.5, 1.0));
    std::vector<const float*> w, in;
    std::vector<size_t> offset;
    for (int j = 0; j < taps; ++j) w.push_back(weights[size_t(j)].data()), offset.push_back(size_t(2 * taps - 1 - 2 * j) * size_t(n));
    for (auto& v : values) in.push_back(v.data());
    float lanes[8][8] = {}, tail[8] = {};
    accumulateTaps(n, nc, in.data(), w.data(), offset.data(), taps, lanes, tail);
    const int vecN = n / 8 * 8;
    for (int c = 0; c < nc; ++c) {
      float want[8] = {}, wantTail = 0;
      double exact = 0;
      for (int j = 0; j < taps; ++j) {
        const float* v = in[size_t(c)] + offset[size_t(j)];
        for (int i = 0; i < vecN; ++i) want[i % 8] += w[size_t(j)][i] * v[i];
        for (int i = vecN; i < n; ++i) wantTail += w[size_t(j)][i] * v[i];
        for (int i = 0; i < n; ++i) exact += double(w[size_t(j)][i]) * double(v[i]);
      }
      for (int k = 0; k < 8; ++k) EXPECT_EQ(lanes[c][k], want[k]) << "n " << n << " nc " << nc << " channel " << c << " lane " << k;
      EXPECT_EQ(tail[c], wantTail) << "n " << n << " nc " << nc << " channel " << c;
      double total = wantTail;
      for (int k = 0; k < 8; ++k) total += lanes[c][k];
      EXPECT_NEAR(total, exact, 1e-5 * std::max(1.0, std::abs(exact))) << "n " << n << " nc " << nc;
    }
  }
}

TEST(ResampleAov, OutputVariablesAndSpecialFilters) {
  ScratchDir dir;
  TestScene s = makeScene(16, 16, {0.0});
  TestMp far, glass, wall;
  far.knots = {s.rect(0, 0, 16, 16, 20)};
  far.objectId = 7;
  glass.knots = {s.rect(0, 0, 8, 16, 10)};
  glass.objectId = 3;
  glass.oi = {0.5f, 0.5f, 0.5f}, glass.ci = {0.25f, 0.25f, 0.25f};
  wall.knots = {s.rect(8, 0, 12, 16, 10)};
  wall.objectId = 5;
  s.mps = {far, glass, wall};
  auto reader = writeScene(s, dir.path("aov.mps"));
  RenderSpec spec = specFor(reader, 0, 0, 2, 2);
  spec.aovs = {AovRequest::parse("id", "t"), AovRequest::parse("z", "t"), AovRequest::parse("N", "t")};
  RenderResult r = render(spec);
  const ImageChannel* id = r.image.find("id");
  ASSERT_TRUE(id && id->isUInt);
  // zmin takes the closest surface whose opacity reaches the threshold: the glass does not.
  EXPECT_EQ(id->u[8 * 16 + 3], 7u);
  EXPECT_EQ(id->u[8 * 16 + 10], 5u);
  EXPECT_EQ(id->u[8 * 16 + 14], 7u);
  // "z" under the pixel filter composites like colour: half glass (10), half wall behind (20).
  EXPECT_NEAR(channel(r, "z").f[8 * 16 + 3], 15.0, 1e-3);
  EXPECT_NEAR(channel(r, "z").f[8 * 16 + 10], 10.0, 1e-3);
  // Z, like RenderMan's zthreshold, skips surfaces less opaque than the threshold.
  EXPECT_NEAR(channel(r, "Z").f[8 * 16 + 3], 20.0, 1e-3);
  // N composites like colour: glass (opacity 0.5) over the far wall, both N = -z.
  EXPECT_NEAR(channel(r, "N.Z").f[8 * 16 + 3], -1.0, 1e-6);
  EXPECT_NEAR(channel(r, "N.Z").f[8 * 16 + 14], -1.0, 1e-6);
  // With a threshold below the glass's opacity, the glass becomes the closest surface.
  spec.raster.opacityThreshold = 0.4f;
  RenderResult r2 = render(spec);
  EXPECT_EQ(r2.image.find("id")->u[8 * 16 + 3], 3u);
  // Unknown variables are a clear error listing what the store has.
  spec.aovs = {AovRequest::parse("nonesuch", "--aov")};
  try {
    render(spec);
    FAIL() << "expected an error";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("nonesuch"), std::string::npos);
    EXPECT_NE(std::string(e.what()).find("Ci"), std::string::npos);
  }
}

TEST(ResampleErrors, IntervalOutsideTheStoreIsAClearError) {
  ScratchDir dir;
  auto reader = writeScene(movingSquareScene(MovingSquare{}), dir.path("square.mps"));
  try {
    render(specFor(reader, 0.5, 1.5, 2, 2));
    FAIL() << "expected an error";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("not covered"), std::string::npos) << e.what();
  }
}

TEST(ResampleReference, ManySmallMovingMicropolygonsLoseNoHits) {
  // Grids of ~1.5 px micropolygons sharing vertices, moving up to 30 px with motion in depth, as
  // the shading pass makes them: per-stratum bounds must never drop a hit the ray caster finds.
  ScratchDir dir;
  TestScene s = makeScene(40, 30);
  Rng rng(23);
  for (int gi = 0; gi < 14; ++gi) {
    const double ox = rng.uniform(-8, 36), oy = rng.uniform(-8, 26), z0 = rng.uniform(5, 50), dz = rng.uniform(-3, 3);
    const glm::dvec2 vel(rng.uniform(-30, 30), rng.uniform(-30, 30));
    glm::vec3 ci(float(rng.uniform()), float(rng.uniform()), float(rng.uniform()));
    for (int j = 0; j < 8; ++j)
      for (int i = 0; i < 8; ++i) {
        TestMp mp;
        mp.ci = ci;
        mp.gridId = uint32_t(gi + 1);
        for (int k = 0; k < 2; ++k) {
          const double x = ox + vel.x * k, y = oy + vel.y * k, z = z0 + dz * k;
          mp.knots.push_back(s.rect(x + i * 1.5, y + j * 1.5, x + (i + 1) * 1.5, y + (j + 1) * 1.5, z));
        }
        s.mps.push_back(mp);
      }
  }
  auto reader = writeScene(s, dir.path("grids.mps"));
  for (auto [a, b] : {std::pair{0.0, 1.0}, std::pair{0.2, 0.45}}) {
    RenderSpec spec = specFor(reader, a, b, 4, 4, 2);
    RenderResult r = render(spec);
    Reference ref = rayCast(s, spec, 40, 30);
    double diff = 0;
    for (size_t p = 0; p < ref.a.size(); ++p) diff += std::abs(channel(r, "A").f[p] - ref.a[p]);
    EXPECT_LT(diff, 3.0 / 16) << "interval " << a << ":" << b << ": more than 3 samples disagree";
    EXPECT_GT(r.stats.raster.hits, 1000u);  // (sized for the sanitizer build: the ray caster is brute force)
  }
}
