// Volumes at re-sample time (resample/volume.h), held to analytic truths: a homogeneous medium
// transmits exp(-σ·chord) along each sample's ray, an emitting one adds E(1 - e^{-σ·chord})/σ,
// surfaces cut the march where they stand, a velocity grid carries the medium with time, and
// the deep image carries the volume as thick samples that flatten to the flat image. The
// reference is computed per sample from the renderer's own sample positions and times (the
// SamplePattern), by ray-box and ray-sphere intersection in double precision. Test VDBs are made
// here with OpenVDB.
#include <cmath>
#include <filesystem>
#include <fstream>
#include <functional>
#include <optional>
#include <sstream>
#include <string>

#include <gtest/gtest.h>
#include <openvdb/openvdb.h>
#include <tbb/global_control.h>

#include "common/error.h"
#include "resample/deep.h"
#include "resample/resampler.h"
#include "resample/volume.h"
#include "test_util.h"
#include "tests/resample_test_util.h"

namespace reshutter {
namespace {

using namespace resample;
using test::ScratchDir;

constexpr int kW = 48, kH = 36;
constexpr double kVoxel = 0.05;

/// The effective world bounds of voxels [i0, i1] filled with one value: trilinear interpolation
/// ramps across half a voxel on each side, which integrates to the faces at i ± 0.5.
struct Box {
  openvdb::Coord i0, i1;
  glm::dvec3 lo() const { return {(i0.x() - 0.5) * kVoxel, (i0.y() - 0.5) * kVoxel, (i0.z() - 0.5) * kVoxel}; }
  glm::dvec3 hi() const { return {(i1.x() + 0.5) * kVoxel, (i1.y() + 0.5) * kVoxel, (i1.z() + 0.5) * kVoxel}; }
};

// Voxels [x0, x1] × [y0, y1] × [z0, z1] in world units (voxel centres), rounded to the grid.
Box boxOf(double x0, double x1, double y0, double y1, double z0, double z1) {
  auto c = [](double v) { return int(std::lround(v / kVoxel)); };
  return {openvdb::Coord(c(x0), c(y0), c(z0)), openvdb::Coord(c(x1), c(y1), c(z1))};
}

openvdb::FloatGrid::Ptr filledGrid(const Box& box, float value, const std::string& name) {
  auto g = openvdb::FloatGrid::create(0.f);
  g->setTransform(openvdb::math::Transform::createLinearTransform(kVoxel));
  g->fill(openvdb::CoordBBox(box.i0, box.i1), value, true);
  g->setName(name);
  g->setGridClass(openvdb::GRID_FOG_VOLUME);
  return g;
}

std::string writeVdb(const ScratchDir& dir, const std::string& name, const openvdb::GridPtrVec& grids) {
  openvdb::initialize();
  const std::string path = dir.path(name);
  openvdb::io::File(path).write(grids);
  return path;
}

// Length of the ray origin + s·dir inside the axis-aligned box [lo, hi] for s in [s0, s1].
double chordInBox(const glm::dvec3& dir, const glm::dvec3& lo, const glm::dvec3& hi, double s0, double s1) {
  double a = s0, b = s1;
  for (int k = 0; k < 3; ++k) {
    if (dir[k] == 0) {
      if (0 < lo[k] || 0 > hi[k]) return 0;
      continue;
    }
    double ta = lo[k] / dir[k], tb = hi[k] / dir[k];
    if (ta > tb) std::swap(ta, tb);
    a = std::max(a, ta), b = std::min(b, tb);
  }
  return b > a ? (b - a) * glm::length(dir) : 0.0;
}

/// The box filter's pixel value (box:1, the tests' spec): the mean over the pixel's own samples
/// of f(ray direction at depth 1, absolute time), with the renderer's sample positions and times.
double pixelMean(const test::TestScene& scene, const RenderSpec& spec, int px, int py, const std::function<double(const glm::dvec3&, double)>& f) {
  const SamplePattern pattern(spec.samplesX, spec.samplesY, spec.seed);
  const int N = pattern.spp();
  std::vector<uint16_t> stratumOf(static_cast<size_t>(N));
  std::vector<float> u(static_cast<size_t>(N));
  pattern.times(px, py, stratumOf.data(), u.data());
  const ShutterGroup& g = spec.shutter.groups()[0];
  const int pat = pattern.patternOf(px, py);
  double sum = 0;
  for (int i = 0; i < N; ++i) {
    const glm::vec2 o = pattern.offset(pat, i);
    const float x = float(px) + o.x, y = float(py) + o.y;
    sum += f(scene.cam(x, y, 1.0), g.open + double(u[size_t(i)]) * g.length());
  }
  return sum / N;
}

struct Fixture {
  ScratchDir dir;
  test::TestScene scene = test::makeScene(kW, kH, {0.0});
  std::shared_ptr<const store::StoreReader> store;

