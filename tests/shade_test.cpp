// Tests of the shading pass: dicing (area vs shading rate, shared vertices, the eye plane),
// shaders and lights against the RenderMan formulas written out independently here, motion
// (transform knots, deformation, camera motion, animated colour), flags, output variables,
// determinism, the demo scene and every RIB scene in ../shared/data/rib.
#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <map>
#include <random>
#include <set>

#include <gtest/gtest.h>
#include <tbb/global_control.h>
#include <glm/geometric.hpp>
#include <glm/gtc/matrix_transform.hpp>

#include "common/error.h"
#include "common/log.h"
#include "shade/demo_scene.h"
#include "shade/rib_scene.h"
#include "shade/shading_pass.h"
#include "shade/shadows.h"
#include "store/reader.h"
#include "tests/test_util.h"

namespace reshutter::shade {
namespace {

using glm::dvec3;

// Keeps copies of every grid the pass sends.
struct CaptureSink final : store::GridSink {
  struct Grid {
    uint32_t schedule = 0, numVertices = 0, objectId = 0, gridId = 0;
    uint8_t flags = 0;
    std::vector<glm::vec3> positions;
    std::vector<uint32_t> corners;
    std::vector<std::vector<float>> attrs;
    size_t mps() const { return corners.size() / 4; }
  };
  std::vector<store::Schedule> schedules{store::Schedule{0.0}};
  std::vector<Grid> grids;
  uint32_t addSchedule(const store::Schedule& k) override {
    if (k.size() == 1) return 0;
    for (size_t i = 1; i < schedules.size(); ++i)
      if (schedules[i] == k) return uint32_t(i);
    schedules.push_back(k);
    return uint32_t(schedules.size() - 1);
  }
  void addGrid(const store::GridInput& g) override {
    Grid c;
    c.schedule = g.schedule, c.numVertices = g.numVertices, c.objectId = g.objectId, c.gridId = g.gridId, c.flags = g.flags;
    c.positions.assign(g.positions.begin(), g.positions.end());
    c.corners.assign(g.corners.begin(), g.corners.end());
    for (const auto& a : g.attrs) c.attrs.emplace_back(a.f.begin(), a.f.end());
    grids.push_back(std::move(c));
  }
  uint64_t mps() const {
    uint64_t n = 0;
    for (const auto& g : grids) n += g.mps();
    return n;
  }
};

// A frame built with the Scene API: options, then `world` between WorldBegin and WorldEnd.
template <typename F>
FrameScene frameOf(F&& world, int width = 320, int height = 240, double fov = 40, std::vector<std::string> outputs = {},
                   std::function<void(Scene&)> camera = nullptr) {
  FrameScene out;
  Scene s([&](FrameScene& f) { out = std::move(f); });
  s.format(width, height, 1);
  s.perspective(fov);
  s.clipping(0.1, 1000);
  s.shutter(0, 1);
  if (!outputs.empty()) {
    std::string mode;
    for (const auto& o : outputs) mode += (mode.empty() ? "" : ",") + o;
    s.display("+aov", mode);
  }
  if (camera) camera(s);
  s.worldBegin();
  world(s);
  s.worldEnd();
  return out;
}

CaptureSink shadeCapture(const FrameScene& f, ShadeOptions o = {}) {
  CaptureSink sink;
  shadeFrame(f, o, sink);
  return sink;
}

int attrIndex(const FrameScene& f, const std::string& name, const ShadeOptions& o = {}) { return storeMeta(f, o).schema.find(name); }

double rasterArea(const store::Projector& pr, const CaptureSink::Grid& g, size_t m, uint32_t knot = 0) {
  const uint32_t* c = &g.corners[m * 4];
  const int n = c[3] == store::kNoCorner ? 3 : 4;
  glm::dvec2 r[4];
  for (int i = 0; i < n; ++i) r[i] = pr.project(glm::dvec3(g.positions[size_t(knot) * g.numVertices + c[i]]));
  double a = 0;
  for (int i = 0; i < n; ++i) a += r[i].x * r[(i + 1) % n].y - r[(i + 1) % n].x * r[i].y;
  return std::abs(a) / 2;
}

// ---------------------------------------------------------------------------------------------
// Dicing

TEST(ShadeDice, MicropolygonAreaFollowsShadingRate) {
  for (double rate : {0.25, 1.0, 4.0, 16.0}) {
    FrameScene f = frameOf([&](Scene& s) {
      s.shadingRate(rate);
      s.patch({dvec3(-1, -1, 5), dvec3(1, -1, 5), dvec3(-1, 1, 5), dvec3(1, 1, 5)});
    });
    CaptureSink sink = shadeCapture(f);
    store::Projector pr(storeMeta(f, {}).cameras[0]);
    double sum = 0, mx = 0;
    uint64_t n = 0;
    for (const auto& g : sink.grids)
      for (size_t m = 0; m < g.mps(); ++m) {
        double a = rasterArea(pr, g, m);
        sum += a, mx = std::max(mx, a), ++n;
      }
    ASSERT_GT(n, 0u);
    const double mean = sum / double(n);
    EXPECT_LE(mx, rate * 1.001) << "rate " << rate;
    EXPECT_GE(mean, rate * 0.6) << "rate " << rate;
    // The square covers a known raster area: the micropolygons must tile it.
    const double side = 2.0 / 5.0 * pr.ax;
    EXPECT_NEAR(sum, side * side, side * side * 1e-3) << "rate " << rate;
  }
}

TEST(ShadeDice, SphereMicropolygonsNoLargerThanRateAndGridsBounded) {
  FrameScene f = frameOf([](Scene& s) {
    s.translate(0, 0, 6);
    s.shadingRate(2);
    s.sphere(1, -1, 1, 360);
  });
  CaptureSink sink = shadeCapture(f);
  store::Projector pr(storeMeta(f, {}).cameras[0]);
  double sum = 0;
  uint64_t n = 0;
  for (const auto& g : sink.grids) {
    EXPECT_LE(g.mps(), 16u * 16u);
    for (size_t m = 0; m < g.mps(); ++m) {
      double a = rasterArea(pr, g, m);
      EXPECT_LE(a, 2 * 1.25);  // test points on a curved piece underestimate its length a little
      sum += a, ++n;
    }
  }
  // Front and back halves both count: twice the disc's area, within the dicing slack.
  const double r = 1.0 / std::sqrt(35.0) * pr.ax;  // silhouette radius in pixels
  EXPECT_NEAR(sum, 2 * M_PI * r * r, 0.05 * 2 * M_PI * r * r);
  EXPECT_GT(sum / double(n), 2 * 0.3);  // nor much smaller than the rate on average
}

TEST(ShadeDice, GridsAreConsistentDiscs) {
  FrameScene f = frameOf([](Scene& s) {
    s.translate(0, 0, 5);
    s.torus(1, 0.3, 0, 360, 360);
    s.sphere(0.5, -0.5, 0.5, 360);
    s.patch({dvec3(-3, -3, 2), dvec3(3, -3, 2), dvec3(-3, 3, 3), dvec3(3, 3, 3)});
  });
  CaptureSink sink = shadeCapture(f);
  ASSERT_FALSE(sink.grids.empty());
  uint64_t triangles = 0;
  for (const auto& g : sink.grids) {
    // Every directed edge once, every interior edge shared by index with its reverse (consistent
    // winding, no duplicated vertices along it), every vertex used, and the whole a disc: V - E +
    // F = 1 (quads, and triangles where a rim meets a coarser side or a collapsed one).
    std::map<std::pair<uint32_t, uint32_t>, int> edges;
    std::set<uint32_t> used;
    for (size_t m = 0; m < g.mps(); ++m) {
      const uint32_t* c = &g.corners[m * 4];
      const int n = c[3] == store::kNoCorner ? 3 : 4;
      triangles += n == 3;
      for (int i = 0; i < n; ++i) {
        ASSERT_NE(c[i], c[(i + 1) % n]);
        ++edges[{c[i], c[(i + 1) % n]}];
        used.insert(c[i]);
      }
    }
    size_t undirected = 0;
    for (const auto& [e, count] : edges) {
      ASSERT_EQ(count, 1);
      undirected += edges.count({e.second, e.first}) ? 1 : 2;  // an interior edge is met twice
    }
    EXPECT_EQ(used.size(), g.numVertices) << "grid " << g.gridId;
    EXPECT_EQ(int64_t(g.numVertices) - int64_t(undirected / 2) + int64_t(g.mps()), 1) << "grid " << g.gridId;
  }
  EXPECT_GT(triangles, 0u);  // the sphere's poles at least
}

TEST(ShadeDiceHard, SphereCrossingEyePlane) {
  // A sphere around the near plane (and the eye): only what lies in front may be stored, with
  // finite positions and no micropolygon straddling the plane.
  FrameScene f = frameOf([](Scene& s) {
    s.translate(0.2, 0.1, 0.5);
    s.sphere(1, -1, 1, 360);
  });
  ShadeOptions o;
  CaptureSink sink;
  ShadeStats st = shadeFrame(f, o, sink);
  EXPECT_GT(st.eyeSplits, 0u);
  EXPECT_GT(sink.mps(), 1000u);
  EXPECT_LT(sink.mps(), 2'000'000u);
  for (const auto& g : sink.grids)
    for (size_t m = 0; m < g.mps(); ++m)
      for (int i = 0; i < 4; ++i) {
        uint32_t c = g.corners[m * 4 + i];
        if (c == store::kNoCorner) continue;
        const auto& p = g.positions[c];
        ASSERT_TRUE(std::isfinite(p.x) && std::isfinite(p.y) && std::isfinite(p.z));
        ASSERT_GE(p.z, 0.1f);
      }
}

TEST(ShadeDiceHard, DegenerateAndEnclosingPrimitives) {
  // Zero-size quadrics, collinear polygons, a sphere around the eye and a huge one far away:
  // nothing may throw, and the store writer (which rejects non-finite data) must take it all.
  FrameScene f = frameOf([](Scene& s) {
    s.sphere(0, 0, 0, 360);
    s.disk(1, 0, 360);
    s.cone(0, 0, 360);
    s.torus(0, 0, 0, 360, 360);
    s.cylinder(1, 2, 2, 360);
    s.polygon({dvec3(0, 0, 3), dvec3(1, 0, 3), dvec3(2, 0, 3)});
    s.polygon({dvec3(0, 0, 3), dvec3(0, 0, 3), dvec3(0, 0, 3), dvec3(0, 0, 3)});
    s.sphere(50, -50, 50, 360);  // the eye is inside
    s.translate(0, 0, 1e6);
    s.sphere(1e5, -1e5, 1e5, 360);
  });
  test::ScratchDir dir;
  StoreResult r;
  ASSERT_NO_THROW(r = shadeToStore(f, ShadeOptions{}, dir.path("d.mps")));
  EXPECT_GT(r.shade.micropolygons, 10'000u);
  EXPECT_LT(r.shade.micropolygons, 3'000'000u);
  store::StoreReader reader(dir.path("d.mps"));
  EXPECT_EQ(reader.verify().micropolygons, r.shade.micropolygons);
}

TEST(ShadeDiceHard, SphereMovingThroughEyePlane) {
  FrameScene f = frameOf([](Scene& s) {
    s.motionBegin({0, 1});
    s.translate(0, 0, 4);
    s.translate(0.3, 0, -3);
    s.motionEnd();
    s.sphere(1, -1, 1, 360);
  });
  CaptureSink sink = shadeCapture(f);
  ASSERT_GT(sink.mps(), 0u);
  for (const auto& g : sink.grids) {
    ASSERT_EQ(sink.schedules[g.schedule].size(), 2u);
    for (size_t m = 0; m < g.mps(); ++m)
      for (uint32_t k = 0; k < 2; ++k) {
        const int n = g.corners[m * 4 + 3] == store::kNoCorner ? 3 : 4;
        int behind = 0;
        for (int i = 0; i < n; ++i) behind += g.positions[k * g.numVertices + g.corners[m * 4 + i]].z < 0.1f;
        ASSERT_TRUE(behind == 0 || behind == n) << "a micropolygon straddles the near plane at knot " << k;
      }
  }
}

TEST(ShadeDice, MotionFactorCoarsensFastObjects) {
  auto count = [](double mf) {
    FrameScene f = frameOf([&](Scene& s) {
      s.motionFactor(mf);
      s.motionBegin({0, 1});
      s.translate(-1.5, 0, 6);
      s.translate(1.5, 0, 6);
      s.motionEnd();
      s.sphere(1, -1, 1, 360);
    });
    return shadeCapture(f).mps();
  };
  const uint64_t still = count(0), coarse = count(1);
  EXPECT_LT(coarse * 2, still);  // ~190 px of motion: the rate grows ~13×
  EXPECT_GT(coarse, 0u);
}

TEST(ShadeDice, OffscreenPrimitivesCulled) {
  FrameScene f = frameOf([](Scene& s) {
    s.translate(0, 0, 5);
    s.sphere(1, -1, 1, 360);
    s.translate(100, 0, 0);
    s.sphere(1, -1, 1, 360);
    s.translate(-100, 0, -20);  // behind the camera
    s.sphere(1, -1, 1, 360);
  });
  CaptureSink sink = shadeCapture(f);
  ASSERT_FALSE(sink.grids.empty());
  for (const auto& g : sink.grids)
    for (const auto& p : g.positions) ASSERT_LT(std::abs(p.x), 50.f);
}

// ---------------------------------------------------------------------------------------------
// Shading against the RenderMan formulas, written out independently of shade/shaders.cpp.

struct Lit {
  const char* shader;
  const char* light;
};

dvec3 faceforwardN(const dvec3& N, const dvec3& I) { return glm::dot(I, N) > 0 ? -N : N; }

class ShadeShaders : public ::testing::TestWithParam<Lit> {};

TEST_P(ShadeShaders, SpherePointsMatchAnalyticFormulas) {
  const Lit lit = GetParam();
  const dvec3 Cs(0.8, 0.5, 0.3), Os(0.9, 0.7, 1.0), specColor(0.6, 0.9, 1.0);
  const double Ka = 0.3, Kd = 0.7, Ks = 0.6, rough = 0.15, intensity = 2.5;
  const dvec3 lightColor(1.0, 0.9, 0.7), from(2, 3, 1), to(0, 0, 6);
  const double cone = 0.6, delta = 0.15, beam = 3;
  FrameScene f = frameOf(
      [&](Scene& s) {
        ParamMap lp = {{"intensity", {intensity}},
                       {"lightcolor", {lightColor.x, lightColor.y, lightColor.z}},
                       {"from", {from.x, from.y, from.z}},
                       {"to", {to.x, to.y, to.z}},
                       {"coneangle", {cone}},
                       {"conedeltaangle", {delta}},
                       {"beamdistribution", {beam}}};
        s.lightSource(lit.light, "1", lp);
        s.color(Cs);
        s.opacity(Os);
        s.surface(lit.shader, {{"Ka", {Ka}}, {"Kd", {Kd}}, {"Ks", {Ks}}, {"roughness", {rough}}, {"specularcolor", {specColor.x, specColor.y, specColor.z}}});
        s.translate(0, 0, 6);
        s.rotate(30, 1, 1, 0);
        s.sphere(1.5, -1.5, 1.5, 360);
      },
      160, 120, 40, {"P", "N", "specular"});
  CaptureSink sink = shadeCapture(f);
  const int iCi = attrIndex(f, "Ci"), iOi = attrIndex(f, "Oi"), iP = attrIndex(f, "P"), iN = attrIndex(f, "N"), iS = attrIndex(f, "specular");
  ASSERT_GE(iS, 0);
  const std::string light = lit.light, shader = lit.shader;
  const dvec3 Cl0 = intensity * lightColor;
  const dvec3 axis = glm::normalize(to - from);
  uint64_t checked = 0, litPoints = 0;
  for (const auto& g : sink.grids)
    for (uint32_t v = 0; v < g.numVertices; ++v) {
      auto get = [&](int a) { return dvec3(g.attrs[size_t(a)][v * 3], g.attrs[size_t(a)][v * 3 + 1], g.attrs[size_t(a)][v * 3 + 2]); };
      const dvec3 P = get(iP), N = glm::normalize(get(iN)), Ci = get(iCi), Oi = get(iOi), spec = get(iS);
      const dvec3 I = P, V = -glm::normalize(I);
      const dvec3 Nf = faceforwardN(N, I);  // a sphere's N is its Ng
      // One light: direction towards it and its colour at P.
      dvec3 L(0.0), Cl(0.0), amb(0.0);
      bool has = false;
      if (light == "ambientlight") amb = Cl0;
      if (light == "distantlight") L = -axis, Cl = Cl0, has = true;
      if (light == "pointlight") L = from - P, Cl = Cl0 / glm::dot(L, L), has = true;
      if (light == "spotlight") {
        L = from - P;
        const double cosangle = glm::dot(P - from, axis) / glm::length(P - from);
        const double c0 = std::cos(cone), c1 = std::cos(cone - delta);
        const double x = std::clamp((cosangle - c0) / (c1 - c0), 0.0, 1.0);
        if (cosangle >= c0) Cl = Cl0 * std::pow(cosangle, beam) / glm::dot(L, L) * (x * x * (3 - 2 * x)), has = true;
      }
      dvec3 diff(0.0), specular(0.0);
      if (has) {
        const dvec3 Ln = glm::normalize(L);
        const double cosine = glm::dot(Ln, Nf);
        if (cosine > 0) {
          diff = Cl * cosine;
          const dvec3 H = glm::normalize(Ln + V);
          specular = Cl * std::pow(std::max(0.0, glm::dot(Nf, H)), 1.0 / rough);
          ++litPoints;
        }
      }
      dvec3 expect, expectSpec(0.0);
      if (shader == "constant") expect = Os * Cs;
      if (shader == "matte") expect = Os * Cs * (Ka * amb + Kd * diff);
      if (shader == "metal") expectSpec = Os * Cs * Ks * specular, expect = Os * Cs * Ka * amb + expectSpec;
      if (shader == "plastic") expectSpec = Os * specColor * Ks * specular, expect = Os * (Cs * (Ka * amb + Kd * diff)) + expectSpec;
      for (int c = 0; c < 3; ++c) {
        ASSERT_NEAR(Ci[c], expect[c], 2e-4 + 1e-4 * std::abs(expect[c])) << shader << " + " << light << " at P=(" << P.x << "," << P.y << "," << P.z << ")";
        ASSERT_NEAR(spec[c], expectSpec[c], 2e-4 + 1e-4 * std::abs(expectSpec[c]));
        ASSERT_FLOAT_EQ(float(Oi[c]), float(Os[c]));
      }
      ++checked;
    }
  EXPECT_GT(checked, 500u);
  if (light != "ambientlight") {
    EXPECT_GT(litPoints, 50u);
  }
}

INSTANTIATE_TEST_SUITE_P(AllShadersAndLights, ShadeShaders,
                         ::testing::Values(Lit{"constant", "pointlight"}, Lit{"matte", "ambientlight"}, Lit{"matte", "distantlight"},
                                           Lit{"matte", "pointlight"}, Lit{"matte", "spotlight"}, Lit{"metal", "distantlight"}, Lit{"metal", "pointlight"},
                                           Lit{"plastic", "ambientlight"}, Lit{"plastic", "pointlight"}, Lit{"plastic", "spotlight"},
                                           Lit{"plastic", "distantlight"}),
                         [](const auto& info) { return std::string(info.param.shader) + "_" + info.param.light; });

// ---------------------------------------------------------------------------------------------
// Motion

TEST(ShadeMotion, ThreeKnotRotateStoresTransformedPointsAtEveryKnot) {
  const double angles[3] = {0, 25, 50};
  FrameScene f = frameOf([&](Scene& s) {
    s.translate(0.5, 0, 6);
    s.motionBegin({0, 0.5, 1});
    for (double a : angles) s.rotate(a, 0.3, 1, 0.2);
    s.motionEnd();
    s.sphere(1, -1, 1, 360);
  });
  CaptureSink sink = shadeCapture(f);
  ASSERT_EQ(sink.schedules.size(), 2u);
  EXPECT_EQ(sink.schedules[1], (store::Schedule{0, 0.5, 1}));
  const glm::dmat4 T = glm::translate(glm::dmat4(1.0), dvec3(0.5, 0, 6));
  glm::dmat4 M[3];
  for (int k = 0; k < 3; ++k) M[k] = T * glm::rotate(glm::dmat4(1.0), glm::radians(angles[k]), dvec3(0.3, 1, 0.2));
  uint64_t n = 0;
  for (const auto& g : sink.grids) {
    ASSERT_EQ(g.schedule, 1u);
    for (uint32_t v = 0; v < g.numVertices; ++v) {
      // The object-space point from knot 0, carried to each knot by that knot's transform.
      const dvec3 obj = dvec3(glm::inverse(M[0]) * glm::dvec4(dvec3(g.positions[v]), 1.0));
      for (uint32_t k = 1; k < 3; ++k) {
        const dvec3 expect = dvec3(M[k] * glm::dvec4(obj, 1.0));
        const dvec3 got(g.positions[k * g.numVertices + v]);
        ASSERT_LT(glm::length(got - expect), 4e-6 * glm::length(expect)) << "knot " << k;
      }
      ++n;
    }
  }
  EXPECT_GT(n, 100u);
}

TEST(ShadeMotion, StaticPrimitivesGetOneKnotAndMovingCameraMovesEverything) {
  FrameScene still = frameOf([](Scene& s) {
    s.translate(0, 0, 5);
    s.sphere(1, -1, 1, 360);
  });
  CaptureSink a = shadeCapture(still);
  ASSERT_FALSE(a.grids.empty());
  for (const auto& g : a.grids) EXPECT_EQ(g.schedule, 0u);

  FrameScene moving = frameOf(
      [](Scene& s) {
        s.translate(0, 0, 5);
        s.sphere(1, -1, 1, 360);
      },
      320, 240, 40, {},
      [](Scene& s) {
        s.motionBegin({0, 1});
        s.translate(0, 0, 0);
        s.translate(-0.5, 0, 0);
        s.motionEnd();
      });
  CaptureSink b = shadeCapture(moving);
  ASSERT_FALSE(b.grids.empty());
  for (const auto& g : b.grids) {
    ASSERT_EQ(b.schedules[g.schedule].size(), 2u);
    for (uint32_t v = 0; v < g.numVertices; ++v) {
      ASSERT_NEAR(g.positions[g.numVertices + v].x - g.positions[v].x, -0.5f, 1e-5f);
      ASSERT_NEAR(g.positions[g.numVertices + v].z, g.positions[v].z, 1e-5f);
    }
  }
}

TEST(ShadeMotion, NestedMovingCoordinateSystemsUnionTheirKnots) {
  // A moving camera (knots 0, 1) and a rotating object (knots 0, 0.25, 1): the object gets the
  // union of the knots, each the product of both transforms at that time.
  FrameScene f = frameOf(
      [](Scene& s) {
        s.translate(0, 0, 6);
        s.motionBegin({0, 0.25, 1});
        s.rotate(0, 0, 0, 1);
        s.rotate(20, 0, 0, 1);
        s.rotate(40, 0, 0, 1);
        s.motionEnd();
        s.patch({dvec3(-1, -1, 0), dvec3(1, -1, 0), dvec3(-1, 1, 0), dvec3(1, 1, 0)});
      },
      320, 240, 40, {},
      [](Scene& s) {
        s.motionBegin({0, 1});
        s.translate(0, 0, 0);
        s.translate(-1, 0, 0);
        s.motionEnd();
      });
  CaptureSink sink = shadeCapture(f);
  ASSERT_EQ(sink.schedules.size(), 2u);
  EXPECT_EQ(sink.schedules[1], (store::Schedule{0, 0.25, 1}));
  // The patch corner (1, 1, 0) is a grid vertex whatever the dicing rate.
  const double rot[3] = {0, 20, 40}, camX[3] = {0, -0.25, -1};
  bool found = false;
  for (const auto& g : sink.grids)
    for (uint32_t v = 0; v < g.numVertices; ++v) {
      const glm::dvec4 corner = glm::rotate(glm::dmat4(1.0), glm::radians(rot[0]), dvec3(0, 0, 1)) * glm::dvec4(1, 1, 0, 1);
      if (glm::length(dvec3(g.positions[v]) - dvec3(corner.x + camX[0], corner.y, 6)) > 1e-6) continue;
      found = true;
      for (int k = 1; k < 3; ++k) {
        const glm::dvec4 c = glm::rotate(glm::dmat4(1.0), glm::radians(rot[k]), dvec3(0, 0, 1)) * glm::dvec4(1, 1, 0, 1);
        EXPECT_NEAR(g.positions[size_t(k) * g.numVertices + v].x, c.x + camX[k], 1e-6);
        EXPECT_NEAR(g.positions[size_t(k) * g.numVertices + v].y, c.y, 1e-6);
      }
    }
  EXPECT_TRUE(found);
}

TEST(ShadeMotion, MotionThatStandsStillIsStatic) {
  FrameScene f = frameOf([](Scene& s) {
    s.motionBegin({0, 1});
    s.translate(0, 0, 5);
    s.translate(0, 0, 5);
    s.motionEnd();
    s.sphere(1, -1, 1, 360);
    s.motionBegin({0, 0.5});  // moves only before the interval below
    s.translate(1, 0, 0);
    s.translate(2, 0, 0);
    s.motionEnd();
    s.sphere(0.5, -0.5, 0.5, 360);
  });
  ShadeOptions o;
  o.interval = std::make_pair(0.5, 1.0);
  CaptureSink sink = shadeCapture(f, o);
  ASSERT_FALSE(sink.grids.empty());
  for (const auto& g : sink.grids) EXPECT_EQ(g.schedule, 0u);
  o.interval = std::make_pair(0.0, 1.0);
  CaptureSink moving = shadeCapture(f, o);
  EXPECT_EQ(moving.schedules.size(), 2u);  // the second sphere moves over [0, 0.5]
}

TEST(ShadeMotion, DeformingSphereScalesBetweenKeys) {
  FrameScene f = frameOf([](Scene& s) {
    s.translate(0, 0, 8);
    s.motionBegin({0, 1});
    s.sphere(1, -1, 1, 360);
    s.sphere(2, -2, 2, 360);
    s.motionEnd();
  });
  CaptureSink sink = shadeCapture(f);
  ASSERT_FALSE(sink.grids.empty());
  for (const auto& g : sink.grids)
    for (uint32_t v = 0; v < g.numVertices; ++v) {
      const glm::vec3 c(0, 0, 8);
      ASSERT_NEAR(glm::length(g.positions[v] - c), 1.0f, 1e-5f);
      ASSERT_NEAR(glm::length(g.positions[g.numVertices + v] - c), 2.0f, 1e-5f);
    }
}

TEST(ShadeMotion, AnimatedColourShadedAtChosenTimeAndIntervalClipsKnots) {
  FrameScene f = frameOf([](Scene& s) {
    s.surface("constant", {});
    s.motionBegin({0, 1});
    s.color({1, 0, 0});
    s.color({0, 0, 1});
    s.motionEnd();
    s.motionBegin({0, 1});
    s.translate(-1, 0, 6);
    s.translate(1, 0, 6);
    s.motionEnd();
    s.sphere(1, -1, 1, 360);
  });
  ShadeOptions o;
  o.shadeAt = 0.25;
  o.interval = std::make_pair(0.25, 0.5);
  CaptureSink sink = shadeCapture(f, o);
  ASSERT_FALSE(sink.grids.empty());
  ASSERT_EQ(sink.schedules.size(), 2u);
  EXPECT_EQ(sink.schedules[1], (store::Schedule{0.25, 0.5}));
  const auto& g = sink.grids[0];
  EXPECT_NEAR(g.attrs[0][0], 0.75f, 1e-6f);
  EXPECT_NEAR(g.attrs[0][2], 0.25f, 1e-6f);
  // Knots at the interval's ends: the sphere's centre moved from x = -0.5 to x = 0.
  double dx = 0;
  for (uint32_t v = 0; v < g.numVertices; ++v) dx += g.positions[g.numVertices + v].x - g.positions[v].x;
  EXPECT_NEAR(dx / g.numVertices, 0.5, 1e-5);
  store::StoreMeta m = storeMeta(f, o);
  EXPECT_EQ(m.shutterOpen, 0.25);
  EXPECT_EQ(m.shutterClose, 0.5);
}

// ---------------------------------------------------------------------------------------------
// Attributes, outputs, determinism

TEST(ShadeAttributes, MatteSidesAndIdentifiers) {
  FrameScene f = frameOf([](Scene& s) {
    s.attributeBegin();
    s.identifier("hero");
    s.matte(true);
    s.translate(-1.5, 0, 6);
    s.sphere(1, -1, 1, 360);
    s.attributeEnd();
    s.attributeBegin();
    s.identifier("ground");
    s.sides(1);
    s.translate(1.5, 0, 6);
    s.sphere(1, -1, 1, 360);
    s.attributeEnd();
  });
  ASSERT_EQ(f.objectNames, (std::vector<std::string>{"hero", "ground"}));
  CaptureSink sink = shadeCapture(f);
  std::set<std::pair<uint32_t, uint8_t>> seen;
  for (const auto& g : sink.grids) seen.insert({g.objectId, g.flags});
  EXPECT_EQ(seen, (std::set<std::pair<uint32_t, uint8_t>>{{1, store::kMatte | store::kTwoSided}, {2, 0}}));
  EXPECT_NE(storeMeta(f, {}).provenance.find("2=\"ground\""), std::string::npos);
}

TEST(ShadeAttributes, OrientationFlipsNormalsAndWindingFollowsThem) {
  // Outward normals by default (and under a mirroring Scale with Orientation "outside"); inward
  // after ReverseOrientation. Micropolygon rings always turn counter-clockwise around N.
  for (int mode = 0; mode < 3; ++mode) {
    FrameScene f = frameOf(
        [&](Scene& s) {
          s.translate(0, 0, 5);
          if (mode == 1) s.reverseOrientation();
          if (mode == 2) {
            s.scale(1, -1, 1);
            s.orientation("outside");
          }
          s.sphere(1, -1, 1, 360);
        },
        160, 120, 40, {"N"});
    CaptureSink sink = shadeCapture(f);
    const double expect = mode == 1 ? -1 : 1;
    uint64_t n = 0;
    for (const auto& g : sink.grids)
      for (size_t m = 0; m < g.mps(); ++m) {
        const uint32_t* c = &g.corners[m * 4];
        const dvec3 p0(g.positions[c[0]]), p1(g.positions[c[1]]), p3(g.positions[c[3] == store::kNoCorner ? c[2] : c[3]]);
        const dvec3 N(g.attrs[2][c[0] * 3], g.attrs[2][c[0] * 3 + 1], g.attrs[2][c[0] * 3 + 2]);
        const dvec3 outward = glm::normalize(p0 - dvec3(0, 0, 5));
        ASSERT_GT(expect * glm::dot(N, outward), 0.99) << "mode " << mode;
        const dvec3 ring = glm::cross(p1 - p0, p3 - p0);
        if (glm::length(ring) > 1e-9) {
          ASSERT_GT(glm::dot(ring, N), 0) << "mode " << mode;
        }
        ++n;
      }
    EXPECT_GT(n, 100u);
  }
}

TEST(ShadeAttributes, NamedCamerasAndIlluminateReachTheStore) {
  FrameScene f = frameOf(
      [](Scene& s) {
        s.lightSource("pointlight", "key", {{"from", {0, 0, 0}}, {"intensity", {20}}});
        s.illuminate("key", false);
        s.surface("matte", {});
        s.translate(0, 0, 5);
        s.sphere(1, -1, 1, 360);
      },
      160, 120, 40, {},
      [](Scene& s) {
        s.transformBegin();
        s.translate(-1, 0, 0);
        s.camera("right");
        s.transformEnd();
      });
  const store::StoreMeta m = storeMeta(f, {});
  ASSERT_EQ(m.cameras.size(), 2u);
  EXPECT_EQ(m.cameras[1].name, "right");
  EXPECT_EQ(m.cameras[1].worldToCamera[3][0], -1.0);
  CaptureSink sink = shadeCapture(f);
  for (const auto& g : sink.grids)
    for (float c : g.attrs[0]) ASSERT_EQ(c, 0.f);  // the only light is off: matte is black
}

TEST(ShadeOutputs, OnlyRequestedVariablesAreStored) {
  FrameScene plain = frameOf([](Scene& s) { s.sphere(1, -1, 1, 360); });
  EXPECT_EQ(storeMeta(plain, {}).schema.attrs.size(), 2u);
  FrameScene f = frameOf(
      [](Scene& s) {
        s.translate(0, 0, 5);
        s.sphere(1, -1, 1, 360);
      },
      160, 120, 40, {"N", "s", "Cs", "depth", "bogus", "rgba"});
  const auto schema = storeMeta(f, {}).schema;
  std::vector<std::string> names;
  for (const auto& a : schema.attrs) names.push_back(a.name);
  EXPECT_EQ(names, (std::vector<std::string>{"Ci", "Oi", "N", "s", "Cs", "depth"}));
  CaptureSink sink = shadeCapture(f);
  for (const auto& g : sink.grids) {
    ASSERT_EQ(g.attrs.size(), 6u);
    for (uint32_t v = 0; v < g.numVertices; ++v) {
      ASSERT_NEAR(g.attrs[5][v], g.positions[v].z, 1e-5f);  // depth at the shading time = knot 0
      ASSERT_NEAR(glm::length(glm::vec3(g.attrs[2][v * 3], g.attrs[2][v * 3 + 1], g.attrs[2][v * 3 + 2])), 1.0f, 1e-5f);
    }
  }
}

uint64_t digest(const CaptureSink& s) {
  uint64_t h = 1469598103934665603ull;
  auto mix = [&](const void* p, size_t n) {
    const auto* b = static_cast<const unsigned char*>(p);
    for (size_t i = 0; i < n; ++i) h = (h ^ b[i]) * 1099511628211ull;
  };
  for (const auto& g : s.grids) {
    mix(g.positions.data(), g.positions.size() * sizeof(glm::vec3));
    mix(g.corners.data(), g.corners.size() * 4);
    for (const auto& a : g.attrs) mix(a.data(), a.size() * 4);
    mix(&g.gridId, 4);
    mix(&g.objectId, 4);
  }
  return h;
}

TEST(ShadePass, OutputIdenticalForAnyThreadCount) {
  FrameScene f = demoFrame(320, 180);
  uint64_t one, many;
  {
    tbb::global_control gc(tbb::global_control::max_allowed_parallelism, 1);
    one = digest(shadeCapture(f));
  }
  {
    tbb::global_control gc(tbb::global_control::max_allowed_parallelism, 4);
    many = digest(shadeCapture(f));
  }
  EXPECT_EQ(one, many);
}

TEST(ShadeDemo, DemoHasEveryIngredient) {
  FrameScene f = demoFrame();
  CaptureSink sink = shadeCapture(f);
  EXPECT_GT(sink.mps(), 100'000u);
  EXPECT_LT(sink.mps(), 2'000'000u);
  std::set<size_t> knotCounts;
  bool matte = false, translucent = false;
  for (const auto& g : sink.grids) {
    knotCounts.insert(sink.schedules[g.schedule].size());
    matte = matte || (g.flags & store::kMatte);
    for (size_t i = 0; i < g.attrs[1].size(); ++i) translucent = translucent || g.attrs[1][i] < 0.5f;
  }
  EXPECT_EQ(knotCounts, (std::set<size_t>{1, 2, 3, 5}));
  EXPECT_TRUE(matte);
  EXPECT_TRUE(translucent);
  EXPECT_GE(f.objectNames.size(), 9u);
}

TEST(ShadeDemo, WritesAValidStore) {
  test::ScratchDir dir;
  const std::string path = dir.path("demo.mps");
  StoreResult r = shadeToStore(demoFrame(320, 180), ShadeOptions{}, path);
  EXPECT_EQ(r.write.micropolygons, r.shade.micropolygons);
  store::StoreReader reader(path);
  EXPECT_EQ(reader.verify().micropolygons, r.shade.micropolygons);
  EXPECT_GE(reader.meta().schedules.size(), 4u);
}

// ---------------------------------------------------------------------------------------------
// RIB scenes

/// The one frame a RIB file makes (a test failure when it makes another number).
FrameScene onlyFrameOf(const std::string& path) {
  FrameScene got;
  int frames = 0;
  Scene scene([&](FrameScene& f) { got = std::move(f), ++frames; });
  readRibScene(path, scene);
  EXPECT_EQ(frames, 1) << path;
  return got;
}

TEST(ShadeRib, EverySharedSceneShades) {
  const std::string dir = test::sharedDir() + "/data/rib";
  ASSERT_TRUE(std::filesystem::is_directory(dir)) << dir;
  int files = 0;
  for (const auto& e : std::filesystem::directory_iterator(dir)) {
    if (e.path().extension() != ".rib") continue;
    ++files;
    uint64_t mps = 0;
    int frames = 0;
    Scene scene([&](FrameScene& f) {
      ShadeOptions o;
      o.dice.shadingRateScale = 4;  // coarser than the files ask: this checks robustness, not quality
      CaptureSink sink;
      shadeFrame(f, o, sink);
      storeMeta(f, o).validate(e.path().string());
      mps += sink.mps();
      ++frames;
    });
    ASSERT_NO_THROW(readRibScene(e.path().string(), scene)) << e.path();
    EXPECT_GE(frames, 1) << e.path();
    EXPECT_GT(mps, 0u) << e.path();
  }
  EXPECT_GE(files, 6);
}

TEST(ShadeRib, EveryProductionSceneShadesOrSaysWhatItSkipped) {
  // ../shared/data/rib-production: no frame may come out empty in silence - it shades
  // micropolygons, or it names the primitives it could not make.
  const std::string dir = test::sharedDir() + "/data/rib-production";
  ASSERT_TRUE(std::filesystem::is_directory(dir)) << dir;
  int files = 0, shaded = 0;
  for (const auto& e : std::filesystem::recursive_directory_iterator(dir)) {
    if (e.path().extension() != ".rib" || e.path().filename() == "teapot.rib") continue;  // teapot.rib is fig12.7's archive
    ++files;
    int frames = 0;
    Scene scene([&](FrameScene& f) {
      ShadeOptions o;
      o.dice.shadingRateScale = 4;
      CaptureSink sink;
      shadeFrame(f, o, sink);
      EXPECT_TRUE(sink.mps() > 0 || !f.skipped.empty()) << e.path();
      shaded += sink.mps() > 0;
      ++frames;
    });
    ASSERT_NO_THROW(readRibScene(e.path().string(), scene)) << e.path();
    EXPECT_GE(frames, 1) << e.path();
  }
  EXPECT_GE(files, 6);
  EXPECT_GE(shaded, 6);  // the bicubic teapot, object instances, the depth-of-field cubes, subdivision creases, bezier grass, NURBS
}

TEST(ShadeRib, RequestsMapToSceneState) {
  test::ScratchDir dir;
  const std::string path = dir.path("scene.rib");
  std::ofstream(path) << R"(
Format 200 100 1
Projection "perspective" "fov" [40]
Shutter 0 1
Display "out.exr" "file" "rgba"
Display "+n.exr" "file" "N,specular"
FrameBegin 7
WorldBegin
  LightSource "distantlight" 1 "intensity" [1.5]
  AttributeBegin
    Attribute "identifier" "name" ["spinner"]
    Matte 1
    Translate 0 0 5
    MotionBegin [0 0.5 1]
      Rotate 0 0 1 0
      Rotate 10 0 1 0
      Rotate 20 0 1 0
    MotionEnd
    Surface "plastic" "roughness" [0.2]
    Polygon "P" [-1 -1 0  1 -1 0  1 1 0  -1 1 0] "Cs" [1 0 0  0 1 0  0 0 1  1 1 1]
    Blobby 1 [1001 0] [1 0 0 0 0 1 0 0 0 0 1 0 0 0 0 1] [""]
  AttributeEnd
WorldEnd
FrameEnd
)";
  FrameScene got;
  Scene scene([&](FrameScene& f) { got = std::move(f); });
  const size_t warnings = warningCount();
  readRibScene(path, scene);
  EXPECT_GT(warningCount(), warnings);  // the Blobby
  EXPECT_EQ(got.skipped, (std::map<std::string, uint64_t>{{"Blobby", 1}}));
  EXPECT_EQ(got.options.frame, 7);
  EXPECT_EQ(got.options.camera.width, 200);
  EXPECT_EQ(got.options.outputs, (std::vector<std::string>{"N", "specular"}));
  ASSERT_EQ(got.prims.size(), 1u);
  std::array<dvec3, 4> cs;
  ASSERT_TRUE(got.prims[0].corners(got.prims[0].mesh->Cs, cs));
  EXPECT_EQ(cs[1], dvec3(0, 1, 0));  // P10 is the polygon's second point
  EXPECT_EQ(cs[3], dvec3(0, 0, 1));  // P11 its third
  EXPECT_TRUE(got.prims[0].attrs->matte);
  EXPECT_EQ(got.prims[0].xform->times, (std::vector<double>{0, 0.5, 1}));
  ASSERT_EQ(got.lights.size(), 1u);
  EXPECT_EQ(got.lights[0].intensity, 1.5);
  CaptureSink sink = shadeCapture(got);
  EXPECT_GT(sink.mps(), 0u);
}

TEST(ShadeRib, WhatExportersWriteIsKeptNotFatal) {
  // A RIS-era exporter's scene: Camera "world", a RIS projection, RIS materials, lights and
  // options, parameters nobody declared, conditional passes, and a primitive the pass cannot
  // make. The frame comes through; RIS requests are kept; the skipped primitive is counted.
  test::ScratchDir dir;
  const std::string path = dir.path("ris.rib");
  std::ofstream(path) << R"(
Option "user" "string pass" ["beauty"]
Format 64 48 1
Projection "PxrCamera" "float fov" [45]
Hider "raytrace" "int maxsamples" [64]
Integrator "PxrPathTracer" "main" "int maxPathLength" [4]
DisplayFilter "PxrBackgroundDisplayFilter" "bg" "color backgroundColor" [0 0 0]
Translate 0 0 5
Camera "world" "float[2] shutteropening" [0 1]
WorldBegin
  Light "PxrDistantLight" "key" "float intensity" [2]
  Attribute "identifier" "shadinggroup" ["g1"] "name" ["ball"]
  Pattern "PxrTexture" "tex" "string filename" ["wood.tx"]
  Bxdf "PxrDiffuse" "mat" "reference color diffuseColor" ["tex:resultRGB"] "color diffuseColor" [0.8 0.2 0.1]
  Surface "paintedplastic" "mapname" ["grid.tx"] "Kd" [0.7]
  IfBegin "$user:pass == 'beauty'"
    Sphere 1 -1 1 360
  Else
    Cone 1 1 360
  IfEnd
  Blobby 1 [1001 0] [1 0 0 0 0 1 0 0 0 0 1 0 0 0 0 1] [""]
WorldEnd
)";
  const FrameScene got = onlyFrameOf(path);
  EXPECT_EQ(got.options.camera.fovDegrees, 45);
  EXPECT_EQ(got.options.camera.worldToCamera[3][2], 5);  // the transform before Camera "world"
  ASSERT_EQ(got.prims.size(), 1u);
  EXPECT_EQ(got.prims[0].kind, PrimKind::Sphere);  // the beauty branch
  EXPECT_EQ(got.prims[0].attrs->surface.values[0].Kd, double(0.7f));  // RIB numbers are RtFloats
  ASSERT_EQ(got.risNodes.size(), 3u);
  EXPECT_EQ(got.risNodes[0].type, "PxrDistantLight");
  EXPECT_EQ(got.risNodes[0].numbers.at("intensity"), std::vector<double>{2});
  EXPECT_EQ(got.risNodes[1].strings.at("filename"), std::vector<std::string>{"wood.tx"});
  ASSERT_EQ(got.prims[0].attrs->bxdf, 3u);
  EXPECT_EQ(got.risNodes[2].handle, "mat");
  EXPECT_EQ(got.risNodes[2].numbers.at("diffuseColor"), (std::vector<double>{0.8f, 0.2f, 0.1f}));
  ASSERT_EQ(got.options.risOptions.size(), 3u);
  EXPECT_EQ(got.options.risOptions[0].request, "Hider");
  EXPECT_EQ(got.options.risOptions[1].type, "PxrPathTracer");
  EXPECT_EQ(got.skipped, (std::map<std::string, uint64_t>{{"Blobby", 1}}));
  EXPECT_EQ(got.objectNames, std::vector<std::string>{"ball"});
}

TEST(ShadeRib, ObjectInstancesPlaceTheirDefinitionUnderTheCurrentState) {
  // Two primitives retained (one sets its own Color), instanced twice under other transforms
  // and colours; a primitive the pass cannot make inside the definition is counted per instance.
  test::ScratchDir dir;
  const std::string path = dir.path("objects.rib");
  std::ofstream(path) << R"(
ObjectBegin "pair"
  Translate 1 0 0
  Sphere 1 -1 1 360
  AttributeBegin
    Color [0 0 1]
    GeneralPolygon [3] "P" [0 0 0 1 0 0 0 1 0]
  AttributeEnd
  Blobby 1 [1001 0] [1 0 0 0 0 1 0 0 0 0 1 0 0 0 0 1] [""]
ObjectEnd
WorldBegin
  Translate 0 0 5
  Color [1 0 0]
  ObjectInstance "pair"
  Translate 0 2 0
  Color [0 1 0]
  ObjectInstance "pair"
WorldEnd
)";
  const FrameScene got = onlyFrameOf(path);
  ASSERT_EQ(got.prims.size(), 4u);
  const dvec3 origin(0.0);
  auto placed = [&](size_t i) { return dvec3(got.prims[i].xform->at(0) * glm::dvec4(origin, 1.0)); };
  EXPECT_EQ(placed(0), dvec3(1, 0, 5));  // the definition's Translate, then the instance's
  EXPECT_EQ(placed(2), dvec3(1, 2, 5));
  EXPECT_EQ(got.prims[0].kind, PrimKind::Sphere);
  EXPECT_TRUE(got.prims[1].triangle);
  EXPECT_EQ(got.prims[0].attrs->color.values[0], dvec3(1, 0, 0));  // the instance's colour
  EXPECT_EQ(got.prims[2].attrs->color.values[0], dvec3(0, 1, 0));
  EXPECT_EQ(got.prims[1].attrs->color.values[0], dvec3(0, 0, 1));  // set inside the definition
  EXPECT_EQ(got.prims[3].attrs->color.values[0], dvec3(0, 0, 1));
  EXPECT_EQ(got.skipped, (std::map<std::string, uint64_t>{{"Blobby", 2}}));
  auto error = [&](const std::string& text) {
    std::ofstream(path) << text;
    Scene s([](FrameScene&) {});
    try {
      readRibScene(path, s);
    } catch (const Error& e) {
      return std::string(e.what());
    }
    return std::string("no error");
  };
  EXPECT_NE(error("WorldBegin\nObjectInstance 7\nWorldEnd\n").find("objects.rib:2 (ObjectInstance): ObjectInstance of undefined object '7'"), std::string::npos);
  EXPECT_NE(error("ObjectEnd\n").find("ObjectEnd without ObjectBegin"), std::string::npos);
}

TEST(ShadeRib, DelayedArchivesAreReadInPlaceAndProgramsNeverRun) {
  test::ScratchDir dir;
  std::ofstream(dir.path("sub.rib")) << "Color [0 0 1]\nSphere 1 -1 1 360\n";
  const std::string path = dir.path("scene.rib");
  std::ofstream(path) << R"(
WorldBegin
  Translate 0 0 5
  Color [1 0 0]
  Procedural "DelayedReadArchive" ["sub.rib"] [-1 1 -1 1 -1 1]
  Procedural2 "DelayedReadArchive2" "SimpleBound" "string filename" ["sub.rib"] "float[6] bound" [-1 1 -1 1 -1 1]
  Disk 0 1 360
  Procedural "RunProgram" ["rm -rf /tmp/never" ""] [-1 1 -1 1 -1 1]
  Procedural "DynamicLoad" ["plugin.so" ""] [-1 1 -1 1 -1 1]
WorldEnd
)";
  const FrameScene got = onlyFrameOf(path);
  ASSERT_EQ(got.prims.size(), 3u);
  EXPECT_EQ(got.prims[0].kind, PrimKind::Sphere);
  EXPECT_EQ(got.prims[0].attrs->color.values[0], dvec3(0, 0, 1));  // the archive's colour inside it
  EXPECT_EQ(got.prims[2].kind, PrimKind::Disk);
  EXPECT_EQ(got.prims[2].attrs->color.values[0], dvec3(1, 0, 0));  // and not after it
  EXPECT_EQ(got.skipped, (std::map<std::string, uint64_t>{{"Procedural", 2}}));
}

