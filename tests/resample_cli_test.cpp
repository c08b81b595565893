// The re-sampler from the command line, as a user runs it: images an independent reader opens
// (OpenImageIO's iinfo and idiff), every lossless compression, unwritable outputs, the bucket
// size chosen or given, every instruction set's image the same, and bad arguments as one-line
// errors that write nothing.
#include <algorithm>
#include <filesystem>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "resample/gather.h"
#include "resample/resampler.h"
#include "tests/resample_test_util.h"
#include "tests/test_util.h"

using namespace reshutter;
using namespace reshutter::resample;
using namespace reshutter::test;

TEST(ResampleCli, ImagesOpenInAnIndependentReader) {
  ScratchDir dir;
  const std::string store = dir.path("gen.mps");
  ASSERT_EQ(runReshutter("generate -n 40000 --width 160 --height 90 --transparent 0.3 -o " + store).exitCode, 0);
  const std::string a = dir.path("a.exr"), b = dir.path("b.exr"), tif = dir.path("p.tif"), png = dir.path("p.png");
  CommandResult r = runReshutter("-j 1 resample " + store + " -o " + a + " --spp 9 --aov z --aov id --crop 20 140 10 80 --preview " + tif +
                                 "=R,G,B --quantize 0,65535,0,65535 --preview " + png + " --shutter 0.25:0.75");
  ASSERT_EQ(r.exitCode, 0) << r.err;
  ASSERT_EQ(runReshutter("-j 2 resample " + store + " -o " + b + " --spp 9 --aov z --aov id --crop 20 140 10 80 --shutter 0.25:0.75 --bucket 16").exitCode, 0);
  CommandResult info = runImageTool("iinfo -v " + a);
  ASSERT_EQ(info.exitCode, 0) << info.err;
  for (const char* want :
       {"120 x   70", "full/display size: 160 x 90", "pixel data origin: x=20, y=10",
        "R (float), G (float), B (float), A (float), Z (float), z (float), id (uint)", "worldToCamera", "worldToNDC", "reshutter/shutterInterval", "software"})
    EXPECT_NE(info.out.find(want), std::string::npos) << want << " not in\n" << info.out;
  // Same image from another thread count and bucket size, as an independent reader sees it.
  CommandResult diff = runImageTool("idiff -q -fail 0 -failpercent 0 -warn 0 " + a + " " + b);
  EXPECT_EQ(diff.exitCode, 0) << diff.out << diff.err;
  CommandResult tinfo = runImageTool("iinfo -v " + tif);
  EXPECT_NE(tinfo.out.find("uint16"), std::string::npos) << tinfo.out;
  CommandResult pinfo = runImageTool("iinfo -v " + png);
  EXPECT_NE(pinfo.out.find("4 channel, uint16 png"), std::string::npos) << pinfo.out;  // --quantize up to 65535: 16 bits
}

// Every lossless codec gives back exactly the pixels of the uncompressed file, as an independent
// reader sees them, and the header names the codec; the default is PIZ.
TEST(ResampleCli, LosslessCompressionsKeepEveryPixel) {
  ScratchDir dir;
  const std::string store = dir.path("gen.mps");
  ASSERT_EQ(runReshutter("generate -n 4000 --width 96 --height 64 --transparent 0.3 -o " + store).exitCode, 0);
  const std::string args = " --spp 9 --aov z --aov id --aov Ci:average";
  const std::string plain = dir.path("none.exr");
  ASSERT_EQ(runReshutter("resample " + store + " -o " + plain + args + " --compression none").exitCode, 0);
  for (const std::string codec : {"rle", "zips", "zip", "piz", "default"}) {
    const std::string out = dir.path(codec + ".exr");
    CommandResult r = runReshutter("resample " + store + " -o " + out + args + (codec == "default" ? "" : " --compression " + codec));
    ASSERT_EQ(r.exitCode, 0) << r.err;
    CommandResult info = runImageTool("iinfo -v " + out);
    ASSERT_EQ(info.exitCode, 0) << info.err;
    const std::string want = "compression: \"" + (codec == "default" ? std::string("piz") : codec) + "\"";
    EXPECT_NE(info.out.find(want), std::string::npos) << want << " not in\n" << info.out;
    CommandResult diff = runImageTool("idiff -q -fail 0 -failpercent 0 -warn 0 " + plain + " " + out);
    EXPECT_EQ(diff.exitCode, 0) << codec << ": " << diff.out << diff.err;
  }
}

