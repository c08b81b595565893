// Depth of field (resample/raster_lens.cpp): an out-of-focus edge blurs by exactly the thin-lens
// circle of confusion, a surface at the focal distance is the pinhole image, a stored frame
// re-focuses, a moving defocused square converges to its integral over time and lens, and every
// render agrees sample by sample with a ray caster whose rays leave the lens (tests/resample_test_util.h).
#include <algorithm>
#include <cmath>
#include <cstring>
#include <fstream>
#include <numeric>
#include <optional>

#include <gtest/gtest.h>
#include <tbb/global_control.h>

#include "common/error.h"
#include "common/random.h"
#include "store/reader.h"
#include "tests/resample_test_util.h"
#include "tests/test_util.h"

using namespace reshutter;
using namespace reshutter::resample;
using namespace reshutter::test;

namespace {

// `reshutter generate ARGS` written to path and opened (null, with a failure, if it did not run).
std::shared_ptr<const store::StoreReader> generatedStore(const std::string& args, const std::string& path) {
  const CommandResult gen = runReshutter("generate " + args + " -o " + path);
  EXPECT_EQ(gen.exitCode, 0) << gen.err;
  return gen.exitCode == 0 ? std::make_shared<const store::StoreReader>(path) : nullptr;
}

// A static opaque surface at depth z covering raster x >= edge (and far beyond the frame).
TestScene edgeScene(double edge, double z, int W = 64, int H = 24) {
  TestScene s = makeScene(W, H, {0.0});
  TestMp mp;
  mp.knots = {s.rect(edge, -60, W + 60, H + 60, z)};
  s.mps.push_back(mp);
  return s;
}

std::vector<double> columnMeans(const RenderResult& r) {
  const auto& A = channel(r, "A").f;
  const int W = r.image.width, H = r.image.height;
  std::vector<double> col(size_t(W), 0.0);
  for (int py = 0; py < H; ++py)
    for (int px = 0; px < W; ++px) col[size_t(px)] += A[size_t(py) * W + px] / H;
  return col;
}

// The largest alpha in column px, or the smallest (lowest).
float columnExtreme(const RenderResult& r, int px, bool lowest) {
  const auto& A = channel(r, "A").f;
  float e = A[size_t(px)];
  for (int py = 0; py < r.image.height; ++py) {
    const float v = A[size_t(py) * r.image.width + px];
    e = lowest ? std::min(e, v) : std::max(e, v);
  }
  return e;
}

}  // namespace

TEST(LensAnalytic, OutOfFocusEdgeBlursByTheCircleOfConfusion) {
  ScratchDir dir;
  const double edge = 30.3, z = 10, d = 5, r = 7.5;
  const TestScene s = edgeScene(edge, z);
  auto reader = writeScene(s, dir.path("edge.mps"));
  RenderSpec spec = specFor(reader, 0, 0, 8, 8, 3);
  spec.lens = lensFor(s, r, z, d);
  EXPECT_EQ(lensTimeBlocks(spec), 1);  // nothing moves: planes are lens strata
  RenderResult res = render(spec);
  EXPECT_GT(res.stats.raster.lensMicropolygons, 0u);
  EXPECT_EQ(res.stats.raster.staticMicropolygons, 0u);
  const std::vector<double> col = columnMeans(res);
  // The sample at x sees the surface where its lens point's displacement r·u (u the lens point's
  // x on the unit disk) is at most x - edge: the pixel's column is that disk fraction averaged
  // over the pixel.
  double sumErr = 0;
  for (int px = 0; px < int(col.size()); ++px) {
    double expected = 0;
    const int steps = 400;
    for (int k = 0; k < steps; ++k) expected += diskBelow((px + (k + 0.5) / steps - edge) / r) / steps;
    const double err = std::abs(col[size_t(px)] - expected);
    sumErr += err;
    EXPECT_LT(err, 0.03) << "column " << px << ": " << col[size_t(px)] << " against " << expected;
    // Nothing reaches past the circle of confusion, and inside it nothing is lost.
    if (px + 1 < edge - r - 1e-3) {
      EXPECT_EQ(columnExtreme(res, px, false), 0.f) << "column " << px;
    }
    if (px > edge + r + 1e-3) {
      EXPECT_EQ(columnExtreme(res, px, true), 1.f) << "column " << px;
    }
  }
  EXPECT_LT(sumErr / double(col.size()), 0.008);
  // The blur is as wide as the circle: columns a pixel inside it on both sides are partial.
  EXPECT_GT(col[size_t(edge - r + 1)], 0.0);
  EXPECT_LT(col[size_t(edge + r - 2)], 1.0);
}

