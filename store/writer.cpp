#include "store/writer.h"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <unordered_map>

#include <tbb/parallel_for.h>

#include "common/atomic_file.h"
#include "common/error.h"
#include "store/codec.h"

namespace reshutter::store {
namespace {

struct TileKey {
  int32_t tx, ty;
  uint32_t schedule;
  bool shadedInTime;  // its grids carry colours at every shading time (parts stay homogeneous)
  bool operator==(const TileKey&) const = default;
  auto order() const { return std::tuple(ty, tx, schedule, shadedInTime); }
};
struct TileKeyHash {
  size_t operator()(const TileKey& k) const {
    uint64_t h = (uint64_t(uint32_t(k.tx)) << 32 | uint32_t(k.ty)) ^ ((uint64_t(k.schedule) * 2 + k.shadedInTime) * 0x9E3779B97F4A7C15ull);
    h ^= h >> 31;
    h *= 0xBF58476D1CE4E5B9ull;
    return size_t(h ^ (h >> 29));
  }
};

constexpr int32_t kTileCoordLimit = 1 << 30;

// Fixed-size chunks of 32-bit words, recycled for the writer's lifetime. Tile builders append
// into chunks instead of growing vectors: thousands of partly filled tiles would otherwise
// reallocate and copy their arrays, and every fresh allocation costs page faults.
constexpr size_t kChunkWords = 2048;

class ChunkPool {
 public:
  uint32_t* take() {
    if (free_.empty()) {
      constexpr size_t kSlabChunks = 64;
      slabs_.emplace_back(new uint32_t[kChunkWords * kSlabChunks]);
      for (size_t i = 0; i < kSlabChunks; ++i) free_.push_back(slabs_.back().get() + i * kChunkWords);
    }
    uint32_t* c = free_.back();
    free_.pop_back();
    ++inUse_;
    return c;
  }
  void give(uint32_t* c) {
    free_.push_back(c);
    --inUse_;
  }
  size_t bytesInUse() const { return inUse_ * kChunkWords * 4; }

 private:
  std::vector<std::unique_ptr<uint32_t[]>> slabs_;
  std::vector<uint32_t*> free_;
  size_t inUse_ = 0;
};

// Append-only fixed-size records in pool chunks.
class RecordLog {
 public:
  void reset(uint32_t recordWords) {
    words_ = recordWords;
    perChunk_ = uint32_t(kChunkWords / recordWords);
    count_ = 0;
  }
  uint32_t* append(ChunkPool& pool) {
    if (count_ == chunks_.size() * perChunk_) chunks_.push_back(pool.take());
    uint32_t* r = chunks_.back() + (count_ % perChunk_) * words_;
    ++count_;
    return r;
  }
  const uint32_t* record(size_t i) const { return chunks_[i / perChunk_] + (i % perChunk_) * words_; }
  size_t size() const { return count_; }
  size_t chunkCount() const { return chunks_.size(); }
  void release(ChunkPool& pool) {
    for (uint32_t* c : chunks_) pool.give(c);
    chunks_.clear();
    count_ = 0;
  }