// Every output is checked before the render: one that cannot be written (its directory is
// missing, or a bad quantize for a preview) fails the command before anything is rendered or
// written, so the flat EXR that could have been written is not left behind either.
TEST(ResampleCli, UnwritableOutputFailsBeforeAnythingIsWritten) {
  ScratchDir dir;
  const std::string store = dir.path("gen.mps");
  ASSERT_EQ(runReshutter("generate -n 2000 --width 64 --height 48 -o " + store).exitCode, 0);
  const std::string flat = dir.path("flat.exr");
  for (const std::string& extra : {" --preview " + dir.path("missing/p.png"), " --deep " + dir.path("missing/d.exr"),
                                   " --preview " + dir.path("p.png") + " --quantize 1,2", std::string(" --compression bogus")}) {
    CommandResult r = runReshutter("resample " + store + " -o " + flat + extra + " --stats");
    EXPECT_EQ(r.exitCode, 1) << extra;
    EXPECT_EQ(std::count(r.err.begin(), r.err.end(), '\n'), 1) << extra << ": " << r.err;
    EXPECT_EQ(r.out.find("sample tests"), std::string::npos) << extra << ": rendered before failing";
    EXPECT_FALSE(std::filesystem::exists(flat)) << extra << ": the flat EXR was written before the failing output";
  }
  CommandResult r = runReshutter("resample " + store + " -o " + dir.path("missing/flat.exr"));
  EXPECT_EQ(r.exitCode, 1);
  EXPECT_NE(r.err.find(dir.path("missing/flat.exr")), std::string::npos) << r.err;
  EXPECT_NE(r.err.find("no such directory"), std::string::npos) << r.err;
}

// --bucket 0 (the default) chooses the bucket size per render - 64 px for a motion-free store,
// whose samples are pixel-major, 96 for a moving one, through a lens by its circle of confusion -
// and --stats names it; a size given is
// used as given, the image is the same (an independent reader's comparison), and a size outside
// 4 to 1024 other than 0 is a one-line error naming the option, before anything is written.
TEST(ResampleCli, BucketSizeIsChosenOrGivenAndCheckedAtTheDoor) {
  ScratchDir dir;
  const std::string still = dir.path("still.mps"), moving = dir.path("moving.mps");
  ASSERT_EQ(runReshutter("generate -n 6000 --width 150 --height 100 --motion 0 --knots 1 -o " + still).exitCode, 0);
  ASSERT_EQ(runReshutter("generate -n 6000 --width 150 --height 100 -o " + moving).exitCode, 0);
  for (const auto& [store, chosen] : {std::pair{still, 64}, std::pair{moving, 96}}) {
    const std::string automatic = dir.path("auto.exr"), given = dir.path("given.exr");
    CommandResult r = runReshutter("resample " + store + " -o " + automatic + " --compression none --stats");
    ASSERT_EQ(r.exitCode, 0) << r.err;
    EXPECT_NE(r.out.find("buckets of " + std::to_string(chosen) + " px"), std::string::npos) << r.out;
    CommandResult g = runReshutter("resample " + store + " -o " + given + " --compression none --stats --bucket 24");
    ASSERT_EQ(g.exitCode, 0) << g.err;
    EXPECT_NE(g.out.find("buckets of 24 px"), std::string::npos) << g.out;
    CommandResult diff = runImageTool("idiff -q -fail 0 -failpercent 0 -warn 0 " + automatic + " " + given);
    EXPECT_EQ(diff.exitCode, 0) << store << ": " << diff.out << diff.err;
  }
  // Through a lens the size follows the circle of confusion: the stores' depths are 5 to 50, so
  // focused at 5 with a focal length of 1 the far circle's radius is 0.18 ay / (2 N) px (ay =
  // 50 / tan 20 deg, the 40 degree view over 100 rows): about 2 px at f/6, 25 at f/0.5 and 100
  // at f/0.125 - the smallest size, one between, the largest (motion: at least 96). Each lens
  // image is also the one a given size makes.
  auto bucketOf = [](const std::string& out) {
    const size_t at = out.find("buckets of ");
    return at == std::string::npos ? -1 : std::atoi(out.c_str() + at + 11);
  };
  for (const std::string& store : {still, moving}) {
    std::vector<int> sizes;
    for (const char* fstop : {"6", "0.5", "0.125"}) {
      const std::string lens = std::string(" --fstop ") + fstop + " --focal-length 1 --focus-distance 5 --compression none --stats";
      const std::string automatic = dir.path("lens_auto.exr"), given = dir.path("lens_given.exr");
      CommandResult r = runReshutter("resample " + store + " -o " + automatic + lens);
      ASSERT_EQ(r.exitCode, 0) << r.err;
      EXPECT_NE(r.out.find("micropolygons through the lens"), std::string::npos) << r.out;
      sizes.push_back(bucketOf(r.out));
      ASSERT_EQ(runReshutter("resample " + store + " -o " + given + lens + " --bucket 40").exitCode, 0);
      CommandResult diff = runImageTool("idiff -q -fail 0 -failpercent 0 -warn 0 " + automatic + " " + given);
      EXPECT_EQ(diff.exitCode, 0) << store << " f/" << fstop << ": " << diff.out << diff.err;
    }
    if (store == still) {
      EXPECT_EQ(sizes[0], 48);
      EXPECT_TRUE(sizes[1] > 48 && sizes[1] < 128) << sizes[1];
    } else {
      EXPECT_EQ(sizes[0], 96);
      EXPECT_TRUE(sizes[1] >= 96 && sizes[1] <= 128) << sizes[1];
    }
    EXPECT_EQ(sizes[2], 128);
  }
  // The rule itself: within 48-128, never smaller for a larger circle, at least 96 with motion.
  int last = 0;
  for (double radius = 0; radius <= 400; radius += 0.5) {
    const int b = lensBucketSize(radius, false), m = lensBucketSize(radius, true);
    EXPECT_TRUE(b >= 48 && b <= 128 && b >= last && m >= 96 && m <= 128 && m >= b) << radius;
    last = b;
  }
  EXPECT_EQ(lensBucketSize(INFINITY, false), 128);
  for (const std::string bad : {"2", "-8", "2048"}) {
    const std::string out = dir.path("bad.exr");
    CommandResult r = runReshutter("resample " + still + " -o " + out + " --bucket " + bad);
    EXPECT_EQ(r.exitCode, 1) << bad;
    EXPECT_EQ(std::count(r.err.begin(), r.err.end(), '\n'), 1) << bad << ": " << r.err;
    EXPECT_NE(r.err.find("--bucket"), std::string::npos) << r.err;
    EXPECT_FALSE(std::filesystem::exists(out)) << bad;
  }
}