TEST(LensAnalytic, InFocusSurfaceIsThePinholeImageAndAStoredFrameRefocuses) {
  ScratchDir dir;
  const double edge = 30.3, z = 10;
  TestScene s = edgeScene(edge, z);
  // The store's camera records a lens focused at 5 (RIB DepthOfField), so the edge is blurred.
  const RenderSpec::LensOverride recorded = lensFor(s, 6, z, 5);
  s.meta.cameras[0].lens = {*recorded.fstop, *recorded.focalLength, *recorded.focalDistance};
  auto reader = writeScene(s, dir.path("edge.mps"));
  ASSERT_TRUE(reader->meta().cameras[0].lens.active());
  EXPECT_EQ(reader->meta().cameras[0].lens, s.meta.cameras[0].lens);

  RenderSpec pinholeSpec = specFor(reader, 0, 0, 4, 4, 9);
  pinholeSpec.lens.pinhole = true;
  const RenderResult pinhole = render(pinholeSpec);
  EXPECT_EQ(pinhole.stats.raster.lensMicropolygons, 0u);
  EXPECT_GT(pinhole.stats.raster.staticMicropolygons, 0u);

  const RenderResult stored = render(specFor(reader, 0, 0, 4, 4, 9));
  EXPECT_GT(stored.stats.raster.lensMicropolygons, 0u);
  const std::vector<double> blurred = columnMeans(stored);
  EXPECT_GT(blurred[size_t(edge) - 3], 0.05);  // light three pixels before the edge: defocus
  EXPECT_LT(blurred[size_t(edge) + 3], 0.95);

  // Re-focused on the surface's depth: the pinhole image, sample for sample.
  RenderSpec refocus = specFor(reader, 0, 0, 4, 4, 9);
  refocus.lens.focalDistance = z;
  const RenderResult sharp = render(refocus);
  EXPECT_GT(sharp.stats.raster.lensMicropolygons, 0u);
  const auto &A = channel(sharp, "A").f, &P = channel(pinhole, "A").f;
  ASSERT_EQ(A.size(), P.size());
  for (size_t i = 0; i < A.size(); ++i) ASSERT_NEAR(A[i], P[i], 1e-6) << "pixel " << i;
  EXPECT_EQ(columnExtreme(sharp, int(edge) - 1, false), 0.f);
  EXPECT_EQ(columnExtreme(sharp, int(edge) + 1, true), 1.f);
}

TEST(LensReference, AgreesWithARayCasterWhoseRaysLeaveTheLens) {
  // Random moving quads and triangles, some transparent, some mattes, in front of and behind the
  // focal plane; rays from each sample's own lens point at its own time.
  ScratchDir dir;
  const TestScene s = randomQuadScene(23, true);
  auto reader = writeScene(s, dir.path("random.mps"));
  for (auto [a, b] : {std::pair{0.0, 1.0}, std::pair{0.3, 0.55}, std::pair{0.8, 0.8}}) {
    RenderSpec spec = specFor(reader, a, b, 4, 4, 5);
    spec.lens = lensFor(s, 4, 30, 8);  // 4 px at depth 30, more in front of the focal plane
    EXPECT_EQ(lensTimeBlocks(spec), a == b ? 1 : 4) << "interval " << a << ":" << b;  // an instant needs no time blocks
    RenderResult r = render(spec);
    EXPECT_GT(r.stats.raster.lensMicropolygons, 0u);
    // The quads' knot at 0.4 lies inside both intervals: their paths are drawn segment by segment.
    EXPECT_EQ(r.stats.raster.lensSegmentDraws > 0, a < 0.4 && b > 0.4) << "interval " << a << ":" << b;
    expectRayCasterAgrees(s, spec, r, 40, 28, cat("interval ", a, ":", b));
  }
}

