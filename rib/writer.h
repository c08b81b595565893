// RIB writer for micropolygon dumps in the reference workflow's exact form
// (../shared/reference/000_*.txt): a header stating camera and shutter, then one PointsPolygons
// per grid under CoordSysTransform "camera", carrying the premultiplied shaded colour as "Cs", the
// opacity as "Os" and, for moving grids, the shutter-close position as "blurP"; plain or gzipped.
// Numbers are written as the shortest text that reads back as the same float, so a dump parsed by
// rib::Reader gives back every value bit for bit.
//
// The writer knows RIB, not stores: it takes plain arrays, so that rib/ keeps depending on
// common/ only (the reader's users, the fuzz target among them, do not pull in the store). The
// store-facing part - a store::GridSink that turns StoreMeta and GridInput into these calls - is
// the thin adapter shade::DumpRibWriter (shade/dump_writer.h), next to the dump's reader
// (shade/ingest.h). Used by the ingest tests (an input written by someone else's rules) and the
// benchmarks (store size against gzipped RIB, parse and ingest throughput).
#pragma once

#include <cstdint>
#include <memory>
#include <span>
#include <string>

namespace reshutter::rib {

/// What a dump's header says: the frame, the camera (Format, Projection, ScreenWindow, Clipping)
/// and the shutter.
struct DumpHeader {
  int64_t frame = 1;
  int width = 640, height = 480;
  double pixelAspect = 1.0;
  bool perspective = true;
  double fovDegrees = 90.0;                 // perspective only
  double screenWindow[4] = {-1, 1, -1, 1};  // left right bottom top, written as given
  double nearClip = 1e-4, farClip = 1e30;
  double shutterOpen = 0.0, shutterClose = 1.0;
};

/// A corner index marking a polygon's fourth corner absent: the polygon is a triangle.
inline constexpr uint32_t kNoCorner = 0xffffffffu;

/// One grid, written as one PointsPolygons.
struct DumpGrid {
  uint32_t numVertices = 0;
  std::span<const uint32_t> corners;  // 4 per polygon, vertex indices; corners[4i+3] == kNoCorner: a triangle
  std::span<const float> P;           // 3 × numVertices: positions at shutter open (camera space)
  std::span<const float> blurP;       // empty (a static grid), or 3 × numVertices: positions at shutter close
  std::span<const float> Cs, Os;      // premultiplied colour and opacity, written as given
};

class DumpWriter {
 public:
  /// `gzip`: write through zlib at `level`. Throws Error naming `path` when it cannot be created.
  DumpWriter(const std::string& path, const DumpHeader& header, bool gzip, int level = 6);
  ~DumpWriter();
  void addGrid(const DumpGrid& grid);
  /// Ends the frame and closes the file; a failed write or gzip close throws Error.
  void close();
  const std::string& path() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace reshutter::rib
