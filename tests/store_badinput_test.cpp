// Damaged and hostile stores: each gives an Error naming the file (and the tile where there is
// one), never a crash. Files are damaged byte by byte or crafted with the format's own functions.
#include <cmath>
#include <cstring>
#include <filesystem>

#include <gtest/gtest.h>

#include "common/error.h"
#include "store/codec.h"
#include "store/format.h"
#include "tests/fuzz/store_fuzz_input.h"
#include "tests/store_test_util.h"
#include "tests/test_util.h"

using namespace reshutter;
using namespace reshutter::store;

namespace {

std::string goodStore(const test::ScratchDir& dir, const std::string& name = "good.mps") {
  const Schema schema = test::fullSchema();
  std::string path = dir.path(name);
  StoreWriter w(path, test::testMeta(schema));
  test::GridSpec spec;
  spec.knots = 2;
  spec.schedule = w.addSchedule({0.0, 1.0});
  Rng rng(1);
  uint32_t id = 0;
  for (int g = 0; g < 30; ++g) w.addGrid(test::randomGrid(rng, schema, spec, uint32_t(g), id).view());
  w.close();
  return path;
}

// Expects opening (and verifying) `path` to fail with an Error whose message contains `needle`.
void expectRejected(const std::string& path, const std::string& needle) {
  try {
    StoreReader r(path);
    r.verify();
    ADD_FAILURE() << "accepted " << path << " (expected: " << needle << ")";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find(path), std::string::npos) << "message must name the file: " << e.what();
    EXPECT_NE(std::string(e.what()).find(needle), std::string::npos) << e.what();
    EXPECT_EQ(std::string(e.what()).find('\n'), std::string::npos) << "one line";
  }
}

struct Footer {
  uint64_t metaOffset, metaSize, metaSum, indexOffset, indexSize, indexSum;
};
Footer footerOf(const std::vector<uint8_t>& b) {
  Footer f;
  std::memcpy(&f, b.data() + b.size() - kFooterSize, sizeof f);
  return f;
}

// Re-serialises meta and index after `edit`, keeping checksums valid: tests what the reader
// does with well-formed but lying content.
template <typename Edit>
void rewrite(const std::string& path, Edit edit) {
  auto bytes = test::readBytes(path);
  Footer f = footerOf(bytes);
  ByteReader mr({bytes.data() + f.metaOffset, f.metaSize}, "meta");
  StoreMeta meta = readMeta(mr, 1);
  ByteReader ir({bytes.data() + f.indexOffset, f.indexSize}, "index");
  auto entries = readIndex(ir, meta);
  edit(meta, entries);
  ByteWriter mw, iw;
  writeMeta(meta, mw);
  writeIndex(entries, meta, iw);
  std::vector<uint8_t> out(bytes.begin(), bytes.begin() + long(f.metaOffset));
  const uint32_t version = formatVersionFor(meta);  // the edit may need a later format
  std::memcpy(out.data() + 8, &version, 4);
  Footer nf{f.metaOffset, mw.size(), checksum(mw.bytes()), f.metaOffset + mw.size(), iw.size(), checksum(iw.bytes())};
  out.insert(out.end(), mw.bytes().begin(), mw.bytes().end());
  out.insert(out.end(), iw.bytes().begin(), iw.bytes().end());
  const uint8_t* nfp = reinterpret_cast<const uint8_t*>(&nf);
  out.insert(out.end(), nfp, nfp + sizeof nf);
  out.insert(out.end(), kFooterMagic, kFooterMagic + 8);
  uint32_t tail[2] = {formatVersionFor(meta), 0};
  const uint8_t* tp = reinterpret_cast<const uint8_t*>(tail);
  out.insert(out.end(), tp, tp + 8);
  test::writeBytes(path, out);
}