TEST(LensSegments, ACurvedPathThroughTheLensTestsAboutWhatThePinholeTests) {
  // Small quads sweeping arcs of a circle over five knots: a box over a whole arc holds tens of
  // times the samples a quad can cover. Drawn one knot segment at a time, each sample is held to
  // its own segment's lerped box, so through a negligible lens (a tenth of a pixel) the exact
  // tests are about the pinhole path's (which bounds each time stratum), and each sample tests a
  // quad once: the ray caster agrees sample by sample, through that lens and through a wide one.
  ScratchDir dir;
  const int W = 48, H = 40;
  TestScene s = makeScene(W, H, {0.0, 0.25, 0.5, 0.75, 1.0});
  Rng rng(5);
  for (int i = 0; i < 16; ++i) {
    TestMp mp;
    const double cx = rng.uniform(8, W - 8), cy = rng.uniform(8, H - 8), radius = rng.uniform(6, 14), size = rng.uniform(1, 3), z = rng.uniform(5, 20);
    const double phase = rng.uniform(0, 2 * M_PI), sweep = rng.uniform(1.5, 3) * (i % 2 ? 1 : -1);
    for (int k = 0; k < 5; ++k) {
      const double angle = phase + sweep * k / 4.0, x = cx + radius * std::cos(angle), y = cy + radius * std::sin(angle);
      mp.knots.push_back(s.rect(x, y, x + size, y + size, z));
    }
    // Half of them transparent: a sample that tested a quad twice would composite it twice.
    const float opacity = i % 4 < 2 ? 1.f : 0.5f;
    mp.ci = glm::vec3(float(rng.uniform()), float(rng.uniform()), float(rng.uniform())) * opacity, mp.oi = glm::vec3(opacity);
    s.mps.push_back(mp);
  }
  auto reader = writeScene(s, dir.path("arcs.mps"));
  RenderSpec pinhole = specFor(reader, 0.05, 0.95, 4, 4, 3);
  const RenderResult p = render(pinhole);
  ASSERT_GT(p.stats.raster.hits, 0u);
  for (double r : {0.1, 4.0}) {
    RenderSpec spec = pinhole;
    spec.lens = lensFor(s, r, 20, 10);
    const RenderResult l = render(spec);
    const std::string what = cat("circle of confusion ", r, " px at depth 20");
    ASSERT_EQ(l.stats.raster.lensMicropolygons, uint64_t(s.mps.size())) << what;
    EXPECT_GE(l.stats.raster.lensSegmentDraws, 3 * s.mps.size()) << what;  // the region's times hold three knots or more
    if (r < 1) {
      EXPECT_LT(double(l.stats.raster.sampleTests), 1.25 * double(p.stats.raster.sampleTests))
          << what << ": " << l.stats.raster.sampleTests << " exact tests, the pinhole's " << p.stats.raster.sampleTests;
    }
    expectRayCasterAgrees(s, spec, l, W, H, what);
  }
}

