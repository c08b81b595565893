// How the commands that render (resample, fields, retime) turn shutter options into the
// re-sampler's shutter model, and how they find the stores of a shot. One definition, so every
// command reads `--shutter`, `--shutter-angle`, `--shutter-position`, `--shutter-shape` and
// `--rolling-shutter` the same way.
//
// Time conventions (../shared/DESIGN.md): frame N's store covers [N + open, N + close] in absolute source
// frames and frame N's nominal time is N. A target frame's interval is given relative to its
// nominal time, in target-frame durations:
//   --shutter A:B                   [nominal + A·d, nominal + B·d]           (d: target frame duration)
//   --shutter-angle X --shutter-position start|center|end
//                                   length X/360·d opening at, centred on or closing at the nominal time
// For `resample`, d = 1 and the nominal time is the store's frame (so `--shutter 0:0.5` is the
// first half of the store's frame, as RenderMan's Shutter).
#pragma once

#include <map>
#include <memory>
#include <string>
#include <vector>

#include <CLI/CLI.hpp>

#include "resample/resampler.h"
#include "store/reader.h"

namespace reshutter::cli {

/// Parses "OPEN:CLOSE" (two finite numbers, OPEN <= CLOSE); throws Error naming `where`.
void parseInterval(const std::string& text, const std::string& where, double& open, double& close);

struct ShutterOptions {
  std::string shutter;             // "A:B"
  double angle = -1;               // degrees; < 0: not given
  std::string position = "start";  // start center end
  std::string shape = "box";
  double rolling = 0;              // read-out duration in target frames
  std::string direction = "down";

  void addTo(CLI::App* app, bool withInterval = true);
  bool given() const { return !shutter.empty() || angle >= 0; }
  /// [open, close] relative to a nominal time, in target-frame durations; defaults to
  /// [defaultOpen, defaultClose] when neither --shutter nor an angle is given.
  void interval(double& open, double& close, double defaultOpen, double defaultClose) const;
  resample::ShutterShape parsedShape() const;
  /// Applies the rolling read-out (duration in target frames × `frameDuration` source frames).
  void applyRolling(resample::ShutterModel& model, double frameDuration) const;
};

/// The stores of a shot named by a frame pattern (`shot.####.mps`), opened on demand and kept
/// while they are needed. Every store must share the first one's shutter and schema.
class ShotStores {
 public:
  ShotStores(std::string pattern, size_t cacheBytes);
  /// Source frames whose stores an interval [t0, t1] (absolute source frames) needs.
  std::vector<int64_t> framesFor(double t0, double t1);
  /// Throws one Error listing every missing store among `frames`, before any work starts.
  void requireAll(const std::vector<int64_t>& frames) const;
  /// The sources covering [t0, t1]; drops stores no longer needed (frames before t0's first).
  std::vector<resample::Source> sourcesFor(double t0, double t1);
  /// Metadata of the shot's first store opened (the one nearest `near` for a pattern).
  const store::StoreMeta& firstMeta(double near);
  std::string pathOf(int64_t frame) const;

 private:
  std::shared_ptr<const store::StoreReader> open(int64_t frame);
  void probe(double near);
  std::string pattern_;
  size_t cacheBytes_;
  bool probed_ = false;
  double open_ = 0, close_ = 1;
  std::map<int64_t, std::shared_ptr<const store::StoreReader>> openStores_;
  std::shared_ptr<const store::StoreReader> first_;
};

}  // namespace reshutter::cli
