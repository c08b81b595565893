// Other cameras from one shading pass (resample/camera_view.h): a camera moved by a baseline shifts
// a fronto-parallel quad by exactly f·b/z pixels, a converged stereo pair leaves its convergence
// depth in place, any camera agrees sample by sample with a ray caster looking at the scene from
// there, a look-at placed where the shading camera stands reproduces it, the multi-view OpenEXR
// holds each view bit for bit, and a RIB scene shaded once for two cameras renders the other as
// shading from it would.
#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <functional>

#include <OpenEXR/ImfCheckFile.h>
#include <glm/gtc/matrix_transform.hpp>
#include <gtest/gtest.h>

#include "resample/camera_view.h"
#include "store/reader.h"
#include "tests/exr_test_util.h"
#include "tests/resample_test_util.h"
#include "tests/test_util.h"

using namespace reshutter;
using namespace reshutter::resample;
using namespace reshutter::test;

namespace {

// `c` moved by `offset` along its own axes (camera-space units).
store::Camera moved(const store::Camera& c, const glm::dvec3& offset, const char* name) {
  store::Camera m = c;
  m.name = name;
  m.worldToCamera = glm::translate(glm::dmat4(1.0), -offset) * c.worldToCamera;
  return m;
}

// The scene as `view` sees it: every corner carried into its space, `view` its camera - what
// shading from `view` directly would have stored.
TestScene seenFrom(const TestScene& s, const store::Camera& view) {
  TestScene out = s;
  const glm::dmat4 m = primaryToView(s.meta.cameras[0], view);
  for (TestMp& mp : out.mps)
    for (auto& knot : mp.knots)
      for (glm::dvec3& p : knot) p = glm::dvec3(m * glm::dvec4(p, 1.0));
  out.meta.cameras[0] = view;
  return out;
}

// The scene as a camera that moves against the primary (either of them moving) sees it: at the
// scene's knots and both cameras' motion times, each corner where it is in the primary's space at
// that time (linear between the scene's knots) carried by the transform between them at that time.
TestScene seenFromMoving(const TestScene& s, const store::Camera& view) {
  const store::Camera& primary = s.meta.cameras[0];
  std::vector<double> times = s.knotTimes;
  for (const store::Camera* c : {&primary, &view}) times.insert(times.end(), c->motionTimes.begin(), c->motionTimes.end());
  std::sort(times.begin(), times.end());
  times.erase(std::unique(times.begin(), times.end()), times.end());
  TestScene out = s;
  out.knotTimes = times;
  for (size_t m = 0; m < s.mps.size(); ++m) {
    const auto& knots = s.mps[m].knots;
    auto& carried = out.mps[m].knots;
    carried.clear();
    for (double t : times) {
      size_t k = 0;
      while (k + 2 < s.knotTimes.size() && s.knotTimes[k + 1] <= t) ++k;
      const double w = knots.size() < 2 ? 0.0 : std::clamp((t - s.knotTimes[k]) / (s.knotTimes[k + 1] - s.knotTimes[k]), 0.0, 1.0);
      const glm::dmat4 toView = store::primaryToView(primary, view, t);
      std::array<glm::dvec3, 4> q;
      for (int c = 0; c < 4; ++c) {
        const glm::dvec3 p = knots.size() < 2 ? knots[0][size_t(c)] : knots[k][size_t(c)] + w * (knots[k + 1][size_t(c)] - knots[k][size_t(c)]);
        q[size_t(c)] = glm::dvec3(toView * glm::dvec4(p, 1.0));
      }
      carried.push_back(q);
    }
  }
  out.meta.cameras[0] = view;
  return out;
}

struct ShutterCase {
  const char* what;
  ShutterModel shutter;
};

// Renders `reader` from `view` over each of `cases` and through a lens, each against the ray
// caster looking at `seen` (the scene as `view` sees it).
void expectRayCasterAgreesOnEveryPath(std::shared_ptr<const store::StoreReader> reader, const store::Camera& view, const TestScene& seen,
                                      const std::vector<ShutterCase>& cases) {
  for (const ShutterCase& c : cases) {
    RenderSpec spec = specFor(reader, 0, 1, 4, 4, 3);
    spec.shutter = c.shutter;
    spec.camera = view;
    const RenderResult r = render(spec);
    EXPECT_GT(r.stats.partsCarried, 0u) << c.what;
    EXPECT_GT(r.stats.raster.hits, 1000u) << c.what << ": the view sees too little to test";
    expectRayCasterAgrees(seen, spec, r, 40, 28, c.what);
  }
  RenderSpec spec = specFor(reader, 0, 1, 4, 4, 5);
  spec.camera = view;
  spec.lens.fstop = 4, spec.lens.focalLength = 1, spec.lens.focalDistance = 9;
  const RenderResult r = render(spec);
  EXPECT_GT(r.stats.raster.lensMicropolygons, 0u);
  expectRayCasterAgrees(seen, spec, r, 40, 28, "through a lens");
}

// `c` moving: at each of `times` where `at(time)` puts it.
store::Camera movingCamera(store::Camera c, const std::vector<double>& times, const std::function<glm::dmat4(double)>& at, const char* name) {
  c.name = name;
  c.motionTimes = times;
  c.motionWorldToCamera.clear();
  for (double t : times) c.motionWorldToCamera.push_back(at(t));
  c.worldToCamera = c.motionWorldToCamera[0];
  return c;
}

// A red quad at depth 4 over raster [40, 100) × [20, 60) in front of a blue one at depth 16 over
// [8, 152) × [8, 72), on a 160 × 80 frame: every edge on a pixel boundary.
TestScene parallaxScene() {
  TestScene s = makeScene(160, 80, {0.0});
  TestMp front, back;
  front.knots = {s.rect(40, 20, 100, 60, 4)};
  front.ci = {1, 0, 0};
  back.knots = {s.rect(8, 8, 152, 72, 16)};
  back.ci = {0, 0, 1};
  s.mps = {front, back};
  return s;
}

// Expects the render to show the red quad over x in [f0, f1) and the blue one over [b0, b1)
// (rows as in parallaxScene): with every edge on a pixel boundary each pixel is exactly covered
// or not, whatever its samples - bar a sample within float rounding of an edge.
void expectQuadsAt(const RenderResult& r, int f0, int f1, int b0, int b1, const std::string& what) {
  const auto &R = channel(r, "R").f, &B = channel(r, "B").f, &A = channel(r, "A").f;
  int off = 0;
  for (int y = 0; y < r.image.height; ++y)
    for (int x = 0; x < r.image.width; ++x) {
      const bool red = x >= f0 && x < f1 && y >= 20 && y < 60;
      const bool blue = !red && x >= b0 && x < b1 && y >= 8 && y < 72;
      const size_t i = size_t(y) * size_t(r.image.width) + size_t(x);
      const double err = std::max({std::abs(R[i] - (red ? 1.0 : 0.0)), std::abs(B[i] - (blue ? 1.0 : 0.0)), std::abs(A[i] - (red || blue ? 1.0 : 0.0))});
      if (err > 1e-6) {
        ++off;
        EXPECT_LE(err, 1.0 / 16 + 1e-6) << what << ": pixel " << x << "," << y;
      }
    }
  EXPECT_LE(off, 2) << what << ": pixels off the analytic image";
}

}  // namespace

