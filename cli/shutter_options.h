// How the commands that render (resample, fields, retime) read shutter options. One definition, so
// every command reads `--shutter`, `--shutter-angle`, `--shutter-position`, `--shutter-shape` and
// `--rolling-shutter` the same way; what the values mean for a sequence (fields, rate conversion)
// is the library's (resample/retime.h), and a shot's stores are store/shot.h's.
//
// Time conventions (docs/resample.md): frame N's store covers [N + open, N + close] in absolute source
// frames and frame N's nominal time is N. A target frame's interval is given relative to its
// nominal time, in target-frame durations:
//   --shutter A:B                   [nominal + A·d, nominal + B·d]           (d: target frame duration)
//   --shutter-angle X --shutter-position start|center|end
//                                   length X/360·d opening at, centred on or closing at the nominal time
// For `resample`, d = 1 and the nominal time is the store's frame (so `--shutter 0:0.5` is the
// first half of the store's frame, as RenderMan's Shutter).
#pragma once

#include <string>

#include <CLI/CLI.hpp>

#include "resample/resampler.h"

namespace reshutter::cli {

/// Parses "OPEN:CLOSE" (two finite numbers, OPEN <= CLOSE); throws Error naming `where`.
void parseInterval(const std::string& text, const std::string& where, double& open, double& close);

struct ShutterOptions {
  std::string shutter;             // "A:B"
  double angle = -1;               // degrees; < 0: not given
  std::string position = "start";  // start center end
  std::string shape = "box";
  double rolling = 0;  // read-out duration in target frames
  std::string direction = "down";

  void addTo(CLI::App* app, bool withInterval = true);
  bool given() const { return !shutter.empty() || angle >= 0; }
  /// [open, close] relative to a nominal time, in target-frame durations; defaults to
  /// [defaultOpen, defaultClose] when neither --shutter nor an angle is given.
  void interval(double& open, double& close, double defaultOpen, double defaultClose) const;
  resample::ShutterShape parsedShape() const;
  /// The rolling read-out, its duration in target frames.
  resample::RollingShutter rollingShutter() const;
  /// Applies the rolling read-out (duration in target frames × `frameDuration` source frames).
  void applyRolling(resample::ShutterModel& model, double frameDuration) const;
};

}  // namespace reshutter::cli
