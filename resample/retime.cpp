#include "resample/retime.h"

#include <algorithm>

#include "common/check.h"
#include "common/error.h"

namespace reshutter::resample {

ShutterPosition parseShutterPosition(const std::string& text, const std::string& where) {
  if (text == "start") return ShutterPosition::Start;
  if (text == "center") return ShutterPosition::Center;
  if (text == "end") return ShutterPosition::End;
  fail(where, "expected start, center or end, got '", text, "'");
}

std::pair<double, double> angleInterval(double angleDegrees, ShutterPosition position) {
  const double len = angleDegrees / 360.0;
  switch (position) {
    case ShutterPosition::Start: return {0.0, len};
    case ShutterPosition::Center: return {-len / 2, len / 2};
    case ShutterPosition::End: return {-len, 0.0};
  }
  CHECK(false, "unknown shutter position ", int(position));
}

// ---------------------------------------------------------------------------------------------
// Interlaced fields

int parseDominance(const std::string& text, const std::string& where) {
  if (text == "upper") return 0;
  if (text == "lower") return 1;
  fail(where, "expected upper or lower, got '", text, "'");
}

std::pair<ShutterGroup, ShutterGroup> fieldGroups(int64_t frame, const FieldShutter& fields) {
  const double F = double(frame), d = 0.5, a = fields.open, b = fields.close;
  return {ShutterGroup{F + a * d, F + b * d, fields.shape}, ShutterGroup{F + d + a * d, F + d + b * d, fields.shape}};
}

ShutterModel fieldShutter(int64_t frame, const FieldShutter& fields) {
  auto [g1, g2] = fieldGroups(frame, fields);
  ShutterModel m = ShutterModel::fields(g1, g2, fields.firstFieldParity);
  m.setRolling(fields.rolling);
  return m;
}

std::vector<OutputFrame> fieldFrames(const std::vector<int64_t>& frames, const FieldShutter& fields) {
  std::vector<OutputFrame> out;
  for (int64_t f : frames) out.push_back({f, fieldShutter(f, fields)});
  return out;
}

std::pair<ShutterModel, ShutterModel> fieldPassShutters(int64_t frame, const FieldShutter& fields) {
  auto [g1, g2] = fieldGroups(frame, fields);
  std::pair<ShutterModel, ShutterModel> passes{ShutterModel::progressive(g1.open, g1.close, g1.shape), ShutterModel::progressive(g2.open, g2.close, g2.shape)};
  passes.first.setRolling(fields.rolling);
  passes.second.setRolling(fields.rolling);
  return passes;
}

void interlaceFields(RenderResult& first, const RenderResult& second, int firstFieldParity) {
  FlatImage& out = first.image;
  const FlatImage& src = second.image;
  CHECK(out.x0 == src.x0 && out.y0 == src.y0 && out.width == src.width && out.height == src.height, "the fields' data windows differ");
  CHECK(out.channels.size() == src.channels.size(), "the fields have ", out.channels.size(), " and ", src.channels.size(), " channels");
  const size_t W = size_t(out.width);
  for (size_t c = 0; c < out.channels.size(); ++c) {
    auto& dst = out.channels[c];
    const auto& from = src.channels[c];
    CHECK(dst.name == from.name && dst.f.size() == from.f.size() && dst.u.size() == from.u.size(), "channel ", dst.name, " differs between the fields");
    for (int y = 0; y < out.height; ++y) {
      if (!secondFieldRow(out.y0 + y, firstFieldParity)) continue;
      const size_t row = size_t(y) * W;
      if (!dst.f.empty()) std::copy(from.f.begin() + long(row), from.f.begin() + long(row + W), dst.f.begin() + long(row));
      if (!dst.u.empty()) std::copy(from.u.begin() + long(row), from.u.begin() + long(row + W), dst.u.begin() + long(row));
    }
  }
  // The deep image is rebuilt rather than patched: a pixel's samples are a run in one block, and
  // field 2's runs live in the other render's blocks. Block 0 holds field 1's rows, block 1 field 2's.
  const DeepImage& d1 = first.deep;
  const DeepImage& d2 = second.deep;
  CHECK((d1.width == 0) == (d2.width == 0), "one field has a deep image, the other not");
  if (d1.width != 0) {
    CHECK(d1.x0 == d2.x0 && d1.y0 == d2.y0 && d1.width == d2.width && d1.height == d2.height, "the fields' deep data windows differ");
    CHECK(d1.layout.nf() == d2.layout.nf() && d1.layout.nu() == d2.layout.nu(), "the fields' deep layouts differ");
    DeepImage woven;
    woven.reset(d1.x0, d1.y0, d1.width, d1.height, d1.fullWidth, d1.fullHeight, d1.layout, 2);
    woven.tidy = d1.tidy && d2.tidy;
    woven.objectNames = d1.objectNames;
    DeepPixel px;
    for (int y = d1.y0; y < d1.y0 + d1.height; ++y) {
      const bool inSecond = secondFieldRow(y, firstFieldParity);
      const DeepImage& from = inSecond ? d2 : d1;
      for (int x = d1.x0; x < d1.x0 + d1.width; ++x) {
        from.getPixel(x, y, px);
        woven.setPixel(inSecond ? 1 : 0, x, y, px);
      }
    }
    first.deep = std::move(woven);
  }
  first.provenance.shutter = "two-pass fields: " + first.provenance.shutter + " / " + second.provenance.shutter;
  first.provenance.shutterClose = second.provenance.shutterClose;
}

// ---------------------------------------------------------------------------------------------
// Frame-rate conversion

long double RateConversion::ratio() const {
  // A user's rate can reach here as 0/N (a decimal too small to write with six places), so this is
  // an Error, not a CHECK.
  if (!(from.num > 0 && from.den > 0 && to.num > 0 && to.den > 0))
    fail("rate conversion", "from ", from.num, "/", from.den, " to ", to.num, "/", to.den, " fps: both rates must be positive");
  return (static_cast<long double>(from.num) * to.den) / (static_cast<long double>(from.den) * to.num);
}

std::vector<OutputFrame> retimeFrames(const std::vector<int64_t>& frames, const RateConversion& conversion) {
  // One target frame lasts from/to source frames; output frame k's nominal time is k·from/to.
  const long double ratio = conversion.ratio();
  const double d = double(ratio);
  RollingShutter rolling = conversion.rolling;
  rolling.duration = conversion.rolling.duration * d;
  std::vector<OutputFrame> out;
  for (int64_t k : frames) {
    const double nominal = double(static_cast<long double>(k) * ratio);
    ShutterModel m = ShutterModel::progressive(nominal + conversion.open * d, nominal + conversion.close * d, conversion.shape);
    m.setRolling(rolling);
    out.push_back({k, m});
  }
  return out;
}

// ---------------------------------------------------------------------------------------------
// Sources

std::vector<Source> sourcesFor(store::ShotStores& shot, double t0, double t1) {
  std::vector<Source> sources;
  for (const store::FrameStore& s : shot.storesFor(t0, t1)) sources.push_back(Source{s.reader, s.frame});
  return sources;
}

void requireStores(store::ShotStores& shot, const std::vector<OutputFrame>& frames) {
  std::vector<int64_t> all;
  for (const auto& f : frames) {
    auto need = shot.framesFor(f.shutter.earliest(), f.shutter.latest());
    all.insert(all.end(), need.begin(), need.end());
  }
  std::sort(all.begin(), all.end());
  all.erase(std::unique(all.begin(), all.end()), all.end());
  shot.requireAll(all);
}

RenderSpec frameSpec(store::ShotStores& shot, const ShutterModel& shutter) {
  RenderSpec spec;
  spec.shutter = shutter;
  spec.sources = sourcesFor(shot, shutter.earliest(), shutter.latest());
  return spec;
}

}  // namespace reshutter::resample
