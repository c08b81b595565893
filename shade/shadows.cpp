// The shadow scene in Embree and the visibility of a light (shade/shadows.h says what it promises).
#include "shade/shadows.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <map>
#include <numbers>

#include <embree3/rtcore.h>
#include <tbb/parallel_for.h>
#include <glm/geometric.hpp>

#include "common/error.h"
#include "common/random.h"
#include "store/model.h"

namespace reshutter::shade {

struct ShadowScene::Impl {
  RTCDevice device = nullptr;
  RTCScene still = nullptr;
  RTCScene deforming = nullptr;  // the pieces whose vertices move, in time steps (only when some do)
  RTCScene rigid = nullptr;      // the rigidly moving pieces' BVHs, instanced with motion-blurred transforms
  std::vector<RTCScene> instanced;  // those pieces' own BVHs
  // `rigid` at each of the chosen times, its transforms fixed: a ray through a static instance
  // skips the blend and inversion of a matrix per instance and the motion boxes per BVH node.
  std::vector<double> fixedAt;
  std::vector<RTCScene> fixed;
  // Per fixed time, everything at once: `still` and `deforming` instanced as they are and the
  // rigid casters fixed there - one traversal for a ray that needs both answers only together.
  std::vector<RTCScene> whole;
  double open = 0, close = 0;  // the moving pieces' interval (Embree's ray time 0 to 1)
  /// Embree's ray time (0 to 1 over the interval) of a time in frames.
  float rayTime(double time) const {
    const double span = close - open;
    return span > 0 ? float(std::clamp((time - open) / span, 0.0, 1.0)) : 0.f;
  }
  /// Which of `fixedAt` is exactly `time`; -1 for none.
  int fixedIndex(double time) const {
    for (size_t k = 0; k < fixedAt.size(); ++k)
      if (fixedAt[k] == time) return int(k);
    return -1;
  }
  ~Impl() {
    for (RTCScene s : {still, deforming, rigid})
      if (s) rtcReleaseScene(s);
    for (RTCScene s : fixed) rtcReleaseScene(s);
    for (RTCScene s : whole) rtcReleaseScene(s);
    for (RTCScene s : instanced) rtcReleaseScene(s);
    if (device) rtcReleaseDevice(device);
  }
};

namespace {
void check(RTCDevice device, const char* what) {
  const RTCError e = rtcGetDeviceError(device);
  if (e != RTC_ERROR_NONE) fail("shadows", "Embree could not ", what, " (error ", int(e), e == RTC_ERROR_OUT_OF_MEMORY ? ": out of memory" : "", ")");
}
}  // namespace

namespace {

// Where piece `p`'s vertices are at Embree time step `step` of `steps` over [open, close]: its own
// knots when they are the steps, else linear between its knots (positions are linear between
// knots, so resampling keeps each path's shape up to the steps' spacing).
void stepPositions(const ShadowScene::Piece& p, size_t nV, unsigned step, unsigned steps, double open, double close, float* out) {
  const size_t K = std::max<size_t>(1, p.knots.size());
  auto put = [&](size_t v, const glm::vec3& P) { out[3 * v] = P.x, out[3 * v + 1] = P.y, out[3 * v + 2] = P.z; };
  if (K == 1 || steps == 1 || steps == K) {
    const size_t k = K == 1 || steps == 1 ? 0 : step;
    for (size_t v = 0; v < nV; ++v) put(v, p.P[k * nV + v]);
    return;
  }
  size_t k;
  double w;
  locate(p.knots, open + (close - open) * double(step) / double(steps - 1), k, w);
  const float f = float(w);
  for (size_t v = 0; v < nV; ++v) {
    const glm::vec3& a = p.P[k * nV + v];
    put(v, a + f * (p.P[(k + 1) * nV + v] - a));
  }
}

// Embree time steps for positions at `knots` over [open, close]: the knots when they are evenly
// spread over it, else twice as many even steps.
unsigned stepsForKnots(const std::vector<double>& knots, double open, double close) {
  const size_t K = knots.size();
  if (K <= 1 || !(close > open)) return 1;
  const double span = close - open;
  bool even = std::abs(knots.front() - open) <= 1e-9 * span && std::abs(knots.back() - close) <= 1e-9 * span;
  for (size_t k = 0; even && k < K; ++k) even = std::abs(knots[k] - (open + span * double(k) / double(K - 1))) <= 1e-9 * span;
  return unsigned(even ? K : std::min<size_t>(2 * K, 129));
}

// Embree time steps for a piece: 1 when it stands still, else as stepsForKnots.
unsigned stepsFor(const ShadowScene::Piece& p, double open, double close) {
  const size_t K = p.knots.size();
  if (K <= 1 || !(close > open)) return 1;
  const size_t nV = p.P.size() / K;
  if (store::verticesStandStill(p.P, nV, 0, nV)) return 1;
  return stepsForKnots(p.knots, open, close);
}

}  // namespace

ShadowScene::ShadowScene(std::span<const Piece> pieces, double open, double close, std::span<const RigidMotion> rigid, std::span<const double> fixAt)
    : impl_(std::make_unique<Impl>()) {
  impl_->open = open, impl_->close = close;
  impl_->device = rtcNewDevice(nullptr);
  if (!impl_->device) fail("shadows", "Embree could not start (rtcNewDevice)");
  auto newScene = [&] {
    RTCScene scene = rtcNewScene(impl_->device);
    rtcSetSceneFlags(scene, RTC_SCENE_FLAG_ROBUST);
    rtcSetSceneBuildQuality(scene, RTC_BUILD_QUALITY_MEDIUM);
    return scene;
  };
  auto ensure = [&](RTCScene& scene) {
    if (!scene) scene = newScene();
    return scene;
  };
  impl_->still = newScene();
  // One quad geometry of `members`' micropolygons in `steps` time steps (a geometry's vertex
  // buffers are its steps), into `scene`.
  auto attachQuads = [&](RTCScene scene, const std::vector<size_t>& members, unsigned steps) {
    // Where each member's vertices and micropolygons go in the geometry.
    std::vector<uint64_t> vertexBase(members.size() + 1, 0), quadBase(members.size() + 1, 0);
    for (size_t j = 0; j < members.size(); ++j) {
      const Piece& p = pieces[members[j]];
      vertexBase[j + 1] = vertexBase[j] + p.P.size() / std::max<size_t>(1, p.knots.size());
      quadBase[j + 1] = quadBase[j] + p.corners.size() / 4;
    }
    micropolygons_ += quadBase.back();
    if (vertexBase.back() > std::numeric_limits<uint32_t>::max()) fail("shadows", "the frame has more than 2^32 vertices in one shadow geometry");
    RTCGeometry geom = rtcNewGeometry(impl_->device, RTC_GEOMETRY_TYPE_QUAD);
    if (steps > 1) rtcSetGeometryTimeStepCount(geom, steps);
    std::vector<float*> vertices(steps);
    for (unsigned s = 0; s < steps; ++s)
      vertices[s] = static_cast<float*>(rtcSetNewGeometryBuffer(geom, RTC_BUFFER_TYPE_VERTEX, s, RTC_FORMAT_FLOAT3, 3 * sizeof(float), vertexBase.back()));
    auto* quads = static_cast<uint32_t*>(rtcSetNewGeometryBuffer(geom, RTC_BUFFER_TYPE_INDEX, 0, RTC_FORMAT_UINT4, 4 * sizeof(uint32_t), quadBase.back()));
    check(impl_->device, "allocate the shadow geometry");
    tbb::parallel_for(size_t(0), members.size(), [&](size_t j) {
      const Piece& p = pieces[members[j]];
      const size_t nV = size_t(vertexBase[j + 1] - vertexBase[j]);
      for (unsigned s = 0; s < steps; ++s) stepPositions(p, nV, s, steps, open, close, vertices[s] + 3 * vertexBase[j]);
      uint32_t* q = quads + 4 * quadBase[j];
      const auto base = uint32_t(vertexBase[j]);
      for (size_t m = 0; m + 4 <= p.corners.size(); m += 4) {
        const uint32_t* c = &p.corners[m];
        // Embree's quad is the triangles (v0 v1 v3) and (v2 v3 v1); a triangle repeats its last
        // corner, which leaves the second one empty.
        const uint32_t last = c[3] == store::kNoCorner ? c[2] : c[3];
        *q++ = base + c[0], *q++ = base + c[1], *q++ = base + c[2], *q++ = base + last;
      }
    });
    rtcCommitGeometry(geom);
    rtcAttachGeometry(scene, geom);
    rtcReleaseGeometry(geom);
    return quadBase.back();
  };
  std::map<unsigned, std::vector<size_t>> groups;
  std::vector<std::vector<size_t>> rigidMembers(rigid.size());
  const bool interval = close > open;
  for (size_t i = 0; i < pieces.size(); ++i) {
    if (pieces[i].corners.empty()) continue;
    const int r = pieces[i].rigid;
    if (r >= 0 && size_t(r) < rigid.size() && interval && rigid[size_t(r)].moving()) rigidMembers[size_t(r)].push_back(i);
    else if (r >= 0) fail("shadows", "a piece names rigid motion ", r, " of ", rigid.size(), " outside an interval that moves it");
    else groups[stepsFor(pieces[i], open, close)].push_back(i);
  }
  for (const auto& [steps, members] : groups) attachQuads(steps > 1 ? ensure(impl_->deforming) : impl_->still, members, steps);
  auto setTransform = [](RTCGeometry instance, unsigned step, const glm::dmat4& m) {
    float columns[12];
    for (int c = 0; c < 4; ++c)
      for (int row = 0; row < 3; ++row) columns[3 * c + row] = float(m[c][row]);
    rtcSetGeometryTransform(instance, step, RTC_FORMAT_FLOAT3X4_COLUMN_MAJOR, columns);
  };
  // An instance of `local` with the transform `m` at every step, into each of `scenes`.
  auto attachStatic = [&](RTCScene local, const glm::dmat4& m, std::initializer_list<RTCScene> scenes) {
    RTCGeometry instance = rtcNewGeometry(impl_->device, RTC_GEOMETRY_TYPE_INSTANCE);
    rtcSetGeometryInstancedScene(instance, local);
    setTransform(instance, 0, m);
    rtcCommitGeometry(instance);
    for (RTCScene scene : scenes) rtcAttachGeometry(scene, instance);
    rtcReleaseGeometry(instance);
  };
  if (interval) impl_->fixedAt.assign(fixAt.begin(), fixAt.end());
  impl_->fixed.assign(impl_->fixedAt.size(), nullptr), impl_->whole.assign(impl_->fixedAt.size(), nullptr);
  for (size_t r = 0; r < rigid.size(); ++r) {
    if (rigidMembers[r].empty()) continue;
    const RigidMotion& motion = rigid[r];
    if (motion.mats.size() != motion.times.size()) fail("shadows", "rigid motion ", r, " has ", motion.mats.size(), " transforms for ", motion.times.size(), " knots");
    RTCScene local = newScene();
    impl_->instanced.push_back(local);
    rigidMicropolygons_ += attachQuads(local, rigidMembers[r], 1);
    rtcCommitScene(local);
    ++rigidInstances_;
    RTCGeometry instance = rtcNewGeometry(impl_->device, RTC_GEOMETRY_TYPE_INSTANCE);
    rtcSetGeometryInstancedScene(instance, local);
    const unsigned steps = stepsForKnots(motion.times, open, close);
    rtcSetGeometryTimeStepCount(instance, steps);
    // The blend of the knots' matrices at each step's time, as stepPositions() blends positions.
    for (unsigned s = 0; s < steps; ++s) setTransform(instance, s, motion.at(open + (close - open) * double(s) / double(steps - 1)));
    rtcCommitGeometry(instance);
    rtcAttachGeometry(ensure(impl_->rigid), instance);
    rtcReleaseGeometry(instance);
    // At each fixed time, the knots' matrices blended there, as the vertices move
    // (MotionXform::at). `whole` takes the BVH itself: Embree instances one level deep.
    for (size_t k = 0; k < impl_->fixedAt.size(); ++k)
      attachStatic(local, motion.at(std::clamp(impl_->fixedAt[k], open, close)), {ensure(impl_->fixed[k]), ensure(impl_->whole[k])});
  }
  if (!impl_->rigid) impl_->fixedAt.clear(), impl_->fixed.clear(), impl_->whole.clear();
  for (RTCScene s : {impl_->still, impl_->deforming, impl_->rigid})
    if (s) rtcCommitScene(s);
  for (RTCScene s : impl_->fixed) rtcCommitScene(s);
  for (RTCScene whole : impl_->whole) {
    attachStatic(impl_->still, glm::dmat4(1.0), {whole});
    if (impl_->deforming) attachStatic(impl_->deforming, glm::dmat4(1.0), {whole});
    rtcCommitScene(whole);
  }
  check(impl_->device, "build the shadow scene");
}

ShadowScene::~ShadowScene() = default;

size_t ShadowScene::fixedInstants() const { return impl_->fixed.size(); }
bool ShadowScene::moves() const { return impl_->rigid || impl_->deforming; }

namespace {
bool occludedIn(RTCScene scene, const glm::dvec3& origin, const glm::dvec3& dir, double tfar, float time) {
  if (!scene || !(tfar > 0)) return false;
  RTCIntersectContext context;
  rtcInitIntersectContext(&context);
  RTCRay ray{};
  ray.org_x = float(origin.x), ray.org_y = float(origin.y), ray.org_z = float(origin.z);
  ray.dir_x = float(dir.x), ray.dir_y = float(dir.y), ray.dir_z = float(dir.z);
  ray.tnear = 0;
  ray.tfar = std::isfinite(tfar) ? float(tfar) : std::numeric_limits<float>::infinity();
  ray.mask = ~0u;
  ray.time = time;
  rtcOccluded1(scene, &context, &ray);
  return ray.tfar == -std::numeric_limits<float>::infinity();
}
}  // namespace

bool ShadowScene::occludedByStill(const glm::dvec3& origin, const glm::dvec3& dir, double tfar) const {
  return occludedIn(impl_->still, origin, dir, tfar, 0.f);
}

bool ShadowScene::occluded(const glm::dvec3& origin, const glm::dvec3& dir, double tfar, double time) const {
  if (const int k = impl_->fixedIndex(time); k >= 0) return occludedIn(impl_->whole[size_t(k)], origin, dir, tfar, impl_->rayTime(time));
  return occludedByStill(origin, dir, tfar) || occludedByMoving(origin, dir, tfar, time);
}

bool ShadowScene::occludedByMoving(const glm::dvec3& origin, const glm::dvec3& dir, double tfar, double time) const {
  if (!moves()) return false;
  const float rayTime = impl_->rayTime(time);
  const int k = impl_->fixedIndex(time);
  return occludedIn(k >= 0 ? impl_->fixed[size_t(k)] : impl_->rigid, origin, dir, tfar, rayTime) || occludedIn(impl_->deforming, origin, dir, tfar, rayTime);
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

namespace {
glm::dvec3 corner(const ShadowBox& b, int i) { return glm::dvec3(i & 1 ? b.hi.x : b.lo.x, i & 2 ? b.hi.y : b.lo.y, i & 4 ? b.hi.z : b.lo.z); }
bool parallel(const LitLight& l) { return l.kind == LightKind::Distant || (l.kind == LightKind::Uber && l.uber.parallel); }
double diagonal(const ShadowBox& b) { return glm::length(b.hi - b.lo); }
}  // namespace

MovingCasters::MovingCasters(std::span<const LitLight> lights, std::vector<ShadowBox> casters) : casters_(std::move(casters)), lit_(lights) {
  lights_.resize(lights.size());
  for (size_t li = 0; li < lights.size(); ++li) {
    const LitLight& light = lights[li];
    FromLight& f = lights_[li];
    f.shadows = light.shadows && light.kind != LightKind::Ambient;
    if (!f.shadows) continue;
    f.directional = parallel(light);
    if (f.directional) f.d = glm::normalize(light.axis), frame(f.d, f.e1, f.e2);
    const double rl = glm::length(light.halfU) + glm::length(light.halfV);
    for (const ShadowBox& caster : casters_) {
      Seen s;
      if (f.directional) {
        for (int k = 0; k < 3; ++k) s.lo[k] = INFINITY, s.hi[k] = -INFINITY;
        for (int i = 0; i < 8; ++i) {
          const glm::dvec3 p = corner(caster, i);
          const double pc[3] = {glm::dot(p, f.e1), glm::dot(p, f.e2), glm::dot(p, f.d)};
          for (int k = 0; k < 3; ++k) s.lo[k] = std::min(s.lo[k], pc[k]), s.hi[k] = std::max(s.hi[k], pc[k]);
        }
      } else {
        // A local light (its emitter within radius rl of its position): the segment from a
        // shadowed point to the light's centre passes within rl of the caster, so it meets the
        // caster's bounding sphere grown by rl - the receiver's sphere must then lie in that
        // sphere's cone.
        s.radius = 0.5 * diagonal(caster) * (1 + 1e-6) + rl;
        s.toCaster = 0.5 * (caster.lo + caster.hi) - light.position;
        s.distance = glm::length(s.toCaster);
        s.halfAngle = std::asin(std::min(1.0, s.radius / s.distance));
        s.cosHalf = std::cos(s.halfAngle), s.sinHalf = std::sin(s.halfAngle);
      }
      f.casters.push_back(s);
    }
  }
}

bool MovingCasters::mayShadow(size_t li, const ShadowBox& receiver) const {
  if (li >= lights_.size() || !lights_[li].shadows) return false;
  const FromLight& f = lights_[li];
  const LitLight& light = lit_[li];
  if (f.directional) {
    // Shadows fall along the light's direction d: the receiver must lie beyond the caster along
    // d, and overlap it seen along d (widened by a soft light's cone over the gap).
    double lo[3] = {INFINITY, INFINITY, INFINITY}, hi[3] = {-INFINITY, -INFINITY, -INFINITY};
    for (int i = 0; i < 8; ++i) {
      const glm::dvec3 q = corner(receiver, i);
      const double qc[3] = {glm::dot(q, f.e1), glm::dot(q, f.e2), glm::dot(q, f.d)};
      for (int k = 0; k < 3; ++k) lo[k] = std::min(lo[k], qc[k]), hi[k] = std::max(hi[k], qc[k]);
    }
    const double receiverSize = diagonal(receiver);
    for (size_t ci = 0; ci < casters_.size(); ++ci) {
      const Seen& c = f.casters[ci];
      const double slack = 1e-6 * (1 + diagonal(casters_[ci]) + receiverSize);
      if (hi[2] + slack < c.lo[2]) continue;
      const double grow = light.tanHalfAngle * std::max(0.0, hi[2] - c.lo[2]) + slack;
      if (lo[0] <= c.hi[0] + grow && c.lo[0] - grow <= hi[0] && lo[1] <= c.hi[1] + grow && c.lo[1] - grow <= hi[1]) return true;
    }
    return false;
  }
  const glm::dvec3 toR = 0.5 * (receiver.lo + receiver.hi) - light.position;
  const double rR = 0.5 * diagonal(receiver) * (1 + 1e-6), dR = glm::length(toR);
  if (!(dR > rR)) return true;
  // The angle between a caster's centre and the receiver's, seen from the light, against the sum
  // of their half-angles (each at most a right angle) and a little slack: compared by cosines,
  // cos(a + b) = cos a cos b - sin a sin b, so each caster costs a dot product, not an acos.
  const double receiverAngle = std::asin(std::min(1.0, rR / dR)) + 1e-9;
  const double cosR = std::cos(receiverAngle), sinR = std::sin(receiverAngle);
  for (const Seen& c : f.casters) {
    if (!(c.distance > c.radius)) return true;
    if (dR + rR < c.distance - c.radius) continue;  // wholly nearer the light than the caster
    const double cosAngle = std::clamp(glm::dot(c.toCaster, toR) / (c.distance * dR), -1.0, 1.0);
    if (c.halfAngle + receiverAngle >= std::numbers::pi || cosAngle >= c.cosHalf * cosR - c.sinHalf * sinR) return true;
  }
  return false;
}

size_t shadowRays(const LitLight& light, const glm::dvec3& P, const glm::dvec3& Ng, double bias, int samples, uint64_t seed, std::vector<ShadowRay>& rays) {
  rays.clear();
  if (!light.shadows || light.kind == LightKind::Ambient) return 0;
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
  for (int k = 0; k < n; ++k) {
    double a = 0.5, b = 0.5;
    if (area) {
      a = (k + 0.5) / n + rotA, b = radicalInverse2(uint32_t(k)) + rotB;
      a -= std::floor(a), b -= std::floor(b);
    }
    if (directional) {
      double x = 0, y = 0;
      if (area) concentric(a, b, x, y);
      rays.push_back(ShadowRay{origin, glm::normalize(-light.axis + light.tanHalfAngle * (x * e1 + y * e2)), std::numeric_limits<double>::infinity()});
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
      rays.push_back(ShadowRay{origin, d / len, len * (1 - 1e-6)});  // stop short of the emitter, which may itself be geometry
    }
  }
  return size_t(n);
}

}  // namespace reshutter::shade
