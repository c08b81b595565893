// The payload codec's building blocks: lossy codecs meet the bounds stated in store/codec.h over
// dense sweeps of their input ranges; the raw payload round-trips and has the size it claims.
#include <bit>
#include <cmath>

#include <gtest/gtest.h>

#include <glm/geometric.hpp>

#include "common/random.h"
#include "store/codec.h"
#include "tests/store_test_util.h"

using namespace reshutter;
using namespace reshutter::store;

TEST(StoreCodec, HalfRelativeErrorBound) {
  Rng rng(3);
  for (int i = 0; i < 200000; ++i) {
    float v = float(std::ldexp(rng.uniform(1.0, 2.0), int(rng.below(31)) - 15)) * (rng.below(2) ? 1.f : -1.f);
    float d = decodeHalf(encodeHalf(v));
    if (std::abs(v) >= 0x1.0p-14f && std::abs(v) <= 65504.f) {
      ASSERT_LE(std::abs(d - v), std::ldexp(std::abs(v), -11)) << v;
    } else if (std::abs(v) < 0x1.0p-14f) {
      ASSERT_LE(std::abs(d - v), 0x1.0p-25f) << v;
    }
  }
  EXPECT_EQ(decodeHalf(encodeHalf(1e9f)), 65504.f);
  EXPECT_EQ(decodeHalf(encodeHalf(-1e9f)), -65504.f);
}

TEST(StoreCodec, Unorm16AbsoluteErrorBound) {
  for (int i = 0; i <= 1000000; ++i) {
    float v = float(i) / 1e6f;
    ASSERT_LE(std::abs(decodeUnorm16(encodeUnorm16(v)) - v), 0.5f / 65535.f + 1e-7f) << v;
  }
  EXPECT_EQ(decodeUnorm16(encodeUnorm16(-3.f)), 0.f);
  EXPECT_EQ(decodeUnorm16(encodeUnorm16(7.f)), 1.f);
  EXPECT_EQ(decodeUnorm16(encodeUnorm16(NAN)), 0.f);
}

TEST(StoreCodec, OctAngularErrorBound) {
  Rng rng(5);
  double worst = 0;
  for (int i = 0; i < 300000; ++i) {
    double z = rng.uniform(-1, 1), a = rng.uniform(0, 2 * M_PI), r = std::sqrt(1 - z * z);
    float n[3] = {float(r * std::cos(a)), float(r * std::sin(a)), float(z)};
    if (i % 3 == 0) n[0] *= 7.0f, n[1] *= 7.0f, n[2] *= 7.0f;  // non-unit input: direction kept
    uint16_t q[2];
    encodeOct(n, q);
    float d[3];
    decodeOct(q, d);
    // atan2(|a×b|, a·b) stays accurate for tiny angles, where acos of a dot product does not.
    glm::dvec3 va(n[0], n[1], n[2]), vb(d[0], d[1], d[2]);
    worst = std::max(worst, std::atan2(glm::length(glm::cross(va, vb)), glm::dot(va, vb)));
    ASSERT_NEAR(double(d[0]) * d[0] + double(d[1]) * d[1] + double(d[2]) * d[2], 1.0, 1e-6);
  }
  EXPECT_LE(worst, 5e-5);
  // The axes and the octahedron's folds decode exactly.
  for (auto axis : {glm::vec3(1, 0, 0), glm::vec3(0, -1, 0), glm::vec3(0, 0, -1), glm::vec3(0, 0, 1)}) {
    uint16_t q[2];
    encodeOct(&axis.x, q);
    float d[3];
    decodeOct(q, d);
    EXPECT_NEAR(d[0], axis.x, 1e-6);
    EXPECT_NEAR(d[1], axis.y, 1e-6);
    EXPECT_NEAR(d[2], axis.z, 1e-6);
  }
}

TEST(StoreCodec, RawPayloadRoundTripAndSize) {
  const Schema schema = test::fullSchema();
  Rng rng(9);
  test::GridSpec spec;
  spec.knots = 3;
  uint32_t id = 0;
  auto g = test::randomGrid(rng, schema, spec, 0, id);
  TilePart part;
  part.numVertices = g.numVertices;
  part.numMicropolygons = uint32_t(g.corners.size() / 4);
  part.numKnots = 3;
  part.positions = g.positions;
  part.corners = g.corners;
  part.objectId.assign(part.numMicropolygons, 5);
  part.gridId.assign(part.numMicropolygons, 6);
  part.flags.assign(part.numMicropolygons, 1);
  part.attrs.resize(schema.attrs.size());
  uint64_t presence = 0;
  for (size_t a = 0; a < schema.attrs.size(); ++a) {
    part.attrs[a].f = g.f[a];
    part.attrs[a].u = g.u[a];
    presence |= 1ull << a;
  }
  std::vector<uint8_t> raw;
  encodeRaw(schema, part, presence, raw);
  EXPECT_EQ(raw.size(), rawPayloadSize(schema, part.numVertices, part.numMicropolygons, 3, presence));
  std::vector<uint8_t> z, back;
  compress(raw, 3, z);
  decompress(z, raw.size(), back, [] { return std::string("test"); });
  EXPECT_EQ(back, raw);
  TilePart out;
  out.numVertices = part.numVertices, out.numMicropolygons = part.numMicropolygons, out.numKnots = 3;
  decodeRaw(schema, back, presence, out);
  EXPECT_EQ(out.positions, part.positions);
  EXPECT_EQ(out.corners, part.corners);
  EXPECT_EQ(out.objectId, part.objectId);
  EXPECT_EQ(out.flags, part.flags);
  for (size_t a = 0; a < schema.attrs.size(); ++a) {
    ASSERT_EQ(out.attrs[a].f.size(), part.attrs[a].f.size());
    for (size_t i = 0; i < part.attrs[a].f.size(); ++i) EXPECT_EQ(std::bit_cast<uint32_t>(out.attrs[a].f[i]), std::bit_cast<uint32_t>(part.attrs[a].f[i]));
    EXPECT_EQ(out.attrs[a].u, part.attrs[a].u);
  }
  EXPECT_THROW(decompress(z, raw.size() + 1, back, [] { return std::string("test"); }), Error);
}
