#include "store/reader.h"

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstring>
#include <future>
#include <list>
#include <mutex>
#include <unordered_map>

#include <fcntl.h>
#include <sys/mman.h>
#include <sys/stat.h>
#include <unistd.h>

#include "common/error.h"
#include "store/codec.h"

namespace reshutter::store {

namespace {

// No float is an infinity or a NaN (an exponent of all ones).
bool allFinite(const float* f, size_t n) {
  uint32_t bad = 0;
  for (size_t k = 0; k < n; ++k) {
    uint32_t bits;
    std::memcpy(&bits, f + k, 4);
    bad |= uint32_t((bits & 0x7f800000u) == 0x7f800000u);
  }
  return bad == 0;
}

// Every corner names one of the part's vertices (a triangle's fourth corner may be kNoCorner).
bool cornersValid(const TilePart& part) {
  const uint32_t* c = part.corners.data();
  const uint32_t nV = part.numVertices;
  uint32_t bad = 0;
  for (size_t m = 0; m < part.numMicropolygons; ++m)
    bad |= uint32_t(c[m * 4] >= nV) | uint32_t(c[m * 4 + 1] >= nV) | uint32_t(c[m * 4 + 2] >= nV) | uint32_t(c[m * 4 + 3] >= nV && c[m * 4 + 3] != kNoCorner);
  return bad == 0;
}

}  // namespace

struct StoreReader::Impl {
  std::string path;
  ReaderOptions options;
  int fd = -1;
  const uint8_t* data = nullptr;
  size_t size = 0;
  uint64_t payloadEnd = 0;
  bool releasing = false;  // dropping decoded payload pages (ReaderOptions::releasePages, when the payload outgrows the cache)
  StoreMeta meta;
  std::vector<TileEntry> entries;
  std::vector<uint32_t> partNumber;  // n-th part of its tile, for messages
  Projector projector;
  ViewBounds view;  // the parts' bounds in the primary camera
  uint64_t micropolygons = 0;

  struct Slot {
    std::shared_future<std::shared_ptr<const TilePart>> future;
    size_t bytes = 0;
    bool ready = false;
    std::list<size_t>::iterator lru;
  };
  mutable std::mutex cacheMutex;
  mutable std::unordered_map<size_t, Slot> slots;
  mutable std::list<size_t> lru;  // front = most recent
  mutable CacheStats stats;

  ~Impl() {
    if (data) ::munmap(const_cast<uint8_t*>(data), size);
    if (fd >= 0) ::close(fd);
  }

