// The shading pass on RIB scenes: every scene in ../shared/data/rib and rib-production shades (or
// says what it skipped), requests map onto scene state, what exporters write is kept, object
// instances and delayed archives, the pathological primitives the fuzzer found stop at their
// budget, and bad input names its file and line.
#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <map>
#include <set>

#include <gtest/gtest.h>
#include <glm/geometric.hpp>

#include "common/error.h"
#include "common/log.h"
#include "shade/rib_scene.h"
#include "shade/shading_pass.h"
#include "store/reader.h"
#include "tests/shade_test_util.h"
#include "tests/test_util.h"

namespace reshutter::shade {
namespace {

using glm::dvec3;
using namespace testing;

/// The one frame a RIB file makes (a test failure when it makes another number).
FrameScene onlyFrameOf(const std::string& path) {
  FrameScene got;
  int frames = 0;
  Scene scene([&](FrameScene& f) { got = std::move(f), ++frames; });
  readRibScene(path, scene);
  EXPECT_EQ(frames, 1) << path;
  return got;
}

TEST(ShadeRib, EverySharedSceneShades) {
  const std::string dir = test::sharedDir() + "/data/rib";
  ASSERT_TRUE(std::filesystem::is_directory(dir)) << dir;
  int files = 0;
  for (const auto& e : std::filesystem::directory_iterator(dir)) {
    if (e.path().extension() != ".rib") continue;
    ++files;
    uint64_t mps = 0;
    int frames = 0;
    Scene scene([&](FrameScene& f) {
      ShadeOptions o;
      o.dice.shadingRateScale = 4;  // coarser than the files ask: this checks robustness, not quality
      CaptureSink sink;
      shadeFrame(f, o, sink);
      storeMeta(f, o).validate(e.path().string());
      mps += sink.mps();
      ++frames;
    });
    ASSERT_NO_THROW(readRibScene(e.path().string(), scene)) << e.path();
    EXPECT_GE(frames, 1) << e.path();
    EXPECT_GT(mps, 0u) << e.path();
  }
  EXPECT_GE(files, 6);
}

TEST(ShadeRib, EveryProductionSceneShadesOrSaysWhatItSkipped) {
  // ../shared/data/rib-production: no frame may come out empty in silence - it shades
  // micropolygons, or it names the primitives it could not make.
  const std::string dir = test::sharedDir() + "/data/rib-production";
  ASSERT_TRUE(std::filesystem::is_directory(dir)) << dir;
  int files = 0, shaded = 0;
  for (const auto& e : std::filesystem::recursive_directory_iterator(dir)) {
    if (e.path().extension() != ".rib" || e.path().filename() == "teapot.rib") continue;  // teapot.rib is fig12.7's archive
    ++files;
    int frames = 0;
    Scene scene([&](FrameScene& f) {
      ShadeOptions o;
      o.dice.shadingRateScale = 4;
      CaptureSink sink;
      shadeFrame(f, o, sink);
      EXPECT_TRUE(sink.mps() > 0 || !f.skipped.empty()) << e.path();
      shaded += sink.mps() > 0;
      ++frames;
    });
    ASSERT_NO_THROW(readRibScene(e.path().string(), scene)) << e.path();
    EXPECT_GE(frames, 1) << e.path();
  }
  EXPECT_GE(files, 6);
  EXPECT_GE(shaded, 6);  // the bicubic teapot, object instances, the depth-of-field cubes, subdivision creases, bezier grass, NURBS
}

TEST(ShadeRib, RequestsMapToSceneState) {
  test::ScratchDir dir;
  const std::string path = dir.path("scene.rib");
  std::ofstream(path) << R"(
Format 200 100 1
Projection "perspective" "fov" [40]
Shutter 0 1
Display "out.exr" "file" "rgba"
Display "+n.exr" "file" "N,specular"
FrameBegin 7
WorldBegin
  LightSource "distantlight" 1 "intensity" [1.5]
  AttributeBegin
    Attribute "identifier" "name" ["spinner"]
    Matte 1
    Translate 0 0 5
    MotionBegin [0 0.5 1]
      Rotate 0 0 1 0
      Rotate 10 0 1 0
      Rotate 20 0 1 0
    MotionEnd
    Surface "plastic" "roughness" [0.2]
    Polygon "P" [-1 -1 0  1 -1 0  1 1 0  -1 1 0] "Cs" [1 0 0  0 1 0  0 0 1  1 1 1]
    Blobby 1 [1001 0] [1 0 0 0 0 1 0 0 0 0 1 0 0 0 0 1] [""]
  AttributeEnd
WorldEnd
FrameEnd
)";
  FrameScene got;
  Scene scene([&](FrameScene& f) { got = std::move(f); });
  const size_t warnings = warningCount();
  readRibScene(path, scene);
  EXPECT_GT(warningCount(), warnings);  // the Blobby
  EXPECT_EQ(got.skipped, (std::map<std::string, uint64_t>{{"Blobby", 1}}));
  EXPECT_EQ(got.options.frame, 7);
  EXPECT_EQ(got.options.camera.width, 200);
  EXPECT_EQ(got.options.outputs, (std::vector<std::string>{"N", "specular"}));
  ASSERT_EQ(got.prims.size(), 1u);
  std::array<dvec3, 4> cs;
  ASSERT_TRUE(got.prims[0].corners(got.prims[0].mesh->Cs, cs));
  EXPECT_EQ(cs[1], dvec3(0, 1, 0));  // P10 is the polygon's second point
  EXPECT_EQ(cs[3], dvec3(0, 0, 1));  // P11 its third
  EXPECT_TRUE(got.prims[0].attrs->matte);
  EXPECT_EQ(got.prims[0].xform->times, (std::vector<double>{0, 0.5, 1}));
  ASSERT_EQ(got.lights.size(), 1u);
  EXPECT_EQ(got.lights[0].intensity, 1.5);
  CaptureSink sink = shadeCapture(got);
  EXPECT_GT(sink.mps(), 0u);
}

TEST(ShadeRib, WhatExportersWriteIsKeptNotFatal) {
  // A RIS-era exporter's scene: Camera "world", a RIS projection, RIS materials, lights and
  // options, parameters nobody declared, conditional passes, and a primitive the pass cannot
  // make. The frame comes through; RIS requests are kept; the skipped primitive is counted.
  test::ScratchDir dir;
  const std::string path = dir.path("ris.rib");
  std::ofstream(path) << R"(
Option "user" "string pass" ["beauty"]
Format 64 48 1
Projection "PxrCamera" "float fov" [45]
Hider "raytrace" "int maxsamples" [64]
Integrator "PxrPathTracer" "main" "int maxPathLength" [4]
DisplayFilter "PxrBackgroundDisplayFilter" "bg" "color backgroundColor" [0 0 0]
Translate 0 0 5
Camera "world" "float[2] shutteropening" [0 1]
WorldBegin
  Light "PxrDistantLight" "key" "float intensity" [2]
  Attribute "identifier" "shadinggroup" ["g1"] "name" ["ball"]
  Pattern "PxrTexture" "tex" "string filename" ["wood.tx"]
  Bxdf "PxrDiffuse" "mat" "reference color diffuseColor" ["tex:resultRGB"] "color diffuseColor" [0.8 0.2 0.1]
  Surface "paintedplastic" "mapname" ["grid.tx"] "Kd" [0.7]
  IfBegin "$user:pass == 'beauty'"
    Sphere 1 -1 1 360
  Else
    Cone 1 1 360
  IfEnd
  Blobby 1 [1001 0] [1 0 0 0 0 1 0 0 0 0 1 0 0 0 0 1] [""]
WorldEnd
)";
  const FrameScene got = onlyFrameOf(path);
  EXPECT_EQ(got.options.camera.fovDegrees, 45);
  EXPECT_EQ(got.options.camera.worldToCamera[3][2], 5);  // the transform before Camera "world"
  ASSERT_EQ(got.prims.size(), 1u);
  EXPECT_EQ(got.prims[0].kind, PrimKind::Sphere);  // the beauty branch
  EXPECT_EQ(got.prims[0].attrs->surface.values[0].Kd, double(0.7f));  // RIB numbers are RtFloats
  ASSERT_EQ(got.risNodes.size(), 3u);
  EXPECT_EQ(got.risNodes[0].type, "PxrDistantLight");
  EXPECT_EQ(got.risNodes[0].numbers.at("intensity"), std::vector<double>{2});
  EXPECT_EQ(got.risNodes[1].strings.at("filename"), std::vector<std::string>{"wood.tx"});
  ASSERT_EQ(got.prims[0].attrs->bxdf, 3u);
  EXPECT_EQ(got.risNodes[2].handle, "mat");
  EXPECT_EQ(got.risNodes[2].numbers.at("diffuseColor"), (std::vector<double>{0.8f, 0.2f, 0.1f}));
  ASSERT_EQ(got.options.risOptions.size(), 3u);
  EXPECT_EQ(got.options.risOptions[0].request, "Hider");
  EXPECT_EQ(got.options.risOptions[1].type, "PxrPathTracer");
  EXPECT_EQ(got.skipped, (std::map<std::string, uint64_t>{{"Blobby", 1}}));
  EXPECT_EQ(got.objectNames, std::vector<std::string>{"ball"});
}

