// A bucket's samples: where and when every sample of a region (bucket interior plus the filter's
// margin) lies, stored stratum-major (plane s holds each pixel's sample in time stratum s) - or,
// when no sample's time is drawn and there is no lens, pixel-major (each pixel's samples side by
// side: only the static path draws then, and a micropolygon's samples are a few cache lines
// instead of one or two per stratum) - with the time range of each stratum and shutter group; and
// the region tests the drawing paths make against it (which pixels a raster box touches, whether
// a box misses the region).
//
// Sample times are float offsets from one base shared by every bucket (tBase), so a sample's time
// is the same whichever bucket computes it, and precise at any frame number.
#pragma once

#include <algorithm>
#include <array>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <vector>

#include "resample/sampling.h"
#include "resample/shutter.h"

namespace reshutter::resample {

/// A per-sample array whose first element lies `skewLines` cache lines into its allocation. The
/// rasterizer reads and writes several per-sample arrays at one sample index; large allocations
/// all start at the same offset within a page, so unskewed those elements share one L1 set (64
/// sets of 8 ways) and a hit's loads and stores evicted each other. Each array has a skew of its
/// own (BucketSamples, HitBuffer, the drawing scratch of raster_impl.h).
template <class T>
class SkewedArray {
 public:
  explicit SkewedArray(int skewLines) : skew_(size_t(skewLines) * 64 / sizeof(T)) {}
  void resize(size_t n) {
    storage_.resize(skew_ + n);
    p_ = storage_.data() + skew_;
  }
  void assign(size_t n, T v) {
    storage_.assign(skew_ + n, v);
    p_ = storage_.data() + skew_;
  }
  T* data() { return p_; }
  const T* data() const { return p_; }
  T& operator[](size_t i) { return p_[i]; }
  const T& operator[](size_t i) const { return p_[i]; }

 private:
  size_t skew_;
  std::vector<T> storage_;
  T* p_ = nullptr;
};

/// The vector kernels read up to 7 floats past a row's end and write up to 15 entries past a
/// count: every per-sample array has this much room past its end.
inline constexpr size_t kPad = 16;

/// The smallest and largest of n > 0 floats, none NaN: exact in any order, so four lanes at a
/// time where the CPU has them (the compiler will not vectorise a float min without -ffast-math).
void floatRange(const float* v, size_t n, float& lo, float& hi);

struct BucketSamples {
  /// With a lens (lensTimeBlocks >= 1), each sample also has a lens position, and the planes pair
  /// lens and time strata (SamplePattern::lensPlanes) rather than being time strata.
  /// drawTimes false: nothing reads a sample's time (RasterOptions::sampleTimes): samples take
  /// their row's time at the middle of the interval and lie in planes by their order.
  BucketSamples(const SamplePattern& pattern, const ShutterModel& shutter, int lensTimeBlocks = 0, bool drawTimes = true);

  /// Lays out the samples of region [x0, x0+w) × [y0, y0+h) (raster pixels).
  void prepare(int x0, int y0, int w, int h);

  const SamplePattern& pattern;
  const ShutterModel& shutter;
  const int N;  // samples per pixel = time strata (= lens strata)
  /// Depth of field: with lensTimeBlocks 1, plane s holds each pixel's sample in lens stratum s (its
  /// time stratum is the pixel's own permutation); with A > 1 time blocks, plane s pairs time block
  /// s / (N/A) with a quadrant of the lens (SamplePattern::lensPlanes): for moving scenes. Which
  /// lens point and time each sample gets follows from it; the lens path's search does not use
  /// the planes (it sorts the samples by depth layer). Without a lens, planes are time strata.
  const bool lensPlanes;
  const int lensTimeBlocks;
  const bool drawTimes;
  /// No drawn times and no lens: sample i of pixel p lies at slot p N + i (idxOf is the identity).
  /// Only the static path draws then (every part stands still, or the shutter is an instant), and
  /// it reads the samples through slot() and its gather's rows.
  const bool pixelMajor;
  /// Whether a render's samples are pixel-major (for a plan that chooses by it before any bucket).
  static bool pixelMajorFor(bool drawTimes, bool lens) { return !drawTimes && !lens; }