// Builds a store by hand around one payload the writer would refuse to produce.
void craftWithPart(const std::string& path, const StoreMeta& meta, TileEntry entry, const TilePart& part) {
  std::vector<uint8_t> raw, compressed;
  encodeRaw(meta.schema, part, entry.attrPresence, raw);
  compress(raw, 1, compressed);
  entry.offset = kHeaderSize;
  entry.rawSize = uint32_t(raw.size());
  entry.compressedSize = uint32_t(compressed.size());
  entry.checksum = checksum(compressed);
  std::vector<uint8_t> out(kHeaderMagic, kHeaderMagic + 8);
  uint32_t hv[2] = {formatVersionFor(meta), 0};
  out.insert(out.end(), reinterpret_cast<uint8_t*>(hv), reinterpret_cast<uint8_t*>(hv) + 8);
  out.insert(out.end(), compressed.begin(), compressed.end());
  ByteWriter mw, iw;
  writeMeta(meta, mw);
  writeIndex({entry}, meta, iw);
  Footer f{out.size(), mw.size(), checksum(mw.bytes()), out.size() + mw.size(), iw.size(), checksum(iw.bytes())};
  out.insert(out.end(), mw.bytes().begin(), mw.bytes().end());
  out.insert(out.end(), iw.bytes().begin(), iw.bytes().end());
  out.insert(out.end(), reinterpret_cast<uint8_t*>(&f), reinterpret_cast<uint8_t*>(&f) + sizeof f);
  out.insert(out.end(), kFooterMagic, kFooterMagic + 8);
  out.insert(out.end(), reinterpret_cast<uint8_t*>(hv), reinterpret_cast<uint8_t*>(hv) + 8);
  test::writeBytes(path, out);
}

TilePart oneQuad(const Schema& schema, glm::vec3 p0) {
  TilePart p;
  p.numVertices = 4, p.numMicropolygons = 1, p.numKnots = 1;
  p.positions = {p0, p0 + glm::vec3(1, 0, 0), p0 + glm::vec3(1, 1, 0), p0 + glm::vec3(0, 1, 0)};
  p.corners = {0, 1, 2, 3};
  p.objectId = {0}, p.gridId = {0}, p.flags = {0};
  p.attrs.resize(schema.attrs.size());
  p.attrs[size_t(schema.ci())].f.assign(12, 0.5f);
  p.attrs[size_t(schema.oi())].f.assign(12, 1.0f);
  return p;
}

Schema minimalSchema() {
  Schema s;
  s.attrs = {{"Ci", AttrType::Color, AttrRate::Vertex, AttrCodec::Lossless}, {"Oi", AttrType::Color, AttrRate::Vertex, AttrCodec::Lossless}};
  return s;
}

}  // namespace

TEST(StoreBadInput, TruncatedAnywhere) {
  test::ScratchDir dir;
  auto bytes = test::readBytes(goodStore(dir));
  for (size_t keep : {size_t(0), size_t(7), size_t(16), size_t(100), bytes.size() / 2, bytes.size() - 70, bytes.size() - 1}) {
    std::string path = dir.path("cut" + std::to_string(keep) + ".mps");
    test::writeBytes(path, std::vector<uint8_t>(bytes.begin(), bytes.begin() + long(keep)));
    try {
      StoreReader r(path);
      r.verify();
      ADD_FAILURE() << "accepted a file cut to " << keep << " bytes";
    } catch (const Error& e) {
      EXPECT_NE(std::string(e.what()).find(path), std::string::npos) << e.what();
    }
  }
}

TEST(StoreBadInput, WrongMagicAndNewerVersion) {
  test::ScratchDir dir;
  auto bytes = test::readBytes(goodStore(dir));
  auto magic = bytes;
  magic[0] = 'X';
  test::writeBytes(dir.path("magic.mps"), magic);
  expectRejected(dir.path("magic.mps"), "not a reshutter store");
  auto newer = bytes;
  newer[8] = uint8_t(kFormatVersion + 1);
  test::writeBytes(dir.path("newer.mps"), newer);
  expectRejected(dir.path("newer.mps"), "newer reshutter");
}

TEST(StoreBadInput, PayloadChecksumMismatchNamesTheTile) {
  test::ScratchDir dir;
  std::string path = goodStore(dir);
  auto bytes = test::readBytes(path);
  bytes[kHeaderSize + 5] ^= 0x40;  // inside the first part's payload
  test::writeBytes(dir.path("flip.mps"), bytes);
  expectRejected(dir.path("flip.mps"), "checksum mismatch");
  try {
    StoreReader r(dir.path("flip.mps"));
    r.verify();
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("tile ("), std::string::npos) << e.what();
  }
}

TEST(StoreBadInput, IndexAndMetadataChecksums) {
  test::ScratchDir dir;
  auto bytes = test::readBytes(goodStore(dir));
  Footer f = footerOf(bytes);
  auto idx = bytes;
  idx[f.indexOffset + 20] ^= 1;
  test::writeBytes(dir.path("idx.mps"), idx);
  expectRejected(dir.path("idx.mps"), "index: checksum mismatch");
  auto meta = bytes;
  meta[f.metaOffset + 3] ^= 1;
  test::writeBytes(dir.path("meta.mps"), meta);
  expectRejected(dir.path("meta.mps"), "metadata: checksum mismatch");
}

