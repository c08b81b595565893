// Round trips through the .mps writer and reader: every attribute type at both rates, 1 to 8
// motion knots, random full-entropy data (bit-exact for lossless codecs), spilling under a tiny
// memory budget, mixed motion schedules, triangles, partial attribute presence, determinism,
// and concurrent cached reads.
#include <bit>
#include <cmath>
#include <set>

#include <gtest/gtest.h>
#include <tbb/parallel_for.h>
#include <glm/geometric.hpp>

#include "store/codec.h"
#include "tests/store_test_util.h"
#include "tests/test_util.h"

using namespace reshutter;
using namespace reshutter::store;
using reshutter::test::FlatStore;

namespace {

void expectBitEqual(float a, float b, const std::string& what) {
  EXPECT_EQ(std::bit_cast<uint32_t>(a), std::bit_cast<uint32_t>(b)) << what << ": " << a << " vs " << b;
}

void compareExact(const FlatStore& in, const FlatStore& out, const Schema& schema) {
  ASSERT_EQ(in.size(), out.size());
  for (const auto& [id, a] : in) {
    auto it = out.find(id);
    ASSERT_NE(it, out.end()) << "micropolygon " << id << " missing";
    const auto& b = it->second;
    EXPECT_EQ(a.objectId, b.objectId);
    EXPECT_EQ(a.gridId, b.gridId);
    EXPECT_EQ(a.flags, b.flags);
    EXPECT_EQ(a.corners, b.corners);
    EXPECT_EQ(a.schedule, b.schedule);
    ASSERT_EQ(a.positions.size(), b.positions.size());
    for (size_t i = 0; i < a.positions.size(); ++i)
      for (int c = 0; c < 3; ++c) expectBitEqual(a.positions[i][c], b.positions[i][c], "position");
    for (size_t at = 0; at < schema.attrs.size(); ++at) {
      if (a.attrF[at].empty() && a.attrU[at].empty()) {
        // Absent in the input: absent in the part, or zero-padded because a neighbour had it.
        for (float v : b.attrF[at]) EXPECT_EQ(v, 0.0f);
        for (uint32_t v : b.attrU[at]) EXPECT_EQ(v, 0u);
        continue;
      }
      ASSERT_EQ(a.attrF[at].size(), b.attrF[at].size()) << schema.attrs[at].name;
      for (size_t i = 0; i < a.attrF[at].size(); ++i) expectBitEqual(a.attrF[at][i], b.attrF[at][i], schema.attrs[at].name);
      EXPECT_EQ(a.attrU[at], b.attrU[at]) << schema.attrs[at].name;
    }
  }
}

struct Written {
  FlatStore input;
  WriteStats stats;
};

Written writeRandomStore(const std::string& path, const StoreMeta& meta, const std::vector<test::GridSpec>& specs, int gridsEach, WriterOptions options = {},
                         uint64_t seed = 7) {
  Written w;
  StoreWriter writer(path, meta, options);
  Rng rng(seed);
  uint32_t mpid = 0, gridId = 0;
  for (int n = 0; n < gridsEach; ++n)
    for (auto spec : specs) {
      if (spec.knots > 1) {
        Schedule s;
        for (int k = 0; k < spec.knots; ++k) s.push_back(double(k) / (spec.knots - 1));
        spec.schedule = writer.addSchedule(s);
      }
      auto g = test::randomGrid(rng, meta.schema, spec, gridId++, mpid);
      writer.addGrid(g.view());
      test::flatten(g, meta.schema, w.input);
    }
  w.stats = writer.close();
  return w;
}

}  // namespace

TEST(StoreRoundTrip, EveryAttributeTypeAndKnotCountIsBitExact) {
  test::ScratchDir dir;
  const Schema schema = test::fullSchema();
  for (int knots = 1; knots <= 8; ++knots) {
    SCOPED_TRACE("knots " + std::to_string(knots));
    std::string path = dir.path("k" + std::to_string(knots) + ".mps");
    test::GridSpec spec;
    spec.knots = knots;
    spec.nu = 7, spec.nv = 5;
    auto w = writeRandomStore(path, test::testMeta(schema), {spec}, 40);
    StoreReader reader(path);
    EXPECT_EQ(reader.micropolygonCount(), w.input.size());
    compareExact(w.input, test::flatten(reader), schema);
    EXPECT_NO_THROW(reader.verify());
  }
}

