// Production primitives against independent truths: bicubic patches against de Casteljau and the
// textbook basis functions, shared mesh edges bit for bit, patch-mesh silhouettes against their
// exact coverage pixel by pixel.
#include <cmath>
#include <fstream>
#include <random>

#include <gtest/gtest.h>

#include "common/error.h"
#include "shade/dice.h"
#include "shade/rib_scene.h"
#include "shade/scene.h"
#include "shade/shading_pass.h"
#include "shade/trim.h"
#include "tests/exr_test_util.h"
#include "tests/primitives_test_util.h"
#include "tests/test_util.h"

namespace reshutter::shade {
namespace {

using glm::dvec3;
using namespace testing;

TEST(PrimBicubic, BezierPatchIsDeCasteljau) {
  const auto cv = randomPoints(16, 7);
  const auto prims = primsOf([&](Scene& s) { s.patchMesh(true, 4, false, 4, false, cv); });
  ASSERT_EQ(prims.size(), 1u);
  ASSERT_EQ(prims[0].kind, PrimKind::Bicubic);
  for (double u : {0.0, 0.13, 0.5, 0.77, 1.0})
    for (double v : {0.0, 0.31, 0.6, 1.0}) {
      const dvec3 got = evalP(prims[0], prims[0].keys[0], u, v), want = deCasteljau(cv, u, v);
      EXPECT_LT(glm::length(got - want), 1e-12) << u << " " << v;
    }
  // The normal is along dP/du x dP/dv, by central differences of de Casteljau.
  const double h = 1e-6, u = 0.4, v = 0.7;
  const dvec3 du = (deCasteljau(cv, u + h, v) - deCasteljau(cv, u - h, v)) / (2 * h);
  const dvec3 dv = (deCasteljau(cv, u, v + h) - deCasteljau(cv, u, v - h)) / (2 * h);
  const dvec3 n = glm::normalize(evalNg(prims[0], prims[0].keys[0], u, v));
  EXPECT_GT(glm::dot(n, glm::normalize(glm::cross(du, dv))), 1 - 1e-8);
}

TEST(PrimBicubic, EveryBasisIsItsTextbookDefinition) {
  // Uniform cubic B-spline, Catmull-Rom, Hermite (P0 T0 P1 T1) and power basis functions as
  // written in the literature, against the mesh's evaluation.
  using Fn = std::function<std::array<double, 4>(double)>;
  const std::vector<std::pair<std::string, Fn>> bases = {
      {"b-spline",
       [](double t) {
         return std::array<double, 4>{std::pow(1 - t, 3) / 6, (3 * t * t * t - 6 * t * t + 4) / 6, (-3 * t * t * t + 3 * t * t + 3 * t + 1) / 6, t * t * t / 6};
       }},
      {"catmull-rom",
       [](double t) {
         return std::array<double, 4>{0.5 * (-t * t * t + 2 * t * t - t), 0.5 * (3 * t * t * t - 5 * t * t + 2), 0.5 * (-3 * t * t * t + 4 * t * t + t),
                                      0.5 * (t * t * t - t * t)};
       }},
      {"hermite",
       [](double t) {
         return std::array<double, 4>{2 * t * t * t - 3 * t * t + 1, t * t * t - 2 * t * t + t, -2 * t * t * t + 3 * t * t, t * t * t - t * t};
       }},
      {"power",
       [](double t) {
         return std::array<double, 4>{t * t * t, t * t, t, 1};
       }},
  };
  for (const auto& [name, fn] : bases) {
    CubicBasis b;
    ASSERT_TRUE(CubicBasis::named(name, b)) << name;
    const auto cv = randomPoints(16, 11);
    const auto prims = primsOf([&](Scene& s) {
      s.basis(b, b);
      s.patchMesh(true, 4, false, 4, false, cv);
    });
    ASSERT_EQ(prims.size(), 1u) << name;
    for (double u : {0.0, 0.25, 0.6, 1.0})
      for (double v : {0.0, 0.45, 1.0}) {
        const auto wu = fn(u), wv = fn(v);
        dvec3 want(0.0);
        for (size_t l = 0; l < 4; ++l)
          for (size_t k = 0; k < 4; ++k) want += wu[k] * wv[l] * cv[l * 4 + k];
        EXPECT_LT(glm::length(evalP(prims[0], prims[0].keys[0], u, v) - want), 1e-12) << name << " " << u << " " << v;
      }
  }
}

TEST(PrimBicubic, MeshPatchesShareTheirEdgesBitForBit) {
  // Neighbouring patches of a B-spline and a Catmull-Rom mesh (windows overlapping by three
  // control points) and of a bezier mesh (sharing one) evaluate identical points on their shared
  // edges: no crack can open between their grids there.
  for (const std::string name : {"b-spline", "catmull-rom", "bezier"}) {
    CubicBasis b;
    ASSERT_TRUE(CubicBasis::named(name, b));
    const int n = name == "bezier" ? 7 : 6;
    const auto cv = randomPoints(size_t(n * n), 3);
    const auto prims = primsOf([&](Scene& s) {
      s.basis(b, b);
      s.patchMesh(true, n, false, n, false, cv);
    });
    const int np = name == "bezier" ? 2 : 3;
    ASSERT_EQ(prims.size(), size_t(np * np)) << name;
    for (int pv = 0; pv < np; ++pv)
      for (int pu = 0; pu + 1 < np; ++pu) {
        const Primitive& a = prims[size_t(pv * np + pu)];
        const Primitive& c = prims[size_t(pv * np + pu + 1)];
        const Primitive& below = prims[size_t(pu * np + pv)];
        const Primitive& above = prims[size_t((pu + 1) * np + pv)];
        for (double t : {0.0, 0.1, 0.37, 0.5, 0.9, 1.0}) {
          EXPECT_EQ(evalP(a, a.keys[0], 1.0, t), evalP(c, c.keys[0], 0.0, t)) << name;
          EXPECT_EQ(evalP(below, below.keys[0], t, 1.0), evalP(above, above.keys[0], t, 0.0)) << name;
        }
      }
  }
}

TEST(PrimBicubic, PeriodicMeshesWrapAndBadCountsAreErrors) {
  CubicBasis bspline;
  ASSERT_TRUE(CubicBasis::named("b-spline", bspline));
  const auto cv = randomPoints(8 * 5, 5);
  const auto prims = primsOf([&](Scene& s) {
    s.basis(bspline, bspline);
    s.patchMesh(true, 8, true, 5, false, cv);  // 8 patches around, 2 along v
  });
  ASSERT_EQ(prims.size(), 16u);
  EXPECT_EQ(evalP(prims[7], prims[7].keys[0], 1.0, 0.3), evalP(prims[0], prims[0].keys[0], 0.0, 0.3));  // closes on itself
  EXPECT_NE(buildError([&](Scene& s) { s.patchMesh(true, 5, false, 4, false, randomPoints(20, 1)); }).find("nu = 5 does not make whole bicubic patches"),
            std::string::npos);
  EXPECT_NE(buildError([&](Scene& s) { s.patchMesh(true, 4, false, 4, false, randomPoints(15, 1)); }).find("needs 16 control points, has 15"),
            std::string::npos);
  CubicBasis bad;
  bad.step = 0;
  EXPECT_NE(buildError([&](Scene& s) { s.basis(bad, bad); }).find("step 0"), std::string::npos);
}

// ---------------------------------------------------------------------------------------------
// Subdivision surfaces (OpenSubdiv)

// A regular n x n grid of points with random heights, as quads (u fastest).
struct GridMesh {
  std::vector<int> nverts, verts;
  std::vector<dvec3> P;
};
GridMesh gridMesh(int n, uint32_t seed) {
  GridMesh m;
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> h(-0.5, 0.5);
  for (int j = 0; j < n; ++j)
    for (int i = 0; i < n; ++i) m.P.emplace_back(i, j, h(rng));
  for (int j = 0; j + 1 < n; ++j)
    for (int i = 0; i + 1 < n; ++i) {
      m.nverts.push_back(4);
      for (int v : {j * n + i, j * n + i + 1, (j + 1) * n + i + 1, (j + 1) * n + i}) m.verts.push_back(v);
    }
  return m;
}

TEST(PrimSubdiv, RegularFacesAreUniformBSplinePatchesAndBoundariesFollowTheTag) {
  // Away from extraordinary vertices and boundaries, Catmull-Clark's limit surface is the
  // uniform bicubic B-spline of the face's 4 x 4 neighbourhood.
  const int n = 6;
  const GridMesh m = gridMesh(n, 9);
  CubicBasis bspline;
  ASSERT_TRUE(CubicBasis::named("b-spline", bspline));
  for (int boundary : {0, 1, 2}) {
    SubdivTags tags;
    tags.interpolateBoundary = boundary;
    const auto prims = primsOf([&](Scene& s) { s.subdivisionMesh(SubdivScheme::CatmullClark, m.nverts, m.verts, tags, m.P); });
    // Without the tag only the faces clear of the boundary have a surface (RenderMan and
    // OpenSubdiv agree); with it, every face.
    ASSERT_EQ(prims.size(), boundary ? 25u : 9u) << boundary;
    const Primitive* centre = nullptr;
    for (const auto& p : prims)
      if (p.ptexFace == 12) centre = &p;
    ASSERT_NE(centre, nullptr);
    std::vector<dvec3> window;
    for (int l = 0; l < 4; ++l)
      for (int k = 0; k < 4; ++k) window.push_back(m.P[size_t((1 + l) * n + 1 + k)]);
    for (double u : {0.0, 0.3, 0.5, 1.0})
      for (double v : {0.0, 0.7, 1.0}) {
        double wu[4], wv[4];
        bspline.weights(u, wu), bspline.weights(v, wv);
        dvec3 want(0.0);
        for (size_t l = 0; l < 4; ++l)
          for (size_t k = 0; k < 4; ++k) want += wu[k] * wv[l] * window[l * 4 + k];
        EXPECT_LT(glm::length(evalP(*centre, centre->keys[0], u, v) - want), 1e-9) << u << " " << v;
      }
  }
}

TEST(PrimSubdiv, SharpCornersCreasesHolesAndKeys) {
  // A cube: an infinitely sharp corner's limit point is the vertex itself; a hole removes its
  // face's ptex face; a motion block makes one surface with a key per copy, evaluated linearly
  // between them.
  const std::vector<int> nverts(6, 4);
  const std::vector<int> verts = {0, 1, 3, 2, 2, 3, 5, 4, 4, 5, 7, 6, 6, 7, 1, 0, 1, 7, 5, 3, 6, 0, 2, 4};
  const std::vector<dvec3> P = {{-1, -1, 1}, {1, -1, 1}, {-1, 1, 1}, {1, 1, 1}, {-1, 1, -1}, {1, 1, -1}, {-1, -1, -1}, {1, -1, -1}};
  SubdivTags smooth, sharp, holed;
  sharp.corners = {{0, 10.0}};
  holed.holes = {2};
  auto limitOfVertex0 = [&](const std::vector<Primitive>& prims) {
    for (const auto& p : prims)
      if (p.ptexFace == 0) return evalP(p, p.keys[0], 0, 0);  // face 0's first corner is vertex 0
    return dvec3(NAN);
  };
  const auto soft = primsOf([&](Scene& s) { s.subdivisionMesh(SubdivScheme::CatmullClark, nverts, verts, smooth, P); });
  const auto hard = primsOf([&](Scene& s) { s.subdivisionMesh(SubdivScheme::CatmullClark, nverts, verts, sharp, P); });
  ASSERT_EQ(soft.size(), 6u);
  EXPECT_GT(glm::length(limitOfVertex0(soft) - P[0]), 0.3);  // smooth: pulled far inside
  EXPECT_LT(glm::length(limitOfVertex0(hard) - P[0]), 1e-9);
  // The smooth cube's corner limit, by the Catmull-Clark limit rule for valence 3:
  // (n^2 v + 4 sum(edge neighbours) + sum(face-opposite vertices)) / (n (n + 5)).
  const dvec3 want = (9.0 * P[0] + 4.0 * (P[1] + P[2] + P[6]) + (P[3] + P[4] + P[7])) / 24.0;
  EXPECT_LT(glm::length(limitOfVertex0(soft) - want), 1e-9);
  EXPECT_EQ(primsOf([&](Scene& s) { s.subdivisionMesh(SubdivScheme::CatmullClark, nverts, verts, holed, P); }).size(), 5u);

  std::vector<dvec3> moved = P;
  for (auto& p : moved) p += dvec3(2, 0, 0);
  const auto keyed = primsOf([&](Scene& s) {
    s.motionBegin({0, 1});
    s.subdivisionMesh(SubdivScheme::CatmullClark, nverts, verts, smooth, P);
    s.subdivisionMesh(SubdivScheme::CatmullClark, nverts, verts, smooth, moved);
    s.motionEnd();
  });
  ASSERT_EQ(keyed.size(), 6u);
  ASSERT_EQ(keyed[0].keys.size(), 2u);
  EXPECT_EQ(keyed[0].subdiv->numKeys(), 2u);
  const dvec3 a = evalP(keyed[0], keyed[0].shapeAt(0), 0.3, 0.6), b = evalP(keyed[0], keyed[0].shapeAt(1), 0.3, 0.6);
  EXPECT_LT(glm::length(b - a - dvec3(2, 0, 0)), 1e-9);
  EXPECT_LT(glm::length(evalP(keyed[0], keyed[0].shapeAt(0.25), 0.3, 0.6) - (a + dvec3(0.5, 0, 0))), 1e-9);
}

TEST(PrimSubdiv, LoopMeshesAreTrianglesAndBadMeshesAreOneLineErrors) {
  // An octahedron under Loop: eight triangular faces, each a collapsed-row primitive whose
  // apex row evaluates to one point.
  const std::vector<int> nverts(8, 3);
  const std::vector<int> verts = {0, 1, 2, 0, 2, 3, 0, 3, 4, 0, 4, 1, 5, 2, 1, 5, 3, 2, 5, 4, 3, 5, 1, 4};
  const std::vector<dvec3> P = {{0, 0, 1}, {1, 0, 0}, {0, 1, 0}, {-1, 0, 0}, {0, -1, 0}, {0, 0, -1}};
  const auto prims = primsOf([&](Scene& s) { s.subdivisionMesh(SubdivScheme::Loop, nverts, verts, {}, P); });
  ASSERT_EQ(prims.size(), 8u);
  for (const auto& p : prims) {
    EXPECT_TRUE(p.triangle);
    EXPECT_EQ(evalP(p, p.keys[0], 0.0, 1.0), evalP(p, p.keys[0], 1.0, 1.0));
    const dvec3 c = evalP(p, p.keys[0], 0.3, 0.3);
    EXPECT_GT(glm::length(c), 0.4);  // on the smooth limit, inside the octahedron's hull
    EXPECT_LT(glm::length(c), 1.0);
    EXPECT_GT(glm::dot(glm::normalize(evalNg(p, p.keys[0], 0.3, 0.3)), glm::normalize(c)), 0.5);  // outward
  }
  EXPECT_NE(buildError([&](Scene& s) {
              s.subdivisionMesh(SubdivScheme::Loop, {4}, {0, 1, 2, 3}, {}, P);
            }).find("a loop mesh is made of triangles"),
            std::string::npos);
  EXPECT_NE(buildError([&](Scene& s) {
              s.subdivisionMesh(SubdivScheme::CatmullClark, {3}, {0, 1, 9}, {}, P);
            }).find("vertex index 9 out of range"),
            std::string::npos);
  EXPECT_NE(buildError([&](Scene& s) { s.subdivisionMesh(SubdivScheme::CatmullClark, {4}, {0, 1, 2}, {}, P); }).find("add up to 4"), std::string::npos);
  SubdivTags badHole;
  badHole.holes = {3};
  EXPECT_NE(buildError([&](Scene& s) {
              s.subdivisionMesh(SubdivScheme::CatmullClark, {3}, {0, 1, 2}, badHole, P);
            }).find("hole face 3 out of range"),
            std::string::npos);
}

// ---------------------------------------------------------------------------------------------
// The other quadrics

TEST(PrimQuadric, HyperboloidAndParaboloidAreTheirDefinitions) {
  const auto prims = primsOf([&](Scene& s) {
    s.hyperboloid(dvec3(1, 0, -1), dvec3(0, 1, 1), 360);
    s.hyperboloid(dvec3(0.7, 0, -0.5), dvec3(0.7, 0, 0.5), 270);
    s.cylinder(0.7, -0.5, 0.5, 270);
    s.paraboloid(2, 0.5, 3, 300);
  });
  ASSERT_EQ(prims.size(), 4u);
  // The line from point1 to point2 swept about z.
  const dvec3 h = evalP(prims[0], prims[0].keys[0], 0.25, 0.5);  // the line's midpoint turned 90 degrees
  EXPECT_LT(glm::length(h - dvec3(-0.5, 0.5, 0.0)), 1e-12);
  // A hyperboloid of a vertical line is the cylinder: same points, same normals.
  for (double u : {0.0, 0.4, 1.0})
    for (double v : {0.0, 0.6, 1.0}) {
      EXPECT_LT(glm::length(evalP(prims[1], prims[1].keys[0], u, v) - evalP(prims[2], prims[2].keys[0], u, v)), 1e-12);
      EXPECT_GT(glm::dot(glm::normalize(evalNg(prims[1], prims[1].keys[0], u, v)), glm::normalize(evalNg(prims[2], prims[2].keys[0], u, v))), 1 - 1e-12);
    }
  // z = zmax (r / rmax)^2, with the normal along the outward gradient (x, y, -rmax^2 / (2 zmax)).
  for (double u : {0.1, 0.5, 0.9})
    for (double v : {0.0, 0.5, 1.0}) {
      const dvec3 p = evalP(prims[3], prims[3].keys[0], u, v);
      EXPECT_NEAR(p.z, 3 * (p.x * p.x + p.y * p.y) / 4, 1e-12);
      EXPECT_NEAR(std::atan2(p.y, p.x), (u * 300 > 180 ? u * 300 - 360 : u * 300) * M_PI / 180, 1e-9);
      const dvec3 g = glm::normalize(dvec3(p.x, p.y, -4.0 / (2 * 3)));
      EXPECT_GT(glm::dot(glm::normalize(evalNg(prims[3], prims[3].keys[0], u, v)), g), 1 - 1e-9);
    }
}

// The primitives of a RIB world block (read through the RIB reader and its scene handler).
std::vector<Primitive> ribPrims(const std::string& world) {
  test::ScratchDir dir;
  std::ofstream(dir.path("s.rib")) << "WorldBegin\n" << world << "\nWorldEnd\n";
  std::vector<Primitive> out;
  Scene scene([&](FrameScene& f) { out = std::move(f.prims); });
  readRibScene(dir.path("s.rib"), scene);
  return out;
}

// The message of the Error a RIB world block throws ("no error" when it reads cleanly).
std::string ribError(const std::string& world) {
  try {
    ribPrims(world);
  } catch (const Error& e) {
    return std::string(e.what());
  }
  return std::string("no error");
}

TEST(PrimPatch, HeightFieldsStandOnTheParametricGrid) {
  // "Pz": RenderMan's height field, x and y the mesh's parameters, z given. A bilinear patch is
  // then (u, v, bilinear z); a bicubic b-spline mesh over a 5 x 5 grid reproduces the plane z =
  // 2x - y + 1 exactly (b-splines reproduce linear functions), over its inner knots.
  {
    const auto prims = ribPrims("Patch \"bilinear\" \"Pz\" [1 2 3 5]");
    ASSERT_EQ(prims.size(), 1u);
    for (double u : {0.0, 0.3, 1.0})
      for (double v : {0.0, 0.6, 1.0}) {
        const dvec3 p = evalP(prims[0], prims[0].keys[0], u, v);
        EXPECT_NEAR(glm::length(p - dvec3(u, v, (1 - u) * (1 - v) * 1 + u * (1 - v) * 2 + (1 - u) * v * 3 + u * v * 5)), 0, 1e-12);
      }
  }
  std::string z;
  for (int j = 0; j < 5; ++j)
    for (int i = 0; i < 5; ++i) z += cat(2.0 * i / 4 - j / 4.0 + 1, " ");  // exact in decimal
  const auto mesh = ribPrims("Basis \"b-spline\" 1 \"b-spline\" 1\nPatchMesh \"bicubic\" 5 \"nonperiodic\" 5 \"nonperiodic\" \"Pz\" [" + z + "]");
  ASSERT_EQ(mesh.size(), 4u);  // 2 x 2 patches
  for (const Primitive& p : mesh)
    for (double u : {0.0, 0.5, 1.0})
      for (double v : {0.0, 0.25, 1.0}) {
        const dvec3 q = evalP(p, p.keys[0], u, v);
        EXPECT_GE(q.x, 0.25 - 1e-12);
        EXPECT_LE(q.x, 0.75 + 1e-12);
        EXPECT_NEAR(q.z, 2 * q.x - q.y + 1, 1e-12);
      }
  // Wrong counts and requests that have no parametric grid are one-line errors.
  for (const std::string bad :
       {"Patch \"bilinear\" \"Pz\" [1 2 3]", "PatchMesh \"bilinear\" 3 \"nonperiodic\" 2 \"nonperiodic\" \"Pz\" [1 2 3 4 5]", "Polygon \"Pz\" [1 2 3]"}) {
    const std::string e = ribError(bad);
    EXPECT_NE(e.find("Pz"), std::string::npos) << bad << ": " << e;
    EXPECT_EQ(e.find('\n'), std::string::npos) << e;
  }
}

// A circle as RenderMan writes it: a rational quadratic NURBS of nine points (weights 1 and
// √2/2 at the corners of the square around it), exactly round.
struct TrimCircle {
  std::vector<int> ncurves{1}, order{3}, n{9};
  std::vector<double> knot{0, 0, 0, 0.25, 0.25, 0.5, 0.5, 0.75, 0.75, 1, 1, 1}, min{0}, max{1}, u, v, w;
  TrimCircle(double cu, double cv, double r) {
    const double s = std::sqrt(0.5);
    const double x[9] = {1, 1, 0, -1, -1, -1, 0, 1, 1}, y[9] = {0, 1, 1, 1, 0, -1, -1, -1, 0};
    for (int i = 0; i < 9; ++i) u.push_back(cu + r * x[i]), v.push_back(cv + r * y[i]), w.push_back(i % 2 ? s : 1);
  }
  std::string rib() const {
    std::string out = "TrimCurve [1] [3] [0 0 0 0.25 0.25 0.5 0.5 0.75 0.75 1 1 1] [0] [1] [9] [";
    for (double x : u) out += cat(x, " ");
    out += "] [";
    for (double x : v) out += cat(x, " ");
    out += "] [";
    for (double x : w) out += cat(x, " ");
    return out + "]";
  }
};

TEST(PrimTrim, LoopsAreTheirCurvesAndTheOddRuleHolds) {
  // The flattened circle lies on the circle; a square of four linear curves is that square.
  const TrimCircle c(0.5, 0.4, 0.3);
  const TrimLoops circle(c.ncurves, c.order, c.knot, c.min, c.max, c.n, c.u, c.v, c.w);
  ASSERT_EQ(circle.loops().size(), 1u);
  EXPECT_GT(circle.loops()[0].size(), 100u);
  for (const auto& p : circle.loops()[0]) EXPECT_NEAR(std::hypot(p.x - 0.5, p.y - 0.4), 0.3, 1e-12);
  EXPECT_TRUE(circle.encloses(0.5, 0.4));
  EXPECT_TRUE(circle.encloses(0.5 + 0.29, 0.4));
  EXPECT_FALSE(circle.encloses(0.5 + 0.31, 0.4));
  EXPECT_FALSE(circle.encloses(0.75, 0.65));  // inside the control square, outside the circle
  // Two loops: a square with the circle inside it; the odd rule makes the ring between them inside.
  const TrimLoops ring(
      {4, 1}, {2, 2, 2, 2, 3}, {0, 0, 1, 1, 0, 0, 1, 1, 0, 0, 1, 1, 0, 0, 1, 1, 0, 0, 0, 0.25, 0.25, 0.5, 0.5, 0.75, 0.75, 1, 1, 1}, {0, 0, 0, 0, 0},
      {1, 1, 1, 1, 1}, {2, 2, 2, 2, 9},
      [&] {
        std::vector<double> u = {0, 1, 1, 1, 1, 0, 0, 0};
        u.insert(u.end(), c.u.begin(), c.u.end());
        return u;
      }(),
      [&] {
        std::vector<double> v = {-0.1, -0.1, -0.1, 0.9, 0.9, 0.9, 0.9, -0.1};
        v.insert(v.end(), c.v.begin(), c.v.end());
        return v;
      }(),
      [&] {
        std::vector<double> w(8, 1.0);
        w.insert(w.end(), c.w.begin(), c.w.end());
        return w;
      }());
  ASSERT_EQ(ring.loops().size(), 2u);
  EXPECT_FALSE(ring.encloses(0.5, 0.4));
  EXPECT_TRUE(ring.encloses(0.05, 0.0));
  EXPECT_FALSE(ring.encloses(1.05, 0.0));
  EXPECT_TRUE(ring.crosses(0.75, 0.85, 0.3, 0.5));
  EXPECT_FALSE(ring.crosses(0.45, 0.55, 0.35, 0.45));
}

// A NuPatch square (order 2, 60 x 60 pixels on screen, orthographic, 1 unit = 1 pixel),
// optionally trimmed: the raster area its micropolygons cover, and the pass's statistics.
std::pair<double, ShadeStats> trimmedSquareArea(const std::string& trim) {
  test::ScratchDir dir;
  std::ofstream(dir.path("t.rib")) << "Format 64 64 1\nProjection \"orthographic\"\nScreenWindow -32 32 -32 32\nWorldBegin\nShadingRate 0.25\n"
                                   << trim << "\nNuPatch 2 2 [0 0 1 1] 0 1 2 2 [0 0 1 1] 0 1 \"P\" [-30 -30 5  30 -30 5  -30 30 5  30 30 5]\nWorldEnd\n";
  FrameScene frame;
  Scene scene([&](FrameScene& f) { frame = std::move(f); });
  readRibScene(dir.path("t.rib"), scene);
  struct AreaSink final : store::GridSink {
    double area = 0;
    uint32_t addSchedule(const store::Schedule&) override { return 0; }
    void addGrid(const store::GridInput& g) override {
      for (size_t m = 0; m < g.corners.size() / 4; ++m) {
        const uint32_t* c = &g.corners[m * 4];
        const int k = c[3] == store::kNoCorner ? 3 : 4;
        for (int i = 0; i < k; ++i) {
          const glm::vec3 a = g.positions[c[i]], b = g.positions[c[(i + 1) % k]];
          area += 0.5 * (double(a.x) * b.y - double(b.x) * a.y);
        }
      }
    }
  } sink;
  const ShadeStats stats = shadeFrame(frame, {}, sink);
  return {std::abs(sink.area), stats};
}

TEST(PrimTrim, TrimmedPatchesCoverTheirTrimmedArea) {
  // A circle of radius 0.3 (18 px) trims the square: by default ("inside") the disc is cut away,
  // with "outside" only the disc is kept. Micropolygons are kept or cut by their centres, so the
  // area is exact to within the boundary's length times half a micropolygon (0.5 px across).
  const double square = 60.0 * 60.0, disc = M_PI * 18.0 * 18.0, tolerance = 2 * M_PI * 18.0 * 0.25;
  const auto [whole, wholeStats] = trimmedSquareArea("");
  EXPECT_NEAR(whole, square, 1e-3 * square);
  EXPECT_EQ(wholeStats.trimmedMicropolygons, 0u);
  const std::string circle = TrimCircle(0.5, 0.5, 0.3).rib();
  const auto [holed, holedStats] = trimmedSquareArea(circle);
  EXPECT_NEAR(holed, square - disc, tolerance);
  EXPECT_GT(holedStats.trimmedMicropolygons, 0u);
  const auto [kept, keptStats] = trimmedSquareArea("Attribute \"trimcurve\" \"sense\" \"outside\"\n" + circle);
  EXPECT_NEAR(kept, disc, tolerance);
  EXPECT_GT(keptStats.trimmedMicropolygons, holedStats.trimmedMicropolygons);
  // The trim is an attribute: it ends with its block.
  const auto [after, afterStats] = trimmedSquareArea("AttributeBegin\n" + circle + "\nAttributeEnd");
  EXPECT_NEAR(after, square, 1e-3 * square);
}

TEST(PrimTrim, BadTrimCurvesAreOneLineErrors) {
  for (const std::string bad : {"TrimCurve [1] [3] [0 0 0 1 1] [0] [1] [3] [0 1 0] [0 0 1] [1 1 1]",      // a knot short
                                "TrimCurve [1] [3] [0 0 0 1 1 1] [0] [2] [3] [0 1 0] [0 0 1] [1 1 1]",    // range beyond the knots
                                "TrimCurve [1] [3] [0 0 0 1 1 1] [0] [1] [3] [0 1 0] [0 0 1] [1 0 1]",    // a zero weight
                                "TrimCurve [1] [4] [0 0 0 0 1 1 1] [0] [1] [3] [0 1 0] [0 0 1] [1 1 1]",  // order above the points
                                "TrimCurve [1] [3] [0 0 1 0 1 1] [0] [1] [3] [0 1 0] [0 0 1] [1 1 1]",    // decreasing knots
                                "TrimCurve [2] [3] [0 0 0 1 1 1] [0] [1] [3] [0 1 0] [0 0 1] [1 1 1]",    // a loop short of curves
                                "Attribute \"trimcurve\" \"sense\" \"sideways\""}) {
    const std::string e = ribError(bad);
    EXPECT_NE(e.find("s.rib:"), std::string::npos) << bad << ": " << e;
    EXPECT_EQ(e.find('\n'), std::string::npos) << e;
  }
}

TEST(PrimFaceVarying, EachFaceTakesItsOwnValueAtSharedPoints) {
  // Two quads sharing an edge, a colour per face vertex (RenderMan facevarying): at the shared
  // points each face has its own colour; vertex data beside it (st per point) still follows the
  // points. Face vertex k has colour (k, 0, 0) and each corner's colour names the face vertex it
  // came from, so a corner's point can be checked against that face vertex's point.
  const std::vector<dvec3> P = {{0, 0, 5}, {1, 0, 5}, {2, 0, 5}, {0, 1, 5}, {1, 1, 5}, {2, 1, 5}};
  const std::vector<int> verts = {0, 1, 4, 3, 1, 2, 5, 4};
  Scene::VertexData vd;
  for (size_t k = 0; k < verts.size(); ++k) vd.Cs.emplace_back(double(k), 0, 0);
  for (const auto& p : P) vd.st.emplace_back(p.x / 2, p.y);
  auto checkCorners = [&](const std::vector<Primitive>& prims, const std::vector<int>& faceVerts, const char* what) {
    ASSERT_FALSE(prims.empty()) << what;
    for (const Primitive& p : prims) {
      std::array<dvec3, 4> cs;
      ASSERT_TRUE(p.corners(p.mesh->Cs, cs)) << what;
      std::array<glm::dvec2, 4> st;
      ASSERT_TRUE(p.cornerST(st)) << what;
      for (size_t c = 0; c < 4; ++c) {
        const size_t k = size_t(cs[c].x);
        ASSERT_LT(k, faceVerts.size()) << what;
        EXPECT_EQ(P[size_t(faceVerts[k])], p.keys[0].P[c]) << what << " corner " << c;
        EXPECT_EQ(st[c], glm::dvec2(p.keys[0].P[c].x / 2, p.keys[0].P[c].y)) << what << " corner " << c;
      }
    }
  };
  const auto quads = primsOf([&](Scene& s) { s.pointsPolygons({4, 4}, verts, P, vd); });
  ASSERT_EQ(quads.size(), 2u);
  checkCorners(quads, verts, "PointsPolygons");
  std::array<dvec3, 4> left, right;
  quads[0].corners(quads[0].mesh->Cs, left), quads[1].corners(quads[1].mesh->Cs, right);
  EXPECT_NE(left[1], right[0]);  // point 1, seen from each face

  // A polygon with a hole: its triangles' corners take the colours of their loop vertices.
  const std::vector<dvec3> Q = {{0, 0, 5}, {4, 0, 5}, {4, 4, 5}, {0, 4, 5}, {1, 1, 5}, {1, 3, 5}, {3, 3, 5}, {3, 1, 5}};
  const std::vector<int> loops = {0, 1, 2, 3, 4, 5, 6, 7};
  Scene::VertexData hv;
  for (size_t k = 0; k < loops.size(); ++k) hv.Cs.emplace_back(double(k), 0, 0);
  for (const auto& q : Q) hv.st.emplace_back(q.x / 2, q.y);
  const auto holed = primsOf([&](Scene& s) { s.generalPolygons({2}, {4, 4}, loops, Q, hv); });
  ASSERT_EQ(holed.size(), 8u);
  for (const Primitive& p : holed) {
    std::array<dvec3, 4> cs;
    ASSERT_TRUE(p.corners(p.mesh->Cs, cs));
    for (size_t c = 0; c < 4; ++c) EXPECT_EQ(Q[size_t(loops[size_t(cs[c].x)])], p.keys[0].P[c]) << "corner " << c;
  }

  // Subdivision: a ptex face's corners take its face vertices' values.
  const auto subdiv = primsOf([&](Scene& s) {
    Scene::VertexData sv;
    sv.st = {{0, 0}, {1, 0}, {1, 1}, {0, 1}, {5, 0}, {6, 0}, {6, 1}, {5, 1}};  // two islands
    SubdivTags tags;
    tags.interpolateBoundary = 1;  // two boundary faces: without it neither has a limit surface
    s.subdivisionMesh(SubdivScheme::CatmullClark, {4, 4}, verts, tags, P, sv);
  });
  ASSERT_EQ(subdiv.size(), 2u);
  std::array<glm::dvec2, 4> st0, st1;
  ASSERT_TRUE(subdiv[0].cornerST(st0));
  ASSERT_TRUE(subdiv[1].cornerST(st1));
  EXPECT_EQ(st0[0], glm::dvec2(0, 0));
  EXPECT_EQ(st0[3], glm::dvec2(1, 1));  // P11: the face's third vertex
  EXPECT_EQ(st1[0], glm::dvec2(5, 0));
  EXPECT_EQ(st1[3], glm::dvec2(6, 1));
}

// ---------------------------------------------------------------------------------------------
// Rendered through the CLI: coverage against exact areas, and cracks.

TEST(PrimBicubic, PlanarMeshesCoverExactlyTheirKnownArea) {
  // A regular planar grid of control points, 1 unit = 1 pixel (orthographic). A B-spline mesh
  // reproduces linear functions, so it covers exactly the rectangle of its inner control points;
  // a bezier mesh interpolates its rim, so it covers its whole hull. Each pixel's alpha (box
  // filter, 16x16 stratified samples) is checked against the exact overlap area.
  test::ScratchDir dir;
  const int n = 7;
  const double x0 = -9.3, y0 = -7.85, h = 2.55;
  std::string P;
  for (int j = 0; j < n; ++j)
    for (int i = 0; i < n; ++i) P += cat(x0 + h * i, " ", y0 + h * j, " 5 ");
  for (const std::string basis : {"b-spline", "bezier"}) {
    const std::string rib = cat("Format 32 32 1\nProjection \"orthographic\"\nScreenWindow -16 16 -16 16\nWorldBegin\nSurface \"constant\"\nBasis \"", basis,
                                "\" ", basis == "bezier" ? 3 : 1, " \"", basis, "\" ", basis == "bezier" ? 3 : 1, "\nPatchMesh \"bicubic\" ", n,
                                " \"nonperiodic\" ", n, " \"nonperiodic\" \"P\" [", P, "]\nWorldEnd\n");
    const Rendered img = render(dir, basis, rib, "--samples 16x16 --filter box:1x1");
    const double lo = basis == "bezier" ? 0 : 1, hi = basis == "bezier" ? n - 1 : n - 2;
    // Screen (x, y) → raster (x + 16, 16 - y).
    const double rx0 = x0 + h * lo + 16, rx1 = x0 + h * hi + 16, ry0 = 16 - (y0 + h * hi), ry1 = 16 - (y0 + h * lo);
    int full = 0;
    for (int y = 0; y < 32; ++y)
      for (int x = 0; x < 32; ++x) {
        const double cx = std::max(0.0, std::min(x + 1.0, rx1) - std::max(double(x), rx0));
        const double cy = std::max(0.0, std::min(y + 1.0, ry1) - std::max(double(y), ry0));
        const double a = img.alpha()[size_t(y * 32 + x)];
        EXPECT_NEAR(a, cx * cy, 2.0 / 16 + 1e-6) << basis << " pixel " << x << "," << y;
        if (cx * cy == 1) {
          EXPECT_EQ(a, 1.0f) << basis << " pixel " << x << "," << y;
        } else if (cx * cy == 0) {
          EXPECT_EQ(a, 0.0f) << basis << " pixel " << x << "," << y;
        }
        full += cx * cy == 1;
      }
    EXPECT_GT(full, 64) << basis;
  }
}

}  // namespace
}  // namespace reshutter::shade
