// Splitting: screen-size driven, crack-free (DiagSplit) splitting of a primitive into leaves.
#include "shade/split.h"

#include <algorithm>
#include <array>
#include <cmath>

#include <glm/geometric.hpp>

#include "shade/dice.h"
#include "store/view_bounds.h"

namespace reshutter::shade {

UV pointOnSegment(const UV& a, const UV& b, int k, int n) {
  if (k <= 0) return a;
  if (k >= n) return b;
  const double t = double(k) / n;
  return {a.u + (b.u - a.u) * t, a.v + (b.v - a.v) * t};
}

std::vector<double> clipKnots(const Primitive& p, double open, double close) {
  std::vector<double> all = p.knotTimes();
  if (all.empty() || !(close > open)) return {open};
  std::vector<double> out{open};
  for (double t : all)
    if (t > open && t < close) out.push_back(t);
  out.push_back(close);
  // Motion that stands still inside the interval (identical keys, or moving only outside it) is
  // static: one knot, schedule 0, and no motion cost downstream.
  const glm::dmat4 m0 = p.xform->at(open);
  const Shape s0 = p.shapeAt(open);
  for (double t : out) {
    if (p.xform->at(t) != m0) return out;
    const Shape s = p.shapeAt(t);
    if (s.q != s0.q || s.P != s0.P || s.cv != s0.cv || s.cw != s0.cw || s.key != s0.key) return out;
  }
  return {open};
}

namespace {

// A side while splitting: the segment (a, b) in its own order; final sides (n > 0) are the
// points lo … hi of its n steps, the others are cut at their middle.
struct Edge {
  UV a, b;
  int n = 0, lo = 0, hi = 0;
  bool collapsed = false;
  double need = 0;  // steps it would take
  UV start() const { return n ? pointOnSegment(a, b, lo, n) : a; }
  UV end() const { return n ? pointOnSegment(a, b, hi, n) : b; }
  int steps() const { return hi - lo; }
  bool cuttableAtAPoint() const { return n && !collapsed && hi - lo >= 2; }
};

// An edge as one piece runs along it: from its start to its end (forward) or back.
struct Side {
  Edge e;
  bool forward = true;
  UV from() const { return forward ? e.start() : e.end(); }
  UV to() const { return forward ? e.end() : e.start(); }
};

struct Piece {
  std::array<Side, 4> s;  // bottom, right, top, left, counter-clockwise
  UV corner(int i) const { return s[size_t(i)].from(); }
};

UV bilinearUV(const Piece& pc, double x, double y) {
  const UV c0 = pc.corner(0), c1 = pc.corner(1), c2 = pc.corner(2), c3 = pc.corner(3);
  const double w0 = (1 - x) * (1 - y), w1 = x * (1 - y), w2 = x * y, w3 = (1 - x) * y;
  return {w0 * c0.u + w1 * c1.u + w2 * c2.u + w3 * c3.u, w0 * c0.v + w1 * c1.v + w2 * c2.v + w3 * c3.v};
}

struct Estimate {
  bool allBehind = true, straddle = false, offscreen = false, beyondFar = true;
  double lu = 0, lv = 0, motion = 0;  // raster lengths in pixels
  double cu = 0, cv = 0;              // camera-space lengths (for eye splits)
};

/// One camera the pieces are measured and culled for: the primary (the store's raster), or another
/// the store records, reached from the primary's camera space by `fromPrimary`.
struct SplitView {
  store::Projector proj;
  const store::Camera* cam = nullptr;
  std::vector<glm::dmat4> fromPrimary;  // at each of the splitter's times (one when it never changes)
  bool primary = true;
  double window[4] = {0, 0, 0, 0};  // raster x0 x1 y0 y1 kept (the screen and the cull margin)
  /// Point c of the primary's camera space at the splitter's time k, in this camera's space.
  glm::dvec3 in(size_t k, const glm::dvec3& c) const {
    return primary ? c : glm::dvec3(fromPrimary[fromPrimary.size() > 1 ? k : 0] * glm::dvec4(c, 1.0));
  }
};

class Splitter {
 public:
  Splitter(const Primitive& p, const std::vector<double>& knots, const store::Camera& cam, const std::vector<store::Camera>& others, const DiceOptions& o,
           std::vector<Leaf>& out, DiceStats& stats)
      : p_(p), o_(o), out_(out), stats_(stats) {
    // Measured and culled at the piece's knots, and - for a camera that moves against the primary
    // (the piece's knots hold the primary's own motion) - at that camera's motion times too.
    times_ = knots;
    std::vector<bool> moves;  // per other camera
    for (const store::Camera& c : others) {
      const std::vector<double> t = store::carryTimes(cam, c);
      moves.push_back(!t.empty());
      if (!t.empty()) times_ = store::unionTimes(times_, t);
    }
    if (times_.empty()) {
      shapes_.push_back(p.keys.empty() ? Shape{} : p.keys[0]);
      mats_.push_back(p.xform->at(0));
    }
    const bool still = knots.empty();  // where it is in the primary's space at every time
    for (double t : times_) {
      shapes_.push_back(still ? (p.keys.empty() ? Shape{} : p.keys[0]) : p.shapeAt(t));
      mats_.push_back(p.xform->at(still ? 0.0 : t));
    }
    const Attributes& a = *p.attrs;
    motionFactor_ = o.motionFactor ? *o.motionFactor : a.motionFactor;
    rate_ = a.shadingRate * o.shadingRateScale;
    views_.push_back(viewOf(cam, cam, true, false));
    for (size_t i = 0; i < others.size(); ++i) views_.push_back(viewOf(cam, others[i], false, moves[i]));
  }

