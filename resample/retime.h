// Re-timing: the shutter of every output frame of a sequence rendered from a shot's stores, and
// the two-pass interlace. Owns the arithmetic that turns what a user asks for (interlaced fields
// with a dominance and a field shutter; a rate conversion with a shutter angle, position, shape
// and rolling read-out) into one ShutterModel per output frame (resample/shutter.h), finding the
// stores each frame's shutter reaches (store/shot.h), and interlacing two full-frame field
// renders row by row, flat channels and deep pixels alike. It renders nothing itself: every frame
// goes through the one re-sampler (resample/resampler.h).
//
// Time conventions (docs/resample.md): times are absolute source frames; a store for frame N
// covers [N + open, N + close] and frame N's nominal time is N. A shutter is given relative to its
// frame's (or field's) nominal time in that frame's (or field's) durations:
//   [open, close]                              [nominal + open·d, nominal + close·d]
//   angle X at position start | center | end  length X/360·d opening at, centred on or closing at the nominal time
#pragma once

#include <cstdint>
#include <string>
#include <utility>
#include <vector>

#include "resample/resampler.h"
#include "resample/shutter.h"
#include "store/model.h"
#include "store/shot.h"

namespace reshutter::resample {

/// Where a shutter of a given angle sits on its nominal time (Blender's shutter position).
enum class ShutterPosition { Start, Center, End };
/// "start", "center", "end"; throws Error naming `where` otherwise.
ShutterPosition parseShutterPosition(const std::string& text, const std::string& where);
/// [open, close] of an `angleDegrees` shutter at `position`, relative to the nominal time, in
/// frame durations (360° = one frame).
std::pair<double, double> angleInterval(double angleDegrees, ShutterPosition position);

/// One output frame of a sequence: its number and the shutter it is rendered with (absolute
/// source frames).
struct OutputFrame {
  int64_t frame = 0;
  ShutterModel shutter;
};

// ---------------------------------------------------------------------------------------------
// Interlaced fields

/// Field 1 of frame N is nominally at N, field 2 at N + 1/2; each is open for [open, close]
/// field durations (half a frame) about its nominal time: the default 180° field shutter exposes
/// [N, N + 0.25] and [N + 0.5, N + 0.75].
struct FieldShutter {
  int firstFieldParity = 0;      // rows with row % 2 == parity are field 1: 0 upper dominance, 1 lower
  double open = 0, close = 0.5;  // each field's interval relative to its nominal time, field durations
  ShutterShape shape = ShutterShape::box();
  RollingShutter rolling;  // duration in frames (the frame's rows are read out once)
};

/// Parity of field 1's rows: "upper" (row 0 in field 1) → 0, "lower" → 1; Error naming `where` otherwise.
int parseDominance(const std::string& text, const std::string& where);
/// The two fields' intervals of frame `frame` (absolute source frames).
std::pair<ShutterGroup, ShutterGroup> fieldGroups(int64_t frame, const FieldShutter& fields);
/// One-pass: every row samples only its own field's interval.
ShutterModel fieldShutter(int64_t frame, const FieldShutter& fields);
std::vector<OutputFrame> fieldFrames(const std::vector<int64_t>& frames, const FieldShutter& fields);
/// Two-pass: each field as a progressive shutter for a full frame, field 1 first.
std::pair<ShutterModel, ShutterModel> fieldPassShutters(int64_t frame, const FieldShutter& fields);
/// Whether raster row y (absolute, not data-window relative) belongs to field 2.
inline bool secondFieldRow(int y, int firstFieldParity) { return ShutterModel::fieldOfRow(y, firstFieldParity) == 1; }

/// Interlaces two full-frame renders of one frame's fields: `first` keeps its field-1 rows and
/// takes `second`'s field-2 rows, in every flat channel and, when both carry one, in the deep
/// image; the provenance names both shutters. The two must come from one spec but for the
/// shutter (same data window, channels and deep layout); anything else is a CHECK failure.
void interlaceFields(RenderResult& first, const RenderResult& second, int firstFieldParity);

// ---------------------------------------------------------------------------------------------
// Frame-rate conversion

/// Output frame k of rate `to` is nominally at k·from/to source frames; its shutter [open, close]
/// is in target-frame durations about that time (default 180°, opening at the nominal time), its
/// rolling read-out duration in target frames.
struct RateConversion {
  store::Rational from{24, 1}, to{24, 1};  // source and target rates; one not positive is an Error
  double open = 0, close = 0.5;
  ShutterShape shape = ShutterShape::box();
  RollingShutter rolling;
  /// Source frames per target frame, from/to, exact up to long double rounding.
  long double ratio() const;
};

std::vector<OutputFrame> retimeFrames(const std::vector<int64_t>& frames, const RateConversion& conversion);

// ---------------------------------------------------------------------------------------------
// Sources

/// The re-sampler's sources for [t0, t1] from a shot's stores (ShotStores::storesFor).
std::vector<Source> sourcesFor(store::ShotStores& shot, double t0, double t1);
/// Throws one Error listing every store any of `frames` needs that is missing, before any work.
void requireStores(store::ShotStores& shot, const std::vector<OutputFrame>& frames);
/// A spec with `shutter` and the sources its times reach; the caller adds the render settings.
RenderSpec frameSpec(store::ShotStores& shot, const ShutterModel& shutter);

}  // namespace reshutter::resample