TEST(CameraParallax, ABaselineShiftsEachDepthByFocalLengthTimesBaselineOverDepth) {
  ScratchDir dir;
  const TestScene s = parallaxScene();
  auto reader = writeScene(s, dir.path("p.mps"));
  const double ax = store::Projector(s.meta.cameras[0]).ax;
  // The camera moved right by b: x_raster moves by -ax·b/z, 8 px at depth 4 and 2 px at depth 16.
  const double b = 8.0 * 4.0 / ax;
  RenderSpec spec = specFor(reader, 0, 1, 4, 4);
  const RenderResult still = render(spec);
  expectQuadsAt(still, 40, 100, 8, 152, "the shading camera");
  EXPECT_EQ(still.stats.partsCarried, 0u);
  spec.camera = moved(s.meta.cameras[0], {b, 0, 0}, "right");
  const RenderResult right = render(spec);
  expectQuadsAt(right, 32, 92, 6, 150, "moved by the baseline");
  EXPECT_GT(right.stats.partsCarried, 0u) << "the carried path was not taken";
  // The header records the camera rendered from.
  EXPECT_EQ(right.provenance.worldToCamera, spec.camera->worldToCamera);

  // A stereo pair 2b apart converged at depth 4: the red quad stays put in both eyes, the blue one
  // moves by ±ax·b·(1/4 - 1/16) = ±6 px.
  const std::vector<store::Camera> eyes = stereoPair(s.meta.cameras[0], 2 * b, 4.0);
  ASSERT_EQ(eyes.size(), 2u);
  EXPECT_EQ(eyes[0].name, "left");
  EXPECT_EQ(eyes[1].name, "right");
  spec.camera = eyes[0];
  expectQuadsAt(render(spec), 40, 100, 2, 146, "left eye");
  spec.camera = eyes[1];
  expectQuadsAt(render(spec), 40, 100, 14, 158, "right eye");
  // Parallel eyes (no convergence): each depth by its own parallax.
  spec.camera = stereoPair(s.meta.cameras[0], 2 * b, INFINITY)[0];
  expectQuadsAt(render(spec), 48, 108, 10, 154, "parallel left eye");
}

TEST(CameraReference, AnyCameraAgreesWithTheRayCasterLookingFromThere) {
  // Moving, transparent, matte quads rendered from a camera turned, moved and widened: against
  // the ray caster looking at the scene carried into that camera - full shutter, an instant, a
  // sub-interval, interlaced fields, and through a lens.
  ScratchDir dir;
  const TestScene s = randomQuadScene(11, true);
  auto reader = writeScene(s, dir.path("r.mps"));
  const store::Camera view = lookAtCamera(s.meta.cameras[0], {0.6, -0.3, -0.4}, {-0.5, 0.4, 14.0}, {0.15, 1, 0}, 56.0);
  expectRayCasterAgreesOnEveryPath(reader, view, seenFrom(s, view),
                                   {{"full shutter", ShutterModel::progressive(1.0, 2.0)},
                                    {"instant", ShutterModel::progressive(1.35, 1.35)},
                                    {"sub-interval", ShutterModel::progressive(1.2, 1.45)},
                                    {"fields", ShutterModel::fields({1.0, 1.25}, {1.5, 1.75}, 0)}});
}

TEST(CameraLookAt, PlacedWhereTheShadingCameraStandsItRendersItsImage) {
  // The shading camera's world mirrors z (RIB's Scale 1 1 -1) and is turned and moved: a look-at
  // from its eye along its axis keeps that handedness, so the image is the camera's, not a mirror.
  ScratchDir dir;
  TestScene s = randomQuadScene(5, false);
  glm::dmat4 w = glm::scale(glm::dmat4(1.0), glm::dvec3(1, 1, -1));
  w = glm::rotate(w, 0.7, glm::normalize(glm::dvec3(0.2, 1, 0.1)));
  w = glm::translate(w, glm::dvec3(3, -1, 2));
  s.meta.cameras[0].worldToCamera = w;
  auto reader = writeScene(s, dir.path("l.mps"));
  const glm::dmat4 toWorld = glm::inverse(w);
  const glm::dvec3 from(toWorld * glm::dvec4(0, 0, 0, 1)), to(toWorld * glm::dvec4(0, 0, 1, 1)), up(toWorld * glm::dvec4(0, 1, 0, 0));
  const store::Camera view = lookAtCamera(s.meta.cameras[0], from, to, up, std::nullopt);
  for (int c = 0; c < 4; ++c)
    for (int r = 0; r < 4; ++r) EXPECT_NEAR(view.worldToCamera[c][r], w[c][r], 1e-12) << c << "," << r;
  RenderSpec spec = specFor(reader, 0, 1, 4, 4);
  spec.camera = view;
  const RenderResult r = render(spec);
  expectRayCasterAgrees(s, spec, r, 40, 28, "look-at from the shading camera's eye");

  // The shading camera itself, at another resolution too, takes the store's own bounds: the same
  // image bit for bit, nothing carried.
  spec.camera.reset();
  const RenderResult plain = render(spec);
  spec.camera = s.meta.cameras[0];
  const RenderResult same = render(spec);
  EXPECT_EQ(same.stats.partsCarried, 0u);
  EXPECT_EQ(channel(same, "R").f, channel(plain, "R").f);
  EXPECT_EQ(channel(same, "A").f, channel(plain, "A").f);

  // Degenerate requests are errors naming the option.
  EXPECT_THROW(lookAtCamera(s.meta.cameras[0], from, from, up, std::nullopt), Error);
  EXPECT_THROW(lookAtCamera(s.meta.cameras[0], from, to, to - from, std::nullopt), Error);
  EXPECT_THROW(stereoPair(s.meta.cameras[0], -1, INFINITY), Error);
}