  void run() {
    const UV c[4] = {{0, 0}, {1, 0}, {1, 1}, {0, 1}};
    Piece whole;
    for (int i = 0; i < 4; ++i) whole.s[size_t(i)] = side(c[i], c[(i + 1) % 4]);
    split(whole, 0, 0);
  }

 private:
  static constexpr int kTest = 5;
  using TestPoints = std::array<std::array<glm::dvec3, kTest>, kTest>;  // a piece's test points at one knot

  // `moves`: the carry from the primary into `cam` changes over the shutter (store::carryTimes()).
  SplitView viewOf(const store::Camera& primary, const store::Camera& cam, bool isPrimary, bool moves) const {
    SplitView v;
    v.proj = store::Projector(cam);
    v.cam = &cam;
    v.primary = isPrimary;
    if (!moves) v.fromPrimary = {store::primaryToView(primary, cam)};
    else
      for (double t : times_) v.fromPrimary.push_back(store::primaryToView(primary, cam, t));
    const double mx = o_.cullMargin * cam.width, my = o_.cullMargin * cam.height;
    v.window[0] = -mx, v.window[1] = cam.width + mx, v.window[2] = -my, v.window[3] = cam.height + my;
    return v;
  }

  /// A point of the piece in the primary camera's space.
  glm::dvec3 camera(size_t k, const UV& uv) const { return glm::dvec3(mats_[k] * glm::dvec4(evalP(p_, shapes_[k], uv.u, uv.v), 1.0)); }
  static bool inFront(const SplitView& v, const glm::dvec3& c) { return !v.proj.perspective || c.z >= v.proj.nearClip; }
  double edgeLength(double motion) const { return std::sqrt(rate_ * (1.0 + motionFactor_ * motion / 16.0)); }