 private:
  std::vector<uint32_t*> chunks_;
  uint32_t words_ = 1, perChunk_ = 1;
  size_t count_ = 0;
};

// Record layouts. Vertex: K×3 position words, then every vertex-rate attribute of the schema
// (zeros where a grid lacks it). Micropolygon: 4 corners, object id, grid id, flags, then every
// micropolygon-rate attribute. A part of grids shaded once has no words for the attributes
// carried at later shading times ("Ci@k", ...): its parts never hold them, and most grids of a
// frame shaded in time are shaded once.
struct RecordLayout {
  struct Field {  // one attribute of the record tail
    uint32_t attr, offset;
    int components;
    bool isUInt, isOpacity;
  };
  std::vector<Field> fields[2];  // by AttrRate: the attributes the record holds, in schema order
  uint32_t vertexAttrWords = 0, mpAttrWords = 0;
  static constexpr uint32_t kMpFixedWords = 7;
  RecordLayout(const Schema& schema, bool withTimed) {
    for (uint32_t ai = 0; ai < schema.attrs.size(); ++ai) {
      const auto& a = schema.attrs[ai];
      if (!withTimed && StoreMeta::timedIndex(a.name)) continue;
      uint32_t& words = a.rate == AttrRate::Vertex ? vertexAttrWords : mpAttrWords;
      const int nc = componentCount(a.type);
      fields[size_t(a.rate)].push_back(Field{ai, words, nc, a.type == AttrType::UInt, StoreMeta::timedBase(a.name) == "Oi"});
      words += uint32_t(nc);
    }
  }
  uint32_t vertexWords(uint32_t knots) const { return 3 * knots + vertexAttrWords; }
  uint32_t mpWords() const { return kMpFixedWords + mpAttrWords; }
  const std::vector<Field>& of(AttrRate rate) const { return fields[size_t(rate)]; }
};

struct Builder {
  TileKey key;
  uint32_t numKnots = 1;
  RecordLog vertices, mps;
  uint64_t presence = 0;
  uint32_t effects = 0;
  std::vector<KnotBounds> bounds;
  uint32_t stamp = 0;

