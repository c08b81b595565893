// A shot's stores (store/shot.h): which frames' stores a time interval needs (whole-frame and
// 180° dumps, frame boundaries, instants, negative frames, a single store), missing stores
// reported all at once naming every file, a store whose name and contents disagree or whose
// shutter differs from the shot's, and stores released as a sequence moves forward.
#include <filesystem>

#include <gtest/gtest.h>

#include "common/error.h"
#include "common/frame_range.h"
#include "store/shot.h"
#include "tests/store_test_util.h"
#include "tests/test_util.h"

using namespace reshutter;
using namespace reshutter::store;
using reshutter::test::ScratchDir;

namespace {

// A small store of `frame` covering [frame + open, frame + close].
void writeFrame(const std::string& path, int64_t frame, double open = 0, double close = 1) {
  const Schema schema = test::fullSchema();
  StoreMeta meta = test::testMeta(schema, 32, 24);
  meta.frame = frame;
  meta.shutterOpen = open, meta.shutterClose = close;
  StoreWriter w(path, meta);
  test::GridSpec spec;
  spec.knots = 2;
  spec.schedule = w.addSchedule({open, close});
  Rng rng(uint64_t(frame + 100));
  uint32_t id = 0;
  w.addGrid(test::randomGrid(rng, schema, spec, 0, id).view());
  w.close();
}

// The error `fn` throws (an empty one, and a test failure, if it throws none).
template <typename Fn>
Error errorOf(Fn fn) {
  try {
    fn();
  } catch (const Error& e) {
    return e;
  }
  ADD_FAILURE() << "expected an Error";
  return Error("", "");
}

using Frames = std::vector<int64_t>;

}  // namespace

// Stores dumped over whole frames: an interval needs each store its coverage overlaps with
// positive length; one that only touches the interval's end (or start) is not needed.
TEST(ShotStores, FramesForFindsTheStoresAnIntervalOverlaps) {
  ScratchDir dir;
  const std::string pattern = dir.path("shot.####.mps");
  ShotStores shot(pattern, 0);
  for (int64_t f = 1; f <= 4; ++f) writeFrame(shot.pathOf(f), f);
  EXPECT_EQ(shot.framesFor(1.2, 1.6), Frames({1}));
  EXPECT_EQ(shot.framesFor(1.8, 2.2), Frames({1, 2}));  // across a frame boundary: both stores
  EXPECT_EQ(shot.framesFor(1.0, 2.0), Frames({1}));     // frame 0 ends at 1.0, frame 2 starts at 2.0
  EXPECT_EQ(shot.framesFor(2.0, 2.5), Frames({2}));
  EXPECT_EQ(shot.framesFor(2.5, 2.5), Frames({2}));           // an instant inside one frame
  EXPECT_EQ(shot.framesFor(0.5, 3.5), Frames({0, 1, 2, 3}));  // frame 0 has no store: finding frames does not check files
  EXPECT_EQ(shot.pathOf(3), dir.path("shot.0003.mps"));
  EXPECT_EQ(shot.firstMeta(99).frame, 1) << "the shot's shutter comes from the store nearest the first time asked for";
}

// Dumps with a 180° shutter cover only the first half of each frame: an interval in the gap needs
// no store (the re-sampler then reports the uncovered times), one across it needs both sides.
TEST(ShotStores, HalfFrameDumpsLeaveGaps) {
  ScratchDir dir;
  ShotStores shot(dir.path("half.####.mps"), 0);
  for (int64_t f = 1; f <= 3; ++f) writeFrame(shot.pathOf(f), f, 0, 0.5);
  EXPECT_EQ(shot.framesFor(1.6, 1.9), Frames{});
  EXPECT_EQ(shot.framesFor(1.4, 2.1), Frames({1, 2}));
  EXPECT_EQ(shot.framesFor(1.5, 2.0), Frames{}) << "touching coverage at both ends only";
  EXPECT_EQ(shot.framesFor(2.25, 2.25), Frames({2}));
  EXPECT_EQ(shot.firstMeta(2).shutterClose, 0.5);
}

// Frame numbers below zero name and find their stores like any others.
TEST(ShotStores, NegativeFrames) {
  ScratchDir dir;
  ShotStores shot(dir.path("neg.####.mps"), 0);
  for (int64_t f = -3; f <= 0; ++f) writeFrame(shot.pathOf(f), f);
  EXPECT_NE(shot.pathOf(-2), shot.pathOf(2));
  EXPECT_EQ(shot.framesFor(-2.5, -1.5), Frames({-3, -2}));
  const auto stores = shot.storesFor(-2.5, -1.5);
  ASSERT_EQ(stores.size(), 2u);
  EXPECT_EQ(stores[0].frame, -3);
  EXPECT_EQ(stores[0].reader->meta().frame, -3);
  EXPECT_EQ(stores[1].reader->meta().frame, -2);
  EXPECT_EQ(stores[1].reader->path(), shot.pathOf(-2));
}

// A name without a frame placeholder is a shot of one store, whatever interval is asked for (the
// re-sampler checks that the store covers it).
TEST(ShotStores, ASingleStoreServesEveryInterval) {
  ScratchDir dir;
  const std::string path = dir.path("one.mps");
  writeFrame(path, 7);
  ShotStores shot(path, 0);
  EXPECT_EQ(shot.framesFor(7.2, 7.4), Frames({7}));
  EXPECT_EQ(shot.framesFor(3.0, 12.0), Frames({7}));
  const auto stores = shot.storesFor(7.0, 8.0);
  ASSERT_EQ(stores.size(), 1u);
  EXPECT_EQ(stores[0].frame, 7);
  EXPECT_EQ(stores[0].reader->path(), path);
}