  // The side from `from` to `to`, measured along itself alone: the same answer for every piece
  // (of this primitive or of one whose surface meets it there) that has it.
  Side side(const UV& from, const UV& to) const {
    // Its own order: by the end points in space at the first knot (along the axis they differ
    // most in), by (u, v) where they coincide.
    const glm::dvec3 pf = camera(0, from), pt = camera(0, to), d = pt - pf;
    int axis = 0;
    for (int i = 1; i < 3; ++i)
      if (std::abs(d[i]) > std::abs(d[axis])) axis = i;
    const bool fromFirst = d[axis] != 0 ? d[axis] > 0 : (from.u < to.u || (from.u == to.u && from.v < to.v));
    Edge e;
    e.a = fromFirst ? from : to, e.b = fromFirst ? to : from;

    // Measured on every camera's raster: the finest rate any of them needs wins.
    double longest = 0, motion = 0, spread = 0, scale = 0;
    // Per camera, the previous knot's projections (scratch kept across calls: no allocation per side).
    std::vector<std::array<glm::dvec2, kTest>>& prev = sidePrev_;
    std::vector<std::array<bool, kTest>>& prevFront = sidePrevFront_;
    prev.assign(views_.size(), {}), prevFront.assign(views_.size(), std::array<bool, kTest>{});
    for (size_t k = 0; k < shapes_.size(); ++k) {
      glm::dvec3 c[kTest];
      glm::dvec3 first(0.0);  // collapsed: one point at every knot (it may move)
      for (int i = 0; i < kTest; ++i) {
        const bool end = k == 0 && (i == 0 || i == kTest - 1);  // the end points at the first knot are known
        c[i] = end ? ((i == 0) == fromFirst ? pf : pt) : camera(k, pointOnSegment(e.a, e.b, i, kTest - 1));
        if (i == 0) first = c[i];
        spread = std::max(spread, glm::length(c[i] - first));
        scale = std::max({scale, std::abs(c[i].x), std::abs(c[i].y), std::abs(c[i].z)});
      }
      for (size_t v = 0; v < views_.size(); ++v) {
        const SplitView& view = views_[v];
        glm::dvec2 r[kTest];
        bool front[kTest];
        for (int i = 0; i < kTest; ++i) {
          const glm::dvec3 cv = view.in(k, c[i]);
          front[i] = inFront(view, cv);
          r[i] = front[i] ? view.proj.project(cv) : glm::dvec2(0.0);
          if (front[i] && prevFront[v][size_t(i)]) motion = std::max(motion, glm::length(r[i] - prev[v][size_t(i)]));
          prev[v][size_t(i)] = r[i], prevFront[v][size_t(i)] = front[i];
        }
        for (int i = 0; i + 1 < kTest; ++i)
          if (front[i] && front[i + 1]) longest = std::max(longest, (kTest - 1) * glm::length(r[i + 1] - r[i]));
      }
    }
    if (spread <= 1e-12 * std::max(1.0, scale)) {
      e.collapsed = true, e.n = 1, e.lo = 0, e.hi = 1, e.need = 0;
    } else {
      // Measured where it lies in front of the eye (the piece's own eye splits deal with the
      // rest); a side that cannot be measured at all takes a whole grid.
      e.need = longest / edgeLength(motion);
      if (!std::isfinite(e.need)) e.need = o_.maxGridSize;
      // A disc needs a few steps around to have an area at all (it has no neighbours to agree with).
      const int least = p_.kind == PrimKind::Point && std::abs(to.u - from.u) > std::abs(to.v - from.v) ? std::min(8, o_.maxGridSize) : 1;
      if (e.need <= o_.maxGridSize) e.n = std::max(least, int(std::ceil(e.need))), e.lo = 0, e.hi = e.n;
    }
    return {e, fromFirst};
  }

  // Cuts a piece's side in two, in the piece's running order; `m` is where. A final side is cut
  // at one of its own points: the middle one, or for a single step one of its ends (the piece
  // on that side of the cut gets a side of no length, and is a triangle in (u, v)).
  void cut(const Side& s, Side& first, Side& second, UV& m) const {
    const Edge& e = s.e;
    if (e.n && !e.collapsed) {
      const int mid = (e.lo + e.hi) / 2;
      Edge lo = e, hi = e;
      lo.hi = mid, hi.lo = mid;
      m = pointOnSegment(e.a, e.b, mid, e.n);
      first = {s.forward ? lo : hi, s.forward}, second = {s.forward ? hi : lo, s.forward};
      return;
    }
    const UV from = s.from(), to = s.to();
    m = {0.5 * (from.u + to.u), 0.5 * (from.v + to.v)};
    first = side(from, m), second = side(m, to);
  }

