// `reshutter fields` and `reshutter retime`: sequences re-timed from a shot's stores. Both build
// a shutter model per output frame (resample/shutter.h) and hand it, with the stores whose
// coverage it reaches, to the one re-sampler; neither is a renderer of its own.
#include <cmath>
#include <cstdio>
#include <numeric>

#include "cli/commands.h"
#include "cli/render_options.h"
#include "cli/shutter_options.h"
#include "common/error.h"
#include "common/frame_range.h"
#include "common/log.h"
#include "common/progress.h"
#include "store/shot.h"

namespace reshutter::cli {
namespace {

using resample::RenderResult;
using resample::RenderSpec;
using resample::ShutterGroup;
using resample::ShutterModel;

std::vector<resample::Source> sourcesFor(store::ShotStores& stores, double t0, double t1) {
  std::vector<resample::Source> sources;
  for (const store::FrameStore& s : stores.storesFor(t0, t1)) sources.push_back(resample::Source{s.reader, s.frame});
  return sources;
}

/// One output frame: its number and the shutter it is rendered with (absolute source frames).
struct OutputFrame {
  int64_t frame;
  ShutterModel shutter;
};

/// Renders a sequence: checks every store and output name first, then renders frame by frame
/// with a progress bar over frames.
int renderSequence(const std::string& storePattern, const std::string& outPattern, const std::vector<OutputFrame>& frames,
                   const RenderOptions& render, const std::string& what) {
  if (frames.empty()) fail("--frames", "no frames to render");
  if (outPattern.empty() && render.deep.empty()) fail(what, "nothing to write: give -o OUT.####.exr, --deep DEEP.####.exr or both");
  if (frames.size() > 1 && !outPattern.empty() && !hasFramePlaceholder(outPattern))
    fail("-o", "'", outPattern, "' has no frame placeholder (####, %04d, @) but ", frames.size(), " frames are rendered");
  if (frames.size() > 1 && !render.deep.empty() && !hasFramePlaceholder(render.deep))
    fail("--deep", "'", render.deep, "' has no frame placeholder (####, %04d, @) but ", frames.size(), " frames are rendered");
  store::ShotStores stores(storePattern, size_t(render.cacheMb * 1e6));
  // Every store any frame needs, checked before any work.
  {
    std::vector<int64_t> all;
    for (const auto& f : frames) {
      auto need = stores.framesFor(f.shutter.earliest(), f.shutter.latest());
      all.insert(all.end(), need.begin(), need.end());
    }
    std::sort(all.begin(), all.end());
    all.erase(std::unique(all.begin(), all.end()), all.end());
    stores.requireAll(all);
  }
  for (const auto& f : frames) render.checkOutputs(outPattern.empty() ? "" : expandFramePattern(outPattern, f.frame), f.frame);
  Progress progress(what, frames.size());
  double seconds = 0;
  for (const auto& f : frames) {
    RenderSpec spec;
    spec.shutter = f.shutter;
    spec.sources = sourcesFor(stores, f.shutter.earliest(), f.shutter.latest());
    render.applyTo(spec);
    spec.progress = frames.size() == 1;
    RenderResult result = resample::render(spec);
    result.provenance.frame = f.frame;
    render.writeOutputs(result, outPattern.empty() ? "" : expandFramePattern(outPattern, f.frame), f.frame);
    seconds += result.stats.wallSeconds;
    if (render.stats) std::printf("frame %lld\n%s", static_cast<long long>(f.frame), result.stats.report().c_str());
    progress.advance();
  }
  progress.finish();
  const std::string wrote = outPattern.empty() ? render.deep : render.deep.empty() ? outPattern : outPattern + " and " + render.deep;
  note(cat("wrote ", frames.size(), " frame", frames.size() == 1 ? "" : "s", " (", wrote, ") in ", seconds, " s"));
  return 0;
}

struct FieldsCommand {
  std::string input, output, frames;
  std::string dominance = "upper";
  double fieldAngle = 180;
  std::string fieldShutter;
  std::string position = "start";
  bool twoPass = false;
  ShutterOptions shutter;
  RenderOptions render;

  // Field intervals of frame N (absolute source frames): field 1's nominal time is N, field 2's
  // N + 1/2; each is open for the field shutter (in field durations, 1/2 frame).
  std::pair<ShutterGroup, ShutterGroup> fieldGroups(int64_t frame) const {
    double a = 0, b = fieldAngle / 360.0;
    if (!fieldShutter.empty()) {
      parseInterval(fieldShutter, "--field-shutter", a, b);
    } else if (position == "center") {
      a = -b / 2, b = b / 2;
    } else if (position == "end") {
      a = -b, b = 0;
    }
    const double F = double(frame), d = 0.5;
    auto shape = shutter.parsedShape();
    return {ShutterGroup{F + a * d, F + b * d, shape}, ShutterGroup{F + d + a * d, F + d + b * d, shape}};
  }