TEST(CameraMultiView, TheStereoFileHoldsEachViewBitForBit) {
  ScratchDir dir;
  const TestScene s = parallaxScene();
  auto reader = writeScene(s, dir.path("s.mps"));
  const std::string exr = dir.path("stereo.exr"), deep = dir.path("stereo_deep.exr");
  const CommandResult run = runReshutter("resample " + dir.path("s.mps") + " -o " + exr + " --deep " + deep +
                                         " --stereo 0.5:6 --spp 16 --filter box:1x1 --compression zip --preview " + dir.path("stereo.png") + " --stats");
  ASSERT_EQ(run.exitCode, 0) << run.err;
  EXPECT_NE(run.out.find("carried into the view's camera"), std::string::npos) << run.out;
  EXPECT_FALSE(Imf::checkOpenEXRFile(exr.c_str(), false, false, true)) << "checkOpenEXRFile reports a problem";
  EXPECT_FALSE(Imf::checkOpenEXRFile(deep.c_str(), false, false, true)) << "checkOpenEXRFile reports a problem with the deep file";
  EXPECT_TRUE(std::filesystem::exists(dir.path("stereo_left.png")));
  EXPECT_TRUE(std::filesystem::exists(dir.path("stereo_right.png")));
  // OpenImageIO reads the views (an independent reader of the multiView convention).
  const CommandResult info = runImageTool("iinfo -v " + exr);
  EXPECT_EQ(info.exitCode, 0) << info.err;
  EXPECT_NE(info.out.find("multiView"), std::string::npos) << info.out;
  EXPECT_NE(info.out.find("\"left\", \"right\""), std::string::npos) << info.out;

  const resample::FlatImage file = readFlatExr(exr);
  const std::vector<store::Camera> eyes = stereoPair(s.meta.cameras[0], 0.5, 6);
  for (size_t v = 0; v < eyes.size(); ++v) {
    RenderSpec spec = specFor(reader, 0, 1, 4, 4);
    spec.camera = eyes[v];
    spec.deep = true;
    const RenderResult one = render(spec);
    for (const char* c : {"R", "G", "B", "A", "Z"}) {
      const std::string name = v == 0 ? c : viewChannelName(c, eyes[v].name);
      const resample::ImageChannel* ch = file.find(name);
      ASSERT_NE(ch, nullptr) << name;
      EXPECT_EQ(ch->f, channel(one, c).f) << name << " differs from the single-camera render";
    }
    // The deep file: a part per view, named by its view attribute, each the view's deep image.
    std::string view;
    const DeepExr part = readDeepExrPart(deep, int(v), view);
    EXPECT_EQ(view, eyes[v].name);
    const resample::DeepImage& a = part.image;
    const resample::DeepImage& b = one.deep;
    ASSERT_EQ(a.width, b.width);
    uint64_t samples = 0;
    for (int y = b.y0; y < b.y0 + b.height; ++y)
      for (int x = b.x0; x < b.x0 + b.width; ++x) {
        const auto &ra = a.ref(x, y), &rb = b.ref(x, y);
        ASSERT_EQ(ra.count, rb.count) << "view " << view << " pixel " << x << "," << y;
        samples += rb.count;
        for (uint32_t k = 0; k < rb.count; ++k)
          for (int f : {kDeepR, kDeepG, kDeepB, kDeepA, kDeepZ})
            EXPECT_EQ(a.block(ra.block).f[size_t(ra.first + k) * size_t(a.layout.nf()) + size_t(f)],
                      b.block(rb.block).f[size_t(rb.first + k) * size_t(b.layout.nf()) + size_t(f)]);
      }
    EXPECT_GT(samples, 0u);
  }
  EXPECT_EQ(viewChannelName("N.X", "right"), "N.right.X");

  // Unknown cameras: one line naming the cameras the store has, no image.
  const CommandResult bad = runReshutter("resample " + dir.path("s.mps") + " -o " + dir.path("x.exr") + " --camera nosuch");
  EXPECT_NE(bad.exitCode, 0);
  EXPECT_NE(bad.err.find("'nosuch'"), std::string::npos) << bad.err;
  EXPECT_NE(bad.err.find("world"), std::string::npos) << bad.err;
  EXPECT_FALSE(std::filesystem::exists(dir.path("x.exr")));
}

namespace {

// An orange sphere ahead of the eye and a green one 5.5 to its side, past a 40° frame's edge.
const char* const kTwoSpheres =
    "WorldBegin\nSurface \"constant\"\nColor [1 0.5 0.2]\nTranslate 0 0 6\nSphere 1 -1 1 360\n"
    "AttributeBegin\nColor [0 1 0]\nTranslate 5.5 0 0\nSphere 0.6 -0.6 0.6 360\nAttributeEnd\nWorldEnd\n";

// Store `mps` in `dir` re-sampled at 16 spp with `extra` options into `exr` there, read back.
resample::FlatImage resampled(const ScratchDir& dir, const std::string& mps, const std::string& exr, const std::string& extra) {
  const CommandResult r = runReshutter("resample " + dir.path(mps) + " -o " + dir.path(exr) + " --spp 16 " + extra);
  EXPECT_EQ(r.exitCode, 0) << r.err;
  return readFlatExr(dir.path(exr));
}

double rmseRgba(const resample::FlatImage& a, const resample::FlatImage& b) {
  double sum = 0;
  size_t n = 0;
  for (const char* c : {"R", "G", "B", "A"}) {
    const auto &x = a.find(c)->f, &y = b.find(c)->f;
    EXPECT_EQ(x.size(), y.size());
    for (size_t i = 0; i < std::min(x.size(), y.size()); ++i) sum += (x[i] - y[i]) * (x[i] - y[i]), ++n;
  }
  return std::sqrt(sum / double(std::max<size_t>(n, 1)));
}

double channelMax(const resample::FlatImage& im, const char* c) {
  const auto& v = im.find(c)->f;
  return v.empty() ? 0.0 : double(*std::max_element(v.begin(), v.end()));
}

}  // namespace

