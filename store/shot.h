// The stores of a shot: one .mps per source frame, named by a frame pattern (`shot.####.mps`,
// common/frame_range.h). Owns finding which frames' stores a time interval needs, checking before
// any work that they all exist (one error listing every missing file), opening them on demand and
// releasing them once a forward-moving sequence no longer reaches them, and the rules that make a
// set of files one shot: each store holds the frame its name says and all share one shutter.
// A name without a placeholder is a shot of one store. Re-timing (resample/retime.h) turns the
// stores an interval needs into the re-sampler's sources.
//
// Time conventions (docs/resample.md): times are absolute source frames; frame F's store covers
// [F + open, F + close], its shutter relative to its own frame.
#pragma once

#include <cstdint>
#include <map>
#include <memory>
#include <string>
#include <vector>

#include "store/model.h"
#include "store/reader.h"

namespace reshutter::store {

/// One source frame's store.
struct FrameStore {
  std::shared_ptr<const StoreReader> reader;
  int64_t frame = 0;
};

/// The stores of a shot named by a frame pattern, opened on demand and kept while they are needed.
/// Every store must share the first one's shutter, and hold the frame its name says.
class ShotStores {
 public:
  /// `cacheBytes`: each store's decoded-part cache (ReaderOptions::cacheBytes).
  ShotStores(std::string pattern, size_t cacheBytes);
  /// Source frames whose stores an interval [t0, t1] (absolute source frames) needs: those whose
  /// coverage overlaps it with positive length, or holds the instant t0 = t1. The first call
  /// learns the shot's shutter from the store nearest t0 (an error when none is near).
  std::vector<int64_t> framesFor(double t0, double t1);
  /// Throws one Error listing every missing store among `frames`, before any work starts.
  void requireAll(const std::vector<int64_t>& frames) const;
  /// The stores covering [t0, t1], in frame order; releases stores no longer needed (frames
  /// before the interval's first), since sequences move forward in time.
  std::vector<FrameStore> storesFor(double t0, double t1);
  /// Metadata of the shot's first store opened (the one nearest `near` for a pattern).
  const StoreMeta& firstMeta(double near);
  /// The file name of `frame`'s store.
  std::string pathOf(int64_t frame) const;
  /// Frames whose stores are open now (for tests of the release rule).
  std::vector<int64_t> openFrames() const;

 private:
  std::shared_ptr<const StoreReader> open(int64_t frame);
  void probe(double near);
  std::string pattern_;
  size_t cacheBytes_;
  bool probed_ = false;
  double open_ = 0, close_ = 1;
  std::map<int64_t, std::shared_ptr<const StoreReader>> openStores_;
  std::shared_ptr<const StoreReader> first_;
};

}  // namespace reshutter::store
