#include "store/synthetic.h"

#include <cmath>
#include <vector>

#include "common/random.h"

namespace reshutter::store {

StoreMeta syntheticMeta(const SyntheticOptions& o) {
  StoreMeta m;
  m.frame = 1;
  m.shutterOpen = 0.0;
  m.shutterClose = 1.0;
  Camera cam;
  cam.width = o.width;
  cam.height = o.height;
  cam.fovDegrees = 40.0;
  cam.nearClip = 0.1;
  cam.farClip = 1000.0;
  m.cameras = {cam};
  m.schema.attrs = {{"Ci", AttrType::Color, AttrRate::Vertex, o.colorCodec}, {"Oi", AttrType::Color, AttrRate::Vertex, o.opacityCodec}};
  m.provenance = "reshutter synthetic scene";
  return m;
}

uint64_t generateSynthetic(const SyntheticOptions& o, GridSink& writer) {
  const int g = o.gridSize, gv = g + 1;
  const uint32_t nV = uint32_t(gv * gv);
  const int K = std::max(1, o.knots);
  Schedule knots;
  for (int k = 0; k < K; ++k) knots.push_back(K == 1 ? 0.0 : double(k) / (K - 1));
  const uint32_t schedule = writer.addSchedule(knots);
  const Projector proj(syntheticMeta(o).cameras[0]);

  std::vector<uint32_t> corners;
  for (int j = 0; j < g; ++j)
    for (int i = 0; i < g; ++i) {
      uint32_t v = uint32_t(j * gv + i);
      corners.insert(corners.end(), {v, v + 1, v + 1 + uint32_t(gv), v + uint32_t(gv)});
    }
  std::vector<glm::vec3> positions(size_t(K) * nV);
  std::vector<float> ci(size_t(nV) * 3), oi(size_t(nV) * 3);

  const uint64_t perGrid = uint64_t(g) * g;
  const uint64_t grids = (o.micropolygons + perGrid - 1) / perGrid;
  for (uint64_t gi = 0; gi < grids; ++gi) {
    Rng rng(hashCombine(o.seed, gi));
    const double x0 = rng.uniform(-g, o.width), y0 = rng.uniform(-g, o.height);
    const double z0 = rng.uniform(5.0, 50.0);
    const double angle = rng.uniform(0.0, 2 * M_PI);
    double motion = rng.uniform(0.0, o.maxMotionPx);
    double dz = rng.uniform(-0.02, 0.02) * z0;
    const double tilt = rng.uniform(-0.3, 0.3), bulge = rng.uniform(0.0, 0.5);
    const double hue = rng.uniform(0.0, 6.28);
    const bool transparent = rng.uniform() < o.transparentFraction;
    const float alpha = transparent ? float(rng.uniform(0.2, 0.8)) : 1.0f;
    // Drawn last so that a scene without still grids keeps every other draw of its seed.
    if (o.stillFraction > 0.0 && rng.uniform() < o.stillFraction) motion = 0.0, dz = 0.0;
    for (int j = 0; j < gv; ++j)
      for (int i = 0; i < gv; ++i) {
        const size_t v = size_t(j) * gv + size_t(i);
        const double u = double(i) / g - 0.5, w = double(j) / g - 0.5;
        const double z = z0 * (1.0 + 0.01 * (tilt * u + bulge * (u * u + w * w)));
        const glm::dvec3 p = proj.unproject({x0 + i, y0 + j}, z);
        for (int k = 0; k < K; ++k) {
          const double s = K == 1 ? 0.0 : double(k) / (K - 1);
          // Screen-space displacement of `motion` px at depth z0, plus a little motion in depth.
          glm::dvec3 d(std::cos(angle) * motion * s * z0 / proj.ax, std::sin(angle) * motion * s * z0 / -proj.ay, dz * s);
          positions[size_t(k) * nV + v] = glm::vec3(p + d);
        }
        const double grain = 1.0 + o.texture * (2.0 * toUnitDouble(mix64(hashCombine(gi, v))) - 1.0);
        const double shade = (0.6 + 0.4 * std::cos(3.0 * u) * std::cos(3.0 * w)) * grain;
        ci[v * 3 + 0] = float(alpha * shade * (0.5 + 0.5 * std::sin(hue)));
        ci[v * 3 + 1] = float(alpha * shade * (0.5 + 0.5 * std::sin(hue + 2.1)));
        ci[v * 3 + 2] = float(alpha * shade * (0.5 + 0.5 * std::sin(hue + 4.2)));
        oi[v * 3 + 0] = oi[v * 3 + 1] = oi[v * 3 + 2] = alpha;
      }
    GridInput grid;
    grid.schedule = schedule;
    grid.numVertices = nV;
    grid.positions = positions;
    grid.corners = corners;
    grid.objectId = uint32_t(gi % 97);
    grid.gridId = uint32_t(gi);
    grid.attrs = {AttrValues{ci, {}}, AttrValues{oi, {}}};
    writer.addGrid(grid);
  }
  return grids * perGrid;
}

}  // namespace reshutter::store