TEST(CameraRib, ShadedOnceForTwoCamerasRightRendersAsShadingFromIt) {
  // A sphere both cameras see and a green one only the turned camera "right" sees (the primary's
  // frame and overscan end well before it). Shaded once for both, rendered from "right": the
  // image of the same scene shaded with "right" as its camera, within the noise of two seeds.
  ScratchDir dir;
  const std::string world = kTwoSpheres;
  const std::string head = "Format 96 64 1\nProjection \"perspective\" \"fov\" 40\n";
  const std::string turn = "Rotate -30 0 1 0\n";
  std::ofstream(dir.path("both.rib")) << head << turn << "Camera \"right\"\nIdentity\n" << world;
  std::ofstream(dir.path("right.rib")) << head << turn << world;
  const CommandResult both = runReshutter("shade " + dir.path("both.rib") + " -o " + dir.path("both.mps"));
  ASSERT_EQ(both.exitCode, 0) << both.err;
  EXPECT_NE(both.out.find("geometry detail expansion"), std::string::npos) << both.out;
  ASSERT_EQ(runReshutter("shade " + dir.path("right.rib") + " -o " + dir.path("right.mps")).exitCode, 0);
  const CommandResult info = runReshutter("info " + dir.path("both.mps"));
  EXPECT_NE(info.out.find("right"), std::string::npos) << info.out;

  auto renderTo = [&](const std::string& mps, const std::string& exr, const std::string& extra) { return resampled(dir, mps, exr, extra); };
  const resample::FlatImage primary = renderTo("both.mps", "primary.exr", "");
  const resample::FlatImage fromStore = renderTo("both.mps", "from_store.exr", "--camera right");
  const resample::FlatImage direct = renderTo("right.mps", "direct.exr", "");
  const resample::FlatImage directSeed = renderTo("right.mps", "direct_seed.exr", "--seed 7");
  // The set-up holds: only "right" sees the green sphere.
  EXPECT_EQ(channelMax(primary, "G") > 0.6, false) << "the primary camera sees the green sphere: the test is vacuous";
  EXPECT_GT(channelMax(direct, "G"), 0.9);
  EXPECT_GT(channelMax(fromStore, "G"), 0.9) << "what only camera right sees was culled at shading";
  const double noise = rmseRgba(direct, directSeed), err = rmseRgba(fromStore, direct);
  EXPECT_GT(noise, 0.0);
  EXPECT_LT(err, 2.0 * noise + 1e-3) << "shaded once for two cameras vs shaded from right: RMSE " << err << ", two seeds " << noise;

  // The same camera read from a RIB snippet: the same image, bit for bit.
  std::ofstream(dir.path("right_cam.rib")) << head << turn;
  const resample::FlatImage fromSnippet = renderTo("both.mps", "snippet.exr", "--camera-rib " + dir.path("right_cam.rib"));
  EXPECT_EQ(fromSnippet.find("R")->f, fromStore.find("R")->f);
  EXPECT_EQ(fromSnippet.find("A")->f, fromStore.find("A")->f);
  // ... and added to a scene that has no Camera request: the same store, the same image.
  std::ofstream(dir.path("plain.rib")) << head << world;
  const CommandResult added = runReshutter("shade " + dir.path("plain.rib") + " --add-camera " + dir.path("right_cam.rib") + " -o " + dir.path("added.mps"));
  ASSERT_EQ(added.exitCode, 0) << added.err;
  EXPECT_EQ(renderTo("added.mps", "added.exr", "--camera right_cam").find("R")->f, fromStore.find("R")->f);
  const CommandResult missing = runReshutter("resample " + dir.path("both.mps") + " -o " + dir.path("y.exr") + " --camera-rib " + dir.path("none.rib"));
  EXPECT_NE(missing.exitCode, 0);
  EXPECT_NE(missing.err.find("none.rib"), std::string::npos) << missing.err;
  EXPECT_FALSE(std::filesystem::exists(dir.path("y.exr")));

  // What no shading camera looked at is reported: nothing for a recorded camera; for one at the
  // primary's eye looking back, away from the scene, every sample.
  const CommandResult recorded = runReshutter("resample " + dir.path("both.mps") + " -o " + dir.path("x.exr") + " --camera right --stats");
  EXPECT_EQ(recorded.out.find("unseen"), std::string::npos) << "a recorded camera's samples were judged: " << recorded.out;
  const CommandResult away = runReshutter("resample " + dir.path("both.mps") + " -o " + dir.path("x.exr") + " --look-from 0,0,0 --look-at 0,0,-1 --stats");
  ASSERT_EQ(away.exitCode, 0) << away.err;
  EXPECT_EQ(numberBefore(away.out, " samples ("), uint64_t(96 * 64 * 16)) << away.out;
  // A camera beside the primary looking the same way: the strip beyond the primary's frame.
  const CommandResult beside = runReshutter("resample " + dir.path("both.mps") + " -o " + dir.path("x.exr") + " --look-from -1,0,0 --look-at -1,0,1 --stats");
  ASSERT_EQ(beside.exitCode, 0) << beside.err;
  const uint64_t strip = numberBefore(beside.out, " samples (");
  EXPECT_GT(strip, 0u) << beside.out;
  EXPECT_LT(double(strip), 0.5 * double(96 * 64 * 16)) << beside.out;
}