  // Splits across u (cutting bottom and top) or across v (cutting right and left).
  void splitPiece(const Piece& pc, bool acrossU, int depth, int eyeDepth) {
    Piece a, b;
    UV m0, m1;
    Side f0, s0, f1, s1;
    if (acrossU) {
      cut(pc.s[0], f0, s0, m0);  // bottom: c0 → m0 → c1
      cut(pc.s[2], f1, s1, m1);  // top:    c2 → m1 → c3
      const Side mid = side(m0, m1);
      Side back = mid;
      back.forward = !mid.forward;
      a.s = {f0, mid, s1, pc.s[3]};   // c0 m0 m1 c3
      b.s = {s0, pc.s[1], f1, back};  // m0 c1 c2 m1
    } else {
      cut(pc.s[1], f0, s0, m0);  // right: c1 → m0 → c2
      cut(pc.s[3], f1, s1, m1);  // left:  c3 → m1 → c0
      const Side mid = side(m1, m0);
      Side back = mid;
      back.forward = !mid.forward;
      a.s = {pc.s[0], f0, back, s1};  // c0 c1 m0 m1
      b.s = {mid, s0, pc.s[2], f1};   // m1 m0 c2 c3
    }
    split(a, depth + 1, eyeDepth);
    split(b, depth + 1, eyeDepth);
  }

  /// The piece as every camera sees it: culled only where every camera culls it (behind its eye,
  /// beyond its far plane or outside its window), sized for the camera that needs the most
  /// micropolygons; `primary` holds the primary camera's own verdict and sizes (for the detail
  /// expansion statistic).
  Estimate estimate(const Piece& pc, Estimate* primary = nullptr) const {
    const size_t K = shapes_.size();
    UV uv[kTest][kTest];
    for (int j = 0; j < kTest; ++j)
      for (int i = 0; i < kTest; ++i) uv[j][i] = bilinearUV(pc, double(i) / (kTest - 1), double(j) / (kTest - 1));
    // The test points in the primary's space, once for every camera (scratch kept across calls).
    std::vector<TestPoints>& c = estimatePoints_;
    c.resize(K);
    for (size_t k = 0; k < K; ++k)
      for (int j = 0; j < kTest; ++j)
        for (int i = 0; i < kTest; ++i) c[k][size_t(j)][size_t(i)] = camera(k, uv[j][i]);
    Estimate all;
    all.allBehind = true, all.beyondFar = true, all.offscreen = true;
    for (size_t v = 0; v < views_.size(); ++v) {
      const Estimate e = estimateIn(views_[v], c);
      if (v == 0 && primary) *primary = e;
      all.allBehind = all.allBehind && e.allBehind, all.beyondFar = all.beyondFar && e.beyondFar;
      const bool culled = e.allBehind || e.beyondFar || e.offscreen;
      all.offscreen = all.offscreen && culled;
      if (culled) continue;
      all.straddle = all.straddle || e.straddle;
      all.lu = std::max(all.lu, e.lu), all.lv = std::max(all.lv, e.lv), all.motion = std::max(all.motion, e.motion);
      all.cu = std::max(all.cu, e.cu), all.cv = std::max(all.cv, e.cv);
    }
    return all;
  }

