#include "store/shot.h"

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <sstream>

#include "common/error.h"
#include "common/frame_range.h"

namespace reshutter::store {

ShotStores::ShotStores(std::string pattern, size_t cacheBytes) : pattern_(std::move(pattern)), cacheBytes_(cacheBytes) {}

std::string ShotStores::pathOf(int64_t frame) const { return expandFramePattern(pattern_, frame); }

std::vector<int64_t> ShotStores::openFrames() const {
  std::vector<int64_t> frames;
  for (const auto& [frame, reader] : openStores_) frames.push_back(frame);
  return frames;
}

std::shared_ptr<const StoreReader> ShotStores::open(int64_t frame) {
  if (auto it = openStores_.find(frame); it != openStores_.end()) return it->second;
  ReaderOptions ro;
  ro.cacheBytes = cacheBytes_;
  auto reader = std::make_shared<const StoreReader>(pathOf(frame), ro);
  const auto& m = reader->meta();
  if (hasFramePlaceholder(pattern_) && m.frame != frame) fail(pathOf(frame), "the store says it holds frame ", m.frame, ", its name says frame ", frame);
  if (first_) {
    const auto& f = first_->meta();
    if (m.shutterOpen != f.shutterOpen || m.shutterClose != f.shutterClose)
      fail(pathOf(frame), "its shutter [", m.shutterOpen, ", ", m.shutterClose, "] differs from ", first_->path(), "'s [", f.shutterOpen, ", ", f.shutterClose,
           "]; a shot's stores must share one shutter");
  }
  openStores_[frame] = reader;
  return reader;
}

void ShotStores::probe(double near) {
  if (probed_) return;
  if (!hasFramePlaceholder(pattern_)) {
    ReaderOptions ro;
    ro.cacheBytes = cacheBytes_;
    first_ = std::make_shared<const StoreReader>(pattern_, ro);
    openStores_[first_->meta().frame] = first_;
  } else {
    // Learn the shot's shutter from the store nearest the first time asked for.
    const int64_t centre = int64_t(std::floor(near));
    for (int64_t d = 0; d <= 4 && !first_; ++d)
      for (int64_t f : {centre + d, centre - d})
        if (!first_ && std::filesystem::exists(pathOf(f))) first_ = open(f);
    if (!first_) {
      // Nothing near the time asked for (a caller may only guess it, as retime does for the
      // shot's own rate): the stored frame nearest to it, if the pattern matches any file.
      const std::vector<int64_t> onDisk = framesOnDisk(pattern_);
      if (!onDisk.empty()) {
        const auto after = std::lower_bound(onDisk.begin(), onDisk.end(), centre);
        const int64_t f = after == onDisk.end() ? onDisk.back() : after == onDisk.begin() || *after - centre <= centre - *(after - 1) ? *after : *(after - 1);
        first_ = open(f);
      }
    }
    if (!first_) fail(pattern_, "no store found near frame ", centre, " (looked for ", pathOf(centre), " and its neighbours) or anywhere the pattern matches");
  }
  open_ = first_->meta().shutterOpen, close_ = first_->meta().shutterClose;
  probed_ = true;
}

const StoreMeta& ShotStores::firstMeta(double near) {
  probe(near);
  return first_->meta();
}

std::vector<int64_t> ShotStores::framesFor(double t0, double t1) {
  probe(t0);
  if (!hasFramePlaceholder(pattern_)) return {first_->meta().frame};
  // Frame F covers [F + open, F + close]. It is needed when that overlaps [t0, t1] with positive
  // length, or holds the instant t0 = t1; a store that only touches the interval's end is not.
  std::vector<int64_t> frames;
  for (int64_t f = int64_t(std::floor(t0 - close_)) - 1; double(f) + open_ <= t1 + 1; ++f) {
    const double lo = double(f) + open_, hi = double(f) + close_;
    const bool overlaps = t0 < t1 ? (lo < t1 && hi > t0) || (lo == hi && lo >= t0 && lo <= t1) : (t0 >= lo && t0 <= hi);
    if (overlaps) frames.push_back(f);
  }
  return frames;
}

void ShotStores::requireAll(const std::vector<int64_t>& frames) const {
  std::vector<std::string> missing;
  for (int64_t f : frames)
    if (!openStores_.count(f) && !std::filesystem::exists(pathOf(f))) missing.push_back(pathOf(f));
  if (missing.empty()) return;
  std::ostringstream s;
  for (size_t i = 0; i < missing.size(); ++i) {
    if (i == 12) {
      s << " and " << missing.size() - 12 << " more";
      break;
    }
    s << (i ? ", " : "") << missing[i];
  }
  fail(pattern_, missing.size(), " store", missing.size() == 1 ? " is" : "s are", " missing: ", s.str());
}

std::vector<FrameStore> ShotStores::storesFor(double t0, double t1) {
  std::vector<int64_t> frames = framesFor(t0, t1);
  requireAll(frames);
  // Release stores this and later intervals no longer reach (sequences move forward in time).
  for (auto it = openStores_.begin(); it != openStores_.end();) {
    if (!frames.empty() && it->first < frames.front() && it->second != first_) it = openStores_.erase(it);
    else ++it;
  }
  std::vector<FrameStore> stores;
  for (int64_t f : frames) stores.push_back(FrameStore{open(f), f});
  return stores;
}

}  // namespace reshutter::store
