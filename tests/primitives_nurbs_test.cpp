// Production primitives, continued: curves as camera-facing ribbons and discs against their area,
// NURBS surfaces against Cox-de Boor's recurrence and an exact rational quarter circle, and
// general polygons with holes cut out exactly.
#include <cmath>
#include <vector>

#include <gtest/gtest.h>

#include "common/error.h"
#include "shade/dice.h"
#include "shade/scene.h"
#include "tests/primitives_test_util.h"
#include "tests/test_util.h"

namespace reshutter::shade {
namespace {

using glm::dvec3;
using namespace testing;

TEST(PrimCurves, RibbonsFollowTheirCurveAndFaceTheCamera) {
  // A cubic bezier curve with a tapering width and a linear one; orthographic view along +z.
  const std::vector<dvec3> cv = {{0, 0, 5}, {1, 2, 5}, {3, 2, 6}, {4, 0, 5}};
  const auto prims = primsOf([&](Scene& s) {
    s.curves(true, {4}, false, cv, {0.4, 0.1}, {});
    s.curves(false, {3}, false, {{0, 0, 5}, {2, 0, 5}, {2, 2, 5}}, {0.5}, {});
  });
  ASSERT_EQ(prims.size(), 3u);  // one cubic segment, two linear ones
  const Primitive& c = prims[0];
  for (double v : {0.0, 0.3, 0.8, 1.0}) {
    const Shape s = c.shapeAt(0);
    const dvec3 mid = evalP(c, s, 0.5, v), left = evalP(c, s, 0.0, v), right = evalP(c, s, 1.0, v);
    EXPECT_LT(
        glm::length(mid - deCasteljau({cv[0], cv[1], cv[2], cv[3], cv[0], cv[1], cv[2], cv[3], cv[0], cv[1], cv[2], cv[3], cv[0], cv[1], cv[2], cv[3]}, v, 0)),
        1e-12);
    EXPECT_NEAR(glm::length(right - left), 0.4 + v * (0.1 - 0.4), 1e-12);  // the width, interpolated
    EXPECT_NEAR((right - left).z, 0.0, 1e-12);                             // across the view, not along it
    EXPECT_LT(evalNg(c, s, 0.5, v).z, 0.0);                                // facing the camera
  }
  // The linear curve's second segment starts where the first ends.
  EXPECT_EQ(evalP(prims[1], prims[1].keys[0], 0.5, 1.0), evalP(prims[2], prims[2].keys[0], 0.5, 0.0));
  EXPECT_NE(buildError([&](Scene& s) { s.curves(true, {5}, false, std::vector<dvec3>(5), {1}, {}); }).find("not whole cubic segments"), std::string::npos);
  EXPECT_NE(buildError([&](Scene& s) { s.curves(false, {3}, false, std::vector<dvec3>(4), {1}, {}); }).find("\"P\" has 4"), std::string::npos);
  EXPECT_NE(buildError([&](Scene& s) { s.curves(false, {3}, false, std::vector<dvec3>(3), {1, 2}, {}); }).find("1 or 3 (varying)"), std::string::npos);
  EXPECT_NE(buildError([&](Scene& s) { s.points(std::vector<dvec3>(3), {1, 2}); }).find("1 or 3"), std::string::npos);
  EXPECT_NE(buildError([&](Scene& s) { s.points(std::vector<dvec3>(1), {-1}); }).find("non-negative"), std::string::npos);
}

TEST(PrimCurves, RibbonsAndDiscsCoverTheirArea) {
  // Orthographic, 1 unit = 1 pixel: a linear curve of constant width is a rectangle (exact
  // coverage pixel by pixel); a point is a disc of its width (interior full, exterior empty,
  // total area within the polygon's approximation).
  test::ScratchDir dir;
  const Rendered img = render(dir, "curves",
                              "Format 32 32 1\nProjection \"orthographic\"\nScreenWindow -16 16 -16 16\nWorldBegin\nSurface \"constant\"\n"
                              "Curves \"linear\" [2] \"nonperiodic\" \"P\" [-12.3 5.6 5  9.7 5.6 5] \"constantwidth\" [3.5]\n"
                              "Points \"P\" [0 -7 5] \"constantwidth\" [12]\nWorldEnd\n",
                              "--samples 16x16 --filter box:1x1");
  const double rx0 = -12.3 + 16, rx1 = 9.7 + 16, ry0 = 16 - (5.6 + 1.75), ry1 = 16 - (5.6 - 1.75);
  double discArea = 0;
  for (int y = 0; y < 32; ++y)
    for (int x = 0; x < 32; ++x) {
      const double a = img.alpha()[size_t(y * 32 + x)];
      if (y < 16) {
        const double cx = std::max(0.0, std::min(x + 1.0, rx1) - std::max(double(x), rx0));
        const double cy = std::max(0.0, std::min(y + 1.0, ry1) - std::max(double(y), ry0));
        EXPECT_NEAR(a, cx * cy, 2.0 / 16 + 1e-6) << "ribbon pixel " << x << "," << y;
        continue;
      }
      discArea += a;
      const double d = std::hypot(x + 0.5 - 16, y + 0.5 - 23);  // disc centre (0, -7) → raster (16, 23)
      if (d < 6 - 1.5) {
        EXPECT_EQ(a, 1.0f) << "disc pixel " << x << "," << y;
      } else if (d > 6 + 1.5) {
        EXPECT_EQ(a, 0.0f) << "disc pixel " << x << "," << y;
      }
    }
  EXPECT_NEAR(discArea, M_PI * 36, 0.04 * M_PI * 36);
}

// ---------------------------------------------------------------------------------------------
// NURBS

// The textbook recursion (Cox-de Boor) over the whole knot vector: basis function i of `order`.
double coxDeBoor(const std::vector<double>& t, int i, int order, double x) {
  if (order == 1) {
    // Half-open spans, and the last non-empty span closed at its end.
    const bool last = x == t.back() && t[size_t(i)] < t[size_t(i + 1)] && t[size_t(i + 1)] == t.back();
    return (t[size_t(i)] <= x && x < t[size_t(i + 1)]) || last ? 1.0 : 0.0;
  }
  double a = 0, b = 0;
  const double d1 = t[size_t(i + order - 1)] - t[size_t(i)], d2 = t[size_t(i + order)] - t[size_t(i + 1)];
  if (d1 > 0) a = (x - t[size_t(i)]) / d1 * coxDeBoor(t, i, order - 1, x);
  if (d2 > 0) b = (t[size_t(i + order)] - x) / d2 * coxDeBoor(t, i + 1, order - 1, x);
  return a + b;
}

// The primitive of `prims` whose span holds (x, y), evaluated there.
dvec3 nurbsSurfaceAt(const std::vector<Primitive>& prims, double x, double y) {
  for (const auto& p : prims) {
    const NurbsSpan& n = *p.nurbs;
    if (x >= n.u0 && x <= n.u1 && y >= n.v0 && y <= n.v1) return evalP(p, p.keys[0], (x - n.u0) / (n.u1 - n.u0), (y - n.v0) / (n.v1 - n.v0));
  }
  return dvec3(NAN);
}

TEST(PrimNurbs, SurfacesAreCoxDeBoorRationalCombinations) {
  // A random rational surface of orders 3 x 4 over non-uniform knots with a double knot, against
  // the textbook recursion over the whole knot vector.
  const int nu = 6, nv = 5, ou = 3, ov = 4;
  const std::vector<double> uk = {0, 0, 0, 0.3, 0.3, 0.7, 1, 1, 1}, vk = {-1, -1, -1, -1, 0.5, 2, 2, 2, 2};
  std::mt19937 rng(4);
  std::uniform_real_distribution<double> d(-2, 2), w(0.3, 3);
  std::vector<glm::dvec4> Pw;
  for (int i = 0; i < nu * nv; ++i) {
    const double wi = w(rng);
    Pw.emplace_back(d(rng) * wi, d(rng) * wi, d(rng) * wi, wi);  // homogeneous, as RIB's Pw
  }
  const auto prims = primsOf([&](Scene& s) { s.nuPatch(nu, ou, uk, 0, 1, nv, ov, vk, -1, 2, Pw); });
  ASSERT_EQ(prims.size(), 3u * 2u);  // u spans [0,.3] [.3,.7] [.7,1] (the double knot's empty span skipped), v spans [-1,.5] [.5,2]
  for (double x : {0.0, 0.1, 0.3, 0.55, 0.99, 1.0})
    for (double y : {-1.0, 0.0, 0.5, 1.7, 2.0}) {
      glm::dvec4 sum(0.0);
      for (int j = 0; j < nv; ++j)
        for (int i = 0; i < nu; ++i) sum += coxDeBoor(uk, i, ou, x) * coxDeBoor(vk, j, ov, y) * Pw[size_t(j * nu + i)];
      const dvec3 want = dvec3(sum) / sum.w;
      EXPECT_LT(glm::length(nurbsSurfaceAt(prims, x, y) - want), 1e-9) << x << " " << y;
    }
  // A Bezier-knotted NURBS with unit weights is the bezier patch.
  const auto cv = randomPoints(16, 2);
  std::vector<glm::dvec4> unit;
  for (const auto& c : cv) unit.emplace_back(c, 1.0);
  const auto bez = primsOf([&](Scene& s) { s.nuPatch(4, 4, {0, 0, 0, 0, 1, 1, 1, 1}, 0, 1, 4, 4, {0, 0, 0, 0, 1, 1, 1, 1}, 0, 1, unit); });
  ASSERT_EQ(bez.size(), 1u);
  EXPECT_LT(glm::length(evalP(bez[0], bez[0].keys[0], 0.37, 0.81) - deCasteljau(cv, 0.37, 0.81)), 1e-12);
}

TEST(PrimNurbs, RationalQuarterCircleIsExactAndRangesRestrict) {
  // Order 3 with weights 1, sqrt(2)/2, 1: an exact quarter of the unit circle, extruded in v.
  const double h = std::sqrt(0.5);
  const std::vector<glm::dvec4> Pw = {{1, 0, 0, 1}, {h, h, 0, h}, {0, 1, 0, 1}, {1, 0, 1, 1}, {h, h, h, h}, {0, 1, 1, 1}};
  const auto prims = primsOf([&](Scene& s) { s.nuPatch(3, 3, {0, 0, 0, 1, 1, 1}, 0.25, 1, 2, 2, {0, 0, 1, 1}, 0, 1, Pw); });
  ASSERT_EQ(prims.size(), 1u);
  for (double u : {0.0, 0.2, 0.5, 0.9, 1.0})
    for (double v : {0.0, 0.5, 1.0}) {
      const dvec3 p = evalP(prims[0], prims[0].keys[0], u, v);
      EXPECT_NEAR(p.x * p.x + p.y * p.y, 1.0, 1e-12);
      EXPECT_NEAR(p.z, v, 1e-12);
    }
  // umin = 0.25: the primitive starts a quarter of the way along, not at (1, 0).
  EXPECT_GT(evalP(prims[0], prims[0].keys[0], 0, 0).y, 0.2);
  const dvec3 n = glm::normalize(evalNg(prims[0], prims[0].keys[0], 0.5, 0.5));
  const dvec3 p = evalP(prims[0], prims[0].keys[0], 0.5, 0.5);
  EXPECT_GT(std::abs(glm::dot(n, glm::normalize(dvec3(p.x, p.y, 0)))), 1 - 1e-6);  // radial
}

TEST(PrimNurbs, BadPatchesAreOneLineErrors) {
  const std::vector<glm::dvec4> four(4, glm::dvec4(0, 0, 0, 1));
  const std::vector<double> k22 = {0, 0, 1, 1};
  EXPECT_NE(buildError([&](Scene& s) {
              s.nuPatch(2, 2, {0, 1, 0.5, 1}, 0, 1, 2, 2, k22, 0, 1, four);
            }).find("u knot vector decreases at knot 2"),
            std::string::npos);
  EXPECT_NE(buildError([&](Scene& s) {
              s.nuPatch(2, 3, {0, 0, 0, 1, 1}, 0, 1, 2, 2, k22, 0, 1, four);
            }).find("u order 3 is above its 2 control points"),
            std::string::npos);
  EXPECT_NE(buildError([&](Scene& s) { s.nuPatch(2, 2, {0, 0, 1}, 0, 1, 2, 2, k22, 0, 1, four); }).find("need 4"), std::string::npos);
  EXPECT_NE(buildError([&](Scene& s) {
              s.nuPatch(2, 2, k22, 0, 1, 2, 2, k22, 0, 1, {{0, 0, 0, 1}, {0, 0, 0, 0}, {0, 0, 0, 1}, {0, 0, 0, 1}});
            }).find("weight 0 must be positive"),
            std::string::npos);
  EXPECT_NE(buildError([&](Scene& s) { s.nuPatch(2, 2, k22, 0, 2, 2, 2, k22, 0, 1, four); }).find("not inside [0, 1]"), std::string::npos);
  EXPECT_NE(buildError([&](Scene& s) {
              s.nuPatch(2, 2, k22, 0, 1, 2, 2, k22, 0, 1, std::vector<glm::dvec4>(3, glm::dvec4(1)));
            }).find("needs 4 control points, has 3"),
            std::string::npos);
}

TEST(PrimPolygon, HolesAreCutOutExactly) {
  // Orthographic, 1 unit = 1 pixel: a non-convex outline (an L) with two holes, one of them
  // non-convex, as PointsGeneralPolygons and as GeneralPolygon (wound the other way). Every
  // pixel's alpha is the exact area of the L minus the holes inside it.
  test::ScratchDir dir;
  // L: (-12,-12) (12,-12) (12,0) (0,0) (0,12) (-12,12); holes: a square (4..9, -9..-4) and a
  // U shape inside the tall arm.
  const std::string P =
      "-12 -12 5  12 -12 5  12 0 5  0 0 5  0 12 5  -12 12 5  "
      "4 -9 5  4 -4 5  9 -4 5  9 -9 5  "
      "-9 2 5  -9 9 5  -7 9 5  -7 4 5  -4 4 5  -4 9 5  -2 9 5  -2 2 5";
  const std::string head = "Format 32 32 1\nProjection \"orthographic\"\nScreenWindow -16 16 -16 16\nWorldBegin\nSurface \"constant\"\n";
  auto insideL = [](double x, double y) {
    const bool l = x >= -12 && x <= 12 && y >= -12 && y <= 12 && !(x > 0 && y > 0);
    const bool square = x > 4 && x < 9 && y > -9 && y < -4;
    const bool u = x > -9 && x < -2 && y > 2 && y < 9 && !(x > -7 && x < -4 && y > 4);
    return l && !square && !u;
  };
  for (const std::string& request : {std::string("PointsGeneralPolygons [3] [6 4 8] [0 1 2 3 4 5  6 7 8 9  10 11 12 13 14 15 16 17] \"P\" [") + P + "]",
                                     std::string("GeneralPolygon [6 4 8] \"P\" [") + P + "]"}) {
    const Rendered img = render(dir, "holes", head + request + "\nWorldEnd\n", "--samples 16x16 --filter box:1x1");
    int full = 0, empty = 0;
    for (int y = 0; y < 32; ++y)
      for (int x = 0; x < 32; ++x) {
        // The exact area inside the pixel, on a 64 x 64 grid of cell centres (edges lie on
        // integers, so each pixel is wholly in or out: the grid is exact here).
        const double sx = x - 16 + 0.5, sy = 16 - y - 0.5;
        const float want = insideL(sx, sy) ? 1.0f : 0.0f;
        EXPECT_EQ(img.alpha()[size_t(y * 32 + x)], want) << request.substr(0, 22) << " pixel " << x << "," << y;
        full += want == 1, empty += want == 0;
      }
    EXPECT_GT(full, 300);
    EXPECT_GT(empty, 300);
  }
  // A hole outside its outline cannot be cut: a one-line error.
  EXPECT_NE(buildError([&](Scene& s) {
              s.generalPolygons({2}, {3, 3}, {0, 1, 2, 3, 4, 5}, {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}, {5, 5, 0}, {6, 5, 0}, {5, 6, 0}});
            }).find("polygon 0 with holes cannot be triangulated"),
            std::string::npos);
}

TEST(PrimPolygon, SplitTrianglesKeepEveryPiece) {
  // A triangle big enough to be split into many grids: every pixel well inside it is covered.
  // (Each piece used to drop half of its last row as if it were the triangle's apex.)
  test::ScratchDir dir;
  const Rendered img = render(dir, "tri",
                              "Format 32 32 1\nProjection \"orthographic\"\nScreenWindow -16 16 -16 16\nShadingRate 0.25\nWorldBegin\nSurface \"constant\"\n"
                              "Polygon \"P\" [-15 -15 5  15 -15 5  -15 15 5]\nWorldEnd\n",
                              "--samples 4x4 --filter box:1x1");
  int inside = 0;
  for (int y = 0; y < 32; ++y)
    for (int x = 0; x < 32; ++x) {
      // Screen (sx, sy) of the pixel's corners; inside with a pixel of margin from every edge.
      const double sx0 = x - 16, sx1 = x - 15, sy0 = 16 - (y + 1), sy1 = 16 - y;
      if (sx0 < -14 || sy0 < -14 || sx1 + sy1 > -1) continue;
      EXPECT_EQ(img.alpha()[size_t(y * 32 + x)], 1.0f) << x << "," << y;
      ++inside;
    }
  EXPECT_GT(inside, 300);
}

}  // namespace
}  // namespace reshutter::shade
