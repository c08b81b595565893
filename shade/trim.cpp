// Trim curves: flattening RenderMan's TrimCurve loops and the odd winding rule.
#include "shade/trim.h"

#include <algorithm>
#include <cmath>

#include <glm/vec4.hpp>

#include "common/error.h"
#include "shade/dice.h"

namespace reshutter::shade {

TrimLoops::TrimLoops(const std::vector<int>& ncurves, const std::vector<int>& order, const std::vector<double>& knot, const std::vector<double>& min,
                     const std::vector<double>& max, const std::vector<int>& n, const std::vector<double>& u, const std::vector<double>& v,
                     const std::vector<double>& w, int segmentsPerSpan) {
  size_t curves = 0;
  for (int c : ncurves) {
    if (c < 1) throw Error("TrimCurve", cat("a loop has ", c, " curves"));
    curves += size_t(c);
  }
  if (order.size() != curves || min.size() != curves || max.size() != curves || n.size() != curves)
    throw Error("TrimCurve", cat("", curves, " curves need as many orders, mins, maxes and point counts (", order.size(), ", ", min.size(), ", ", max.size(),
                                 ", ", n.size(), " given)"));
  size_t knots = 0, points = 0;
  for (size_t c = 0; c < curves; ++c) {
    if (order[c] < 1 || order[c] > 32) throw Error("TrimCurve", cat("curve ", c, " has order ", order[c], " (1 to 32)"));
    if (n[c] < order[c]) throw Error("TrimCurve", cat("curve ", c, " has order ", order[c], " above its ", n[c], " control points"));
    knots += size_t(n[c] + order[c]), points += size_t(n[c]);
  }
  if (knot.size() != knots) throw Error("TrimCurve", cat("the curves need ", knots, " knots, ", knot.size(), " given"));
  if (u.size() != points || v.size() != points || w.size() != points)
    throw Error("TrimCurve", cat("the curves need ", points, " control points, u v w have ", u.size(), " ", v.size(), " ", w.size()));

  size_t c = 0, k0 = 0, p0 = 0;
  for (int loopCurves : ncurves) {
    std::vector<glm::dvec2> loop;
    for (int i = 0; i < loopCurves; ++i, ++c) {
      const int k = order[c], np = n[c];
      const double* t = knot.data() + k0;
      for (int j = 0; j < np + k; ++j) {
        if (!std::isfinite(t[j])) throw Error("TrimCurve", cat("curve ", c, " knot ", j, " is not finite"));
        if (j && t[j] < t[j - 1]) throw Error("TrimCurve", cat("curve ", c, " knots decrease at knot ", j));
      }
      for (int j = 0; j < np; ++j) {
        const size_t q = p0 + size_t(j);
        if (!std::isfinite(u[q]) || !std::isfinite(v[q]) || !(w[q] > 0) || !std::isfinite(w[q]))
          throw Error("TrimCurve", cat("curve ", c, " control point ", j, " is not finite or has a weight that is not positive"));
      }
      const double lo = min[c], hi = max[c];
      if (!(lo < hi) || lo < t[k - 1] || hi > t[np])
        throw Error("TrimCurve", cat("curve ", c, " range [", lo, ", ", hi, "] is not inside [", t[k - 1], ", ", t[np], "]"));
      // Each knot span inside [lo, hi], flattened evenly; the curve's points in homogeneous
      // (u w, v w, w) combined by the span's basis functions.
      for (int span = k - 1; span < np; ++span) {
        const double a = std::max(t[span], lo), b = std::min(t[span + 1], hi);
        if (!(a < b)) continue;
        for (int s = loop.empty() ? 0 : 1; s <= segmentsPerSpan; ++s) {
          const double x = s == segmentsPerSpan ? b : a + (b - a) * s / segmentsPerSpan;
          double N[32];
          nurbsBasis(t + span - (k - 1), k, x, N);
          glm::dvec3 h(0.0);
          for (int j = 0; j < k; ++j) {
            const size_t q = p0 + size_t(span - (k - 1) + j);
            h += N[j] * glm::dvec3(u[q] * w[q], v[q] * w[q], w[q]);
          }
          loop.emplace_back(h.x / h.z, h.y / h.z);
        }
      }
      k0 += size_t(np + k), p0 += size_t(np);
    }
    if (loop.size() < 2) continue;
    if (loop.back() != loop.front()) loop.push_back(loop.front());  // loops are closed; a small gap closes here
    glm::dvec4 box(loop[0], loop[0]);
    for (const auto& p : loop) box = glm::dvec4(std::min(box.x, p.x), std::min(box.y, p.y), std::max(box.z, p.x), std::max(box.w, p.y));
    loops_.push_back(std::move(loop));
    bounds_.push_back(box);
  }
}

bool TrimLoops::encloses(double u, double v) const {
  bool inside = false;
  for (size_t l = 0; l < loops_.size(); ++l) {
    const glm::dvec4& b = bounds_[l];
    if (v < b.y || v >= b.w || u < b.x) continue;  // the ray towards +u cannot cross this loop
    const auto& p = loops_[l];
    for (size_t i = 0; i + 1 < p.size(); ++i) {
      const glm::dvec2 a = p[i], c = p[i + 1];
      if ((a.y > v) != (c.y > v) && u < a.x + (v - a.y) * (c.x - a.x) / (c.y - a.y)) inside = !inside;
    }
  }
  return inside;
}

bool TrimLoops::crosses(double u0, double u1, double v0, double v1) const {
  for (size_t l = 0; l < loops_.size(); ++l) {
    const glm::dvec4& b = bounds_[l];
    if (b.z < u0 || b.x > u1 || b.w < v0 || b.y > v1) continue;
    const auto& p = loops_[l];
    for (size_t i = 0; i + 1 < p.size(); ++i) {
      const glm::dvec2 a = p[i], c = p[i + 1];
      if (std::max(a.x, c.x) >= u0 && std::min(a.x, c.x) <= u1 && std::max(a.y, c.y) >= v0 && std::min(a.y, c.y) <= v1) return true;
    }
  }
  return false;
}

}  // namespace reshutter::shade
