#include <filesystem>
#include <fstream>

#include <gtest/gtest.h>

#include "common/atomic_file.h"
#include "common/check.h"
#include "common/error.h"
#include "common/frame_range.h"
#include "tests/test_util.h"

using namespace reshutter;

TEST(FrameRange, SingleRangeStepAndList) {
  EXPECT_EQ(parseFrameRange("7"), (std::vector<int64_t>{7}));
  EXPECT_EQ(parseFrameRange("1-5"), (std::vector<int64_t>{1, 2, 3, 4, 5}));
  EXPECT_EQ(parseFrameRange("1-10x3"), (std::vector<int64_t>{1, 4, 7, 10}));
  EXPECT_EQ(parseFrameRange("1-3,10,20-24x2"), (std::vector<int64_t>{1, 2, 3, 10, 20, 22, 24}));
  EXPECT_EQ(parseFrameRange("-3--1"), (std::vector<int64_t>{-3, -2, -1}));
  EXPECT_EQ(parseFrameRange("1-100").size(), 100u);
}

TEST(FrameRange, RejectsBadSyntaxWithPosition) {
  for (const char* bad : {"", "a", "1-", "5-1", "1-10x0", "1-10x-2", "1,,2", "1-3;4"}) {
    try {
      parseFrameRange(bad, "--frames");
      ADD_FAILURE() << "accepted '" << bad << "'";
    } catch (const Error& e) {
      EXPECT_EQ(e.where(), "--frames");
      EXPECT_FALSE(e.problem().empty());
    }
  }
}

TEST(FramePattern, HashesPrintfAndAt) {
  EXPECT_EQ(expandFramePattern("shot.####.mps", 7), "shot.0007.mps");
  EXPECT_EQ(expandFramePattern("shot.#.mps", 123), "shot.123.mps");
  EXPECT_EQ(expandFramePattern("shot.%04d.exr", 42), "shot.0042.exr");
  EXPECT_EQ(expandFramePattern("shot.%d.exr", 42), "shot.42.exr");
  EXPECT_EQ(expandFramePattern("shot.@.exr", 5), "shot.5.exr");
  EXPECT_EQ(expandFramePattern("shot.@@@.exr", 5), "shot.005.exr");
  EXPECT_EQ(expandFramePattern("shot.####.mps", -12), "shot.-0012.mps");
  EXPECT_EQ(expandFramePattern("100%%.%03d.exr", 1), "100%%.001.exr");
  EXPECT_EQ(expandFramePattern("plain.exr", 9), "plain.exr");
  EXPECT_TRUE(hasFramePlaceholder("a.####.b"));
  EXPECT_TRUE(hasFramePlaceholder("a.%04d.b"));
  EXPECT_FALSE(hasFramePlaceholder("a.b"));
  EXPECT_FALSE(hasFramePlaceholder("100%%.exr"));
}

TEST(AtomicFile, NothingUnderFinalNameUntilCommit) {
  test::ScratchDir dir;
  std::string target = dir.path("out.bin");
  {
    AtomicFile f(target);
    writeAll(f.fd(), "abc", 3, f.tempPath());
    EXPECT_TRUE(std::filesystem::exists(f.tempPath()));
    EXPECT_FALSE(std::filesystem::exists(target));
    // destroyed without commit: discarded
  }
  EXPECT_FALSE(std::filesystem::exists(target));
  EXPECT_TRUE(std::filesystem::is_empty(dir.dir()));
  {
    AtomicFile f(target);
    writeAll(f.fd(), "abc", 3, f.tempPath());
    f.commit();
  }
  EXPECT_EQ(test::readBytes(target).size(), 3u);
  EXPECT_EQ(std::distance(std::filesystem::directory_iterator(dir.dir()), {}), 1);
}

TEST(AtomicFile, UnwritableDirectoryIsAnError) { EXPECT_THROW(AtomicFile("/nonexistent-dir/x.mps"), Error); }

// checkCanCreate() refuses what AtomicFile's constructor refuses, creates nothing, and accepts
// what it accepts.
TEST(AtomicFile, CheckCanCreateAgreesWithTheConstructorAndCreatesNothing) {
  test::ScratchDir dir;
  EXPECT_THROW(checkCanCreate("/nonexistent-dir/x.mps"), Error);
  EXPECT_THROW(checkCanCreate(dir.path("missing/x.exr")), Error);
  EXPECT_THROW(checkCanCreate(dir.dir().string() + "/"), Error);  // no file name
  std::filesystem::create_directory(dir.path("sub"));
  EXPECT_THROW(checkCanCreate(dir.path("sub")), Error);  // names a directory
  EXPECT_NO_THROW(checkCanCreate(dir.path("x.exr")));
  EXPECT_FALSE(std::filesystem::exists(dir.path("x.exr")));
  EXPECT_EQ(std::distance(std::filesystem::directory_iterator(dir.dir()), {}), 1);  // only sub/
  EXPECT_NO_THROW(AtomicFile(dir.path("x.exr")));
}

TEST(ErrorModel, WhereAndProblemJoinIntoOneLine) {
  Error e("scene.rib:12 (Sphere)", "expected 4 numbers");
  EXPECT_STREQ(e.what(), "scene.rib:12 (Sphere): expected 4 numbers");
  EXPECT_EQ(e.where(), "scene.rib:12 (Sphere)");
}

// A broken invariant is an InternalError naming the file, line and condition - never a
// reshutter::Error, which the CLI would report as bad input (exit 1 instead of 3).
TEST(Check, FailedCheckIsAnInternalErrorNotBadInput) {
  int evaluated = 0;
  CHECK(++evaluated == 1, "never shown");
  EXPECT_EQ(evaluated, 1);  // the condition runs exactly once
  try {
    const int parts = 3;
    CHECK(parts == 4, "part count ", parts);
    FAIL() << "CHECK did not throw";
  } catch (const reshutter::Error&) {
    FAIL() << "an internal failure was dressed as bad input";
  } catch (const reshutter::InternalError& e) {
    const std::string what = e.what();
    EXPECT_NE(what.find("common_test.cpp:"), std::string::npos) << what;
    EXPECT_NE(what.find("check 'parts == 4' failed: part count 3"), std::string::npos) << what;
  }
}

// The frames a pattern finds on disk: exactly the files it expands to, with its own padding.
TEST(FrameRange, FramesOnDiskAreTheFilesThePatternExpandsTo) {
  test::ScratchDir dir;
  for (const char* name : {"shot.0001.mps", "shot.0007.mps", "shot.-0001.mps", "shot.-001.mps", "shot.7.mps", "shot.0003.mps.tmp", "other.0002.mps",
                           "shot.00x1.mps", "shot..mps", "12.mps", "3.mps"})
    std::ofstream(dir.path(name)) << "x";
  EXPECT_EQ(framesOnDisk(dir.path("shot.####.mps")), (std::vector<int64_t>{-1, 1, 7}));
  EXPECT_EQ(framesOnDisk(dir.path("shot.%04d.mps")), (std::vector<int64_t>{-1, 1, 7}));
  EXPECT_EQ(framesOnDisk(dir.path("shot.@.mps")), (std::vector<int64_t>{7}));
  EXPECT_EQ(framesOnDisk(dir.path("#.mps")), (std::vector<int64_t>{3, 12}));  // # pads to at least one digit
  EXPECT_EQ(framesOnDisk(dir.path("@@.mps")), (std::vector<int64_t>{12}));
  EXPECT_TRUE(framesOnDisk(dir.path("missing/shot.####.mps")).empty());
  EXPECT_TRUE(framesOnDisk(dir.path("shot.0001.mps")).empty());  // no placeholder
}
