#include "store/view_bounds.h"

#include <algorithm>
#include <cmath>

#include <glm/mat3x3.hpp>

namespace reshutter::store {

ViewBounds::ViewBounds(const std::vector<TileEntry>& entries, const std::vector<Schedule>& schedules, const Projector& projector, double open, double close)
    : entries_(&entries), schedules_(&schedules), projector_(projector) {
  shutterBounds_.resize(entries.size()), depthRange_.resize(entries.size());
  for (size_t i = 0; i < entries.size(); ++i) {
    const TileEntry& e = entries[i];
    shutterBounds_[i] = boundsOver(e, schedules[e.schedule], projector_, open, close);
    depthRange_[i] = {INFINITY, -INFINITY};
    for (const KnotBounds& kb : e.knots) depthRange_[i].first = std::min(depthRange_[i].first, kb.camera[2]), depthRange_[i].second = std::max(depthRange_[i].second, kb.camera[5]);
  }
}

RasterRect ViewBounds::bounds(size_t i, double t0, double t1) const {
  const TileEntry& e = entries_->at(i);
  return boundsOver(e, (*schedules_)[e.schedule], projector_, t0, t1);
}

RasterRect ViewBounds::extent() const {
  RasterRect r;
  for (const RasterRect& b : shutterBounds_) r.extend(b);
  return r;
}

std::pair<float, float> ViewBounds::depths() const {
  std::pair<float, float> d{INFINITY, -INFINITY};
  for (const auto& [lo, hi] : depthRange_) d.first = std::min(d.first, lo), d.second = std::max(d.second, hi);
  return d;
}

ViewBounds::CircleTotals ViewBounds::circleTotals(const Lens& lens) const {
  CircleTotals t;
  if (!lens.active()) return t;
  for (size_t i = 0; i < depthRange_.size(); ++i) {
    const double coc = circleOfConfusion(lens, depthRange_[i].first, depthRange_[i].second), n = double((*entries_)[i].numMicropolygons);
    if (std::isfinite(coc)) t.weighted += n * coc, t.micropolygons += n;
  }
  return t;
}

void ViewBounds::visit(const RasterRect& rect, double t0, double t1, const std::function<void(size_t)>& fn, const Lens& lens) const {
  for (size_t i = 0; i < entries_->size(); ++i) {
    // A point at depth z moves by a L (1/d - 1/z) on the raster for lens point L: the part's depths
    // bound its reach (a part reaching the eye plane reaches everywhere). No lens: no widening.
    float wx = 0, wy = 0;
    if (lens.active()) {
      const double coc = circleOfConfusion(lens, depthRange_[i].first, depthRange_[i].second);
      if (!std::isfinite(coc)) {
        fn(i);
        continue;
      }
      wx = float(coc * std::abs(projector_.ax) * 1.0001 + 1e-3), wy = float(coc * std::abs(projector_.ay) * 1.0001 + 1e-3);
    }
    auto widened = [&](RasterRect r) {
      if (!r.empty && (wx > 0 || wy > 0)) r.x0 -= wx, r.y0 -= wy, r.x1 += wx, r.y1 += wy;
      return r;
    };
    if (!widened(shutterBounds_[i]).overlaps(rect)) continue;
    if (widened(bounds(i, t0, t1)).overlaps(rect)) fn(i);
  }
}

namespace {

// The box of `points` carried by `m`, padded for the float rounding of a carried position (a
// relative 1e-6), as lo/hi.
void carriedBox(const glm::dvec3* points, int n, const glm::dmat4& m, glm::dvec3* carried, double lo[3], double hi[3]) {
  for (int i = 0; i < 3; ++i) lo[i] = INFINITY, hi[i] = -INFINITY;
  for (int c = 0; c < n; ++c) {
    carried[c] = glm::dvec3(m * glm::dvec4(points[c], 1.0));
    for (int i = 0; i < 3; ++i) lo[i] = std::min(lo[i], carried[c][i]), hi[i] = std::max(hi[i], carried[c][i]);
  }
}

// The projection of the hull of `points` (each padded as a carried position is), when all lie in
// front of the near plane: a perspective projection maps the hull to the hull of the projected
// points. Empty when one does not.
RasterRect projectedHull(const glm::dvec3* points, int n, const double lo[3], const double hi[3], const Projector& projector) {
  RasterRect r;
  for (int c = 0; c < n; ++c) {
    float point[6];
    for (int i = 0; i < 3; ++i) {
      const double pad = 1e-6 * std::max({std::abs(lo[i]), std::abs(hi[i]), 1e-30});
      point[i] = std::nextafter(float(points[c][i] - pad), -INFINITY);
      point[i + 3] = std::nextafter(float(points[c][i] + pad), INFINITY);
    }
    if (projector.perspective && point[2] < projector.nearClip) return RasterRect{};
    r.extend(projectCameraBox(point, projector));
  }
  return r;
}

// One knot's bounds carried into another camera's space. A part's points lie in its camera box,
// and - where its primary raster bound is finite - in the slab of the primary's frustum over that
// bound between the box's depths. For a tile of micropolygons at many depths the slab is far
// tighter than the box (whose corners pair the tile's near x with its far depth), so each bound
// is the intersection of both.
KnotBounds carriedKnot(const KnotBounds& kb, const glm::dmat4& m, const Projector& primary, const Projector& projector) {
  glm::dvec3 box[8], boxCarried[8];
  for (int c = 0; c < 8; ++c) box[c] = {kb.camera[(c & 1) ? 3 : 0], kb.camera[(c & 2) ? 4 : 1], kb.camera[(c & 4) ? 5 : 2]};
  double lo[3], hi[3];
  carriedBox(box, 8, m, boxCarried, lo, hi);
  glm::dvec3 slabCarried[8];
  double slo[3], shi[3];
  const bool slab = kb.rasterFinite && std::isfinite(kb.camera[2]) && std::isfinite(kb.camera[5]) && (!primary.perspective || kb.camera[2] > 0);
  if (slab) {
    glm::dvec3 corners[8];
    for (int c = 0; c < 8; ++c)
      corners[c] = primary.unproject({kb.raster[(c & 1) ? 2 : 0], kb.raster[(c & 2) ? 3 : 1]}, (c & 4) ? kb.camera[5] : kb.camera[2]);
    carriedBox(corners, 8, m, slabCarried, slo, shi);
    for (int i = 0; i < 3; ++i) lo[i] = std::max(lo[i], slo[i]), hi[i] = std::min(hi[i], shi[i]);
  }
  KnotBounds out;
  for (int i = 0; i < 3; ++i) {
    const double pad = 1e-6 * std::max({std::abs(lo[i]), std::abs(hi[i]), 1e-30});
    out.camera[i] = std::nextafter(float(lo[i] - pad), -INFINITY);
    out.camera[i + 3] = std::nextafter(float(hi[i] + pad), INFINITY);
  }
  out.rasterFinite = !projector.perspective || out.camera[2] >= projector.nearClip;
  if (!out.rasterFinite) return out;
  RasterRect r = projectedHull(boxCarried, 8, lo, hi, projector);
  if (slab) {
    const RasterRect t = projectedHull(slabCarried, 8, lo, hi, projector);
    if (!t.empty) r = r.empty ? t : RasterRect{std::max(r.x0, t.x0), std::max(r.y0, t.y0), std::min(r.x1, t.x1), std::min(r.y1, t.y1), false};
  }
  if (r.empty) {
    out.rasterFinite = false;  // unreachable while the box lies in front; the caller projects the box instead
    return out;
  }
  out.raster[0] = r.x0, out.raster[1] = r.y0, out.raster[2] = r.x1, out.raster[3] = r.y1;
  return out;
}

}  // namespace

glm::dmat4 primaryToView(const Camera& primary, const Camera& view) { return view.worldToCamera * glm::inverse(primary.worldToCamera); }

glm::dmat4 primaryToView(const Camera& primary, const Camera& view, double t) { return view.worldToCameraAt(t) * glm::inverse(primary.worldToCameraAt(t)); }

std::vector<double> carryTimes(const Camera& primary, const Camera& view) {
  if (!primary.moving() && !view.moving()) return {};
  const std::vector<double> t = unionTimes(primary.motionTimes, view.motionTimes);
  // Both are linear between these times: one transform at all of them is one at every time.
  const glm::dmat4 first = primaryToView(primary, view, t[0]);
  for (double x : t) {
    const glm::dmat4 m = primaryToView(primary, view, x);
    for (int i = 0; i < 4; ++i)
      for (int j = 0; j < 4; ++j)
        if (std::abs(m[i][j] - first[i][j]) > 1e-12 * (1.0 + std::abs(first[i][j]))) return t;
  }
  return {};
}

std::vector<TileEntry> carriedEntries(const std::vector<TileEntry>& entries, const glm::dmat4& primaryToView, const Projector& primary, const Projector& projector) {
  std::vector<TileEntry> out = entries;
  for (TileEntry& e : out)
    for (KnotBounds& kb : e.knots) kb = carriedKnot(kb, primaryToView, primary, projector);
  return out;
}

namespace {

// Point, vector and normal attributes carried by `primaryToView`.
void carryAttributes(TilePart& out, const glm::dmat4& primaryToView, const Schema& schema) {
  const glm::dmat3 linear(primaryToView);
  const glm::dmat3 normals = glm::transpose(glm::inverse(linear));
  for (size_t a = 0; a < schema.attrs.size() && a < out.attrs.size(); ++a) {
    const AttrType type = schema.attrs[a].type;
    if (type != AttrType::Point && type != AttrType::Vector && type != AttrType::Normal) continue;
    std::vector<float>& f = out.attrs[a].f;
    for (size_t i = 0; i + 2 < f.size(); i += 3) {
      const glm::dvec3 v(f[i], f[i + 1], f[i + 2]);
      const glm::dvec3 w = type == AttrType::Point ? glm::dvec3(primaryToView * glm::dvec4(v, 1.0)) : type == AttrType::Vector ? linear * v : normals * v;
      f[i] = float(w.x), f[i + 1] = float(w.y), f[i + 2] = float(w.z);
    }
  }
}

}  // namespace

TilePart carriedPart(const TilePart& part, const glm::dmat4& primaryToView, const Schema& schema) {
  TilePart out = part;
  for (glm::vec3& p : out.positions) p = glm::vec3(primaryToView * glm::dvec4(glm::dvec3(p), 1.0));
  carryAttributes(out, primaryToView, schema);
  return out;
}

CarriedSchedule carriedSchedule(const Schedule& schedule, bool stillSchedule, const std::vector<double>& carryTimes, const std::function<glm::dmat4(double)>& carry) {
  CarriedSchedule out;
  for (double time : stillSchedule ? carryTimes : unionTimes(carryTimes, schedule)) {
    uint32_t k = 0;
    double w = 0;
    if (!stillSchedule && schedule.size() > 1) {
      while (k + 2 < schedule.size() && schedule[k + 1] <= time) ++k;
      w = std::clamp((time - schedule[k]) / (schedule[k + 1] - schedule[k]), 0.0, 1.0);
      if (w == 1) ++k, w = 0;
    }
    out.times.push_back(time), out.toView.push_back(carry(time)), out.segment.push_back(k), out.weight.push_back(w);
  }
  return out;
}

std::vector<TileEntry> carriedEntries(const std::vector<TileEntry>& entries, const std::vector<CarriedSchedule>& schedules, const Projector& primary,
                                      const Projector& projector) {
  std::vector<TileEntry> out = entries;
  for (TileEntry& e : out) {
    const CarriedSchedule& cs = schedules[e.schedule];
    std::vector<KnotBounds> knots;
    for (size_t j = 0; j < cs.times.size(); ++j) {
      const uint32_t k = cs.segment[j];
      KnotBounds kb = e.knots[k];
      if (cs.weight[j] > 0) {
        // Between two knots a vertex lies on the segment joining its two positions: in the box
        // lerped between the knots' boxes, and - both ends in front - in the union of their
        // raster bounds (a perspective projection maps the segment to the one joining theirs).
        const KnotBounds& b = e.knots[k + 1];
        lerpedCameraBox(e.knots[k].camera, b.camera, cs.weight[j], kb.camera);
        kb.rasterFinite = kb.rasterFinite && b.rasterFinite;
        if (kb.rasterFinite)
          for (int i = 0; i < 2; ++i) kb.raster[i] = std::min(kb.raster[i], b.raster[i]), kb.raster[i + 2] = std::max(kb.raster[i + 2], b.raster[i + 2]);
      }
      knots.push_back(carriedKnot(kb, cs.toView[j], primary, projector));
    }
    e.knots = std::move(knots);
    if (e.knots.size() > 1) e.effects |= kEffectMoving;
  }
  return out;
}

TilePart carriedPart(const TilePart& part, const CarriedSchedule& schedule, const Schema& schema) {
  TilePart out = part;
  const uint32_t K = uint32_t(schedule.times.size()), nV = part.numVertices;
  out.numKnots = K;
  out.positions.resize(size_t(K) * nV);
  for (uint32_t j = 0; j < K; ++j) {
    const uint32_t k = std::min(schedule.segment[j], part.numKnots - 1);
    const double w = k + 1 < part.numKnots ? schedule.weight[j] : 0.0;
    const glm::dmat4& m = schedule.toView[j];
    for (uint32_t v = 0; v < nV; ++v) {
      glm::dvec3 p(part.position(k, v));
      if (w > 0) p += w * (glm::dvec3(part.position(k + 1, v)) - p);
      out.positions[size_t(j) * nV + v] = glm::vec3(m * glm::dvec4(p, 1.0));
    }
  }
  carryAttributes(out, schedule.toView[0], schema);
  return out;
}

}  // namespace reshutter::store