  void reset(const TileKey& k, uint32_t knots, const RecordLayout& layout) {
    key = k;
    numKnots = knots;
    vertices.reset(layout.vertexWords(knots));
    mps.reset(layout.mpWords());
    presence = 0;
    effects = k.shadedInTime ? uint32_t(kEffectShadedInTime) : 0u;
    bounds.assign(knots, KnotBounds{});
    for (auto& kb : bounds) {
      kb.raster[0] = kb.raster[1] = INFINITY, kb.raster[2] = kb.raster[3] = -INFINITY;
      for (int i = 0; i < 3; ++i) kb.camera[i] = INFINITY, kb.camera[i + 3] = -INFINITY;
    }
  }
  size_t chunks() const { return vertices.chunkCount() + mps.chunkCount(); }
  uint32_t numMicropolygons() const { return uint32_t(mps.size()); }
};

// Unpacks a builder's records into the structure-of-arrays part the codec encodes.
void unpack(const Builder& b, const Schema& schema, const RecordLayout& layout, TilePart& part) {
  const uint32_t nV = uint32_t(b.vertices.size()), nMp = uint32_t(b.mps.size()), K = b.numKnots;
  part.numVertices = nV, part.numMicropolygons = nMp, part.numKnots = K;
  part.positions.resize(size_t(K) * nV);
  part.corners.resize(size_t(nMp) * 4);
  part.objectId.resize(nMp), part.gridId.resize(nMp), part.flags.resize(nMp);
  part.attrs.resize(schema.attrs.size());
  for (size_t ai = 0; ai < schema.attrs.size(); ++ai) {
    const auto& a = schema.attrs[ai];
    auto& arr = part.attrs[ai];
    const size_t n = (b.presence >> ai & 1) ? size_t(a.rate == AttrRate::Vertex ? nV : nMp) * componentCount(a.type) : 0;
    if (a.type == AttrType::UInt) arr.u.resize(n), arr.f.clear();
    else arr.f.resize(n), arr.u.clear();
  }
  // The fields this part holds (the builder set a presence bit for each attribute it stored).
  auto present = [&](AttrRate rate) {
    std::vector<RecordLayout::Field> out;
    for (const RecordLayout::Field& f : layout.of(rate))
      if (b.presence >> f.attr & 1) out.push_back(f);
    return out;
  };
  auto copyFields = [&](const std::vector<RecordLayout::Field>& fields, const uint32_t* tail, size_t element) {
    for (const RecordLayout::Field& f : fields) {
      if (f.isUInt) part.attrs[f.attr].u[element] = tail[f.offset];
      else std::memcpy(&part.attrs[f.attr].f[element * size_t(f.components)], tail + f.offset, size_t(f.components) * 4);
    }
  };
  const std::vector<RecordLayout::Field> vertexFields = present(AttrRate::Vertex), mpFields = present(AttrRate::Micropolygon);
  for (uint32_t v = 0; v < nV; ++v) {
    const uint32_t* r = b.vertices.record(v);
    for (uint32_t k = 0; k < K; ++k) std::memcpy(&part.positions[size_t(k) * nV + v], r + 3 * k, 12);
    copyFields(vertexFields, r + 3 * K, v);
  }
  for (uint32_t m = 0; m < nMp; ++m) {
    const uint32_t* r = b.mps.record(m);
    std::memcpy(&part.corners[size_t(m) * 4], r, 16);
    part.objectId[m] = r[4], part.gridId[m] = r[5], part.flags[m] = uint8_t(r[6]);
    copyFields(mpFields, r + RecordLayout::kMpFixedWords, m);
  }
}

// A part ready to be encoded: its index entry (bounds filled) and its builder.
struct PendingPart {
  TileEntry entry;
  std::unique_ptr<Builder> builder;
  std::vector<uint8_t> compressed;
};

}  // namespace

struct StoreWriter::Impl {
  StoreMeta meta;
  WriterOptions options;
  AtomicFile file;
  uint64_t offset = kHeaderSize;
  Projector projector;
  std::unordered_map<TileKey, std::unique_ptr<Builder>, TileKeyHash> builders;
  std::vector<std::unique_ptr<Builder>> full;
  std::vector<std::unique_ptr<Builder>> spareBuilders;
  ChunkPool chunks;
  RecordLayout layouts[2];  // [shaded in time]: a part's records hold the later times' attributes only when its grids carry them
  std::vector<TileEntry> entries;
  bool failed = false, closed = false;
  WriteStats stats;
  uint32_t stampCounter = 0;
  // The grid being added: its schedule and positions as stored (static when it stands still).
  uint32_t gridSchedule = 0;
  std::span<const glm::vec3> gridPositions;
  bool gridShadedInTime = false;
  // Per schema attribute: an opacity ("Oi" or "Oi@k"), whose values set the transparency effects.
  int firstTimedColour = -1;  // "Ci@1": present in a grid that is shaded in time
  // Per-grid scratch, reused.
  std::vector<glm::dvec2> raster;  // knot-major
  std::vector<uint8_t> inFront;    // knot-major
  std::vector<uint32_t> stamps, local;
  std::vector<uint32_t> mpSlot, slotStart, slotFill, bySlot;
  std::vector<TileKey> slotKeys;
  std::unordered_map<TileKey, uint32_t, TileKeyHash> slotMap;  // used once a grid spans many tiles

  uint32_t slotOf(const TileKey& key) {
    if (slotKeys.size() <= 8) {
      for (uint32_t s = 0; s < slotKeys.size(); ++s)
        if (slotKeys[s] == key) return s;
      if (slotKeys.size() < 8) {
        slotKeys.push_back(key);
        return uint32_t(slotKeys.size() - 1);
      }
      for (uint32_t s = 0; s < slotKeys.size(); ++s) slotMap.emplace(slotKeys[s], s);
    }
    auto [it, inserted] = slotMap.emplace(key, uint32_t(slotKeys.size()));
    if (inserted) slotKeys.push_back(key);
    return it->second;
  }

  Impl(const std::string& path, StoreMeta m, WriterOptions o) : meta(std::move(m)), options(o), file(path), projector(meta.cameras.at(0)), layouts{RecordLayout(meta.schema, false), RecordLayout(meta.schema, true)} {
    if (meta.shadingTimes.size() > 1) firstTimedColour = meta.schema.find(StoreMeta::timedName("Ci", 1));
    char header[kHeaderSize] = {};
    std::copy(std::begin(kHeaderMagic), std::end(kHeaderMagic), header);
    uint32_t v = formatVersionFor(meta);
    std::memcpy(header + 8, &v, 4);
    writeAll(file.fd(), header, kHeaderSize, file.tempPath());
    if (options.maxPartMicropolygons == 0 || options.maxPartMicropolygons > kMaxPartMicropolygons) options.maxPartMicropolygons = kMaxPartMicropolygons;
  }

