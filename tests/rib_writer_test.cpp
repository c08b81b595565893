// RIB dump writer (rib/writer.h): what it writes, read back with the project's own RIB reader,
// is the header and the grids it was given - every float bit for bit, triangles as three corners,
// blurP only on moving grids - plain and gzipped alike.
#include <cmath>
#include <cstring>
#include <limits>
#include <map>
#include <random>

#include <gtest/gtest.h>

#include "common/check.h"
#include "rib/rib.h"
#include "rib/writer.h"
#include "tests/test_util.h"

using namespace reshutter;
using namespace reshutter::rib;

namespace {

struct ReadGrid {
  std::vector<double> nverts, verts;
  std::map<std::string, std::vector<double>> params;  // parameter name → its numbers
};

/// What a dump reads back as: the request names in order, the header's values, the grids.
struct ReadBack : RequestHandler {
  std::vector<std::string> names;
  std::map<std::string, std::vector<Value>> header;  // request → its values (last occurrence)
  std::vector<ReadGrid> grids;
  bool handle(const Request& r, const Args& a) override {
    names.emplace_back(r.name);
    if (r.name != "PointsPolygons") {
      header[std::string(r.name)] = r.values;
      return true;
    }
    ReadGrid g;
    g.nverts = a.numbers(0), g.verts = a.numbers(1);
    for (const Param& p : a.params(2)) g.params[p.decl.name] = p.value->isNumber() ? std::vector<double>{p.value->number} : p.value->numbers;
    grids.push_back(std::move(g));
    return true;
  }
};

ReadBack readBack(const std::string& path) {
  Reader reader;
  ReadBack h;
  reader.parseFile(path, h);
  return h;
}

/// A grid with its own storage; triangles where `triangle(m)` says so.
struct OwnedGrid {
  uint32_t numVertices = 0;
  std::vector<uint32_t> corners;
  std::vector<float> P, blurP, Cs, Os;
  DumpGrid view() const { return {numVertices, corners, P, blurP, Cs, Os}; }
};

/// Floats from every exponent range, denormals, zeros and the extremes among them: the shortest
/// text must still read back as the same float.
float awkwardFloat(std::mt19937& rng) {
  std::uniform_int_distribution<int> pick(0, 9);
  switch (pick(rng)) {
    case 0: return std::numeric_limits<float>::denorm_min() * float(1 + rng() % 1000);
    case 1: return -0.0f;
    case 2: return std::numeric_limits<float>::max();
    case 3: return -std::numeric_limits<float>::min();
    case 4: return 0.1f;
    default: {
      uint32_t bits = uint32_t(rng());
      float f;
      std::memcpy(&f, &bits, 4);
      return std::isfinite(f) ? f : 1.0f / 3.0f;
    }
  }
}

OwnedGrid randomGrid(std::mt19937& rng, uint32_t numVertices, uint32_t numPolygons, bool moving) {
  OwnedGrid g;
  g.numVertices = numVertices;
  for (uint32_t m = 0; m < numPolygons; ++m) {
    for (int j = 0; j < 3; ++j) g.corners.push_back(uint32_t(rng() % numVertices));
    g.corners.push_back(m % 3 == 1 ? kNoCorner : uint32_t(rng() % numVertices));  // every third a triangle
  }
  for (uint32_t i = 0; i < numVertices * 3; ++i) g.P.push_back(awkwardFloat(rng));
  if (moving)
    for (uint32_t i = 0; i < numVertices * 3; ++i) g.blurP.push_back(awkwardFloat(rng));
  for (uint32_t i = 0; i < numVertices * 3; ++i) g.Cs.push_back(awkwardFloat(rng)), g.Os.push_back(awkwardFloat(rng));
  return g;
}

/// `read` (doubles from the reader) holds exactly the floats `written`, bit for bit, the sign of
/// zero included (the writer writes -0.0f as "-0").
void expectSameFloats(const std::vector<float>& written, const std::vector<double>& read, const std::string& what) {
  ASSERT_EQ(written.size(), read.size()) << what;
  for (size_t i = 0; i < written.size(); ++i) {
    const float r = float(read[i]);
    EXPECT_EQ(std::memcmp(&r, &written[i], 4), 0) << what << "[" << i << "]: wrote " << written[i] << ", read " << r;
  }
}

void expectGridReadsBack(const OwnedGrid& g, const ReadGrid& r) {
  std::vector<double> nverts, verts;
  for (size_t m = 0; m < g.corners.size() / 4; ++m) {
    nverts.push_back(g.corners[m * 4 + 3] == kNoCorner ? 3 : 4);
    for (int j = 0; j < 4; ++j)
      if (g.corners[m * 4 + j] != kNoCorner) verts.push_back(g.corners[m * 4 + j]);
  }
  EXPECT_EQ(r.nverts, nverts);
  EXPECT_EQ(r.verts, verts);
  ASSERT_TRUE(r.params.count("P") && r.params.count("Cs") && r.params.count("Os"));
  expectSameFloats(g.P, r.params.at("P"), "P");
  expectSameFloats(g.Cs, r.params.at("Cs"), "Cs");
  expectSameFloats(g.Os, r.params.at("Os"), "Os");
  EXPECT_EQ(r.params.count("blurP"), g.blurP.empty() ? 0u : 1u);
  if (!g.blurP.empty()) expectSameFloats(g.blurP, r.params.at("blurP"), "blurP");
}

std::vector<double> numbersOf(const std::vector<Value>& values) {
  std::vector<double> out;
  for (const Value& v : values)
    if (v.isNumber()) out.push_back(v.number);
    else out.insert(out.end(), v.numbers.begin(), v.numbers.end());
  return out;
}

}  // namespace