// --simd picks the inner loops' instruction set: every set this CPU runs writes the same file as
// an independent reader sees it; one it does not run (AVX-512 on most desktops) is a one-line
// error before anything is written.
TEST(ResampleCli, EveryInstructionSetWritesTheSameImage) {
  ScratchDir dir;
  const std::string store = dir.path("gen.mps");
  ASSERT_EQ(runReshutter("generate -n 20000 --width 120 --height 80 -o " + store).exitCode, 0);
  const std::string scalar = dir.path("none.exr");
  ASSERT_EQ(runReshutter("resample " + store + " -o " + scalar + " --spp 16 --simd none").exitCode, 0);
  for (const std::string simd : {"auto", "avx2", "avx512"}) {
    const std::string out = dir.path(simd + ".exr");
    CommandResult r = runReshutter("resample " + store + " -o " + out + " --spp 16 --simd " + simd);
    const bool runs = simd == "auto" || (simd == "avx2" ? kernels::available() : kernels::available(kernels::Isa::Avx512));
    if (!runs) {
      EXPECT_EQ(r.exitCode, 1) << simd;
      EXPECT_EQ(std::count(r.err.begin(), r.err.end(), '\n'), 1) << r.err;
      EXPECT_NE(r.err.find("--simd"), std::string::npos) << r.err;
      EXPECT_FALSE(std::filesystem::exists(out)) << simd;
      continue;
    }
    ASSERT_EQ(r.exitCode, 0) << simd << ": " << r.err;
    CommandResult diff = runImageTool("idiff -q -fail 0 -failpercent 0 -warn 0 " + scalar + " " + out);
    EXPECT_EQ(diff.exitCode, 0) << simd << ": " << diff.out << diff.err;
  }
  CommandResult bad = runReshutter("resample " + store + " -o " + dir.path("x.exr") + " --simd sse9");
  EXPECT_NE(bad.exitCode, 0);
  EXPECT_NE(bad.err.find("--simd"), std::string::npos) << bad.err;
}

TEST(ResampleCli, BadArgumentsGiveOneLineAndNoOutput) {
  ScratchDir dir;
  const std::string store = dir.path("gen.mps");
  ASSERT_EQ(runReshutter("generate -n 2000 --width 64 --height 48 -o " + store).exitCode, 0);
  for (const char* args : {"--shutter 0.5:0.2", "--shutter 0:2", "--filter nonesuch", "--aov bogus", "--spp 0", "--shutter-shape trapezoid:0.9:0.1"}) {
    const std::string out = dir.path("x.exr");
    CommandResult r = runReshutter("resample " + store + " -o " + out + " " + args);
    EXPECT_NE(r.exitCode, 0) << args;
    EXPECT_EQ(std::count(r.err.begin(), r.err.end(), '\n'), 1) << args << ": " << r.err;
    EXPECT_EQ(r.err.rfind("reshutter: ", 0), 0u) << r.err;
    EXPECT_FALSE(std::filesystem::exists(out)) << args;
  }
}
