// Ear clipping with hole bridges (triangulate.h).
#include "shade/triangulate.h"

#include <algorithm>
#include <cmath>

#include <glm/geometric.hpp>
#include <glm/vec2.hpp>

namespace reshutter::shade {

namespace {

using Vec2 = glm::dvec2;

double cross2(const Vec2& a, const Vec2& b, const Vec2& c) { return (b.x - a.x) * (c.y - a.y) - (b.y - a.y) * (c.x - a.x); }

double signedArea(const std::vector<Vec2>& q, const std::vector<int>& loop) {
  double a = 0;
  for (size_t i = 0; i < loop.size(); ++i) {
    const Vec2 &p = q[size_t(loop[i])], &r = q[size_t(loop[(i + 1) % loop.size()])];
    a += p.x * r.y - r.x * p.y;
  }
  return 0.5 * a;
}

bool inTriangle(const Vec2& a, const Vec2& b, const Vec2& c, const Vec2& p) {
  return cross2(a, b, p) >= 0 && cross2(b, c, p) >= 0 && cross2(c, a, p) >= 0;
}

// Splices `hole` (clockwise) into `outline` (counter-clockwise) through a vertex of the outline
// that its rightmost vertex sees; false when none is found.
bool bridge(const std::vector<Vec2>& q, std::vector<int>& outline, const std::vector<int>& hole) {
  size_t mi = 0;
  for (size_t i = 1; i < hole.size(); ++i)
    if (q[size_t(hole[i])].x > q[size_t(hole[mi])].x) mi = i;
  const Vec2 M = q[size_t(hole[mi])];
  // The nearest outline edge the ray from M towards +x crosses, and the point where it does.
  double bestX = INFINITY;
  size_t edge = SIZE_MAX;
  for (size_t i = 0; i < outline.size(); ++i) {
    const Vec2 &a = q[size_t(outline[i])], &b = q[size_t(outline[(i + 1) % outline.size()])];
    if ((a.y > M.y) == (b.y > M.y)) continue;
    const double x = a.x + (M.y - a.y) * (b.x - a.x) / (b.y - a.y);
    if (x >= M.x && x < bestX) bestX = x, edge = i;
  }
  if (edge == SIZE_MAX) return false;
  const size_t ia = edge, ib = (edge + 1) % outline.size();
  size_t pick = q[size_t(outline[ia])].x > q[size_t(outline[ib])].x ? ia : ib;
  const Vec2 I(bestX, M.y), P = q[size_t(outline[pick])];
  // A reflex outline vertex inside (M, I, P) would hide P: take the one nearest the ray instead.
  double bestAngle = INFINITY;
  for (size_t i = 0; i < outline.size(); ++i) {
    const Vec2 &prev = q[size_t(outline[(i + outline.size() - 1) % outline.size()])], &v = q[size_t(outline[i])],
               &next = q[size_t(outline[(i + 1) % outline.size()])];
    if (i == pick || cross2(prev, v, next) > 0) continue;  // convex vertices cannot hide P
    const bool inside = P.y >= M.y ? inTriangle(M, I, P, v) : inTriangle(M, P, I, v);
    if (!inside) continue;
    const double angle = std::atan2(std::abs(v.y - M.y), v.x - M.x);
    if (angle < bestAngle) bestAngle = angle, pick = i;
  }
  std::vector<int> joined(outline.begin(), outline.begin() + std::ptrdiff_t(pick) + 1);
  for (size_t k = 0; k <= hole.size(); ++k) joined.push_back(hole[(mi + k) % hole.size()]);
  joined.push_back(outline[pick]);
  joined.insert(joined.end(), outline.begin() + std::ptrdiff_t(pick) + 1, outline.end());
  outline = std::move(joined);
  return true;
}

}  // namespace

bool earClipLoop(const std::vector<Vec2>& q, const std::vector<int>& loop, std::vector<std::array<int, 3>>& triangles) {
  if (loop.size() < 3) return false;
  const double orient = signedArea(q, loop) >= 0 ? 1 : -1;
  const size_t first = triangles.size();
  std::vector<int> idx = loop;
  size_t guard = 0;
  while (idx.size() > 3) {
    bool clipped = false;
    for (size_t i = 0; i < idx.size() && !clipped; ++i) {
      const int a = idx[(i + idx.size() - 1) % idx.size()], b = idx[i], c = idx[(i + 1) % idx.size()];
      const Vec2 &A = q[size_t(a)], &B = q[size_t(b)], &C = q[size_t(c)];
      if (orient * cross2(A, B, C) <= 0) continue;  // reflex or degenerate corner
      bool blocked = false;
      for (int p : idx) {
        const Vec2& X = q[size_t(p)];
        if (p == a || p == b || p == c || X == A || X == B || X == C) continue;
        if (orient * cross2(A, B, X) >= 0 && orient * cross2(B, C, X) >= 0 && orient * cross2(C, A, X) >= 0) {
          blocked = true;
          break;
        }
      }
      if (blocked) continue;
      triangles.push_back({a, b, c});
      idx.erase(idx.begin() + std::ptrdiff_t(i));
      clipped = true;
    }
    if (!clipped || ++guard > loop.size()) {
      triangles.resize(first);
      return false;
    }
  }
  triangles.push_back({idx[0], idx[1], idx[2]});
  return true;
}

bool triangulateLoops(const std::vector<glm::dvec3>& P, const std::vector<std::vector<int>>& loops, std::vector<std::array<int, 3>>& triangles) {
  if (loops.empty() || loops[0].size() < 3) return false;
  for (const auto& l : loops)
    for (int i : l)
      if (i < 0 || size_t(i) >= P.size()) return false;
  // The outline's plane (Newell's normal) and two axes in it.
  glm::dvec3 n(0.0);
  const auto& outer = loops[0];
  for (size_t i = 0; i < outer.size(); ++i) {
    const glm::dvec3 &a = P[size_t(outer[i])], &b = P[size_t(outer[(i + 1) % outer.size()])];
    n += glm::dvec3((a.y - b.y) * (a.z + b.z), (a.z - b.z) * (a.x + b.x), (a.x - b.x) * (a.y + b.y));
  }
  if (!(glm::dot(n, n) > 0)) return false;
  n = glm::normalize(n);
  const glm::dvec3 ax = glm::normalize(std::abs(n.x) < 0.9 ? glm::cross(n, glm::dvec3(1, 0, 0)) : glm::cross(n, glm::dvec3(0, 1, 0)));
  const glm::dvec3 ay = glm::cross(n, ax);
  std::vector<Vec2> q(P.size());
  for (size_t i = 0; i < P.size(); ++i) q[i] = Vec2(glm::dot(P[i], ax), glm::dot(P[i], ay));
  // Outline counter-clockwise, holes clockwise, holes bridged rightmost first.
  std::vector<int> outline = outer;
  const bool flipped = signedArea(q, outline) < 0;
  if (flipped) std::reverse(outline.begin(), outline.end());
  std::vector<std::vector<int>> holes(loops.begin() + 1, loops.end());
  for (auto& h : holes) {
    if (h.size() < 3) return false;
    if (signedArea(q, h) > 0) std::reverse(h.begin(), h.end());
  }
  auto rightmost = [&](const std::vector<int>& h) {
    double x = -INFINITY;
    for (int i : h) x = std::max(x, q[size_t(i)].x);
    return x;
  };
  std::sort(holes.begin(), holes.end(), [&](const auto& a, const auto& b) { return rightmost(a) > rightmost(b); });
  for (const auto& h : holes)
    if (!bridge(q, outline, h)) return false;
  std::vector<std::array<int, 3>> clipped;
  if (!earClipLoop(q, outline, clipped)) return false;
  // The outline was turned counter-clockwise; the triangles take its given winding back.
  for (auto& t : clipped) triangles.push_back(flipped ? std::array<int, 3>{t[0], t[2], t[1]} : t);
  return true;
}

}  // namespace reshutter::shade