TEST(LensAnalytic, MovingDefocusedSquareConvergesToItsIntegralOverTimeAndLens) {
  ScratchDir dir;
  const double x0 = 9.3, y0 = 7.6, w = 11.45, h = 8.8, vx = 12.7, vy = 5.35, z = 10, r = 4.5;
  TestScene s = makeScene(44, 32);
  TestMp mp;
  mp.knots = {s.rect(x0, y0, x0 + w, y0 + h, z), s.rect(x0 + vx, y0 + vy, x0 + w + vx, y0 + h + vy, z)};
  s.mps.push_back(mp);
  auto reader = writeScene(s, dir.path("square.mps"));
  const RenderSpec::LensOverride lens = lensFor(s, r, z, 4);
  const double a = 0.1, b = 0.85;
  // The integral: over the lens (polar midpoints, area-weighted), the exact time-averaged coverage
  // of the square displaced by r·u (analyticCoverage()).
  const int W = 44, H = 32, NR = 24, NT = 48;
  std::vector<double> expected(size_t(W) * H, 0.0);
  for (int py = 0; py < H; ++py)
    for (int px = 0; px < W; ++px) {
      if (px < x0 - r - 2 || px > x0 + w + vx + r + 2 || py < y0 - r - 2 || py > y0 + h + vy + r + 2) continue;
      double sum = 0;
      for (int ir = 0; ir < NR; ++ir)
        for (int it = 0; it < NT; ++it) {
          const double rho = std::sqrt((ir + 0.5) / NR), phi = 2 * M_PI * (it + 0.5) / NT;  // equal-area rings
          sum += analyticCoverage(px, py, x0 + r * rho * std::cos(phi), y0 + r * rho * std::sin(phi), w, h, vx, vy, a, b);
        }
      expected[size_t(py) * W + px] = sum / (NR * NT);
    }
  // The integral keeps the square's area: defocus and motion move coverage, they do not make or
  // lose it (the square stays in the frame).
  EXPECT_NEAR(std::accumulate(expected.begin(), expected.end(), 0.0), w * h, 1e-3 * w * h);
  std::vector<double> rms;
  double bias = 0;
  for (int n : {2, 4, 8, 16}) {
    double sum = 0;
    const int seeds = n == 16 ? 8 : 2;  // the bias check needs the mean of several images
    for (int seed = 0; seed < seeds; ++seed) {
      RenderSpec spec = specFor(reader, a, b, n, n, uint64_t(seed));
      spec.lens = lens;
      EXPECT_EQ(lensTimeBlocks(spec), n % 2 ? 1 : n * n / 4);  // a moving square: time blocks with even grids of 8+ samples
      const RenderResult res = render(spec);
      EXPECT_GT(res.stats.raster.lensMicropolygons, 0u);
      const auto& A = channel(res, "A").f;
      double e2 = 0, mean = 0;
      for (size_t p = 0; p < A.size(); ++p) {
        const double d = A[p] - expected[p];
        e2 += d * d, mean += d;
      }
      sum += e2 / double(A.size());
      if (n == 16) bias += mean / double(A.size()) / seeds;
    }
    rms.push_back(std::sqrt(sum / seeds));
  }
  for (size_t i = 1; i < rms.size(); ++i) EXPECT_LT(rms[i], rms[i - 1]) << "error did not fall at step " << i;
  // 4 → 256 samples per pixel in five dimensions (x, y, t, lens u, v): at least the Monte Carlo rate.
  EXPECT_LT(rms.back(), rms.front() / 8) << "rms 4 spp " << rms.front() << ", 256 spp " << rms.back();
  EXPECT_LT(rms.back(), 0.01);
  // No bias: the image's total alpha scatters by ~0.36 from seed to seed (2.6e-4 a pixel), so the
  // mean of eight is held to 4 standard errors.
  EXPECT_LT(std::abs(bias), 4e-4);
}

