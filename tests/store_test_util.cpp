#include "tests/store_test_util.h"

#include <gtest/gtest.h>

namespace reshutter::test {
using namespace store;

Schema fullSchema(AttrCodec colorCodec, AttrCodec opacityCodec, AttrCodec normalCodec) {
  Schema s;
  s.attrs = {
      {"Ci", AttrType::Color, AttrRate::Vertex, colorCodec},
      {"Oi", AttrType::Color, AttrRate::Vertex, opacityCodec},
      {"mpid", AttrType::UInt, AttrRate::Micropolygon, AttrCodec::Lossless},
      {"s", AttrType::Float, AttrRate::Vertex, AttrCodec::Lossless},
      {"P", AttrType::Point, AttrRate::Vertex, AttrCodec::Lossless},
      {"dPdtime", AttrType::Vector, AttrRate::Vertex, AttrCodec::Lossless},
      {"N", AttrType::Normal, AttrRate::Vertex, normalCodec},
      {"Cs", AttrType::Color, AttrRate::Micropolygon, colorCodec},
      {"area", AttrType::Float, AttrRate::Micropolygon, AttrCodec::Lossless},
      {"Ng", AttrType::Normal, AttrRate::Micropolygon, normalCodec},
      {"id", AttrType::UInt, AttrRate::Vertex, AttrCodec::Lossless},
  };
  return s;
}

StoreMeta testMeta(const Schema& schema, int width, int height) {
  StoreMeta m;
  m.schema = schema;
  m.cameras[0].width = width;
  m.cameras[0].height = height;
  m.cameras[0].fovDegrees = 50;
  m.cameras[0].nearClip = 0.5;
  m.tileSize = 16;
  m.provenance = "test";
  return m;
}

OwnedGrid randomGrid(Rng& rng, const Schema& schema, const GridSpec& spec, uint32_t gridId, uint32_t& nextMpId) {
  OwnedGrid g;
  g.schedule = spec.schedule;
  g.gridId = gridId;
  g.objectId = rng.below(1000);
  g.flags = uint8_t(rng.below(4));
  const int vu = spec.nu + 1, vv = spec.nv + 1;
  g.numVertices = uint32_t(vu * vv);
  const double z = rng.uniform(spec.zMin, spec.zMax);
  const glm::dvec3 origin(rng.uniform(-0.6, 0.6) * z, rng.uniform(-0.45, 0.45) * z, z);
  std::vector<glm::dvec3> velocity(size_t(spec.knots));
  for (auto& v : velocity) v = glm::dvec3(rng.uniform(-1, 1), rng.uniform(-1, 1), rng.uniform(-0.3, 0.3)) * spec.motion;
  g.positions.resize(size_t(spec.knots) * g.numVertices);
  for (int k = 0; k < spec.knots; ++k)
    for (int j = 0; j < vv; ++j)
      for (int i = 0; i < vu; ++i) {
        glm::dvec3 p = origin + glm::dvec3(i, j, rng.uniform(-0.2, 0.2)) * (spec.spread / std::max(spec.nu, spec.nv));
        for (int kk = 1; kk <= k; ++kk) p += velocity[size_t(kk)];
        g.positions[size_t(k) * g.numVertices + size_t(j * vu + i)] = glm::vec3(p);
      }
  // Later knots must reuse the same jitter: regenerate them from knot 0 plus motion.
  for (int k = 1; k < spec.knots; ++k)
    for (uint32_t v = 0; v < g.numVertices; ++v) {
      glm::dvec3 p(g.positions[v]);
      for (int kk = 1; kk <= k; ++kk) p += velocity[size_t(kk)];
      g.positions[size_t(k) * g.numVertices + v] = glm::vec3(p);
    }
  for (int j = 0; j < spec.nv; ++j)
    for (int i = 0; i < spec.nu; ++i) {
      uint32_t v = uint32_t(j * vu + i);
      if (spec.triangles) {
        g.corners.insert(g.corners.end(), {v, v + 1, v + 1 + uint32_t(vu), kNoCorner});
        g.corners.insert(g.corners.end(), {v, v + 1 + uint32_t(vu), v + uint32_t(vu), kNoCorner});
      } else {
        g.corners.insert(g.corners.end(), {v, v + 1, v + 1 + uint32_t(vu), v + uint32_t(vu)});
      }
    }
  const size_t nMp = g.corners.size() / 4;
  g.f.resize(schema.attrs.size());
  g.u.resize(schema.attrs.size());
  for (size_t a = 0; a < schema.attrs.size(); ++a) {
    const auto& d = schema.attrs[a];
    bool optional = d.name != "Ci" && d.name != "Oi" && d.name != "mpid";
    if (spec.dropOptional && optional) continue;
    size_t count = d.rate == AttrRate::Vertex ? g.numVertices : nMp;
    if (d.name == "mpid") {
      for (size_t i = 0; i < count; ++i) g.u[a].push_back(nextMpId++);
      continue;
    }
    if (d.type == AttrType::UInt) {
      for (size_t i = 0; i < count; ++i) g.u[a].push_back(uint32_t(rng.next()));
      continue;
    }
    int nc = componentCount(d.type);
    for (size_t i = 0; i < count * nc; ++i) {
      double v = spec.randomBits ? rng.uniform(-4.0, 4.0) : 0.25 * double(i % 7);
      if (d.name == "Oi" || d.codec == AttrCodec::Unorm16) v = rng.uniform(0.0, 1.0);
      g.f[a].push_back(float(v));
    }
  }
  return g;
}

void flatten(const OwnedGrid& g, const Schema& schema, FlatStore& out) {
  const size_t nMp = g.corners.size() / 4;
  const int mpidAttr = schema.find("mpid");
  const int K = int(g.positions.size() / g.numVertices);
  for (size_t m = 0; m < nMp; ++m) {
    FlatMp f;
    f.objectId = g.objectId, f.gridId = g.gridId, f.flags = g.flags, f.schedule = g.schedule;
    const uint32_t* c = &g.corners[m * 4];
    f.corners = c[3] == kNoCorner ? 3 : 4;
    for (int k = 0; k < K; ++k)
      for (int j = 0; j < 4; ++j) f.positions.push_back(c[j] == kNoCorner ? glm::vec3(0) : g.positions[size_t(k) * g.numVertices + c[j]]);
    f.attrF.resize(schema.attrs.size());
    f.attrU.resize(schema.attrs.size());
    for (size_t a = 0; a < schema.attrs.size(); ++a) {
      const auto& d = schema.attrs[a];
      int nc = componentCount(d.type);
      bool present = !g.f[a].empty() || !g.u[a].empty();
      if (!present) continue;
      if (d.rate == AttrRate::Micropolygon) {
        if (d.type == AttrType::UInt) f.attrU[a].push_back(g.u[a][m]);
        else
          for (int i = 0; i < nc; ++i) f.attrF[a].push_back(g.f[a][m * nc + i]);
      } else {
        for (int j = 0; j < f.corners; ++j) {
          if (d.type == AttrType::UInt) f.attrU[a].push_back(g.u[a][c[j]]);
          else
            for (int i = 0; i < nc; ++i) f.attrF[a].push_back(g.f[a][size_t(c[j]) * nc + i]);
        }
      }
    }
    out[g.u[size_t(mpidAttr)][m]] = std::move(f);
  }
}

FlatStore flatten(const StoreReader& reader) {
  FlatStore out;
  const Schema& schema = reader.meta().schema;
  const int mpidAttr = schema.find("mpid");
  for (size_t e = 0; e < reader.entries().size(); ++e) {
    TilePart part = reader.decode(e);
    const auto& entry = reader.entries()[e];
    for (uint32_t m = 0; m < part.numMicropolygons; ++m) {
      FlatMp f;
      f.objectId = part.objectId[m], f.gridId = part.gridId[m], f.flags = part.flags[m], f.schedule = entry.schedule;
      const uint32_t* c = &part.corners[size_t(m) * 4];
      f.corners = c[3] == kNoCorner ? 3 : 4;
      for (uint32_t k = 0; k < part.numKnots; ++k)
        for (int j = 0; j < 4; ++j) f.positions.push_back(c[j] == kNoCorner ? glm::vec3(0) : part.position(k, c[j]));
      f.attrF.resize(schema.attrs.size());
      f.attrU.resize(schema.attrs.size());
      for (size_t a = 0; a < schema.attrs.size(); ++a) {
        const auto& d = schema.attrs[a];
        const auto& arr = part.attrs[a];
        if (!arr.present()) continue;
        int nc = componentCount(d.type);
        if (d.rate == AttrRate::Micropolygon) {
          if (d.type == AttrType::UInt) f.attrU[a].push_back(arr.u[m]);
          else
            for (int i = 0; i < nc; ++i) f.attrF[a].push_back(arr.f[size_t(m) * nc + i]);
        } else {
          for (int j = 0; j < f.corners; ++j) {
            if (d.type == AttrType::UInt) f.attrU[a].push_back(arr.u[c[j]]);
            else
              for (int i = 0; i < nc; ++i) f.attrF[a].push_back(arr.f[size_t(c[j]) * nc + i]);
          }
        }
      }
      uint32_t id = part.attrs[size_t(mpidAttr)].u[m];
      EXPECT_EQ(out.count(id), 0u) << "micropolygon " << id << " stored twice";
      out[id] = std::move(f);
    }
  }
  return out;
}

}  // namespace reshutter::test