TEST(ShadeRib, ObjectInstancesPlaceTheirDefinitionUnderTheCurrentState) {
  // Two primitives retained (one sets its own Color), instanced twice under other transforms
  // and colours; a primitive the pass cannot make inside the definition is counted per instance.
  test::ScratchDir dir;
  const std::string path = dir.path("objects.rib");
  std::ofstream(path) << R"(
ObjectBegin "pair"
  Translate 1 0 0
  Sphere 1 -1 1 360
  AttributeBegin
    Color [0 0 1]
    GeneralPolygon [3] "P" [0 0 0 1 0 0 0 1 0]
  AttributeEnd
  Blobby 1 [1001 0] [1 0 0 0 0 1 0 0 0 0 1 0 0 0 0 1] [""]
ObjectEnd
WorldBegin
  Translate 0 0 5
  Color [1 0 0]
  ObjectInstance "pair"
  Translate 0 2 0
  Color [0 1 0]
  ObjectInstance "pair"
WorldEnd
)";
  const FrameScene got = onlyFrameOf(path);
  ASSERT_EQ(got.prims.size(), 4u);
  const dvec3 origin(0.0);
  auto placed = [&](size_t i) { return dvec3(got.prims[i].xform->at(0) * glm::dvec4(origin, 1.0)); };
  EXPECT_EQ(placed(0), dvec3(1, 0, 5));  // the definition's Translate, then the instance's
  EXPECT_EQ(placed(2), dvec3(1, 2, 5));
  EXPECT_EQ(got.prims[0].kind, PrimKind::Sphere);
  EXPECT_TRUE(got.prims[1].triangle);
  EXPECT_EQ(got.prims[0].attrs->color.values[0], dvec3(1, 0, 0));  // the instance's colour
  EXPECT_EQ(got.prims[2].attrs->color.values[0], dvec3(0, 1, 0));
  EXPECT_EQ(got.prims[1].attrs->color.values[0], dvec3(0, 0, 1));  // set inside the definition
  EXPECT_EQ(got.prims[3].attrs->color.values[0], dvec3(0, 0, 1));
  EXPECT_EQ(got.skipped, (std::map<std::string, uint64_t>{{"Blobby", 2}}));
  auto error = [&](const std::string& text) {
    std::ofstream(path) << text;
    Scene s([](FrameScene&) {});
    try {
      readRibScene(path, s);
    } catch (const Error& e) {
      return std::string(e.what());
    }
    return std::string("no error");
  };
  EXPECT_NE(error("WorldBegin\nObjectInstance 7\nWorldEnd\n").find("objects.rib:2 (ObjectInstance): ObjectInstance of undefined object '7'"), std::string::npos);
  EXPECT_NE(error("ObjectEnd\n").find("ObjectEnd without ObjectBegin"), std::string::npos);
}

