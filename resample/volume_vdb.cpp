// The volume plugin (libreshutter_volume.so, resample/volume_engine.h): OpenVDB's side of
// volumes - placing the files' volumes (volume_vdb_scene.cpp loads them), the ray march (OpenVDB's
// VolumeRayIntersector skips empty space, its samplers interpolate), shared rays and the lighting
// cache. With volume_vdb_scene.cpp and volume_smoke.cpp, the only files that include OpenVDB.
#include <algorithm>
#include <array>
#include <atomic>
#include <cmath>
#include <mutex>
#include <optional>
#include <sstream>

#include <openvdb/openvdb.h>
#include <openvdb/tools/Interpolation.h>
#include <openvdb/tools/RayIntersector.h>
#include <openvdb/tree/LeafManager.h>
#include <tbb/enumerable_thread_specific.h>
#include <tbb/parallel_for.h>
#include <glm/geometric.hpp>
#include <glm/mat4x4.hpp>

#include "common/error.h"
#include "resample/volume_vdb.h"

namespace reshutter::resample {

namespace {

using namespace vdb;
using IndexRay = openvdb::math::Ray<double>;

openvdb::Vec3d apply(const glm::dmat4& m, const glm::dvec3& p) { return toVdb(glm::dvec3(m * glm::dvec4(p, 1.0))); }

// An affine map written out, so that the per-step transforms inline (glm's 4×4 product is a call
// at -O2, and a tenth of a march's time).
struct Affine {
  glm::dvec3 x{1, 0, 0}, y{0, 1, 0}, z{0, 0, 1}, t{0.0};
  Affine() = default;
  explicit Affine(const glm::dmat4& m) : x(m[0]), y(m[1]), z(m[2]), t(m[3]) {}
  glm::dvec3 operator()(const glm::dvec3& p) const { return x * p.x + y * p.y + z * p.z + t; }
  glm::dvec3 linear(const glm::dvec3& d) const { return x * d.x + y * d.y + z * d.z; }  // a direction
  openvdb::Vec3d vdb(const glm::dvec3& p) const { return toVdb((*this)(p)); }
};

// ------------------------------------------------------------------------------------------
// Tracing

struct VdbLighting;

struct VdbTracer final : VolumeTracerEngine {
  VdbTracer(const VdbScene& scene, const VolumeCamera& camera, double earliest, double latest, const VdbLighting* lighting);
  bool touches(double x0, double y0, double x1, double y1) const override;
  void beginRegion(int x0, int y0, int w, int h) override;
  bool sharesRays() const override { return shareRays; }
  void integrate(double x, double y, double u, double v, double t, double z0, double z1, VolumeSegment& out, std::vector<VolumeSlice>* slices,
                 double ratio, VolumeStats& stats) override;
  void integrateShared(double x, double y, double z0, double z1, VolumeSegment& out, std::vector<VolumeSlice>* slices, double ratio, VolumeStats& stats);