TEST(StoreRoundTrip, SpillsUnderATinyMemoryBudgetWithoutLosingOrder) {
  test::ScratchDir dir;
  const Schema schema = test::fullSchema();
  test::GridSpec spec;
  spec.knots = 2;
  spec.nu = spec.nv = 8;
  spec.spread = 0.5;  // small grids: many land in the same tiles
  WriterOptions tiny;
  tiny.memoryBudget = 256 << 10;
  tiny.maxPartMicropolygons = 50;
  auto w = writeRandomStore(dir.path("spill.mps"), test::testMeta(schema), {spec}, 300, tiny);
  StoreReader reader(dir.path("spill.mps"));
  EXPECT_GT(reader.entries().size(), w.stats.tiles) << "a tiny budget must split tiles into several parts";
  // Over budget only by what one grid adds: at most 16 KB per tile it touches (~25 here).
  EXPECT_LE(w.stats.peakBufferedBytes, tiny.memoryBudget + 512 * 1024u) << "the writer must honour its budget";
  compareExact(w.input, test::flatten(reader), schema);
  reader.verify();

  // Producer order inside a tile: within each (tile, schedule), mpids increase part after part.
  const int mpid = schema.find("mpid");
  std::map<std::tuple<int, int, uint32_t>, uint32_t> lastId;
  for (size_t e = 0; e < reader.entries().size(); ++e) {
    const auto& en = reader.entries()[e];
    TilePart p = reader.decode(e);
    auto key = std::tuple(en.tx, en.ty, en.schedule);
    for (uint32_t id : p.attrs[size_t(mpid)].u) {
      auto it = lastId.find(key);
      if (it != lastId.end()) {
        EXPECT_LT(it->second, id) << "order broken in tile " << en.tx << "," << en.ty;
      }
      lastId[key] = id;
    }
  }
}

TEST(StoreRoundTrip, MixedSchedulesTrianglesAndPartialAttributes) {
  test::ScratchDir dir;
  const Schema schema = test::fullSchema();
  std::vector<test::GridSpec> specs(4);
  specs[0].knots = 1;
  specs[1].knots = 2;
  specs[2].knots = 3, specs[2].triangles = true;
  specs[3].knots = 2, specs[3].dropOptional = true;
  auto w = writeRandomStore(dir.path("mixed.mps"), test::testMeta(schema), specs, 50);
  StoreReader reader(dir.path("mixed.mps"));
  EXPECT_EQ(reader.meta().schedules.size(), 3u);  // static, [0 1], [0 0.5 1]
  compareExact(w.input, test::flatten(reader), schema);
  reader.verify();
  bool sawTriangles = false;
  for (const auto& e : reader.entries()) sawTriangles |= (e.effects & kEffectTriangles) != 0;
  EXPECT_TRUE(sawTriangles);
}

TEST(StoreRoundTrip, StillGridsAreStoredStatic) {
  // A P + blurP dump gives every grid two knots, the static ones two equal knots. The writer
  // stores those static (schedule 0, one knot, parts whose effects say "not moving") so that
  // re-sampling draws them on its static path; a grid one ulp away from still keeps its knots.
  test::ScratchDir dir;
  const Schema schema = test::fullSchema();
  const StoreMeta meta = test::testMeta(schema);
  StoreWriter writer(dir.path("still.mps"), meta, {});
  const uint32_t twoKnots = writer.addSchedule({0.0, 1.0});
  Rng rng(11);
  FlatStore expected;
  std::set<uint32_t> stillGrids;
  uint32_t mpid = 0, gridId = 0;
  uint64_t stillCount = 0;
  for (int n = 0; n < 60; ++n) {
    test::GridSpec spec;
    spec.knots = 2, spec.schedule = twoKnots;
    spec.spread = 0.5;       // small grids: still and moving ones share tiles
    const int kind = n % 3;  // 0 still, 1 moving, 2 still but for one coordinate one ulp off
    spec.motion = kind == 1 ? 0.5 : 0.0;
    auto g = test::randomGrid(rng, schema, spec, gridId++, mpid);
    if (kind == 2) {
      float& x = g.positions[g.numVertices + g.numVertices / 2].x;
      x = std::nextafter(x, INFINITY);
    }
    writer.addGrid(g.view());
    FlatStore in;
    test::flatten(g, schema, in);
    for (auto& [id, mp] : in) {
      if (kind == 0) mp.schedule = 0, mp.positions.resize(4);  // knot 0's corners
      expected[id] = mp;
    }
    if (kind == 0) stillGrids.insert(g.gridId), stillCount += g.corners.size() / 4;
  }
  const WriteStats stats = writer.close();
  EXPECT_EQ(stats.stillMicropolygons, stillCount);
  StoreReader reader(dir.path("still.mps"));
  reader.verify();
  compareExact(expected, test::flatten(reader), schema);
  size_t staticParts = 0, movingParts = 0;
  for (size_t e = 0; e < reader.entries().size(); ++e) {
    const auto& en = reader.entries()[e];
    const TilePart part = reader.decode(e);
    for (uint32_t m = 0; m < part.numMicropolygons; ++m) EXPECT_EQ(en.schedule == 0, stillGrids.count(part.gridId[m]) == 1) << "grid " << part.gridId[m];
    if (en.schedule == 0) {
      ++staticParts;
      EXPECT_EQ(part.numKnots, 1u);
      EXPECT_FALSE(en.effects & kEffectMoving);
    } else {
      // Moving exactly when one of its vertices moves (a part of the nudged grid may not hold
      // the nudged vertex).
      bool moves = false;
      for (uint32_t v = 0; v < part.numVertices; ++v) moves |= part.position(1, v) != part.position(0, v);
      EXPECT_EQ((en.effects & kEffectMoving) != 0, moves);
      movingParts += moves;
    }
  }
  EXPECT_GT(staticParts, 0u);
  EXPECT_GT(movingParts, 0u);
}

