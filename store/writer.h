// StoreWriter: streams grids of micropolygons into a .mps file with bounded memory.
//
// Micropolygons are assigned to tiles by their centroid in the primary camera's raster at the
// first knot where they lie in front of the near plane. Each (tile, motion schedule) accumulates
// a TilePart; full parts, and the largest ones whenever the buffered total exceeds the memory
// budget, are compressed (in parallel, with TBB) and appended to a temporary file, which close()
// completes with metadata, index and footer and renames into place. Nothing appears under the
// final name unless close() succeeds.
#pragma once

#include <cstdint>
#include <memory>
#include <string>

#include "store/format.h"
#include "store/model.h"

namespace reshutter::store {

struct WriterOptions {
  /// Bytes of unflushed micropolygon data. Each open tile holds at least 16 KB (two 8 KB chunks),
  /// and a grid is added whole before the budget is enforced.
  size_t memoryBudget = size_t(64) << 20;
  int zstdLevel = 3;
  uint32_t maxPartMicropolygons = 8192;
};

struct WriteStats {
  uint64_t micropolygons = 0, vertices = 0, parts = 0, tiles = 0;
  uint64_t stillMicropolygons = 0;  // of grids given several knots that stood still, stored static
  uint64_t rawBytes = 0, fileBytes = 0;
  uint64_t peakBufferedBytes = 0;
};

class StoreWriter final : public GridSink {
 public:
  StoreWriter(const std::string& path, StoreMeta meta, WriterOptions options = {});
  ~StoreWriter() override;
  StoreWriter(const StoreWriter&) = delete;
  StoreWriter& operator=(const StoreWriter&) = delete;

  /// Registers a motion schedule (knot times inside the shutter, strictly increasing) and returns
  /// its index for GridInput::schedule; identical schedules share an index. One knot = static (0).
  uint32_t addSchedule(const Schedule& knotTimes) override;

  /// Adds a grid. Throws Error (naming the grid id) on inconsistent input or non-finite values;
  /// the store is then unusable and close() will refuse.
  void addGrid(const GridInput& grid) override;

  /// Finishes the file and moves it into place.
  WriteStats close();

  const StoreMeta& meta() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace reshutter::store