TEST(LensRib, DepthOfFieldIsRecordedAndTheCommandLineRefocuses) {
  ScratchDir dir;
  const std::string rib = dir.path("dof.rib");
  std::ofstream(rib) << "Format 64 48 1\nProjection \"perspective\" \"fov\" 40\nDepthOfField 2.8 0.5 4\nWorldBegin\n"
                        "Surface \"constant\"\nColor [1 1 1]\nTranslate 0 0 8\nPolygon \"P\" [-1 -1 0  1 -1 0  1 1 0  -1 1 0]\nWorldEnd\n";
  const std::string mps = dir.path("dof.mps");
  const CommandResult shade = runReshutter("shade " + rib + " -o " + mps);
  ASSERT_EQ(shade.exitCode, 0) << shade.err;
  const store::StoreReader reader(mps);
  const store::Lens& lens = reader.meta().cameras[0].lens;
  EXPECT_FLOAT_EQ(float(lens.fstop), 2.8f);  // RIB numbers are floats
  EXPECT_EQ(lens.focalLength, 0.5);
  EXPECT_EQ(lens.focalDistance, 4);
  // Written as format 4 (the lowest version that holds a lens); a store without one is not.
  EXPECT_EQ(readBytes(mps).at(8), 4);
  const CommandResult info = runReshutter("info " + mps);
  EXPECT_NE(info.out.find("lens f/2.8 focal length 0.5 focus 4"), std::string::npos) << info.out;

  const CommandResult blurred = runReshutter("resample " + mps + " -o " + dir.path("b.exr") + " --stats");
  ASSERT_EQ(blurred.exitCode, 0) << blurred.err;
  EXPECT_NE(blurred.out.find("through the lens"), std::string::npos) << blurred.out;
  const CommandResult pinhole = runReshutter("resample " + mps + " -o " + dir.path("p.exr") + " --pinhole --stats");
  ASSERT_EQ(pinhole.exitCode, 0) << pinhole.err;
  EXPECT_EQ(pinhole.out.find("through the lens"), std::string::npos) << pinhole.out;
  // Re-focused on the square (depth 8): the pinhole image, pixel for pixel (idiff: an independent reader).
  const CommandResult refocus = runReshutter("resample " + mps + " -o " + dir.path("r.exr") + " --focus-distance 8");
  ASSERT_EQ(refocus.exitCode, 0) << refocus.err;
  EXPECT_EQ(runImageTool("idiff -fail 1e-6 -warn 1e-6 " + dir.path("r.exr") + " " + dir.path("p.exr")).exitCode, 0);
  EXPECT_NE(runImageTool("idiff -fail 1e-3 " + dir.path("b.exr") + " " + dir.path("p.exr")).exitCode, 0);

  // A store without a lens needs all three values; a bad value is one line and no image.
  const std::string flat = dir.path("flat.mps");
  ASSERT_EQ(runReshutter("generate -n 2000 --width 64 --height 48 -o " + flat).exitCode, 0);
  EXPECT_EQ(readBytes(flat).at(8), 1);
  for (const std::string& bad : {std::string("--focus-distance 5"), std::string("--fstop 2 --focal-length 1 --focus-distance -1")}) {
    const CommandResult r = runReshutter("resample " + flat + " -o " + dir.path("x.exr") + " " + bad);
    EXPECT_NE(r.exitCode, 0) << bad;
    EXPECT_EQ(std::count(r.err.begin(), r.err.end(), '\n'), 1) << r.err;
    EXPECT_FALSE(std::filesystem::exists(dir.path("x.exr"))) << bad;
  }
  const CommandResult ok = runReshutter("resample " + flat + " -o " + dir.path("x.exr") + " --fstop 2 --focal-length 1 --focus-distance 5 --stats");
  EXPECT_EQ(ok.exitCode, 0) << ok.err;
  EXPECT_NE(ok.out.find("through the lens"), std::string::npos) << ok.out;
}

TEST(LensShade, WhatTheLensBlursIntoViewIsShaded) {
  // A square 6 px beyond the frame's right edge (overscan 0): the pinhole never sees it, a lens
  // whose circle of confusion there is 12 px blurs it into the frame - the shading pass keeps it.
  ScratchDir dir;
  auto ribWith = [&](const std::string& lens) {
    const std::string rib = dir.path("offscreen" + std::to_string(lens.size()) + ".rib");
    std::ofstream(rib) << ("Format 64 48 1\nProjection \"perspective\" \"fov\" 40\n" + lens +
                       "WorldBegin\nSurface \"constant\"\nColor [1 1 1]\nTranslate 0 0 8\n"
                       "Polygon \"P\" [-1 -1 0  1 -1 0  1 1 0  -1 1 0]\nPolygon \"P\" [4.6 -1 0  6.6 -1 0  6.6 1 0  4.6 1 0]\nWorldEnd\n");
    return rib;
  };
  auto micropolygons = [&](const std::string& rib, const std::string& mps) {
    const CommandResult r = runReshutter("shade " + rib + " --overscan 0 -o " + mps);
    EXPECT_EQ(r.exitCode, 0) << r.err;
    uint64_t n = 0;
    const store::StoreReader reader(mps);
    for (const auto& e : reader.entries()) n += e.numMicropolygons;
    return n;
  };
  const uint64_t pinhole = micropolygons(ribWith(""), dir.path("p.mps"));
  const uint64_t lens = micropolygons(ribWith("DepthOfField 1 1 2\n"), dir.path("l.mps"));
  EXPECT_GT(pinhole, 0u);
  EXPECT_GT(lens, pinhole + pinhole / 2) << "the off-screen square was culled";  // both squares' worth
  // And it shows: the right-most column is lit by its blur.
  const CommandResult r = runReshutter("resample " + dir.path("l.mps") + " -o " + dir.path("l.exr") + " --preview " + dir.path("l.png"));
  ASSERT_EQ(r.exitCode, 0) << r.err;
  const CommandResult stats = runImageTool("oiiotool " + dir.path("l.exr") + " --cut 4x48+60+0 --stats");
  EXPECT_EQ(stats.exitCode, 0) << stats.err;
  EXPECT_EQ(stats.out.find("Max: 0.000000 0.000000 0.000000 0.000000"), std::string::npos) << stats.out;
}