TEST(ShadeRib, DelayedArchivesOutOfViewAreNeverRead) {
  // "missing.rib" does not exist: reading it would be an error, so a scene that reads cleanly
  // proves the archive was culled by its bound. In view, behind the eye, past an edge, and
  // moving across the screen (in view between its knots).
  test::ScratchDir dir;
  std::ofstream(dir.path("sub.rib")) << "Sphere 1 -1 1 360\n";
  auto frame = [&](const std::string& world) {
    const std::string path = dir.path("scene.rib");
    std::ofstream(path) << "Format 320 240 1\nProjection \"perspective\" \"fov\" [40]\nShutter 0 1\nWorldBegin\n" << world << "\nWorldEnd\n";
    return onlyFrameOf(path);
  };
  const std::string missing = "Procedural \"DelayedReadArchive\" [\"missing.rib\"] [-1 1 -1 1 -1 1]\n";
  EXPECT_EQ(frame("Translate 0 0 -5\n" + missing + "Disk 5 1 360").culledArchives, 1u);            // behind the eye
  EXPECT_EQ(frame("Translate 40 0 5\n" + missing + "Disk 5 1 360").culledArchives, 1u);            // far to the right
  EXPECT_EQ(frame("Translate 0 40 5\n" + missing + "Disk 5 1 360").culledArchives, 1u);            // far above
  const FrameScene seen = frame("Translate 0 0 5\nProcedural \"DelayedReadArchive\" [\"sub.rib\"] [-1 1 -1 1 -1 1]");
  EXPECT_EQ(seen.culledArchives, 0u);
  EXPECT_EQ(seen.prims.size(), 1u);
  // Moving from far left to far right: on screen in between, so read (and here: missing).
  EXPECT_THROW(frame("MotionBegin [0 1]\nTranslate -40 0 5\nTranslate 40 0 5\nMotionEnd\n" + missing), Error);
  EXPECT_THROW(frame("Translate 0 0 5\n" + missing), Error);  // in view: read, and missing
}