TEST(StoreBadInput, IndexOffsetsOutOfRange) {
  test::ScratchDir dir;
  std::string path = goodStore(dir);
  rewrite(path, [](StoreMeta&, std::vector<TileEntry>& e) { e[1].offset = 1ull << 40; });
  expectRejected(path, "outside the data section");
  path = goodStore(dir, "b.mps");
  rewrite(path, [](StoreMeta&, std::vector<TileEntry>& e) { e[0].numMicropolygons += 1; });
  expectRejected(path, "does not match its counts");
  path = goodStore(dir, "c.mps");
  rewrite(path, [](StoreMeta&, std::vector<TileEntry>& e) { e[0].schedule = 99; });
  expectRejected(path, "motion schedule 99");
}

TEST(StoreBadInput, KnotTimesNotIncreasing) {
  test::ScratchDir dir;
  const Schema schema = test::fullSchema();
  StoreWriter w(dir.path("k.mps"), test::testMeta(schema));
  EXPECT_THROW(w.addSchedule({0.0, 0.5, 0.5}), Error);
  EXPECT_THROW(w.addSchedule({0.6, 0.2}), Error);
  EXPECT_THROW(w.addSchedule({0.0, 1.5}), Error);  // outside the shutter
  EXPECT_THROW(w.addSchedule({0.0, NAN}), Error);

  std::string path = goodStore(dir);
  rewrite(path, [](StoreMeta& m, std::vector<TileEntry>&) { m.schedules[1] = {0.7, 0.3}; });
  expectRejected(path, "not strictly increasing");
}

TEST(StoreBadInput, CameraMotionRoundTripsAndIsChecked) {
  // A moving camera is kept (format 5) and read back exactly; a store without one stays at the
  // format it had, so older builds still read it; motion that is not a motion is refused.
  test::ScratchDir dir;
  const std::string still = goodStore(dir, "still.mps");
  EXPECT_LT(test::readBytes(still)[8], 5) << "a store without camera motion was written as format 5";
  const Schema schema = test::fullSchema();
  StoreMeta meta = test::testMeta(schema);
  Camera& c = meta.cameras[0];
  c.motionTimes = {0.0, 0.25, 1.0};
  for (double t : c.motionTimes) {
    glm::dmat4 m(1.0);
    m[3][0] = -2 * t, m[3][2] = 0.5 * t * t;
    c.motionWorldToCamera.push_back(m);
  }
  c.worldToCamera = c.motionWorldToCamera[0];
  {
    StoreWriter w(dir.path("moving.mps"), meta);
    w.close();
  }
  EXPECT_EQ(test::readBytes(dir.path("moving.mps"))[8], 5);
  StoreReader r(dir.path("moving.mps"));
  EXPECT_TRUE(r.meta().cameras[0] == c);
  EXPECT_EQ(r.meta().cameras[0].worldToCameraAt(0.625)[3][0], -2 * 0.625) << "between motion times the transform is linear";
  EXPECT_EQ(r.meta().cameras[0].worldToCameraAt(7.0), c.motionWorldToCamera.back()) << "after the last time it is held";

  auto bad = [&](const char* name, const std::vector<double>& times, size_t mats, const std::string& needle) {
    const std::string path = goodStore(dir, name);
    rewrite(path, [&](StoreMeta& m, std::vector<TileEntry>&) {
      m.cameras[0].motionTimes = times;
      m.cameras[0].motionWorldToCamera.assign(mats, glm::dmat4(1.0));
      m.cameras[0].motionWorldToCamera.back()[3][0] = 1;
    });
    expectRejected(path, needle);
  };
  bad("outside.mps", {0.0, 2.0}, 2, "outside the shutter");
  bad("backwards.mps", {0.5, 0.2}, 2, "not strictly increasing");
  StoreMeta unpaired = meta;  // the file cannot say this: the writer refuses it
  unpaired.cameras[0].motionWorldToCamera.pop_back();
  EXPECT_THROW(StoreWriter(dir.path("unpaired.mps"), unpaired), Error);
  EXPECT_FALSE(std::filesystem::exists(dir.path("unpaired.mps")));
}

