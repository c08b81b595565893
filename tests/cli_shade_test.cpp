// `reshutter shade` and `reshutter demo` as a user meets them: a real RIB scene to a valid store,
// several frames to a numbered pattern, reference mode (--shade-at, --interval), and one-line
// errors naming the RIB file and line with no partial output left behind.
#include <filesystem>
#include <fstream>

#include <gtest/gtest.h>

#include "store/reader.h"
#include "tests/test_util.h"

using reshutter::test::runReshutter;
using reshutter::test::ScratchDir;

namespace {

const char* kTwoFrames = R"(
Format 160 120 1
Projection "perspective" "fov" [40]
Shutter 0 1
FrameBegin 3
WorldBegin
  LightSource "pointlight" 1 "from" [0 3 -2] "intensity" [12]
  Surface "plastic"
  Translate 0 0 5
  MotionBegin [0 1]
    Translate -0.5 0 0
    Translate 0.5 0 0
  MotionEnd
  Sphere 1 -1 1 360
WorldEnd
FrameEnd
FrameBegin 4
WorldBegin
  Translate 0 0 5
  Sphere 1 -1 1 360
WorldEnd
FrameEnd
)";

}  // namespace

TEST(CliShade, SharedSceneToValidStore) {
  ScratchDir dir;
  const std::string out = dir.path("mb.mps");
  auto r = runReshutter("shade " + reshutter::test::sharedDir() + "/data/rib/aqsis_mb_deformation.rib -o " + out);
  ASSERT_EQ(r.exitCode, 0) << r.err;
  EXPECT_NE(r.out.find("micropolygons"), std::string::npos) << r.out;
  EXPECT_EQ(r.out.find("skipped"), std::string::npos) << r.out;  // every primitive of the scene is made
  reshutter::store::StoreReader reader(out);
  EXPECT_GT(reader.verify().micropolygons, 1000u);
  EXPECT_EQ(reader.meta().frame, 0);
  EXPECT_NE(reader.meta().provenance.find("Sphere"), std::string::npos);  // object names recorded
  EXPECT_GE(reader.meta().schedules.size(), 2u);
}

TEST(CliShade, FramesToPatternAndReferenceMode) {
  ScratchDir dir;
  const std::string rib = dir.path("two.rib");
  std::ofstream(rib) << kTwoFrames;
  auto r = runReshutter("shade " + rib + " -o " + dir.path("shot.####.mps"));
  ASSERT_EQ(r.exitCode, 0) << r.err;
  EXPECT_TRUE(std::filesystem::exists(dir.path("shot.0003.mps")));
  EXPECT_TRUE(std::filesystem::exists(dir.path("shot.0004.mps")));

  // Without a pattern several frames are an error; --frame-range picks one.
  auto bad = runReshutter("shade " + rib + " -o " + dir.path("one.mps"));
  EXPECT_EQ(bad.exitCode, 1);
  EXPECT_NE(bad.err.find("frame pattern"), std::string::npos) << bad.err;
  auto one = runReshutter("shade " + rib + " --frame-range 4 -o " + dir.path("four.mps"));
  ASSERT_EQ(one.exitCode, 0) << one.err;

  // Reference mode: the second field's interval, shaded at its own opening.
  auto ref = runReshutter("shade " + rib + " --frame-range 3 --interval 0.5:1 --shade-at 0.5 -o " + dir.path("field2.mps"));
  ASSERT_EQ(ref.exitCode, 0) << ref.err;
  reshutter::store::StoreReader reader(dir.path("field2.mps"));
  EXPECT_EQ(reader.meta().shutterOpen, 0.5);
  EXPECT_EQ(reader.meta().shutterClose, 1.0);
  ASSERT_EQ(reader.meta().schedules.size(), 2u);
  EXPECT_EQ(reader.meta().schedules[1], (reshutter::store::Schedule{0.5, 1.0}));
}

TEST(CliShade, BadSceneOneLineErrorNoOutput) {
  ScratchDir dir;
  const std::string rib = dir.path("bad.rib");
  std::ofstream(rib) << "WorldBegin\nSphere 1 -1 1 360\nAttributeEnd\nWorldEnd\n";
  auto r = runReshutter("shade " + rib + " -o " + dir.path("bad.mps"));
  EXPECT_EQ(r.exitCode, 1);
  EXPECT_NE(r.err.find("bad.rib:3"), std::string::npos) << r.err;
  EXPECT_FALSE(std::filesystem::exists(dir.path("bad.mps")));
  auto missing = runReshutter("shade " + dir.path("nope.rib") + " -o " + dir.path("x.mps"));
  EXPECT_EQ(missing.exitCode, 1);
  EXPECT_NE(missing.err.find("nope.rib"), std::string::npos) << missing.err;
}

// NaN is how the command marks an option not given: given as a value, it is a usage error (exit
// 2, one line, nothing written), not silently "shade at shutter open".
TEST(CliShade, SkippedPrimitivesAreCountedAndAFrameOfOnlyThoseFails) {
  ScratchDir dir;
  const std::string head = "Format 32 24 1\nProjection \"perspective\"\nWorldBegin\nTranslate 0 0 5\n";
  const std::string blob = "Blobby 1 [1001 0] [1 0 0 0 0 1 0 0 0 0 1 0 0 0 0 1] [\"\"]\n";
  std::ofstream(dir.path("some.rib")) << head << blob << blob << "Sphere 1 -1 1 360\nWorldEnd\n";
  auto r = runReshutter("-q shade " + dir.path("some.rib") + " -o " + dir.path("some.mps"));
  ASSERT_EQ(r.exitCode, 0) << r.err;
  EXPECT_NE(r.out.find("skipped primitives: 2 Blobby"), std::string::npos) << r.out;  // even under -q

  std::ofstream(dir.path("none.rib")) << head << blob << "WorldEnd\n";
  r = runReshutter("shade " + dir.path("none.rib") + " -o " + dir.path("none.mps"));
  EXPECT_EQ(r.exitCode, 1);
  EXPECT_NE(r.err.find("every primitive was skipped (1 Blobby)"), std::string::npos) << r.err;
  EXPECT_FALSE(std::filesystem::exists(dir.path("none.mps")));
}

TEST(CliShade, NonFiniteTimesAreUsageErrors) {
  ScratchDir dir;
  const std::string rib = reshutter::test::sharedDir() + "/data/rib/aqsis_mb_deformation.rib";
  for (const std::string option : {"--shade-at nan", "--shade-at inf", "--motion-factor nan"}) {
    auto r = runReshutter("shade " + rib + " " + option + " -o " + dir.path("x.mps"));
    EXPECT_EQ(r.exitCode, 2) << option << ": " << r.err;
    EXPECT_NE(r.err.find("finite"), std::string::npos) << r.err;
    EXPECT_FALSE(std::filesystem::exists(dir.path("x.mps"))) << option;
  }
  EXPECT_EQ(runReshutter("shade " + rib + " --shade-at 0.5 -o " + dir.path("ok.mps")).exitCode, 0);  // a finite time is taken
}

TEST(CliShade, DemoWritesItsStore) {
  ScratchDir dir;
  auto r = runReshutter("demo --res 320 180 -o " + dir.path("demo"));
  ASSERT_EQ(r.exitCode, 0) << r.err;
  EXPECT_NE(r.out.find("demo.mps"), std::string::npos) << r.out;
  reshutter::store::StoreReader reader(dir.path("demo/demo.mps"));
  EXPECT_GT(reader.verify().micropolygons, 50'000u);
  EXPECT_EQ(reader.meta().cameras[0].width, 320);
}
