#include "resample/shutter.h"

#include <algorithm>
#include <cmath>
#include <sstream>

#include "common/error.h"

namespace reshutter::resample {

ShutterShape ShutterShape::box() { return ShutterShape{}; }

ShutterShape ShutterShape::curve(std::vector<std::pair<double, double>> points) {
  ShutterShape s;
  std::sort(points.begin(), points.end());
  if (points.size() < 2 || points.front().first != 0.0 || points.back().first != 1.0) fail("shutter shape", "a curve needs points at fractions 0 and 1");
  s.box_ = false;
  double area = 0;
  s.cdf_.push_back(0);
  for (size_t i = 0; i < points.size(); ++i) {
    auto [f, w] = points[i];
    if (!(w >= 0) || !std::isfinite(w)) fail("shutter shape", "weights must be finite and non-negative");
    if (i > 0 && !(f > s.f_.back())) fail("shutter shape", "fractions must increase");
    if (i > 0) {
      area += 0.5 * (w + s.w_.back()) * (f - s.f_.back());
      s.cdf_.push_back(area);
    }
    s.f_.push_back(f);
    s.w_.push_back(w);
  }
  if (!(area > 0)) fail("shutter shape", "the shutter never opens (zero area)");
  for (double& c : s.cdf_) c /= area;
  for (double& w : s.w_) w /= area;
  s.cdf_.back() = 1.0;
  std::ostringstream d;
  d << "curve";
  for (auto [f, w] : points) d << " " << f << ":" << w;
  s.description_ = d.str();
  return s;
}

ShutterShape ShutterShape::trapezoid(double a, double b) {
  if (!(a >= 0 && a <= b && b <= 1)) fail("shutter shape", "trapezoid needs 0 <= a <= b <= 1 (got ", a, ", ", b, ")");
  std::vector<std::pair<double, double>> pts{{0.0, a > 0 ? 0.0 : 1.0}};
  if (a > 0) pts.push_back({a, 1.0});
  if (b > a || (a == 0 && b < 1)) pts.push_back({b, 1.0});
  pts.push_back({1.0, b < 1 ? 0.0 : 1.0});
  // Remove duplicate fractions (a = 0 or b = 1 collapse ramps).
  std::vector<std::pair<double, double>> clean;
  for (auto p : pts)
    if (clean.empty() || p.first > clean.back().first) clean.push_back(p);
  ShutterShape s = curve(clean);
  if (a == 0 && b == 1) return box();
  std::ostringstream d;
  d << "trapezoid " << a << " " << b;
  s.description_ = d.str();
  return s;
}

ShutterShape ShutterShape::parse(const std::string& text, const std::string& where) {
  std::vector<std::string> parts;
  std::stringstream ss(text);
  std::string item;
  while (std::getline(ss, item, ':')) parts.push_back(item);
  try {
    if (text == "box") return box();
    if (!parts.empty() && parts[0] == "trapezoid" && parts.size() == 3) return trapezoid(std::stod(parts[1]), std::stod(parts[2]));
    if (text.rfind("curve:", 0) == 0) {
      std::vector<std::pair<double, double>> pts;
      std::stringstream list(text.substr(6));
      while (std::getline(list, item, ',')) {
        auto colon = item.find(':');
        if (colon == std::string::npos) fail(where, "curve points are fraction:weight, got '", item, "'");
        pts.push_back({std::stod(item.substr(0, colon)), std::stod(item.substr(colon + 1))});
      }
      return curve(pts);
    }
  } catch (const Error& e) {
    fail(where, e.problem());
  } catch (const std::exception&) {
    fail(where, "cannot read the numbers in '", text, "'");
  }
  fail(where, "unknown shutter shape '", text, "' (box, trapezoid:A:B, curve:F:W,F:W,...)");
}

double ShutterShape::warp(double u) const {
  if (box_) return u;
  u = std::clamp(u, 0.0, 1.0);
  size_t i = size_t(std::upper_bound(cdf_.begin(), cdf_.end(), u) - cdf_.begin());
  if (i == 0) return 0.0;
  if (i >= cdf_.size()) return 1.0;
  --i;
  // On [f_i, f_i+1] the density is linear: w(x) = w0 + (w1 - w0)·x/h; solve the quadratic for x.
  const double h = f_[i + 1] - f_[i], w0 = w_[i], w1 = w_[i + 1], need = u - cdf_[i];
  const double slope = (w1 - w0) / h;
  double x;
  if (std::abs(slope) < 1e-12) {
    x = w0 > 0 ? need / w0 : 0.0;
  } else {
    double disc = std::max(0.0, w0 * w0 + 2.0 * slope * need);
    x = (-w0 + std::sqrt(disc)) / slope;
    // The stable form avoids cancellation when w0 dominates.
    if (w0 > 0) x = 2.0 * need / (w0 + std::sqrt(disc));
  }
  return std::clamp(f_[i] + std::clamp(x, 0.0, h), 0.0, 1.0);
}

double ShutterShape::density(double f) const {
  if (box_) return (f >= 0 && f <= 1) ? 1.0 : 0.0;
  if (f < 0 || f > 1) return 0.0;
  size_t i = size_t(std::upper_bound(f_.begin(), f_.end(), f) - f_.begin());
  if (i == 0) return w_.front();
  if (i >= f_.size()) return w_.back();
  double a = (f - f_[i - 1]) / (f_[i] - f_[i - 1]);
  return w_[i - 1] + a * (w_[i] - w_[i - 1]);
}

ShutterModel ShutterModel::progressive(double open, double close, ShutterShape shape) {
  ShutterModel m;
  m.groups_ = {ShutterGroup{open, close, std::move(shape)}};
  return m;
}

ShutterModel ShutterModel::fields(ShutterGroup first, ShutterGroup second, int firstFieldParity) {
  ShutterModel m;
  m.groups_ = {std::move(first), std::move(second)};
  m.parity_ = firstFieldParity & 1;
  return m;
}

void ShutterModel::timeRange(int group, double y0, double y1, double u0, double u1, double& t0, double& t1) const {
  const ShutterGroup& g = groups_[size_t(group)];
  double d0 = rolling_.delay(y0), d1 = rolling_.delay(y1);
  t0 = g.open + std::min(d0, d1) + g.shape.warp(u0) * g.length();
  t1 = g.open + std::max(d0, d1) + g.shape.warp(u1) * g.length();
}

double ShutterModel::earliest() const {
  double t = groups_[0].open;
  for (const auto& g : groups_) t = std::min(t, g.open);
  return t + std::min(0.0, std::min(rolling_.delay(0), rolling_.delay(rolling_.height)));
}

double ShutterModel::latest() const {
  double t = groups_[0].close;
  for (const auto& g : groups_) t = std::max(t, g.close);
  return t + std::max(rolling_.delay(0), rolling_.delay(rolling_.height));
}

}  // namespace reshutter::resample
