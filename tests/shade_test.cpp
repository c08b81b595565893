// Tests of the shading pass: dicing (area vs shading rate, shared vertices, the eye plane),
// shaders and lights against the RenderMan formulas written out independently here, motion
// (transform knots, deformation, camera motion, animated colour), flags, output variables,
// determinism and the demo scene. The RIB scenes are tests/shade_rib_test.cpp; the shadow scene
// tests/shadow_scene_test.cpp.
#include <algorithm>
#include <cmath>
#include <map>
#include <set>

#include <gtest/gtest.h>
#include <tbb/global_control.h>
#include <glm/geometric.hpp>
#include <glm/gtc/matrix_transform.hpp>

#include "common/error.h"
#include "common/log.h"
#include "shade/demo_scene.h"
#include "shade/scene.h"
#include "shade/shading_pass.h"
#include "store/reader.h"
#include "tests/shade_test_util.h"
#include "tests/test_util.h"

namespace reshutter::shade {
namespace {

using glm::dvec3;
using namespace testing;


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

}  // namespace
}  // namespace reshutter::shade