TEST(ShadeDiceHard, APathologicalPrimitiveStopsAtItsBudget) {
  // Found by the RIB fuzzer: a tooled-steel cube instanced under a transform sheared 8047 times
  // (a number cut by NUL bytes), which seen edge-on wants hundreds of millions of micropolygons
  // (minutes of splitting). Past the budget its remaining pieces are diced a grid each: the
  // work stops within one grid per level of the recursion, and the primitive is counted.
  const std::string path = test::sourceDir() + "/tests/corpus/rib/fuzz_sheared_instance_timeout.rib";
  setVerbosity(Verbosity::Quiet);  // the mutated file's undeclared parameters warn
  const FrameScene f = onlyFrameOf(path);
  setVerbosity(Verbosity::Normal);
  const store::Camera cam = storeMeta(f, {}).cameras[0];
  auto split = [&](uint64_t budget, uint64_t& over) {
    DiceOptions o;
    o.maxMicropolygonsPerPrimitive = budget;
    uint64_t most = 0;
    over = 0;
    for (const Primitive& p : f.prims) {
      std::vector<Leaf> leaves;
      DiceStats stats;
      splitPrimitive(p, clipKnots(p, 0, 0), cam, {}, o, leaves, stats);
      uint64_t mps = 0;
      for (const Leaf& l : leaves) mps += uint64_t(l.nu) * uint64_t(l.nv);
      most = std::max(most, mps);
      over += stats.overBudget;
    }
    return most;
  };
  uint64_t over = 0;
  const uint64_t budget = 1000000, bounded = split(budget, over);  // the other faces need less
  EXPECT_EQ(over, 1u);
  EXPECT_GT(bounded, budget);
  EXPECT_LE(bounded, budget + 16 * 16 * uint64_t(DiceOptions{}.maxSplitDepth + 2));
  // Four times the budget is reached too: the primitive really wants more.
  EXPECT_GT(split(4 * budget, over), 4 * budget);
  EXPECT_EQ(over, 1u);

  // Found next: a mutated CSG scene whose splitting culls nearly every piece it makes (it ran
  // past the fuzzer's 30 s on a small camera). Pieces visited are bounded by a quarter of the
  // budget, plus the pieces pending on the recursion.
  setVerbosity(Verbosity::Quiet);
  const FrameScene g = onlyFrameOf(test::sourceDir() + "/tests/corpus/rib/fuzz_culled_slivers_timeout.rib");
  setVerbosity(Verbosity::Normal);
  store::Camera small = storeMeta(g, {}).cameras[0];
  small.width = 48, small.height = 36;
  DiceOptions o;
  o.maxMicropolygonsPerPrimitive = 20000;
  uint64_t most = 0;
  for (const Primitive& p : g.prims) {
    std::vector<Leaf> leaves;
    DiceStats stats;
    splitPrimitive(p, clipKnots(p, 0, 0), small, {}, o, leaves, stats);
    most = std::max(most, stats.leaves + stats.culledPieces + stats.eyeSplits);
  }
  EXPECT_LE(most, 20000 / 4 + 2 * uint64_t(o.maxSplitDepth + 2));
}