  std::string where() const { return file.finalPath(); }

  // Stamps mark which grid vertices a builder already holds during the current grid; they only
  // ever grow, so a stale stamp can never match. On wrap-around the table is cleared.
  uint32_t nextStamp() {
    if (stampCounter == 0xffffffffu) {
      std::fill(stamps.begin(), stamps.end(), 0u);
      stampCounter = 0;
    }
    return ++stampCounter;
  }

  Builder& builderFor(const TileKey& key) {
    auto it = builders.find(key);
    if (it != builders.end()) return *it->second;
    std::unique_ptr<Builder> b;
    if (!spareBuilders.empty()) {
      b = std::move(spareBuilders.back());
      spareBuilders.pop_back();
    } else {
      b = std::make_unique<Builder>();
    }
    b->reset(key, uint32_t(meta.schedules[key.schedule].size()), layouts[key.shadedInTime]);
    b->stamp = nextStamp();
    return *builders.emplace(key, std::move(b)).first->second;
  }

  void retire(const TileKey& key) {
    auto it = builders.find(key);
    full.push_back(std::move(it->second));
    builders.erase(it);
  }

  // A grid that gives "Ci@1" carries its shading at every time (validate() checks the rest).
  bool shadedInTime(const GridInput& g) const {
    return firstTimedColour >= 0 && size_t(firstTimedColour) < g.attrs.size() && g.attrs[size_t(firstTimedColour)].present();
  }

  void validate(const GridInput& g) const {
    std::string w = cat(where(), ": grid ", g.gridId, " (object ", g.objectId, ")");
    if (g.schedule >= meta.schedules.size()) fail(w, "names motion schedule ", g.schedule, " but only ", meta.schedules.size(), " exist");
    const size_t K = meta.schedules[g.schedule].size();
    if (g.positions.size() != K * g.numVertices) fail(w, "has ", g.positions.size(), " positions; expected ", K, " knots x ", g.numVertices, " vertices");
    if (g.corners.size() % 4) fail(w, "corner list length ", g.corners.size(), " is not a multiple of 4");
    if (g.numVertices > kMaxPartVertices) fail(w, "has ", g.numVertices, " vertices (at most ", kMaxPartVertices, ")");
    for (size_t i = 0; i < g.positions.size(); ++i) {
      const auto& p = g.positions[i];
      if (!std::isfinite(p.x) || !std::isfinite(p.y) || !std::isfinite(p.z))
        fail(w, "vertex ", i % g.numVertices, " at knot ", i / g.numVertices, " has a non-finite position");
    }
    const size_t nMp = g.numMicropolygons();
    for (size_t i = 0; i < nMp; ++i)
      for (int j = 0; j < 4; ++j) {
        uint32_t c = g.corners[i * 4 + j];
        if (c >= g.numVertices && !(j == 3 && c == kNoCorner)) fail(w, "micropolygon ", i, " corner ", j, " names vertex ", c, " of ", g.numVertices);
      }
    if (!g.attrs.empty() && g.attrs.size() != meta.schema.attrs.size())
      fail(w, "gives ", g.attrs.size(), " attribute slots; the schema has ", meta.schema.attrs.size());
    const bool timed = shadedInTime(g);
    for (size_t ai = 0; ai < meta.schema.attrs.size(); ++ai) {
      const auto& a = meta.schema.attrs[ai];
      bool present = ai < g.attrs.size() && g.attrs[ai].present();
      if (!present) {
        if (a.name == "Ci" || a.name == "Oi") fail(w, "lacks '", a.name, "'");
        if (timed && StoreMeta::timedIndex(a.name)) fail(w, "is shaded in time but lacks '", a.name, "'");
        continue;
      }
      if (!timed && StoreMeta::timedIndex(a.name)) fail(w, "gives '", a.name, "' without 'Ci@1'");
      const auto& v = g.attrs[ai];
      size_t count = a.rate == AttrRate::Vertex ? g.numVertices : nMp;
      size_t expected = count * componentCount(a.type);
      size_t given = a.type == AttrType::UInt ? v.u.size() : v.f.size();
      if (given != expected) fail(w, "attribute '", a.name, "' has ", given, " values; expected ", expected);
      for (size_t i = 0; i < v.f.size(); ++i)
        if (!std::isfinite(v.f[i])) fail(w, "attribute '", a.name, "' value ", i, " is not finite");
    }
  }

