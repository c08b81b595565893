// Dump ingest: the reference workflow's dump round-trips exactly through a store; motion blocks,
// blurP, moving transforms, polygon splitting, variables, orientation, camera and frames; bad
// dumps fail with one clear error; the CLI front end.
#include <cmath>
#include <cstring>
#include <fstream>
#include <map>
#include <random>
#include <set>

#include <gtest/gtest.h>

#include "common/error.h"
#include "common/log.h"
#include "shade/dump_writer.h"
#include "shade/ingest.h"
#include "shade/rib_scene.h"
#include "store/reader.h"
#include "store/synthetic.h"
#include "tests/test_util.h"

using namespace reshutter;
using namespace reshutter::store;

namespace {

struct Grid {
  Schedule knots;
  uint32_t numVertices = 0;
  std::vector<glm::vec3> positions;
  std::vector<uint32_t> corners;
  std::vector<std::vector<float>> attrs;
  uint8_t flags = 0;
  uint32_t gridId = 0;
};

/// Keeps copies of every grid (and forwards them, when `next` is set).
struct Capture : GridSink {
  std::vector<Schedule> schedules{Schedule{0.0}};
  std::vector<Grid> grids;
  GridSink* next = nullptr;
  uint32_t addSchedule(const Schedule& k) override {
    if (next) next->addSchedule(k);
    schedules.push_back(k);
    return uint32_t(schedules.size() - 1);
  }
  void addGrid(const GridInput& g) override {
    if (next) next->addGrid(g);
    Grid c;
    c.knots = schedules.at(g.schedule);
    c.numVertices = g.numVertices;
    c.positions.assign(g.positions.begin(), g.positions.end());
    c.corners.assign(g.corners.begin(), g.corners.end());
    for (const auto& a : g.attrs) c.attrs.emplace_back(a.f.begin(), a.f.end());
    c.flags = g.flags;
    c.gridId = g.gridId;
    grids.push_back(std::move(c));
  }
};

void writeFile(const std::string& path, const std::string& text) { std::ofstream(path, std::ios::binary) << text; }

struct Ingested {
  StoreMeta meta;
  std::vector<Grid> grids;
  shade::IngestStats stats;
  const std::vector<float>& attr(size_t grid, const std::string& name) const {
    int i = meta.schema.find(name);
    EXPECT_GE(i, 0) << name;
    return grids.at(grid).attrs.at(size_t(i));
  }
};

Ingested ingestText(const std::string& rib, const shade::IngestOptions& opt = {}) {
  test::ScratchDir dir;
  const std::string path = dir.path("dump.rib");
  writeFile(path, rib);
  Ingested r;
  r.meta = shade::scanDump(path, opt);
  Capture cap;
  shade::ingestDumpInto(path, r.meta, cap, r.stats, opt);
  r.grids = std::move(cap.grids);
  return r;
}

std::string ingestError(const std::string& rib) {
  test::ScratchDir dir;
  const std::string path = dir.path("dump.rib");
  writeFile(path, rib);
  try {
    StoreMeta m = shade::scanDump(path);
    Capture cap;
    shade::IngestStats st;
    shade::ingestDumpInto(path, m, cap, st);
  } catch (const Error& e) {
    std::string w = e.what();
    auto slash = w.rfind("dump.rib");
    return slash == std::string::npos ? w : w.substr(slash);
  }
  ADD_FAILURE() << "no error for\n" << rib;
  return {};
}

// A synthetic scene written as a reference-form dump (shade::DumpRibWriter, gzipped) at path;
// returns the grids as generated, the truth to compare an ingest with.
Capture dumpSynthetic(const SyntheticOptions& so, const std::string& path) {
  Capture truth;
  shade::DumpRibWriter dump(path, syntheticMeta(so), true);
  truth.next = &dump;
  generateSynthetic(so, truth);
  dump.close();
  truth.next = nullptr;
  return truth;
}

const std::string kHeader = "Format 64 48 1\nProjection \"perspective\" \"fov\" [60]\nShutter 0 1\nWorldBegin\n";
const std::string kSquare = "\"P\" [0 0 5  1 0 5  1 1 5  0 1 5]";

double area2d(const std::vector<glm::vec3>& p, const std::vector<uint32_t>& ring) {
  double a = 0;
  for (size_t i = 0; i < ring.size(); ++i) {
    const auto& u = p[ring[i]];
    const auto& v = p[ring[(i + 1) % ring.size()]];
    a += double(u.x) * v.y - double(v.x) * u.y;
  }
  return a / 2;
}

}  // namespace

