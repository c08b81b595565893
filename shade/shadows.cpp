// The shadow scene in Embree and the visibility of a light (shade/shadows.h says what it promises).
#include "shade/shadows.h"

#include <algorithm>
#include <cmath>
#include <limits>

#include <embree3/rtcore.h>
#include <tbb/parallel_for.h>
#include <glm/geometric.hpp>

#include "common/error.h"
#include "common/random.h"
#include "store/model.h"

namespace reshutter::shade {

struct ShadowScene::Impl {
  RTCDevice device = nullptr;
  RTCScene scene = nullptr;
  ~Impl() {
    if (scene) rtcReleaseScene(scene);
    if (device) rtcReleaseDevice(device);
  }
};

namespace {
void check(RTCDevice device, const char* what) {
  const RTCError e = rtcGetDeviceError(device);
  if (e != RTC_ERROR_NONE) fail("shadows", "Embree could not ", what, " (error ", int(e), e == RTC_ERROR_OUT_OF_MEMORY ? ": out of memory" : "", ")");
}
}  // namespace

ShadowScene::ShadowScene(std::span<const Piece> pieces) : impl_(std::make_unique<Impl>()) {
  // Where each piece's vertices and micropolygons go in the one geometry.
  std::vector<uint64_t> vertexBase(pieces.size() + 1, 0), quadBase(pieces.size() + 1, 0);
  for (size_t i = 0; i < pieces.size(); ++i) {
    vertexBase[i + 1] = vertexBase[i] + pieces[i].P.size();
    quadBase[i + 1] = quadBase[i] + pieces[i].corners.size() / 4;
  }
  micropolygons_ = quadBase.back();
  if (vertexBase.back() > std::numeric_limits<uint32_t>::max()) fail("shadows", "the frame has more than 2^32 vertices at the shading time");
  impl_->device = rtcNewDevice(nullptr);
  if (!impl_->device) fail("shadows", "Embree could not start (rtcNewDevice)");
  impl_->scene = rtcNewScene(impl_->device);
  rtcSetSceneFlags(impl_->scene, RTC_SCENE_FLAG_ROBUST);
  rtcSetSceneBuildQuality(impl_->scene, RTC_BUILD_QUALITY_MEDIUM);
  if (micropolygons_ > 0) {
    RTCGeometry geom = rtcNewGeometry(impl_->device, RTC_GEOMETRY_TYPE_QUAD);
    auto* vertices = static_cast<float*>(rtcSetNewGeometryBuffer(geom, RTC_BUFFER_TYPE_VERTEX, 0, RTC_FORMAT_FLOAT3, 3 * sizeof(float), vertexBase.back()));
    auto* quads = static_cast<uint32_t*>(rtcSetNewGeometryBuffer(geom, RTC_BUFFER_TYPE_INDEX, 0, RTC_FORMAT_UINT4, 4 * sizeof(uint32_t), quadBase.back()));
    check(impl_->device, "allocate the shadow geometry");
    tbb::parallel_for(size_t(0), pieces.size(), [&](size_t i) {
      const Piece& p = pieces[i];
      float* v = vertices + 3 * vertexBase[i];
      for (const glm::vec3& P : p.P) *v++ = P.x, *v++ = P.y, *v++ = P.z;
      uint32_t* q = quads + 4 * quadBase[i];
      const auto base = uint32_t(vertexBase[i]);
      for (size_t m = 0; m + 4 <= p.corners.size(); m += 4) {
        const uint32_t* c = &p.corners[m];
        // Embree's quad is the triangles (v0 v1 v3) and (v2 v3 v1); a triangle repeats its last
        // corner, which leaves the second one empty.
        const uint32_t last = c[3] == store::kNoCorner ? c[2] : c[3];
        *q++ = base + c[0], *q++ = base + c[1], *q++ = base + c[2], *q++ = base + last;
      }
    });
    rtcCommitGeometry(geom);
    rtcAttachGeometry(impl_->scene, geom);
    rtcReleaseGeometry(geom);
  }
  rtcCommitScene(impl_->scene);
  check(impl_->device, "build the shadow scene");
}

ShadowScene::~ShadowScene() = default;

bool ShadowScene::occluded(const glm::dvec3& origin, const glm::dvec3& dir, double tfar) const {
  if (micropolygons_ == 0 || !(tfar > 0)) return false;
  RTCIntersectContext context;
  rtcInitIntersectContext(&context);
  RTCRay ray{};
  ray.org_x = float(origin.x), ray.org_y = float(origin.y), ray.org_z = float(origin.z);
  ray.dir_x = float(dir.x), ray.dir_y = float(dir.y), ray.dir_z = float(dir.z);
  ray.tnear = 0;
  ray.tfar = std::isfinite(tfar) ? float(tfar) : std::numeric_limits<float>::infinity();
  ray.mask = ~0u;
  rtcOccluded1(impl_->scene, &context, &ray);
  return ray.tfar == -std::numeric_limits<float>::infinity();
}

namespace {

/// Two unit vectors perpendicular to unit `w` and to each other.
void frame(const glm::dvec3& w, glm::dvec3& e1, glm::dvec3& e2) {
  const glm::dvec3 a = std::abs(w.x) < 0.9 ? glm::dvec3(1, 0, 0) : glm::dvec3(0, 1, 0);
  e1 = glm::normalize(glm::cross(a, w));
  e2 = glm::cross(w, e1);
}

/// Shirley and Chiu's concentric map from the unit square onto the unit disc (keeps strata
/// compact, so the stratified pattern stays stratified on the disc).
void concentric(double a, double b, double& x, double& y) {
  const double u = 2 * a - 1, v = 2 * b - 1;
  if (u == 0 && v == 0) return void(x = y = 0);
  constexpr double quarterPi = 0.78539816339744830962;
  if (std::abs(u) > std::abs(v)) x = u * std::cos(quarterPi * v / u), y = u * std::sin(quarterPi * v / u);
  else x = v * std::sin(quarterPi * u / v), y = v * std::cos(quarterPi * u / v);
}

double radicalInverse2(uint32_t i) {
  i = (i << 16) | (i >> 16);
  i = ((i & 0x00ff00ffu) << 8) | ((i & 0xff00ff00u) >> 8);
  i = ((i & 0x0f0f0f0fu) << 4) | ((i & 0xf0f0f0f0u) >> 4);
  i = ((i & 0x33333333u) << 2) | ((i & 0xccccccccu) >> 2);
  i = ((i & 0x55555555u) << 1) | ((i & 0xaaaaaaaau) >> 1);
  return double(i) * 0x1.0p-32;
}

}  // namespace

double lightVisibility(const ShadowScene& scene, const LitLight& light, const glm::dvec3& P, const glm::dvec3& Ng, double bias, int samples, uint64_t seed,
                       uint64_t& rays) {
  if (!light.shadows || light.kind == LightKind::Ambient) return 1.0;
  const bool directional = light.kind == LightKind::Distant || (light.kind == LightKind::Uber && light.uber.parallel);
  const glm::dvec3 towardCentre = directional ? -light.axis : light.position - P;
  // Lift the origin off the diced surface on the side the light is.
  const glm::dvec3 origin = P + (glm::dot(Ng, towardCentre) >= 0 ? bias : -bias) * Ng;
  const bool area = light.kind == LightKind::Distant ? light.tanHalfAngle > 0 : light.shape != LightShape::Point;
  const int n = area ? std::max(samples, 1) : 1;
  // A point's own rotation of the Hammersley set (Cranley-Patterson).
  const uint64_t h = mix64(seed);
  const double rotA = toUnitDouble(h), rotB = toUnitDouble(mix64(h ^ 0x5851F42D4C957F2Dull));
  glm::dvec3 e1, e2;
  if (light.kind == LightKind::Distant) frame(-light.axis, e1, e2);
  else if (light.shape == LightShape::Sphere) {
    const double d = glm::length(towardCentre);
    frame(d > 0 ? towardCentre / d : glm::dvec3(0, 0, 1), e1, e2);
  }
  int visible = 0;
  for (int k = 0; k < n; ++k) {
    double a = 0.5, b = 0.5;
    if (area) {
      a = (k + 0.5) / n + rotA, b = radicalInverse2(uint32_t(k)) + rotB;
      a -= std::floor(a), b -= std::floor(b);
    }
    glm::dvec3 dir;
    double tfar;
    if (directional) {
      double x = 0, y = 0;
      if (area) concentric(a, b, x, y);
      dir = glm::normalize(-light.axis + light.tanHalfAngle * (x * e1 + y * e2));
      tfar = std::numeric_limits<double>::infinity();
    } else {
      glm::dvec3 target = light.position;
      if (light.shape == LightShape::Rect) {
        target += (2 * a - 1) * light.halfU + (2 * b - 1) * light.halfV;
      } else if (light.shape != LightShape::Point) {
        double x, y;
        concentric(a, b, x, y);
        // A sphere is seen as the disc across it facing the point.
        target += light.shape == LightShape::Disk ? x * light.halfU + y * light.halfV : glm::length(light.halfU) * (x * e1 + y * e2);
      }
      const glm::dvec3 d = target - origin;
      const double len = glm::length(d);
      if (!(len > 0)) continue;
      dir = d / len;
      tfar = len * (1 - 1e-6);  // stop short of the emitter, which may itself be geometry
    }
    ++rays;
    visible += !scene.occluded(origin, dir, tfar);
  }
  return double(visible) / n;
}

}  // namespace reshutter::shade