TEST(LensReference, FieldsAndRollingShutterAgreeWithTheRayCaster) {
  // The lens path draws every group's samples at their own times: interlaced fields and a rolling
  // read-out, moving quads, against the ray caster (which takes the same groups and rows).
  ScratchDir dir;
  TestScene s = makeScene(36, 24, {0.0, 1.0});
  Rng rng(31);
  for (int i = 0; i < 24; ++i) {
    TestMp mp;
    const double cx = rng.uniform(0, 36), cy = rng.uniform(0, 24), size = rng.uniform(2, 8), z = rng.uniform(4, 25);
    const glm::dvec2 vel(rng.uniform(-12, 12), rng.uniform(-6, 6));
    for (int k = 0; k < 2; ++k) mp.knots.push_back(s.rect(cx + vel.x * k, cy + vel.y * k, cx + size + vel.x * k, cy + size + vel.y * k, z));
    mp.ci = {float(rng.uniform()), float(rng.uniform()), float(rng.uniform())};
    s.mps.push_back(mp);
  }
  auto reader = writeScene(s, dir.path("f.mps"));
  const double F = double(reader->meta().frame);
  RenderSpec fields = specFor(reader, 0, 1, 4, 4, 2);
  fields.shutter = ShutterModel::fields(ShutterGroup{F, F + 0.5}, ShutterGroup{F + 0.5, F + 1.0}, 0);
  fields.lens = lensFor(s, 3, 25, 6);
  const RenderResult rf = render(fields);
  EXPECT_GT(rf.stats.raster.lensMicropolygons, 0u);
  expectRayCasterAgrees(s, fields, rf, 36, 24, "fields");
  RenderSpec rolling = specFor(reader, 0, 0.5, 4, 4, 2);
  RollingShutter rs;
  rs.duration = 0.4, rs.height = 24;
  rolling.shutter.setRolling(rs);
  rolling.lens = lensFor(s, 3, 25, 6);
  const RenderResult rr = render(rolling);
  EXPECT_GT(rr.stats.raster.lensMicropolygons, 0u);
  expectRayCasterAgrees(s, rolling, rr, 36, 24, "rolling");
}

// The lens path draws its micropolygons by depth layer, each searching the samples sorted into
// cells of their positions sheared by the layer's depth (raster_lens.cpp). Occlusion culling -
// layers nearest first, samples already hidden left out of a layer's cells - must change no bit of
// any output, flat or deep, still or moving, through a narrow or a wide aperture; and the samples
// a micropolygon examines must stay about what the pinhole needs, not grow with the circle of
// confusion (an aperture 16 times wider, up to ~25 px: a search bounded per lens stratum would
// examine tens of times more).
TEST(LensLayers, CullingIsExactAndTheSearchDoesNotGrowWithTheCircle) {
  ScratchDir dir;
  for (const char* motion : {"0 --knots 1", "12 --knots 3"}) {
    auto reader = generatedStore(std::string("-n 20000 --width 96 --height 72 --transparent 0.3 --motion ") + motion, dir.path(std::string("gen") + motion[0] + ".mps"));
    ASSERT_TRUE(reader);
    std::vector<double> examined;
    for (double fstop : {4.0, 0.25}) {  // depths 5 to 50 focused at 20: circles up to ~1.5 and ~25 px
      RenderSpec spec = specFor(reader, 0.1, 0.9, 4, 4, 7);
      spec.lens.fstop = fstop, spec.lens.focalLength = 1, spec.lens.focalDistance = 20;
      spec.aovs = {AovRequest::parse("z", "test"), AovRequest::parse("id", "test")};
      spec.deep = true;
      const auto [culled, all] = renderCulledAndNot(spec);
      const std::string what = std::string("motion ") + motion + " f/" + std::to_string(fstop);
      expectSameOutputs(culled, all, what);
      ASSERT_GT(all.stats.raster.lensMicropolygons, 0u) << what;
      EXPECT_GT(all.stats.raster.lensLayers, 0u) << what;
      // Hidden samples were left out of the cells, and hidden surfaces skipped.
      EXPECT_LT(double(culled.stats.raster.lensScanned), 0.8 * double(all.stats.raster.lensScanned)) << what;
      EXPECT_LT(culled.stats.raster.hits, all.stats.raster.hits) << what;
      examined.push_back(double(all.stats.raster.lensScanned) / double(all.stats.raster.lensMicropolygons));
    }
    EXPECT_LT(examined[1], 2.0 * examined[0]) << "motion " << motion << ": " << examined[0] << " then " << examined[1] << " samples per micropolygon";
  }
}