TEST(IngestTest, ReferenceWorkflowDumpRoundTripsExactly) {
  // Grids written by shade::DumpRibWriter in the reference form (PointsPolygons, "Cs", "Os",
  // "blurP", CoordSysTransform "camera", gzipped), ingested, and read back from the store.
  test::ScratchDir dir;
  SyntheticOptions so;
  so.micropolygons = 30000;
  so.width = 320, so.height = 240;
  so.transparentFraction = 0.3;
  so.maxMotionPx = 20;
  const StoreMeta src = syntheticMeta(so);
  const Capture truth = dumpSynthetic(so, dir.path("dump.rib.gz"));
  size_t total = 0;
  for (const auto& g : truth.grids) total += g.corners.size() / 4;
  ASSERT_GE(total, 30000u);
  shade::IngestStats st = shade::ingestDump(dir.path("dump.rib.gz"), dir.path("frame.mps"));
  EXPECT_EQ(st.micropolygons, total);
  EXPECT_EQ(st.movingMicropolygons, total);

  StoreReader reader(dir.path("frame.mps"));
  reader.verify();
  const StoreMeta& m = reader.meta();
  EXPECT_EQ(m.shutterOpen, src.shutterOpen);
  EXPECT_EQ(m.shutterClose, src.shutterClose);
  const Camera &a = m.cameras[0], &b = src.cameras[0];
  EXPECT_EQ(a.width, b.width);
  EXPECT_EQ(a.height, b.height);
  EXPECT_EQ(a.projection, b.projection);
  EXPECT_NEAR(a.fovDegrees, b.fovDegrees, 1e-6);
  double wa[4], wb[4];
  a.effectiveScreenWindow(wa), b.effectiveScreenWindow(wb);
  for (int i = 0; i < 4; ++i) EXPECT_NEAR(wa[i], wb[i], 1e-6);
  ASSERT_EQ(m.schema.ci(), 0);
  ASSERT_EQ(m.schema.oi(), 1);
  EXPECT_EQ(m.schema.attrs[0].rate, AttrRate::Vertex);

  // Every micropolygon, keyed by its grid and the exact positions of its corners at both knots.
  using Key = std::pair<uint32_t, std::vector<float>>;
  std::map<Key, std::vector<float>> expected;  // → Ci and Oi of its corners
  const int sci = src.schema.ci(), soi = src.schema.oi();
  uint32_t gridIndex = 0;
  for (const auto& g : truth.grids) {
    ASSERT_EQ(g.knots, (Schedule{0.0, 1.0}));
    for (size_t mp = 0; mp < g.corners.size() / 4; ++mp) {
      Key k{gridIndex, {}};
      std::vector<float> col;
      for (int c = 0; c < 4; ++c) {
        uint32_t v = g.corners[mp * 4 + size_t(c)];
        if (v == kNoCorner) continue;
        for (int kn = 0; kn < 2; ++kn)
          for (int x = 0; x < 3; ++x) k.second.push_back(g.positions[size_t(kn) * g.numVertices + v][x]);
        for (int x = 0; x < 3; ++x) col.push_back(g.attrs[size_t(sci)][v * 3 + size_t(x)]), col.push_back(g.attrs[size_t(soi)][v * 3 + size_t(x)]);
      }
      expected[k] = col;
    }
    ++gridIndex;
  }
  size_t found = 0;
  for (size_t e = 0; e < reader.entries().size(); ++e) {
    TilePart p = reader.decode(e);
    ASSERT_EQ(p.numKnots, 2u);
    for (uint32_t mp = 0; mp < p.numMicropolygons; ++mp) {
      Key k{p.gridId[mp], {}};
      std::vector<float> col;
      for (int c = 0; c < 4; ++c) {
        uint32_t v = p.corners[mp * 4 + uint32_t(c)];
        if (v == kNoCorner) continue;
        for (uint32_t kn = 0; kn < 2; ++kn)
          for (int x = 0; x < 3; ++x) k.second.push_back(p.position(kn, v)[x]);
        for (int x = 0; x < 3; ++x) col.push_back(p.attrs[0].f[v * 3 + uint32_t(x)]), col.push_back(p.attrs[1].f[v * 3 + uint32_t(x)]);
      }
      auto it = expected.find(k);
      ASSERT_NE(it, expected.end()) << "micropolygon with no exact original (grid " << k.first << ")";
      EXPECT_EQ(it->second, col) << "colour/opacity differ (grid " << k.first << ")";
      ++found;
      EXPECT_TRUE(p.flags[mp] & kTwoSided);  // the dump says Sides 2
    }
  }
  EXPECT_EQ(found, total);
}

TEST(IngestTest, StillObjectsOfADumpAreStoredStatic) {
  // The reference dump writes "blurP" for every grid; a static object's blurP equals its P. Those
  // grids are stored static (one knot, schedule 0), and the ingest counts only the others moving.
  test::ScratchDir dir;
  SyntheticOptions so;
  so.micropolygons = 20000;
  so.width = 320, so.height = 240;
  so.stillFraction = 0.5;
  const Capture truth = dumpSynthetic(so, dir.path("dump.rib.gz"));
  std::set<uint32_t> stillGrids;
  uint64_t still = 0, moving = 0;
  for (size_t gi = 0; gi < truth.grids.size(); ++gi) {
    const auto& g = truth.grids[gi];
    const bool same = std::equal(g.positions.begin(), g.positions.begin() + g.numVertices, g.positions.begin() + g.numVertices);
    (same ? still : moving) += g.corners.size() / 4;
    if (same) stillGrids.insert(uint32_t(gi));
  }
  ASSERT_GT(still, 0u);
  ASSERT_GT(moving, 0u);
  shade::IngestStats st = shade::ingestDump(dir.path("dump.rib.gz"), dir.path("frame.mps"));
  EXPECT_EQ(st.movingMicropolygons, moving);
  EXPECT_EQ(st.write.stillMicropolygons, still);
  StoreReader reader(dir.path("frame.mps"));
  reader.verify();
  uint64_t staticSeen = 0;
  for (size_t e = 0; e < reader.entries().size(); ++e) {
    const TilePart p = reader.decode(e);
    for (uint32_t mp = 0; mp < p.numMicropolygons; ++mp) {
      const bool isStill = stillGrids.count(p.gridId[mp]) == 1;
      EXPECT_EQ(reader.entries()[e].schedule == 0, isStill) << "grid " << p.gridId[mp];
      staticSeen += isStill;
    }
  }
  EXPECT_EQ(staticSeen, still);
}

