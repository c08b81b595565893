// The shutter model: which times each output sample sees. A shutter is a set of *groups*, each an
// interval [open, close] in frames with an opening shape; every output row belongs to one group
// (progressive: one group; interlaced fields: rows alternate between two). Within a group a
// sample's time is open + rolling(y) + warp(u)·(close − open), where u ∈ [0, 1) is the sample's
// stratified time variate, warp() the inverse CDF of the opening shape (samples follow the shape:
// importance sampling, not weights) and rolling(y) the CMOS read-out delay of the sample's row.
#pragma once

#include <string>
#include <utility>
#include <vector>

namespace reshutter::resample {

/// Opening function of a shutter over its interval: box (instant open and close), trapezoid
/// (RenderMan's "shutteropening" [a b]: fully open from fraction a to b, linear ramps either side)
/// or a sampled curve (piecewise linear through (fraction, weight) points).
class ShutterShape {
 public:
  static ShutterShape box();
  static ShutterShape trapezoid(double a, double b);
  static ShutterShape curve(std::vector<std::pair<double, double>> points);
  /// Parses "box", "trapezoid:0.2:0.8", "curve:0:0,0.5:1,1:0". Throws Error naming `where`.
  static ShutterShape parse(const std::string& text, const std::string& where);

  /// Inverse CDF: maps u ∈ [0, 1] to the fraction of the interval where that much of the
  /// exposure has accumulated. Monotone; warp(0) = 0, warp(1) = 1.
  double warp(double u) const;
  /// Opening weight at a fraction (for tests and documentation plots), normalised to mean 1.
  double density(double fraction) const;
  bool isBox() const { return box_; }
  const std::string& description() const { return description_; }

 private:
  bool box_ = true;
  std::vector<double> f_, w_, cdf_;  // nodes: fraction, weight, cumulative area (normalised)
  std::string description_ = "box";
};

struct ShutterGroup {
  double open = 0.0, close = 1.0;  // frames, in the same frame-relative time as the store
  ShutterShape shape = ShutterShape::box();
  double length() const { return close - open; }
};

/// Rolling shutter: the row at raster y starts its exposure `duration`·(y / height) frames later
/// (direction down) or earlier rows later (direction up).
struct RollingShutter {
  double duration = 0.0;
  bool upward = false;
  int height = 1;
  double delay(double y) const {
    double f = y / double(height);
    return duration * (upward ? 1.0 - f : f);
  }
};

class ShutterModel {
 public:
  ShutterModel() = default;
  /// One interval for every row.
  static ShutterModel progressive(double open, double close, ShutterShape shape = ShutterShape::box());
  /// Interlaced: rows with (row % 2 == firstFieldParity) see `first`, the others `second`.
  static ShutterModel fields(ShutterGroup first, ShutterGroup second, int firstFieldParity);

  const std::vector<ShutterGroup>& groups() const { return groups_; }
  int groupOfRow(int row) const { return groups_.size() == 1 ? 0 : fieldOfRow(row, parity_); }
  /// Interlaced: 0 for a row of the first field (row % 2 == firstFieldParity), 1 for the second.
  static int fieldOfRow(int row, int firstFieldParity) { return ((row - firstFieldParity) % 2 + 2) % 2; }
  void setRolling(RollingShutter r) { rolling_ = r; }
  const RollingShutter& rolling() const { return rolling_; }

  double time(int group, double y, double u) const {
    const ShutterGroup& g = groups_[size_t(group)];
    // A global box shutter (the common case, once per sample in every bucket): the delay is ±0
    // and warp(u) = u, so this is the same sum without the division and the out-of-line call.
    if (rolling_.duration == 0.0 && g.shape.isBox()) return g.open + u * g.length();
    return g.open + rolling_.delay(y) + g.shape.warp(u) * g.length();
  }
  /// Bounds of time(group, y, u) for y ∈ [y0, y1], u ∈ [u0, u1].
  void timeRange(int group, double y0, double y1, double u0, double u1, double& t0, double& t1) const;
  /// Earliest and latest time any sample can see.
  double earliest() const;
  double latest() const;
  /// True when every sample of a group sees the same instant (zero-length, no rolling).
  bool instantaneous(int group) const { return groups_[size_t(group)].length() == 0.0 && rolling_.duration == 0.0; }

 private:
  std::vector<ShutterGroup> groups_{ShutterGroup{}};
  int parity_ = 0;
  RollingShutter rolling_;
};

}  // namespace reshutter::resample