TEST(ShadeRib, BadInputNamesFileAndLine) {
  test::ScratchDir dir;
  const std::string path = dir.path("bad.rib");
  std::ofstream(path) << "WorldBegin\nMotionBegin [0 1]\nTranslate 1 0 0\nMotionEnd\nWorldEnd\n";
  Scene scene([](FrameScene&) {});
  try {
    readRibScene(path, scene);
    FAIL() << "expected an error";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("bad.rib:4"), std::string::npos) << e.what();
  }
}

// MovingCasters promises to be conservative: false only when no caster can shadow any point of
// the receiver's box from the light. Brute force: random casters, receivers and lights (a point
// light, a square area light, a sharp and a soft distant light); wherever some segment from a
// point of the receiver to a point of the emitter (or a ray along a direction of the distant
// light's cone) passes through a caster's box, mayShadow must say so. And it must cull: many
// receivers far from every caster's shadow come back false.
TEST(ShadeShadows, MovingCastersNeverMissACasterBetweenAReceiverAndItsLight) {
  std::mt19937 rng(20261127);
  auto uniform = [&](double lo, double hi) { return std::uniform_real_distribution<double>(lo, hi)(rng); };
  auto randomBox = [&](double spread, double size) {
    ShadowBox b;
    const glm::dvec3 c(uniform(-spread, spread), uniform(-spread, spread), uniform(-spread, spread));
    const glm::dvec3 h(uniform(0.05, size), uniform(0.05, size), uniform(0.05, size));
    b.lo = c - h, b.hi = c + h;
    return b;
  };
  // Whether the segment from `a` along `d` for s in [0, sMax] meets `box` (slabs).
  auto meets = [](const glm::dvec3& a, const glm::dvec3& d, double sMax, const ShadowBox& box) {
    double s0 = 0, s1 = sMax;
    for (int k = 0; k < 3; ++k) {
      if (std::abs(d[k]) < 1e-300) {
        if (a[k] < box.lo[k] || a[k] > box.hi[k]) return false;
        continue;
      }
      double t0 = (box.lo[k] - a[k]) / d[k], t1 = (box.hi[k] - a[k]) / d[k];
      if (t0 > t1) std::swap(t0, t1);
      s0 = std::max(s0, t0), s1 = std::min(s1, t1);
      if (s0 > s1) return false;
    }
    return true;
  };
  std::vector<LitLight> lights(4);
  lights[0].kind = LightKind::Point, lights[0].position = {0, 6, 0}, lights[0].shadows = true;
  lights[1].kind = LightKind::Point, lights[1].shape = LightShape::Rect, lights[1].position = {3, 5, -2}, lights[1].halfU = {0.8, 0, 0},
  lights[1].halfV = {0, 0, 0.8}, lights[1].shadows = true;
  lights[2].kind = LightKind::Distant, lights[2].axis = glm::normalize(glm::dvec3(0.3, -1, 0.2)), lights[2].shadows = true;
  lights[3].kind = LightKind::Distant, lights[3].axis = glm::normalize(glm::dvec3(-0.4, -1, 0.1)), lights[3].tanHalfAngle = 0.1, lights[3].shadows = true;
  int shadowed = 0, culled = 0;
  for (int scene = 0; scene < 24; ++scene) {
    std::vector<ShadowBox> casters;
    for (int i = 0; i < 3; ++i) casters.push_back(randomBox(3, 0.8));
    const MovingCasters moving(lights, casters);
    for (int r = 0; r < 60; ++r) {
      const ShadowBox receiver = randomBox(4, 0.6);
      for (size_t li = 0; li < lights.size(); ++li) {
        const LitLight& l = lights[li];
        const bool may = moving.mayShadow(li, receiver);
        bool found = false;
        for (int k = 0; k < 48 && !found; ++k) {
          // A point of the receiver's box: its corners first, then inside.
          const glm::dvec3 p = k < 8 ? glm::dvec3(k & 1 ? receiver.hi.x : receiver.lo.x, k & 2 ? receiver.hi.y : receiver.lo.y, k & 4 ? receiver.hi.z : receiver.lo.z)
                                     : glm::dvec3(uniform(receiver.lo.x, receiver.hi.x), uniform(receiver.lo.y, receiver.hi.y), uniform(receiver.lo.z, receiver.hi.z));
          for (int e = 0; e < 8 && !found; ++e) {
            glm::dvec3 d;
            double sMax = 1;
            if (l.kind == LightKind::Distant) {
              glm::dvec3 dir = -l.axis;
              if (l.tanHalfAngle > 0) {
                const glm::dvec3 e1 = glm::normalize(glm::cross(dir, glm::dvec3(0, 0, 1))), e2 = glm::cross(dir, e1);
                double x, y;
                do x = uniform(-1, 1), y = uniform(-1, 1);
                while (x * x + y * y > 1);
                dir = glm::normalize(dir + l.tanHalfAngle * (x * e1 + y * e2));
              }
              d = dir, sMax = 1e6;
            } else {
              d = l.position + uniform(-1, 1) * l.halfU + uniform(-1, 1) * l.halfV - p;
            }
            for (const ShadowBox& c : casters) found |= meets(p, d, sMax, c);
          }
        }
        if (found) {
          ++shadowed;
          EXPECT_TRUE(may) << "scene " << scene << ", receiver " << r << ", light " << li << ": a caster lies between them";
        }
        culled += !may;
      }
    }
  }
  // Not vacuous: both kinds occur often.
  EXPECT_GT(shadowed, 500);
  EXPECT_GT(culled, 500);
}

