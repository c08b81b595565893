#include "store/model.h"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <set>

#include "common/error.h"

namespace reshutter::store {

int componentCount(AttrType t) { return (t == AttrType::Float || t == AttrType::UInt) ? 1 : 3; }

const char* toString(AttrType t) {
  switch (t) {
    case AttrType::Float: return "float";
    case AttrType::Color: return "color";
    case AttrType::Point: return "point";
    case AttrType::Vector: return "vector";
    case AttrType::Normal: return "normal";
    case AttrType::UInt: return "uint";
  }
  return "?";
}
const char* toString(AttrRate r) { return r == AttrRate::Vertex ? "vertex" : "micropolygon"; }
const char* toString(AttrCodec c) {
  switch (c) {
    case AttrCodec::Lossless: return "lossless";
    case AttrCodec::Half: return "half";
    case AttrCodec::Unorm16: return "unorm16";
    case AttrCodec::Oct32: return "oct32";
  }
  return "?";
}
bool parseAttrType(const std::string& s, AttrType& out) {
  for (auto t : {AttrType::Float, AttrType::Color, AttrType::Point, AttrType::Vector, AttrType::Normal, AttrType::UInt})
    if (s == toString(t)) {
      out = t;
      return true;
    }
  return false;
}
bool parseAttrCodec(const std::string& s, AttrCodec& out) {
  for (auto c : {AttrCodec::Lossless, AttrCodec::Half, AttrCodec::Unorm16, AttrCodec::Oct32})
    if (s == toString(c)) {
      out = c;
      return true;
    }
  return false;
}

bool verticesStandStill(std::span<const glm::vec3> positions, size_t stride, size_t first, size_t count) {
  if (stride == 0 || count == 0) return true;
  const size_t bytes = count * sizeof(glm::vec3);
  for (size_t at = stride + first; at + count <= positions.size(); at += stride)
    if (std::memcmp(&positions[at], &positions[first], bytes) != 0) return false;
  return true;
}

bool GridInput::standsStill() const { return verticesStandStill(positions, numVertices, 0, numVertices); }

int Schema::find(const std::string& name) const {
  for (size_t i = 0; i < attrs.size(); ++i)
    if (attrs[i].name == name) return int(i);
  return -1;
}

void Camera::effectiveScreenWindow(double out[4]) const {
  if (screenWindow[0] != screenWindow[1] && screenWindow[2] != screenWindow[3]) {
    for (int i = 0; i < 4; ++i) out[i] = screenWindow[i];
    return;
  }
  double aspect = double(width) * pixelAspect / double(height);
  if (aspect >= 1.0) {
    out[0] = -aspect, out[1] = aspect, out[2] = -1, out[3] = 1;
  } else {
    out[0] = -1, out[1] = 1, out[2] = -1 / aspect, out[3] = 1 / aspect;
  }
}

bool Camera::operator==(const Camera& o) const {
  for (int i = 0; i < 4; ++i)
    if (screenWindow[i] != o.screenWindow[i]) return false;
  return name == o.name && projection == o.projection && fovDegrees == o.fovDegrees && width == o.width && height == o.height && pixelAspect == o.pixelAspect &&
         nearClip == o.nearClip && farClip == o.farClip && worldToCamera == o.worldToCamera && lens == o.lens && motionTimes == o.motionTimes &&
         motionWorldToCamera == o.motionWorldToCamera;
}

glm::dmat4 Camera::worldToCameraAt(double t) const {
  if (!moving()) return worldToCamera;
  const auto& T = motionTimes;
  if (t <= T.front()) return motionWorldToCamera.front();
  if (t >= T.back()) return motionWorldToCamera.back();
  const size_t i = size_t(std::upper_bound(T.begin(), T.end(), t) - T.begin()) - 1;
  const double w = (t - T[i]) / (T[i + 1] - T[i]);
  if (w == 0) return motionWorldToCamera[i];
  return motionWorldToCamera[i] * (1.0 - w) + motionWorldToCamera[i + 1] * w;
}

std::vector<double> unionTimes(const std::vector<double>& a, const std::vector<double>& b) {
  std::vector<double> t(a);
  t.insert(t.end(), b.begin(), b.end());
  std::sort(t.begin(), t.end());
  t.erase(std::unique(t.begin(), t.end()), t.end());
  return t;
}

std::vector<double> timesWithin(const std::vector<double>& times, double open, double close) {
  std::vector<double> t{open};
  for (double x : times)
    if (x > open && x < close) t.push_back(x);
  if (close > open) t.push_back(close);
  return t;
}

void Camera::clipMotion(double open, double close) {
  if (!moving()) return;
  std::vector<double> times = timesWithin(motionTimes, open, close);
  std::vector<glm::dmat4> mats;
  for (double t : times) mats.push_back(worldToCameraAt(t));
  worldToCamera = mats[0];
  const bool still = std::all_of(mats.begin(), mats.end(), [&](const glm::dmat4& m) { return m == mats[0]; });
  motionTimes = still ? std::vector<double>{} : std::move(times);
  motionWorldToCamera = still ? std::vector<glm::dmat4>{} : std::move(mats);
}

double circleOfConfusion(const Lens& lens, double z0, double z1) {
  if (!lens.active()) return 0.0;
  if (!(z0 > 0)) return INFINITY;
  const double invD = 1.0 / lens.focalDistance;
  return lens.radius() * std::max(std::abs(invD - 1.0 / z0), std::abs(invD - 1.0 / z1));
}

double circleOfConfusion(const Camera& camera, double z0, double z1) {
  return camera.projection == Projection::Perspective ? circleOfConfusion(camera.lens, z0, z1) : 0.0;
}

Projector::Projector(const Camera& cam) {
  double sw[4];
  cam.effectiveScreenWindow(sw);
  perspective = cam.projection == Projection::Perspective;
  double scale = perspective ? 1.0 / std::tan(cam.fovDegrees * M_PI / 360.0) : 1.0;
  ax = scale * cam.width / (sw[1] - sw[0]);
  bx = -sw[0] * cam.width / (sw[1] - sw[0]);
  ay = -scale * cam.height / (sw[3] - sw[2]);
  by = sw[3] * cam.height / (sw[3] - sw[2]);
  nearClip = cam.nearClip;
}

glm::dvec3 Projector::unproject(const glm::dvec2& r, double z) const {
  double iz = perspective ? z : 1.0;
  return {(r.x - bx) / ax * iz, (r.y - by) / ay * iz, z};
}

bool parseRational(const std::string& s, Rational& out) {
  if (s == "23.976" || s == "23.98") return out = {24000, 1001}, true;
  if (s == "29.97") return out = {30000, 1001}, true;
  if (s == "59.94") return out = {60000, 1001}, true;
  if (s == "47.952") return out = {48000, 1001}, true;
  if (s == "119.88") return out = {120000, 1001}, true;
  auto slash = s.find('/');
  try {
    size_t used = 0;
    if (slash == std::string::npos) {
      double v = std::stod(s, &used);
      if (used != s.size() || !(v > 0) || v > 1e6) return false;
      int64_t den = 1;
      while (std::abs(v * den - std::round(v * den)) > 1e-9 && den < 1000000) den *= 10;
      const int64_t num = int64_t(std::llround(v * den));
      if (num <= 0) return false;  // below a millionth: it would be the rate 0/N
      out = {num, den};
      return true;
    }
    int64_t num = std::stoll(s.substr(0, slash), &used);
    if (used != slash) return false;
    std::string d = s.substr(slash + 1);
    int64_t den = std::stoll(d, &used);
    if (used != d.size() || num <= 0 || den <= 0) return false;
    out = {num, den};
    return true;
  } catch (const std::exception&) {
    return false;
  }
}

bool StoredLight::illuminate(const glm::dvec3& P, glm::dvec3& L, glm::dvec3& Cl) const {
  switch (kind) {
    case Kind::Ambient: return false;
    case Kind::Distant: L = -axis, Cl = colour; return true;
    case Kind::Point:
    case Kind::Face:
    case Kind::Spot: {
      L = position - P;
      const double d2 = glm::dot(L, L);
      if (!(d2 > 0)) return false;
      const double cosine = -glm::dot(L, axis) / std::sqrt(d2);
      double atten = 1 / d2;
      if (kind == Kind::Face) {
        if (!(cosine > 0)) return false;
        atten *= cosine;
      } else if (kind == Kind::Spot) {
        // spotlight.sl's cone: smoothstep between the outer and inner cosines, cos^beam inside.
        if (cosine < cosOuter) return false;
        const double c = std::max(cosine, 0.0), u = std::clamp((cosine - cosOuter) / std::max(cosInner - cosOuter, 1e-12), 0.0, 1.0);
        atten *= std::pow(c, beam) * u * u * (3 - 2 * u);
      }
      Cl = colour * atten;
      return true;
    }
  }
  return false;
}

void StoreMeta::validate(const std::string& where) const {
  if (!std::isfinite(shutterOpen) || !std::isfinite(shutterClose) || shutterClose < shutterOpen)
    fail(where, "shutter [", shutterOpen, ", ", shutterClose, "] is not an interval");
  if (fps.num <= 0 || fps.den <= 0) fail(where, "frame rate ", fps.num, "/", fps.den, " is not positive");
  if (schedules.empty() || schedules[0].size() != 1) fail(where, "schedule 0 must be the static one-knot schedule");
  for (size_t s = 0; s < schedules.size(); ++s) {
    const auto& k = schedules[s];
    if (k.empty() || k.size() > 64) fail(where, "motion schedule ", s, " has ", k.size(), " knots (1 to 64 allowed)");
    for (size_t i = 0; i < k.size(); ++i) {
      if (!std::isfinite(k[i])) fail(where, "motion schedule ", s, ": knot time ", i, " is not finite");
      if (s > 0 && (k[i] < shutterOpen || k[i] > shutterClose))
        fail(where, "motion schedule ", s, ": knot time ", k[i], " lies outside the shutter [", shutterOpen, ", ", shutterClose, "]");
      if (i > 0 && !(k[i] > k[i - 1])) fail(where, "motion schedule ", s, ": knot times not strictly increasing (", k[i - 1], " then ", k[i], ")");
    }
  }
  if (cameras.empty()) fail(where, "no camera");
  for (const auto& c : cameras) {
    if (c.width <= 0 || c.height <= 0 || c.width > 1 << 20 || c.height > 1 << 20)
      fail(where, "camera '", c.name, "': resolution ", c.width, "x", c.height, " out of range");
    if (c.projection == Projection::Perspective && !(c.fovDegrees > 0 && c.fovDegrees < 180))
      fail(where, "camera '", c.name, "': field of view ", c.fovDegrees, " not in (0, 180)");
    if (!(c.pixelAspect > 0) || !std::isfinite(c.pixelAspect)) fail(where, "camera '", c.name, "': bad pixel aspect");
    if (!(c.nearClip > 0) || !(c.farClip > c.nearClip)) fail(where, "camera '", c.name, "': clipping planes ", c.nearClip, " ", c.farClip, " invalid");
    double sw[4];
    c.effectiveScreenWindow(sw);
    for (double v : sw)
      if (!std::isfinite(v)) fail(where, "camera '", c.name, "': screen window not finite");
    for (int i = 0; i < 4; ++i)
      for (int j = 0; j < 4; ++j)
        if (!std::isfinite(c.worldToCamera[i][j])) fail(where, "camera '", c.name, "': world-to-camera matrix not finite");
    if (c.motionTimes.size() != c.motionWorldToCamera.size() || c.motionTimes.size() == 1 || c.motionTimes.size() > 64)
      fail(where, "camera '", c.name, "': ", c.motionTimes.size(), " motion times for ", c.motionWorldToCamera.size(), " transforms (2 to 64 of each, or none)");
    for (size_t k = 0; k < c.motionTimes.size(); ++k) {
      const double t = c.motionTimes[k];
      if (!std::isfinite(t) || t < shutterOpen || t > shutterClose)
        fail(where, "camera '", c.name, "': motion time ", t, " lies outside the shutter [", shutterOpen, ", ", shutterClose, "]");
      if (k > 0 && !(t > c.motionTimes[k - 1])) fail(where, "camera '", c.name, "': motion times not strictly increasing");
      for (int i = 0; i < 4; ++i)
        for (int j = 0; j < 4; ++j)
          if (!std::isfinite(c.motionWorldToCamera[k][i][j])) fail(where, "camera '", c.name, "': world-to-camera matrix at time ", t, " not finite");
    }
  }
  if (tileSize < 4 || tileSize > 4096) fail(where, "tile size ", tileSize, " out of range (4 to 4096)");
  if (schema.attrs.size() > Schema::kMaxAttributes) fail(where, "schema has ", schema.attrs.size(), " attributes (at most ", Schema::kMaxAttributes, ")");
  std::set<std::string> names;
  for (const auto& a : schema.attrs) {
    if (a.name.empty()) fail(where, "attribute with an empty name");
    if (!names.insert(a.name).second) fail(where, "attribute '", a.name, "' declared twice");
    if (a.type == AttrType::UInt && a.codec != AttrCodec::Lossless) fail(where, "attribute '", a.name, "': uint attributes are lossless only");
    if (a.codec == AttrCodec::Oct32 && componentCount(a.type) != 3) fail(where, "attribute '", a.name, "': oct32 needs a 3-component type");
  }
  for (const char* required : {"Ci", "Oi"}) {
    int i = schema.find(required);
    if (i < 0) fail(where, "schema lacks '", required, "'");
    if (schema.attrs[size_t(i)].type != AttrType::Color) fail(where, "'", required, "' must be a color");
  }
  if (shadingTimes.size() > kMaxShadingTimes) fail(where, shadingTimes.size(), " shading times (at most ", kMaxShadingTimes, ")");
  // The later opacities may be left out, all of them (the first time's holds throughout).
  const bool laterOpacities = shadingTimes.size() > 1 && schema.find(timedName("Oi", 1)) >= 0;
  for (size_t k = 0; k < shadingTimes.size(); ++k) {
    if (!std::isfinite(shadingTimes[k])) fail(where, "shading time ", k, " is not finite");
    if (k > 0 && !(shadingTimes[k] > shadingTimes[k - 1]))
      fail(where, "shading times not strictly increasing (", shadingTimes[k - 1], " then ", shadingTimes[k], ")");
    for (const char* base : {"Ci", laterOpacities ? "Oi" : nullptr}) {
      if (k == 0 || !base) continue;
      const int i = schema.find(timedName(base, k));
      if (i < 0) fail(where, "shading time ", k, " has no '", timedName(base, k), "' in the schema");
      const AttrDecl& a = schema.attrs[size_t(i)];
      const AttrRate rate = schema.attrs[size_t(schema.find(base))].rate;
      if (a.type != AttrType::Color || a.rate != rate) fail(where, "'", a.name, "' must be a color given as often as '", base, "'");
    }
  }
  // Any other attribute at a shading time: its base declared alike, and it at every time.
  for (const AttrDecl& a : schema.attrs) {
    const size_t k = timedIndex(a.name);
    if (k == 0) continue;
    if (k >= std::max<size_t>(shadingTimes.size(), 1)) fail(where, "'", a.name, "' is for shading time ", k, ", but the store has ", shadingTimes.size());
    const std::string base = timedBase(a.name);
    const int bi = schema.find(base);
    if (bi < 0) fail(where, "'", a.name, "' has no '", base, "' in the schema");
    const AttrDecl& b = schema.attrs[size_t(bi)];
    if (a.type != b.type || a.rate != b.rate || a.codec != b.codec) fail(where, "'", a.name, "' must be declared as '", base, "' is");
    for (size_t j = 1; j < shadingTimes.size(); ++j)
      if (schema.find(timedName(base, j)) < 0) fail(where, "'", base, "' is given at shading time ", k, " but not at ", j);
  }
  auto finite3 = [](const glm::dvec3& v) { return std::isfinite(v.x) && std::isfinite(v.y) && std::isfinite(v.z); };
  for (size_t i = 0; i < lights.size(); ++i) {
    const StoredLight& l = lights[i];
    if (uint8_t(l.kind) > uint8_t(StoredLight::Kind::Face)) fail(where, "light ", i, " is of an unknown kind");
    if (!finite3(l.position) || !finite3(l.axis) || !finite3(l.colour) || !std::isfinite(l.cosOuter) || !std::isfinite(l.cosInner) || !std::isfinite(l.beam))
      fail(where, "light ", i, " has a value that is not finite");
  }
  for (size_t i = 0; i < volumes.size(); ++i) {
    const StoredVolume& v = volumes[i];
    if (v.path.empty() || v.density.empty()) fail(where, "volume ", i, " has no file or no density grid");
    if (v.times.empty() || v.times.size() != v.fileToCamera.size() || v.times.size() > 64)
      fail(where, "volume ", i, " has ", v.times.size(), " times and ", v.fileToCamera.size(), " transforms");
    for (size_t k = 0; k < v.times.size(); ++k) {
      if (!std::isfinite(v.times[k]) || (k > 0 && !(v.times[k] > v.times[k - 1]))) fail(where, "volume ", i, ": its times are not finite and increasing");
      for (int a = 0; a < 4; ++a)
        for (int b = 0; b < 4; ++b)
          if (!std::isfinite(v.fileToCamera[k][a][b])) fail(where, "volume ", i, ": a transform is not finite");
    }
  }
}

std::string StoreMeta::timedName(const std::string& base, size_t k) { return k == 0 ? base : base + "@" + std::to_string(k); }

size_t StoreMeta::timedIndex(const std::string& name) {
  const size_t at = name.rfind('@');
  if (at == std::string::npos || at == 0 || at + 1 == name.size()) return 0;
  size_t k = 0;
  for (size_t i = at + 1; i < name.size(); ++i) {
    if (name[i] < '0' || name[i] > '9' || k > kMaxShadingTimes) return 0;
    k = k * 10 + size_t(name[i] - '0');
  }
  return k;
}

std::string StoreMeta::timedBase(const std::string& name) { return timedIndex(name) ? name.substr(0, name.rfind('@')) : name; }

size_t TilePart::memoryBytes() const {
  size_t b = positions.size() * sizeof(glm::vec3) + corners.size() * 4 + objectId.size() * 4 + gridId.size() * 4 + flags.size();
  for (const auto& a : attrs) b += a.f.size() * 4 + a.u.size() * 4;
  return b + sizeof(TilePart);
}

}  // namespace reshutter::store