// The depth layers' width (RasterOptions::lensLayerWidth, chosen per render from the typical
// circle of confusion) trades sorts for search: narrower layers sort the bucket's samples more
// often and search less around each micropolygon. The image does not depend on it (only which of
// two surfaces at exactly one depth a sample keeps could, and random depths have no such ties),
// flat or deep, still or moving; the layers sorted must follow the width.
TEST(LensLayers, AnyWidthGivesTheSameImage) {
  ScratchDir dir;
  for (const char* motion : {"0 --knots 1", "12 --knots 2"}) {
    auto reader = generatedStore(std::string("-n 20000 --width 96 --height 72 --transparent 0.3 --motion ") + motion, dir.path(std::string("gen") + motion[0] + ".mps"));
    ASSERT_TRUE(reader);
    std::optional<RenderResult> chosen;
    uint64_t lastLayers = UINT64_MAX;
    for (float width : {0.f, 0.5f, 1.f, 2.f, 4.f}) {
      RenderSpec spec = specFor(reader, 0.1, 0.9, 4, 4, 7);
      spec.lens.fstop = 0.25, spec.lens.focalLength = 1, spec.lens.focalDistance = 20;  // circles up to ~25 px
      spec.aovs = {AovRequest::parse("z", "test"), AovRequest::parse("id", "test")};
      spec.deep = true;
      spec.raster.lensLayerWidth = width;
      const RenderResult r = render(spec);
      const std::string what = std::string("motion ") + motion + " width " + std::to_string(width);
      ASSERT_GT(r.stats.raster.lensMicropolygons, 0u) << what;
      if (width > 0.f) EXPECT_EQ(r.stats.lensLayerWidth, width) << what;
      else EXPECT_TRUE(r.stats.lensLayerWidth >= 1.f && r.stats.lensLayerWidth <= 2.f) << what;
      if (!chosen) {
        chosen = r;
        continue;
      }
      expectSameOutputs(r, *chosen, what);
      EXPECT_LT(r.stats.raster.lensLayers, lastLayers) << what;
      lastLayers = r.stats.raster.lensLayers;
    }
  }
  // The rule: 1 to 2 px, never narrower for a larger circle.
  float last = 0.f;
  for (double radius = 0; radius <= 200; radius += 0.5) {
    const float w = lensLayerWidth(radius);
    EXPECT_TRUE(w >= 1.f && w <= 2.f && w >= last) << radius;
    last = w;
  }
  EXPECT_EQ(lensLayerWidth(INFINITY), 2.f);
}