  struct PerVolume {
    explicit PerVolume(const VdbScene::Volume& volume)
        : v(&volume), intersector(*volume.intersector), density(volume.density->getConstAccessor()) {}
    const VdbScene::Volume* v;
    Intersector intersector;  // shallow copy of the master: its own ray and accessor
    FloatGrid::ConstAccessor density;
    std::optional<FloatGrid::ConstAccessor> emissionScalar;
    std::optional<Vec3SGrid::ConstAccessor> emissionColour, velocity, colour;
    // Camera space → the file's index space, affine: index = cameraToIndex · camera point.
    glm::dmat4 cameraToFile{1.0};
    Affine toFile, toDensity, toEmission, toColour;  // camera space → file world, density, emission and colour index space
    Affine fileToDensity, fileToVelocity;  // file world → index space (after a velocity's backtrace)
    double voxelInCamera = 1;              // a voxel's size in camera-space units
    double reach = 0;                      // file world units the velocity can carry density over the render's times
    bool hdda = true;                      // the intersector's dilation covers the reach
    glm::dvec3 lo{0.0}, hi{0.0};           // file world bounds widened by the reach
    bool moving = false;                   // placed by a moving transform: placed again per ray (placeAt)
  };
  // The in-scattered light cached per volume (VolumeLighting), null where not cached.
  struct LightLookup {
    const Vec3SGrid* grid = nullptr;
    std::optional<Vec3SGrid::ConstAccessor> acc;
    Affine index;  // camera space → the cache's index space
  };
  std::vector<LightLookup> lightCache;
  void cacheLighting(const VdbLighting& lighting);
  // The cached in-scattered light at camera point p (false: none cached there).
  bool cachedLight(const glm::dvec3& p, double S[3]) {
    for (size_t i = 0; i < lightCache.size(); ++i) {
      LightLookup& c = lightCache[i];
      if (!c.grid) continue;
      const PerVolume& pv = volumes[i];
      const glm::dvec3 f = pv.toFile(p);
      if (f.x < pv.lo.x || f.y < pv.lo.y || f.z < pv.lo.z || f.x > pv.hi.x || f.y > pv.hi.y || f.z > pv.hi.z) continue;
      const openvdb::Vec3s v = openvdb::tools::BoxSampler::sample(*c.acc, c.index.vdb(p));
      S[0] = v.x(), S[1] = v.y(), S[2] = v.z();
      return true;
    }
    return false;
  }
  // The light arriving at camera point p and scattered toward the eye (direction toEye), over
  // every light: Σ Cl · T(to the light) · phase, with the ambient lights' colour unshadowed.
  void inScattered(const glm::dvec3& p, const glm::dvec3& toEye, double g, double seconds, double S[3], uint64_t& lookups) {
    S[0] = S[1] = S[2] = 0;
    for (const store::StoredLight& light : camera.lights) {
      if (light.kind == store::StoredLight::Kind::Ambient) {
        for (int k = 0; k < 3; ++k) S[k] += light.colour[k];
        continue;
      }
      glm::dvec3 L, Cl;
      if (!light.illuminate(p, L, Cl)) continue;
      const double dist = light.kind == store::StoredLight::Kind::Distant ? INFINITY : glm::length(L);
      const glm::dvec3 l = glm::normalize(L);
      const double cosTheta = -glm::dot(l, toEye);
      const double phase = g == 0 ? 1.0 : (1 - g * g) / std::pow(1 + g * g - 2 * g * cosTheta, 1.5);
      const double T = transmittance(p, l, dist, seconds, lookups);
      for (int k = 0; k < 3; ++k) S[k] += Cl[k] * phase * T;
    }
  }
  // Narrows [a, b] to the parameters s at which camera-space point p + s·d lies inside the
  // volume's (widened) bounds in its file's world space: the slab test. Empty: a >= b.
  static void clipToBounds(const PerVolume& pv, const glm::dvec3& p, const glm::dvec3& d, double& a, double& b) {
    const glm::dvec3 f0 = pv.toFile(p), fd = pv.toFile.linear(d);
    for (int k = 0; k < 3 && a <= b; ++k) {
      if (fd[k] == 0.0) {
        if (f0[k] < pv.lo[k] || f0[k] > pv.hi[k]) a = INFINITY;
        continue;
      }
      double ta = (pv.lo[k] - f0[k]) / fd[k], tb = (pv.hi[k] - f0[k]) / fd[k];
      if (ta > tb) std::swap(ta, tb);
      a = std::max(a, ta), b = std::min(b, tb);
    }
  }
  // Places a volume: camera space → its file's world space, and the maps derived from it.
  void place(PerVolume& pv, const glm::dmat4& cameraToFile) {
    const auto& v = *pv.v;
    pv.cameraToFile = cameraToFile;
    pv.voxelInCamera = v.voxelSize / glm::length(glm::dvec3(cameraToFile[0]));
    pv.toFile = Affine(cameraToFile), pv.toDensity = Affine(v.densityIndex * cameraToFile), pv.toEmission = Affine(v.emissionIndex * cameraToFile);
    pv.toColour = Affine(v.colourIndex * cameraToFile);
  }
  // A moving scene volume's transform at frame-relative time tau: linear between its knots,
  // held outside them.
  static glm::dmat4 fileToCameraAt(const VolumeSpec& s, double tau) {
    if (tau <= s.times.front()) return s.fileToCamera.front();
    if (tau >= s.times.back()) return s.fileToCamera.back();
    size_t k = 0;
    while (k + 2 < s.times.size() && s.times[k + 1] <= tau) ++k;
    const double w = (tau - s.times[k]) / (s.times[k + 1] - s.times[k]);
    return s.fileToCamera[k] + (s.fileToCamera[k + 1] - s.fileToCamera[k]) * w;
  }
  // Moving volumes placed where they are at absolute time t.
  void placeAt(double t) {
    for (auto& pv : volumes)
      if (pv.moving) place(pv, glm::inverse(fileToCameraAt(pv.v->spec, t - camera.referenceFrame)));
  }
  const VdbScene& scene;
  VolumeCamera camera;
  glm::dmat4 cameraToWorld{1.0};
  std::vector<PerVolume> volumes;
  std::vector<std::pair<double, double>> spans;  // scratch: a ray's intervals in camera depth

