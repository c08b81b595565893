// StoreReader: opens a .mps by memory-mapping it, validates header, footer, metadata and index,
// and decodes tile parts on demand. Every part decodes on its own; decoded parts live in an LRU
// cache bounded in bytes, shared safely by concurrent TBB tasks (a part requested by two tasks at
// once is decoded once). Any inconsistency is an Error naming the file and the tile.
#pragma once

#include <cstdint>
#include <functional>
#include <memory>
#include <string>
#include <vector>

#include "store/format.h"
#include "store/model.h"
#include "store/view_bounds.h"

namespace reshutter::store {

struct ReaderOptions {
  size_t cacheBytes = size_t(256) << 20;  // decoded parts kept; 0 = no cache (pure streaming)
  /// Drop a part's mapped pages once decoded, so resident memory stays at the cache budget
  /// instead of growing with the file (the pages stay in the OS page cache). Only done when the
  /// payload is larger than cacheBytes: below that, the mapped pages are bounded by the budget
  /// anyway, and dropping them costs cross-core TLB flushes.
  bool releasePages = true;
};

struct CacheStats {
  uint64_t hits = 0, misses = 0, evictions = 0;
  uint64_t releases = 0;  // parts dropped because their caller said it was done with them (release)
  uint64_t waits = 0;  // hits on a part another thread was still decoding (the caller waited)
  size_t bytes = 0, peakBytes = 0;
};

struct VerifyReport {
  uint64_t parts = 0, micropolygons = 0, vertices = 0;
};

class StoreReader {
 public:
  explicit StoreReader(const std::string& path, ReaderOptions options = {});
  ~StoreReader();
  StoreReader(const StoreReader&) = delete;
  StoreReader& operator=(const StoreReader&) = delete;

  const std::string& path() const;
  const StoreMeta& meta() const;
  const std::vector<TileEntry>& entries() const;
  uint64_t fileBytes() const;
  uint64_t micropolygonCount() const;
  /// "file: tile (tx,ty) part n" for messages.
  std::string where(size_t entry) const;

  /// Decodes a part without the cache, validating checksum, sizes, indices and finiteness.
  TilePart decode(size_t entry) const;
  /// Cached decode. A part another thread is decoding is waited for.
  std::shared_ptr<const TilePart> part(size_t entry) const;
  /// The caller needs this part no more: drop it from the cache now rather than when the LRU
  /// budget would, so that the memory it holds is reused by the next decode instead of new pages
  /// being touched. Holders of the part keep it; a part not cached or still decoding is left alone.
  void release(size_t entry) const;
  CacheStats cacheStats() const;

  /// Bound of a part over [t0, t1] in the primary camera's raster.
  RasterRect bounds(size_t entry, double t0, double t1) const;
  /// Every part's bounds in the primary camera (bounds() and visit() are its).
  const ViewBounds& primaryBounds() const;
  /// Calls fn(entry) for every part whose bound over [t0, t1] overlaps `rect`, in index order.
  /// With a lens (Camera::lens) each bound is first widened by the largest circle of confusion
  /// the part's depths take.
  void visit(const RasterRect& rect, double t0, double t1, const std::function<void(size_t)>& fn, const Lens& lens = {}) const;

  /// Decodes every part and checks every invariant (checksums, bounds hold at every knot, tile
  /// assignment, effect flags, payload ranges). Throws Error on the first violation.
  VerifyReport verify(const std::function<void(size_t done)>& progress = {}) const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace reshutter::store
