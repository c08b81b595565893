// The .mps file layout and its tile index.
//
//   [header 16 B: magic "RSHUTMPS", u32 version, u32 reserved]
//   [tile part payloads: zstd frames, in the order the writer flushed them]
//   [metadata block]  [index block]
//   [footer 64 B: u64 meta offset/size/checksum, u64 index offset/size/checksum,
//                 magic "RSHUTEND", u32 version, u32 reserved]
//
// A tile is one cell of a sparse grid over the primary camera's raster (tileSize pixels square,
// unbounded integer coordinates). Each micropolygon lives in exactly one tile; a tile holds one or
// more *parts*, each self-contained (its own vertices, payload, checksum and bounds), because the
// writer flushes tiles in pieces to stay inside its memory budget and keeps micropolygons with
// different motion schedules apart. Index entries are sorted by tile (row-major), and within a
// tile by producer order.
#pragma once

#include <cstdint>
#include <limits>
#include <span>
#include <string>
#include <vector>

#include "common/bytes.h"
#include "store/model.h"

namespace reshutter::store {

constexpr char kHeaderMagic[8] = {'R', 'S', 'H', 'U', 'T', 'M', 'P', 'S'};
constexpr char kFooterMagic[8] = {'R', 'S', 'H', 'U', 'T', 'E', 'N', 'D'};
/// Version 2 adds StoreMeta::shadingTimes, version 3 the lights and the scene's volumes, version 4
/// each camera's lens (depth of field), version 5 each camera's motion; a store
/// is written as the lowest version that holds its metadata, so stores without them stay readable
/// by older builds, byte for byte as before.
constexpr uint32_t kFormatVersion = 5;
constexpr size_t kHeaderSize = 16;
constexpr size_t kFooterSize = 64;
/// Tile coordinate of micropolygons that never lie in front of the primary camera's near plane
/// during the shutter: kept (another camera may see them), never visited for the primary camera.
constexpr int32_t kBehindCameraTile = std::numeric_limits<int32_t>::min();
/// Hard caps that keep a corrupt index from requesting absurd allocations.
constexpr uint32_t kMaxPartMicropolygons = 1u << 22;
constexpr uint32_t kMaxPartVertices = 1u << 24;

/// Which effects a part needs; the resampler takes cheaper paths when bits are clear.
enum Effect : uint32_t {
  kEffectMoving = 1,            // some vertex position differs between knots
  kEffectTransparent = 2,       // some Oi channel < 1
  kEffectMatte = 4,             // some micropolygon is a matte (holdout)
  kEffectTwoSided = 8,          // some micropolygon is two-sided
  kEffectTriangles = 16,        // some micropolygon is a triangle
  kEffectNearCrossing = 32,     // at some knot a vertex lies before the near plane
  kEffectColouredOpacity = 64,  // some Oi has unequal channels
  kEffectShadedInTime = 128,    // its colours are given at every StoreMeta::shadingTimes ("Ci@k", "Oi@k")
};
std::string effectNames(uint32_t effects);

/// Conservative bounds of a part at one motion knot.
struct KnotBounds {
  float raster[4] = {0, 0, 0, 0};        // x0 y0 x1 y1 in the primary camera's raster (valid if rasterFinite)
  float camera[6] = {0, 0, 0, 0, 0, 0};  // camera-space box: min xyz, max xyz
  bool rasterFinite = true;              // false when some vertex is before the near plane at this knot
};

struct TileEntry {
  int32_t tx = 0, ty = 0;
  uint32_t schedule = 0;
  uint32_t numMicropolygons = 0, numVertices = 0;
  uint32_t effects = 0;
  uint64_t attrPresence = 0;  // bit i: schema attribute i stored in this part
  uint64_t offset = 0;
  uint32_t compressedSize = 0, rawSize = 0;
  uint64_t checksum = 0;
  std::vector<KnotBounds> knots;  // one per knot of the schedule
};

/// A raster-space rectangle; `empty` means nothing can be visible.
struct RasterRect {
  float x0 = 0, y0 = 0, x1 = 0, y1 = 0;
  bool empty = true;
  bool overlaps(const RasterRect& o) const { return !empty && !o.empty && x0 <= o.x1 && o.x0 <= x1 && y0 <= o.y1 && o.y0 <= y1; }
  void extend(const RasterRect& o);
};

/// Bound of a part over the time interval [t0, t1] for the primary camera. Between knots
/// positions are linear in camera space, so while every vertex stays in front of the near plane
/// the screen path of each vertex is a straight segment and the union of the knots' raster boxes
/// bounds the interval; otherwise the near-clipped camera-space box is projected instead.
/// The camera-space box of a part `f` of the way between two knots' boxes `a` and `b`: positions
/// are linear in camera space there, so it holds every vertex at that time. Widened by a relative
/// 1e-6 for the float arithmetic that interpolates positions downstream.
void lerpedCameraBox(const float a[6], const float b[6], double f, float out[6]);

RasterRect boundsOver(const TileEntry& entry, const Schedule& schedule, const Projector& projector, double t0, double t1);

/// Projects a camera-space box clipped to z >= near (perspective) or as is (orthographic).
RasterRect projectCameraBox(const float box[6], const Projector& projector);

/// Range of knot indices whose segments cover [t0, t1] (clamped to the schedule's ends).
void knotRange(const Schedule& schedule, double t0, double t1, size_t& first, size_t& last);

/// The format version a store with this metadata is written as (1 unless it shades in time).
uint32_t formatVersionFor(const StoreMeta& meta);
void writeMeta(const StoreMeta& meta, ByteWriter& out);
/// Reads metadata written as format `version`.
StoreMeta readMeta(ByteReader& in, uint32_t version);
void writeIndex(const std::vector<TileEntry>& entries, const StoreMeta& meta, ByteWriter& out);
std::vector<TileEntry> readIndex(ByteReader& in, const StoreMeta& meta);

}  // namespace reshutter::store