TEST(CameraBounds, CarriedBoundsHoldEveryCarriedVertex) {
  // The bounds a render from another camera culls by (store/view_bounds.h): at every knot each
  // carried vertex lies in its part's carried camera box and, in front of the near plane, projects
  // into its carried raster bound - for cameras moved, turned, widened and looking back at the scene.
  ScratchDir dir;
  TestScene s = randomQuadScene(23, true);
  s.meta.tileSize = 8;  // many parts, each of several depths
  auto reader = writeScene(s, dir.path("b.mps"));
  const store::Camera& primary = s.meta.cameras[0];
  const std::vector<store::Camera> views = {
      moved(primary, {0.3, 0, 0}, "moved"), lookAtCamera(primary, {2, 1, -3}, {0, 0, 15}, {0, 1, 0}, 70.0),
      lookAtCamera(primary, {-1, 0.5, 40}, {0, 0, 10}, {0, 1, 0}, 60.0),  // behind the scene, looking back
      lookAtCamera(primary, {0, 0, 12}, {5, 0, 12}, {0, 1, 0}, 90.0)};   // inside it, looking sideways
  uint64_t checked = 0;
  for (const store::Camera& v : views) {
    const store::Projector proj(v);
    const glm::dmat4 m = primaryToView(primary, v);
    const std::vector<store::TileEntry> carried = store::carriedEntries(reader->entries(), m, store::Projector(primary), proj);
    for (size_t e = 0; e < carried.size(); ++e) {
      const store::TilePart part = store::carriedPart(reader->decode(e), m, reader->meta().schema);
      for (uint32_t k = 0; k < part.numKnots; ++k) {
        const store::KnotBounds& kb = carried[e].knots[k];
        for (uint32_t i = 0; i < part.numVertices; ++i) {
          const glm::vec3 p = part.position(k, i);
          for (int a = 0; a < 3; ++a) {
            EXPECT_GE(p[a], kb.camera[a]) << v.name << " part " << e << " knot " << k;
            EXPECT_LE(p[a], kb.camera[a + 3]) << v.name << " part " << e << " knot " << k;
          }
          if (!kb.rasterFinite) continue;
          ASSERT_GE(double(p.z), proj.nearClip) << "a finite raster bound with a vertex before the near plane";
          const glm::dvec2 r = proj.project(glm::dvec3(p));
          EXPECT_TRUE(r.x >= kb.raster[0] && r.x <= kb.raster[2] && r.y >= kb.raster[1] && r.y <= kb.raster[3])
              << v.name << " part " << e << " knot " << k << ": " << r.x << "," << r.y << " outside [" << kb.raster[0] << ", " << kb.raster[2] << "] x ["
              << kb.raster[1] << ", " << kb.raster[3] << "]";
          ++checked;
        }
      }
    }
  }
  EXPECT_GT(checked, 1000u);

  // Cameras that move against the primary: every carried knot - the parts' own and the motion's
  // between them - holds its carried vertices, the still parts' included.
  const store::Camera swing = movingCamera(primary, {0.0, 0.25, 0.7, 1.0}, [&](double t) {
    return lookAtCamera(primary, {3 * std::sin(2 * t), 1 - t, -3 + 2 * t}, {0, 0, 15}, {0, 1, 0}, 70.0).worldToCamera;
  }, "swing");
  const store::Projector proj(swing);
  std::vector<store::CarriedSchedule> schedules;
  for (size_t k = 0; k < reader->meta().schedules.size(); ++k)
    schedules.push_back(store::carriedSchedule(reader->meta().schedules[k], k == 0, carryTimes(primary, swing, 0, 1),
                                               [&](double t) { return store::primaryToView(primary, swing, t); }));
  const std::vector<store::TileEntry> carried = store::carriedEntries(reader->entries(), schedules, store::Projector(primary), proj);
  uint64_t movingChecked = 0, stillParts = 0;
  for (size_t e = 0; e < carried.size(); ++e) {
    const store::TilePart part = store::carriedPart(reader->decode(e), schedules[reader->entries()[e].schedule], reader->meta().schema);
    ASSERT_EQ(part.numKnots, carried[e].knots.size());
    if (reader->entries()[e].schedule == 0) ++stillParts;
    for (uint32_t k = 0; k < part.numKnots; ++k) {
      const store::KnotBounds& kb = carried[e].knots[k];
      for (uint32_t i = 0; i < part.numVertices; ++i) {
        const glm::vec3 p = part.position(k, i);
        for (int a = 0; a < 3; ++a) EXPECT_TRUE(p[a] >= kb.camera[a] && p[a] <= kb.camera[a + 3]) << "part " << e << " knot " << k;
        if (!kb.rasterFinite) continue;
        const glm::dvec2 r = proj.project(glm::dvec3(p));
        EXPECT_TRUE(r.x >= kb.raster[0] && r.x <= kb.raster[2] && r.y >= kb.raster[1] && r.y <= kb.raster[3]) << "part " << e << " knot " << k;
        ++movingChecked;
      }
    }
  }
  EXPECT_GT(movingChecked, 500u);
  EXPECT_GT(stillParts, 0u) << "no still part was carried into the moving camera";
}