TEST(RibWriterTest, DumpReadsBackAsTheGridsAndCameraWritten) {
  test::ScratchDir dir;
  DumpHeader h;
  h.frame = 42;
  h.width = 320, h.height = 180, h.pixelAspect = 1.5;
  h.perspective = true, h.fovDegrees = 37.5;
  const double sw[4] = {-1.25, 1.5, -0.75, 0.5};
  std::copy(sw, sw + 4, h.screenWindow);
  h.nearClip = 0.01, h.farClip = 5000;
  h.shutterOpen = 0.25, h.shutterClose = 0.75;
  std::mt19937 rng(7);
  std::vector<OwnedGrid> grids;
  grids.push_back(randomGrid(rng, 25, 16, true));
  grids.push_back(randomGrid(rng, 9, 4, false));  // static: P alone
  grids.push_back(randomGrid(rng, 3, 1, true));   // one triangle
  grids.back().corners = {0, 1, 2, kNoCorner};
  for (bool gzip : {false, true}) {
    SCOPED_TRACE(gzip ? "gzipped" : "plain");
    const std::string path = dir.path(gzip ? "dump.rib.gz" : "dump.rib");
    {
      DumpWriter w(path, h, gzip);
      for (const auto& g : grids) w.addGrid(g.view());
      w.close();
    }
    const auto bytes = test::readBytes(path);
    ASSERT_GE(bytes.size(), 2u);
    EXPECT_EQ(bytes[0] == 0x1f && bytes[1] == 0x8b, gzip) << "gzip magic";

    const ReadBack r = readBack(path);
    const std::vector<std::string> expectNames = {"Declare",        "FrameBegin",     "Format",         "Projection",        "ScreenWindow",
                                                  "Clipping",       "Shutter",        "WorldBegin",     "CoordSysTransform", "Sides",
                                                  "PointsPolygons", "PointsPolygons", "PointsPolygons", "WorldEnd",          "FrameEnd"};
    EXPECT_EQ(r.names, expectNames);
    EXPECT_EQ(numbersOf(r.header.at("FrameBegin")), (std::vector<double>{42}));
    EXPECT_EQ(numbersOf(r.header.at("Format")), (std::vector<double>{320, 180, 1.5}));
    ASSERT_EQ(r.header.at("Projection").size(), 3u);
    EXPECT_EQ(r.header.at("Projection")[0].string, "perspective");
    EXPECT_EQ(numbersOf({r.header.at("Projection")[2]}), (std::vector<double>{37.5}));
    EXPECT_EQ(numbersOf(r.header.at("ScreenWindow")), (std::vector<double>(sw, sw + 4)));
    EXPECT_EQ(numbersOf(r.header.at("Clipping")), (std::vector<double>{float(0.01), 5000}));
    EXPECT_EQ(numbersOf(r.header.at("Shutter")), (std::vector<double>{0.25, 0.75}));
    EXPECT_EQ(r.header.at("CoordSysTransform").at(0).string, "camera");
    ASSERT_EQ(r.grids.size(), grids.size());
    for (size_t i = 0; i < grids.size(); ++i) {
      SCOPED_TRACE(i);
      expectGridReadsBack(grids[i], r.grids[i]);
    }
  }
}

TEST(RibWriterTest, OrthographicHeaderAndEmptyDump) {
  test::ScratchDir dir;
  DumpHeader h;
  h.perspective = false;
  const std::string path = dir.path("ortho.rib");
  DumpWriter w(path, h, false);
  w.close();
  const ReadBack r = readBack(path);
  ASSERT_TRUE(r.header.count("Projection"));
  ASSERT_EQ(r.header.at("Projection").size(), 1u);  // no "fov"
  EXPECT_EQ(r.header.at("Projection")[0].string, "orthographic");
  EXPECT_TRUE(r.grids.empty());
  EXPECT_EQ(r.names.back(), "FrameEnd");
}

TEST(RibWriterTest, MismatchedGridIsAnInternalError) {
  test::ScratchDir dir;
  DumpWriter w(dir.path("bad.rib"), DumpHeader{}, false);
  OwnedGrid g;
  g.numVertices = 4;
  g.P = {0, 0, 1, 1, 0, 1, 1, 1, 1};  // three vertices' worth
  g.corners = {0, 1, 2, 3};
  EXPECT_THROW(w.addGrid(g.view()), InternalError);
  g.P.insert(g.P.end(), {0, 1, 1});
  g.blurP = {0, 0, 1};  // blurP shorter than P
  EXPECT_THROW(w.addGrid(g.view()), InternalError);
}

TEST(RibWriterTest, UnwritablePathIsAnErrorNamingIt) {
  test::ScratchDir dir;
  const std::string path = dir.path("no/such/dir/dump.rib");
  for (bool gzip : {false, true}) {
    try {
      DumpWriter w(path, DumpHeader{}, gzip);
      ADD_FAILURE() << "no error for " << path;
    } catch (const Error& e) {
      EXPECT_EQ(e.where(), path);
    }
  }
}
