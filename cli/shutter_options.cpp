#include "cli/shutter_options.h"

#include <cmath>
#include <cstdio>
#include <tuple>

#include "common/error.h"
#include "resample/retime.h"

namespace reshutter::cli {

void ShutterOptions::addTo(CLI::App* app, bool withInterval) {
  if (withInterval) {
    auto* s = app->add_option("--shutter", shutter,
                              "Interval OPEN:CLOSE relative to the target frame's nominal time, in target frames\n"
                              "(OPEN = CLOSE: the exact instant)")
                  ->group("Shutter");
    app->add_option("--shutter-angle", angle, "Shutter angle in degrees (360 = the whole frame)")->check(CLI::Range(0.0, 360.0))->excludes(s)->group("Shutter");
    app->add_option("--shutter-position", position, "Where the shutter sits on the nominal time: start, center or end (as Blender)")
        ->check(CLI::IsMember({"start", "center", "end"}))
        ->capture_default_str()
        ->group("Shutter");
  }
  app->add_option("--shutter-shape", shape,
                  "Shutter opening: box, trapezoid:A:B (RenderMan shutteropening: fully open from A to B),\n"
                  "curve:F:W,F:W,... (piecewise linear); sample times follow the shape")
      ->capture_default_str()
      ->group("Shutter");
  app->add_option("--rolling-shutter", rolling, "Rolling shutter: rows are read out over this many target frames (CMOS)")
      ->check(CLI::Range(0.0, 100.0))
      ->group("Shutter");
  app->add_option("--direction", direction, "Rolling read-out direction: down (top row first) or up")
      ->check(CLI::IsMember({"down", "up"}))
      ->capture_default_str()
      ->group("Shutter");
}

void parseInterval(const std::string& text, const std::string& where, double& open, double& close) {
  char tail = 0;
  if (std::sscanf(text.c_str(), "%lf:%lf%c", &open, &close, &tail) != 2 || !std::isfinite(open) || !std::isfinite(close))
    fail(where, "expected OPEN:CLOSE, got '", text, "'");
  if (close < open) fail(where, "the interval ", open, ":", close, " closes before it opens");
}

void ShutterOptions::interval(double& open, double& close, double defaultOpen, double defaultClose) const {
  open = defaultOpen, close = defaultClose;
  if (!shutter.empty()) {
    parseInterval(shutter, "--shutter", open, close);
  } else if (angle >= 0) {
    std::tie(open, close) = resample::angleInterval(angle, resample::parseShutterPosition(position, "--shutter-position"));
  }
}

resample::ShutterShape ShutterOptions::parsedShape() const { return resample::ShutterShape::parse(shape, "--shutter-shape"); }

resample::RollingShutter ShutterOptions::rollingShutter() const {
  resample::RollingShutter r;
  r.duration = rolling;
  r.upward = direction == "up";
  return r;
}

void ShutterOptions::applyRolling(resample::ShutterModel& model, double frameDuration) const {
  resample::RollingShutter r = rollingShutter();
  r.duration = rolling * frameDuration;
  model.setRolling(r);
}

}  // namespace reshutter::cli
