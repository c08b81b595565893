// Shading in time (shade/shade_grid.h): which grids may shade differently over the shutter,
// decided from what the scene says changes, and shading them at the other times.
#include <algorithm>
#include <cmath>

#include <glm/gtc/matrix_inverse.hpp>
#include <glm/matrix.hpp>

#include "shade/shade_grid.h"

namespace reshutter::shade::pass {

namespace {

/// Whether every vertex moves by the same offset (a rigid translation in camera space).
bool translatesRigidly(std::span<const glm::vec3> P, size_t nV, size_t K) {
  float scale = 0;
  for (const glm::vec3& p : P) scale = std::max({scale, std::abs(p.x), std::abs(p.y), std::abs(p.z)});
  const float eps = 1e-5f * scale;
  for (size_t k = 1; k < K; ++k) {
    const glm::vec3 d = P[k * nV] - P[0];
    for (size_t v = 1; v < nV; ++v) {
      const glm::vec3 e = P[k * nV + v] - P[v] - d;
      if (std::abs(e.x) > eps || std::abs(e.y) > eps || std::abs(e.z) > eps) return false;
    }
  }
  return true;
}

/// Grid `g`, diced at the shading time `shadeAt`, as diceLeaf() would dice it at time `t` when
/// its primitive moves rigidly: its shading geometry carried by M(t) · M(shadeAt)^-1, the same up
/// to rounding without evaluating the surface again. False when the primitive's shape changes
/// over time (deformation keys, a camera-facing kind), a transform is nearly singular, or the
/// motion turns it inside out (the dicing's winding changes, so the grid is diced again and
/// found to differ). `keepsLengths`: whether the carry keeps every length to 0.1 % (the blend of
/// two knots' rotations shrinks what it turns).
bool carryRigidly(const Primitive& p, const DicedGrid& g, double shadeAt, double t, DicedGrid& out, bool& keepsLengths) {
  if (p.times.size() > 1 || p.kind == PrimKind::Curve || p.kind == PrimKind::Point) return false;
  const glm::dmat4 from = p.xform->at(shadeAt), to = p.xform->at(t);
  if (!wellInvertible(from) || !wellInvertible(to) || (glm::determinant(from) < 0) != (glm::determinant(to) < 0)) return false;
  const glm::dmat4 R = to * glm::inverse(from);
  const glm::dmat3 normals = glm::inverseTranspose(glm::dmat3(R));
  const glm::dmat3 gram = glm::transpose(glm::dmat3(R)) * glm::dmat3(R);  // the identity for a rotation
  keepsLengths = true;
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) keepsLengths &= std::abs(gram[i][j] - (i == j ? 1.0 : 0.0)) <= 1e-3;
  const size_t nV = g.numVertices;
  out.nu = g.nu, out.nv = g.nv, out.numVertices = g.numVertices;
  out.positions.clear(), out.corners.clear();
  out.P.resize(nV), out.N.resize(nV), out.Ng.resize(nV);
  auto carryNormal = [&](const glm::dvec3& n) {
    const glm::dvec3 m = normals * n;
    const double len = glm::length(m);
    return len > 0 ? m / len : n;
  };
  for (size_t i = 0; i < nV; ++i) {
    out.P[i] = glm::dvec3(R * glm::dvec4(g.P[i], 1.0));
    out.N[i] = carryNormal(g.N[i]), out.Ng[i] = carryNormal(g.Ng[i]);
  }
  out.u = g.u, out.v = g.v, out.s = g.s, out.t = g.t;
  return true;
}

/// A later shading time on a coarser lattice (ShadeOptions::timeStride): which vertices stand
/// at every stride-th lattice point, and, per lattice index, the coarse span that holds it.
class CoarseLattice {
 public:
  /// False when the grid has no lattice, or one too small to thin.
  bool set(const DicedGrid& g, int stride) {
    if (stride < 2 || g.lattice.size() != size_t(g.nu + 1) * size_t(g.nv + 1) || (g.nu <= 1 && g.nv <= 1)) return false;
    g_ = &g, stride_ = stride, row_ = g.nu + 1;
    spans(g.nu, cu_, su_), spans(g.nv, cv_, sv_);
    std::vector<uint8_t> reached(g.numVertices, 0), taken(g.numVertices, 0);
    for (uint32_t v : g.lattice) {
      if (v >= g.numVertices) return false;
      reached[v] = 1;
    }
    coarse_.clear();
    auto take = [&](uint32_t v) {
      if (!taken[v]) taken[v] = 1, coarse_.push_back(v);
    };
    for (int j : cv_)
      for (int i : cu_) take(at(i, j));
    for (uint32_t v = 0; v < g.numVertices; ++v)  // none expected: every vertex stands on the lattice
      if (!reached[v]) take(v);
    return true;
  }