  // Camera-space ray through raster (x, y) and lens point (u, v) on the unit disk: point(z) =
  // origin + dir · z. Through a lens the ray leaves the lens point L and meets the pinhole ray
  // at the focal distance d: L + (p − L/d) z.
  void rayThrough(double x, double y, double u, double v, glm::dvec3& origin, glm::dvec3& dir) const {
    origin = glm::dvec3(0.0), dir = glm::dvec3(0.0, 0.0, 1.0);
    if (camera.perspective) dir = {(x - camera.bx) / camera.ax, (y - camera.by) / camera.ay, 1.0};
    else origin = {(x - camera.bx) / camera.ax, (y - camera.by) / camera.ay, 0.0};
    if (lens()) {
      origin = {camera.lensRadius * u, camera.lensRadius * v, 0.0};
      dir -= origin / camera.focalDistance;
    }
  }
  bool lens() const { return camera.perspective && camera.lensRadius > 0; }
  // Each volume's intervals of camera depth in [z0, zFar] that may hold density, merged and
  // sorted into `spans`; returns the march's step in camera depth (INFINITY: nothing to march).
  double collectSpans(const glm::dvec3& origin, const glm::dvec3& dir, double z0, double zFar, VolumeStats& stats) {
    spans.clear();
    double stepZ = INFINITY;
    for (auto& pv : volumes) {
      double a = z0, b = zFar;
      clipToBounds(pv, origin, dir, a, b);
      if (!(a < b)) continue;
      ++stats.rays;
      // The ray in the density grid's index space, parametrised by camera depth.
      const glm::dvec3 i0 = pv.toDensity(origin), id = pv.toDensity.linear(dir);
      const double indexPerZ = glm::length(id);
      if (!(indexPerZ > 0)) continue;
      stepZ = std::min(stepZ, double(scene.options().step) / indexPerZ);
      if (!pv.hdda) {
        spans.emplace_back(a, b);
        continue;
      }
      IndexRay ray(toVdb(i0), toVdb(id), a, b);
      if (!pv.intersector.setIndexRay(ray)) continue;
      double s0, s1;
      while (pv.intersector.march(s0, s1)) spans.emplace_back(std::max(s0, a), std::min(s1, b));
    }
    if (spans.empty()) return INFINITY;
    std::sort(spans.begin(), spans.end());
    // Merge overlapping intervals in place.
    size_t n = 0;
    for (size_t i = 1; i < spans.size(); ++i)
      if (spans[i].first <= spans[n].second) spans[n].second = std::max(spans[n].second, spans[i].second);
      else spans[++n] = spans[i];
    spans.resize(n + 1);
    return stepZ;
  }
  // One step of the march, at camera point p (ray direction dir), ds world units long: the light
  // it sends toward the eye (relative to its front: add) and its optical depth (returned).
  double step(const glm::dvec3& p, const glm::dvec3& dir, double ds, double seconds, double add[3], bool& emits, VolumeStats& stats) {
    double sigma = 0, e[3] = {0, 0, 0}, scatter[3] = {0, 0, 0}, phaseG = 0;
    medium(p, seconds, sigma, e, scatter, phaseG, stats.steps);
    if (sigma > 0 && !camera.lights.empty()) {
      // Single scattering: the lights' colour here, through the medium toward each, by the
      // phase function (normalised so that isotropic scattering is 1, as RenderMan's volume
      // shaders light), times the albedo-weighted extinction below.
      double S[3];
      if (cachedLight(p, S)) ++stats.cachedShadows;
      else inScattered(p, -glm::normalize(dir), phaseG, seconds, S, stats.shadowSteps);
      for (int k = 0; k < 3; ++k) scatter[k] = scatter[k] / sigma * S[k];
    } else {
      scatter[0] = scatter[1] = scatter[2] = 0;
    }
    // The scattered light: the albedo-weighted extinction times the in-scattered light, whose
    // σ cancels the gain's division: albedo · S · (1 - e^{-σ ds}).
    const double tau = sigma * ds;
    const double stepT = std::exp(-tau);
    const double gain = tau > 1e-9 ? (1.0 - stepT) / sigma : ds;
    for (int k = 0; k < 3; ++k) add[k] = e[k] * gain + scatter[k] * (1.0 - stepT);
    emits = e[0] != 0.0 || e[1] != 0.0 || e[2] != 0.0;
    return tau;
  }

  // ----------------------------------------------------------------------------------------
  // Shared rays (VolumeOptions::raySpacing): rays on a screen lattice, each marched once from
  // the eye to the volumes' far side and tabulated; every sample's segment interpolates the four
  // around it. A ray depends only on its lattice point, so images do not depend on buckets or
  // threads.

  // A tabulated ray: at depth z, the optical depth and the radiance (premultiplied, toward the
  // eye) accumulated from the eye. Entries bracket the steps that hold medium; between entries
  // both are linear in depth, outside them constant.
  struct TableEntry {
    float z, tau, L[3];
  };
  struct SharedRay {
    bool made = false;
    std::vector<TableEntry> entries;
  };
  struct LatticeRow {
    int64_t j = INT64_MIN;
    std::vector<SharedRay> rays;  // lattice columns [iLo, iHi]
  };
  bool shareRays = false;
  double spacing = 1;           // pixels between lattice points; point (i, j) at ((i + ½) s, (j + ½) s)
  double rayTime = 0;           // the render's earliest time: shared rays are for unmoving volumes
  int64_t iLo = 0, iHi = -1;    // the region's lattice columns (beginRegion)
  std::array<LatticeRow, 4> rows;  // the rows a pixel-major walk needs, by j mod 4