  // A white wall filling the view at depth z (with margin), optionally a quad in front.
  void wall(double z) {
    test::TestMp mp;
    mp.knots = {scene.rect(-8, -8, kW + 8, kH + 8, z)};
    mp.ci = {1, 1, 1};
    scene.mps.push_back(mp);
  }
  RenderSpec spec(std::shared_ptr<const VolumeScene> volumes, double open = 0, double close = 1) {
    store = test::writeScene(scene, dir.path("scene.mps"));
    RenderSpec s = test::specFor(store, open, close, 4, 4, 7);
    s.volumes = std::move(volumes);
    return s;
  }
};

// The analytic truths hold for each sample's own ray: by default every sample marches it
// (raySpacing 0); shared rays are checked against that march (SharedRays below) and, where their
// blend is exact (across a slab), against the same truths.
std::shared_ptr<const VolumeScene> volumeOf(const std::string& spec, float step = 0.5f, bool skip = true, bool cacheShadows = true, float raySpacing = 0.f) {
  VolumeOptions o;
  o.step = step, o.skipEmpty = skip, o.cacheShadows = cacheShadows, o.raySpacing = raySpacing;
  return std::make_shared<const VolumeScene>(std::vector<VolumeSpec>{VolumeSpec::parse(spec, "test")}, o);
}

TEST(Volume, HomogeneousBoxInFrontOfAWallTransmitsExpMinusSigmaChord) {
  Fixture fx;
  fx.wall(8.0);
  const Box box = boxOf(-4, 4, -3, 3, 3, 5);
  const float sigma = 0.7f;
  const std::string vdb = writeVdb(fx.dir, "box.vdb", {filledGrid(box, 1.f, "density")});
  for (int variant = 0; variant < 3; ++variant) {
    // The slab fills the view, so blending shared rays is exact to rounding here too.
    const bool skip = variant != 1, shared = variant == 2;
    SCOPED_TRACE(shared ? "shared rays" : skip ? "empty space skipped" : "whole bounds marched");
    const RenderSpec spec = fx.spec(volumeOf(vdb + ",density-scale=" + std::to_string(sigma), 0.5f, skip, true, shared ? 1.f : 0.f));
    const RenderResult r = render(spec);
    EXPECT_GT(r.stats.volumes.rays, 0u);
    EXPECT_GT(r.stats.volumes.steps, 0u);
    EXPECT_EQ(r.stats.volumes.sharedSegments > 0, shared);
    const auto& R = test::channel(r, "R");
    const auto& A = test::channel(r, "A");
    double worst = 0;
    for (int py = 0; py < kH; ++py)
      for (int px = 0; px < kW; ++px) {
        const double expect =
            pixelMean(fx.scene, spec, px, py, [&](const glm::dvec3& d, double) { return std::exp(-sigma * chordInBox(d, box.lo(), box.hi(), 0, 8)); });
        const size_t o = size_t(py) * kW + px;
        worst = std::max(worst, std::abs(R.f[o] - expect));
        EXPECT_NEAR(A.f[o], 1.0, 1e-6);  // the wall is opaque: the volume in front changes colour, not coverage
      }
    EXPECT_LT(worst, 2e-3);
  }
}

TEST(Volume, EmissionOnlySlabGlowsByTheAnalyticIntegral) {
  Fixture fx;
  const Box box = boxOf(-4, 4, -3, 3, 3, 5);
  const float sigma = 0.9f, emission = 0.6f;
  const std::string vdb = writeVdb(fx.dir, "glow.vdb", {filledGrid(box, 1.f, "density"), filledGrid(box, emission, "heat")});
  const RenderSpec spec = fx.spec(volumeOf(vdb + ",emission=heat,emission-color=1:0.5:0.25,density-scale=" + std::to_string(sigma)));
  const RenderResult r = render(spec);
  const auto& R = test::channel(r, "R");
  const auto& B = test::channel(r, "B");
  const auto& A = test::channel(r, "A");
  double worst = 0;
  for (int py = 0; py < kH; ++py)
    for (int px = 0; px < kW; ++px) {
      const size_t o = size_t(py) * kW + px;
      const double opacity =
          pixelMean(fx.scene, spec, px, py, [&](const glm::dvec3& d, double) { return 1 - std::exp(-sigma * chordInBox(d, box.lo(), box.hi(), 0, 1e9)); });
      const double glow = emission * opacity / sigma;  // E (1 - e^{-σL}) / σ, averaged
      worst = std::max({worst, std::abs(R.f[o] - glow), std::abs(B.f[o] - 0.25 * glow), std::abs(A.f[o] - opacity)});
    }
  EXPECT_LT(worst, 2e-3);
}

TEST(Volume, SphereTransmittanceFollowsTheChordPixelByPixel) {
  Fixture fx;
  fx.wall(9.0);
  // Voxels whose centres lie inside a sphere of radius 1 at (0.2, -0.1, 5).
  const glm::dvec3 c(0.2, -0.1, 5.0);
  const double radius = 1.0, h = 0.025;
  auto g = openvdb::FloatGrid::create(0.f);
  g->setTransform(openvdb::math::Transform::createLinearTransform(h));
  g->setName("density");
  auto acc = g->getAccessor();
  const int n = int(std::ceil(radius / h)) + 1;
  const openvdb::Coord ic(int(std::lround(c.x / h)), int(std::lround(c.y / h)), int(std::lround(c.z / h)));
  for (int i = -n; i <= n; ++i)
    for (int j = -n; j <= n; ++j)
      for (int k = -n; k <= n; ++k) {
        const glm::dvec3 p((ic.x() + i) * h, (ic.y() + j) * h, (ic.z() + k) * h);
        if (glm::length(p - c) < radius) acc.setValue(openvdb::Coord(ic.x() + i, ic.y() + j, ic.z() + k), 1.f);
      }
  const std::string vdb = writeVdb(fx.dir, "sphere.vdb", {g});
  const double sigma = 1.2;
  const RenderSpec spec = fx.spec(volumeOf(vdb + ",density-scale=1.2", 0.25f));
  const RenderResult r = render(spec);
  const auto& R = test::channel(r, "R");
  double worst = 0, sum = 0;
  int inside = 0;
  for (int py = 0; py < kH; ++py)
    for (int px = 0; px < kW; ++px) {
      double chordMean = 0;
      const double expect = pixelMean(fx.scene, spec, px, py, [&](const glm::dvec3& d, double) {
        // |p(s) - c|² = radius² along p(s) = s·d.
        const double A = glm::dot(d, d), B = -2 * glm::dot(d, c), C = glm::dot(c, c) - radius * radius, disc = B * B - 4 * A * C;
        const double chord = disc > 0 ? std::sqrt(disc) / A * std::sqrt(A) : 0.0;
        chordMean += chord;
        return std::exp(-sigma * chord);
      });
      const double err = std::abs(R.f[size_t(py) * kW + px] - expect);
      worst = std::max(worst, err), sum += err;
      inside += chordMean > 0;
    }
  EXPECT_GT(inside, 100);  // the sphere covers a good part of the frame
  // Voxelisation moves the surface by up to half a voxel: large only where the chord is short.
  EXPECT_LT(worst, 0.03);
  EXPECT_LT(sum / (kW * kH), 2e-3);
}

// Through a lens a volume blurs as a surface does (issue #26): each sample's ray leaves its own
// lens point. A thin dense slab at depth 10 covering raster x >= the frame's centre column, in front of
// a white wall, focused at depth 5: a sample at x sees the slab where its lens displacement r·u
// (u the lens point's x on the unit disk, r the circle of confusion at the slab's front) is at
// most x - edge, so a column's red is 1 minus that disk fraction averaged over the pixel. Buckets
// of 4 pixels, narrower than the blur: a bucket beside the slab must still march it. Focused on
// the slab, the image is the pinhole's. Shared rays (the default) give way to each sample's march.
TEST(Volume, ThroughALensAVolumeBlursByItsCircleOfConfusion) {
  constexpr int W = 64, H = 24;
  ScratchDir dir;
  test::TestScene scene = test::makeScene(W, H, {0.0});
  test::TestMp wallMp;
  wallMp.knots = {scene.rect(-200, -200, W + 200, H + 200, 40)};
  wallMp.ci = {1, 1, 1};
  scene.mps.push_back(wallMp);
  auto store = test::writeScene(scene, dir.path("wall.mps"));
  // Two voxels thick (0.1 world units): thin enough that a lens ray's slope across it moves it a
  // small fraction of a pixel, dense enough (optical depth 25) to be opaque.
  const glm::dvec3 a = scene.cam(-30, -30, 10), b = scene.cam(W + 30, H + 30, 10);
  Box slab = boxOf(0.0, std::max(a.x, b.x), std::min(a.y, b.y), std::max(a.y, b.y), 0, 0);
  slab.i0.z() = 199, slab.i1.z() = 200;
  const double zFront = slab.lo().z, zMiddle = 0.5 * (slab.lo().z + slab.hi().z);
  const std::string vdb = writeVdb(dir, "slab.vdb", {filledGrid(slab, 1.f, "density")});
  const auto volumes = volumeOf(vdb + ",density-scale=250", 0.5f, true, true, 1.f);  // raySpacing 1: shared unless a lens forbids it
  const store::Projector projector(scene.meta.cameras[0]);
  // The slab's face x = slab.lo().x seen at its front depth, in raster columns (the face lies on
  // the optical axis's side plane, so every depth puts it within a voxel of the centre).
  const double edge = projector.ax * slab.lo().x / zFront + projector.bx;
  // One aperture: a circle of confusion of r pixels at the slab's front when focused at depth 5.
  const double r = 6.5;
  const RenderSpec::LensOverride lens = test::lensFor(scene, r, zFront, 5.0);
  // The pinhole reference marches every sample's ray too: shared rays blend optical depth across
  // a lattice spacing, which moves a hard edge by up to that.
  const auto marched = volumeOf(vdb + ",density-scale=250", 0.5f, true, true, 0.f);
  auto renderWith = [&](std::optional<double> focus) {
    RenderSpec spec = test::specFor(store, 0, 0, 8, 8, 3);
    spec.bucketSize = 4;
    spec.volumes = focus ? volumes : marched;
    if (focus) spec.lens = lens, spec.lens.focalDistance = *focus;
    return render(spec);
  };
  auto redColumns = [&](const RenderResult& res) {
    const auto& R = test::channel(res, "R").f;
    std::vector<double> col(size_t(W), 0.0);
    for (int py = 0; py < H; ++py)
      for (int px = 0; px < W; ++px) col[size_t(px)] += R[size_t(py) * W + px] / H;
    return col;
  };
  const RenderResult pinhole = renderWith(std::nullopt);
  {
    RenderSpec shared = test::specFor(store, 0, 0, 2, 2, 3);
    shared.volumes = volumes;
    EXPECT_GT(render(shared).stats.volumes.sharedSegments, 0u);  // without a lens the same volumes share rays
  }
  const std::vector<double> sharp = redColumns(pinhole);
  EXPECT_GT(sharp[size_t(edge) - 2], 0.999);
  EXPECT_LT(sharp[size_t(edge) + 2], 1e-3);

  const RenderResult blurred = renderWith(5.0);
  EXPECT_EQ(blurred.stats.volumes.sharedSegments, 0u);
  EXPECT_GT(blurred.stats.volumes.rays, 0u);
  EXPECT_GT(blurred.stats.raster.lensMicropolygons, 0u);  // the wall went through the lens path too
  const std::vector<double> col = redColumns(blurred);
  double sumErr = 0;
  for (int px = 0; px < W; ++px) {
    double covered = 0;
    const int steps = 400;
    for (int k = 0; k < steps; ++k) covered += test::diskBelow((px + (k + 0.5) / steps - edge) / r) / steps;
    const double err = std::abs(col[size_t(px)] - (1 - covered));
    sumErr += err;
    EXPECT_LT(err, 0.04) << "column " << px << ": " << col[size_t(px)] << " against " << 1 - covered;
  }
  EXPECT_LT(sumErr / W, 0.01);
  // The blur is as wide as the circle, on both sides of the edge.
  EXPECT_LT(col[size_t(edge - r + 1)], 0.999);
  EXPECT_GT(col[size_t(edge + r - 2)], 1e-3);

  // Focused on the slab: within a few per cent of the pinhole image column by column (its
  // thickness still blurs by a few hundredths of a pixel).
  const std::vector<double> focused = redColumns(renderWith(zMiddle));
  for (int px = 0; px < W; ++px) EXPECT_NEAR(focused[size_t(px)], sharp[size_t(px)], 0.05) << "column " << px;
}

TEST(Volume, SingleScatteringFromTheStoresLightWithSelfShadowing) {
  // A slab lit by a distant light shining along the view axis, from the camera's side: a point at
  // depth z inside receives the light through z - front of the medium, and sends it back through
  // (z - front)·|d| of it, so the slab adds a·I·|d|/(1+|d|)·(1 - e^{-σL(1+|d|)}) (isotropic phase).
  Fixture fx;
  store::StoredLight sun;
  sun.kind = store::StoredLight::Kind::Distant;
  sun.axis = {0, 0, 1};
  sun.colour = glm::dvec3(0.8);
  fx.scene.meta.lights = {sun};
  const Box box = boxOf(-4, 4, -3, 3, 3, 5);
  const double sigma = 0.6, L = box.hi().z - box.lo().z;
  const std::string vdb = writeVdb(fx.dir, "lit.vdb", {filledGrid(box, 1.f, "density")});
  const RenderSpec spec = fx.spec(volumeOf(vdb + ",density-scale=0.6,albedo=1:0.5:0.25"));
  const RenderResult r = render(spec);
  EXPECT_GT(r.stats.volumes.shadowSteps, 0u);
  EXPECT_GT(r.stats.volumes.cachedShadows, 0u);
  double worst = 0;
  for (int py = 0; py < kH; ++py)
    for (int px = 0; px < kW; ++px) {
      const double lit = pixelMean(fx.scene, spec, px, py, [&](const glm::dvec3& d, double) {
        const double n = glm::length(d);
        return 0.8 * n / (1 + n) * (1 - std::exp(-sigma * L * (1 + n)));
      });
      const size_t o = size_t(py) * kW + px;
      worst = std::max({worst, std::abs(test::channel(r, "R").f[o] - lit), std::abs(test::channel(r, "G").f[o] - 0.5 * lit),
                        std::abs(test::channel(r, "B").f[o] - 0.25 * lit)});
    }
  EXPECT_LT(worst, 3e-3);
  // Shadow rays from every step (no cache) agree, over a corner of the frame.
  RenderSpec exact = fx.spec(volumeOf(vdb + ",density-scale=0.6,albedo=1:0.5:0.25", 0.5f, true, false));
  exact.cropX0 = 0, exact.cropX1 = 6, exact.cropY0 = 0, exact.cropY1 = 6;
  const RenderResult e = render(exact);
  EXPECT_EQ(e.stats.volumes.cachedShadows, 0u);
  for (int py = 0; py < 6; ++py)
    for (int px = 0; px < 6; ++px) EXPECT_NEAR(test::channel(e, "R").f[size_t(py) * 6 + px], test::channel(r, "R").f[size_t(py) * kW + px], 3e-3);
  // A colour grid (Houdini's Cd) scales the albedo voxel by voxel: white albedo under a Cd of
  // (1, 0.5, 0.25), filled two voxels past the density so that its interpolation is constant
  // wherever there is medium, scatters what albedo 1:0.5:0.25 does.
  auto cd = openvdb::Vec3SGrid::create(openvdb::Vec3s(0.f));
  cd->setTransform(openvdb::math::Transform::createLinearTransform(kVoxel));
  cd->fill(openvdb::CoordBBox(box.i0.offsetBy(-2), box.i1.offsetBy(2)), openvdb::Vec3s(1.f, 0.5f, 0.25f), true);
  cd->setName("Cd");
  const std::string coloured = writeVdb(fx.dir, "coloured.vdb", {filledGrid(box, 1.f, "density"), cd});
  const RenderResult c = render(fx.spec(volumeOf(coloured + ",density-scale=0.6,color=Cd")));
  for (const char* ch : {"R", "G", "B"})
    for (size_t o = 0; o < test::channel(r, ch).f.size(); ++o) ASSERT_NEAR(test::channel(c, ch).f[o], test::channel(r, ch).f[o], 1e-6) << ch << " " << o;
  // Without the store's lights the same slab scatters nothing.
  fx.scene.meta.lights.clear();
  const RenderResult dark = render(fx.spec(volumeOf(vdb + ",density-scale=0.6")));
  EXPECT_EQ(dark.stats.volumes.shadowSteps, 0u);
  for (float v : test::channel(dark, "R").f) ASSERT_EQ(v, 0.f);
}

TEST(Volume, SurfacesCutTheMarchAndTransparentOnesInterleave) {
  Fixture fx;
  fx.wall(8.0);
  const Box box = boxOf(-4, 4, -3, 3, 3, 5);
  const double zq = 4.0;
  // An opaque grey quad inside the medium over the left third, a 50 % transparent one over the right third.
  test::TestMp opaque;
  opaque.knots = {fx.scene.rect(-8, -8, 16, kH + 8, zq)};
  opaque.ci = {0.5, 0.5, 0.5};
  test::TestMp glass;
  glass.knots = {fx.scene.rect(32, -8, kW + 8, kH + 8, zq)};
  glass.ci = {0.25, 0.25, 0.25}, glass.oi = {0.5, 0.5, 0.5};
  fx.scene.mps.push_back(opaque), fx.scene.mps.push_back(glass);
  const float sigma = 0.8f;
  const std::string vdb = writeVdb(fx.dir, "box.vdb", {filledGrid(box, 1.f, "density")});
  const RenderSpec spec = fx.spec(volumeOf(vdb + ",density-scale=0.8"));
  const RenderResult r = render(spec);
  const auto& R = test::channel(r, "R");
  double worst = 0;
  for (int py = 0; py < kH; ++py)
    for (const int px : {4, 10, 24, 38, 44}) {
      const double expect = pixelMean(fx.scene, spec, px, py, [&](const glm::dvec3& d, double) {
        const double front = std::exp(-sigma * chordInBox(d, box.lo(), box.hi(), 0, zq)), back = std::exp(-sigma * chordInBox(d, box.lo(), box.hi(), zq, 8));
        if (px < 16) return front * 0.5;                   // stops at the opaque quad
        if (px >= 32) return front * (0.25 + 0.5 * back);  // glass, then the medium behind it, then the wall
        return front * back;                               // the whole chord, then the wall
      });
      worst = std::max(worst, std::abs(R.f[size_t(py) * kW + px] - expect));
    }
  EXPECT_LT(worst, 2e-3);
}

TEST(Volume, VelocityGridCarriesTheMediumWithEachSamplesTime) {
  Fixture fx;
  fx.wall(8.0);
  // A slab narrower than the view, moving +x by D world units over the frame's 1/24 s shutter.
  const Box box = boxOf(-1, 0, -3, 3, 3, 5);
  const double D = 0.6, fps = 24;
  auto vel = openvdb::Vec3SGrid::create(openvdb::Vec3s(0.f));
  vel->setTransform(openvdb::math::Transform::createLinearTransform(kVoxel));
  vel->fill(openvdb::CoordBBox(box.i0.offsetBy(-30), box.i1.offsetBy(30)), openvdb::Vec3s(float(D * fps), 0.f, 0.f), true);
  vel->setName("vel");
  const std::string vdb = writeVdb(fx.dir, "moving.vdb", {filledGrid(box, 1.f, "density"), vel});
  const float sigma = 1.5f;
  const RenderSpec spec = fx.spec(volumeOf(vdb + ",density-scale=1.5"));
  const RenderResult r = render(spec);
  const auto& R = test::channel(r, "R");
  double worst = 0, sum = 0;
  int partial = 0;  // pixels the slab covers for part of the shutter only: the blur
  for (int py = 0; py < kH; ++py)
    for (int px = 0; px < kW; ++px) {
      const double expect = pixelMean(fx.scene, spec, px, py, [&](const glm::dvec3& d, double t) {
        const glm::dvec3 shift((t - double(fx.scene.meta.frame)) / fps * D * fps, 0, 0);
        return std::exp(-sigma * chordInBox(d, box.lo() + shift, box.hi() + shift, 0, 8));
      });
      const double v = R.f[size_t(py) * kW + px];
      worst = std::max(worst, std::abs(v - expect)), sum += std::abs(v - expect);
      partial += expect > 0.1 && expect < 0.9;
    }
  EXPECT_GT(partial, 3 * kH);
  // The slab's side faces are interpolated over a voxel, which rays cross at a slant: a few
  // hundredths at the edges (as for a still slab), nothing on average.
  EXPECT_LT(worst, 0.04);
  EXPECT_LT(sum / (kW * kH), 2e-3);
}

TEST(Volume, DeepImageCarriesTheVolumeAsThickSamplesAndFlattensToTheFlatImage) {
  Fixture fx;
  fx.wall(8.0);
  test::TestMp glass;
  glass.knots = {fx.scene.rect(20, -8, kW + 8, kH + 8, 4.0)};
  glass.ci = {0.2, 0.1, 0.1}, glass.oi = {0.4, 0.4, 0.4};
  fx.scene.mps.push_back(glass);
  const Box box = boxOf(-4, 4, -3, 3, 3, 5);
  const std::string vdb = writeVdb(fx.dir, "glow.vdb", {filledGrid(box, 1.f, "density"), filledGrid(box, 0.5f, "heat")});
  for (float spacing : {0.f, 1.f}) {
  SCOPED_TRACE(spacing > 0 ? "shared rays" : "a ray per sample");
  RenderSpec spec = fx.spec(volumeOf(vdb + ",emission=heat,density-scale=0.6", 0.5f, true, true, spacing));
  spec.deep = true;
  spec.filter = FilterSpec::parse("gaussian:2x2", "test");
  const RenderResult r = render(spec);
  EXPECT_EQ(r.stats.volumes.sharedSegments > 0, spacing > 0);
  const auto& R = test::channel(r, "R");
  const auto& A = test::channel(r, "A");
  DeepPixel px;
  size_t thick = 0;
  double worst = 0;
  for (int y = 0; y < kH; ++y)
    for (int x = 0; x < kW; ++x) {
      r.deep.getPixel(x, y, px);
      EXPECT_TRUE(isTidy(px));
      for (size_t i = 0; i < px.size(); ++i)
        if (px.uat(i)[kDeepObjectId] == kVolumeObjectId) {
          EXPECT_LT(px.at(i)[kDeepZ], px.at(i)[kDeepZBack]);
          // The medium, interpolated, spans 3 - h to 5 + h; a step reaches half a step beyond.
          EXPECT_GE(px.at(i)[kDeepZ], 3.0 - 1.5 * kVoxel);
          EXPECT_LE(px.at(i)[kDeepZBack], 5.0 + 1.5 * kVoxel);
          ++thick;
        }
      const FlatDeepPixel f = flattenDeepPixel(px, r.deep.layout, true);
      const size_t o = size_t(y) * kW + x;
      worst = std::max({worst, std::abs(f.r - R.f[o]), std::abs(f.a - A.f[o])});
    }
  EXPECT_GT(thick, size_t(kW * kH));  // several slices per pixel
  EXPECT_LT(worst, 1e-4);
  }
}

// Shared rays (VolumeOptions::raySpacing) against every sample marching its own ray, on a sphere
// of fog whose chord changes fastest at its rim: the blend's error is small on average, grows
// with the spacing, and costs a fraction of the lookups; the image does not depend on buckets or
// threads; a volume that moves is marched per sample whatever the spacing.
TEST(Volume, SharedRaysFollowTheMarchAndTheirErrorGrowsWithTheSpacing) {
  Fixture fx;
  fx.wall(8.0);
  const glm::dvec3 c(0.3, -0.2, 4.0);
  const double radius = 1.4;
  auto g = openvdb::FloatGrid::create(0.f);
  g->setTransform(openvdb::math::Transform::createLinearTransform(kVoxel));
  g->setGridClass(openvdb::GRID_FOG_VOLUME);
  g->setName("density");
  auto acc = g->getAccessor();
  const int n = int(std::ceil(radius / kVoxel)) + 1;
  for (int i = -n; i <= n; ++i)
    for (int j = -n; j <= n; ++j)
      for (int k = -n; k <= n; ++k) {
        const glm::dvec3 p(i * kVoxel, j * kVoxel, k * kVoxel);
        // Density falling off toward the rim, as smoke does.
        const double r = glm::length(p) / radius;
        if (r < 1) acc.setValue(openvdb::Coord(int(std::lround(c.x / kVoxel)) + i, int(std::lround(c.y / kVoxel)) + j, int(std::lround(c.z / kVoxel)) + k), float(1 - r * r));
      }
  const std::string vdb = writeVdb(fx.dir, "puff.vdb", {g});
  const std::string what = vdb + ",density-scale=1.5";
  const RenderResult marched = render(fx.spec(volumeOf(what, 0.5f)));
  EXPECT_EQ(marched.stats.volumes.sharedSegments, 0u);
  auto meanError = [&](const RenderResult& r) {
    double sum = 0;
    const auto& a = test::channel(r, "R").f;
    const auto& b = test::channel(marched, "R").f;
    for (size_t i = 0; i < a.size(); ++i) sum += std::abs(double(a[i]) - double(b[i]));
    return sum / double(a.size());
  };
  double previous = 0;
  for (float spacing : {1.f, 2.f, 4.f}) {
    SCOPED_TRACE("spacing " + std::to_string(spacing));
    const RenderResult r = render(fx.spec(volumeOf(what, 0.5f, true, true, spacing)));
    EXPECT_GT(r.stats.volumes.sharedSegments, 0u);
    EXPECT_LT(r.stats.volumes.sharedRays, r.stats.volumes.sharedSegments / 8);
    EXPECT_LT(r.stats.volumes.steps, marched.stats.volumes.steps / 4);
    const double e = meanError(r);
    EXPECT_GT(e, previous);
    if (spacing == 1.f) {
      EXPECT_LT(e, 2e-3);
    }
    previous = e;
  }
  // Buckets and threads do not change a bit.
  auto renderWith = [&](int threads, int bucket) {
    tbb::global_control limit(tbb::global_control::max_allowed_parallelism, size_t(threads));
    RenderSpec spec = fx.spec(volumeOf(what, 0.5f, true, true, 1.f));
    spec.bucketSize = bucket;
    return render(spec);
  };
  const RenderResult ra = renderWith(1, 8), rb = renderWith(2, 13);
  for (const char* ch : {"R", "G", "B", "A"}) EXPECT_EQ(test::channel(ra, ch).f, test::channel(rb, ch).f) << ch;
  // A volume carried by a velocity grid has rays that depend on time: marched per sample.
  auto vel = openvdb::Vec3SGrid::create(openvdb::Vec3s(0.f));
  vel->setTransform(openvdb::math::Transform::createLinearTransform(kVoxel));
  vel->fill(openvdb::CoordBBox(openvdb::Coord(-80), openvdb::Coord(80)), openvdb::Vec3s(2.f, 0.f, 0.f), true);
  vel->setName("vel");
  const std::string moving = writeVdb(fx.dir, "moving.vdb", {g, vel});
  const RenderResult m = render(fx.spec(volumeOf(moving + ",density-scale=1.5", 0.5f, true, true, 1.f)));
  EXPECT_GT(m.stats.volumes.steps, 0u);
  EXPECT_EQ(m.stats.volumes.sharedSegments, 0u);
}

TEST(Volume, ARenderWithoutVolumesOrOutOfViewMarchesNothing) {
  Fixture fx;
  fx.wall(8.0);
  const RenderResult plain = render(fx.spec(nullptr));
  EXPECT_EQ(plain.stats.volumes.rays, 0u);
  // A volume wholly outside the view: no bucket sees it, so no ray is marched and the image is
  // the one without it, bit for bit.
  const Box away = boxOf(40, 44, -2, 2, 3, 5);
  const std::string vdb = writeVdb(fx.dir, "away.vdb", {filledGrid(away, 1.f, "density")});
  const RenderResult with = render(fx.spec(volumeOf(vdb)));
  EXPECT_EQ(with.stats.volumes.rays, 0u);
  EXPECT_EQ(test::channel(with, "R").f, test::channel(plain, "R").f);
}

TEST(Volume, BadInputIsAOneLineErrorNamingTheFile) {
  ScratchDir dir;
  const Box box = boxOf(0, 1, 0, 1, 0, 1);
  auto vel = openvdb::Vec3SGrid::create();
  vel->setName("vel");
  vel->fill(openvdb::CoordBBox(box.i0, box.i1), openvdb::Vec3s(1.f), true);
  const std::string vdb = writeVdb(dir, "v.vdb", {filledGrid(box, 1.f, "density"), vel});
  auto error = [](const std::string& spec) {
    try {
      VolumeScene({VolumeSpec::parse(spec, "--volume")}, VolumeOptions{});
    } catch (const Error& e) {
      return std::string(e.what());
    }
    return std::string("no error");
  };
  EXPECT_NE(error(dir.path("missing.vdb")).find("no such file"), std::string::npos);
  EXPECT_NE(error(vdb + ",density=smoke").find("no grid named 'smoke' (the file has: density vel)"), std::string::npos) << error(vdb + ",density=smoke");
  EXPECT_NE(error(vdb + ",density=vel").find("must be a float grid"), std::string::npos);
  EXPECT_NE(error(vdb + ",color=density").find("must be a vec3 grid"), std::string::npos);
  EXPECT_NE(error(vdb + ",colour=1").find("unknown volume key 'colour'"), std::string::npos);
  EXPECT_NE(error(vdb + ",scale=-1").find("'scale' must be positive"), std::string::npos);
  const std::string text = dir.path("text.vdb");
  test::writeBytes(text, {'n', 'o', 't', ' ', 'v', 'd', 'b'});
  EXPECT_NE(error(text).find("not a readable OpenVDB file"), std::string::npos);
  // NaN densities: a warning, and the voxels count as empty.
  auto nan = filledGrid(box, std::nanf(""), "density");
  const std::string nanPath = writeVdb(dir, "nan.vdb", {nan});
  const VolumeScene scene({VolumeSpec::parse(nanPath, "--volume")}, VolumeOptions{});
  ASSERT_EQ(scene.warnings().size(), 1u);
  EXPECT_NE(scene.warnings()[0].find("non-finite density"), std::string::npos);
}

// For the command-line tests: a store of a wall filling the view at depth 8 (s.0001.mps) and a
// box of fog in front of it; returns the box's file.
std::string wallStoreAndBox(const ScratchDir& dir) {
  test::TestScene scene = test::makeScene(kW, kH, {0.0});
  test::TestMp mp;
  mp.knots = {scene.rect(-8, -8, kW + 8, kH + 8, 8.0)};
  scene.mps.push_back(mp);
  test::writeScene(scene, dir.path("s.0001.mps"));
  return writeVdb(dir, "box.vdb", {filledGrid(boxOf(-4, 4, -3, 3, 3, 5), 1.f, "density")});
}

TEST(Volume, CliAddsAVolumeAndReportsIt) {
  ScratchDir dir;
  const std::string vdb = wallStoreAndBox(dir);
  const auto res = test::runReshutter("resample " + dir.path("s.0001.mps") + " --volume " + vdb + ",density-scale=0.5 --stats -o " + dir.path("out.exr"));
  ASSERT_EQ(res.exitCode, 0) << res.err;
  EXPECT_GT(test::numberBefore(res.out + res.err, " ray segments marched"), 0u);
  const auto bad = test::runReshutter("resample " + dir.path("s.0001.mps") + " --volume " + dir.path("nope.vdb") + " -o " + dir.path("bad.exr"));
  EXPECT_EQ(bad.exitCode, 1);
  EXPECT_NE(bad.err.find("nope.vdb: no such file"), std::string::npos) << bad.err;
  EXPECT_FALSE(std::filesystem::exists(dir.path("bad.exr")));
}

// OpenVDB is a module the program loads when a volume is asked for: a render without volumes
// never loads it (the dynamic loader's own report, LD_DEBUG=files, names every object it loads
// and what needed it). Sanitizer builds link OpenImageIO's texture module at start
// (shade/CMakeLists.txt), and OpenImageIO itself needs OpenVDB: there the only line naming
// libopenvdb must be OpenImageIO's. A missing module is a one-line error saying where it looked.
TEST(Volume, OpenVdbIsLoadedOnlyWhenAVolumeIsAsked) {
  ScratchDir dir;
  const std::string vdb = wallStoreAndBox(dir);
  const std::string bin = RESHUTTER_BINARY;
  const auto plain = test::runCommand("LD_DEBUG=files " + bin + " -q resample " + dir.path("s.0001.mps") + " -o " + dir.path("plain.exr"));
  ASSERT_EQ(plain.exitCode, 0) << plain.err;
  EXPECT_NE(plain.err.find("libOpenEXR"), std::string::npos);  // the loader did report (it names what the program links)
  EXPECT_EQ(plain.err.find("libreshutter_volume"), std::string::npos);
  std::istringstream lines(plain.err);
  for (std::string line; std::getline(lines, line);)
    if (const size_t by = line.find("needed by"); by != std::string::npos && line.find("file=libopenvdb") != std::string::npos) {
      EXPECT_NE(line.find("libOpenImageIO", by), std::string::npos) << line;
    }
  const auto with = test::runCommand("LD_DEBUG=files " + bin + " -q resample " + dir.path("s.0001.mps") + " --volume " + vdb + " -o " + dir.path("with.exr"));
  ASSERT_EQ(with.exitCode, 0) << with.err;
  EXPECT_NE(with.err.find("libreshutter_volume"), std::string::npos);
  EXPECT_NE(with.err.find("libopenvdb"), std::string::npos);
  const auto missing = test::runCommand("RESHUTTER_VOLUME_MODULE=" + dir.path("none.so") + " " + bin + " -q resample " + dir.path("s.0001.mps") +
                                        " --volume " + vdb + " -o " + dir.path("missing.exr"));
  EXPECT_EQ(missing.exitCode, 1);
  EXPECT_NE(missing.err.find(dir.path("none.so") + ": no such file"), std::string::npos) << missing.err;
  EXPECT_FALSE(std::filesystem::exists(dir.path("missing.exr")));
}

}  // namespace
}  // namespace reshutter