  void addGrid(const GridInput& g) {
    if (closed || failed) fail(where(), "writer is closed or failed earlier");
    try {
      validate(g);
    } catch (...) {
      failed = true;
      throw;
    }
    const size_t nMp = g.numMicropolygons();
    if (nMp == 0) return;
    // A grid that stands still is stored static whatever knots it came with: one position per
    // vertex, and parts whose effects say "static", which re-sampling draws on its static path.
    gridSchedule = g.schedule, gridPositions = g.positions;
    gridShadedInTime = shadedInTime(g);
    meta.shadedInTimeGrids += gridShadedInTime;
    if (meta.schedules[g.schedule].size() > 1 && g.standsStill()) {
      gridSchedule = 0, gridPositions = g.positions.first(g.numVertices);
      stats.stillMicropolygons += nMp;
    }
    const uint32_t nV = g.numVertices, K = uint32_t(meta.schedules[gridSchedule].size());

    raster.resize(size_t(K) * nV);
    inFront.resize(size_t(K) * nV);
    for (size_t i = 0; i < size_t(K) * nV; ++i) {
      glm::dvec3 p(gridPositions[i]);
      bool front = !projector.perspective || p.z >= projector.nearClip;
      inFront[i] = front;
      raster[i] = front ? projector.project(p) : glm::dvec2(0.0);
    }

    // Tile of each micropolygon, and the distinct tiles in order of first appearance.
    mpSlot.resize(nMp);
    slotKeys.clear();
    slotMap.clear();
    const double invTile = 1.0 / meta.tileSize;
    for (size_t i = 0; i < nMp; ++i) {
      const uint32_t* c = &g.corners[i * 4];
      int nc = c[3] == kNoCorner ? 3 : 4;
      TileKey key{kBehindCameraTile, kBehindCameraTile, gridSchedule, gridShadedInTime};
      for (uint32_t k = 0; k < K; ++k) {
        size_t base = size_t(k) * nV;
        bool front = true;
        for (int j = 0; j < nc; ++j) front = front && inFront[base + c[j]];
        if (!front) continue;
        glm::dvec2 centre(0.0);
        for (int j = 0; j < nc; ++j) centre += raster[base + c[j]];
        centre /= double(nc);
        auto coord = [&](double v) { return int32_t(std::clamp(std::floor(v * invTile), double(-kTileCoordLimit), double(kTileCoordLimit))); };
        key.tx = coord(centre.x), key.ty = coord(centre.y);
        break;
      }
      mpSlot[i] = slotOf(key);
    }
    // Group the micropolygons by tile (a counting sort keeps the producer's order in each).
    slotStart.assign(slotKeys.size() + 1, 0);
    for (size_t i = 0; i < nMp; ++i) ++slotStart[mpSlot[i] + 1];
    for (size_t s = 0; s < slotKeys.size(); ++s) slotStart[s + 1] += slotStart[s];
    bySlot.resize(nMp);
    {
      std::vector<uint32_t>& fillPos = slotFill;
      fillPos.assign(slotStart.begin(), slotStart.end() - 1);
      for (size_t i = 0; i < nMp; ++i) bySlot[fillPos[mpSlot[i]]++] = uint32_t(i);
    }

    if (stamps.size() < nV) stamps.resize(nV, 0), local.resize(nV);
    for (uint32_t slot = 0; slot < slotKeys.size(); ++slot) {
      Builder* b = &builderFor(slotKeys[slot]);
      b->stamp = nextStamp();  // vertex indices are per grid: a fresh stamp per (builder, grid)
      for (uint32_t n = slotStart[slot]; n < slotStart[slot + 1]; ++n) {
        const uint32_t i = bySlot[n];
        if (b->numMicropolygons() >= options.maxPartMicropolygons) {
          retire(b->key);
          b = &builderFor(slotKeys[slot]);
        }
        addMicropolygon(*b, g, i, K);
      }
    }
    stats.micropolygons += nMp;
    // Only the tiles this grid touched can have filled up.
    for (const TileKey& key : slotKeys) {
      auto it = builders.find(key);
      if (it != builders.end() && it->second->numMicropolygons() >= options.maxPartMicropolygons) retire(key);
    }
    stats.peakBufferedBytes = std::max<uint64_t>(stats.peakBufferedBytes, chunks.bytesInUse());
    if (chunks.bytesInUse() > options.memoryBudget) spillLargest();
    if (full.size() >= 32) writeFull();
  }

