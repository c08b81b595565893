// Random micropolygon grids for store tests, and a flat record of every micropolygon so that a
// store's contents can be compared with what went in, whatever tile each one landed in.
#pragma once

#include <map>
#include <vector>

#include "common/random.h"
#include "store/model.h"
#include "store/reader.h"
#include "store/writer.h"

namespace reshutter::test {

/// One micropolygon with everything resolved: corner positions per knot, per-corner vertex
/// attributes, per-micropolygon attributes.
struct FlatMp {
  uint32_t objectId = 0, gridId = 0;
  uint8_t flags = 0;
  int corners = 4;
  uint32_t schedule = 0;
  std::vector<glm::vec3> positions;       // knots × 4
  std::vector<std::vector<float>> attrF;  // per schema attr: vertex rate 4×nc, mp rate nc
  std::vector<std::vector<uint32_t>> attrU;
};

/// Key: the "mpid" uint attribute (per micropolygon) every test grid carries.
using FlatStore = std::map<uint32_t, FlatMp>;

struct OwnedGrid {
  uint32_t schedule = 0;
  uint32_t numVertices = 0;
  std::vector<glm::vec3> positions;
  std::vector<uint32_t> corners;
  uint32_t objectId = 0, gridId = 0;
  uint8_t flags = 0;
  std::vector<std::vector<float>> f;
  std::vector<std::vector<uint32_t>> u;
  store::GridInput view() const {
    store::GridInput g;
    g.schedule = schedule;
    g.numVertices = numVertices;
    g.positions = positions;
    g.corners = corners;
    g.objectId = objectId;
    g.gridId = gridId;
    g.flags = flags;
    for (size_t i = 0; i < f.size(); ++i) g.attrs.push_back(store::AttrValues{f[i], u[i]});
    return g;
  }
};

/// Schema with Ci, Oi, every other type at both rates, and "mpid".
store::Schema fullSchema(store::AttrCodec colorCodec = store::AttrCodec::Lossless, store::AttrCodec opacityCodec = store::AttrCodec::Lossless,
                         store::AttrCodec normalCodec = store::AttrCodec::Lossless);
store::StoreMeta testMeta(const store::Schema& schema, int width = 256, int height = 192);

struct GridSpec {
  int nu = 4, nv = 3;  // micropolygons per side
  uint32_t schedule = 0;
  int knots = 1;
  bool triangles = false;  // split every quad into two triangles
  double zMin = 2, zMax = 60;
  double spread = 2.0;        // camera-space extent of the grid
  double motion = 0.5;        // camera-space motion per knot
  bool randomBits = true;     // attribute values with full-entropy mantissas
  bool dropOptional = false;  // leave out every attribute but Ci, Oi, mpid
};

/// A random grid; `nextMpId` numbers its micropolygons.
OwnedGrid randomGrid(Rng& rng, const store::Schema& schema, const GridSpec& spec, uint32_t gridId, uint32_t& nextMpId);
/// Flattens a grid (input side).
void flatten(const OwnedGrid& g, const store::Schema& schema, FlatStore& out);
/// Flattens every part of a store (output side).
FlatStore flatten(const store::StoreReader& reader);

}  // namespace reshutter::test