  void open() {
    fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
    if (fd < 0) fail(path, "cannot open: ", std::strerror(errno));
    struct stat st;
    if (::fstat(fd, &st) != 0) fail(path, "cannot stat: ", std::strerror(errno));
    if (!S_ISREG(st.st_mode)) fail(path, "not a regular file");
    size = size_t(st.st_size);
    if (size < kHeaderSize) fail(path, "not a reshutter store (", size, " bytes, too short for a header)");
    void* m = ::mmap(nullptr, size, PROT_READ, MAP_PRIVATE, fd, 0);
    if (m == MAP_FAILED) fail(path, "cannot map: ", std::strerror(errno));
    data = static_cast<const uint8_t*>(m);

    if (std::memcmp(data, kHeaderMagic, 8) != 0) fail(path, "not a reshutter store (bad magic)");
    uint32_t version;
    std::memcpy(&version, data + 8, 4);
    if (version > kFormatVersion) fail(path, "written by a newer reshutter (format version ", version, "; this build reads up to ", kFormatVersion, ")");
    if (version == 0) fail(path, "invalid format version 0");
    if (size < kHeaderSize + kFooterSize) fail(path, "truncated (", size, " bytes; no room for the footer)");

    ByteReader footer({data + size - kFooterSize, kFooterSize}, path + ": footer");
    uint64_t metaOffset = footer.get<uint64_t>(), metaSize = footer.get<uint64_t>(), metaSum = footer.get<uint64_t>();
    uint64_t indexOffset = footer.get<uint64_t>(), indexSize = footer.get<uint64_t>(), indexSum = footer.get<uint64_t>();
    char magic[8];
    footer.getBytes(magic, 8);
    if (std::memcmp(magic, kFooterMagic, 8) != 0) fail(path, "truncated or damaged (no valid footer; was the write interrupted?)");
    const uint64_t bodyEnd = size - kFooterSize;
    if (metaOffset < kHeaderSize || metaSize > bodyEnd || metaOffset > bodyEnd - metaSize || indexOffset != metaOffset + metaSize ||
        indexSize > bodyEnd - indexOffset || indexOffset + indexSize != bodyEnd)
      fail(path, "footer offsets out of range (metadata ", metaOffset, "+", metaSize, ", index ", indexOffset, "+", indexSize, ", file ", size, ")");
    std::span<const uint8_t> metaBytes(data + metaOffset, metaSize), indexBytes(data + indexOffset, indexSize);
    if (checksum(metaBytes) != metaSum) fail(path + ": metadata", "checksum mismatch");
    if (checksum(indexBytes) != indexSum) fail(path + ": index", "checksum mismatch");
    ByteReader metaReader(metaBytes, path + ": metadata");
    meta = readMeta(metaReader, version);
    ByteReader indexReader(indexBytes, path + ": index");
    entries = readIndex(indexReader, meta);
    payloadEnd = metaOffset;
    // Dropping decoded pages pays only when the payload could outgrow the decoded-part budget:
    // each MADV_DONTNEED in a multi-threaded process interrupts the other cores to flush their
    // TLBs (measured: ~0.4 CPU-s of system time on the 5 M bench frame, 87 MB file, 2 threads).
    // A payload within the budget stays resident at most at its own size.
    releasing = options.releasePages && metaOffset > options.cacheBytes;
    // Tiles are read in bucket order, not file order: no readahead for the payload section.
    if (releasing) ::madvise(m, size_t(metaOffset) / 4096 * 4096, MADV_RANDOM);
    projector = Projector(meta.cameras[0]);

    partNumber.resize(entries.size());
    for (size_t i = 0; i < entries.size(); ++i) {
      const auto& e = entries[i];
      partNumber[i] = (i > 0 && entries[i - 1].tx == e.tx && entries[i - 1].ty == e.ty) ? partNumber[i - 1] + 1 : 0;
      if (e.offset < kHeaderSize || e.compressedSize > payloadEnd || e.offset > payloadEnd - e.compressedSize)
        fail(where(i), "payload range ", e.offset, "+", e.compressedSize, " lies outside the data section");
      size_t expected = rawPayloadSize(meta.schema, e.numVertices, e.numMicropolygons, uint32_t(e.knots.size()), e.attrPresence);
      if (e.rawSize != expected) fail(where(i), "payload size ", e.rawSize, " does not match its counts (", expected, ")");
      micropolygons += e.numMicropolygons;
    }
    view = ViewBounds(entries, meta.schedules, projector, meta.shutterOpen, meta.shutterClose);
  }

  // Drops the mapped pages of a decoded payload so resident memory does not grow with the file.
  // The kernel maps up to 64 KB around each faulting page ("fault-around"), so neighbours of the
  // range are dropped too. That is safe even while another thread reads them: the mapping is
  // private and never written, so a dropped page simply faults in again from the file.
  void releasePages(uint64_t offset, uint64_t length) const {
    constexpr uint64_t kFaultAround = 64 << 10;
    const uint64_t page = uint64_t(::sysconf(_SC_PAGESIZE));
    uint64_t begin = offset > kFaultAround ? offset - kFaultAround : 0;
    uint64_t end = std::min<uint64_t>(size, offset + length + kFaultAround);
    begin = begin / page * page;
    end = std::min<uint64_t>((end + page - 1) / page * page, (size + page - 1) / page * page);
    ::madvise(const_cast<uint8_t*>(data) + begin, end - begin, MADV_DONTNEED);
  }

  std::string where(size_t i) const {
    const auto& e = entries[i];
    if (e.tx == kBehindCameraTile && e.ty == kBehindCameraTile) return cat(path, ": tile (behind camera) part ", partNumber[i]);
    return cat(path, ": tile (", e.tx, ",", e.ty, ") part ", partNumber[i]);
  }

  TilePart decode(size_t i) const {
    if (i >= entries.size()) fail(path, "no tile part ", i);
    const auto& e = entries[i];
    std::span<const uint8_t> compressed(data + e.offset, e.compressedSize);
    if (checksum(compressed) != e.checksum) fail(where(i), "checksum mismatch (the file is damaged)");
    thread_local std::vector<uint8_t> raw;
    decompress(compressed, e.rawSize, raw, [&] { return where(i); });
    if (releasing) releasePages(e.offset, e.compressedSize);
    TilePart part;
    part.numVertices = e.numVertices;
    part.numMicropolygons = e.numMicropolygons;
    part.numKnots = uint32_t(e.knots.size());
    decodeRaw(meta.schema, raw, e.attrPresence, part);
    // Every part is checked whole, in branch-free passes the compiler vectorises; the loops that
    // name the offender run only when one fails.
    if (!cornersValid(part))
      for (uint32_t m = 0; m < part.numMicropolygons; ++m)
        for (int j = 0; j < 4; ++j) {
          uint32_t c = part.corners[size_t(m) * 4 + j];
          if (c >= part.numVertices && !(j == 3 && c == kNoCorner)) fail(where(i), "micropolygon ", m, " names vertex ", c, " of ", part.numVertices);
        }
    if (!allFinite(reinterpret_cast<const float*>(part.positions.data()), part.positions.size() * 3))
      for (size_t v = 0; v < part.positions.size(); ++v) {
        const auto& p = part.positions[v];
        if (!std::isfinite(p.x) || !std::isfinite(p.y) || !std::isfinite(p.z))
          fail(where(i), "vertex ", v % std::max(1u, part.numVertices), " at knot ", v / std::max(1u, part.numVertices), " has a non-finite position");
      }
    for (size_t a = 0; a < part.attrs.size(); ++a)
      if (!allFinite(part.attrs[a].f.data(), part.attrs[a].f.size())) fail(where(i), "attribute '", meta.schema.attrs[a].name, "' holds a non-finite value");
    return part;
  }