  void addMicropolygon(Builder& b, const GridInput& g, size_t i, uint32_t K) {
    const uint32_t* c = &g.corners[i * 4];
    uint32_t localCorners[4];
    for (int j = 0; j < 4; ++j) {
      uint32_t v = c[j];
      if (v == kNoCorner) {
        localCorners[j] = kNoCorner;
        b.effects |= kEffectTriangles;
        continue;
      }
      if (stamps[v] != b.stamp) {
        stamps[v] = b.stamp;
        local[v] = uint32_t(b.vertices.size());
        addVertex(b, g, v, K);
      }
      localCorners[j] = local[v];
    }
    uint32_t* r = b.mps.append(chunks);
    std::memcpy(r, localCorners, 16);
    r[4] = g.objectId, r[5] = g.gridId, r[6] = g.flags;
    if (g.flags & kMatte) b.effects |= kEffectMatte;
    if (g.flags & kTwoSided) b.effects |= kEffectTwoSided;
    packAttributes(b, g, AttrRate::Micropolygon, i, r + RecordLayout::kMpFixedWords);
  }

  // Copies element `element`'s attributes of one rate (per micropolygon or per vertex) into a
  // record's attribute words; an attribute the grid lacks is zero.
  void packAttributes(Builder& b, const GridInput& g, AttrRate rate, size_t element, uint32_t* tail) {
    for (const RecordLayout::Field& f : layouts[b.key.shadedInTime].of(rate)) {
      uint32_t* dst = tail + f.offset;
      if (f.attr >= g.attrs.size() || !g.attrs[f.attr].present()) {
        std::fill(dst, dst + f.components, 0u);
        continue;
      }
      if (f.isUInt) {
        dst[0] = g.attrs[f.attr].u[element];
      } else {
        const float* src = &g.attrs[f.attr].f[element * size_t(f.components)];
        std::memcpy(dst, src, size_t(f.components) * 4);
        if (f.isOpacity) noteOpacity(b, src);
      }
      b.presence |= uint64_t(1) << f.attr;
    }
  }

  static void noteOpacity(Builder& b, const float* o) {
    if (o[0] < 1.0f || o[1] < 1.0f || o[2] < 1.0f) b.effects |= kEffectTransparent;
    if (o[0] != o[1] || o[1] != o[2]) b.effects |= kEffectColouredOpacity;
  }

