// Writes micropolygon grids as a RIB dump in the reference workflow's exact form
// (../shared/reference/000_*.txt): one motion-blurred PointsPolygons per grid under
// CoordSysTransform "camera", carrying the premultiplied shaded colour as "Cs", the opacity as
// "Os" and the shutter-close position as "blurP". Used by the benchmarks (store size vs gzipped
// RIB, parse throughput) and by the ingest tests as an input written by someone else's rules.
#pragma once

#include <memory>
#include <string>

#include "store/model.h"

namespace reshutter::bench {

class DumpRibWriter final : public store::GridSink {
 public:
  /// `gzip`: write through zlib at `level`. Camera and shutter come from `meta`.
  DumpRibWriter(const std::string& path, const store::StoreMeta& meta, bool gzip, int level = 6);
  ~DumpRibWriter() override;
  uint32_t addSchedule(const store::Schedule& knotTimes) override;
  /// Two-knot grids (schedule [open close]) become P + blurP; static grids P only.
  void addGrid(const store::GridInput& grid) override;
  void close();

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace reshutter::bench