TEST(IngestTest, MotionBlocksWithAnyKnotTimes) {
  // [0 2] with Shutter 0 2 (aqsis_simpledeformation's form): two knots at 0 and 2, exact.
  auto r = ingestText("Shutter 0 2\nProjection \"perspective\"\nWorldBegin\nMotionBegin [0 2]\nPolygon " + kSquare +
                      "\nPolygon \"P\" [0 0 6  2 0 6  2 2 6  0 2 6]\nMotionEnd\n");
  ASSERT_EQ(r.grids.size(), 1u);
  EXPECT_EQ(r.grids[0].knots, (Schedule{0, 2}));
  EXPECT_EQ(r.grids[0].positions[2], glm::vec3(1, 1, 5));
  EXPECT_EQ(r.grids[0].positions[4 + 2], glm::vec3(2, 2, 6));
  EXPECT_EQ(r.meta.shutterClose, 2);

  // Three knots, and a shutter shorter than the motion: clipped, interpolated at the shutter end.
  r = ingestText(
      "Shutter 0 0.75\nWorldBegin\nMotionBegin [0 0.5 1]\nPolygon \"P\" [0 0 1 1 0 1 1 1 1]\nPolygon \"P\" [0 0 2 1 0 2 1 1 2]\n"
      "Polygon \"P\" [0 0 4 1 0 4 1 1 4]\nMotionEnd\n");
  ASSERT_EQ(r.grids.size(), 1u);
  EXPECT_EQ(r.grids[0].knots, (Schedule{0, 0.5, 0.75}));
  EXPECT_FLOAT_EQ(r.grids[0].positions[6].z, 3.0f);
  EXPECT_EQ(r.grids[0].corners[3], kNoCorner);  // a triangle stays a triangle

  // blurP: P at shutter open, blurP at close.
  r = ingestText("Shutter 0.25 0.75\nWorldBegin\nCoordSysTransform \"camera\"\nPointsPolygons [4] [0 1 2 3] " + kSquare +
                 " \"blurP\" [0 0 7  1 0 7  1 1 7  0 1 7]\n");
  ASSERT_EQ(r.grids.size(), 1u);
  EXPECT_EQ(r.grids[0].knots, (Schedule{0.25, 0.75}));
  EXPECT_EQ(r.grids[0].positions[4].z, 7.0f);
  EXPECT_EQ(r.grids[0].positions[0].z, 5.0f);
}

TEST(IngestTest, MovingTransformsAndWorldSpaceGeometry) {
  // A camera transform before WorldBegin, and a moving transform around static geometry.
  auto r = ingestText(
      "Shutter 0 1\nProjection \"perspective\"\nTranslate 0 0 10\nWorldBegin\nAttributeBegin\nMotionBegin [0 1]\nTranslate 0 0 0\n"
      "Translate 3 0 0\nMotionEnd\nPolygon " +
      kSquare + "\nAttributeEnd\nPolygon " + kSquare + "\n");
  ASSERT_EQ(r.grids.size(), 2u);
  EXPECT_EQ(r.meta.cameras[0].worldToCamera[3][2], 10.0);
  EXPECT_EQ(r.grids[0].knots, (Schedule{0, 1}));
  EXPECT_EQ(r.grids[0].positions[1], glm::vec3(1, 0, 15));
  EXPECT_EQ(r.grids[0].positions[4 + 1], glm::vec3(4, 0, 15));
  EXPECT_EQ(r.grids[1].knots, (Schedule{0}));  // AttributeEnd restored the static transform
  EXPECT_EQ(r.grids[1].positions[2], glm::vec3(1, 1, 15));

  // A moving camera moves world-space geometry; CoordSysTransform "camera" geometry does not move.
  r = ingestText("Shutter 0 1\nMotionBegin [0 1]\nTranslate 0 0 10\nTranslate 0 0 12\nMotionEnd\nWorldBegin\nPolygon " + kSquare +
                 "\nCoordSysTransform \"camera\"\nPolygon " + kSquare + "\n");
  ASSERT_EQ(r.grids.size(), 2u);
  EXPECT_EQ(r.grids[0].knots, (Schedule{0, 1}));
  EXPECT_EQ(r.grids[0].positions[4].z, 17.0f);
  EXPECT_EQ(r.grids[1].knots, (Schedule{0}));
  EXPECT_EQ(r.grids[1].positions[0].z, 5.0f);
}