  /// Shades time k's vertices into `values` (parallel to the schema; `first`: time 0's): the
  /// coarse lattice, then every cell where the change since `first` is not smooth, then the
  /// rest by the change interpolated from their cell's corners. `shade(list)` shades vertices.
  template <class Shade>
  void shadeTime(const ShadeContext& c, const std::vector<std::vector<float>>& first, std::vector<std::vector<float>>& values, Shade&& shade,
                 InTimeCounts& counts) {
    const DicedGrid& g = *g_;
    shaded_.assign(g.numVertices, 0);
    shade(std::span<const uint32_t>(coarse_));
    for (uint32_t v : coarse_) shaded_[v] = 1;
    // Nothing changed at the coarse points (a still grid no moving shadow reached at this time,
    // most often): every change to interpolate is zero, so the rest take the first time's values
    // as the blend below would make them (+ 0: a negative zero comes out positive there too).
    const bool steady = eachCarried(c, first, values, [&](size_t slot, size_t N) {
      for (uint32_t v : coarse_)
        for (size_t n = 0; n < N; ++n)
          if (values[slot][v * N + n] != first[slot][v * N + n]) return false;
      return true;
    });
    if (steady) {
      eachCarried(c, first, values, [&](size_t slot, size_t N) {
        for (uint32_t v = 0; v < g.numVertices; ++v)
          if (!shaded_[v])
            for (size_t n = 0; n < N; ++n) values[slot][v * N + n] = first[slot][v * N + n] + 0.f;
        return true;
      });
      counts.laterVertices += coarse_.size();
      counts.interpolatedVertices += g.numVertices - coarse_.size();
      ++counts.steadyShadings;
      return;
    }
    // The change of colour and opacity since the first time at each coarse point, components
    // 0-2 Ci, 3-5 Oi.
    const size_t A = cu_.size(), B = cv_.size();
    const int slots[2] = {c.ci, c.oi};
    delta_.resize(A * B * 6);
    for (size_t b = 0; b < B; ++b)
      for (size_t a = 0; a < A; ++a)
        for (int n = 0; n < 6; ++n) {
          const size_t slot = size_t(slots[n / 3]), e = size_t(at(cu_[a], cv_[b])) * 3 + size_t(n % 3);
          delta_[(b * A + a) * 6 + size_t(n)] = values[slot][e] - first[slot][e];
        }
    auto D = [&](size_t a, size_t b) { return &delta_[(b * A + a) * 6]; };
    // How far from linear the change bends at each coarse point, along u and along v: its second
    // difference there (as on an even lattice of the stride), per component. Along a side with
    // two coarse points only (a lone span), the difference across it, at both ends.
    const double H2 = double(stride_) * stride_;
    auto curvature = [&](const float* d0, const float* d, const float* d1, double h0, double h1, float* out) {
      const double scale = 2 * H2 / (h0 + h1);
      for (int n = 0; n < 6; ++n) out[n] = float(std::abs(((d1[n] - d[n]) / h1 - (d[n] - d0[n]) / h0) * scale));
    };
    auto step = [&](const float* d0, const float* d1, float* out0, float* out1) {
      for (int n = 0; n < 6; ++n) out0[n] = out1[n] = std::abs(d1[n] - d0[n]);
    };
    bendU_.assign(A * B * 6, 0.f), bendV_.assign(A * B * 6, 0.f);
    auto U = [&](size_t a, size_t b) { return &bendU_[(b * A + a) * 6]; };
    auto V = [&](size_t a, size_t b) { return &bendV_[(b * A + a) * 6]; };
    for (size_t b = 0; b < B; ++b) {
      if (A == 2) step(D(0, b), D(1, b), U(0, b), U(1, b));
      for (size_t a = 1; a + 1 < A; ++a) curvature(D(a - 1, b), D(a, b), D(a + 1, b), cu_[a] - cu_[a - 1], cu_[a + 1] - cu_[a], U(a, b));
    }
    for (size_t a = 0; a < A; ++a) {
      if (B == 2) step(D(a, 0), D(a, 1), V(a, 0), V(a, 1));
      for (size_t b = 1; b + 1 < B; ++b) curvature(D(a, b - 1), D(a, b), D(a, b + 1), cv_[b] - cv_[b - 1], cv_[b + 1] - cv_[b], V(a, b));
    }
    // A span between two coarse points is shaded in full when the change bends by more than twice
    // the tolerance at either of its ends (at its one interior end, at the lattice's first and
    // last span). A step of J inside a span bends by J at both its ends and is missed by up to
    // J / 2 in between; a smooth change is missed by about an eighth of its bend. Either end, not
    // both: an edge found in one span is shaded in its neighbours too, where a curved edge may
    // cross without reaching a coarse point.
    const float threshold = float(2 * c.tolerance);
    auto bends = [&](const float* lo, const float* hi) {
      for (int n = 0; n < 6; ++n)
        if (std::max(lo[n], hi[n]) > threshold) return true;
      return false;
    };
    auto spanU = [&](size_t a, size_t b) {
      const size_t lo = A == 2 ? 0 : std::max<size_t>(a, 1), hi = A == 2 ? 1 : std::min<size_t>(a + 1, A - 2);
      return bends(U(lo, b), U(hi, b));
    };
    auto spanV = [&](size_t a, size_t b) {
      const size_t lo = B == 2 ? 0 : std::max<size_t>(b, 1), hi = B == 2 ? 1 : std::min<size_t>(b + 1, B - 2);
      return bends(V(a, lo), V(a, hi));
    };
    refine_.clear();
    for (size_t b = 0; b + 1 < B; ++b)
      for (size_t a = 0; a + 1 < A; ++a) {
        if (!(spanU(a, b) || spanU(a, b + 1) || spanV(a, b) || spanV(a + 1, b))) continue;
        for (int j = cv_[b]; j <= cv_[b + 1]; ++j)
          for (int i = cu_[a]; i <= cu_[a + 1]; ++i)
            if (const uint32_t v = at(i, j); !shaded_[v]) shaded_[v] = 1, refine_.push_back(v);
      }
    if (!refine_.empty()) shade(std::span<const uint32_t>(refine_));
    counts.laterVertices += coarse_.size() + refine_.size();
    // The rest: the change bilinear between the corners of the cell that holds it.
    blends_.clear();
    for (int j = 0; j <= g.nv; ++j)
      for (int i = 0; i <= g.nu; ++i) {
        const uint32_t v = at(i, j);
        if (shaded_[v]) continue;
        shaded_[v] = 1;
        const int a = su_[size_t(i)], b = sv_[size_t(j)];
        const int i0 = cu_[size_t(a)], i1 = cu_[size_t(a) + 1], j0 = cv_[size_t(b)], j1 = cv_[size_t(b) + 1];
        const float wu = float(i - i0) / float(i1 - i0), wv = float(j - j0) / float(j1 - j0);
        blends_.push_back({v, {at(i0, j0), at(i1, j0), at(i0, j1), at(i1, j1)}, {(1 - wu) * (1 - wv), wu * (1 - wv), (1 - wu) * wv, wu * wv}});
      }
    counts.interpolatedVertices += blends_.size();
    eachCarried(c, first, values, [&](size_t slot, size_t N) {
      if (N == 3)
        interpolate<3>(first[slot].data(), values[slot].data());
      else
        interpolate<1>(first[slot].data(), values[slot].data());
      return true;
    });
  }

