// Tile bounds are conservative: every point of every micropolygon, at every time of the shutter
// (sampled densely) and for any sub-interval, projects inside its part's bound - including
// micropolygons that cross the eye plane while the shutter is open and ones far off screen.
#include <cmath>

#include <gtest/gtest.h>

#include "tests/store_test_util.h"
#include "tests/test_util.h"

using namespace reshutter;
using namespace reshutter::store;

namespace {

glm::dvec3 at(const TilePart& p, const Schedule& s, uint32_t v, double t) {
  if (p.numKnots == 1 || t <= s.front()) return glm::dvec3(p.position(0, v));
  if (t >= s.back()) return glm::dvec3(p.position(p.numKnots - 1, v));
  size_t k = 0;
  while (s[k + 1] < t) ++k;
  double f = (t - s[k]) / (s[k + 1] - s[k]);
  return glm::mix(glm::dvec3(p.position(uint32_t(k), v)), glm::dvec3(p.position(uint32_t(k + 1), v)), f);
}

bool inside(const RasterRect& r, glm::dvec2 q) { return !r.empty && q.x >= r.x0 && q.x <= r.x1 && q.y >= r.y0 && q.y <= r.y1; }

// Checks sampled points of every micropolygon at `steps` times against bounds over [t, t] and
// over an interval around t; returns the number of visible points checked.
size_t checkStore(const StoreReader& reader, int steps) {
  const auto& meta = reader.meta();
  Projector proj(meta.cameras[0]);
  size_t checked = 0;
  for (size_t e = 0; e < reader.entries().size(); ++e) {
    const auto& entry = reader.entries()[e];
    const Schedule& s = meta.schedules[entry.schedule];
    TilePart p = reader.decode(e);
    for (int step = 0; step <= steps; ++step) {
      double t = meta.shutterOpen + (meta.shutterClose - meta.shutterOpen) * step / steps;
      double t0 = std::max(meta.shutterOpen, t - 0.07), t1 = std::min(meta.shutterClose, t + 0.03);
      RasterRect instant = reader.bounds(e, t, t), around = reader.bounds(e, t0, t1), whole = reader.bounds(e, meta.shutterOpen, meta.shutterClose);
      for (uint32_t m = 0; m < p.numMicropolygons; ++m) {
        const uint32_t* c = &p.corners[size_t(m) * 4];
        glm::dvec3 q[4];
        for (int j = 0; j < 4; ++j) q[j] = c[j] == kNoCorner ? glm::dvec3(0) : at(p, s, c[j], t);
        if (c[3] == kNoCorner) q[3] = q[2];
        for (double u : {0.0, 0.3, 1.0})
          for (double v : {0.0, 0.6, 1.0}) {
            glm::dvec3 pt = glm::mix(glm::mix(q[0], q[1], u), glm::mix(q[3], q[2], u), v);
            if (pt.z < proj.nearClip) continue;  // clipped by the renderer: no bound needed
            glm::dvec2 r = proj.project(pt);
            if (!inside(instant, r) || !inside(around, r) || !inside(whole, r)) {
              ADD_FAILURE() << reader.where(e) << " mp " << m << " t=" << t << " at (" << r.x << "," << r.y << ") escapes its bounds";
              return checked;
            }
            ++checked;
          }
      }
    }
  }
  return checked;
}

std::string writeStore(const test::ScratchDir& dir, const std::string& name, test::GridSpec spec, int grids, uint64_t seed) {
  const Schema schema = test::fullSchema();
  std::string path = dir.path(name);
  StoreWriter writer(path, test::testMeta(schema));
  Schedule s;
  for (int k = 0; k < spec.knots; ++k) s.push_back(spec.knots == 1 ? 0.0 : double(k) / (spec.knots - 1));
  spec.schedule = writer.addSchedule(s);
  Rng rng(seed);
  uint32_t mpid = 0;
  for (int g = 0; g < grids; ++g) writer.addGrid(test::randomGrid(rng, schema, spec, uint32_t(g), mpid).view());
  writer.close();
  return path;
}

}  // namespace

TEST(StoreBounds, HoldAtEveryTimeForOrdinaryMotion) {
  test::ScratchDir dir;
  test::GridSpec spec;
  spec.knots = 4;
  spec.motion = 1.0;
  StoreReader reader(writeStore(dir, "m.mps", spec, 80, 3));
  EXPECT_GT(checkStore(reader, 64), 10000u);
}

TEST(StoreBoundsHard, HoldWhenMicropolygonsCrossTheEyePlaneDuringTheShutter) {
  test::ScratchDir dir;
  test::GridSpec spec;
  spec.knots = 3;
  spec.zMin = -3, spec.zMax = 4;  // near plane is 0.5: grids start behind, across and in front
  spec.motion = 3.0;              // and sweep through it
  spec.spread = 1.5;
  StoreReader reader(writeStore(dir, "eye.mps", spec, 150, 5));
  bool sawCrossing = false;
  for (const auto& e : reader.entries()) sawCrossing |= (e.effects & kEffectNearCrossing) != 0;
  EXPECT_TRUE(sawCrossing);
  EXPECT_GT(checkStore(reader, 200), 1000u);
  reader.verify();
}

TEST(StoreBoundsHard, HugeCoordinatesAndTinyMotionStayFinite) {
  test::ScratchDir dir;
  test::GridSpec spec;
  spec.knots = 2;
  spec.zMin = 1, spec.zMax = 2;
  spec.spread = 3e6;  // ~1e7 px off screen
  spec.motion = 1e-6;
  StoreReader reader(writeStore(dir, "huge.mps", spec, 20, 11));
  for (size_t e = 0; e < reader.entries().size(); ++e) {
    RasterRect r = reader.bounds(e, 0, 1);
    EXPECT_TRUE(std::isfinite(r.x0) && std::isfinite(r.x1) && std::isfinite(r.y0) && std::isfinite(r.y1));
  }
  checkStore(reader, 16);
  reader.verify();
}

TEST(StoreBounds, SubIntervalBoundsShrinkWithTheInterval) {
  // A quarter of the shutter must not cost the whole shutter's bound: for moving parts, the bound
  // over [0, 0.25] is no larger, and usually smaller, than the bound over [0, 1].
  test::ScratchDir dir;
  test::GridSpec spec;
  spec.knots = 5;
  spec.motion = 2.0;
  StoreReader reader(writeStore(dir, "q.mps", spec, 50, 9));
  size_t smaller = 0;
  for (size_t e = 0; e < reader.entries().size(); ++e) {
    RasterRect q = reader.bounds(e, 0, 0.25), w = reader.bounds(e, 0, 1);
    double aq = double(q.x1 - q.x0) * (q.y1 - q.y0), aw = double(w.x1 - w.x0) * (w.y1 - w.y0);
    EXPECT_LE(aq, aw * (1 + 1e-6));
    if (aq < 0.8 * aw) ++smaller;
  }
  EXPECT_GT(smaller, reader.entries().size() / 2);
}