TEST(IngestTest, PolygonsAreKeptOrSplit) {
  auto r = ingestText(kHeader +
                      "Polygon \"P\" [0 0 5  2 0 5  3 1 5  1 2 5  -1 1 5]\n"                    // convex pentagon
                      "Polygon \"P\" [0 0 5  1 0 5  2 0.5 5  2 1.5 5  1 2 5  0 2 5  -1 1 5]\n"  // convex heptagon
                      "Polygon \"P\" [0 0 5  3 0 5  3 1 5  1 1 5  1 3 5  0 3 5]\n"              // L shape: not convex
                      "PointsPolygons [3 4] [0 1 2  0 2 3 4] \"P\" [0 0 5  1 0 5  1 1 5  0 1 5  9 9 5]\n");
  ASSERT_EQ(r.grids.size(), 4u);
  auto kinds = [](const Grid& g) {
    std::pair<int, int> qt{0, 0};
    for (size_t i = 0; i < g.corners.size() / 4; ++i) ++(g.corners[i * 4 + 3] == kNoCorner ? qt.second : qt.first);
    return qt;
  };
  EXPECT_EQ(kinds(r.grids[0]), (std::pair<int, int>{1, 1}));
  EXPECT_EQ(kinds(r.grids[1]), (std::pair<int, int>{2, 1}));
  EXPECT_EQ(kinds(r.grids[2]), (std::pair<int, int>{0, 4}));
  EXPECT_EQ(kinds(r.grids[3]), (std::pair<int, int>{1, 1}));
  EXPECT_EQ(r.stats.fannedPolygons, 2u);
  EXPECT_EQ(r.stats.earClippedPolygons, 1u);
  // The pieces cover the polygon: same total area, same winding.
  for (size_t g = 0; g < 3; ++g) {
    std::vector<uint32_t> ring;
    for (uint32_t i = 0; i < r.grids[g].numVertices; ++i) ring.push_back(i);
    double whole = area2d(r.grids[g].positions, ring), parts = 0;
    for (size_t m = 0; m < r.grids[g].corners.size() / 4; ++m) {
      std::vector<uint32_t> piece;
      for (int c = 0; c < 4; ++c)
        if (r.grids[g].corners[m * 4 + size_t(c)] != kNoCorner) piece.push_back(r.grids[g].corners[m * 4 + size_t(c)]);
      double a = area2d(r.grids[g].positions, piece);
      EXPECT_GT(a * whole, 0) << "piece winds against its polygon";
      parts += a;
    }
    EXPECT_NEAR(parts, whole, 1e-9) << g;
  }
  // Quads and triangles keep their corners as given.
  EXPECT_EQ(std::vector<uint32_t>(r.grids[3].corners.begin(), r.grids[3].corners.end()), (std::vector<uint32_t>{0, 1, 2, kNoCorner, 0, 2, 3, 4}));
}

TEST(IngestTest, PolygonsWithHolesAreTriangulatedAroundThem) {
  // A 4 x 4 square with a 2 x 2 hole, beside a plain triangle, a colour per face vertex: the
  // pieces cover 16 - 4, wind like the outline, and each corner keeps its loop vertex's colour.
  auto r = ingestText(kHeader +
                      "PointsGeneralPolygons [2 1] [4 4 3] [0 1 2 3 4 5 6 7 0 1 2] \"P\" [0 0 5 4 0 5 4 4 5 0 4 5 1 1 5 1 3 5 3 3 5 3 1 5]"
                      " \"facevarying color Cs\" [0 0 0 1 0 0 2 0 0 3 0 0 4 0 0 5 0 0 6 0 0 7 0 0 8 0 0 9 0 0 10 0 0]\n");
  ASSERT_EQ(r.grids.size(), 1u);
  const Grid& g = r.grids[0];
  EXPECT_EQ(r.stats.earClippedPolygons, 1u);
  const std::vector<glm::vec2> loopPoints = {{0, 0}, {4, 0}, {4, 4}, {0, 4}, {1, 1}, {1, 3}, {3, 3}, {3, 1}, {0, 0}, {4, 0}, {4, 4}};
  const std::vector<float>& cs = r.attr(0, "Ci");  // a dump's Cs is its shaded colour
  double holed = 0, triangle = 0;
  for (size_t m = 0; m < g.corners.size() / 4; ++m) {
    ASSERT_EQ(g.corners[m * 4 + 3], kNoCorner);
    std::vector<uint32_t> piece(g.corners.begin() + std::ptrdiff_t(m * 4), g.corners.begin() + std::ptrdiff_t(m * 4 + 3));
    const double a = area2d(g.positions, piece);
    int face = -1;
    for (uint32_t c : piece) {
      // The vertex's colour names its face vertex, whose point must be where the vertex is.
      const size_t k = size_t(std::lround(cs.at(c * 3)));
      ASSERT_LT(k, loopPoints.size());
      const glm::vec3 at = g.positions[c];
      EXPECT_NEAR(at.x / at.z * 5, loopPoints[k].x, 1e-5);
      EXPECT_NEAR(at.y / at.z * 5, loopPoints[k].y, 1e-5);
      face = k < 8 ? 0 : 1;
    }
    (face == 0 ? holed : triangle) += a;
  }
  EXPECT_NEAR(std::abs(holed), 16 - 4, 1e-9);
  EXPECT_NEAR(std::abs(triangle), 8, 1e-9);
}