 private:
  const DicedGrid* g_ = nullptr;
  int stride_ = 1, row_ = 0;
  std::vector<int> cu_, cv_;  // the coarse lattice indices along u and v: 0, stride, 2 stride, ..., n
  std::vector<int> su_, sv_;  // per lattice index: the coarse span [c[s], c[s + 1]] that holds it
  std::vector<uint32_t> coarse_, refine_;
  std::vector<uint8_t> shaded_;
  struct Blend {  // an interpolated vertex: its cell's corners and their weights
    uint32_t v, q[4];
    float w[4];
  };
  std::vector<Blend> blends_;
  std::vector<float> delta_, bendU_, bendV_;  // per coarse point (b * A + a) and component: the change of Ci and Oi, its bends

  uint32_t at(int i, int j) const { return g_->lattice[size_t(j) * size_t(row_) + size_t(i)]; }
  /// Calls f(slot, components) for each attribute carried in time that the grid has (a
  /// view-dependent input is absent on grids whose shader has no such term), until f says false;
  /// whether none did.
  template <class F>
  static bool eachCarried(const ShadeContext& c, const std::vector<std::vector<float>>& first, const std::vector<std::vector<float>>& values, F&& f) {
    for (const std::vector<int>& timed : c.timedSlots) {
      const size_t slot = size_t(timed[0]);
      if (first[slot].empty() || values[slot].size() != first[slot].size()) continue;
      if (!f(slot, size_t(store::componentCount(c.schema.attrs[slot].type)))) return false;
    }
    return true;
  }
  /// Each blended vertex's value of an attribute of N components: its first-time value plus the
  /// change at its cell's corners, weighted (the corners are shaded, never blended).
  template <size_t N>
  void interpolate(const float* first, float* out) const {
    for (const Blend& e : blends_) {
      float d[N] = {};
      for (int m = 0; m < 4; ++m) {
        const float* now = out + size_t(e.q[m]) * N;
        const float* then = first + size_t(e.q[m]) * N;
        for (size_t n = 0; n < N; ++n) d[n] += e.w[m] * (now[n] - then[n]);
      }
      for (size_t n = 0; n < N; ++n) out[size_t(e.v) * N + n] = first[size_t(e.v) * N + n] + d[n];
    }
  }
  void spans(int n, std::vector<int>& c, std::vector<int>& s) const {
    c.clear();
    for (int i = 0; i < n; i += stride_) c.push_back(i);
    c.push_back(n);
    s.assign(size_t(n) + 1, 0);
    for (size_t a = 0; a + 1 < c.size(); ++a)
      for (int i = c[a]; i <= c[a + 1]; ++i) s[size_t(i)] = int(a);
  }
};

}  // namespace