// Missing stores are one Error that names the shot and every missing file (at most twelve, then
// a count), whichever of them a sequence would reach first.
TEST(ShotStores, MissingStoresAreOneErrorNamingEachFile) {
  ScratchDir dir;
  const std::string pattern = dir.path("gap.####.mps");
  ShotStores shot(pattern, 0);
  for (int64_t f : {1, 2, 4}) writeFrame(shot.pathOf(f), f);
  EXPECT_NO_THROW(shot.requireAll({1, 2, 4}));
  Error one = errorOf([&] { shot.requireAll({1, 2, 3, 4}); });
  EXPECT_EQ(one.where(), pattern);
  EXPECT_NE(one.problem().find("1 store is missing: " + shot.pathOf(3)), std::string::npos) << one.what();
  Error many = errorOf([&] { shot.requireAll({3, 5, 6}); });
  EXPECT_NE(many.problem().find("3 stores are missing"), std::string::npos) << many.what();
  for (int64_t f : {3, 5, 6}) EXPECT_NE(many.problem().find(shot.pathOf(f)), std::string::npos) << f << ": " << many.what();
  Frames lots;
  for (int64_t f = 10; f < 30; ++f) lots.push_back(f);
  Error capped = errorOf([&] { shot.requireAll(lots); });
  EXPECT_NE(capped.problem().find("20 stores are missing"), std::string::npos) << capped.what();
  EXPECT_NE(capped.problem().find(shot.pathOf(21)), std::string::npos) << "the twelfth is named";
  EXPECT_EQ(capped.problem().find(shot.pathOf(22)), std::string::npos) << "the thirteenth is counted";
  EXPECT_NE(capped.problem().find("and 8 more"), std::string::npos) << capped.what();
  // storesFor checks too, before opening anything.
  Error reached = errorOf([&] { shot.storesFor(2.5, 3.5); });
  EXPECT_NE(reached.problem().find(shot.pathOf(3)), std::string::npos) << reached.what();
}

TEST(ShotStores, NoStoreNearTheFirstTimeIsAnErrorNamingTheFileLookedFor) {
  ScratchDir dir;
  const std::string pattern = dir.path("none.####.mps");
  ShotStores shot(pattern, 0);
  Error e = errorOf([&] { shot.framesFor(5.5, 6.0); });
  EXPECT_EQ(e.where(), pattern);
  EXPECT_NE(e.problem().find("no store found near frame 5"), std::string::npos) << e.what();
  EXPECT_NE(e.problem().find(shot.pathOf(5)), std::string::npos) << e.what();
}

// The rules that make files one shot: a store holds the frame its name says, and shares the
// shutter of the shot's first store. Each violation names the file.
TEST(ShotStores, NameAndContentsMustAgreeAndShuttersMatch) {
  ScratchDir dir;
  {
    ShotStores shot(dir.path("wrong.####.mps"), 0);
    writeFrame(shot.pathOf(1), 1);
    writeFrame(shot.pathOf(2), 5);  // named frame 2, holds frame 5
    Error e = errorOf([&] { shot.storesFor(1.5, 2.5); });
    EXPECT_EQ(e.where(), shot.pathOf(2));
    EXPECT_NE(e.problem().find("holds frame 5, its name says frame 2"), std::string::npos) << e.what();
  }
  {
    ShotStores shot(dir.path("mixed.####.mps"), 0);
    writeFrame(shot.pathOf(1), 1);
    writeFrame(shot.pathOf(2), 2, 0, 0.5);  // a 180° dump among whole-frame ones
    Error e = errorOf([&] { shot.storesFor(1.5, 2.25); });
    EXPECT_EQ(e.where(), shot.pathOf(2));
    EXPECT_NE(e.problem().find("differs from " + shot.pathOf(1)), std::string::npos) << e.what();
    EXPECT_NE(e.problem().find("share one shutter"), std::string::npos) << e.what();
  }
}

// A sequence moves forward in time: stores before an interval's first are released (all but the
// shot's first, which holds its shutter), and reopened if asked for again.
TEST(ShotStores, StoresBehindASequenceAreReleased) {
  ScratchDir dir;
  ShotStores shot(dir.path("seq.####.mps"), 0);
  for (int64_t f = 1; f <= 5; ++f) writeFrame(shot.pathOf(f), f);
  shot.storesFor(1.8, 2.2);
  EXPECT_EQ(shot.openFrames(), Frames({1, 2}));
  shot.storesFor(2.8, 3.2);
  EXPECT_EQ(shot.openFrames(), Frames({1, 2, 3}));
  shot.storesFor(4.2, 4.6);
  EXPECT_EQ(shot.openFrames(), Frames({1, 4})) << "2 and 3 are behind the sequence; 1 is the shot's first";
  const auto again = shot.storesFor(2.2, 2.4);
  ASSERT_EQ(again.size(), 1u);
  EXPECT_EQ(again[0].reader->meta().frame, 2);
}

// A caller that can only guess the time (retime reading the shot's own rate before it knows how
// output frames map onto source frames) still finds the shot when no store lies near the guess:
// the stored frame nearest to it.
TEST(ShotStores, AGuessFarFromEveryStoreFindsTheNearestStoredFrame) {
  ScratchDir dir;
  const std::string pattern = dir.path("far.####.mps");
  for (int64_t f : {3, 4, 9}) writeFrame(expandFramePattern(pattern, f), f);
  for (auto [guess, expected] : {std::pair{40.0, int64_t(9)}, std::pair{-20.0, int64_t(3)}, std::pair{6.7, int64_t(4)}}) {
    ShotStores shot(pattern, 0);
    EXPECT_EQ(shot.firstMeta(guess).frame, expected) << "guess " << guess;
  }
}