  Estimate estimateIn(const SplitView& view, const std::vector<TestPoints>& cp) const {
    Estimate e;
    const size_t K = shapes_.size();
    glm::dvec2 r[kTest][kTest], prev[kTest][kTest];
    bool fr[kTest][kTest], prevFront[kTest][kTest];
    double bb[4] = {1e300, -1e300, 1e300, -1e300};
    double zLo = 1e300, zHi = -1e300;  // camera depths of the points in front
    for (size_t k = 0; k < K; ++k) {
      glm::dvec3 c[kTest][kTest];
      int nFront = 0;
      for (int j = 0; j < kTest; ++j)
        for (int i = 0; i < kTest; ++i) {
          c[j][i] = view.in(k, cp[k][size_t(j)][size_t(i)]);
          fr[j][i] = inFront(view, c[j][i]);
          if (c[j][i].z <= view.cam->farClip) e.beyondFar = false;
          r[j][i] = glm::dvec2(0.0);
          if (fr[j][i]) {
            ++nFront;
            r[j][i] = view.proj.project(c[j][i]);
            zLo = std::min(zLo, c[j][i].z), zHi = std::max(zHi, c[j][i].z);
            bb[0] = std::min(bb[0], r[j][i].x), bb[1] = std::max(bb[1], r[j][i].x);
            bb[2] = std::min(bb[2], r[j][i].y), bb[3] = std::max(bb[3], r[j][i].y);
          }
        }
      if (nFront) e.allBehind = false;
      if (nFront && nFront < kTest * kTest) e.straddle = true;
      // The longest test segment times the segment count: dicing steps are uniform in the
      // parameter, so the fastest-moving stretch (near a silhouette fold, say) sets the step.
      for (int j = 0; j < kTest; ++j) {
        double lu = 0, lv = 0, cu = 0, cv = 0;
        for (int i = 0; i + 1 < kTest; ++i) {
          if (fr[j][i] && fr[j][i + 1]) lu = std::max(lu, (kTest - 1) * glm::length(r[j][i + 1] - r[j][i]));
          if (fr[i][j] && fr[i + 1][j]) lv = std::max(lv, (kTest - 1) * glm::length(r[i + 1][j] - r[i][j]));
          cu += glm::length(c[j][i + 1] - c[j][i]);
          cv += glm::length(c[i + 1][j] - c[i][j]);
        }
        e.lu = std::max(e.lu, lu), e.lv = std::max(e.lv, lv);
        e.cu = std::max(e.cu, cu), e.cv = std::max(e.cv, cv);
      }
      if (k > 0)
        for (int j = 0; j < kTest; ++j)
          for (int i = 0; i < kTest; ++i)
            if (fr[j][i] && prevFront[j][i]) e.motion = std::max(e.motion, glm::length(r[j][i] - prev[j][i]));
      for (int j = 0; j < kTest; ++j)
        for (int i = 0; i < kTest; ++i) prev[j][i] = r[j][i], prevFront[j][i] = fr[j][i];
    }
    if (!e.allBehind) {
      // Curved pieces bulge between test points: pad the bound by a tenth of its size.
      double px = 0.1 * (bb[1] - bb[0]) + 1, py = 0.1 * (bb[3] - bb[2]) + 1;
      // A lens sees past the pinhole's frame by each depth's circle of confusion: what it may
      // blur into view is kept (its depths padded like its bound).
      if (const double coc = store::circleOfConfusion(*view.cam, zLo - 0.1 * (zHi - zLo), zHi + 0.1 * (zHi - zLo)); coc > 0)
        px += coc * std::abs(view.proj.ax), py += coc * std::abs(view.proj.ay);
      e.offscreen = bb[1] + px < view.window[0] || bb[0] - px > view.window[1] || bb[3] + py < view.window[2] || bb[2] - py > view.window[3];
    }
    return e;
  }

  void split(const Piece& pc, int depth, int eyeDepth) {
    // Pieces visited count too: splitting that culls nearly everything it makes (slivers along
    // the screen's edge) works without emitting micropolygons.
    if (++visited_ > o_.maxMicropolygonsPerPrimitive / 4 && !overBudget_) overBudget_ = true, ++stats_.overBudget;
    Estimate primary;
    const Estimate e = estimate(pc, &primary);
    if (e.allBehind || e.beyondFar || e.offscreen) {
      ++stats_.culledPieces;
      return;
    }
    if (overBudget_) return emit(pc, o_.maxGridSize, o_.maxGridSize);
    if (e.straddle) {
      if (eyeDepth >= o_.maxEyeSplits || depth >= o_.maxSplitDepth) {
        ++stats_.culledPieces;
        return;
      }
      ++stats_.eyeSplits;
      splitPiece(pc, e.cu >= e.cv, depth, eyeDepth + 1);
      return;
    }
    const double edge = edgeLength(e.motion), G = o_.maxGridSize;
    // Steps across the interior; a piece too large or too fast to measure (infinite coordinates)
    // takes a whole grid.
    auto steps = [&](double length) {
      const double n = std::ceil(length / edge);
      return std::isfinite(n) ? n : G;
    };
    const double iu = steps(e.lu), iv = steps(e.lv);
    // A direction needs a cut when a side along it is not final, or when its interior needs more
    // than a grid and both sides can be cut at one of their points.
    auto needs = [&](const Side& s, const Side& t, double interior) {
      return !s.e.n || !t.e.n || (interior > G && s.e.cuttableAtAPoint() && t.e.cuttableAtAPoint());
    };
    auto stepsAlong = [&](const Side& s, const Side& t, double interior) {
      return std::max({interior, s.e.n ? s.e.steps() : s.e.need, t.e.n ? t.e.steps() : t.e.need});
    };
    const bool needU = needs(pc.s[0], pc.s[2], iu), needV = needs(pc.s[1], pc.s[3], iv);
    if ((needU || needV) && depth < o_.maxSplitDepth) {
      const bool acrossU = needU && (!needV || stepsAlong(pc.s[0], pc.s[2], iu) >= stepsAlong(pc.s[1], pc.s[3], iv));
      splitPiece(pc, acrossU, depth, eyeDepth);
      return;
    }
    emit(pc, iu, iv);
    if (views_.size() > 1 && !(primary.allBehind || primary.beyondFar || primary.offscreen)) {
      const double edge0 = edgeLength(primary.motion);
      auto steps0 = [&](double length) { return std::clamp(std::isfinite(std::ceil(length / edge0)) ? std::ceil(length / edge0) : G, 1.0, G); };
      stats_.primaryMicropolygons += uint64_t(steps0(primary.lu) * steps0(primary.lv));
    }
  }

