// Tile-part payload codec: TilePart ↔ bytes.
//
// A part's payload is one zstd frame over three sections, each a structure of arrays:
//   32-bit words  positions (per knot, per component), corners, object/grid ids, lossless attributes
//   16-bit words  attributes under the Half, Unorm16 and Oct32 codecs
//   bytes         per-micropolygon flags
// Before compression every array is delta-coded along the producer's order (float bits as
// integers, zig-zagged), later knots relative to knot 0, and each section is byte-shuffled
// (all low bytes, then the next ...): neighbouring micropolygons of a diced grid share most high
// bytes, which is what makes the dicing order worth keeping.
//
// Lossy codecs and their bounds (asserted by tests/store_codec_test.cpp):
//   Half     |decoded - v| <= 2^-11·|v| for 2^-14 <= |v| <= 65504, <= 2^-25 below; larger values
//            clamp to ±65504.
//   Unorm16  v clamped to [0, 1], |decoded - v| <= 0.5/65535 (opacity).
//   Oct32    unit direction in octahedral 2×16 bits: angle to the input <= 5e-5 rad (measured
//            worst 4.3e-5 over 3 M random directions); the length is
//            not kept (decoded vectors are unit; a zero vector decodes to (0, 0, 1)).
#pragma once

#include <cstdint>
#include <functional>
#include <span>
#include <string>
#include <vector>

#include "store/model.h"

namespace reshutter::store {

/// Exact size of a part's uncompressed payload for the given counts and attribute presence.
size_t rawPayloadSize(const Schema& schema, uint32_t numVertices, uint32_t numMps, uint32_t numKnots, uint64_t attrPresence);

/// Serialises `part` (attributes marked in `attrPresence`) into the uncompressed payload.
void encodeRaw(const Schema& schema, const TilePart& part, uint64_t attrPresence, std::vector<uint8_t>& out);
/// Inverse of encodeRaw; `raw` must be exactly rawPayloadSize(...) bytes (the caller checks).
void decodeRaw(const Schema& schema, std::span<const uint8_t> raw, uint64_t attrPresence, TilePart& part);

/// zstd wrappers; decompress throws Error(where()) unless the frame holds exactly `rawSize` bytes
/// (`where` is called only then: a render decodes thousands of parts, and naming each cost more
/// than checking its checksum).
void compress(std::span<const uint8_t> raw, int level, std::vector<uint8_t>& out);
void decompress(std::span<const uint8_t> compressed, size_t rawSize, std::vector<uint8_t>& out, const std::function<std::string()>& where);

/// 64-bit checksum (XXH3) of a byte range.
uint64_t checksum(std::span<const uint8_t> bytes);

// Single-value lossy codecs, exposed for tests and the accuracy study.
uint16_t encodeHalf(float v);
float decodeHalf(uint16_t h);
uint16_t encodeUnorm16(float v);
float decodeUnorm16(uint16_t q);
void encodeOct(const float n[3], uint16_t out[2]);
void decodeOct(const uint16_t in[2], float n[3]);

}  // namespace reshutter::store
