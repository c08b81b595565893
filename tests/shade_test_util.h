// What the shading pass's tests share: a sink that keeps every grid the pass sends, frames built
// with the Scene API, and the figures read back from captured grids.
#pragma once
#include <cmath>
#include <functional>
#include <string>
#include <vector>

#include <glm/geometric.hpp>

#include "shade/scene.h"
#include "shade/shading_pass.h"
#include "store/model.h"

namespace reshutter::shade::testing {

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

inline CaptureSink shadeCapture(const FrameScene& f, ShadeOptions o = {}) {
  CaptureSink sink;
  shadeFrame(f, o, sink);
  return sink;
}

inline int attrIndex(const FrameScene& f, const std::string& name, const ShadeOptions& o = {}) { return storeMeta(f, o).schema.find(name); }

inline double rasterArea(const store::Projector& pr, const CaptureSink::Grid& g, size_t m, uint32_t knot = 0) {
  const uint32_t* c = &g.corners[m * 4];
  const int n = c[3] == store::kNoCorner ? 3 : 4;
  glm::dvec2 r[4];
  for (int i = 0; i < n; ++i) r[i] = pr.project(glm::dvec3(g.positions[size_t(knot) * g.numVertices + c[i]]));
  double a = 0;
  for (int i = 0; i < n; ++i) a += r[i].x * r[(i + 1) % n].y - r[(i + 1) % n].x * r[i].y;
  return std::abs(a) / 2;
}

}  // namespace reshutter::shade::testing
