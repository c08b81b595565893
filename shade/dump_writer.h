// Store grids written as a RIB micropolygon dump: the store::GridSink face of rib::DumpWriter
// (rib/writer.h), the mirror of dump ingest (shade/ingest.h). It turns the store's camera and
// shutter into the dump's header and each grid into the reference form's PointsPolygons: Ci as
// "Cs", Oi as "Os", and a two-knot grid's second knot as "blurP". The RIB itself is rib/'s; this
// adapter lives here because shade/ is the first module that sees both the store and RIB.
#pragma once

#include <string>
#include <vector>

#include "rib/writer.h"
#include "store/model.h"

namespace reshutter::shade {

class DumpRibWriter final : public store::GridSink {
 public:
  /// `gzip`: write through zlib at `level`. Camera and shutter come from `meta`.
  DumpRibWriter(const std::string& path, const store::StoreMeta& meta, bool gzip, int level = 6);
  uint32_t addSchedule(const store::Schedule& knotTimes) override;
  /// Two-knot grids (schedule [open close]) become P + blurP; static grids P only. More knots
  /// than two are an Error: the blurP form cannot hold them.
  void addGrid(const store::GridInput& grid) override;
  void close() { rib_.close(); }

 private:
  rib::DumpWriter rib_;
  std::vector<store::Schedule> schedules_{store::Schedule{0.0}};
  int ci_ = -1, oi_ = -1;
};

}  // namespace reshutter::shade