TEST(ShadeRib, DelayedArchivesAreReadInPlaceAndProgramsNeverRun) {
  test::ScratchDir dir;
  std::ofstream(dir.path("sub.rib")) << "Color [0 0 1]\nSphere 1 -1 1 360\n";
  const std::string path = dir.path("scene.rib");
  std::ofstream(path) << R"(
WorldBegin
  Translate 0 0 5
  Color [1 0 0]
  Procedural "DelayedReadArchive" ["sub.rib"] [-1 1 -1 1 -1 1]
  Procedural2 "DelayedReadArchive2" "SimpleBound" "string filename" ["sub.rib"] "float[6] bound" [-1 1 -1 1 -1 1]
  Disk 0 1 360
  Procedural "RunProgram" ["rm -rf /tmp/never" ""] [-1 1 -1 1 -1 1]
  Procedural "DynamicLoad" ["plugin.so" ""] [-1 1 -1 1 -1 1]
WorldEnd
)";
  const FrameScene got = onlyFrameOf(path);
  ASSERT_EQ(got.prims.size(), 3u);
  EXPECT_EQ(got.prims[0].kind, PrimKind::Sphere);
  EXPECT_EQ(got.prims[0].attrs->color.values[0], dvec3(0, 0, 1));  // the archive's colour inside it
  EXPECT_EQ(got.prims[2].kind, PrimKind::Disk);
  EXPECT_EQ(got.prims[2].attrs->color.values[0], dvec3(1, 0, 0));  // and not after it
  EXPECT_EQ(got.skipped, (std::map<std::string, uint64_t>{{"Procedural", 2}}));
}