TEST(CameraMoving, ATruckingCameraSweepsEachDepthByItsOwnParallax) {
  // Static quads seen by a camera that trucks right by b over the shutter: in its raster the red
  // quad (depth 4) slides left by ax·b/4 = 8 px and the blue one (depth 16) by 2 px, linearly in
  // time. Each pixel's coverage is the time average of its overlap with the sliding quads.
  ScratchDir dir;
  TestScene s = parallaxScene();
  s.meta.shutterOpen = 0, s.meta.shutterClose = 1;
  auto reader = writeScene(s, dir.path("p.mps"));
  const store::Camera& primary = s.meta.cameras[0];
  const double ax = store::Projector(primary).ax, b = 8.0 * 4.0 / ax;
  const store::Camera truck = movingCamera(primary, {0.0, 1.0}, [&](double t) { return glm::translate(glm::dmat4(1.0), glm::dvec3(-b * t, 0, 0)) * primary.worldToCamera; }, "truck");
  RenderSpec spec = specFor(reader, 0, 1, 16, 16);
  spec.camera = truck;
  const RenderResult r = render(spec);
  EXPECT_GT(r.stats.partsCarried, 0u);
  EXPECT_GT(r.stats.raster.linearMicropolygons, 0u) << "the parts did not move in the view";
  EXPECT_EQ(r.stats.raster.staticMicropolygons, 0u) << "a part stood still in the moving view";
  // Exact coverage, integrated over time in 4096 steps (the overlap is piecewise linear in t).
  auto expectSwept = [](const resample::PixelVector<float>& R, const resample::PixelVector<float>& B, const std::string& what) {
    auto overlap = [](double a0, double a1, double b0, double b1) { return std::max(0.0, std::min(a1, b1) - std::max(a0, b0)); };
    double worst = 0, redCentroid = 0, redArea = 0;
    for (int x = 0; x < 160; ++x) {
      double red = 0, blue = 0;
      for (int i = 0; i < 4096; ++i) {
        const double t = (i + 0.5) / 4096;
        const double r0 = 40 - 8 * t, r1 = 100 - 8 * t, b0 = 8 - 2 * t, b1 = 152 - 2 * t;
        red += overlap(x, x + 1, r0, r1) / 4096, blue += (overlap(x, x + 1, b0, b1) - overlap(x, x + 1, std::max(r0, b0), std::min(r1, b1))) / 4096;
      }
      for (int y = 20; y < 60; ++y) {  // the rows through both quads
        const size_t i = size_t(y) * 160 + size_t(x);
        worst = std::max({worst, std::abs(R[i] - red), std::abs(B[i] - blue)});
        redCentroid += R[i] * (x + 0.5), redArea += R[i];
      }
    }
    EXPECT_LT(worst, 0.08) << what << ": a pixel's coverage is off the swept area";
    EXPECT_NEAR(redArea / 40, 60.0, 0.02) << what << ": the red quad's area";
    EXPECT_NEAR(redCentroid / redArea, 70.0 - 4.0, 0.01) << what << ": the red quad's mean position over the shutter: its centre 70 less half its 8 px sweep";
  };
  expectSwept(channel(r, "R").f, channel(r, "B").f, "the trucking camera");
  // The same camera on the command line: a look-at whose eye and target move over the shutter.
  const std::string exr = dir.path("truck.exr");
  const CommandResult cli = runReshutter("resample " + dir.path("p.mps") + " -o " + exr + " --spp 256 --filter box:1x1 --look-from 0,0,0," + std::to_string(b) +
                                         ",0,0 --look-at 0,0,1," + std::to_string(b) + ",0,1");
  ASSERT_EQ(cli.exitCode, 0) << cli.err;
  const resample::FlatImage fromCli = readFlatExr(exr);
  expectSwept(fromCli.find("R")->f, fromCli.find("B")->f, "--look-from and --look-at moving");
  // At the shutter's close the trucked camera stands where a camera moved by b does: the same image.
  spec.shutter = ShutterModel::progressive(2.0, 2.0);
  expectQuadsAt(render(spec), 32, 92, 6, 150, "the trucking camera at the close");
  spec.shutter = ShutterModel::progressive(1.0, 1.0);
  expectQuadsAt(render(spec), 40, 100, 8, 152, "the trucking camera at the open");
}

TEST(CameraMoving, MovingCamerasAgreeWithTheRayCasterLookingFromThere) {
  // A camera that pans and dollies over the shutter (three motion times, one between the scene's
  // knots), and a store whose own camera moves: against the ray caster looking at the scene as the
  // moving camera sees it at each knot and motion time - full shutter, a sub-interval, fields, a lens.
  ScratchDir dir;
  const TestScene s = randomQuadScene(31, true);
  auto reader = writeScene(s, dir.path("m.mps"));
  const store::Camera& primary = s.meta.cameras[0];
  const store::Camera pan = movingCamera(primary, {0.0, 0.7, 1.0}, [&](double t) {
    return lookAtCamera(primary, {0.5 * t, -0.2, -0.5 + 0.8 * t}, {-0.6 + 1.2 * t, 0.3, 14.0}, {0.1, 1, 0}, 56.0).worldToCamera;
  }, "pan");
  const TestScene seen = seenFromMoving(s, pan);
  ASSERT_EQ(seen.knotTimes, (std::vector<double>{0.0, 0.4, 0.7, 1.0}));
  expectRayCasterAgreesOnEveryPath(reader, pan, seen,
                                   {{"full shutter", ShutterModel::progressive(1.0, 2.0)},
                                    {"instant", ShutterModel::progressive(1.55, 1.55)},
                                    {"sub-interval", ShutterModel::progressive(1.55, 1.85)},
                                    {"fields", ShutterModel::fields({1.0, 1.25}, {1.5, 1.75}, 0)}});

  // The store's own camera moves (format 5 keeps its motion); the view stands still.
  TestScene m = s;
  m.meta.cameras[0] = movingCamera(primary, {0.0, 1.0}, [&](double t) { return glm::rotate(glm::dmat4(1.0), -0.2 * t, glm::dvec3(0, 1, 0)); }, "world");
  auto movingReader = writeScene(m, dir.path("moving_primary.mps"));
  EXPECT_TRUE(movingReader->meta().cameras[0] == m.meta.cameras[0]) << "the store lost its camera's motion";
  const store::Camera still = lookAtCamera(primary, {0.3, 0, 0}, {0.3, 0, 1}, {0, 1, 0}, std::nullopt);
  RenderSpec spec = specFor(movingReader, 0, 1, 4, 4, 3);
  spec.camera = still;
  const RenderResult r = render(spec);
  EXPECT_GT(r.stats.partsCarried, 0u);
  expectRayCasterAgrees(seenFromMoving(m, still), spec, r, 40, 28, "a still camera, the store's moving");

  // A stereo pair of a moving camera moves with it: the store's own camera's rig carries nothing in time.
  const std::vector<store::Camera> eyes = stereoPair(m.meta.cameras[0], 0.2, INFINITY);
  EXPECT_TRUE(carryTimes(m.meta.cameras[0], eyes[1], 0, 1).empty()) << "a rig moving as one was carried in time";
  spec.camera = eyes[1];
  expectRayCasterAgrees(seenFromMoving(m, eyes[1]), spec, render(spec), 40, 28, "the right eye of the moving camera");
}