  int run() const {
    std::vector<int64_t> list = parseFrameRange(frames, "--frames");
    if (output.empty() && render.deep.empty()) fail("fields", "nothing to write: give -o OUT.####.exr, --deep DEEP.####.exr or both");
    const int parity = dominance == "upper" ? 0 : 1;
    if (!twoPass) {
      std::vector<OutputFrame> out;
      for (int64_t f : list) {
        auto [g1, g2] = fieldGroups(f);
        ShutterModel m = ShutterModel::fields(g1, g2, parity);
        shutter.applyRolling(m, 1.0);
        out.push_back({f, m});
      }
      return renderSequence(input, output, out, render, "fields");
    }
    // The reference semantics: two full progressive renders, rows interlaced afterwards.
    for (int64_t f : list) render.checkOutputs(output.empty() ? "" : expandFramePattern(output, f), f);
    store::ShotStores stores(input, size_t(render.cacheMb * 1e6));
    Progress progress("fields (two-pass)", list.size());
    for (int64_t f : list) {
      auto [g1, g2] = fieldGroups(f);
      RenderResult fields[2];
      int k = 0;
      for (const ShutterGroup& g : {g1, g2}) {
        RenderSpec spec;
        spec.shutter = ShutterModel::progressive(g.open, g.close, g.shape);
        shutter.applyRolling(spec.shutter, 1.0);
        spec.sources = sourcesFor(stores, spec.shutter.earliest(), spec.shutter.latest());
        render.applyTo(spec);
        spec.progress = false;
        fields[k++] = resample::render(spec);
      }
      RenderResult& out = fields[0];
      for (size_t c = 0; c < out.image.channels.size(); ++c) {
        auto& dst = out.image.channels[c];
        const auto& src = fields[1].image.channels[c];
        for (int y = 0; y < out.image.height; ++y) {
          if (((out.image.y0 + y - parity) % 2 + 2) % 2 == 0) continue;  // a first-field row
          const size_t row = size_t(y) * out.image.width;
          if (!dst.f.empty()) std::copy(src.f.begin() + long(row), src.f.begin() + long(row + out.image.width), dst.f.begin() + long(row));
          if (!dst.u.empty()) std::copy(src.u.begin() + long(row), src.u.begin() + long(row + out.image.width), dst.u.begin() + long(row));
        }
      }
      out.provenance.frame = f;
      out.provenance.shutter = "two-pass fields: " + out.provenance.shutter + " / " + fields[1].provenance.shutter;
      out.provenance.shutterClose = fields[1].provenance.shutterClose;
      render.writeOutputs(out, output.empty() ? "" : expandFramePattern(output, f), f);
      if (render.stats)
        std::printf("frame %lld, field 1\n%sframe %lld, field 2\n%s", static_cast<long long>(f), fields[0].stats.report().c_str(),
                    static_cast<long long>(f), fields[1].stats.report().c_str());
      progress.advance();
    }
    return 0;
  }
};

struct RetimeCommand {
  std::string input, output, frames;
  std::string fromFps, toFps;
  ShutterOptions shutter;
  RenderOptions render;