  // Region.
  int x0 = 0, y0 = 0, w = 0, h = 0, P = 0;
  // Stratum planes are PS >= P samples apart, PS chosen so that a plane is an odd number of cache
  // lines: with P itself (a multiple of 64 lines for the default bucket) every plane's pixel p
  // maps to the same L1 set, and a micropolygon's 16 strata evict each other.
  size_t PS = 0;
  size_t sampleSlots = 0;                   // N * PS: the length of every per-sample array
  SkewedArray<float> sx{0}, sy{8}, st{16};  // [slot(s, p)]
  std::vector<uint32_t> idxOf;              // [p * N + i] → slot(s, p) (sample i of pixel p lies in stratum s)
  SkewedArray<float> lx{40}, ly{48};        // lensPlanes: the sample's point on the unit disk, [s * PS + p]
  std::vector<std::array<float, 4>> lensRange;  // lensPlanes: [s] the range u0 u1 v0 v1 of plane s's lens points
  std::vector<uint8_t> rowGroup;            // per region row
  std::vector<uint8_t> groupPresent;
  bool multiGroup = false;                   // more than one shutter group (fields): rows differ
  int rowParity = -1;                        // two groups alternating by row: rowGroup[r] = (rowParity + r) & 1; else -1
  std::vector<double> stratumLo, stratumHi;  // [g * N + s], absolute frames
  double tMin = 0, tMax = 0;
  // The base of the stored times (st): the whole frame before the earliest time, not the earliest
  // time itself, so a field rendered alone and the same field inside an interlaced frame get
  // bit-identical times.
  double tBase = 0;

  /// The slot of pixel p's sample in stratum (or plane) s: s PS + p, or p N + s when pixelMajor.
  size_t slot(int s, size_t p) const { return pixelMajor ? p * size_t(N) + size_t(s) : size_t(s) * PS + p; }

  /// Where to test a micropolygon with raster box (bx0, by0)-(bx1, by1): the pixels its box
  /// touches, and the box (widened for float rounding) that each sample must lie in before its
  /// edge functions are evaluated. An unbounded micropolygon (a corner before the near plane) is
  /// tested everywhere. False when nothing in the region can be covered.
  struct TestArea {
    int px0, py0, px1, py1;
    float sx0 = -INFINITY, sy0 = -INFINITY, sx1 = INFINITY, sy1 = INFINITY;
  };
  bool testArea(bool bounded, float bx0, float by0, float bx1, float by1, TestArea& a) const {
    if (!bounded) {
      a.px0 = x0, a.py0 = y0, a.px1 = x0 + w - 1, a.py1 = y0 + h - 1;
      return true;
    }
    if (!pixelRange(bx0, by0, bx1, by1, a.px0, a.py0, a.px1, a.py1)) return false;
    const float sm = 1e-3f + 1e-6f * std::max(std::max(std::abs(bx0), std::abs(bx1)), std::max(std::abs(by0), std::abs(by1)));
    a.sx0 = bx0 - sm, a.sy0 = by0 - sm, a.sx1 = bx1 + sm, a.sy1 = by1 + sm;
    return true;
  }

  /// Pixel range of a raster box, clipped to the region; false if empty.
  bool pixelRange(float bx0, float by0, float bx1, float by1, int& px0, int& py0, int& px1, int& py1) const {
    // A sample at x lies in pixel floor(x); a small margin absorbs float rounding of projections.
    const float mag = std::max(std::max(std::abs(bx0), std::abs(bx1)), std::max(std::abs(by0), std::abs(by1)));
    const float m = 1e-3f + 1e-6f * mag;
    // Clamped into the region first (NaN goes to the low end), so the floor is a plain int cast:
    // std::floor is a libm call on baseline x86-64 and this runs once per stratum.
    auto clampTo = [](float v, float lo, float hi) { return v >= lo ? (v <= hi ? v : hi) : lo; };
    auto floorInt = [](float v) {
      const int i = int(v);
      return i - (float(i) > v);
    };
    px0 = floorInt(clampTo(bx0 - m, float(x0), float(x0 + w)));
    py0 = floorInt(clampTo(by0 - m, float(y0), float(y0 + h)));
    px1 = std::min(x0 + w - 1, floorInt(clampTo(bx1 + m, float(x0 - 1), float(x0 + w))));
    py1 = std::min(y0 + h - 1, floorInt(clampTo(by1 + m, float(y0 - 1), float(y0 + h))));
    return px0 <= px1 && py0 <= py1;
  }

  /// True when the raster box [bx0, bx1] × [by0, by1] of float-projected positions lies outside
  /// the region by more than `scale` times the culls' rounding margin (1e-3 px plus 1e-6 of the
  /// coordinates' magnitude).
  bool boxMissesRegion(float bx0, float by0, float bx1, float by1, float scale) const {
    const float mm = scale * 1e-3f + scale * 1e-6f * std::max(std::max(std::abs(bx0), std::abs(bx1)), std::max(std::abs(by0), std::abs(by1)));
    return bx1 + mm < float(x0) || bx0 - mm >= float(x0 + w) || by1 + mm < float(y0) || by0 - mm >= float(y0 + h);
  }

  /// True when a chunk's raster vertex positions (xs / ys, n entries; a moving chunk's at every
  /// cull time) lie wholly outside the region: then so does every micropolygon's path, since
  /// within a knot segment each corner moves along the straight screen segment between two cull
  /// positions. The margin is twice the one the per-micropolygon culls use for float rounding (the
  /// static path's chunks, whose vertices do not move, use the culls' own). A vertex before the
  /// near plane (x NaN) keeps the chunk.
  bool pointsMissRegion(const float* xs, const float* ys, size_t n, float scale) const;
};

}  // namespace reshutter::resample
