#include "cli/shutter_options.h"

#include <cmath>
#include <cstdio>
#include <filesystem>
#include <sstream>

#include "common/error.h"
#include "common/frame_range.h"

namespace reshutter::cli {

void ShutterOptions::addTo(CLI::App* app, bool withInterval) {
  if (withInterval) {
    auto* s = app->add_option("--shutter", shutter,
                              "Interval OPEN:CLOSE relative to the target frame's nominal time, in target frames\n"
                              "(OPEN = CLOSE: the exact instant)")
                  ->group("Shutter");
    app->add_option("--shutter-angle", angle, "Shutter angle in degrees (360 = the whole frame)")
        ->check(CLI::Range(0.0, 360.0))
        ->excludes(s)
        ->group("Shutter");
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
    const double len = angle / 360.0;
    if (position == "start") open = 0, close = len;
    else if (position == "center") open = -len / 2, close = len / 2;
    else open = -len, close = 0;
  }
}

resample::ShutterShape ShutterOptions::parsedShape() const { return resample::ShutterShape::parse(shape, "--shutter-shape"); }

void ShutterOptions::applyRolling(resample::ShutterModel& model, double frameDuration) const {
  resample::RollingShutter r;
  r.duration = rolling * frameDuration;
  r.upward = direction == "up";
  model.setRolling(r);
}

// ---------------------------------------------------------------------------------------------

ShotStores::ShotStores(std::string pattern, size_t cacheBytes) : pattern_(std::move(pattern)), cacheBytes_(cacheBytes) {}

std::string ShotStores::pathOf(int64_t frame) const { return expandFramePattern(pattern_, frame); }

std::shared_ptr<const store::StoreReader> ShotStores::open(int64_t frame) {
  if (auto it = openStores_.find(frame); it != openStores_.end()) return it->second;
  store::ReaderOptions ro;
  ro.cacheBytes = cacheBytes_;
  auto reader = std::make_shared<const store::StoreReader>(pathOf(frame), ro);
  const auto& m = reader->meta();
  if (hasFramePlaceholder(pattern_) && m.frame != frame)
    fail(pathOf(frame), "the store says it holds frame ", m.frame, ", its name says frame ", frame);
  if (first_) {
    const auto& f = first_->meta();
    if (m.shutterOpen != f.shutterOpen || m.shutterClose != f.shutterClose)
      fail(pathOf(frame), "its shutter [", m.shutterOpen, ", ", m.shutterClose, "] differs from ", first_->path(), "'s [", f.shutterOpen, ", ",
           f.shutterClose, "]; a shot's stores must share one shutter");
  }
  openStores_[frame] = reader;
  return reader;
}

void ShotStores::probe(double near) {
  if (probed_) return;
  if (!hasFramePlaceholder(pattern_)) {
    store::ReaderOptions ro;
    ro.cacheBytes = cacheBytes_;
    first_ = std::make_shared<const store::StoreReader>(pattern_, ro);
    openStores_[first_->meta().frame] = first_;
  } else {
    // Learn the shot's shutter from the store nearest the first time asked for.
    const int64_t centre = int64_t(std::floor(near));
    for (int64_t d = 0; d <= 4 && !first_; ++d)
      for (int64_t f : {centre + d, centre - d})
        if (!first_ && std::filesystem::exists(pathOf(f))) first_ = open(f);
    if (!first_) fail(pattern_, "no store found near frame ", centre, " (looked for ", pathOf(centre), " and its neighbours)");
  }
  open_ = first_->meta().shutterOpen, close_ = first_->meta().shutterClose;
  probed_ = true;
}

const store::StoreMeta& ShotStores::firstMeta(double near) {
  probe(near);
  return first_->meta();
}

std::vector<int64_t> ShotStores::framesFor(double t0, double t1) {
  probe(t0);
  if (!hasFramePlaceholder(pattern_)) return {first_->meta().frame};
  // Frame F covers [F + open, F + close]. It is needed when that overlaps [t0, t1] with positive
  // length, or holds the instant t0 = t1; a store that only touches the interval's end is not.
  std::vector<int64_t> frames;
  for (int64_t f = int64_t(std::floor(t0 - close_)) - 1; double(f) + open_ <= t1 + 1; ++f) {
    const double lo = double(f) + open_, hi = double(f) + close_;
    const bool overlaps = t0 < t1 ? (lo < t1 && hi > t0) || (lo == hi && lo >= t0 && lo <= t1) : (t0 >= lo && t0 <= hi);
    if (overlaps) frames.push_back(f);
  }
  return frames;
}

void ShotStores::requireAll(const std::vector<int64_t>& frames) const {
  std::vector<std::string> missing;
  for (int64_t f : frames)
    if (!openStores_.count(f) && !std::filesystem::exists(pathOf(f))) missing.push_back(pathOf(f));
  if (missing.empty()) return;
  std::ostringstream s;
  for (size_t i = 0; i < missing.size(); ++i) {
    if (i == 12) {
      s << " and " << missing.size() - 12 << " more";
      break;
    }
    s << (i ? ", " : "") << missing[i];
  }
  fail(pattern_, missing.size(), " store", missing.size() == 1 ? " is" : "s are", " missing: ", s.str());
}

std::vector<resample::Source> ShotStores::sourcesFor(double t0, double t1) {
  std::vector<int64_t> frames = framesFor(t0, t1);
  requireAll(frames);
  // Release stores this and later intervals no longer reach (sequences move forward in time).
  for (auto it = openStores_.begin(); it != openStores_.end();) {
    if (!frames.empty() && it->first < frames.front() && it->second != first_) it = openStores_.erase(it);
    else ++it;
  }
  std::vector<resample::Source> sources;
  for (int64_t f : frames) sources.push_back(resample::Source{open(f), f});
  return sources;
}

}  // namespace reshutter::cli
