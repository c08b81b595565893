#include "shade/dump_writer.h"

#include "common/error.h"

namespace reshutter::shade {

static_assert(rib::kNoCorner == store::kNoCorner, "a dump's triangles are the store's");
static_assert(sizeof(glm::vec3) == 3 * sizeof(float), "positions are read as packed floats");

namespace {

rib::DumpHeader headerOf(const store::StoreMeta& meta) {
  const store::Camera& c = meta.cameras[0];
  rib::DumpHeader h;
  h.frame = meta.frame;
  h.width = c.width, h.height = c.height, h.pixelAspect = c.pixelAspect;
  h.perspective = c.projection == store::Projection::Perspective;
  h.fovDegrees = c.fovDegrees;
  c.effectiveScreenWindow(h.screenWindow);
  h.nearClip = c.nearClip, h.farClip = c.farClip;
  h.shutterOpen = meta.shutterOpen, h.shutterClose = meta.shutterClose;
  return h;
}

/// One knot's positions as the floats they are.
std::span<const float> knotPositions(const store::GridInput& g, size_t knot) {
  return {reinterpret_cast<const float*>(g.positions.data() + knot * g.numVertices), size_t(g.numVertices) * 3};
}

}  // namespace

DumpRibWriter::DumpRibWriter(const std::string& path, const store::StoreMeta& meta, bool gzip, int level)
    : rib_(path, headerOf(meta), gzip, level), ci_(meta.schema.ci()), oi_(meta.schema.oi()) {}

uint32_t DumpRibWriter::addSchedule(const store::Schedule& k) {
  schedules_.push_back(k);
  return uint32_t(schedules_.size() - 1);
}

void DumpRibWriter::addGrid(const store::GridInput& g) {
  const size_t K = schedules_.at(g.schedule).size();
  if (K > 2) fail(rib_.path(), "the blurP dump form holds two knots, not ", K);
  rib::DumpGrid d;
  d.numVertices = g.numVertices;
  d.corners = g.corners;
  d.P = knotPositions(g, 0);
  if (K == 2) d.blurP = knotPositions(g, 1);
  d.Cs = g.attrs.at(size_t(ci_)).f;
  d.Os = g.attrs.at(size_t(oi_)).f;
  rib_.addGrid(d);
}

}  // namespace reshutter::shade
