#include "resample/camera_view.h"

#include <algorithm>
#include <cmath>
#include <cstdio>

#include <glm/geometric.hpp>
#include <glm/mat3x3.hpp>

#include <tbb/parallel_for.h>

#include "common/error.h"

namespace reshutter::resample {

store::Camera lookAtCamera(const store::Camera& base, const glm::dvec3& from, const glm::dvec3& to, const glm::dvec3& up, std::optional<double> fovDegrees) {
  const glm::dvec3 forward = to - from;
  if (!(glm::length(forward) > 0) || !std::isfinite(glm::length(forward))) fail("--look-at", "the camera looks from where it looks at (or at a non-finite point)");
  const glm::dvec3 z = glm::normalize(forward);
  const glm::dvec3 side = glm::cross(up, z);
  if (!(glm::length(side) > 1e-9 * glm::length(up))) fail("--up", "the up vector is parallel to the view direction (or zero)");
  // RenderMan's camera space: x right, y up, z forward - left-handed when the world is.
  glm::dvec3 x = glm::normalize(side);
  const glm::dvec3 y = glm::cross(z, x);
  if (glm::determinant(glm::dmat3(base.worldToCamera)) < 0) x = -x;
  glm::dmat4 m(1.0);  // m[column][row]
  for (int c = 0; c < 3; ++c) m[c][0] = x[c], m[c][1] = y[c], m[c][2] = z[c];
  m[3][0] = -glm::dot(x, from), m[3][1] = -glm::dot(y, from), m[3][2] = -glm::dot(z, from);
  store::Camera cam = base;
  cam.name = "look-at";
  cam.worldToCamera = m;
  cam.motionTimes.clear(), cam.motionWorldToCamera.clear();  // it stands where it is put
  if (fovDegrees) {
    if (!(*fovDegrees > 0 && *fovDegrees < 180)) fail("--fov", "the field of view must lie in (0, 180) degrees, got ", *fovDegrees);
    if (base.projection != store::Projection::Perspective) fail("--fov", "the camera is orthographic: it has no field of view");
    cam.fovDegrees = *fovDegrees;
  }
  return cam;
}

store::Camera movingLookAtCamera(const store::Camera& base, const glm::dvec3 from[2], const glm::dvec3 to[2], const glm::dvec3& up, std::optional<double> fovDegrees,
                                 double open, double close) {
  store::Camera cam = lookAtCamera(base, from[0], to[0], up, fovDegrees);
  if (from[0] == from[1] && to[0] == to[1]) return cam;
  if (!(close > open)) return cam;  // a zero-length shutter: where it is at the open
  const double cosTurn = std::clamp(glm::dot(glm::normalize(to[1] - from[1]), glm::normalize(to[0] - from[0])), -1.0, 1.0);
  const double turnDegrees = std::acos(cosTurn) * 180.0 / M_PI;
  const int steps = std::clamp(int(std::ceil(turnDegrees / kTurnStepDegrees - 1e-4)), 1, 36);  // 10.00001 degrees is one step
  for (int i = 0; i <= steps; ++i) {
    const double w = double(i) / steps;
    cam.motionTimes.push_back(i == steps ? close : open + w * (close - open));
    cam.motionWorldToCamera.push_back(lookAtCamera(base, from[0] + w * (from[1] - from[0]), to[0] + w * (to[1] - to[0]), up, fovDegrees).worldToCamera);
  }
  cam.worldToCamera = cam.motionWorldToCamera[0];
  return cam;
}

std::vector<store::Camera> stereoPair(const store::Camera& centre, double baseline, double convergence) {
  if (!(baseline > 0) || !std::isfinite(baseline)) fail("stereo", "the baseline must be a positive distance, got ", baseline);
  if (!(convergence > 0)) fail("stereo", "the convergence distance must be positive, got ", convergence);
  std::vector<store::Camera> eyes;
  double sw[4];
  centre.effectiveScreenWindow(sw);
  const store::Projector p(centre);
  for (const double side : {-1.0, 1.0}) {
    store::Camera eye = centre;
    eye.name = side < 0 ? "left" : "right";
    const double dx = side * 0.5 * baseline;  // the eye's x in the centre camera's space
    glm::dmat4 shift(1.0);
    shift[3][0] = -dx;
    eye.worldToCamera = shift * centre.worldToCamera;
    for (glm::dmat4& w : eye.motionWorldToCamera) w = shift * w;  // a moving rig moves both eyes
    if (std::isfinite(convergence) && centre.projection == store::Projection::Perspective) {
      // A point on the centre's axis at the convergence depth is at x = -dx for this eye: screen
      // x -dx / convergence · scale. Shifting the window by that much puts it back in the middle.
      const double scale = p.ax * (sw[1] - sw[0]) / centre.width;  // screen units per unit of x/z
      const double s = -dx / convergence * scale;
      eye.screenWindow[0] = sw[0] + s, eye.screenWindow[1] = sw[1] + s, eye.screenWindow[2] = sw[2], eye.screenWindow[3] = sw[3];
    }
    eyes.push_back(eye);
  }
  return eyes;
}

std::vector<store::Camera> stereoPair(const store::Camera& centre, const std::string& rig, const std::string& where) {
  double baseline = 0, convergence = INFINITY;
  char extra = 0;
  const int n = std::sscanf(rig.c_str(), "%lf:%lf%c", &baseline, &convergence, &extra);
  if (n < 1 || n > 2 || (n == 1 && rig.find(':') != std::string::npos))
    fail(where, "expected BASELINE or BASELINE:CONVERGENCE (camera-space units), got '", rig, "'");
  try {
    return stereoPair(centre, baseline, convergence);
  } catch (const Error& e) {
    fail(where, e.problem());
  }
}

std::vector<double> carryTimes(const store::Camera& primary, const store::Camera& view, double open, double close) {
  const std::vector<double> moves = store::carryTimes(primary, view);
  return moves.empty() ? moves : store::timesWithin(moves, open, close);
}

bool sameView(const store::Camera& primary, const store::Camera& view) {
  double a[4], b[4];
  primary.effectiveScreenWindow(a), view.effectiveScreenWindow(b);
  return primary.worldToCamera == view.worldToCamera && primary.motionTimes == view.motionTimes &&
         primary.motionWorldToCamera == view.motionWorldToCamera && primary.projection == view.projection && primary.fovDegrees == view.fovDegrees &&
         std::equal(a, a + 4, b) && primary.nearClip == view.nearClip && double(primary.width) * view.height == double(view.width) * primary.height;
}

ViewRelighting::ViewRelighting(const store::StoreMeta& meta, const glm::dmat4& toView, bool perspective) : meta_(meta), perspective_(perspective) {
  using VT = store::ViewTerm;
  const store::Schema& schema = meta.schema;
  cvi_ = schema.find(VT::kViewIndependent), back_ = schema.find(VT::kBackSide), weight_ = schema.find(VT::kWeight), normal_ = schema.find(VT::kNormal), roughness_ = schema.find(VT::kRoughness);
  ci_ = schema.ci();
  if (back_ < 0 || weight_ < 0 || normal_ < 0 || roughness_ < 0 || ci_ < 0) cvi_ = -1;
  for (size_t k = 0; k < meta.lights.size(); ++k) visibility_.push_back(schema.find(VT::visibility(k)));
  for (size_t k = 1; k < meta.shadingTimes.size(); ++k) timedCi_.push_back(schema.find(store::StoreMeta::timedName("Ci", k)));
  const glm::dmat4 toPrimary = glm::inverse(toView);
  eye_ = glm::dvec3(toPrimary * glm::dvec4(0, 0, 0, 1));
  const glm::dvec3 back = glm::dmat3(toPrimary) * glm::dvec3(0, 0, -1);
  towardsEye_ = glm::length(back) > 0 ? glm::normalize(back) : glm::dvec3(0, 0, -1);
}

uint64_t ViewRelighting::apply(const store::TilePart& primary, store::TilePart& carried) const {
  if (!active()) return 0;
  const auto& a = primary.attrs;
  auto present = [&](int slot) { return slot >= 0 && size_t(slot) < a.size() && a[size_t(slot)].f.size() >= size_t(primary.numVertices) * 3; };
  if (!present(cvi_) || !present(back_) || !present(weight_) || !present(normal_) || !present(ci_) || roughness_ >= int(a.size()) ||
      a[size_t(roughness_)].f.size() < primary.numVertices)
    return 0;
  const float *cvi = a[size_t(cvi_)].f.data(), *back = a[size_t(back_)].f.data(), *weight = a[size_t(weight_)].f.data(), *normal = a[size_t(normal_)].f.data();
  const float* roughness = a[size_t(roughness_)].f.data();
  std::vector<const float*> visibility(visibility_.size(), nullptr);
  for (size_t k = 0; k < visibility_.size(); ++k)
    if (visibility_[k] >= 0 && size_t(visibility_[k]) < a.size() && a[size_t(visibility_[k])].f.size() >= primary.numVertices) visibility[k] = a[size_t(visibility_[k])].f.data();
  float* ci = carried.attrs[size_t(ci_)].f.data();
  std::vector<float*> timed;  // the part's colours at later shading times, where it has them
  for (int slot : timedCi_)
    if (slot >= 0 && carried.attrs[size_t(slot)].f.size() >= size_t(primary.numVertices) * 3) timed.push_back(carried.attrs[size_t(slot)].f.data());
  uint64_t relit = 0;
  for (uint32_t i = 0; i < primary.numVertices; ++i) {
    const double r = roughness[i];
    // 0: no inputs (a grid without a view-dependent term shares the part); anything but a lobe's
    // roughness or the two markers is not this format's: the stored colour stands.
    if (!(r > 0 || r == store::ViewTerm::kNoLobe || r == store::ViewTerm::kHeadlight)) continue;
    const glm::dvec3 P(primary.position(0, i));
    const glm::dvec3 toEye = perspective_ ? eye_ - P : towardsEye_;
    if (!(glm::length(toEye) > 0)) continue;
    const glm::dvec3 V = glm::normalize(toEye);
    glm::dvec3 N(normal[3 * i], normal[3 * i + 1], normal[3 * i + 2]);
    const bool backSide = glm::dot(N, V) < 0;  // faceforward for this eye
    if (backSide) N = -N;
    const float* rest = backSide ? back : cvi;
    glm::dvec3 S(0.0);
    if (r == store::ViewTerm::kNoLobe) {
      // Only the side.
    } else if (r == store::ViewTerm::kHeadlight) {
      const double d = glm::dot(V, N);  // defaultsurface's headlight, N unit
      S = glm::dvec3(d * d);
    } else {
      const double exponent = 1.0 / r;
      glm::dvec3 L, Cl;
      for (size_t k = 0; k < meta_.lights.size(); ++k) {
        const double vis = visibility[k] ? double(visibility[k][i]) : 1.0;
        if (vis <= 0 || !meta_.lights[k].illuminate(P, L, Cl)) continue;
        const glm::dvec3 Ln = glm::normalize(L);
        if (glm::dot(Ln, N) <= 0) continue;
        const glm::dvec3 H = Ln + V;
        const double hl = glm::length(H);
        if (!(hl > 0)) continue;
        const double nh = glm::dot(N, H / hl);
        if (nh > 0) S += vis * Cl * std::pow(nh, exponent);
      }
    }
    for (int c = 0; c < 3; ++c) {
      const double value = double(rest[3 * i + c]) + double(weight[3 * i + c]) * S[c];
      const float now = std::isfinite(value) ? float(value) : 0.f;
      const float change = now - ci[3 * i + c];
      ci[3 * i + c] = now;
      for (float* t : timed) t[3 * i + c] += change;
    }
    ++relit;
  }
  return relit;
}

namespace {

std::vector<store::CarriedSchedule> carriedSchedules(const store::StoreMeta& meta, const store::Camera& view) {
  const store::Camera& primary = meta.cameras[0];
  const std::vector<double> times = carryTimes(primary, view, meta.shutterOpen, meta.shutterClose);
  std::vector<store::CarriedSchedule> out;
  if (times.empty()) return out;
  for (size_t s = 0; s < meta.schedules.size(); ++s)
    out.push_back(store::carriedSchedule(meta.schedules[s], s == 0, times, [&](double t) { return store::primaryToView(primary, view, t); }));
  return out;
}

}  // namespace

CarriedStore::CarriedStore(const store::StoreReader& reader, const store::Camera& view, const store::Projector& projector, bool relight)
    : reader_(reader),
      toView_(store::primaryToView(reader.meta().cameras[0], view, reader.meta().shutterOpen)),
      carried_(carriedSchedules(reader.meta(), view)),
      relighting_(reader.meta(), toView_, view.projection == store::Projection::Perspective),
      relight_(relight) {
  const store::Projector primary(reader.meta().cameras[0]);
  if (carried_.empty()) {
    schedules_ = reader.meta().schedules;
    entries_ = store::carriedEntries(reader.entries(), toView_, primary, projector);
  } else {
    for (const store::CarriedSchedule& cs : carried_) schedules_.push_back(cs.times);
    entries_ = store::carriedEntries(reader.entries(), carried_, primary, projector);
  }
  bounds_ = store::ViewBounds(entries_, schedules_, projector, reader.meta().shutterOpen, reader.meta().shutterClose);
}

std::shared_ptr<const store::TilePart> CarriedStore::part(size_t entry, uint64_t& relit) const {
  const std::shared_ptr<const store::TilePart> primary = reader_.part(entry);
  const store::Schema& schema = reader_.meta().schema;
  auto carried = std::make_shared<store::TilePart>(carried_.empty() ? store::carriedPart(*primary, toView_, schema)
                                                                    : store::carriedPart(*primary, carried_[reader_.entries()[entry].schedule], schema));
  if (relight_) relit += relighting_.apply(*primary, *carried);
  return carried;
}

namespace {

// Whether the segment a → b meets the rectangle [x0, x1] × [y0, y1] (Liang-Barsky).
bool segmentMeetsRect(glm::dvec2 a, glm::dvec2 b, double x0, double y0, double x1, double y1) {
  double t0 = 0, t1 = 1;
  const glm::dvec2 d = b - a;
  const double p[4] = {-d.x, d.x, -d.y, d.y}, q[4] = {a.x - x0, x1 - a.x, a.y - y0, y1 - a.y};
  for (int i = 0; i < 4; ++i) {
    if (p[i] == 0) {
      if (q[i] < 0) return false;
      continue;
    }
    const double r = q[i] / p[i];
    if (p[i] < 0) t0 = std::max(t0, r);
    else t1 = std::min(t1, r);
    if (t0 > t1) return false;
  }
  return true;
}

}  // namespace

std::vector<uint8_t> unseenPixels(const store::StoreReader& reader, const store::Camera& view, const glm::dmat4& toView, int width, int height) {
  std::vector<uint8_t> unseen(size_t(width) * size_t(height), 0);
  const store::StoreMeta& meta = reader.meta();
  const store::Projector vp(view);
  if (!vp.perspective || meta.cameras.empty()) return unseen;
  // The depths the store's parts reach, along the view's rays: bounded by the primary's depths
  // carried (a rigid move changes depths by at most the distance between the eyes).
  const glm::dmat4 toPrimary = glm::inverse(toView);
  const double shift = glm::length(glm::dvec3(toPrimary[3]));
  const store::ViewBounds& stored = reader.primaryBounds();
  double lo = stored.depths().first, hi = stored.depths().second;
  if (!(hi > 0) || !std::isfinite(hi)) return unseen;
  const double zFar = hi + shift;
  lo = std::max(view.nearClip, lo - shift);
  // Every recorded camera's frame, and the primary's kept bounds.
  struct Frame {
    glm::dmat4 fromPrimary;
    store::Projector proj;
    double x0, y0, x1, y1;
  };
  std::vector<Frame> frames;
  for (size_t c = 0; c < meta.cameras.size(); ++c) {
    const store::Camera& cam = meta.cameras[c];
    frames.push_back({store::primaryToView(meta.cameras[0], cam), store::Projector(cam), 0, 0, double(cam.width), double(cam.height)});
  }
  const store::RasterRect kept = stored.extent();
  if (!kept.empty) frames.push_back({glm::dmat4(1.0), store::Projector(meta.cameras[0]), kept.x0, kept.y0, kept.x1, kept.y1});
  tbb::parallel_for(0, height, [&](int y) {
    for (int x = 0; x < width; ++x) {
      const glm::dvec2 r(x + 0.5, y + 0.5);
      const glm::dvec3 a(toPrimary * glm::dvec4(vp.unproject(r, lo), 1.0)), b(toPrimary * glm::dvec4(vp.unproject(r, zFar), 1.0));
      bool seen = false;
      for (const Frame& f : frames) {
        glm::dvec3 pa(f.fromPrimary * glm::dvec4(a, 1.0)), pb(f.fromPrimary * glm::dvec4(b, 1.0));
        if (f.proj.perspective) {
          // The part of the segment in front of this camera's near plane.
          const double near = f.proj.nearClip;
          if (pa.z < near && pb.z < near) continue;
          if (pa.z < near) pa += (pb - pa) * ((near - pa.z) / (pb.z - pa.z));
          if (pb.z < near) pb += (pa - pb) * ((near - pb.z) / (pa.z - pb.z));
        }
        if (segmentMeetsRect(f.proj.project(pa), f.proj.project(pb), f.x0, f.y0, f.x1, f.y1)) {
          seen = true;
          break;
        }
      }
      unseen[size_t(y) * size_t(width) + size_t(x)] = !seen;
    }
  });
  return unseen;
}

store::StoredLight carriedLight(const store::StoredLight& light, const glm::dmat4& toView) {
  store::StoredLight l = light;
  l.position = glm::dvec3(toView * glm::dvec4(light.position, 1.0));
  const glm::dvec3 axis = glm::dmat3(toView) * light.axis;
  if (glm::length(axis) > 0) l.axis = glm::normalize(axis);
  return l;
}

}  // namespace reshutter::resample