TEST(StoreRoundTrip, SameInputGivesIdenticalBytes) {
  test::ScratchDir dir;
  const Schema schema = test::fullSchema();
  test::GridSpec spec;
  spec.knots = 2;
  writeRandomStore(dir.path("a.mps"), test::testMeta(schema), {spec}, 100);
  writeRandomStore(dir.path("b.mps"), test::testMeta(schema), {spec}, 100);
  EXPECT_EQ(test::readBytes(dir.path("a.mps")), test::readBytes(dir.path("b.mps")));
}

TEST(StoreRoundTrip, LossyCodecsStayWithinTheirStatedBounds) {
  test::ScratchDir dir;
  const Schema schema = test::fullSchema(AttrCodec::Half, AttrCodec::Unorm16, AttrCodec::Oct32);
  test::GridSpec spec;
  spec.knots = 2;
  auto w = writeRandomStore(dir.path("lossy.mps"), test::testMeta(schema), {spec}, 60);
  StoreReader reader(dir.path("lossy.mps"));
  FlatStore out = test::flatten(reader);
  ASSERT_EQ(out.size(), w.input.size());
  size_t checked = 0;
  for (const auto& [id, a] : w.input) {
    const auto& b = out.at(id);
    for (size_t i = 0; i < a.positions.size(); ++i) EXPECT_EQ(a.positions[i], b.positions[i]) << "positions stay lossless";
    for (size_t at = 0; at < schema.attrs.size(); ++at) {
      const auto& d = schema.attrs[at];
      ASSERT_EQ(a.attrF[at].size(), b.attrF[at].size());
      if (d.codec == AttrCodec::Half) {
        for (size_t i = 0; i < a.attrF[at].size(); ++i) {
          float v = a.attrF[at][i];
          EXPECT_LE(std::abs(b.attrF[at][i] - v), std::max(std::ldexp(std::abs(v), -11), 0x1.0p-25f)) << d.name;
          ++checked;
        }
      } else if (d.codec == AttrCodec::Unorm16) {
        for (size_t i = 0; i < a.attrF[at].size(); ++i) EXPECT_LE(std::abs(b.attrF[at][i] - a.attrF[at][i]), 0.5f / 65535.0f + 1e-7f) << d.name;
      } else if (d.codec == AttrCodec::Oct32) {
        for (size_t i = 0; i + 2 < a.attrF[at].size(); i += 3) {
          glm::dvec3 x(a.attrF[at][i], a.attrF[at][i + 1], a.attrF[at][i + 2]), y(b.attrF[at][i], b.attrF[at][i + 1], b.attrF[at][i + 2]);
          EXPECT_LE(std::atan2(glm::length(glm::cross(x, y)), glm::dot(x, y)), 5e-5) << d.name;
        }
      }
    }
  }
  EXPECT_GT(checked, 1000u);
}

TEST(StoreRoundTrip, ConcurrentCachedReadsAgreeAndRespectTheBudget) {
  test::ScratchDir dir;
  const Schema schema = test::fullSchema();
  test::GridSpec spec;
  spec.knots = 2;
  spec.nu = spec.nv = 8;
  writeRandomStore(dir.path("c.mps"), test::testMeta(schema), {spec}, 200);
  ReaderOptions opt;
  opt.cacheBytes = 64 << 10;
  StoreReader reader(dir.path("c.mps"), opt);
  const size_t n = reader.entries().size();
  ASSERT_GT(n, 4u);
  std::vector<TilePart> reference;
  for (size_t e = 0; e < n; ++e) reference.push_back(reader.decode(e));
  size_t largest = 0;
  for (const auto& p : reference) largest = std::max(largest, p.memoryBytes());
  // Each part asked for four times running: hits do not depend on how threads interleave (a
  // cyclic walk over more parts than the budget holds hits only when two threads meet).
  tbb::parallel_for(size_t(0), n * 20, [&](size_t i) {
    size_t e = ((i / 4) * 7919) % n;
    auto p = reader.part(e);
    EXPECT_EQ(p->positions, reference[e].positions);
    EXPECT_EQ(p->corners, reference[e].corners);
  });
  CacheStats st = reader.cacheStats();
  EXPECT_GT(st.hits, 0u);
  EXPECT_LE(st.peakBytes, opt.cacheBytes + largest);
}

