// Crack-free dicing (shade/split.h): grids that meet along a surface share the points of their
// common side, whatever rates their interiors are diced at. Checked two ways: topologically (on
// closed surfaces every rim edge of every grid is met by the reverse edge of another grid: no
// T-junction anywhere) and in the image (the Utah teapot, white on black, shows no partly covered
// pixel inside its silhouette at any shading rate).
#include <cmath>
#include <fstream>
#include <map>

#include <gtest/gtest.h>
#include <glm/geometric.hpp>

#include "common/log.h"
#include "shade/scene.h"
#include "shade/shading_pass.h"
#include "tests/exr_test_util.h"
#include "tests/test_util.h"

namespace reshutter::shade {
namespace {

using glm::dvec3;

// The rim edges of every grid: the directed edges of its micropolygons that no other
// micropolygon of the same grid runs back along.
struct RimSink final : store::GridSink {
  struct Edge {
    glm::vec3 a, b;
    uint32_t grid;
  };
  std::vector<Edge> rim;
  uint64_t grids = 0, triangles = 0;
  uint32_t addSchedule(const store::Schedule& k) override { return k.size() > 1 ? 1 : 0; }  // rim edges are taken at the first knot
  void addGrid(const store::GridInput& g) override {
    std::map<std::pair<uint32_t, uint32_t>, int> edges;
    const size_t n = g.corners.size() / 4;
    for (size_t m = 0; m < n; ++m) {
      const uint32_t* c = &g.corners[m * 4];
      const int k = c[3] == store::kNoCorner ? 3 : 4;
      triangles += k == 3;
      for (int i = 0; i < k; ++i) ++edges[{c[i], c[(i + 1) % k]}];
    }
    for (const auto& [e, count] : edges)
      if (!edges.count({e.second, e.first})) rim.push_back({g.positions[e.first], g.positions[e.second], uint32_t(grids)});
    ++grids;
  }
};

// Rim edges that no rim edge of another grid runs back along (end points equal within `tol`):
// the places a crack can open.
size_t unpairedRimEdges(const RimSink& s, double tol) {
  auto cell = [tol](const glm::vec3& p) {
    return std::array<int64_t, 3>{int64_t(std::floor(p.x / (4 * tol))), int64_t(std::floor(p.y / (4 * tol))), int64_t(std::floor(p.z / (4 * tol)))};
  };
  std::map<std::array<int64_t, 3>, std::vector<size_t>> byStart;
  for (size_t i = 0; i < s.rim.size(); ++i) byStart[cell(s.rim[i].a)].push_back(i);
  size_t unpaired = 0;
  for (const auto& e : s.rim) {
    bool found = false;
    const auto c = cell(e.b);
    for (int64_t dz = -1; dz <= 1 && !found; ++dz)
      for (int64_t dy = -1; dy <= 1 && !found; ++dy)
        for (int64_t dx = -1; dx <= 1 && !found; ++dx) {
          auto it = byStart.find({c[0] + dx, c[1] + dy, c[2] + dz});
          if (it == byStart.end()) continue;
          for (size_t j : it->second) {
            const auto& r = s.rim[j];
            if (r.grid != e.grid && glm::length(glm::dvec3(r.a - e.b)) <= tol && glm::length(glm::dvec3(r.b - e.a)) <= tol) {
              found = true;
              break;
            }
          }
        }
    unpaired += !found;
  }
  return unpaired;
}

FrameScene frameOf(const std::function<void(Scene&)>& world) {
  FrameScene out;
  Scene s([&](FrameScene& f) { out = std::move(f); });
  s.format(320, 240, 1);
  s.perspective(60);
  s.clipping(0.1, 1000);
  s.worldBegin();
  world(s);
  s.worldEnd();
  return out;
}

// A torus of revolution as a periodic b-spline patch mesh (nu x nv control points).
void bsplineTorus(Scene& s, int nu, int nv) {
  CubicBasis b;
  CubicBasis::named("b-spline", b);
  s.basis(b, b);
  std::vector<dvec3> P;
  for (int j = 0; j < nv; ++j)
    for (int i = 0; i < nu; ++i) {
      const double a = 2 * M_PI * i / nu, c = 2 * M_PI * j / nv, r = 1.2 + 0.5 * std::cos(c);
      P.emplace_back(r * std::cos(a), r * std::sin(a), 0.5 * std::sin(c));
    }
  s.patchMesh(true, nu, true, nv, true, P);
}

// The eight triangles of an octahedron and, beside it, a cube of six quads (both closed), in view.
void polyhedra(Scene& s) {
  s.scale(0.5, 0.5, 0.5);
  const std::vector<dvec3> P = {{1, 0, 0}, {-1, 0, 0}, {0, 1, 0}, {0, -1, 0}, {0, 0, 1}, {0, 0, -1}};
  const std::vector<int> tris = {0, 2, 4, 2, 1, 4, 1, 3, 4, 3, 0, 4, 2, 0, 5, 1, 2, 5, 3, 1, 5, 0, 3, 5};
  s.pointsPolygons(std::vector<int>(8, 3), tris, P);
  s.translate(2.5, 0, 0);
  std::vector<dvec3> C;
  for (int i = 0; i < 8; ++i) C.emplace_back(i & 1 ? 0.7 : -0.7, i & 2 ? 0.7 : -0.7, i & 4 ? 0.7 : -0.7);
  const std::vector<int> quads = {0, 2, 3, 1, 4, 5, 7, 6, 0, 1, 5, 4, 2, 6, 7, 3, 0, 4, 6, 2, 1, 3, 7, 5};
  s.pointsPolygons(std::vector<int>(6, 4), quads, C);
}

// A catmull-clark cube (a closed limit surface, one primitive per face).
void subdivisionCube(Scene& s) {
  std::vector<dvec3> C;
  for (int i = 0; i < 8; ++i) C.emplace_back(i & 1 ? 1 : -1, i & 2 ? 1 : -1, i & 4 ? 1 : -1);
  const std::vector<int> quads = {0, 2, 3, 1, 4, 5, 7, 6, 0, 1, 5, 4, 2, 6, 7, 3, 0, 4, 6, 2, 1, 3, 7, 5};
  s.subdivisionMesh(SubdivScheme::CatmullClark, std::vector<int>(6, 4), quads, SubdivTags{}, C);
}

TEST(Cracks, RimEdgesPairUpOnClosedSurfacesAtEveryRate) {
  // Each surface close to the eye and tilted, so that its pieces are diced at very different
  // rates (the near side splits, the far side does not).
  const std::vector<std::pair<std::string, std::function<void(Scene&)>>> surfaces = {
      {"b-spline torus mesh", [](Scene& s) { bsplineTorus(s, 12, 8); }},
      {"polygon octahedron and cube", polyhedra},
      {"subdivision cube", subdivisionCube},
      {"torus quadric", [](Scene& s) { s.torus(1.2, 0.5, 0, 360, 360); }},
      {"sphere quadric", [](Scene& s) { s.sphere(1, -1, 1, 360); }},
  };
  for (const auto& [name, build] : surfaces)
    for (double rate : {0.5, 4.0, 40.0}) {
      FrameScene f = frameOf([&](Scene& s) {
        s.translate(0, 0, 3.2);
        s.rotate(-65, 1, 0, 0);
        s.rotate(20, 0, 0, 1);
        s.shadingRate(rate);
        build(s);
      });
      RimSink sink;
      const ShadeStats stats = shadeFrame(f, {}, sink);
      ASSERT_GT(sink.grids, 4u) << name;
      EXPECT_EQ(stats.forcedCuts, 0u) << name;
      EXPECT_EQ(stats.droppedMicropolygons, 0u) << name;
      EXPECT_EQ(stats.culledPieces, 0u) << name;  // all of it in view: every side has its other side
      // Grids met sides coarser than their own rims (the stitching ran) at the finer rates.
      if (rate < 10) {
        EXPECT_GT(sink.triangles, 0u) << name << " at rate " << rate;
      }
      EXPECT_EQ(unpairedRimEdges(sink, 1e-5), 0u) << name << " at rate " << rate << ": " << sink.rim.size() << " rim edges";
    }
}

TEST(Cracks, MovingSurfacesDiceLikeStillOnesAndStayClosed) {
  // Motion with no motionfactor changes nothing about the step counts: a sphere whose camera
  // moves dices into about as many micropolygons as the still one (a pole is one point at each
  // knot, however it moves), and its grids still meet edge to edge.
  auto shade = [](bool moving) {
    FrameScene out;
    Scene s([&](FrameScene& f) { out = std::move(f); });
    s.format(320, 240, 1);
    s.perspective(60);
    s.shutter(0, 1);
    if (moving) {
      s.motionBegin({0, 1});
      s.translate(0, 0, 4);
      s.translate(0.4, 0.1, 4);
      s.motionEnd();
    } else {
      s.translate(0, 0, 4);
    }
    s.worldBegin();
    s.rotate(-70, 1, 0, 0);
    s.sphere(1.5, -1.5, 1.5, 360);
    s.worldEnd();
    RimSink sink;
    const ShadeStats stats = shadeFrame(out, {}, sink);
    EXPECT_EQ(stats.movingGrids, moving ? stats.grids : 0u);
    EXPECT_EQ(unpairedRimEdges(sink, 1e-5), 0u) << (moving ? "moving" : "still");
    return double(stats.micropolygons);
  };
  const double still = shade(false), moving = shade(true);
  EXPECT_GT(still, 1000);
  EXPECT_NEAR(moving / still, 1.0, 0.1);
}

// ---------------------------------------------------------------------------------------------
// The teapot, rendered through the CLI.

TEST(Cracks, TeapotShowsNoCrackPixelAtAnyShadingRate) {
  // White on black, 64 samples per pixel, box filter: a pixel deep inside the silhouette (every
  // pixel within two of it covered at least in part) must be wholly covered. A crack between
  // grids lets background samples through and shows as such a pixel.
  test::ScratchDir dir;
  const std::string teapot = test::sharedDir() + "/data/rib-production/rmr_arman_ch12/teapot.rib";
  for (double rate : {0.25, 1.0, 8.0, 32.0})
    for (int view = 0; view < 2; ++view) {
      const std::string name = cat("teapot", view, "_", rate);
      std::ofstream(dir.path(name + ".rib")) << "Format 320 240 1\nProjection \"perspective\" \"fov\" [30]\nTranslate 0 -0.5 11\n"
                                             << (view ? "Rotate -60 1 0 0\nRotate 150 0 0 1\n" : "Rotate -100 1 0 0\nRotate 30 0 0 1\n")
                                             << "WorldBegin\nShadingRate " << rate << "\nSurface \"constant\"\nReadArchive \"" << teapot << "\"\nWorldEnd\n";
      auto r = test::runReshutter("-q shade " + dir.path(name + ".rib") + " -o " + dir.path(name + ".mps"));
      ASSERT_EQ(r.exitCode, 0) << r.err;
      r = test::runReshutter("-q resample " + dir.path(name + ".mps") + " -o " + dir.path(name + ".exr") + " --samples 8x8 --filter box:1x1");
      ASSERT_EQ(r.exitCode, 0) << r.err;
      const resample::FlatImage img = test::readFlatExr(dir.path(name + ".exr"));
      const auto& A = img.find("A")->f;
      const int W = 320, H = 240;
      size_t inside = 0, cracks = 0;
      std::string where;
      for (int y = 2; y < H - 2; ++y)
        for (int x = 2; x < W - 2; ++x) {
          bool deep = true;
          for (int dy = -2; dy <= 2 && deep; ++dy)
            for (int dx = -2; dx <= 2 && deep; ++dx) deep = A[size_t((y + dy) * W + x + dx)] > 0;
          if (!deep) continue;
          ++inside;
          if (A[size_t(y * W + x)] < 1 - 1e-5) {
            ++cracks;
            if (cracks <= 5) where += cat(" (", x, ",", y, ") ", A[size_t(y * W + x)]);
          }
        }
      EXPECT_GT(inside, 10000u) << name;  // the teapot fills a good part of the frame
      EXPECT_EQ(cracks, 0u) << name << ":" << where;
    }
}

}  // namespace
}  // namespace reshutter::shade