  void addVertex(Builder& b, const GridInput& g, uint32_t v, uint32_t K) {
    const uint32_t nV = g.numVertices;
    uint32_t* r = b.vertices.append(chunks);
    const glm::vec3& p0 = gridPositions[v];
    for (uint32_t k = 0; k < K; ++k) {
      const size_t src = size_t(k) * nV + v;
      const glm::vec3& p = gridPositions[src];
      std::memcpy(r + 3 * k, &p, 12);
      if (p != p0) b.effects |= kEffectMoving;
      KnotBounds& kb = b.bounds[k];
      for (int a = 0; a < 3; ++a) kb.camera[a] = std::min(kb.camera[a], p[a]), kb.camera[a + 3] = std::max(kb.camera[a + 3], p[a]);
      if (inFront[src]) {
        const float rx = float(std::clamp(raster[src].x, -1e30, 1e30)), ry = float(std::clamp(raster[src].y, -1e30, 1e30));
        kb.raster[0] = std::min(kb.raster[0], rx), kb.raster[1] = std::min(kb.raster[1], ry);
        kb.raster[2] = std::max(kb.raster[2], rx), kb.raster[3] = std::max(kb.raster[3], ry);
        // float() may round inwards; finishPart() widens every box by a margin that covers it.
      } else {
        kb.rasterFinite = false;
        b.effects |= kEffectNearCrossing;
      }
    }
    packAttributes(b, g, AttrRate::Vertex, v, r + 3 * K);
  }

  void spillLargest() {
    std::vector<Builder*> order;
    order.reserve(builders.size());
    for (auto& [k, b] : builders) order.push_back(b.get());
    std::sort(order.begin(), order.end(),
              [](const Builder* a, const Builder* b) { return a->chunks() != b->chunks() ? a->chunks() > b->chunks() : a->key.order() < b->key.order(); });
    // Retired builders hold their chunks until written, so count what stays behind.
    size_t remaining = chunks.bytesInUse();
    for (Builder* b : order) {
      if (remaining <= options.memoryBudget * 3 / 4) break;
      remaining -= b->chunks() * kChunkWords * 4;
      retire(b->key);
    }
    writeFull();
  }

  PendingPart finishPart(std::unique_ptr<Builder> owned) {
    PendingPart p;
    const Builder& b = *owned;
    TileEntry& e = p.entry;
    e.tx = b.key.tx, e.ty = b.key.ty, e.schedule = b.key.schedule;
    e.numMicropolygons = uint32_t(b.mps.size());
    e.numVertices = uint32_t(b.vertices.size());
    e.effects = b.effects;
    e.attrPresence = b.presence;
    e.knots = b.bounds;
    // Round the raster boxes outwards by a relative margin: they were accumulated in float from
    // double projections, and consumers project in float.
    for (auto& kb : e.knots) {
      if (!kb.rasterFinite) {
        for (float& v : kb.raster) v = 0;
        continue;
      }
      for (int i = 0; i < 4; ++i) {
        float v = kb.raster[i];
        float margin = 1e-5f * std::max(1.0f, std::abs(v)) + 1e-3f;
        kb.raster[i] = i < 2 ? v - margin : v + margin;
      }
    }
    p.builder = std::move(owned);
    return p;
  }

  void writeFull() {
    if (full.empty()) return;
    std::vector<PendingPart> parts;
    parts.reserve(full.size());
    for (auto& b : full) parts.push_back(finishPart(std::move(b)));
    full.clear();
    const int level = options.zstdLevel;
    const Schema& schema = meta.schema;
    tbb::parallel_for(size_t(0), parts.size(), [&](size_t i) {
      auto& p = parts[i];
      thread_local std::vector<uint8_t> raw;
      thread_local TilePart part;
      unpack(*p.builder, schema, layouts[p.builder->key.shadedInTime], part);
      encodeRaw(schema, part, p.entry.attrPresence, raw);
      compress(raw, level, p.compressed);
      p.entry.rawSize = uint32_t(raw.size());
      p.entry.compressedSize = uint32_t(p.compressed.size());
      p.entry.checksum = checksum(p.compressed);
    });
    for (auto& p : parts) {
      writeAll(file.fd(), p.compressed.data(), p.compressed.size(), file.tempPath());
      p.entry.offset = offset;
      offset += p.compressed.size();
      stats.rawBytes += p.entry.rawSize;
      stats.vertices += p.entry.numVertices;
      ++stats.parts;
      entries.push_back(std::move(p.entry));
      p.builder->vertices.release(chunks);
      p.builder->mps.release(chunks);
      if (spareBuilders.size() < 256) spareBuilders.push_back(std::move(p.builder));
    }
  }