TEST(CameraMoving, ShadedOnceWithAPanningCameraItRendersAsShadingFromIt) {
  // A camera "pan" that turns 30° over the shutter, recorded in a RIB scene shaded from a still
  // primary: rendered from "pan", the image of the same scene shaded with "pan" as its camera,
  // within the noise of two seeds - including a green sphere only the end of the pan sees (kept
  // only if the shading pass culls for the camera at its motion times, not where it starts).
  ScratchDir dir;
  const std::string world = kTwoSpheres;
  const std::string head = "Format 96 64 1\nProjection \"perspective\" \"fov\" 40\nShutter 0 1\n";
  const std::string pan = "MotionBegin [0 1]\nRotate 0 0 1 0\nRotate -30 0 1 0\nMotionEnd\n";
  std::ofstream(dir.path("both.rib")) << head << pan << "Camera \"pan\"\nIdentity\n" << world;
  std::ofstream(dir.path("pan.rib")) << head << pan << world;
  ASSERT_EQ(runReshutter("shade " + dir.path("both.rib") + " -o " + dir.path("both.mps")).exitCode, 0);
  ASSERT_EQ(runReshutter("shade " + dir.path("pan.rib") + " -o " + dir.path("pan.mps")).exitCode, 0);
  const CommandResult info = runReshutter("info " + dir.path("both.mps"));
  EXPECT_NE(info.out.find("moving"), std::string::npos) << "info does not say the camera moves: " << info.out;
  auto renderTo = [&](const std::string& mps, const std::string& exr, const std::string& extra) { return resampled(dir, mps, exr, extra); };
  const resample::FlatImage fromStore = renderTo("both.mps", "from_store.exr", "--camera pan");
  const resample::FlatImage direct = renderTo("pan.mps", "direct.exr", "");
  const resample::FlatImage directSeed = renderTo("pan.mps", "direct_seed.exr", "--seed 7");
  const resample::FlatImage primary = renderTo("both.mps", "primary.exr", "");
  // Green: G above R (the orange sphere has G = R / 2).
  auto greenest = [](const resample::FlatImage& img) {
    const auto &R = img.find("R")->f, &G = img.find("G")->f;
    double most = -1;
    for (size_t i = 0; i < R.size(); ++i) most = std::max(most, double(G[i]) - double(R[i]));
    return most;
  };
  EXPECT_LE(greenest(primary), 0.0) << "the still camera sees the green sphere: the test is vacuous";
  EXPECT_GT(greenest(direct), 0.2);
  EXPECT_GT(greenest(fromStore), 0.2) << "what only the end of the pan sees was culled at shading";
  const double noise = rmseRgba(direct, directSeed), err = rmseRgba(fromStore, direct);
  EXPECT_GT(noise, 0.0);
  EXPECT_LT(err, 2.0 * noise + 1e-3) << "shaded once vs shaded from the panning camera: RMSE " << err << ", two seeds " << noise;
  // The same moving camera read from a RIB snippet: the same image, bit for bit.
  std::ofstream(dir.path("pan_cam.rib")) << head << pan;
  const resample::FlatImage fromSnippet = renderTo("both.mps", "snippet.exr", "--camera-rib " + dir.path("pan_cam.rib"));
  EXPECT_EQ(fromSnippet.find("R")->f, fromStore.find("R")->f) << "the moving camera read from a RIB snippet renders otherwise";
  EXPECT_EQ(fromSnippet.find("A")->f, fromStore.find("A")->f);
}

TEST(CameraMoving, AStillCameraTakesTheCameraMotionOutOfAStoredFrame) {
  // A shared scene whose camera trucks 49 units over the shutter past a still world
  // (aqsis_mb_camera.rib): the store records the camera's motion, and rendered from a still
  // camera where it stood at the open, the whole shutter is that instant's image - the camera
  // motion blur taken out after the fact - while the stored frame itself is blurred.
  ScratchDir dir;
  const std::string rib = sharedDir() + "/data/rib/aqsis_mb_camera.rib";
  ASSERT_EQ(runReshutter("shade " + rib + " -o " + dir.path("mb.mps")).exitCode, 0);
  const CommandResult info = runReshutter("info " + dir.path("mb.mps"));
  EXPECT_NE(info.out.find("world: perspective fov 36, 480x360, pixel aspect 1, screen [-1.33333333 1.33333333 -1 1], clip [0.0001 1e+30], pinhole, moving (2 times 0 to 1)"),
            std::string::npos)
      << info.out;
  std::ofstream(dir.path("open.rib")) << "Orientation \"lh\"\nFormat 480 360 1\nShutter 0 1\nProjection \"perspective\" \"fov\" [36.0]\nRotate 180 0 1 0\n"
                                         "Translate 1 10 -440\nScale 1 -1 1\n";
  auto renderTo = [&](const std::string& exr, const std::string& extra) { return resampled(dir, "mb.mps", exr, extra); };
  const resample::FlatImage atOpen = renderTo("open.exr", "--shutter 0:0");
  const resample::FlatImage blurred = renderTo("blurred.exr", "");
  const resample::FlatImage still = renderTo("still.exr", "--camera-rib " + dir.path("open.rib"));
  const resample::FlatImage stillSeed = renderTo("still_seed.exr", "--camera-rib " + dir.path("open.rib") + " --seed 5");
  const double noise = rmseRgba(still, stillSeed), err = rmseRgba(still, atOpen), blur = rmseRgba(blurred, atOpen);
  EXPECT_GT(blur, 5 * noise) << "the stored frame is not blurred by its camera's motion: the test is vacuous";
  EXPECT_LT(err, 2 * noise + 1e-3) << "a still camera at the open vs the instant at the open: RMSE " << err << ", two seeds " << noise;
}