  // Drops a ready slot from the cache (the caller holds cacheMutex); returns its part, for the
  // caller to free after letting go of the lock.
  std::shared_future<std::shared_ptr<const TilePart>> forget(std::unordered_map<size_t, Slot>::iterator it) const {
    auto part = std::move(it->second.future);
    stats.bytes -= it->second.bytes;
    lru.erase(it->second.lru);
    slots.erase(it);
    return part;
  }

  void release(size_t i) const {
    std::shared_future<std::shared_ptr<const TilePart>> doomed;  // freed after the lock is let go
    std::lock_guard lock(cacheMutex);
    auto it = slots.find(i);
    if (it == slots.end() || !it->second.ready) return;
    doomed = forget(it);
    ++stats.releases;
  }

  std::shared_ptr<const TilePart> cachedPart(size_t i) const {
    if (options.cacheBytes == 0) {
      std::lock_guard lock(cacheMutex);
      ++stats.misses;
      return nullptr;
    }
    std::promise<std::shared_ptr<const TilePart>> promise;
    {
      std::unique_lock lock(cacheMutex);
      auto it = slots.find(i);
      if (it != slots.end()) {
        ++stats.hits;
        if (it->second.ready) lru.splice(lru.begin(), lru, it->second.lru);
        else ++stats.waits;
        auto f = it->second.future;
        lock.unlock();
        return f.get();
      }
      ++stats.misses;
      Slot slot;
      slot.future = promise.get_future().share();
      slots.emplace(i, std::move(slot));
    }
    std::shared_ptr<const TilePart> result;
    try {
      result = std::make_shared<const TilePart>(decode(i));
    } catch (...) {
      promise.set_exception(std::current_exception());
      std::lock_guard lock(cacheMutex);
      slots.erase(i);
      throw;
    }
    promise.set_value(result);
    std::lock_guard lock(cacheMutex);
    auto& slot = slots.at(i);
    slot.ready = true;
    slot.bytes = result->memoryBytes();
    lru.push_front(i);
    slot.lru = lru.begin();
    stats.bytes += slot.bytes;
    while (stats.bytes > options.cacheBytes && lru.size() > 1) {
      forget(slots.find(lru.back()));
      ++stats.evictions;
    }
    stats.peakBytes = std::max(stats.peakBytes, stats.bytes);
    return result;
  }
};

StoreReader::StoreReader(const std::string& path, ReaderOptions options) : impl_(std::make_unique<Impl>()) {
  impl_->path = path;
  impl_->options = options;
  impl_->open();
}
StoreReader::~StoreReader() = default;

const std::string& StoreReader::path() const { return impl_->path; }
const StoreMeta& StoreReader::meta() const { return impl_->meta; }
const std::vector<TileEntry>& StoreReader::entries() const { return impl_->entries; }
uint64_t StoreReader::fileBytes() const { return impl_->size; }
uint64_t StoreReader::micropolygonCount() const { return impl_->micropolygons; }
std::string StoreReader::where(size_t entry) const { return impl_->where(entry); }
TilePart StoreReader::decode(size_t entry) const { return impl_->decode(entry); }

void StoreReader::release(size_t entry) const { impl_->release(entry); }

std::shared_ptr<const TilePart> StoreReader::part(size_t entry) const {
  auto p = impl_->cachedPart(entry);
  return p ? p : std::make_shared<const TilePart>(impl_->decode(entry));
}

CacheStats StoreReader::cacheStats() const {
  std::lock_guard lock(impl_->cacheMutex);
  return impl_->stats;
}

RasterRect StoreReader::bounds(size_t entry, double t0, double t1) const { return impl_->view.bounds(entry, t0, t1); }
const ViewBounds& StoreReader::primaryBounds() const { return impl_->view; }

void StoreReader::visit(const RasterRect& rect, double t0, double t1, const std::function<void(size_t)>& fn, const Lens& lens) const {
  impl_->view.visit(rect, t0, t1, fn, lens);
}

VerifyReport StoreReader::verify(const std::function<void(size_t)>& progress) const {
  const auto& I = *impl_;
  VerifyReport report;
  std::vector<std::pair<uint64_t, uint64_t>> ranges;
  for (size_t i = 0; i < I.entries.size(); ++i) {
    const auto& e = I.entries[i];
    if (i > 0) {
      const auto& p = I.entries[i - 1];
      if (std::tuple(p.ty, p.tx) > std::tuple(e.ty, e.tx)) fail(I.where(i), "index is not sorted by tile");
    }
    ranges.emplace_back(e.offset, e.offset + e.compressedSize);
  }
  std::sort(ranges.begin(), ranges.end());
  for (size_t i = 1; i < ranges.size(); ++i)
    if (ranges[i].first < ranges[i - 1].second) fail(I.path, "two tile parts share payload bytes at offset ", ranges[i].first);

  const double invTile = 1.0 / I.meta.tileSize;
  const int oi = I.meta.schema.oi();
  for (size_t i = 0; i < I.entries.size(); ++i) {
    const auto& e = I.entries[i];
    TilePart part = I.decode(i);
    const uint32_t K = part.numKnots, nV = part.numVertices;
    uint32_t effects = 0;
    for (uint32_t k = 0; k < K; ++k) {
      const KnotBounds& kb = e.knots[k];
      for (uint32_t v = 0; v < nV; ++v) {
        const glm::vec3& p = part.position(k, v);
        if (k > 0 && p != part.position(0, v)) effects |= kEffectMoving;
        for (int a = 0; a < 3; ++a)
          if (p[a] < kb.camera[a] || p[a] > kb.camera[a + 3]) fail(I.where(i), "vertex ", v, " at knot ", k, " lies outside the camera-space bound");
        bool front = !I.projector.perspective || double(p.z) >= I.projector.nearClip;
        if (!front) effects |= kEffectNearCrossing;
        if (front && kb.rasterFinite) {
          glm::dvec2 r = I.projector.project(glm::dvec3(p));
          r = glm::clamp(r, -1e30, 1e30);
          if (r.x < kb.raster[0] || r.x > kb.raster[2] || r.y < kb.raster[1] || r.y > kb.raster[3])
            fail(I.where(i), "vertex ", v, " at knot ", k, " projects to (", r.x, ", ", r.y, ") outside the raster bound");
        }
        if (!front && kb.rasterFinite) fail(I.where(i), "knot ", k, " claims a finite raster bound but vertex ", v, " is before the near plane");
      }
    }
    for (uint32_t m = 0; m < part.numMicropolygons; ++m) {
      const uint32_t* c = &part.corners[size_t(m) * 4];
      int nc = c[3] == kNoCorner ? 3 : 4;
      if (nc == 3) effects |= kEffectTriangles;
      if (part.flags[m] & kMatte) effects |= kEffectMatte;
      if (part.flags[m] & kTwoSided) effects |= kEffectTwoSided;
      int32_t tx = kBehindCameraTile, ty = kBehindCameraTile;
      for (uint32_t k = 0; k < K; ++k) {
        bool front = true;
        for (int j = 0; j < nc; ++j) front = front && (!I.projector.perspective || double(part.position(k, c[j]).z) >= I.projector.nearClip);
        if (!front) continue;
        glm::dvec2 centre(0.0);
        for (int j = 0; j < nc; ++j) centre += I.projector.project(glm::dvec3(part.position(k, c[j])));
        centre /= double(nc);
        auto coord = [&](double v) { return int32_t(std::clamp(std::floor(v * invTile), -double(1 << 30), double(1 << 30))); };
        tx = coord(centre.x), ty = coord(centre.y);
        break;
      }
      if (tx != e.tx || ty != e.ty) fail(I.where(i), "micropolygon ", m, " belongs to tile (", tx, ",", ty, ")");
    }
    if (oi >= 0 && part.attrs[size_t(oi)].present()) {
      const auto& o = part.attrs[size_t(oi)].f;
      for (size_t j = 0; j + 2 < o.size(); j += 3) {
        if (o[j] < 1 || o[j + 1] < 1 || o[j + 2] < 1) effects |= kEffectTransparent;
        if (o[j] != o[j + 1] || o[j + 1] != o[j + 2]) effects |= kEffectColouredOpacity;
      }
    }
    if ((effects & ~e.effects) != 0) fail(I.where(i), "effect flags [", effectNames(e.effects), "] miss [", effectNames(effects & ~e.effects), "]");
    report.parts++;
    report.micropolygons += part.numMicropolygons;
    report.vertices += part.numVertices;
    if (progress) progress(i + 1);
  }
  return report;
}

}  // namespace reshutter::store