TEST(ShadeRib, DelayedArchivesOutOfViewAreNeverRead) {
  // "missing.rib" does not exist: reading it would be an error, so a scene that reads cleanly
  // proves the archive was culled by its bound. In view, behind the eye, past an edge, and
  // moving across the screen (in view between its knots).
  test::ScratchDir dir;
  std::ofstream(dir.path("sub.rib")) << "Sphere 1 -1 1 360\n";
  auto frame = [&](const std::string& world) {
    const std::string path = dir.path("scene.rib");
    std::ofstream(path) << "Format 320 240 1\nProjection \"perspective\" \"fov\" [40]\nShutter 0 1\nWorldBegin\n" << world << "\nWorldEnd\n";
    return onlyFrameOf(path);
  };
  const std::string missing = "Procedural \"DelayedReadArchive\" [\"missing.rib\"] [-1 1 -1 1 -1 1]\n";
  EXPECT_EQ(frame("Translate 0 0 -5\n" + missing + "Disk 5 1 360").culledArchives, 1u);            // behind the eye
  EXPECT_EQ(frame("Translate 40 0 5\n" + missing + "Disk 5 1 360").culledArchives, 1u);            // far to the right
  EXPECT_EQ(frame("Translate 0 40 5\n" + missing + "Disk 5 1 360").culledArchives, 1u);            // far above
  const FrameScene seen = frame("Translate 0 0 5\nProcedural \"DelayedReadArchive\" [\"sub.rib\"] [-1 1 -1 1 -1 1]");
  EXPECT_EQ(seen.culledArchives, 0u);
  EXPECT_EQ(seen.prims.size(), 1u);
  // Moving from far left to far right: on screen in between, so read (and here: missing).
  EXPECT_THROW(frame("MotionBegin [0 1]\nTranslate -40 0 5\nTranslate 40 0 5\nMotionEnd\n" + missing), Error);
  EXPECT_THROW(frame("Translate 0 0 5\n" + missing), Error);  // in view: read, and missing
}