TEST(LensLayers, SortsVisitOnlyTheSamplesTheirSearchesCanReach) {
  // Against sorting every sample of the region for every layer: the same samples examined, the
  // same tests and outputs, from fewer samples visited - moving (time blocks, lens quadrants) and
  // still, a dense store and a sparse one, every kernel set, circles up to ~6 and ~25 px.
  ScratchDir dir;
  for (const char* args : {"-n 20000 --transparent 0.3 --motion 12 --knots 2", "-n 20000 --motion 0 --knots 1", "-n 700 --motion 0 --knots 1"}) {
    auto reader = generatedStore(std::string("--width 96 --height 72 ") + args, dir.path("gen" + std::to_string(std::hash<std::string>{}(args)) + ".mps"));
    ASSERT_TRUE(reader);
    for (const double fstop : {1.0, 0.25})
      for (const int kernels : {0, 1, 2}) {
        RenderResult r[2];
        for (const bool reached : {false, true}) {
          RenderSpec spec = specFor(reader, 0.1, 0.9, 4, 4, 3);
          spec.lens.fstop = fstop, spec.lens.focalLength = 1, spec.lens.focalDistance = 20;
          spec.aovs = {AovRequest::parse("z", "test")};
          spec.deep = true;
          spec.raster.vectorKernels = kernels > 0;
          spec.raster.avx512Kernels = kernels > 1;
          spec.raster.lensSortReached = reached;
          r[reached] = render(spec);
        }
        const std::string what = std::string(args) + " fstop " + std::to_string(fstop) + " kernels " + std::to_string(kernels);
        ASSERT_GT(r[1].stats.raster.lensLayers, 0u) << what;
        EXPECT_EQ(r[0].stats.raster.lensSparseLayers, 0u) << what;
        EXPECT_GT(r[1].stats.raster.lensSparseLayers, 0u) << what;
        EXPECT_LT(r[1].stats.raster.lensSortVisited, r[0].stats.raster.lensSortVisited) << what;
        EXPECT_EQ(r[1].stats.raster.lensScanned, r[0].stats.raster.lensScanned) << what;
        EXPECT_EQ(r[1].stats.raster.sampleTests, r[0].stats.raster.sampleTests) << what;
        expectSameOutputs(r[1], r[0], what);
      }
  }
}

TEST(LensDeterminism, BitIdenticalForAnyThreadCountBucketSizeAndInstructionSet) {
  ScratchDir dir;
  struct Store {
    const char* name;
    std::string args;
    bool moving, sparse;
  };
  // The sparse store's layers reach few tiles of their grids: their sorts read the tile marks.
  for (const Store& st : {Store{"moving", "-n 40000 --transparent 0.3 --motion 12 --knots 3", true, false},
                          Store{"still", "-n 40000 --transparent 0.3 --motion 0 --knots 1", false, false},
                          Store{"sparse", "-n 700 --motion 0 --knots 1", false, true}}) {
    auto reader = generatedStore("--width 128 --height 96 " + st.args, dir.path(std::string(st.name) + ".mps"));
    ASSERT_TRUE(reader);
    struct Variant {
      int threads, bucket;
      bool vector, avx512;
    };
    std::vector<std::vector<float>> images;
    for (const Variant v : {Variant{1, 32, true, true}, Variant{2, 16, true, true}, Variant{2, 57, true, false}, Variant{1, 24, false, false}}) {
      tbb::global_control limit(tbb::global_control::max_allowed_parallelism, size_t(v.threads));
      RenderSpec spec = specFor(reader, 0.1, 0.9, 4, 4, 42);
      spec.filter = FilterSpec::parse("gaussian:2x2", "test");
      spec.bucketSize = v.bucket;
      spec.raster.vectorKernels = v.vector;
      spec.raster.avx512Kernels = v.avx512;
      spec.lens.fstop = 1, spec.lens.focalLength = 1, spec.lens.focalDistance = 20;  // depths 5 to 50: up to ~6 px
      // A moving store: planes pair time blocks with lens quadrants.
      EXPECT_EQ(lensTimeBlocks(spec), st.moving ? 4 : 1);
      const RenderResult r = render(spec);
      EXPECT_GT(r.stats.raster.lensMicropolygons, 0u);
      EXPECT_GT(r.stats.raster.lensLayers, 0u);
      if (st.sparse) {
        EXPECT_GT(r.stats.raster.lensSparseLayers, 0u) << "variant " << images.size();
      }
      // Micropolygons of parts that overlap a bucket but whose blur cannot reach it were left out.
      EXPECT_GT(r.stats.raster.lensCulledMicropolygons, 0u) << st.name << " variant " << images.size();
      std::vector<float> all;
      for (const auto& c : r.image.channels) all.insert(all.end(), c.f.begin(), c.f.end());
      images.push_back(all);
    }
    for (size_t i = 1; i < images.size(); ++i) {
      ASSERT_EQ(images[i].size(), images[0].size());
      EXPECT_EQ(std::memcmp(images[i].data(), images[0].data(), images[0].size() * sizeof(float)), 0) << st.name << " variant " << i;
    }
  }
}