bool wellInvertible(const glm::dmat4& m) {
  const double det = glm::determinant(glm::dmat3(m));
  const double longest = std::max({glm::length(glm::dvec3(m[0])), glm::length(glm::dvec3(m[1])), glm::length(glm::dvec3(m[2]))});
  return std::isfinite(det) && std::isfinite(longest) && std::abs(det) > 1e-9 * longest * longest * longest;
}

bool animated(const Attributes& a) { return a.color.values.size() > 1 || a.opacity.values.size() > 1 || a.surface.values.size() > 1; }

bool lightMoves(const Light& l, double open, double close) { return l.xform.moving() && l.xform.at(open) != l.xform.at(close); }

/// Whether grid `g` of primitive `pi` (lights: the indices into the frame's lights that light
/// it) can shade differently at another time of the interval - decided from what the scene says
/// moves or changes, conservatively: shading at the other times then confirms it. A grid that
/// stands still under fixed lights, an unlit constant one, and a matte one translating rigidly
/// under fixed distant lights that cast no shadows cannot. `movingShadows`, per light: whether
/// a moving caster may shadow the grid from it over the interval (a moving light: may) - all
/// false when the grid cannot shade differently.
bool mayShadeDifferently(const ShadeContext& c, uint32_t pi, std::span<const glm::vec3> positions, uint32_t nV, bool moves, std::span<const uint32_t> lights,
                         std::vector<uint8_t>& movingShadows) {
  movingShadows.assign(lights.size(), 0);
  const Attributes& a = *c.scene.prims[pi].attrs;
  const SurfaceShader& sh = a.surface.values[0];
  bool shadowed = false, local = false, lightMoves = false, castersMay = false;
  if (usesLights(sh.kind)) {
    ShadowBox recv;  // over every knot's positions, when a light may need it
    for (size_t j = 0; j < lights.size(); ++j) {
      const uint32_t li = lights[j];
      if (li >= c.lit.size()) continue;
      const bool casts = c.shadows && c.lit[li].shadows;
      lightMoves |= c.lightMoves[li], shadowed |= casts;
      local |= c.lit[li].kind != LightKind::Distant && c.lit[li].kind != LightKind::Ambient;
      if (!casts || (!c.lightMoves[li] && c.movingCasters.empty())) continue;
      if (!c.lightMoves[li] && !(recv.lo.x <= recv.hi.x))
        for (const glm::vec3& q : positions) recv.add(q);
      movingShadows[j] = c.lightMoves[li] || c.movingCasters.mayShadow(li, recv);  // a moving caster's shadow may move over it
      castersMay |= movingShadows[j] != 0;
    }
  }
  if (animated(a) || lightMoves || castersMay) return true;
  if (sh.kind == SurfaceKind::Constant || !moves) return false;
  if (sh.kind != SurfaceKind::Matte) return true;  // view-dependent terms (or defaultsurface's headlight)
  return shadowed || local || !translatesRigidly(positions, nV, c.split.knots[pi].size());
}

