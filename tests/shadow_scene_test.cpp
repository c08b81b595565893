// The shadow scene of the shading pass (shade/shadows.h): MovingCasters never misses a caster
// between a receiver and its light (brute force over random boxes and lights), and casters
// fixed at the shading times block exactly where they stand then (analytic intersections).
#include <algorithm>
#include <cmath>
#include <random>

#include <gtest/gtest.h>
#include <glm/geometric.hpp>
#include <glm/gtc/matrix_transform.hpp>

#include "shade/shadows.h"

namespace reshutter::shade {
namespace {

using glm::dvec3;

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
  const std::vector<double> fixAt{0, 0.25, 1};
  const ShadowScene scene(pieces, 0, 1, motions, fixAt);
  EXPECT_EQ(scene.fixedInstants(), 3u);  // a count of shutter instants
  EXPECT_EQ(scene.rigidInstances(), 1u);
  // Without rigid motions there is nothing to fix.
  EXPECT_EQ(ShadowScene(std::vector<ShadowScene::Piece>{deforming}, 0, 1, {}, fixAt).fixedInstants(), 0u);
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
