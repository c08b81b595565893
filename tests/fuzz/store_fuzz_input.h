// Turns a fuzz input into store bytes: the first byte selects the mode, the rest is the file.
// With an odd mode byte the footer, index and payload checksums are repaired first, so mutations
// reach the metadata, index and payload decoders instead of stopping at the checksums. Shared by
// the fuzz target and the corpus regression test.
#pragma once

#include <cstdint>
#include <cstring>
#include <vector>

#include "common/error.h"
#include "store/codec.h"
#include "store/format.h"

namespace reshutter::store {

inline void repairChecksums(std::vector<uint8_t>& b) {
  if (b.size() < kHeaderSize + kFooterSize) return;
  uint64_t f[6];
  std::memcpy(f, b.data() + b.size() - kFooterSize, sizeof f);
  const uint64_t bodyEnd = b.size() - kFooterSize;
  if (f[0] > bodyEnd || f[1] > bodyEnd - f[0] || f[3] > bodyEnd || f[4] > bodyEnd - f[3]) return;
  try {
    ByteReader mr({b.data() + f[0], f[1]}, "meta");
    uint32_t version;
    std::memcpy(&version, b.data() + 8, 4);
    StoreMeta meta = readMeta(mr, version);
    ByteReader ir({b.data() + f[3], f[4]}, "index");
    auto entries = readIndex(ir, meta);
    for (auto& e : entries)
      if (e.offset <= f[0] && e.compressedSize <= f[0] - e.offset) e.checksum = checksum({b.data() + e.offset, e.compressedSize});
    ByteWriter iw;
    writeIndex(entries, meta, iw);
    if (iw.size() == f[4]) std::memcpy(b.data() + f[3], iw.bytes().data(), iw.size());
  } catch (const Error&) {
  }
  f[2] = checksum({b.data() + f[0], f[1]});
  f[5] = checksum({b.data() + f[3], f[4]});
  std::memcpy(b.data() + b.size() - kFooterSize, f, sizeof f);
}

inline std::vector<uint8_t> storeFromFuzzInput(const uint8_t* data, size_t size) {
  if (size == 0) return {};
  std::vector<uint8_t> bytes(data + 1, data + size);
  if (data[0] & 1) repairChecksums(bytes);
  return bytes;
}

}  // namespace reshutter::store