  // The piece as a leaf whose interior needs iu × iv steps (its sides may need more).
  void emit(const Piece& pc, double iu, double iv) {
    const double G = o_.maxGridSize;
    Leaf leaf;
    for (size_t i = 0; i < 4; ++i) {
      const Side& s = pc.s[i];
      LeafSide& l = leaf.sides[i];
      Edge e = s.e;
      if (!e.n) {  // the depth limit left it unfinished
        e.n = int(std::clamp(std::isfinite(e.need) ? std::ceil(e.need) : G, 1.0, G)), e.lo = 0, e.hi = e.n;
        ++stats_.forcedCuts;
      }
      l.a = e.a, l.b = e.b, l.n = e.n, l.collapsed = e.collapsed || e.lo == e.hi;
      l.k0 = s.forward ? e.lo : e.hi, l.k1 = s.forward ? e.hi : e.lo;
    }
    auto gridSteps = [&](int s, int t, double interior) {
      return int(std::clamp(std::max({interior, double(leaf.sides[size_t(s)].steps()), double(leaf.sides[size_t(t)].steps())}), 1.0, G));
    };
    leaf.nu = gridSteps(0, 2, iu), leaf.nv = gridSteps(1, 3, iv);
    out_.push_back(leaf);
    ++stats_.leaves;
    micropolygons_ += uint64_t(leaf.nu) * uint64_t(leaf.nv);
    stats_.micropolygons += uint64_t(leaf.nu) * uint64_t(leaf.nv);
    if (!overBudget_ && micropolygons_ > o_.maxMicropolygonsPerPrimitive) overBudget_ = true, ++stats_.overBudget;
  }

  const Primitive& p_;
  const DiceOptions& o_;
  std::vector<Leaf>& out_;
  DiceStats& stats_;
  std::vector<Shape> shapes_;
  std::vector<glm::dmat4> mats_;
  std::vector<double> times_;  // of shapes_ and mats_ (empty: one, the piece stands still)
  double rate_ = 1, motionFactor_ = 0;
  std::vector<SplitView> views_;  // [0] the primary camera
  mutable std::vector<TestPoints> estimatePoints_;  // estimate()'s per knot
  mutable std::vector<std::array<glm::dvec2, kTest>> sidePrev_;
  mutable std::vector<std::array<bool, kTest>> sidePrevFront_;
  uint64_t micropolygons_ = 0;  // in the leaves so far
  uint64_t visited_ = 0;        // pieces estimated so far
  bool overBudget_ = false;
};

}  // namespace

void splitPrimitive(const Primitive& p, const std::vector<double>& knots, const store::Camera& camera, const std::vector<store::Camera>& others,
                    const DiceOptions& options, std::vector<Leaf>& out, DiceStats& stats) {
  Splitter(p, knots, camera, others, options, out, stats).run();
}

}  // namespace reshutter::shade