  void traceShared(int64_t i, int64_t j, SharedRay& ray, VolumeStats& stats) {
    ray.made = true;
    ray.entries.clear();
    ++stats.sharedRays;
    glm::dvec3 origin, dir;
    rayThrough((double(i) + 0.5) * spacing, (double(j) + 0.5) * spacing, 0.0, 0.0, origin, dir);
    const double worldPerZ = glm::length(glm::dvec3(cameraToWorld * glm::dvec4(dir, 0.0)));
    const double seconds = (rayTime - camera.referenceFrame) / camera.framesPerSecond;
    const double stepZ = collectSpans(origin, dir, 0.0, 1e30, stats);
    if (!std::isfinite(stepZ)) return;
    double T = 1.0, tau = 0.0, L[3] = {0, 0, 0};
    for (const auto& [a, b] : spans) {
      if (!(b > a)) continue;
      const int steps = int(std::min(1e6, std::ceil((b - a) / stepZ)));
      const double dz = (b - a) / steps, ds = dz * worldPerZ;
      for (int n = 0; n < steps && T > 1e-7; ++n) {
        const double z = a + (n + 0.5) * dz;
        double add[3];
        bool emits;
        const double stepTau = step(origin + dir * z, dir, ds, seconds, add, emits, stats);
        if (!(stepTau > 0.0) && !emits) continue;
        const float zFront = float(z - 0.5 * dz);
        if (ray.entries.empty() || ray.entries.back().z < zFront)
          ray.entries.push_back({zFront, float(tau), {float(L[0]), float(L[1]), float(L[2])}});
        for (int k = 0; k < 3; ++k) L[k] += T * add[k];
        T *= std::exp(-stepTau), tau += stepTau;
        ray.entries.push_back({float(z + 0.5 * dz), float(tau), {float(L[0]), float(L[1]), float(L[2])}});
      }
    }
  }
  SharedRay& sharedRay(int64_t i, int64_t j, VolumeStats& stats) {
    LatticeRow& row = rows[size_t(j & 3)];
    if (row.j != j) {
      row.j = j;
      row.rays.resize(size_t(iHi - iLo + 1));
      for (SharedRay& r : row.rays) r.made = false;
    }
    SharedRay& ray = row.rays[size_t(std::clamp(i, iLo, iHi) - iLo)];
    if (!ray.made) traceShared(std::clamp(i, iLo, iHi), j, ray, stats);
    return ray;
  }
  // A tabulated ray's optical depth and radiance at depth z.
  static void lookup(const SharedRay& ray, double z, double& tau, double L[3]) {
    const auto& e = ray.entries;
    const auto it = std::upper_bound(e.begin(), e.end(), z, [](double v, const TableEntry& x) { return v < double(x.z); });
    if (it == e.begin()) {
      tau = 0, L[0] = L[1] = L[2] = 0;
      return;
    }
    const TableEntry& a = *(it - 1);
    if (it == e.end()) {
      tau = a.tau;
      for (int k = 0; k < 3; ++k) L[k] = a.L[k];
      return;
    }
    const TableEntry& b = *it;
    const double f = (z - double(a.z)) / (double(b.z) - double(a.z));
    tau = a.tau + f * (double(b.tau) - double(a.tau));
    for (int k = 0; k < 3; ++k) L[k] = a.L[k] + f * (double(b.L[k]) - double(a.L[k]));
  }

  // The medium at camera-space point p, `seconds` after the reference frame: extinction σ (per
  // world unit), emission e, scattering σ_s = albedo · σ per channel, and the σ-weighted
  // anisotropy of the volumes there.
  void medium(const glm::dvec3& p, double seconds, double& sigma, double e[3], double scatter[3], double& g, uint64_t& lookups) {
    double gw = 0;
    for (auto& pv : volumes) {
      glm::dvec3 f = pv.toFile(p);
      if (f.x < pv.lo.x || f.y < pv.lo.y || f.z < pv.lo.z || f.x > pv.hi.x || f.y > pv.hi.y || f.z > pv.hi.z) continue;
      const auto& v = *pv.v;
      const bool advected = pv.velocity && seconds != 0.0;
      if (advected) {
        // Semi-Lagrangian: the density here at this time is the file's density where the flow
        // carried it from (velocity sampled here).
        const openvdb::Vec3s vel = openvdb::tools::BoxSampler::sample(*pv.velocity, pv.fileToVelocity.vdb(f));
        f -= glm::dvec3(vel.x(), vel.y(), vel.z()) * seconds;
      }
      ++lookups;
      const float d = openvdb::tools::BoxSampler::sample(pv.density, advected ? pv.fileToDensity.vdb(f) : pv.toDensity.vdb(p));
      if (d > 0.f) {
        const double s = double(d) * v.spec.densityScale;
        sigma += s, gw += s * v.spec.anisotropy;
        if (pv.colour) {
          const openvdb::Vec3s cd = openvdb::tools::BoxSampler::sample(*pv.colour, advected ? apply(v.colourIndex, f) : pv.toColour.vdb(p));
          for (int k = 0; k < 3; ++k) scatter[k] += s * v.spec.albedo[k] * std::clamp(double(cd[k]), 0.0, 1.0);
        } else {
          for (int k = 0; k < 3; ++k) scatter[k] += s * v.spec.albedo[k];
        }
      }
      if (pv.emissionScalar) {
        const float em = openvdb::tools::BoxSampler::sample(*pv.emissionScalar, advected ? apply(v.emissionIndex, f) : pv.toEmission.vdb(p));
        for (int k = 0; k < 3; ++k) e[k] += double(em) * v.spec.emissionColour[k];
      } else if (pv.emissionColour) {
        const openvdb::Vec3s em = openvdb::tools::BoxSampler::sample(*pv.emissionColour, advected ? apply(v.emissionIndex, f) : pv.toEmission.vdb(p));
        for (int k = 0; k < 3; ++k) e[k] += double(em[k]) * v.spec.emissionColour[k];
      }
    }
    g = sigma > 0 ? gw / sigma : 0.0;
  }