TEST(IngestTest, EveryDeclaredVariableBecomesAnOutput) {
  auto r = ingestText(kHeader +
                      "Declare \"id\" \"uniform float\"\n"
                      "PointsPolygons [4 3] [0 1 2 3  1 4 2] \"P\" [0 0 5  1 0 5  1 1 5  0 1 5  2 0 5]\n"
                      "  \"N\" [0 0 -1  0 0 -1  0 0 -1  0 0 -1  0 0 -1] \"s\" [0 1 1 0 2] \"id\" [7 8]\n"
                      "  \"varying float[2] uv\" [0 0  1 0  1 1  0 1  2 0] \"constant color tint\" [0.5 0.25 1]\n"
                      "  \"Cs\" [1 0 0  0 1 0  0 0 1  1 1 1  0 0 0] \"uniform string label\" [\"a\" \"b\"]\n"
                      "PointsPolygons [4] [0 1 2 3] " +
                      kSquare + " \"facevarying float fv\" [1 2 3 4] \"Os\" [1 1 1  1 1 1  1 1 1  1 1 1]\n");
  const auto& s = r.meta.schema;
  auto rate = [&](const char* n) {
    int i = s.find(n);
    EXPECT_GE(i, 0) << n;
    return i < 0 ? AttrRate::Vertex : s.attrs[size_t(i)].rate;
  };
  EXPECT_EQ(s.attrs[0].name, "Ci");
  EXPECT_EQ(s.attrs[1].name, "Oi");
  EXPECT_EQ(rate("Ci"), AttrRate::Vertex);
  EXPECT_EQ(rate("Oi"), AttrRate::Vertex);
  EXPECT_EQ(rate("N"), AttrRate::Vertex);
  EXPECT_EQ(s.attrs[size_t(s.find("N"))].type, AttrType::Normal);
  EXPECT_EQ(rate("s"), AttrRate::Vertex);
  EXPECT_EQ(rate("id"), AttrRate::Micropolygon);
  EXPECT_EQ(rate("uv[0]"), AttrRate::Vertex);
  EXPECT_EQ(rate("uv[1]"), AttrRate::Vertex);
  EXPECT_EQ(rate("tint"), AttrRate::Micropolygon);
  EXPECT_EQ(rate("fv"), AttrRate::Vertex);
  EXPECT_EQ(s.find("label"), -1);  // strings are not stored
  ASSERT_EQ(r.grids.size(), 2u);
  EXPECT_EQ(r.attr(0, "id"), (std::vector<float>{7, 8}));
  EXPECT_EQ(r.attr(0, "uv[1]"), (std::vector<float>{0, 0, 1, 1, 0}));
  EXPECT_EQ(r.attr(0, "s"), (std::vector<float>{0, 1, 1, 0, 2}));
  EXPECT_EQ(r.attr(0, "tint"), (std::vector<float>{0.5f, 0.25f, 1, 0.5f, 0.25f, 1}));
  EXPECT_EQ(r.attr(0, "Ci")[3 * 3 + 1], 1.0f);
  EXPECT_EQ(r.attr(0, "Oi"), std::vector<float>(15, 1.0f));  // Opacity default, per vertex
  EXPECT_TRUE(r.attr(0, "fv").empty());                      // absent in that grid
  // Facevarying data gets one vertex per face corner.
  EXPECT_EQ(r.grids[1].numVertices, 4u);
  EXPECT_EQ(r.attr(1, "fv"), (std::vector<float>{1, 2, 3, 4}));
  EXPECT_EQ(r.attr(1, "Ci"), std::vector<float>(12, 1.0f));  // Color default
}

TEST(IngestTest, NormalsAndPointsMoveToCameraSpace) {
  auto r = ingestText(
      "Projection \"perspective\"\nWorldBegin\nTranslate 0 0 5\nRotate 90 0 1 0\nDeclare \"Pref\" \"vertex point\"\n"
      "Polygon \"P\" [0 0 0  0 1 0  0 0 1] \"N\" [1 0 0  1 0 0  1 0 0] \"Pref\" [0 0 0  0 0 0  0 0 0]\n");
  const auto& n = r.attr(0, "N");
  EXPECT_NEAR(n[0], 0, 1e-6);
  EXPECT_NEAR(n[2], -1, 1e-6);
  EXPECT_NEAR(r.attr(0, "Pref")[2], 5, 1e-6);
}

TEST(IngestTest, OrientationSidesAndMatte) {
  auto ring = [](const std::string& prefix) {
    auto r = ingestText(kHeader + prefix + "Polygon " + kSquare + "\n");
    return std::make_pair(std::vector<uint32_t>(r.grids[0].corners.begin(), r.grids[0].corners.end()), r.grids[0].flags);
  };
  const std::vector<uint32_t> asGiven{0, 1, 2, 3}, reversed{0, 3, 2, 1};
  EXPECT_EQ(ring("").first, asGiven);
  EXPECT_EQ(ring("").second, kTwoSided);  // RenderMan's default is Sides 2
  EXPECT_EQ(ring("Orientation \"inside\"\n").first, reversed);
  EXPECT_EQ(ring("ReverseOrientation\n").first, reversed);
  EXPECT_EQ(ring("Orientation \"lh\"\n").first, asGiven);
  EXPECT_EQ(ring("Orientation \"rh\"\n").first, reversed);
  EXPECT_EQ(ring("Scale -1 1 1\nOrientation \"lh\"\n").first, reversed);
  // A mirror changes the coordinate system's handedness, not the orientation (RenderMan: a
  // negative scale needs a ReverseOrientation to keep its front faces).
  EXPECT_EQ(ring("Scale -1 1 1\n").first, reversed);
  EXPECT_EQ(ring("Scale -1 1 1\nReverseOrientation\n").first, asGiven);
  EXPECT_EQ(ring("Scale -1 1 1\nOrientation \"outside\"\n").first, asGiven);
  EXPECT_EQ(ring("Orientation \"outside\"\nScale -1 1 1\n").first, reversed);
  EXPECT_EQ(ring("Sides 1\n").second, 0);
  EXPECT_EQ(ring("Matte 1\n").second, kTwoSided | kMatte);
  EXPECT_EQ(ring("AttributeBegin\nSides 1\nAttributeEnd\n").second, kTwoSided);
}

TEST(IngestTest, UndeclaredVariablesAreSkippedWithAWarning) {
  const size_t before = warningCount();
  auto r = ingestText(kHeader + "PointsPolygons [4] [0 1 2 3] " + kSquare + " \"bogus\" [1 2 3 4] \"Cs\" [1 0 0 1 0 0 1 0 0 1 0 0]\n");
  EXPECT_GT(warningCount(), before);
  ASSERT_EQ(r.grids.size(), 1u);
  EXPECT_LT(r.meta.schema.find("bogus"), 0);
  EXPECT_EQ(r.attr(0, "Ci")[0], 1.0f);
}