TEST(ShadeDiceHard, APathologicalPrimitiveStopsAtItsBudget) {
  // Found by the RIB fuzzer: a tooled-steel cube instanced under a transform sheared 8047 times
  // (a number cut by NUL bytes), which seen edge-on wants hundreds of millions of micropolygons
  // (minutes of splitting). Past the budget its remaining pieces are diced a grid each: the
  // work stops within one grid per level of the recursion, and the primitive is counted.
  const std::string path = test::sourceDir() + "/tests/corpus/rib/fuzz_sheared_instance_timeout.rib";
  setVerbosity(Verbosity::Quiet);  // the mutated file's undeclared parameters warn
  const FrameScene f = onlyFrameOf(path);
  setVerbosity(Verbosity::Normal);
  const store::Camera cam = storeMeta(f, {}).cameras[0];
  auto split = [&](uint64_t budget, uint64_t& over) {
    DiceOptions o;
    o.maxMicropolygonsPerPrimitive = budget;
    uint64_t most = 0;
    over = 0;
    for (const Primitive& p : f.prims) {
      std::vector<Leaf> leaves;
      DiceStats stats;
      splitPrimitive(p, clipKnots(p, 0, 0), cam, {}, o, leaves, stats);
      uint64_t mps = 0;
      for (const Leaf& l : leaves) mps += uint64_t(l.nu) * uint64_t(l.nv);
      most = std::max(most, mps);
      over += stats.overBudget;
    }
    return most;
  };
  uint64_t over = 0;
  const uint64_t budget = 1000000, bounded = split(budget, over);  // the other faces need less
  EXPECT_EQ(over, 1u);
  EXPECT_GT(bounded, budget);
  EXPECT_LE(bounded, budget + 16 * 16 * uint64_t(DiceOptions{}.maxSplitDepth + 2));
  // Four times the budget is reached too: the primitive really wants more.
  EXPECT_GT(split(4 * budget, over), 4 * budget);
  EXPECT_EQ(over, 1u);

  // Found next: a mutated CSG scene whose splitting culls nearly every piece it makes (it ran
  // past the fuzzer's 30 s on a small camera). Pieces visited are bounded by a quarter of the
  // budget, plus the pieces pending on the recursion.
  setVerbosity(Verbosity::Quiet);
  const FrameScene g = onlyFrameOf(test::sourceDir() + "/tests/corpus/rib/fuzz_culled_slivers_timeout.rib");
  setVerbosity(Verbosity::Normal);
  store::Camera small = storeMeta(g, {}).cameras[0];
  small.width = 48, small.height = 36;
  DiceOptions o;
  o.maxMicropolygonsPerPrimitive = 20000;
  uint64_t most = 0;
  for (const Primitive& p : g.prims) {
    std::vector<Leaf> leaves;
    DiceStats stats;
    splitPrimitive(p, clipKnots(p, 0, 0), small, {}, o, leaves, stats);
    most = std::max(most, stats.leaves + stats.culledPieces + stats.eyeSplits);
  }
  EXPECT_LE(most, 20000 / 4 + 2 * uint64_t(o.maxSplitDepth + 2));
}

TEST(ShadeRib, BadInputNamesFileAndLine) {
  test::ScratchDir dir;
  const std::string path = dir.path("bad.rib");
  std::ofstream(path) << "WorldBegin\nMotionBegin [0 1]\nTranslate 1 0 0\nMotionEnd\nWorldEnd\n";
  Scene scene([](FrameScene&) {});
  try {
    readRibScene(path, scene);
    FAIL() << "expected an error";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("bad.rib:4"), std::string::npos) << e.what();
  }
}

}  // namespace
}  // namespace reshutter::shade