// Shading in time traces rays at the shading times through the rigid casters instanced with
// their transforms fixed at those times (ShadowScene's fixAt), and at any other time through the
// motion-blurred instances. A ray must be blocked exactly where the casters stand at its time: a
// square moving rigidly over three uneven knots (turning and sliding), and a square deforming
// (its top edge rising), against the analytic intersection at the ray's time. Rays within a hair
// of an edge are left out (ties). Embree's motion blur steps evenly, so uneven knots are
// resampled onto 6 steps (t = 0, 0.2, ... 1) and its instances are exact only at those: the
// other times checked are steps, and at t = 0.25, between the steps either side of the knot at
// 0.3, a scene without fixed times must miss the truth somewhere - which shows that the fixed
// instances were the ones traced.
TEST(ShadeShadows, CastersFixedAtShadingTimesBlockWhereTheyStandThen) {
  using glm::dvec3;
  ShadowScene::Piece rigid, deforming, still;
  // A still rectangle at z = 3, x in [-3, -1.5], y in [-3, 5]: ShadowScene::occluded() traces it with the others.
  still.P = {{-3, -3, 3}, {-1.5, -3, 3}, {-1.5, 5, 3}, {-3, 5, 3}};
  still.corners = {0, 1, 2, 3};
  rigid.P = {{-1, -1, 5}, {1, -1, 5}, {1, 1, 5}, {-1, 1, 5}};
  rigid.corners = {0, 1, 2, 3};
  rigid.rigid = 0;
  // x in [6, 8] at z = 7; y from -1 to 1 at the open, to 3 at the close.
  deforming.P = {{6, -1, 7}, {8, -1, 7}, {8, 1, 7}, {6, 1, 7}, {6, -1, 7}, {8, -1, 7}, {8, 3, 7}, {6, 3, 7}};
  deforming.corners = {0, 1, 2, 3};
  deforming.knots = {0, 1};
  auto placed = [](double dx, double dy, double degrees) {
    return glm::translate(glm::dmat4(1.0), dvec3(dx, dy, 0)) * glm::rotate(glm::dmat4(1.0), glm::radians(degrees), dvec3(0, 0, 1));
  };
  const std::vector<ShadowScene::RigidMotion> motions{ShadowScene::RigidMotion({0, 0.3, 1}, {glm::dmat4(1.0), placed(1, 0.5, 30), placed(3, 0, 80)})};
  const std::vector<ShadowScene::Piece> pieces{rigid, deforming, still};
  const std::vector<double> shadingTimes{0, 0.25, 1};
  const ShadowScene scene(pieces, 0, 1, motions, shadingTimes);
  EXPECT_EQ(scene.fixedInstants(), 3u);  // a count of shutter instants
  EXPECT_EQ(scene.rigidInstances(), 1u);
  // Without rigid motions there is nothing to fix.
  EXPECT_EQ(ShadowScene(std::vector<ShadowScene::Piece>{deforming}, 0, 1, {}, shadingTimes).fixedInstants(), 0u);
  const ShadowScene blurredOnly(pieces, 0, 1, motions);
  EXPECT_EQ(blurredOnly.fixedInstants(), 0u);

  std::mt19937 rng(20261128);
  auto uniform = [&](double lo, double hi) { return std::uniform_real_distribution<double>(lo, hi)(rng); };
  constexpr double kTie = 1e-3;
  for (double t : {0.0, 0.25, 1.0, 0.2, 0.8}) {
    const glm::dmat4 toSquare = glm::inverse(motions[0].at(t));
    int hitsRigid = 0, hitsDeforming = 0, hitsStill = 0, misses = 0, blurredWrong = 0, blurredWholeWrong = 0;
    for (int i = 0; i < 4000; ++i) {
      const dvec3 origin(uniform(-3, 10), uniform(-3, 5), 0), target(uniform(-3, 10), uniform(-3, 5), 10);
      const dvec3 dir = glm::normalize(target - origin);
      // Where the ray crosses each square's plane, and how far inside (> 0) or outside (< 0) the
      // square that point lies.
      const dvec3 atRigid = origin + (5 / dir.z) * dir, atDeforming = origin + (7 / dir.z) * dir, atStill = origin + (3 / dir.z) * dir;
      const double insideStill = std::min({atStill.x + 3, -1.5 - atStill.x, atStill.y + 3, 5 - atStill.y});
      const glm::dvec4 local = toSquare * glm::dvec4(atRigid, 1);
      const double insideRigid = 1 - std::max(std::abs(local.x), std::abs(local.y));
      const double top = 1 + 2 * t;
      const double insideDeforming = std::min({atDeforming.x - 6, 8 - atDeforming.x, atDeforming.y + 1, top - atDeforming.y});
      if (std::abs(insideRigid) < kTie || std::abs(insideDeforming) < kTie || std::abs(insideStill) < kTie) continue;
      const bool blocked = insideRigid > 0 || insideDeforming > 0;
      ASSERT_EQ(scene.occludedByMoving(origin, dir, INFINITY, t), blocked) << "t=" << t << " ray " << i;
      ASSERT_EQ(scene.occludedByStill(origin, dir, INFINITY), insideStill > 0) << "ray " << i;
      // Everything in one traversal at a shading time (still, fixed and deforming together).
      ASSERT_EQ(scene.occluded(origin, dir, INFINITY, t), blocked || insideStill > 0) << "t=" << t << " ray " << i;
      hitsRigid += insideRigid > 0, hitsDeforming += insideDeforming > 0, hitsStill += insideStill > 0, misses += !blocked && !(insideStill > 0);
      blurredWrong += blurredOnly.occludedByMoving(origin, dir, INFINITY, t) != blocked;
      blurredWholeWrong += blurredOnly.occluded(origin, dir, INFINITY, t) != (blocked || insideStill > 0);
    }
    if (t == 0.25) {
      EXPECT_GT(blurredWrong, 10) << "between Embree's steps its blend of matrices is off the knots'";
      EXPECT_GT(blurredWholeWrong, 10);
    } else {
      EXPECT_EQ(blurredWrong, 0) << "t=" << t << " is one of Embree's steps";
      EXPECT_EQ(blurredWholeWrong, 0) << "t=" << t;
    }
    EXPECT_GT(hitsStill, 100) << "t=" << t;
    // Both casters were hit and missed at this time.
    EXPECT_GT(hitsRigid, 100) << "t=" << t;
    EXPECT_GT(hitsDeforming, 100) << "t=" << t;
    EXPECT_GT(misses, 800) << "t=" << t;
  }
}

}  // namespace
}  // namespace reshutter::shade