TEST(IngestTest, CameraIsTheOneTheShadingPassReads) {
  // One interpreter: a dump and a scene with the same options give the same camera and shutter,
  // including the forms the two readers once disagreed on (a one-array ScreenWindow, a RIS
  // projection, FrameAspectRatio, a moving camera, Camera "world").
  const std::vector<std::string> heads = {
      "Format 64 48 1\nProjection \"perspective\" \"fov\" [60]\nShutter 0 1\n",
      "Format 320 240 2\nScreenWindow [-2 2 -1 1]\nProjection \"orthographic\"\nClipping 0.5 500\nShutter 0.25 0.75\n",
      "Format 100 100 1\nFrameAspectRatio 0.5\nProjection \"PxrCamera\" \"float fov\" [35]\nTranslate 0 0 5\nRotate 30 0 1 0\nCamera \"world\"\n",
      "Format 64 64 1\nProjection \"perspective\"\nShutter 0 1\nMotionBegin [0 1]\nTranslate 0 0 1\nTranslate 0 0 2\nMotionEnd\n",
  };
  for (const std::string& head : heads) {
    test::ScratchDir dir;
    const std::string path = dir.path("scene.rib");
    writeFile(path, head + "WorldBegin\nPolygon " + kSquare + "\nWorldEnd\n");
    const StoreMeta dump = shade::scanDump(path);
    std::vector<shade::FrameOptions> frames;
    shade::Scene scene([&](shade::FrameScene& f) { frames.push_back(f.options); });
    shade::readRibScene(path, scene);
    ASSERT_EQ(frames.size(), 1u) << head;
    ASSERT_EQ(dump.cameras.size(), 1u);
    EXPECT_TRUE(dump.cameras[0] == frames[0].camera) << head;
    EXPECT_EQ(dump.shutterOpen, frames[0].shutterOpen) << head;
    EXPECT_EQ(dump.shutterClose, frames[0].shutterClose) << head;
  }
}

TEST(IngestTest, ColourPerKnotIsShadingInTimeOtherVariablesKeepTheFirst) {
  // Cs changing between copies: the store shades in time at the block's knots (Ci, Ci@1).
  size_t before = warningCount();
  auto r = ingestText(kHeader + "MotionBegin [0 1]\nPolygon " + kSquare + " \"Cs\" [1 0 0  1 0 0  1 0 0  1 0 0]\nPolygon " + kSquare +
                      " \"Cs\" [0 1 0  0 1 0  0 1 0  0 1 0]\nMotionEnd\n");
  EXPECT_EQ(warningCount(), before);
  EXPECT_EQ(r.meta.shadingTimes, (std::vector<double>{0, 1}));
  EXPECT_EQ(r.attr(0, "Ci")[0], 1.0f);
  EXPECT_EQ(r.attr(0, "Ci")[1], 0.0f);
  EXPECT_EQ(r.attr(0, "Ci@1")[0], 0.0f);
  EXPECT_EQ(r.attr(0, "Ci@1")[1], 1.0f);
  EXPECT_EQ(r.attr(0, "Oi@1")[0], 1.0f);  // opacity the same at every time
  EXPECT_EQ(r.grids[0].knots, (Schedule{0, 1}));
  // Another variable changing between copies: the first copy's is kept, with a warning.
  before = warningCount();
  r = ingestText(kHeader + "MotionBegin [0 1]\nPolygon " + kSquare + " \"varying float k\" [1 1 1 1]\nPolygon " + kSquare + " \"varying float k\" [2 2 2 2]\nMotionEnd\n");
  EXPECT_GT(warningCount(), before);
  EXPECT_TRUE(r.meta.shadingTimes.empty());
  EXPECT_EQ(r.attr(0, "k")[0], 1.0f);
}

TEST(IngestTest, CameraShutterAndFramesComeFromTheRib) {
  auto r = ingestText(
      "FrameBegin 3\nFormat 320 240 2\nFrameAspectRatio 2\nProjection \"orthographic\"\nClipping 0.5 500\nShutter 0.1 0.6\n"
      "WorldBegin\nPolygon " +
      kSquare +
      "\nWorldEnd\nFrameEnd\n"
      "FrameBegin 4\nWorldBegin\nPolygon " +
      kSquare + "\nPolygon " + kSquare + "\nWorldEnd\nFrameEnd\n");
  const Camera& c = r.meta.cameras[0];
  EXPECT_EQ(r.meta.frame, 3);
  EXPECT_EQ(c.width, 320);
  EXPECT_EQ(c.pixelAspect, 2);
  EXPECT_EQ(c.projection, Projection::Orthographic);
  EXPECT_EQ(c.screenWindow[0], -2);
  EXPECT_EQ(c.screenWindow[3], 1);
  EXPECT_EQ(c.nearClip, 0.5);
  EXPECT_EQ(c.farClip, 500);
  EXPECT_EQ(r.meta.shutterOpen, double(0.1f));  // RIB numbers are RtFloat
  EXPECT_EQ(r.meta.shutterClose, double(0.6f));
  EXPECT_EQ(r.grids.size(), 1u);  // the first frame only

  shade::IngestOptions opt;
  opt.frame = 4;
  opt.fps = Rational{30000, 1001};
  r = ingestText("FrameBegin 3\nWorldBegin\nPolygon " + kSquare + "\nWorldEnd\nFrameEnd\nFrameBegin 4\nScreenWindow -1 1 -0.5 0.5\nWorldBegin\nPolygon " +
                     kSquare + "\nPolygon " + kSquare + "\nWorldEnd\nFrameEnd\n",
                 opt);
  EXPECT_EQ(r.meta.frame, 4);
  EXPECT_EQ(r.meta.fps, (Rational{30000, 1001}));
  EXPECT_EQ(r.meta.cameras[0].screenWindow[2], -0.5);
  EXPECT_EQ(r.grids.size(), 2u);
}