TEST(StoreRoundTrip, VisitFindsExactlyThePartsWhoseBoundsTouchTheRectangle) {
  test::ScratchDir dir;
  const Schema schema = test::fullSchema();
  test::GridSpec spec;
  spec.knots = 3;
  writeRandomStore(dir.path("v.mps"), test::testMeta(schema), {spec}, 100);
  StoreReader reader(dir.path("v.mps"));
  RasterRect rect{40, 30, 90, 70, false};
  std::vector<size_t> visited;
  reader.visit(rect, 0.25, 0.5, [&](size_t e) { visited.push_back(e); });
  std::vector<size_t> expected;
  for (size_t e = 0; e < reader.entries().size(); ++e)
    if (reader.bounds(e, 0.25, 0.5).overlaps(rect)) expected.push_back(e);
  EXPECT_EQ(visited, expected);
  EXPECT_FALSE(expected.empty());
  EXPECT_LT(expected.size(), reader.entries().size());
}

// Frame rates as pipelines write them: broadcast decimals map to their exact NTSC rationals,
// fractions and integers are taken as written, and anything that is not a positive rate (zero,
// negative, below a millionth - which would round to 0/N - or not a number) is refused.
TEST(StoreRational, RatesParseExactlyAndNonRatesAreRefused) {
  const std::pair<const char*, Rational> good[] = {{"24", {24, 1}},     {"29.97", {30000, 1001}},   {"23.976", {24000, 1001}}, {"30000/1001", {30000, 1001}},
                                                   {"12.5", {125, 10}}, {"0.000001", {1, 1000000}}, {"59.94", {60000, 1001}}};
  for (const auto& [text, want] : good) {
    Rational r{0, 0};
    EXPECT_TRUE(parseRational(text, r)) << text;
    EXPECT_EQ(r, want) << text;
  }
  for (const char* text : {"0", "0.0000001", "-24", "0/1", "24/0", "x", "24fps", "", "nan", "1e7"}) {
    Rational r{7, 3};
    EXPECT_FALSE(parseRational(text, r)) << text;
    EXPECT_GT(r.num, 0) << text << ": a refused rate must not be left as 0/N";
  }
}

TEST(StoreRoundTrip, LightsAndSceneVolumesRoundTripAsFormatVersion3) {
  test::ScratchDir dir;
  const Schema schema = test::fullSchema();
  test::GridSpec spec;
  StoreMeta meta = test::testMeta(schema);
  writeRandomStore(dir.path("plain.mps"), meta, {spec}, 10);
  EXPECT_EQ(test::readBytes(dir.path("plain.mps")).at(8), 1u) << "no lights, no volumes, no shading times: version 1, as older builds wrote it";
  StoredLight spot;
  spot.kind = StoredLight::Kind::Spot;
  spot.position = {1, 2, -3}, spot.axis = glm::normalize(glm::dvec3(0, -1, 1)), spot.colour = {5, 4, 3};
  spot.cosOuter = 0.8, spot.cosInner = 0.9, spot.beam = 3;
  StoredLight sun;
  sun.kind = StoredLight::Kind::Distant;
  meta.lights = {spot, sun};
  StoredVolume smoke;
  smoke.path = "smoke.0001.vdb", smoke.density = "density";
  smoke.times = {0.0, 0.5};
  smoke.fileToCamera = {glm::dmat4(1.0), glm::dmat4(2.0)};
  meta.volumes = {smoke};
  writeRandomStore(dir.path("lit.mps"), meta, {spec}, 10);
  EXPECT_EQ(test::readBytes(dir.path("lit.mps")).at(8), 3u);
  const StoreReader reader(dir.path("lit.mps"));
  EXPECT_EQ(reader.meta().lights, meta.lights);
  EXPECT_EQ(reader.meta().volumes, meta.volumes);
  EXPECT_TRUE(reader.meta().shadingTimes.empty());
  // A light's terms: RenderMan's point falloff and spot cone.
  glm::dvec3 L, Cl;
  ASSERT_TRUE(spot.illuminate(spot.position + 2.0 * spot.axis, L, Cl));
  EXPECT_NEAR(Cl.x, 5.0 / 4.0, 1e-12);                                        // on the axis: full cone, cos^beam = 1, 1/d²
  EXPECT_FALSE(spot.illuminate(spot.position + glm::dvec3(0, 1, 0), L, Cl));  // outside the cone
  // A light that is not finite is refused when the store is written.
  meta.lights[0].colour.x = NAN;
  EXPECT_THROW(meta.validate("test"), Error);
}
