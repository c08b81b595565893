#include "resample/volume.h"

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <mutex>
#include <optional>
#include <sstream>

#include <openvdb/openvdb.h>
#include <openvdb/tools/Interpolation.h>
#include <openvdb/tools/RayIntersector.h>
#include <glm/geometric.hpp>
#include <glm/mat4x4.hpp>

#include "common/error.h"

namespace reshutter::resample {

namespace {

using openvdb::FloatGrid;
using openvdb::Vec3SGrid;
using Intersector = openvdb::tools::VolumeRayIntersector<FloatGrid>;
using IndexRay = openvdb::math::Ray<double>;

double parseNumber(const std::string& text, const std::string& where, const std::string& key) {
  try {
    size_t used = 0;
    const double v = std::stod(text, &used);
    if (used == text.size() && std::isfinite(v)) return v;
  } catch (const std::exception&) {
  }
  fail(where, "'", key, "' wants a number, not '", text, "'");
}

glm::dvec3 parseTriple(const std::string& text, const std::string& where, const std::string& key) {
  std::vector<std::string> parts;
  std::stringstream in(text);
  for (std::string p; std::getline(in, p, ':');) parts.push_back(p);
  if (parts.size() != 3) fail(where, "'", key, "' wants three numbers X:Y:Z, not '", text, "'");
  return {parseNumber(parts[0], where, key), parseNumber(parts[1], where, key), parseNumber(parts[2], where, key)};
}

glm::dvec3 toGlm(const openvdb::Vec3d& v) { return {v.x(), v.y(), v.z()}; }
openvdb::Vec3d toVdb(const glm::dvec3& v) { return {v.x, v.y, v.z}; }

}  // namespace

VolumeSpec VolumeSpec::parse(const std::string& text, const std::string& where) {
  VolumeSpec s;
  std::vector<std::string> fields;
  std::stringstream in(text);
  for (std::string f; std::getline(in, f, ',');) fields.push_back(f);
  if (fields.empty() || fields[0].empty()) fail(where, "a volume starts with its OpenVDB file: FILE.vdb[,density=GRID][,scale=S]...");
  s.path = fields[0];
  for (size_t i = 1; i < fields.size(); ++i) {
    const size_t eq = fields[i].find('=');
    if (eq == std::string::npos) fail(where, "'", fields[i], "' is not KEY=VALUE");
    const std::string key = fields[i].substr(0, eq), value = fields[i].substr(eq + 1);
    if (key == "density") s.density = value;
    else if (key == "emission") s.emission = value;
    else if (key == "velocity") s.velocity = value;
    else if (key == "scale") s.scale = parseNumber(value, where, key);
    else if (key == "translate") s.translate = parseTriple(value, where, key);
    else if (key == "density-scale") s.densityScale = float(parseNumber(value, where, key));
    else if (key == "emission-color") s.emissionColour = glm::vec3(parseTriple(value, where, key));
    else fail(where, "unknown volume key '", key, "' (density emission velocity scale translate density-scale emission-color)");
  }
  if (s.density.empty()) fail(where, "a volume needs a density grid");
  if (!(s.scale > 0)) fail(where, "'scale' must be positive");
  if (!(s.densityScale >= 0)) fail(where, "'density-scale' must not be negative");
  return s;
}

// ------------------------------------------------------------------------------------------
// Loading

struct VolumeScene::Impl {
  struct Volume {
    VolumeSpec spec;
    FloatGrid::Ptr density;
    FloatGrid::Ptr emissionScalar;
    Vec3SGrid::Ptr emissionColour;
    Vec3SGrid::Ptr velocity;
    std::unique_ptr<Intersector> intersector;  // the master the tracers copy (shallowly)
    // The active voxels' bounds (dilated by the interpolation's reach) in the file's world space.
    glm::dvec3 fileLo{0.0}, fileHi{0.0};
    double maxSpeed = 0;  // file world units per second
  };
  std::vector<Volume> volumes;
};

namespace {

std::once_flag vdbInitialised;

template <class GridT>
typename GridT::Ptr readGrid(openvdb::io::File& file, const std::string& path, const std::string& name, const char* wanted) {
  if (!file.hasGrid(name)) {
    std::string names;
    for (auto it = file.beginName(); it != file.endName(); ++it) names += (names.empty() ? "" : " ") + it.gridName();
    fail(path, "no grid named '", name, "' (the file has: ", names.empty() ? "no grids" : names, ")");
  }
  openvdb::GridBase::Ptr base = file.readGrid(name);
  typename GridT::Ptr grid = openvdb::gridPtrCast<GridT>(base);
  if (!grid) fail(path, "grid '", name, "' holds ", base->valueType(), " values; a volume's '", name, "' must be a ", wanted, " grid");
  if (!grid->hasUniformVoxels()) fail(path, "grid '", name, "' has non-uniform voxels, which the ray marcher does not support");
  if (!grid->transform().isLinear()) fail(path, "grid '", name, "' has a non-linear (frustum) transform, which the ray marcher does not support");
  return grid;
}

// Non-finite values of a float grid become zero; returns how many there were.
size_t zeroNonFinite(FloatGrid& grid) {
  size_t bad = 0;
  for (auto it = grid.beginValueOn(); it; ++it)
    if (!std::isfinite(*it)) it.setValue(0.f), ++bad;
  return bad;
}

}  // namespace

VolumeScene::VolumeScene(const std::vector<VolumeSpec>& specs, const VolumeOptions& options) : options_(options), impl_(std::make_unique<Impl>()) {
  std::call_once(vdbInitialised, [] { openvdb::initialize(); });
  if (!(options_.step > 0)) fail("--volume-step", "the step must be positive");
  for (const VolumeSpec& spec : specs) {
    const std::string& path = spec.path;
    if (!std::filesystem::exists(path)) fail(path, "no such file");
    Impl::Volume v;
    v.spec = spec;
    openvdb::io::File file(path);
    try {
      file.open(false);
    } catch (const std::exception& e) {
      fail(path, "not a readable OpenVDB file (", e.what(), ")");
    }
    try {
      v.density = readGrid<FloatGrid>(file, path, spec.density, "float");
      if (!spec.emission.empty()) {
        if (!file.hasGrid(spec.emission)) readGrid<FloatGrid>(file, path, spec.emission, "float or vec3");  // fails naming the grids
        openvdb::GridBase::Ptr base = file.readGrid(spec.emission);
        v.emissionScalar = openvdb::gridPtrCast<FloatGrid>(base);
        v.emissionColour = openvdb::gridPtrCast<Vec3SGrid>(base);
        if (!v.emissionScalar && !v.emissionColour)
          fail(path, "grid '", spec.emission, "' holds ", base->valueType(), " values; emission must be a float or vec3 grid");
      }
      std::string velocityName = spec.velocity;
      if (velocityName.empty()) velocityName = file.hasGrid("vel") ? "vel" : file.hasGrid("v") ? "v" : "";
      if (!velocityName.empty()) v.velocity = readGrid<Vec3SGrid>(file, path, velocityName, "vec3");
    } catch (const Error&) {
      throw;
    } catch (const std::exception& e) {
      fail(path, "reading its grids failed: ", e.what());
    }
    file.close();
    if (const size_t bad = zeroNonFinite(*v.density))
      warnings_.push_back(cat(path, ": ", bad, " non-finite density value", bad == 1 ? "" : "s", " set to zero"));
    if (v.emissionScalar) zeroNonFinite(*v.emissionScalar);
    if (v.density->empty() || v.density->activeVoxelCount() == 0) {
      warnings_.push_back(cat(path, ": grid '", spec.density, "' has no active voxels; the volume is left out"));
      continue;
    }
    // Dilated by one voxel: trilinear interpolation reaches one voxel beyond the active ones.
    v.intersector = std::make_unique<Intersector>(*v.density, 1);
    const openvdb::CoordBBox box = v.intersector->bbox();
    glm::dvec3 lo(INFINITY), hi(-INFINITY);
    for (int c = 0; c < 8; ++c) {
      const openvdb::Vec3d corner((c & 1) ? box.max().x() : box.min().x(), (c & 2) ? box.max().y() : box.min().y(), (c & 4) ? box.max().z() : box.min().z());
      const glm::dvec3 w = toGlm(v.density->indexToWorld(corner));
      lo = glm::min(lo, w), hi = glm::max(hi, w);
    }
    v.fileLo = lo, v.fileHi = hi;
    if (v.velocity)
      for (auto it = v.velocity->cbeginValueOn(); it; ++it) {
        const double s = double(it->length());
        if (std::isfinite(s)) v.maxSpeed = std::max(v.maxSpeed, s);
      }
    impl_->volumes.push_back(std::move(v));
  }
}

VolumeScene::~VolumeScene() = default;
size_t VolumeScene::size() const { return impl_->volumes.size(); }

// ------------------------------------------------------------------------------------------
// Tracing

struct VolumeTracer::Impl {
  struct PerVolume {
    const VolumeScene::Impl::Volume* v;
    Intersector intersector;  // shallow copy of the master: its own ray and accessor
    FloatGrid::ConstAccessor density;
    std::optional<FloatGrid::ConstAccessor> emissionScalar;
    std::optional<Vec3SGrid::ConstAccessor> emissionColour, velocity;
    // Camera space → the file's index space, affine: index = cameraToIndex · camera point.
    glm::dmat4 cameraToFile{1.0};
    double reach = 0;             // file world units the velocity can carry density over the render's times
    bool hdda = true;             // the intersector's dilation covers the reach
    glm::dvec3 lo{0.0}, hi{0.0};  // file world bounds widened by the reach
  };
  Impl(const VolumeScene& s, const VolumeCamera& c) : scene(s), camera(c) {}
  const VolumeScene& scene;
  VolumeCamera camera;
  glm::dmat4 cameraToWorld{1.0};
  std::vector<PerVolume> volumes;
  std::vector<std::pair<double, double>> spans;  // scratch: a ray's intervals in camera depth
};

VolumeTracer::VolumeTracer(const VolumeScene& scene, const VolumeCamera& camera, double earliest, double latest)
    : impl_(std::make_unique<Impl>(scene, camera)) {
  Impl& m = *impl_;
  m.cameraToWorld = glm::inverse(camera.worldToCamera);
  const double maxSeconds = std::max(std::abs(earliest - camera.referenceFrame), std::abs(latest - camera.referenceFrame)) / camera.framesPerSecond;
  m.volumes.reserve(scene.impl().volumes.size());
  for (const auto& v : scene.impl().volumes) {
    Impl::PerVolume pv{&v, Intersector(*v.intersector), FloatGrid::ConstAccessor(v.density->getConstAccessor()), {}, {}, {}};
    if (v.emissionScalar) pv.emissionScalar.emplace(v.emissionScalar->getConstAccessor());
    if (v.emissionColour) pv.emissionColour.emplace(v.emissionColour->getConstAccessor());
    if (v.velocity) pv.velocity.emplace(v.velocity->getConstAccessor());
    // world = translate + scale · file world  ⇒  file world = (world - translate) / scale.
    glm::dmat4 worldToFile(1.0 / v.spec.scale);
    worldToFile[3] = glm::dvec4(-v.spec.translate / v.spec.scale, 1.0);
    pv.cameraToFile = worldToFile * m.cameraToWorld;
    pv.reach = v.maxSpeed * maxSeconds;
    // A moving volume's density comes from up to `reach` away: the dilated intersector covers
    // one voxel; beyond that the march steps through the (widened) bounds instead.
    pv.hdda = scene.options().skipEmpty && pv.reach <= 0.0;
    pv.lo = v.fileLo - glm::dvec3(pv.reach), pv.hi = v.fileHi + glm::dvec3(pv.reach);
    m.volumes.push_back(std::move(pv));
  }
}

VolumeTracer::~VolumeTracer() = default;

bool VolumeTracer::touches(double x0, double y0, double x1, double y1) const {
  const Impl& m = *impl_;
  const VolumeCamera& c = m.camera;
  for (const auto& pv : m.volumes) {
    // The bounds' corners in camera space, projected; a corner at or behind the eye plane makes
    // the projection unbounded.
    const glm::dmat4 fileToCamera = glm::inverse(pv.cameraToFile);
    double lx = INFINITY, ly = INFINITY, hx = -INFINITY, hy = -INFINITY;
    bool unbounded = false;
    for (int k = 0; k < 8; ++k) {
      const glm::dvec3 f((k & 1) ? pv.hi.x : pv.lo.x, (k & 2) ? pv.hi.y : pv.lo.y, (k & 4) ? pv.hi.z : pv.lo.z);
      const glm::dvec3 p = glm::dvec3(fileToCamera * glm::dvec4(f, 1.0));
      if (c.perspective && !(p.z > 1e-9)) {
        unbounded = true;
        break;
      }
      const double iz = c.perspective ? 1.0 / p.z : 1.0;
      const double rx = c.ax * p.x * iz + c.bx, ry = c.ay * p.y * iz + c.by;
      lx = std::min(lx, rx), hx = std::max(hx, rx), ly = std::min(ly, ry), hy = std::max(hy, ry);
    }
    if (unbounded) return true;
    // Screen y may run either way (ay < 0): the box is min/max either way.
    if (hx >= x0 - 1 && lx <= x1 + 1 && hy >= y0 - 1 && ly <= y1 + 1) return true;
  }
  return false;
}

void VolumeTracer::integrate(double x, double y, double t, double z0, double z1, VolumeSegment& out, std::vector<VolumeSlice>* slices, double ratio) {
  Impl& m = *impl_;
  out = VolumeSegment{};
  if (!(z1 > z0)) return;
  const VolumeCamera& c = m.camera;
  // Camera-space ray: point(z) = origin + dir · z.
  glm::dvec3 origin(0.0), dir(0.0, 0.0, 1.0);
  if (c.perspective) dir = {(x - c.bx) / c.ax, (y - c.by) / c.ay, 1.0};
  else origin = {(x - c.bx) / c.ax, (y - c.by) / c.ay, 0.0};
  const double worldPerZ = glm::length(glm::dvec3(m.cameraToWorld * glm::dvec4(dir, 0.0)));
  const double seconds = (t - c.referenceFrame) / c.framesPerSecond;
  const double zFar = std::isfinite(z1) ? z1 : 1e30;

  // Each volume's intervals of camera depth that may hold density, merged.
  m.spans.clear();
  double stepZ = INFINITY;
  for (auto& pv : m.volumes) {
    const glm::dvec3 f0 = glm::dvec3(pv.cameraToFile * glm::dvec4(origin, 1.0)), fd = glm::dvec3(pv.cameraToFile * glm::dvec4(dir, 0.0));
    // Clip to the (widened) bounds in the file's world space: the slab test.
    double a = z0, b = zFar;
    for (int k = 0; k < 3 && a <= b; ++k) {
      if (fd[k] == 0.0) {
        if (f0[k] < pv.lo[k] || f0[k] > pv.hi[k]) a = INFINITY;
        continue;
      }
      double ta = (pv.lo[k] - f0[k]) / fd[k], tb = (pv.hi[k] - f0[k]) / fd[k];
      if (ta > tb) std::swap(ta, tb);
      a = std::max(a, ta), b = std::min(b, tb);
    }
    if (!(a < b)) continue;
    ++stats_.rays;
    const FloatGrid& grid = *pv.v->density;
    const glm::dvec3 i0 = toGlm(grid.worldToIndex(toVdb(f0))), i1 = toGlm(grid.worldToIndex(toVdb(f0 + fd)));
    const double indexPerZ = glm::length(i1 - i0);
    if (!(indexPerZ > 0)) continue;
    stepZ = std::min(stepZ, double(m.scene.options().step) / indexPerZ);
    if (!pv.hdda) {
      m.spans.emplace_back(a, b);
      continue;
    }
    IndexRay ray(toVdb(i0), toVdb(i1 - i0), a, b);
    if (!pv.intersector.setIndexRay(ray)) continue;
    double s0, s1;
    while (pv.intersector.march(s0, s1)) m.spans.emplace_back(std::max(s0, a), std::min(s1, b));
  }
  if (m.spans.empty()) return;
  std::sort(m.spans.begin(), m.spans.end());
  // Merge overlapping intervals in place.
  size_t n = 0;
  for (size_t i = 1; i < m.spans.size(); ++i)
    if (m.spans[i].first <= m.spans[n].second) m.spans[n].second = std::max(m.spans[n].second, m.spans[i].second);
    else m.spans[++n] = m.spans[i];
  m.spans.resize(n + 1);

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
      const glm::dvec3 p = origin + dir * z;
      double sigma = 0, e[3] = {0, 0, 0};
      for (auto& pv : m.volumes) {
        glm::dvec3 f = glm::dvec3(pv.cameraToFile * glm::dvec4(p, 1.0));
        if (pv.velocity && seconds != 0.0) {
          // Semi-Lagrangian: the density here at this time is the file's density where the
          // flow carried it from (velocity sampled here).
          const openvdb::Vec3s vel = openvdb::tools::BoxSampler::sample(*pv.velocity, pv.v->velocity->worldToIndex(toVdb(f)));
          f -= glm::dvec3(vel.x(), vel.y(), vel.z()) * seconds;
        }
        if (f.x < pv.lo.x || f.y < pv.lo.y || f.z < pv.lo.z || f.x > pv.hi.x || f.y > pv.hi.y || f.z > pv.hi.z) continue;
        const openvdb::Vec3d ip = pv.v->density->worldToIndex(toVdb(f));
        ++stats_.steps;
        const float d = openvdb::tools::BoxSampler::sample(pv.density, ip);
        if (d > 0.f) sigma += double(d) * pv.v->spec.densityScale;
        if (pv.emissionScalar) {
          const float em = openvdb::tools::BoxSampler::sample(*pv.emissionScalar, pv.v->emissionScalar->worldToIndex(toVdb(f)));
          for (int k = 0; k < 3; ++k) e[k] += double(em) * pv.v->spec.emissionColour[k];
        } else if (pv.emissionColour) {
          const openvdb::Vec3s em = openvdb::tools::BoxSampler::sample(*pv.emissionColour, pv.v->emissionColour->worldToIndex(toVdb(f)));
          for (int k = 0; k < 3; ++k) e[k] += double(em[k]) * pv.v->spec.emissionColour[k];
        }
      }
      // Over the step the medium is taken as constant: transmittance e^{-σ ds}, and the
      // emission it adds toward the eye ∫ e^{-σ s} E ds = E (1 - e^{-σ ds}) / σ.
      const double tau = sigma * ds;
      const double stepT = std::exp(-tau);
      const double gain = tau > 1e-9 ? (1.0 - stepT) / sigma : ds;
      for (int k = 0; k < 3; ++k) L[k] += T * e[k] * gain;
      T *= stepT;
      if (slices && (tau > 0.0 || e[0] != 0.0 || e[1] != 0.0 || e[2] != 0.0)) {
        // The slice spans the steps that hold medium, so deep samples hug it.
        for (int k = 0; k < 3; ++k) sliceL[k] += sliceT * e[k] * gain;
        sliceT *= stepT;
        cur.zFront = std::min(cur.zFront, float(z - 0.5 * dz)), cur.zBack = float(z + 0.5 * dz);
      }
    }
  }
  if (slices) closeSlice();
  for (int k = 0; k < 3; ++k) out.radiance[k] = float(L[k]);
  out.transmittance = float(T);
}

}  // namespace reshutter::resample