TEST(StoreBadInputHard, NonFinitePositionsAndAttributesAreRejected) {
  test::ScratchDir dir;
  const Schema schema = minimalSchema();
  StoreMeta meta = test::testMeta(schema);
  {
    StoreWriter w(dir.path("w.mps"), meta);
    TilePart q = oneQuad(schema, {0, 0, 5});
    q.positions[2].y = NAN;
    GridInput g;
    g.numVertices = 4;
    g.positions = q.positions;
    g.corners = q.corners;
    g.gridId = 17;
    g.attrs = {AttrValues{q.attrs[0].f, {}}, AttrValues{q.attrs[1].f, {}}};
    try {
      w.addGrid(g);
      ADD_FAILURE() << "NaN position accepted";
    } catch (const Error& e) {
      EXPECT_NE(std::string(e.what()).find("grid 17"), std::string::npos) << e.what();
      EXPECT_NE(std::string(e.what()).find("non-finite"), std::string::npos) << e.what();
    }
    EXPECT_THROW(w.close(), Error);  // a failed store is never completed
  }
  EXPECT_FALSE(std::filesystem::exists(dir.path("w.mps")));

  // On read: a position, or a lossless attribute (which keeps its bits, so the value reaches the
  // reader) in its last component, where a check that stopped short would miss it.
  for (float bad : {NAN, INFINITY, -INFINITY})
    for (bool inAttribute : {false, true}) {
      TilePart q = oneQuad(schema, {0, 0, 5});
      if (inAttribute) q.attrs[1].f.back() = bad;
      else q.positions[1].x = bad;
      TileEntry e;
      e.tx = e.ty = 0;
      e.numMicropolygons = 1, e.numVertices = 4;
      e.attrPresence = 3;
      e.knots.resize(1);
      std::string path = dir.path("nan.mps");
      craftWithPart(path, meta, e, q);
      expectRejected(path, inAttribute ? "attribute 'Oi' holds a non-finite value" : "non-finite position");
    }
}

TEST(StoreBadInput, CornerIndexOutOfRange) {
  test::ScratchDir dir;
  const Schema schema = minimalSchema();
  StoreMeta meta = test::testMeta(schema);
  TilePart q = oneQuad(schema, {0, 0, 5});
  q.corners[2] = 4;
  TileEntry e;
  e.numMicropolygons = 1, e.numVertices = 4, e.attrPresence = 3;
  e.knots.resize(1);
  craftWithPart(dir.path("corner.mps"), meta, e, q);
  expectRejected(dir.path("corner.mps"), "names vertex 4");
}

TEST(StoreBadInput, BoundsThatLieAreCaughtByVerify) {
  test::ScratchDir dir;
  std::string path = goodStore(dir);
  rewrite(path, [](StoreMeta&, std::vector<TileEntry>& e) {
    for (auto& k : e[0].knots) k.raster[2] = k.raster[0];  // collapse x extent
  });
  expectRejected(path, "outside the raster bound");
}

TEST(StoreBadInput, WriterRejectsInconsistentGrids) {
  test::ScratchDir dir;
  const Schema schema = minimalSchema();
  StoreWriter w(dir.path("x.mps"), test::testMeta(schema));
  TilePart q = oneQuad(schema, {0, 0, 5});
  GridInput g;
  g.numVertices = 4;
  g.positions = q.positions;
  g.corners = q.corners;
  g.attrs = {AttrValues{q.attrs[0].f, {}}, AttrValues{q.attrs[1].f, {}}};
  GridInput bad = g;
  bad.schedule = 3;
  EXPECT_THROW(w.addGrid(bad), Error);
  StoreWriter w2(dir.path("y.mps"), test::testMeta(schema));
  bad = g;
  std::vector<float> shortCi(5, 0.0f);
  bad.attrs[0].f = shortCi;
  EXPECT_THROW(w2.addGrid(bad), Error);
  StoreWriter w3(dir.path("z.mps"), test::testMeta(schema));
  bad = g;
  bad.attrs[1] = {};
  EXPECT_THROW(w3.addGrid(bad), Error);  // Oi is required
}

TEST(StoreBadInput, FuzzCorpusNeverCrashes) {
  // Inputs found by the fuzz target (tests/fuzz/) and hand-made damaged files: each must open
  // and verify, or fail with an Error - under the sanitizer build this catches regressions.
  const std::filesystem::path corpus = test::sourceDir() + "/tests/corpus/store";
  ASSERT_TRUE(std::filesystem::exists(corpus));
  size_t n = 0;
  test::ScratchDir dir;
  for (const auto& f : std::filesystem::directory_iterator(corpus)) {
    ++n;
    auto input = test::readBytes(f.path().string());
    std::string path = dir.path("case.mps");
    test::writeBytes(path, storeFromFuzzInput(input.data(), input.size()));
    try {
      StoreReader r(path);
      r.verify();
      for (size_t e = 0; e < r.entries().size(); ++e) r.part(e);
    } catch (const Error&) {
    }
  }
  EXPECT_GT(n, 0u);
}