/// Whether grid-level shading can change only through moving casters' shadows: the grid stands
/// still, nothing of its primitive is animated and none of its lights moves (ShadowReuse).
bool onlyShadowsChange(const ShadeContext& c, uint32_t pi, bool moves, std::span<const uint32_t> lights) {
  if (moves || animated(*c.scene.prims[pi].attrs)) return false;
  return std::none_of(lights.begin(), lights.end(), [&](uint32_t li) { return li < c.lightMoves.size() && c.lightMoves[li]; });
}

/// Shading in time for one grid already shaded at the first time into `out` (`moves`: its
/// positions differ between knots; `reuse`: the first time's shadow rays, for a grid that only
/// shadows change): shades it at the other times and keeps them ("Ci@k", "Oi@k", and "name@k"
/// for the output variables carried in time) when the colour or opacity changes by more than the
/// tolerance. Returns whether it kept them.
///
/// The times are refined by bisection: the close first, then the middle of each span whose
/// ends are shaded; where the middle's colour lies within the tolerance of the blend of its
/// ends, the span's other times are blended too rather than shaded (linear between the shaded
/// times, as the re-sampler blends them). Tolerance 0 shades every time.
bool shadeInTime(const ShadeContext& c, uint32_t pi, const Leaf& leaf, const DicedGrid& g, bool moves, std::span<const uint32_t> lightIdx,
                 std::span<const uint8_t> movingShadows, std::span<const float> firstBias, uint64_t leafIndex, GridOut& out, RayCounts& rays, ShadowReuse* reuse,
                 InTimeCounts& counts) {
  const Primitive& p = c.scene.prims[pi];
  const size_t T = c.times.size();
  std::vector<std::vector<std::vector<float>>> at(T);
  DicedGrid gk;
  std::vector<LitLight> lights;
  std::vector<float> biasOfTime;
  float change = 0;
  if (reuse) reuse->recording = false, reuse->first = &out.attrs;
  const std::vector<int>& slots = c.changeSlots;
  CoarseLattice lattice;
  const bool coarse = c.tolerance > 0 && lattice.set(g, c.timeStride);
  auto values = [&](size_t k, int slot) -> std::vector<float>& { return k == 0 ? out.attrs[size_t(slot)] : at[k][size_t(slot)]; };
  // Shades time k into at[k]; false when the grid dices differently there (no blend).
  auto shadeTime = [&](size_t k) {
    // A grid that stands still has the same shading geometry at every time (only its lights,
    // shadows and shader can differ): no second dicing.
    const DicedGrid* geometry = &g;
    // The shadow rays' lifts: the first time's where the micropolygons keep their size (a still
    // grid, or one carried without shrinking), else made anew at this time.
    biasOfTime.assign(firstBias.begin(), firstBias.end());
    if (moves) {
      bool keepsLengths = false;
      if (carryRigidly(p, g, c.shadeAt, c.times[k], gk, keepsLengths)) {
        ++counts.carriedTimes;
        if (!keepsLengths) biasOfTime.clear();
      } else {
        biasOfTime.clear();
        diceLeaf(p, leaf, c.split.knots[pi], c.times[k], c.nearClip, c.perspective, gk);
        if (gk.numVertices != g.numVertices || gk.corners != out.corners) return false;
      }
      geometry = &gk;
    }
    lights.clear();
    for (uint32_t li : lightIdx)  // reusing: the lights stand still, and the first time's rays need the first time's lights
      if (li < c.lit.size()) lights.push_back(reuse ? c.lit[li] : c.litAt[k][li]);
    if (coarse) {
      auto shade = [&](std::span<const uint32_t> only) {
        shadeVertices(c, p, *geometry, out.corners, lights, c.times[k], k, leafIndex, at[k], rays, reuse, movingShadows, only, biasOfTime);
      };
      lattice.shadeTime(c, out.attrs, at[k], shade, counts);
    } else {
      shadeVertices(c, p, *geometry, out.corners, lights, c.times[k], k, leafIndex, at[k], rays, reuse, movingShadows, {}, biasOfTime);
      counts.laterVertices += g.numVertices;
    }
    for (int slot : slots) {
      const std::vector<float>& a = values(0, slot);
      const std::vector<float>& b = values(k, slot);
      for (size_t i = 0; i < a.size(); ++i) change = std::max(change, std::abs(b[i] - a[i]));
    }
    return true;
  };
  // Times lo < k < hi blended between lo and hi (every attribute carried in time).
  auto blend = [&](size_t lo, size_t hi) {
    for (size_t k = lo + 1; k < hi; ++k) {
      const float w = float((c.times[k] - c.times[lo]) / (c.times[hi] - c.times[lo]));
      at[k].resize(out.attrs.size());
      for (const std::vector<int>& timed : c.timedSlots) {
        const int slot = timed[0];
        const std::vector<float>& a = values(lo, slot);
        const std::vector<float>& b = values(hi, slot);
        std::vector<float>& v = at[k][size_t(slot)];
        v.resize(a.size());
        for (size_t i = 0; i < a.size(); ++i) v[i] = a[i] + w * (b[i] - a[i]);
      }
      ++counts.blendedTimes;
    }
  };
  // Refines span [lo, hi] (both shaded); false as shadeTime().
  auto refine = [&](auto&& self, size_t lo, size_t hi) -> bool {
    if (hi - lo < 2) return true;
    const size_t mid = (lo + hi) / 2;
    if (!shadeTime(mid)) return false;
    if (c.tolerance > 0) {
      const float w = float((c.times[mid] - c.times[lo]) / (c.times[hi] - c.times[lo]));
      float off = 0;
      for (int slot : slots) {
        const std::vector<float>& a = values(lo, slot);
        const std::vector<float>& b = values(hi, slot);
        const std::vector<float>& m = values(mid, slot);
        for (size_t i = 0; i < a.size(); ++i) off = std::max(off, std::abs(m[i] - (a[i] + w * (b[i] - a[i]))));
      }
      if (off <= c.tolerance) {
        blend(lo, mid), blend(mid, hi);
        return true;
      }
    }
    return self(self, lo, mid) && self(self, mid, hi);
  };
  if (!shadeTime(T - 1) || !refine(refine, 0, T - 1)) return false;
  if (!(change > c.tolerance) && c.tolerance > 0) return false;
  for (size_t k = 1; k < T; ++k)
    for (const std::vector<int>& timed : c.timedSlots) out.attrs[size_t(timed[k])] = std::move(at[k][size_t(timed[0])]);
  return true;
}

/// Whether anything in the scene can make shading differ over [open, close]: a light that moves
/// in camera space, an animated colour, opacity or shader, or a primitive that moves or deforms
/// under a shader that is not constant.
bool sceneMayShadeInTime(const FrameScene& scene, double open, double close) {
  for (const Light& l : scene.lights)
    if (lightMoves(l, open, close)) return true;
  const Attributes* seen = nullptr;
  for (const Primitive& p : scene.prims) {
    const Attributes& a = *p.attrs;
    if (&a != seen) {
      seen = &a;
      if (animated(a)) return true;
    }
    if (a.surface.values[0].kind != SurfaceKind::Constant && !p.knotTimes().empty() && clipKnots(p, open, close).size() > 1) return true;
  }
  return false;
}

}  // namespace reshutter::shade::pass