  WriteStats close() {
    if (closed) fail(where(), "already closed");
    if (failed) fail(where(), "an earlier error left the store incomplete; not writing it");
    std::vector<TileKey> keys;
    for (auto& [k, b] : builders) keys.push_back(k);
    std::sort(keys.begin(), keys.end(), [](const TileKey& a, const TileKey& b) { return a.order() < b.order(); });
    for (const auto& k : keys) retire(k);
    writeFull();
    std::stable_sort(entries.begin(), entries.end(), [](const TileEntry& a, const TileEntry& b) {
      return std::tuple(a.ty, a.tx, a.schedule, a.offset) < std::tuple(b.ty, b.tx, b.schedule, b.offset);
    });
    for (size_t i = 0; i < entries.size(); ++i)
      if (i == 0 || entries[i].tx != entries[i - 1].tx || entries[i].ty != entries[i - 1].ty) ++stats.tiles;

    ByteWriter metaBytes, indexBytes;
    writeMeta(meta, metaBytes);
    writeIndex(entries, meta, indexBytes);
    uint64_t metaOffset = offset, indexOffset = offset + metaBytes.size();
    writeAll(file.fd(), metaBytes.bytes().data(), metaBytes.size(), file.tempPath());
    writeAll(file.fd(), indexBytes.bytes().data(), indexBytes.size(), file.tempPath());
    ByteWriter footer;
    footer.put<uint64_t>(metaOffset);
    footer.put<uint64_t>(metaBytes.size());
    footer.put<uint64_t>(checksum(metaBytes.bytes()));
    footer.put<uint64_t>(indexOffset);
    footer.put<uint64_t>(indexBytes.size());
    footer.put<uint64_t>(checksum(indexBytes.bytes()));
    footer.putBytes(kFooterMagic, 8);
    footer.put<uint32_t>(formatVersionFor(meta));
    footer.put<uint32_t>(0);
    writeAll(file.fd(), footer.bytes().data(), footer.size(), file.tempPath());
    stats.fileBytes = indexOffset + indexBytes.size() + footer.size();
    file.commit();
    closed = true;
    return stats;
  }
};

StoreWriter::StoreWriter(const std::string& path, StoreMeta meta, WriterOptions options) {
  meta.validate(path);
  impl_ = std::make_unique<Impl>(path, std::move(meta), options);
}

StoreWriter::~StoreWriter() = default;

uint32_t StoreWriter::addSchedule(const Schedule& knots) {
  auto& m = impl_->meta;
  if (knots.size() == 1) return 0;
  for (size_t i = 1; i < m.schedules.size(); ++i)
    if (m.schedules[i] == knots) return uint32_t(i);
  StoreMeta probe;
  probe.shutterOpen = m.shutterOpen;
  probe.shutterClose = m.shutterClose;
  probe.schedules = {Schedule{0.0}, knots};
  probe.cameras = m.cameras;
  probe.schema = m.schema;
  probe.shadingTimes = m.shadingTimes;
  probe.validate(impl_->where());
  m.schedules.push_back(knots);
  return uint32_t(m.schedules.size() - 1);
}

void StoreWriter::addGrid(const GridInput& grid) { impl_->addGrid(grid); }
WriteStats StoreWriter::close() { return impl_->close(); }
const StoreMeta& StoreWriter::meta() const { return impl_->meta; }

}  // namespace reshutter::store