TEST(IngestTest, OnePassUnlessALaterPrimitiveBringsNewVariables) {
  test::ScratchDir dir;
  // Same variables throughout: one pass.
  writeFile(dir.path("same.rib"), kHeader + "Polygon " + kSquare + " \"s\" [0 1 2 3]\nPolygon " + kSquare + " \"s\" [4 5 6 7]\n");
  auto st = shade::ingestDump(dir.path("same.rib"), dir.path("same.mps"));
  EXPECT_EQ(st.passes, 1);
  EXPECT_EQ(st.micropolygons, 2u);
  // A variable first seen in the second primitive, and Cs turning per-vertex: two passes, and the
  // store's schema holds both.
  writeFile(dir.path("grow.rib"), kHeader + "Polygon " + kSquare + "\nPolygon " + kSquare + " \"t\" [4 5 6 7] \"Cs\" [1 0 0 1 0 0 1 0 0 1 0 0]\n");
  st = shade::ingestDump(dir.path("grow.rib"), dir.path("grow.mps"));
  EXPECT_EQ(st.passes, 2);
  EXPECT_EQ(st.micropolygons, 2u);
  StoreReader reader(dir.path("grow.mps"));
  const Schema& s = reader.meta().schema;
  ASSERT_GE(s.find("t"), 0);
  EXPECT_EQ(s.attrs[size_t(s.ci())].rate, AttrRate::Vertex);
  EXPECT_EQ(reader.micropolygonCount(), 2u);
  size_t files = 0;
  for (const auto& e : std::filesystem::directory_iterator(dir.dir()))
    files += e.path().extension() == ".mps" || e.path().string().find(".tmp") != std::string::npos;
  EXPECT_EQ(files, 2u);  // no temporary left behind by the abandoned first pass
}

TEST(IngestHardTest, BadDumpsGiveOneClearError) {
  struct Case {
    std::string rib, where, what;
  };
  const std::vector<Case> cases = {
      {kHeader + "PointsPolygons [4] [0 1 2 3] " + kSquare + "\n\"Cs\" [1 0 0]\n", "dump.rib:5 (PointsPolygons)", "\"Cs\" has 1 values"},
      {kHeader + "PointsPolygons [4] [0 1 2 9] " + kSquare + "\n", "dump.rib:5 (PointsPolygons)", "vertex index 9"},
      {kHeader + "PointsPolygons [4 4] [0 1 2 3] " + kSquare + "\n", "dump.rib:5 (PointsPolygons)", "vertex counts need 8"},
      {kHeader + "PointsPolygons [4] [0 1 2 3] \"P\" [0 0 5 1 0 5 1 1 5 0 1]\n", "dump.rib:5 (PointsPolygons)", "not a multiple of 3"},
      {kHeader + "PointsGeneralPolygons [2] [4 3] [0 1 2 3 4 5 6] \"P\" [0 0 5 4 0 5 4 4 5 0 4 5 5 5 5 6 5 5 6 6 5]\n", "dump.rib:5 (PointsGeneralPolygons)",
       "cannot be triangulated"},
      {kHeader + "Polygon \"P\" [0 0 5 2 0 5 0 2 5 2 2 5 1 -1 5]\n", "dump.rib:5 (Polygon)", "self-intersecting"},
      {kHeader + "PointsPolygons [4] [0 1 2 3] " + kSquare + " \"blurP\" [0 0 5]\n", "dump.rib:5 (PointsPolygons)", "\"blurP\" has 1 points"},
      {kHeader + "MotionBegin [0 1]\nPolygon " + kSquare + "\nPolygon \"P\" [0 0 5 1 0 5 1 1 5]\nMotionEnd\n", "dump.rib:7 (Polygon)", "different topology"},
      {kHeader + "MotionBegin [0 1]\nPolygon " + kSquare + "\nMotionEnd\n", "dump.rib:7 (MotionEnd)", "2 knots but 1 copies"},
      {kHeader + "MotionBegin [1 0]\n", "dump.rib:5 (MotionBegin)", "must increase"},
      {kHeader + "MotionBegin [0 1]\nPolygon " + kSquare + "\nPolygon " + kSquare + "\n", "dump.rib", "inside a motion block"},
      {"Polygon " + kSquare + "\n", "dump.rib", "no WorldBegin"},
      {"Projection \"perspective\" \"fov\" [200]\n", "dump.rib:1 (Projection)", "not in (0, 180)"},
      {"Format 640 480 1\nClipping 10 1\n", "dump.rib:2 (Clipping)", "invalid"},
      {"Projection \"perspective\" \"fov\" []\n", "dump.rib:1 (Projection)", "takes one number"},
      {"Format 1e300 480 1\n", "dump.rib:1 (Format)", "must be an integer"},
      {"FrameBegin 1.5\n", "dump.rib:1 (FrameBegin)", "must be an integer"},
      {kHeader + "Polygon \"P\" [0 0 5 1 0 5]\n", "dump.rib:5 (Polygon)", "2 vertices"},
      {kHeader + "PointsPolygons [4] [0 1 2 3] " + kSquare + " \"Cs\" [1 0 0 1 0 0 1 0 0 1 0 0]\nPolygon " + kSquare + " \"uniform float Cs\" [1]\n",
       "dump.rib:6 (Polygon)", "is a float here and a color elsewhere"},
  };
  for (const auto& c : cases) {
    std::string e = ingestError(c.rib);
    EXPECT_EQ(e.rfind(c.where, 0), 0u) << "error '" << e << "' should start with " << c.where;
    EXPECT_NE(e.find(c.what), std::string::npos) << "error '" << e << "' should say " << c.what;
  }
}

