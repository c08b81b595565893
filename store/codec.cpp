#include "store/codec.h"

#include <algorithm>
#include <bit>
#include <cmath>
#include <cstring>
#include <memory>

#include <Imath/half.h>
#include <xxhash.h>
#include <zstd.h>

#include "common/error.h"

namespace reshutter::store {
namespace {

inline uint32_t zigzag(int32_t d) { return (uint32_t(d) << 1) ^ uint32_t(d >> 31); }
inline int32_t unzigzag(uint32_t z) { return int32_t(z >> 1) ^ -int32_t(z & 1); }
inline uint16_t zigzag16(int16_t d) { return uint16_t((uint16_t(d) << 1) ^ uint16_t(d >> 15)); }
inline int16_t unzigzag16(uint16_t z) { return int16_t((z >> 1) ^ -(z & 1)); }

bool isWordAttr(const AttrDecl& a) { return a.type == AttrType::UInt || a.codec == AttrCodec::Lossless; }
int planesOf(const AttrDecl& a) { return a.codec == AttrCodec::Oct32 ? 2 : componentCount(a.type); }
uint32_t countOf(const AttrDecl& a, uint32_t nV, uint32_t nMp) { return a.rate == AttrRate::Vertex ? nV : nMp; }
bool presentIn(uint64_t presence, size_t i) { return i < 64 && ((presence >> i) & 1u); }

struct Counts {
  size_t words = 0, halves = 0, bytes = 0;
};

Counts countsFor(const Schema& schema, uint32_t nV, uint32_t nMp, uint32_t nK, uint64_t presence) {
  Counts c;
  c.words = size_t(nK) * 3 * nV + size_t(nMp) * 6;  // positions, 4 corners, object id, grid id
  c.bytes = nMp;
  for (size_t i = 0; i < schema.attrs.size(); ++i) {
    if (!presentIn(presence, i)) continue;
    const auto& a = schema.attrs[i];
    size_t n = size_t(countOf(a, nV, nMp)) * planesOf(a);
    (isWordAttr(a) ? c.words : c.halves) += n;
  }
  return c;
}

// Delta + zig-zag along the producer's order; `ref` (knot 0) makes later knots relative to it.
template <typename Get, typename Ref>
void deltaEncode(uint32_t n, Get get, Ref ref, uint32_t* out) {
  int32_t prev = 0;
  for (uint32_t i = 0; i < n; ++i) {
    int32_t v = int32_t(get(i) - ref(i));
    out[i] = zigzag(int32_t(uint32_t(v) - uint32_t(prev)));
    prev = v;
  }
}
template <typename Set, typename Ref>
void deltaDecode(uint32_t n, const uint32_t* in, Ref ref, Set set) {
  uint32_t acc = 0;
  for (uint32_t i = 0; i < n; ++i) {
    acc += uint32_t(unzigzag(in[i]));
    set(i, acc + ref(i));
  }
}
void delta16Encode(uint32_t n, const uint16_t* in, size_t stride, uint16_t* out) {
  uint16_t prev = 0;
  for (uint32_t i = 0; i < n; ++i) {
    uint16_t v = in[i * stride];
    out[i] = zigzag16(int16_t(uint16_t(v - prev)));
    prev = v;
  }
}
void delta16Decode(uint32_t n, const uint16_t* in, uint16_t* out, size_t stride) {
  uint16_t acc = 0;
  for (uint32_t i = 0; i < n; ++i) {
    acc = uint16_t(acc + uint16_t(unzigzag16(in[i])));
    out[i * stride] = acc;
  }
}

template <size_t W>
void shuffle(const uint8_t* in, size_t n, uint8_t* out) {
  for (size_t i = 0; i < n; ++i)
    for (size_t b = 0; b < W; ++b) out[b * n + i] = in[i * W + b];
}
// Element-major: W sequential read streams and one sequential write (plane-major wrote every
// byte W apart, W passes over the output), and the compiler vectorises the byte interleave.
template <size_t W>
void unshuffle(const uint8_t* in, size_t n, uint8_t* out) {
  for (size_t i = 0; i < n; ++i)
    for (size_t b = 0; b < W; ++b) out[i * W + b] = in[b * n + i];
}

inline uint32_t bitsOf(float f) { return std::bit_cast<uint32_t>(f); }
inline float floatOf(uint32_t u) { return std::bit_cast<float>(u); }

uint16_t lossyEncode(const AttrDecl& a, float v) { return a.codec == AttrCodec::Half ? encodeHalf(v) : encodeUnorm16(v); }
float lossyDecode(const AttrDecl& a, uint16_t q) { return a.codec == AttrCodec::Half ? decodeHalf(q) : decodeUnorm16(q); }

}  // namespace

size_t rawPayloadSize(const Schema& schema, uint32_t nV, uint32_t nMp, uint32_t nK, uint64_t presence) {
  Counts c = countsFor(schema, nV, nMp, nK, presence);
  return c.words * 4 + c.halves * 2 + c.bytes;
}

void encodeRaw(const Schema& schema, const TilePart& part, uint64_t presence, std::vector<uint8_t>& out) {
  const uint32_t nV = part.numVertices, nMp = part.numMicropolygons, nK = part.numKnots;
  Counts c = countsFor(schema, nV, nMp, nK, presence);
  // Scratch reused per thread: fresh multi-hundred-KB vectors per part cost more in page faults
  // than the encoding itself.
  thread_local std::vector<uint32_t> words;
  thread_local std::vector<uint16_t> halves;
  words.resize(c.words);
  halves.resize(c.halves);
  uint32_t* w = words.data();
  uint16_t* h = halves.data();

  const float* pos = reinterpret_cast<const float*>(part.positions.data());
  for (uint32_t k = 0; k < nK; ++k)
    for (int comp = 0; comp < 3; ++comp) {
      const float* cur = pos + size_t(k) * nV * 3 + comp;
      const float* base = pos + comp;
      if (k == 0)
        deltaEncode(
            nV, [&](uint32_t i) { return bitsOf(cur[i * 3]); }, [](uint32_t) { return 0u; }, w);
      else
        deltaEncode(
            nV, [&](uint32_t i) { return bitsOf(cur[i * 3]); }, [&](uint32_t i) { return bitsOf(base[i * 3]); }, w);
      w += nV;
    }
  const uint32_t* cn = part.corners.data();
  deltaEncode(
      nMp, [&](uint32_t i) { return cn[i * 4]; }, [](uint32_t) { return 0u; }, w);
  w += nMp;
  for (int j = 1; j < 4; ++j) {
    deltaEncode(
        nMp, [&](uint32_t i) { return cn[i * 4 + j]; }, [&](uint32_t i) { return cn[i * 4]; }, w);
    w += nMp;
  }
  for (const auto* ids : {&part.objectId, &part.gridId}) {
    deltaEncode(
        nMp, [&](uint32_t i) { return (*ids)[i]; }, [](uint32_t) { return 0u; }, w);
    w += nMp;
  }
  for (size_t ai = 0; ai < schema.attrs.size(); ++ai) {
    if (!presentIn(presence, ai)) continue;
    const auto& a = schema.attrs[ai];
    const AttrArray& arr = part.attrs[ai];
    const uint32_t n = countOf(a, nV, nMp);
    const int nc = componentCount(a.type);
    if (a.type == AttrType::UInt) {
      deltaEncode(
          n, [&](uint32_t i) { return arr.u[i]; }, [](uint32_t) { return 0u; }, w);
      w += n;
    } else if (a.codec == AttrCodec::Lossless) {
      for (int comp = 0; comp < nc; ++comp) {
        deltaEncode(
            n, [&](uint32_t i) { return bitsOf(arr.f[size_t(i) * nc + comp]); }, [](uint32_t) { return 0u; }, w);
        w += n;
      }
    } else if (a.codec == AttrCodec::Oct32) {
      std::vector<uint16_t> q(size_t(n) * 2);
      for (uint32_t i = 0; i < n; ++i) encodeOct(&arr.f[size_t(i) * 3], &q[size_t(i) * 2]);
      for (int comp = 0; comp < 2; ++comp, h += n) delta16Encode(n, q.data() + comp, 2, h);
    } else {
      std::vector<uint16_t> q(n);
      for (int comp = 0; comp < nc; ++comp, h += n) {
        for (uint32_t i = 0; i < n; ++i) q[i] = lossyEncode(a, arr.f[size_t(i) * nc + comp]);
        delta16Encode(n, q.data(), 1, h);
      }
    }
  }

  out.resize(c.words * 4 + c.halves * 2 + c.bytes);
  uint8_t* o = out.data();
  shuffle<4>(reinterpret_cast<const uint8_t*>(words.data()), c.words, o);
  o += c.words * 4;
  shuffle<2>(reinterpret_cast<const uint8_t*>(halves.data()), c.halves, o);
  o += c.halves * 2;
  if (nMp) std::memcpy(o, part.flags.data(), nMp);
}

void decodeRaw(const Schema& schema, std::span<const uint8_t> raw, uint64_t presence, TilePart& part) {
  const uint32_t nV = part.numVertices, nMp = part.numMicropolygons, nK = part.numKnots;
  Counts c = countsFor(schema, nV, nMp, nK, presence);
  thread_local std::vector<uint32_t> words;
  thread_local std::vector<uint16_t> halves;
  words.resize(c.words);
  halves.resize(c.halves);
  unshuffle<4>(raw.data(), c.words, reinterpret_cast<uint8_t*>(words.data()));
  unshuffle<2>(raw.data() + c.words * 4, c.halves, reinterpret_cast<uint8_t*>(halves.data()));
  const uint32_t* w = words.data();
  const uint16_t* h = halves.data();

  part.positions.resize(size_t(nK) * nV);
  float* pos = reinterpret_cast<float*>(part.positions.data());
  for (uint32_t k = 0; k < nK; ++k)
    for (int comp = 0; comp < 3; ++comp) {
      float* cur = pos + size_t(k) * nV * 3 + comp;
      const float* base = pos + comp;
      if (k == 0)
        deltaDecode(
            nV, w, [](uint32_t) { return 0u; }, [&](uint32_t i, uint32_t v) { cur[i * 3] = floatOf(v); });
      else
        deltaDecode(
            nV, w, [&](uint32_t i) { return bitsOf(base[i * 3]); }, [&](uint32_t i, uint32_t v) { cur[i * 3] = floatOf(v); });
      w += nV;
    }
  part.corners.resize(size_t(nMp) * 4);
  uint32_t* cn = part.corners.data();
  deltaDecode(
      nMp, w, [](uint32_t) { return 0u; }, [&](uint32_t i, uint32_t v) { cn[i * 4] = v; });
  w += nMp;
  for (int j = 1; j < 4; ++j) {
    deltaDecode(
        nMp, w, [&](uint32_t i) { return cn[i * 4]; }, [&](uint32_t i, uint32_t v) { cn[i * 4 + j] = v; });
    w += nMp;
  }
  for (auto* ids : {&part.objectId, &part.gridId}) {
    ids->resize(nMp);
    deltaDecode(
        nMp, w, [](uint32_t) { return 0u; }, [&](uint32_t i, uint32_t v) { (*ids)[i] = v; });
    w += nMp;
  }
  part.attrs.assign(schema.attrs.size(), AttrArray{});
  for (size_t ai = 0; ai < schema.attrs.size(); ++ai) {
    if (!presentIn(presence, ai)) continue;
    const auto& a = schema.attrs[ai];
    AttrArray& arr = part.attrs[ai];
    const uint32_t n = countOf(a, nV, nMp);
    const int nc = componentCount(a.type);
    if (a.type == AttrType::UInt) {
      arr.u.resize(n);
      deltaDecode(
          n, w, [](uint32_t) { return 0u; }, [&](uint32_t i, uint32_t v) { arr.u[i] = v; });
      w += n;
    } else if (a.codec == AttrCodec::Lossless) {
      arr.f.resize(size_t(n) * nc);
      for (int comp = 0; comp < nc; ++comp) {
        deltaDecode(
            n, w, [](uint32_t) { return 0u; }, [&](uint32_t i, uint32_t v) { arr.f[size_t(i) * nc + comp] = floatOf(v); });
        w += n;
      }
    } else if (a.codec == AttrCodec::Oct32) {
      std::vector<uint16_t> q(size_t(n) * 2);
      for (int comp = 0; comp < 2; ++comp, h += n) delta16Decode(n, h, q.data() + comp, 2);
      arr.f.resize(size_t(n) * 3);
      for (uint32_t i = 0; i < n; ++i) decodeOct(&q[size_t(i) * 2], &arr.f[size_t(i) * 3]);
    } else {
      std::vector<uint16_t> q(n);
      arr.f.resize(size_t(n) * nc);
      for (int comp = 0; comp < nc; ++comp, h += n) {
        delta16Decode(n, h, q.data(), 1);
        for (uint32_t i = 0; i < n; ++i) arr.f[size_t(i) * nc + comp] = lossyDecode(a, q[i]);
      }
    }
  }
  part.flags.assign(raw.data() + c.words * 4 + c.halves * 2, raw.data() + c.words * 4 + c.halves * 2 + nMp);
}

void compress(std::span<const uint8_t> raw, int level, std::vector<uint8_t>& out) {
  // One context and one worst-case buffer per thread: ZSTD_compress() would allocate and clear
  // its tables on every call, and a fresh compressBound()-sized vector costs page faults.
  thread_local std::unique_ptr<ZSTD_CCtx, size_t (*)(ZSTD_CCtx*)> ctx(ZSTD_createCCtx(), ZSTD_freeCCtx);
  thread_local std::vector<uint8_t> scratch;
  if (scratch.size() < ZSTD_compressBound(raw.size())) scratch.resize(ZSTD_compressBound(raw.size()));
  size_t n = ZSTD_compressCCtx(ctx.get(), scratch.data(), scratch.size(), raw.data(), raw.size(), level);
  if (ZSTD_isError(n)) fail("zstd", ZSTD_getErrorName(n));
  out.assign(scratch.begin(), scratch.begin() + long(n));
}

void decompress(std::span<const uint8_t> compressed, size_t rawSize, std::vector<uint8_t>& out, const std::function<std::string()>& where) {
  unsigned long long declared = ZSTD_getFrameContentSize(compressed.data(), compressed.size());
  if (declared == ZSTD_CONTENTSIZE_ERROR || declared == ZSTD_CONTENTSIZE_UNKNOWN || declared != rawSize)
    fail(where(), "compressed payload is corrupt (frame size does not match the index)");
  out.resize(rawSize);
  thread_local std::unique_ptr<ZSTD_DCtx, size_t (*)(ZSTD_DCtx*)> ctx(ZSTD_createDCtx(), ZSTD_freeDCtx);
  size_t n = ZSTD_decompressDCtx(ctx.get(), out.data(), out.size(), compressed.data(), compressed.size());
  if (ZSTD_isError(n) || n != rawSize) fail(where(), "compressed payload is corrupt (", ZSTD_isError(n) ? ZSTD_getErrorName(n) : "short", ")");
}

uint64_t checksum(std::span<const uint8_t> bytes) { return XXH3_64bits(bytes.data(), bytes.size()); }

uint16_t encodeHalf(float v) {
  if (std::isnan(v)) v = 0.0f;
  v = std::clamp(v, -65504.0f, 65504.0f);
  return Imath::half(v).bits();
}
float decodeHalf(uint16_t h) {
  Imath::half x;
  x.setBits(h);
  return float(x);
}

uint16_t encodeUnorm16(float v) {
  if (!(v >= 0.0f)) v = 0.0f;  // also maps NaN to 0
  if (v > 1.0f) v = 1.0f;
  return uint16_t(std::lround(double(v) * 65535.0));
}
float decodeUnorm16(uint16_t q) { return float(double(q) / 65535.0); }

namespace {
inline double signNotZero(double v) { return v < 0.0 ? -1.0 : 1.0; }
inline uint16_t toSnorm16(double v) { return uint16_t(int16_t(std::lround(std::clamp(v, -1.0, 1.0) * 32767.0))); }
inline double fromSnorm16(uint16_t q) { return std::max(-1.0, double(int16_t(q)) / 32767.0); }
void octDecodeD(double px, double py, double n[3]) {
  double z = 1.0 - std::abs(px) - std::abs(py);
  double x = px, y = py;
  if (z < 0) {
    x = (1.0 - std::abs(py)) * signNotZero(px);
    y = (1.0 - std::abs(px)) * signNotZero(py);
  }
  double len = std::sqrt(x * x + y * y + z * z);
  n[0] = x / len;
  n[1] = y / len;
  n[2] = z / len;
}
}  // namespace

void encodeOct(const float nIn[3], uint16_t out[2]) {
  double n[3] = {nIn[0], nIn[1], nIn[2]};
  double l1 = std::abs(n[0]) + std::abs(n[1]) + std::abs(n[2]);
  if (!(l1 > 0.0) || !std::isfinite(l1)) {
    out[0] = out[1] = 0;  // decodes to +z
    return;
  }
  double px = n[0] / l1, py = n[1] / l1;
  if (n[2] < 0) {
    double ox = px, oy = py;
    px = (1.0 - std::abs(oy)) * signNotZero(ox);
    py = (1.0 - std::abs(ox)) * signNotZero(oy);
  }
  // Rounding each coordinate independently can miss the nearest code by one step; try the four
  // neighbours and keep the most accurate (the "precise" variant of Cigolle et al. 2014).
  double fx = std::floor(std::clamp(px, -1.0, 1.0) * 32767.0), fy = std::floor(std::clamp(py, -1.0, 1.0) * 32767.0);
  double best = -2.0;
  double len = std::sqrt(double(nIn[0]) * nIn[0] + double(nIn[1]) * nIn[1] + double(nIn[2]) * nIn[2]);
  for (int dx = 0; dx < 2; ++dx)
    for (int dy = 0; dy < 2; ++dy) {
      double cx = std::clamp(fx + dx, -32767.0, 32767.0), cy = std::clamp(fy + dy, -32767.0, 32767.0);
      uint16_t q[2] = {toSnorm16(cx / 32767.0), toSnorm16(cy / 32767.0)};
      double d[3];
      octDecodeD(fromSnorm16(q[0]), fromSnorm16(q[1]), d);
      double dot = (d[0] * n[0] + d[1] * n[1] + d[2] * n[2]) / len;
      if (dot > best) {
        best = dot;
        out[0] = q[0];
        out[1] = q[1];
      }
    }
}

void decodeOct(const uint16_t in[2], float n[3]) {
  double d[3];
  octDecodeD(fromSnorm16(in[0]), fromSnorm16(in[1]), d);
  n[0] = float(d[0]);
  n[1] = float(d[1]);
  n[2] = float(d[2]);
}

}  // namespace reshutter::store