  int run() const {
    std::vector<int64_t> list = parseFrameRange(frames, "--frames");
    store::Rational from{0, 1}, to{0, 1};
    if (!parseRational(toFps, to)) fail("--to-fps", "expected a rate like 25, 30000/1001 or 29.97, got '", toFps, "'");
    if (fromFps.empty()) {
      // The shot's own rate, from its first store.
      store::ShotStores probe(input, 0);
      const double near = double(list.front()) * 1.0;  // a guess good enough to find a store
      from = probe.firstMeta(near).fps;
    } else if (!parseRational(fromFps, from)) {
      fail("--from-fps", "expected a rate like 24, 24000/1001 or 23.976, got '", fromFps, "'");
    }
    // One target frame lasts from/to source frames; output frame k's nominal time is k·from/to.
    const long double ratio = (static_cast<long double>(from.num) * to.den) / (static_cast<long double>(from.den) * to.num);
    const double d = double(ratio);
    double a, b;
    shutter.interval(a, b, 0.0, 0.5);  // default: a 180° shutter opening on the nominal time
    std::vector<OutputFrame> out;
    for (int64_t k : list) {
      const double nominal = double(static_cast<long double>(k) * ratio);
      ShutterModel m = ShutterModel::progressive(nominal + a * d, nominal + b * d, shutter.parsedShape());
      shutter.applyRolling(m, d);
      out.push_back({k, m});
    }
    return renderSequence(input, output, out, render, "retime");
  }
};

}  // namespace

void addRetimeCommands(CLI::App& app, Registry& registry) {
  {
    auto cmd = std::make_shared<FieldsCommand>();
    auto* sub = app.add_subcommand("fields", "Interlaced video: each output frame's two fields from their own shutter intervals, in one pass");
    sub->add_option("stores", cmd->input, "The shot's stores, e.g. shot.####.mps")->required();
    sub->add_option("-o,--output", cmd->output, "Output OpenEXR pattern, e.g. out.####.exr (optional with --deep)");
    sub->add_option("--frames", cmd->frames, "Frames: 1-48, 1-48x2, 1,5,9, ...")->required();
    sub->add_option("--dominance", cmd->dominance, "Field dominance: upper (row 0 is in the first field) or lower")
        ->check(CLI::IsMember({"upper", "lower"}))
        ->capture_default_str()
        ->group("Shutter");
    auto* angle = sub->add_option("--field-shutter-angle", cmd->fieldAngle, "Shutter angle of each field, degrees of a field duration")
                      ->check(CLI::Range(0.0, 360.0))
                      ->capture_default_str()
                      ->group("Shutter");
    sub->add_option("--field-shutter", cmd->fieldShutter, "Each field's interval OPEN:CLOSE relative to its nominal time, in field durations")
        ->excludes(angle)
        ->group("Shutter");
    sub->add_option("--shutter-position", cmd->position, "Where each field's shutter sits on its nominal time: start, center, end")
        ->check(CLI::IsMember({"start", "center", "end"}))
        ->capture_default_str()
        ->group("Shutter");
    sub->add_flag("--two-pass", cmd->twoPass, "Render each field as a full frame and interlace (the reference; twice the work)")
        ->group("Shutter");
    cmd->shutter.addTo(sub, false);
    cmd->render.addTo(sub);
    sub->footer(
        "Field 1 of frame N is nominally at N, field 2 at N + 1/2 (frames). With the default 180-degree\n"
        "field shutter they expose [N, N+0.25] and [N+0.5, N+0.75], the reference workflow's intervals.\n"
        "Each output row samples only its own field's interval. With a filter no taller than one row\n"
        "(e.g. --filter gaussian:2x1) the result is bit-identical to --two-pass; taller filters blend\n"
        "neighbouring rows, which belong to the other field.\n\n"
        "Examples:\n"
        "  reshutter fields shot.####.mps --frames 1-48 -o ntsc.####.exr\n"
        "  reshutter fields shot.####.mps --frames 1-48 --dominance lower --field-shutter-angle 360 -o pal.%04d.exr");
    registry.add(sub, [cmd] { return cmd->run(); });
  }
  {
    auto cmd = std::make_shared<RetimeCommand>();
    auto* sub = app.add_subcommand("retime", "Frame-rate conversion: render another rate's frames from a shot's stores");
    sub->add_option("stores", cmd->input, "The shot's stores, e.g. shot.####.mps")->required();
    sub->add_option("-o,--output", cmd->output, "Output OpenEXR pattern, e.g. out.####.exr (optional with --deep)");
    sub->add_option("--frames", cmd->frames, "Output frames: 1-100, 1-100x2, 1,5,9, ...")->required();
    sub->add_option("--from-fps", cmd->fromFps, "The shot's rate (default: the stores' own)")->group("Shutter");
    sub->add_option("--to-fps", cmd->toFps, "Target rate: 25, 30, 30000/1001, 29.97, 50, 59.94, ...")->required()->group("Shutter");
    cmd->shutter.addTo(sub, true);
    cmd->render.addTo(sub);
    sub->footer(
        "Output frame k is nominally at k * from/to source frames; its shutter (default 180 degrees, opening\n"
        "at the nominal time) is measured in target frames. An interval that spans two source frames\n"
        "uses both stores; a time no store covers is an error naming it.\n\n"
        "Examples:\n"
        "  reshutter retime shot.####.mps --to-fps 30000/1001 --frames 1-120 -o ntsc.####.exr\n"
        "  reshutter retime shot.####.mps --from-fps 24 --to-fps 50 --shutter-angle 90 --frames 1-100 -o out.%04d.exr\n"
        "  reshutter retime shot.####.mps --to-fps 25 --shutter-angle 180 --shutter-position center --rolling-shutter 0.5 --frames 1-10 -o cmos.####.exr");
    registry.add(sub, [cmd] { return cmd->run(); });
  }
}

}  // namespace reshutter::cli