TEST(IngestTest, CliIngestsAndReportsErrorsOnOneLine) {
  test::ScratchDir dir;
  writeFile(dir.path("dump.rib"), kHeader + "Polygon " + kSquare + " \"Cs\" [1 0 0 1 0 0 1 0 0 1 0 0]\nWorldEnd\n");
  auto r = test::runReshutter("ingest " + dir.path("dump.rib") + " -o " + dir.path("f.mps") + " --frame 12 --fps 25");
  ASSERT_EQ(r.exitCode, 0) << r.err;
  auto info = test::runReshutter("info --json " + dir.path("f.mps"));
  ASSERT_EQ(info.exitCode, 0) << info.err;
  EXPECT_NE(info.out.find("\"micropolygons\": 1,"), std::string::npos) << info.out;
  EXPECT_NE(info.out.find("\"frame\": 12,"), std::string::npos) << info.out;

  writeFile(dir.path("bad.rib"), kHeader + "Polygon \"P\" [0 0 5 1 0 5 1 1]\n");
  r = test::runReshutter("ingest " + dir.path("bad.rib") + " -o " + dir.path("bad.mps"));
  EXPECT_EQ(r.exitCode, 1);
  EXPECT_NE(r.err.find("bad.rib:5 (Polygon)"), std::string::npos) << r.err;
  EXPECT_EQ(std::count(r.err.begin(), r.err.end(), '\n'), 1) << r.err;
  EXPECT_FALSE(std::filesystem::exists(dir.path("bad.mps")));

  // Every real RIB file: polygons ingest, everything else warns; none fails.
  for (const auto& f : std::filesystem::directory_iterator(test::sharedDir() + "/data/rib")) {
    auto rr = test::runReshutter("ingest " + f.path().string() + " -o " + dir.path("real.mps"));
    EXPECT_EQ(rr.exitCode, 0) << f.path() << "\n" << rr.err;
  }
}

TEST(IngestHardTest, MutatedDumpsFailCleanlyOrIngest) {
  // A dump using most of what ingest reads, damaged at random: every run either ingests or throws
  // reshutter::Error (under ASan/UBSan in the sanitizer build: no memory errors, no UB).
  const std::string base =
      "FrameBegin 1\nFormat 64 48 1\nProjection \"perspective\" \"fov\" [45]\nShutter 0 1\nTranslate 0 0 1\nWorldBegin\n"
      "Declare \"blurP\" \"vertex point\"\nAttributeBegin\nOrientation \"inside\"\nSides 1\nColor [1 0.5 0.25]\n"
      "MotionBegin [0 0.5 1]\nTranslate 0 0 0\nTranslate 1 0 0\nTranslate 2 0 1\nMotionEnd\n"
      "PointsPolygons [4 3 5] [0 1 2 3  1 4 2  0 5 6 7 8] \"P\" [0 0 5  1 0 5  1 1 5  0 1 5  2 0 5  -1 -1 5  0 -2 5  1 -1 5  0 0.5 5]\n"
      "  \"Cs\" [1 0 0  0 1 0  0 0 1  1 1 1  0 0 0  1 0 0  0 1 0  0 0 1  1 1 1] \"uniform float id\" [1 2 3]\n"
      "  \"facevarying float fv\" [1 2 3 4 5 6 7 8 9 10 11 12]\nAttributeEnd\n"
      "MotionBegin [0 1]\nPolygon \"P\" [0 0 5 1 0 5 1 1 5]\nPolygon \"P\" [0 0 6 1 0 6 1 1 6]\nMotionEnd\n"
      "CoordSysTransform \"camera\"\nPointsPolygons [4] [0 1 2 3] \"P\" [0 0 5 1 0 5 1 1 5 0 1 5] \"blurP\" [0 0 6 1 0 6 1 1 6 0 1 6]\n"
      "WorldEnd\nFrameEnd\n";
  setVerbosity(Verbosity::Quiet);
  std::mt19937 rng(12345);
  const char alphabet[] = " []\"0123456789.-eP#\nMotionBeginEnd\x80\x8f\xa6\xcc";
  int ingested = 0, failed = 0;
  for (int run = 0; run < 400; ++run) {
    std::string s = base;
    const int edits = 1 + int(rng() % 4);
    for (int e = 0; e < edits; ++e) {
      size_t at = rng() % s.size();
      switch (rng() % 3) {
        case 0: s[at] = alphabet[rng() % (sizeof alphabet - 1)]; break;
        case 1: s.erase(at, 1 + rng() % 8); break;
        default: s.insert(at, 1, alphabet[rng() % (sizeof alphabet - 1)]);
      }
    }
    test::ScratchDir dir;
    writeFile(dir.path("m.rib"), s);
    try {
      StoreMeta m = shade::scanDump(dir.path("m.rib"));
      Capture cap;
      shade::IngestStats st;
      shade::ingestDumpInto(dir.path("m.rib"), m, cap, st);
      ++ingested;
    } catch (const Error&) {
      ++failed;
    }
  }
  setVerbosity(Verbosity::Normal);
  EXPECT_GT(ingested, 10);
  EXPECT_GT(failed, 10);
}