namespace reshutter {
namespace {

using namespace resample;

TEST(Volume, TheScenesOwnVolumeRequestIsRecordedAndRenderedMovingWithItsTransform) {
  ScratchDir dir;
  // The slab of the first test, in the RIB's object space, moving +0.5 in x over the shutter.
  const Box box = boxOf(-1, 1, -3, 3, 3, 5);
  writeVdb(dir, "slab.vdb", {filledGrid(box, 0.8f, "density")});
  std::ofstream(dir.path("scene.rib")) << "Format " << kW << " " << kH << " 1\n"
                                       << "Projection \"perspective\" \"fov\" [50]\nShutter 0 1\nWorldBegin\n"
                                          "Surface \"constant\"\nColor [1 1 1]\nPolygon \"P\" [-20 -20 8  20 -20 8  20 20 8  -20 20 8]\n"
                                          "AttributeBegin\nMotionBegin [0 1]\nTranslate 0 0 0\nTranslate 0.5 0 0\nMotionEnd\n"
                                          "Volume \"blobbydso:impl_openvdb\" [-1 1 -3 3 3 5] [0 0 0] \"constant string[2] blobbydso:stringargs\" "
                                          "[\"slab.vdb\" \"density\"]\nAttributeEnd\nWorldEnd\n";
  const auto shade = test::runReshutter("shade " + dir.path("scene.rib") + " -o " + dir.path("s.mps"));
  ASSERT_EQ(shade.exitCode, 0) << shade.err;
  auto store = std::make_shared<const store::StoreReader>(dir.path("s.mps"));
  ASSERT_EQ(store->meta().volumes.size(), 1u);
  const store::StoredVolume& sv = store->meta().volumes[0];
  EXPECT_EQ(sv.path, std::filesystem::absolute(dir.path("slab.vdb")).lexically_normal().string());
  ASSERT_EQ(sv.times.size(), 2u);
  test::TestScene scene;
  scene.meta = store->meta();
  RenderSpec spec = test::specFor(store, 0, 1, 4, 4, 3);
  const RenderResult r = render(spec);
  EXPECT_GT(r.stats.volumes.rays, 0u);
  double worst = 0, sum = 0;
  int partial = 0;
  for (int py = 0; py < kH; ++py)
    for (int px = 0; px < kW; ++px) {
      const double expect = pixelMean(scene, spec, px, py, [&](const glm::dvec3& d, double t) {
        const glm::dvec3 shift(0.5 * (t - double(scene.meta.frame)), 0, 0);
        return std::exp(-0.8 * chordInBox(d, box.lo() + shift, box.hi() + shift, 0, 8));
      });
      const double v = test::channel(r, "R").f[size_t(py) * kW + px];
      worst = std::max(worst, std::abs(v - expect)), sum += std::abs(v - expect);
      partial += expect > 0.2 && expect < 0.9;
    }
  EXPECT_GT(partial, kH);  // the slab's edges blur
  EXPECT_LT(worst, 0.04);  // slanted interpolated side faces, as for the velocity grid
  EXPECT_LT(sum / (kW * kH), 2e-3);
  // Left out on request, and a missing file is an error naming it.
  spec.sceneVolumes = false;
  EXPECT_EQ(render(spec).stats.volumes.rays, 0u);
  std::filesystem::remove(dir.path("slab.vdb"));
  const auto missing = test::runReshutter("resample " + dir.path("s.mps") + " -o " + dir.path("x.exr"));
  EXPECT_EQ(missing.exitCode, 1);
  EXPECT_NE(missing.err.find("slab.vdb: no such file"), std::string::npos) << missing.err;
}

}  // namespace
}  // namespace reshutter