  // Transmittance from camera-space point p a distance `dist` along unit direction l (to a
  // light): the medium sampled at midpoints of steps of the shadow step, within the volumes' bounds.
  double transmittance(const glm::dvec3& p, const glm::dvec3& l, double dist, double seconds, uint64_t& lookups) {
    double s0 = INFINITY, s1 = 0, step = INFINITY;
    for (const auto& pv : volumes) {
      double a = 0, b = dist;
      clipToBounds(pv, p, l, a, b);
      if (a < b) s0 = std::min(s0, a), s1 = std::max(s1, b), step = std::min(step, double(scene.options().shadowStep) * pv.voxelInCamera);
    }
    if (!(s1 > s0)) return 1.0;
    const int n = int(std::min(1e5, std::ceil((s1 - s0) / step)));
    const double ds = (s1 - s0) / n;
    double tau = 0;
    for (int i = 0; i < n && tau < 20; ++i) {
      double sigma = 0, e[3] = {0, 0, 0}, sc[3] = {0, 0, 0}, g;
      medium(p + l * (s0 + (i + 0.5) * ds), seconds, sigma, e, sc, g, lookups);
      tau += sigma * ds;
    }
    return std::exp(-tau);
  }
};

VdbTracer::VdbTracer(const VdbScene& s, const VolumeCamera& c, double earliest, double latest, const VdbLighting* lighting) : scene(s), camera(c) {
  VdbTracer& m = *this;
  m.cameraToWorld = glm::inverse(camera.worldToCamera);
  const double maxSeconds = std::max(std::abs(earliest - camera.referenceFrame), std::abs(latest - camera.referenceFrame)) / camera.framesPerSecond;
  m.volumes.reserve(scene.volumes.size());
  for (const auto& v : scene.volumes) {
    PerVolume pv(v);
    if (v.emissionScalar) pv.emissionScalar.emplace(v.emissionScalar->getConstAccessor());
    if (v.emissionColour) pv.emissionColour.emplace(v.emissionColour->getConstAccessor());
    if (v.velocity) pv.velocity.emplace(v.velocity->getConstAccessor());
    if (v.colour) pv.colour.emplace(v.colour->getConstAccessor());
    if (!v.spec.fileToCamera.empty()) {
      // A scene volume: placed in camera space (where it is at its first knot, if it moves).
      pv.moving = v.spec.fileToCamera.size() > 1;
      m.place(pv, glm::inverse(v.spec.fileToCamera[0]));
    } else {
      // world = translate + scale · file world  ⇒  file world = (world - translate) / scale.
      glm::dmat4 worldToFile(1.0 / v.spec.scale);
      worldToFile[3] = glm::dvec4(-v.spec.translate / v.spec.scale, 1.0);
      m.place(pv, worldToFile * m.cameraToWorld);
    }
    pv.fileToDensity = Affine(v.densityIndex), pv.fileToVelocity = Affine(v.velocityIndex);
    pv.reach = v.maxSpeed * maxSeconds;
    // A moving volume's density comes from up to `reach` away: the dilated intersector covers
    // one voxel; beyond that the march steps through the (widened) bounds instead.
    pv.hdda = scene.options().skipEmpty && pv.reach <= 0.0;
    pv.lo = v.fileLo - glm::dvec3(pv.reach), pv.hi = v.fileHi + glm::dvec3(pv.reach);
    m.volumes.push_back(std::move(pv));
  }
  if (lighting) m.cacheLighting(*lighting);  // needs the volumes' placement
  // Shared rays serve volumes that stay put over the render: their rays do not depend on time.
  // Nor through a lens: there each sample's ray leaves its own lens point, and the pinhole rays
  // of a lattice are not it.
  m.spacing = scene.options().raySpacing;
  m.shareRays = m.spacing > 0 && !m.lens() && std::none_of(m.volumes.begin(), m.volumes.end(), [](const PerVolume& pv) { return pv.moving || pv.velocity; });
  m.rayTime = earliest;
}

bool VdbTracer::touches(double x0, double y0, double x1, double y1) const {
  const VdbTracer& m = *this;
  const VolumeCamera& c = m.camera;
  for (const auto& pv : m.volumes) {
    // The bounds' corners in camera space, projected; a corner at or behind the eye plane makes
    // the projection unbounded. A moving scene volume's corners move straight between its knots
    // (the transforms are blended linearly), and so do their projections: the knots bound them.
    std::vector<glm::dmat4> placements{glm::inverse(pv.cameraToFile)};
    if (pv.moving) placements = pv.v->spec.fileToCamera;
    double lx = INFINITY, ly = INFINITY, hx = -INFINITY, hy = -INFINITY, zLo = INFINITY, zHi = -INFINITY;
    bool unbounded = false;
    for (size_t k8 = 0; k8 < 8 * placements.size(); ++k8) {
      const int k = int(k8 % 8);
      const glm::dmat4& fileToCamera = placements[k8 / 8];
      const glm::dvec3 f((k & 1) ? pv.hi.x : pv.lo.x, (k & 2) ? pv.hi.y : pv.lo.y, (k & 4) ? pv.hi.z : pv.lo.z);
      const glm::dvec3 p = glm::dvec3(fileToCamera * glm::dvec4(f, 1.0));
      if (c.perspective && !(p.z > 1e-9)) {
        unbounded = true;
        break;
      }
      const double iz = c.perspective ? 1.0 / p.z : 1.0;
      const double rx = c.ax * p.x * iz + c.bx, ry = c.ay * p.y * iz + c.by;
      lx = std::min(lx, rx), hx = std::max(hx, rx), ly = std::min(ly, ry), hy = std::max(hy, ry);
      zLo = std::min(zLo, p.z), zHi = std::max(zHi, p.z);
    }
    if (unbounded) return true;
    // Screen y may run either way (ay < 0): the box is min/max either way.
    // A sample blending shared rays sees medium up to one lattice spacing beyond the bounds.
    const double reach = 1 + (m.shareRays ? m.spacing : 0.0);
    // Through a lens a sample at raster x sees the point the pinhole sees at x + a R u (1/z − 1/d)
    // (|u| <= 1): the bounds widen by the largest circle of confusion over the box's depths.
    double cocX = 0, cocY = 0;
    if (m.lens()) {
      const double k = std::max(std::abs(1 / zLo - 1 / c.focalDistance), std::abs(1 / zHi - 1 / c.focalDistance)) * c.lensRadius;
      cocX = std::abs(c.ax) * k, cocY = std::abs(c.ay) * k;
    }
    if (hx >= x0 - reach - cocX && lx <= x1 + reach + cocX && hy >= y0 - reach - cocY && ly <= y1 + reach + cocY) return true;
  }
  return false;
}

void VdbTracer::integrate(double x, double y, double u, double v, double t, double z0, double z1, VolumeSegment& out, std::vector<VolumeSlice>* slices,
                          double ratio, VolumeStats& stats) {
  VdbTracer& m = *this;
  out = VolumeSegment{};
  if (!(z1 > z0)) return;
  if (m.shareRays) {
    integrateShared(x, y, z0, z1, out, slices, ratio, stats);
    return;
  }
  const VolumeCamera& c = m.camera;
  m.placeAt(t);
  glm::dvec3 origin, dir;
  m.rayThrough(x, y, u, v, origin, dir);
  const double worldPerZ = glm::length(glm::dvec3(m.cameraToWorld * glm::dvec4(dir, 0.0)));
  const double seconds = (t - c.referenceFrame) / c.framesPerSecond;
  const double zFar = std::isfinite(z1) ? z1 : 1e30;
  const double stepZ = m.collectSpans(origin, dir, z0, zFar, stats);
  if (!std::isfinite(stepZ)) return;

  double T = 1.0, L[3] = {0, 0, 0};
  // Deep output's current slice: its steps' extent and what they add relative to its front.
  const double logRatio = slices ? std::log(ratio) : 0.0;
  VolumeSlice cur;
  bool open = false;
  double sliceT = 1.0, sliceL[3] = {0, 0, 0};
  auto closeSlice = [&] {
    if (!open) return;
    open = false;
    if (sliceT >= 1.0 && sliceL[0] == 0.0 && sliceL[1] == 0.0 && sliceL[2] == 0.0) return;  // empty space
    cur.segment.transmittance = float(sliceT);
    for (int k = 0; k < 3; ++k) cur.segment.radiance[k] = float(sliceL[k]);
    slices->push_back(cur);
  };
  for (const auto& [a, b] : m.spans) {
    if (!(b > a)) continue;
    const int steps = int(std::min(1e6, std::ceil((b - a) / stepZ)));
    const double dz = (b - a) / steps, ds = dz * worldPerZ;
    for (int i = 0; i < steps && T > 1e-7; ++i) {
      const double z = a + (i + 0.5) * dz;
      if (slices) {
        const int32_t k = int32_t(std::floor(std::log(std::max(z, 1e-30)) / logRatio));
        if (!open || k != cur.slice) {
          closeSlice();
          open = true, cur.slice = k, cur.zFront = INFINITY, sliceT = 1.0, sliceL[0] = sliceL[1] = sliceL[2] = 0.0;
        }
      }
      double add[3];
      bool emits;
      const double tau = m.step(origin + dir * z, dir, ds, seconds, add, emits, stats);
      const double stepT = std::exp(-tau);
      for (int k = 0; k < 3; ++k) L[k] += T * add[k];
      T *= stepT;
      if (slices && (tau > 0.0 || emits)) {
        // The slice spans the steps that hold medium, so deep samples hug it.
        for (int k = 0; k < 3; ++k) sliceL[k] += sliceT * add[k];
        sliceT *= stepT;
        cur.zFront = std::min(cur.zFront, float(z - 0.5 * dz)), cur.zBack = float(z + 0.5 * dz);
      }
    }
  }
  if (slices) closeSlice();
  for (int k = 0; k < 3; ++k) out.radiance[k] = float(L[k]);
  out.transmittance = float(T);
}

void VdbTracer::beginRegion(int x0, int y0, int w, int h) {
  VdbTracer& m = *this;
  (void)y0, (void)h;
  if (!m.shareRays) return;
  // A sample at x interpolates lattice columns floor(x / s - ½) and the next.
  m.iLo = int64_t(std::floor(double(x0) / m.spacing - 0.5));
  m.iHi = int64_t(std::floor(double(x0 + w) / m.spacing - 0.5)) + 1;
  for (auto& row : m.rows) row.j = INT64_MIN;
}

// The segment [z0, z1] of the ray through raster (x, y) from the four shared rays around it,
// blended bilinearly in optical depth and accumulated radiance (both cumulative from the eye, so
// a sample's segments telescope to its blended whole ray, as they do exactly when marched).
void VdbTracer::integrateShared(double x, double y, double z0, double z1, VolumeSegment& out, std::vector<VolumeSlice>* slices, double ratio,
                                VolumeStats& stats) {
  VdbTracer& m = *this;
  ++stats.sharedSegments;
  const double gx = x / m.spacing - 0.5, gy = y / m.spacing - 0.5;
  const double fi = std::floor(gx), fj = std::floor(gy);
  const int64_t i0 = int64_t(fi), j0 = int64_t(fj);
  const double fx = gx - fi, fy = gy - fj;
  const SharedRay* ray[4];
  double w[4] = {(1 - fx) * (1 - fy), fx * (1 - fy), (1 - fx) * fy, fx * fy};
  for (int r = 0; r < 4; ++r) ray[r] = &m.sharedRay(i0 + (r & 1), j0 + (r >> 1), stats);
  auto at = [&](double z, double& tau, double L[3]) {
    tau = 0, L[0] = L[1] = L[2] = 0;
    for (int r = 0; r < 4; ++r) {
      if (w[r] == 0.0) continue;
      double rt, rl[3];
      lookup(*ray[r], z, rt, rl);
      tau += w[r] * rt;
      for (int k = 0; k < 3; ++k) L[k] += w[r] * rl[k];
    }
  };
  // What [a, b] adds, relative to its front: the radiance gathered over it, seen from a.
  auto segment = [&](double a, double b, VolumeSegment& s) -> bool {
    double ta, tb, la[3], lb[3];
    at(a, ta, la), at(b, tb, lb);
    const double dTau = std::max(0.0, tb - ta);
    // The front's transmittance is in the composite already; a sample so deep in the medium
    // that it is below 1e-35 has stopped compositing long before (the opacity threshold).
    const double unseen = std::exp(std::min(ta, 80.0));
    s.transmittance = float(std::exp(-dTau));
    for (int k = 0; k < 3; ++k) s.radiance[k] = float(std::max(0.0, lb[k] - la[k]) * unseen);
    return dTau > 0.0 || lb[0] != la[0] || lb[1] != la[1] || lb[2] != la[2];
  };
  // The medium's extent over the four rays: nothing to blend outside it.
  double zLo = INFINITY, zHi = -INFINITY;
  for (int r = 0; r < 4; ++r)
    if (w[r] != 0.0 && !ray[r]->entries.empty()) zLo = std::min(zLo, double(ray[r]->entries.front().z)), zHi = std::max(zHi, double(ray[r]->entries.back().z));
  const double a = std::max(z0, zLo), b = std::min(z1, zHi);
  if (!(b > a)) return;
  segment(a, b, out);
  if (!slices) return;
  // Deep output: the segment cut at the slices' depths (ratio^k), each part over its own extent.
  const double logRatio = std::log(ratio);
  const int32_t kA = int32_t(std::floor(std::log(std::max(a, 1e-30)) / logRatio)), kB = int32_t(std::floor(std::log(b) / logRatio));
  for (int32_t k = kA; k <= kB; ++k) {
    const double lo = std::max(a, std::exp(double(k) * logRatio)), hi = std::min(b, std::exp(double(k + 1) * logRatio));
    if (!(hi > lo)) continue;
    VolumeSlice vs;
    vs.slice = k, vs.zFront = float(lo), vs.zBack = float(hi);
    if (segment(lo, hi, vs.segment)) slices->push_back(vs);
  }
}

// ------------------------------------------------------------------------------------------
// Lighting: cached shadows

struct VdbLighting final : VolumeLightingEngine {
  VdbLighting(const VdbScene& scene, const VolumeCamera& camera);
  uint64_t buildSteps() const override { return steps; }
  std::vector<Vec3SGrid::Ptr> grids;  // per volume: the in-scattered light on its lattice (null: not cached)
  uint64_t steps = 0;
};

VdbLighting::VdbLighting(const VdbScene& scene, const VolumeCamera& camera) {
  const auto& volumes = scene.volumes;
  grids.resize(volumes.size());
  // Shadow rays are marched by tracers of their own, one per thread, at the reference frame.
  tbb::enumerable_thread_specific<std::unique_ptr<VdbTracer>> tracers;
  std::atomic<uint64_t> steps{0};
  for (size_t v = 0; v < volumes.size(); ++v) {
    const auto& vol = volumes[v];
    if (vol.velocity || vol.spec.fileToCamera.size() > 1) continue;  // its light moves with it: lit per step instead
    // The lattice: twice the voxel size, over every active voxel (or tile) dilated by the
    // interpolation's reach.
    openvdb::math::Transform::Ptr xform = vol.density->transform().copy();
    xform->preScale(2.0);
    Vec3SGrid::Ptr grid = Vec3SGrid::create(openvdb::Vec3s(0.f));
    grid->setTransform(xform);
    {
      auto acc = grid->getAccessor();
      for (auto it = vol.density->cbeginValueOn(); it; ++it) {
        openvdb::CoordBBox box;
        it.getBoundingBox(box);
        const openvdb::Coord lo((box.min().x() - 2) >> 1, (box.min().y() - 2) >> 1, (box.min().z() - 2) >> 1);
        const openvdb::Coord hi((box.max().x() + 2) >> 1, (box.max().y() + 2) >> 1, (box.max().z() + 2) >> 1);
        for (int x = lo.x(); x <= hi.x(); ++x)
          for (int y = lo.y(); y <= hi.y(); ++y)
            for (int z = lo.z(); z <= hi.z(); ++z) acc.setValueOn(openvdb::Coord(x, y, z));
      }
    }
    // File world → camera for this volume: the tracer's placement, inverted.
    VdbTracer probe(scene, camera, camera.referenceFrame, camera.referenceFrame, nullptr);
    const glm::dmat4 fileToCamera = glm::inverse(probe.volumes[v].cameraToFile);
    const double g = vol.spec.anisotropy;
    openvdb::tree::LeafManager<openvdb::Vec3STree> leaves(grid->tree());
    tbb::parallel_for(tbb::blocked_range<size_t>(0, leaves.leafCount()), [&](const tbb::blocked_range<size_t>& range) {
      auto& tracer = tracers.local();
      if (!tracer) tracer = std::make_unique<VdbTracer>(scene, camera, camera.referenceFrame, camera.referenceFrame, nullptr);
      uint64_t lookups = 0;
      for (size_t i = range.begin(); i != range.end(); ++i)
        for (auto it = leaves.leaf(i).beginValueOn(); it; ++it) {
          const glm::dvec3 f = toGlm(grid->indexToWorld(it.getCoord()));
          const glm::dvec3 p = glm::dvec3(fileToCamera * glm::dvec4(f, 1.0));
          // Toward the eye: exact for a perspective camera (the eye is the origin), the view
          // axis for an orthographic one.
          const glm::dvec3 toEye = camera.perspective ? -glm::normalize(p) : glm::dvec3(0, 0, -1);
          double S[3];
          tracer->inScattered(p, toEye, g, 0.0, S, lookups);
          it.setValue(openvdb::Vec3s(float(S[0]), float(S[1]), float(S[2])));
        }
      steps += lookups;
    });
    grids[v] = grid;
  }
  this->steps = steps;
}

void VdbTracer::cacheLighting(const VdbLighting& lighting) {
  const auto& grids = lighting.grids;
  lightCache.resize(grids.size());
  for (size_t v = 0; v < grids.size(); ++v)
    if (const Vec3SGrid::Ptr& g = grids[v]) {
      LightLookup& c = lightCache[v];
      c.grid = g.get();
      c.acc.emplace(g->getConstAccessor());
      c.index = Affine(indexFromWorld(*g) * volumes[v].cameraToFile);
    }
}

// ------------------------------------------------------------------------------------------
// The engine the plugin exports

struct VdbEngine final : VolumeEngine {
  std::unique_ptr<VolumeSceneEngine> load(const std::vector<VolumeSpec>& specs, const VolumeOptions& options,
                                          std::vector<std::string>& warnings) const override {
    return loadScene(specs, options, warnings);
  }
  std::unique_ptr<VolumeSceneEngine> merge(const VolumeSceneEngine& base, const VolumeSceneEngine& more) const override {
    const auto& b = static_cast<const VdbScene&>(base);
    const auto& m = static_cast<const VdbScene&>(more);
    auto scene = std::make_unique<VdbScene>();
    scene->opts = b.opts;
    scene->volumes = b.volumes;
    scene->volumes.insert(scene->volumes.end(), m.volumes.begin(), m.volumes.end());
    return scene;
  }
  std::unique_ptr<VolumeLightingEngine> light(const VolumeSceneEngine& scene, const VolumeCamera& camera) const override {
    return std::make_unique<VdbLighting>(static_cast<const VdbScene&>(scene), camera);
  }
  std::unique_ptr<VolumeTracerEngine> tracer(const VolumeSceneEngine& scene, const VolumeCamera& camera, double earliest, double latest,
                                             const VolumeLightingEngine* lighting) const override {
    return std::make_unique<VdbTracer>(static_cast<const VdbScene&>(scene), camera, earliest, latest, static_cast<const VdbLighting*>(lighting));
  }
  void writeSmokePuff(const std::string& path, const SmokePuff& puff) const override { writeSmokeVdb(path, puff); }
};

}  // namespace
}  // namespace reshutter::resample

extern "C" __attribute__((visibility("default"))) const reshutter::resample::VolumeEngine* reshutter_volume_engine_v2() {
  static const reshutter::resample::VdbEngine engine;
  return &engine;
}
