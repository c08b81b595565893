#include "store/format.h"

#include <algorithm>
#include <cmath>
#include <vector>

namespace reshutter::store {

std::string effectNames(uint32_t e) {
  static const std::pair<uint32_t, const char*> names[] = {{kEffectMoving, "moving"},
                                                           {kEffectTransparent, "transparent"},
                                                           {kEffectMatte, "matte"},
                                                           {kEffectTwoSided, "two-sided"},
                                                           {kEffectTriangles, "triangles"},
                                                           {kEffectNearCrossing, "near-crossing"},
                                                           {kEffectColouredOpacity, "coloured-opacity"},
                                                           {kEffectShadedInTime, "shaded-in-time"}};
  std::string s;
  for (auto [bit, name] : names)
    if (e & bit) s += (s.empty() ? "" : " ") + std::string(name);
  return s.empty() ? "static opaque" : s;
}

void RasterRect::extend(const RasterRect& o) {
  if (o.empty) return;
  if (empty) {
    *this = o;
    return;
  }
  x0 = std::min(x0, o.x0), y0 = std::min(y0, o.y0), x1 = std::max(x1, o.x1), y1 = std::max(y1, o.y1);
}

namespace {
// Float conversion that never shrinks the box.
float down(double v) {
  if (!(v > -1e30)) return -1e30f;
  if (v > 1e30) return 1e30f;
  float f = float(v);
  return double(f) > v ? std::nextafter(f, -INFINITY) : f;
}
float up(double v) {
  if (!(v < 1e30)) return 1e30f;
  if (v < -1e30) return -1e30f;
  float f = float(v);
  return double(f) < v ? std::nextafter(f, INFINITY) : f;
}
}  // namespace

RasterRect projectCameraBox(const float b[6], const Projector& p) {
  double x0 = b[0], y0 = b[1], z0 = b[2], x1 = b[3], y1 = b[4], z1 = b[5];
  double sx0, sx1, sy0, sy1;
  if (p.perspective) {
    if (z1 < p.nearClip) return {};
    z0 = std::max(z0, p.nearClip);
    // x/z over the box is extremal at its corners (monotone in x and in z for z > 0).
    sx0 = std::min(x0 / z0, x0 / z1), sx1 = std::max(x1 / z0, x1 / z1);
    sy0 = std::min(y0 / z0, y0 / z1), sy1 = std::max(y1 / z0, y1 / z1);
  } else {
    sx0 = x0, sx1 = x1, sy0 = y0, sy1 = y1;
  }
  double rx0 = p.ax * sx0 + p.bx, rx1 = p.ax * sx1 + p.bx;
  double ry0 = p.ay * sy0 + p.by, ry1 = p.ay * sy1 + p.by;
  RasterRect r;
  r.x0 = down(std::min(rx0, rx1)), r.x1 = up(std::max(rx0, rx1));
  r.y0 = down(std::min(ry0, ry1)), r.y1 = up(std::max(ry0, ry1));
  r.empty = false;
  return r;
}

void knotRange(const Schedule& s, double t0, double t1, size_t& first, size_t& last) {
  first = 0;
  last = s.size() - 1;
  while (first + 1 < s.size() && s[first + 1] <= t0) ++first;
  while (last > first && s[last - 1] >= t1) --last;
}

namespace {
// The camera-space box of a part at time t inside knot segment [k, k + 1].
void lerpedBox(const TileEntry& e, const Schedule& s, size_t k, double t, float out[6]) {
  lerpedCameraBox(e.knots[k].camera, e.knots[k + 1].camera, std::clamp((t - s[k]) / (s[k + 1] - s[k]), 0.0, 1.0), out);
}
}  // namespace

void lerpedCameraBox(const float a[6], const float b[6], double f, float out[6]) {
  for (int i = 0; i < 6; ++i) {
    const double v = double(a[i]) + f * (double(b[i]) - double(a[i]));
    const double pad = 1e-6 * std::abs(v) + 1e-30;
    out[i] = i < 3 ? down(v - pad) : up(v + pad);
  }
}

RasterRect boundsOver(const TileEntry& e, const Schedule& s, const Projector& p, double t0, double t1) {
  size_t first, last;
  knotRange(s, t0, t1, first, last);
  bool finite = true;
  for (size_t k = first; k <= last; ++k) finite = finite && e.knots[k].rasterFinite;
  RasterRect r;
  if (finite) {
    for (size_t k = first; k <= last; ++k) {
      const float* b = e.knots[k].raster;
      r.extend(RasterRect{b[0], b[1], b[2], b[3], false});
    }
  } else {
    float box[6] = {INFINITY, INFINITY, INFINITY, -INFINITY, -INFINITY, -INFINITY};
    for (size_t k = first; k <= last; ++k)
      for (int i = 0; i < 3; ++i) {
        box[i] = std::min(box[i], e.knots[k].camera[i]);
        box[i + 3] = std::max(box[i + 3], e.knots[k].camera[i + 3]);
      }
    r = projectCameraBox(box, p);
  }
  if (s.size() < 2 || r.empty || t0 > t1) return r;
  // A sub-interval that ends inside a segment: bound it by the boxes at t0 and t1 and at the
  // knots between. Each vertex's path over [t0, t1] is a polyline through points of those boxes,
  // so while they all lie in front of the eye its projection stays in their projections' union;
  // otherwise the union of the boxes, near-clipped, is projected. Intersected with the knot bound
  // above (both hold), so it is never looser than before.
  const bool innerStart = t0 > s[first] && first + 1 < s.size(), innerEnd = t1 < s[last] && last > 0;
  if (!innerStart && !innerEnd) return r;
  float b0[6], b1[6];
  if (innerStart) lerpedBox(e, s, first, t0, b0);
  else std::copy(e.knots[first].camera, e.knots[first].camera + 6, b0);
  if (innerEnd) lerpedBox(e, s, last - 1, t1, b1);
  else std::copy(e.knots[last].camera, e.knots[last].camera + 6, b1);
  std::vector<const float*> boxes{b0, b1};
  for (size_t k = first + 1; k < last; ++k) boxes.push_back(e.knots[k].camera);
  RasterRect tight;
  bool inFront = true;
  for (const float* b : boxes) inFront = inFront && (!p.perspective || b[2] >= p.nearClip);
  if (inFront) {
    for (const float* b : boxes) tight.extend(projectCameraBox(b, p));
  } else {
    float box[6] = {INFINITY, INFINITY, INFINITY, -INFINITY, -INFINITY, -INFINITY};
    for (const float* b : boxes)
      for (int i = 0; i < 3; ++i) box[i] = std::min(box[i], b[i]), box[i + 3] = std::max(box[i + 3], b[i + 3]);
    tight = projectCameraBox(box, p);
  }
  if (tight.empty) return tight;
  RasterRect out{std::max(r.x0, tight.x0), std::max(r.y0, tight.y0), std::min(r.x1, tight.x1), std::min(r.y1, tight.y1), false};
  if (out.x0 > out.x1 || out.y0 > out.y1) return RasterRect{};
  return out;
}

namespace {
// A 4×4 matrix as 16 doubles, column by column (glm's order).
void putMatrix(ByteWriter& w, const glm::dmat4& m) {
  for (int i = 0; i < 4; ++i)
    for (int j = 0; j < 4; ++j) w.put<double>(m[i][j]);
}
glm::dmat4 getMatrix(ByteReader& r) {
  glm::dmat4 m;
  for (int i = 0; i < 4; ++i)
    for (int j = 0; j < 4; ++j) m[i][j] = r.get<double>();
  return m;
}
// A count, then per time the time and its matrix (a volume's placement, a camera's motion).
void putTimedMatrices(ByteWriter& w, const std::vector<double>& times, const std::vector<glm::dmat4>& mats) {
  w.put<uint32_t>(uint32_t(times.size()));
  for (size_t k = 0; k < times.size(); ++k) w.put<double>(times[k]), putMatrix(w, mats[k]);
}
void getTimedMatrices(ByteReader& r, std::vector<double>& times, std::vector<glm::dmat4>& mats) {
  const size_t n = r.getCount(136);
  times.resize(n), mats.resize(n);
  for (size_t k = 0; k < n; ++k) times[k] = r.get<double>(), mats[k] = getMatrix(r);
}
}  // namespace

void writeMeta(const StoreMeta& m, ByteWriter& w) {
  w.put<int64_t>(m.frame);
  w.put<int64_t>(m.fps.num);
  w.put<int64_t>(m.fps.den);
  w.put<double>(m.shutterOpen);
  w.put<double>(m.shutterClose);
  w.put<uint32_t>(uint32_t(m.schedules.size()));
  for (const auto& s : m.schedules) {
    w.put<uint32_t>(uint32_t(s.size()));
    for (double t : s) w.put<double>(t);
  }
  w.put<uint32_t>(uint32_t(m.cameras.size()));
  for (const auto& c : m.cameras) {
    w.putString(c.name);
    w.put<uint8_t>(uint8_t(c.projection));
    w.put<double>(c.fovDegrees);
    w.put<int32_t>(c.width);
    w.put<int32_t>(c.height);
    w.put<double>(c.pixelAspect);
    for (double v : c.screenWindow) w.put<double>(v);
    w.put<double>(c.nearClip);
    w.put<double>(c.farClip);
    putMatrix(w, c.worldToCamera);
  }
  w.put<uint32_t>(uint32_t(m.schema.attrs.size()));
  for (const auto& a : m.schema.attrs) {
    w.putString(a.name);
    w.put<uint8_t>(uint8_t(a.type));
    w.put<uint8_t>(uint8_t(a.rate));
    w.put<uint8_t>(uint8_t(a.codec));
  }
  w.put<int32_t>(m.tileSize);
  w.putString(m.provenance);
  const uint32_t version = formatVersionFor(m);
  if (version >= 2) {
    w.put<uint32_t>(uint32_t(m.shadingTimes.size()));
    for (double t : m.shadingTimes) w.put<double>(t);
    w.put<uint64_t>(m.shadedInTimeGrids);
  }
  if (version >= 3) {
    auto put3 = [&](const glm::dvec3& v) { w.put<double>(v.x), w.put<double>(v.y), w.put<double>(v.z); };
    w.put<uint32_t>(uint32_t(m.lights.size()));
    for (const StoredLight& l : m.lights) {
      w.put<uint8_t>(uint8_t(l.kind));
      put3(l.position), put3(l.axis), put3(l.colour);
      w.put<double>(l.cosOuter), w.put<double>(l.cosInner), w.put<double>(l.beam);
    }
    w.put<uint32_t>(uint32_t(m.volumes.size()));
    for (const StoredVolume& v : m.volumes) {
      w.putString(v.path), w.putString(v.density);
      putTimedMatrices(w, v.times, v.fileToCamera);
    }
  }
  if (version >= 4)
    for (const Camera& c : m.cameras) {
      const Lens lens = c.lens.active() ? c.lens : Lens{};  // an inactive lens is stored as the pinhole
      w.put<double>(lens.fstop), w.put<double>(lens.focalLength), w.put<double>(lens.focalDistance);
    }
  if (version >= 5)
    for (const Camera& c : m.cameras) putTimedMatrices(w, c.motionTimes, c.motionWorldToCamera);
}

uint32_t formatVersionFor(const StoreMeta& m) {
  for (const Camera& c : m.cameras)
    if (c.moving()) return 5;
  for (const Camera& c : m.cameras)
    if (c.lens.active()) return 4;
  if (!m.lights.empty() || !m.volumes.empty()) return 3;
  return m.shadingTimes.empty() ? 1 : 2;
}

StoreMeta readMeta(ByteReader& r, uint32_t version) {
  StoreMeta m;
  m.frame = r.get<int64_t>();
  m.fps.num = r.get<int64_t>();
  m.fps.den = r.get<int64_t>();
  m.shutterOpen = r.get<double>();
  m.shutterClose = r.get<double>();
  m.schedules.resize(r.getCount(4));
  for (auto& s : m.schedules) {
    s.resize(r.getCount(8));
    for (double& t : s) t = r.get<double>();
  }
  m.cameras.resize(r.getCount(8));
  for (auto& c : m.cameras) {
    c.name = r.getString(4096);
    uint8_t proj = r.get<uint8_t>();
    if (proj > 1) fail(r.context(), "unknown projection ", int(proj));
    c.projection = Projection(proj);
    c.fovDegrees = r.get<double>();
    c.width = r.get<int32_t>();
    c.height = r.get<int32_t>();
    c.pixelAspect = r.get<double>();
    for (double& v : c.screenWindow) v = r.get<double>();
    c.nearClip = r.get<double>();
    c.farClip = r.get<double>();
    c.worldToCamera = getMatrix(r);
  }
  m.schema.attrs.resize(r.getCount(7));
  for (auto& a : m.schema.attrs) {
    a.name = r.getString(4096);
    uint8_t t = r.get<uint8_t>(), rate = r.get<uint8_t>(), codec = r.get<uint8_t>();
    if (t > 5 || rate > 1 || codec > 3) fail(r.context(), "attribute '", a.name, "' has an unknown type, rate or codec");
    a.type = AttrType(t), a.rate = AttrRate(rate), a.codec = AttrCodec(codec);
  }
  m.tileSize = r.get<int32_t>();
  m.provenance = r.getString();
  if (version >= 2) {
    m.shadingTimes.resize(r.getCount(8));
    for (double& t : m.shadingTimes) t = r.get<double>();
    m.shadedInTimeGrids = r.get<uint64_t>();
    if (version == 2 && m.shadingTimes.empty()) fail(r.context(), "format version 2 without shading times");
  }
  if (version >= 3) {
    auto get3 = [&] {
      glm::dvec3 v;
      v.x = r.get<double>(), v.y = r.get<double>(), v.z = r.get<double>();
      return v;
    };
    m.lights.resize(r.getCount(73));
    for (StoredLight& l : m.lights) {
      const uint8_t kind = r.get<uint8_t>();
      if (kind > uint8_t(StoredLight::Kind::Face)) fail(r.context(), "light of unknown kind ", int(kind));
      l.kind = StoredLight::Kind(kind);
      l.position = get3(), l.axis = get3(), l.colour = get3();
      l.cosOuter = r.get<double>(), l.cosInner = r.get<double>(), l.beam = r.get<double>();
    }
    m.volumes.resize(r.getCount(12));
    for (StoredVolume& v : m.volumes) {
      v.path = r.getString(4096), v.density = r.getString(4096);
      getTimedMatrices(r, v.times, v.fileToCamera);
    }
  }
  if (version >= 4) {
    for (Camera& c : m.cameras) {
      c.lens.fstop = r.get<double>(), c.lens.focalLength = r.get<double>(), c.lens.focalDistance = r.get<double>();
      const bool pinhole = c.lens.fstop == 0 && c.lens.focalLength == 0 && c.lens.focalDistance == 0;
      if (!pinhole && !c.lens.active()) fail(r.context(), "camera '", c.name, "' has an invalid lens");
    }
  }
  if (version >= 5) {
    for (Camera& c : m.cameras) getTimedMatrices(r, c.motionTimes, c.motionWorldToCamera);
  }
  if (!r.atEnd()) fail(r.context(), "unexpected bytes after the metadata");
  m.validate(r.context());
  return m;
}

void writeIndex(const std::vector<TileEntry>& entries, const StoreMeta& meta, ByteWriter& w) {
  w.put<uint64_t>(entries.size());
  for (const auto& e : entries) {
    w.put<int32_t>(e.tx);
    w.put<int32_t>(e.ty);
    w.put<uint32_t>(e.schedule);
    w.put<uint32_t>(e.numMicropolygons);
    w.put<uint32_t>(e.numVertices);
    w.put<uint32_t>(e.effects);
    w.put<uint64_t>(e.attrPresence);
    w.put<uint64_t>(e.offset);
    w.put<uint32_t>(e.compressedSize);
    w.put<uint32_t>(e.rawSize);
    w.put<uint64_t>(e.checksum);
    (void)meta;
    for (const auto& k : e.knots) {
      for (float v : k.raster) w.put<float>(v);
      for (float v : k.camera) w.put<float>(v);
      w.put<uint8_t>(k.rasterFinite ? 1 : 0);
    }
  }
}

std::vector<TileEntry> readIndex(ByteReader& r, const StoreMeta& meta) {
  uint64_t n = r.get<uint64_t>();
  constexpr size_t kMinEntryBytes = 56 + 41;  // fixed fields + one knot
  if (n > r.remaining() / kMinEntryBytes) fail(r.context(), "entry count ", n, " exceeds the data present");
  std::vector<TileEntry> entries(n);
  for (size_t i = 0; i < n; ++i) {
    auto& e = entries[i];
    e.tx = r.get<int32_t>();
    e.ty = r.get<int32_t>();
    e.schedule = r.get<uint32_t>();
    e.numMicropolygons = r.get<uint32_t>();
    e.numVertices = r.get<uint32_t>();
    e.effects = r.get<uint32_t>();
    e.attrPresence = r.get<uint64_t>();
    e.offset = r.get<uint64_t>();
    e.compressedSize = r.get<uint32_t>();
    e.rawSize = r.get<uint32_t>();
    e.checksum = r.get<uint64_t>();
    auto where = [&] { return cat(r.context(), " entry ", i, " (tile ", e.tx, ",", e.ty, ")"); };
    if (e.schedule >= meta.schedules.size()) fail(where(), "names motion schedule ", e.schedule, " of ", meta.schedules.size());
    if (e.numMicropolygons > kMaxPartMicropolygons || e.numVertices > kMaxPartVertices)
      fail(where(), "implausible counts (", e.numMicropolygons, " micropolygons, ", e.numVertices, " vertices)");
    if (meta.schema.attrs.size() < 64 && (e.attrPresence >> meta.schema.attrs.size()) != 0) fail(where(), "marks attributes the schema does not declare");
    e.knots.resize(meta.schedules[e.schedule].size());
    for (auto& k : e.knots) {
      for (float& v : k.raster) v = r.get<float>();
      for (float& v : k.camera) v = r.get<float>();
      uint8_t f = r.get<uint8_t>();
      if (f > 1) fail(where(), "bad bounds flag");
      k.rasterFinite = f != 0;
      for (float v : k.raster)
        if (std::isnan(v)) fail(where(), "bounds are NaN");
      for (float v : k.camera)
        if (std::isnan(v)) fail(where(), "bounds are NaN");
    }
  }
  if (!r.atEnd()) fail(r.context(), "unexpected bytes after the index");
  return entries;
}

}  // namespace reshutter::store