TEST(CameraViewDependent, APlasticHighlightFollowsTheOtherEye) {
  // A plastic sphere under a point light, seen by the primary camera and by "right", which orbits
  // it by 35 degrees: its highlight sits elsewhere for each eye. Shaded once with the view-dependent
  // term's inputs kept, "right" re-lit for its own eye matches shading from "right" within the
  // noise of two seeds; as shaded (the knob off) it carries the primary's highlight, an error
  // several times larger.
  ScratchDir dir;
  const std::string world = "WorldBegin\nLightSource \"pointlight\" 1 \"from\" [-3 4 -5] \"intensity\" [40]\n"
                            "LightSource \"ambientlight\" 2 \"intensity\" [0.1]\n"
                            "Surface \"plastic\" \"roughness\" [0.08] \"Ks\" [0.9] \"Kd\" [0.5]\nColor [0.2 0.4 0.9]\nSphere 1.5 -1.5 1.5 360\n"
                            // A constant backdrop shares the sphere's tiles: parts mix grids with the inputs and without.
                            "AttributeBegin\nSurface \"constant\"\nColor [0.3 0.3 0.3]\nTranslate 0 0 3\n"
                            "Polygon \"P\" [-6 -4 0  6 -4 0  6 4 0  -6 4 0]\nAttributeEnd\nWorldEnd\n";
  const std::string head = "Format 96 64 1\nProjection \"perspective\" \"fov\" 40\n";
  std::ofstream(dir.path("both.rib")) << head << "TransformBegin\nTranslate 0 0 6\nRotate 35 0 1 0\nCamera \"right\"\nTransformEnd\nTranslate 0 0 6\n" << world;
  std::ofstream(dir.path("right.rib")) << head << "Translate 0 0 6\nRotate 35 0 1 0\n" << world;
  ASSERT_EQ(runReshutter("shade " + dir.path("both.rib") + " --view-dependent -o " + dir.path("both.mps")).exitCode, 0);
  ASSERT_EQ(runReshutter("shade " + dir.path("both.rib") + " -o " + dir.path("plain.mps")).exitCode, 0);
  ASSERT_EQ(runReshutter("shade " + dir.path("right.rib") + " -o " + dir.path("right.mps")).exitCode, 0);
  // The inputs are in the store, and only where asked for.
  const store::StoreReader with(dir.path("both.mps")), without(dir.path("plain.mps"));
  EXPECT_GE(with.meta().schema.find(store::ViewTerm::kWeight), 0);
  EXPECT_GE(with.meta().schema.find(store::ViewTerm::visibility(0)), 0);
  EXPECT_LT(without.meta().schema.find(store::ViewTerm::kWeight), 0);

  auto renderTo = [&](const std::string& mps, const std::string& exr, const std::string& extra) {
    const CommandResult r = runReshutter("resample " + dir.path(mps) + " -o " + dir.path(exr) + " --spp 16 --stats " + extra);
    EXPECT_EQ(r.exitCode, 0) << r.err;
    return std::pair{readFlatExr(dir.path(exr)), r.out};
  };
  const auto [on, onLog] = renderTo("both.mps", "on.exr", "--camera right");
  const auto [off, offLog] = renderTo("both.mps", "off.exr", "--camera right --view-dependent off");
  const auto direct = renderTo("right.mps", "direct.exr", "").first;
  const auto seed = renderTo("right.mps", "seed.exr", "--seed 7").first;
  EXPECT_GT(numberBefore(onLog, " vertices re-lit"), 1000u) << onLog;
  EXPECT_EQ(offLog.find("re-lit"), std::string::npos) << offLog;
  // The primary camera's own image is the stored shading either way.
  EXPECT_EQ(renderTo("both.mps", "primary_on.exr", "").first.find("R")->f, renderTo("plain.mps", "primary_plain.exr", "").first.find("R")->f);
  const double noise = rmseRgba(seed, direct), errOn = rmseRgba(on, direct), errOff = rmseRgba(off, direct);
  EXPECT_LT(errOn, 2.0 * noise + 2e-3) << "re-lit for camera right: RMSE " << errOn << ", two seeds " << noise;
  EXPECT_GT(errOff, 3.0 * errOn) << "as shaded for the primary camera: RMSE " << errOff << " (re-lit " << errOn << ")";
}

TEST(CameraCli, BadCameraRequestsAreOneLineErrorsAndWriteNothing) {
  // Every camera option a user can get wrong: exit non-zero, one line naming the option or file
  // at fault, no image and no store left behind.
  ScratchDir dir;
  auto reader = writeScene(parallaxScene(), dir.path("s.mps"));
  std::ofstream(dir.path("scene.rib")) << "Format 32 24 1\nProjection \"perspective\" \"fov\" 40\nWorldBegin\nSurface \"constant\"\n"
                                          "Translate 0 0 5\nSphere 1 -1 1 360\nWorldEnd\n";
  std::ofstream(dir.path("world.rib")) << "Projection \"perspective\" \"fov\" 40\n";
  const std::string out = dir.path("x.exr"), mps = dir.path("x.mps");
  struct Bad {
    std::string command, names;
  };
  const std::vector<Bad> bad = {
      {"resample " + dir.path("s.mps") + " -o " + out + " --stereo 0", "--stereo"},
      {"resample " + dir.path("s.mps") + " -o " + out + " --stereo 1:-2", "--stereo"},
      {"resample " + dir.path("s.mps") + " -o " + out + " --stereo wide", "--stereo"},
      {"resample " + dir.path("s.mps") + " -o " + out + " --look-from 0,0,0 --look-at 0,0,0", "--look-at"},
      {"resample " + dir.path("s.mps") + " -o " + out + " --look-from 0,0,0 --look-at 0,1,0", "--up"},
      {"resample " + dir.path("s.mps") + " -o " + out + " --look-from 0,0,0 --look-at 0,0,1 --fov 180", "--fov"},
      {"resample " + dir.path("s.mps") + " -o " + out + " --look-from 0,0,0,1 --look-at 0,0,1", "--look-from"},
      {"resample " + dir.path("s.mps") + " -o " + out + " --look-from 0,0,0,1,0,0 --look-at 0,0,1,1,0,0", "--look-at"},  // at the close it looks from where it looks at
      {"resample " + dir.path("s.mps") + " -o " + out + " --camera world,world", "--camera"},
      {"resample " + dir.path("s.mps") + " -o " + out + " --camera world --camera-rib " + dir.path("world.rib"), "--camera-rib"},
      {"shade " + dir.path("scene.rib") + " -o " + mps + " --add-camera " + dir.path("world.rib"), "--add-camera"},
      {"shade " + dir.path("scene.rib") + " -o " + mps + " --add-camera " + dir.path("none.rib"), "none.rib"},
      {"shade " + dir.path("scene.rib") + " -o " + mps + " --stereo -1", "--stereo"},
  };
  for (const Bad& b : bad) {
    const CommandResult r = runReshutter(b.command);
    EXPECT_NE(r.exitCode, 0) << b.command;
    EXPECT_EQ(std::count(r.err.begin(), r.err.end(), '\n'), 1) << b.command << ": " << r.err;
    EXPECT_NE(r.err.find(b.names), std::string::npos) << b.command << ": " << r.err;
    EXPECT_FALSE(std::filesystem::exists(out)) << b.command;
    EXPECT_FALSE(std::filesystem::exists(mps)) << b.command;
  }
}
