// `reshutter fields` and `reshutter retime`: sequences re-timed from a shot's stores. The commands
// only read options and write files; the shutter of each output frame, the stores it reaches and
// the two-pass interlace are the library's (resample/retime.h, store/shot.h), and every frame is
// rendered by the one re-sampler.
#include <cstdio>
#include <tuple>

#include "cli/commands.h"
#include "cli/render_options.h"
#include "cli/shutter_options.h"
#include "common/error.h"
#include "common/frame_range.h"
#include "common/log.h"
#include "common/progress.h"
#include "resample/retime.h"
#include "store/shot.h"

namespace reshutter::cli {
namespace {

using resample::OutputFrame;
using resample::RenderResult;
using resample::RenderSpec;

/// Checks a sequence before any work, so that a bad one writes nothing: something to write, a
/// frame placeholder where several frames are written, every store any of `shutters` reaches, and
/// every output name of `frameNumbers`.
void checkSequence(store::ShotStores& stores, const std::string& outPattern, const std::vector<int64_t>& frameNumbers, const std::vector<OutputFrame>& shutters,
                   const RenderOptions& render, const std::string& what) {
  if (frameNumbers.empty()) fail("--frames", "no frames to render");
  if (outPattern.empty() && render.deep.empty()) fail(what, "nothing to write: give -o OUT.####.exr, --deep DEEP.####.exr or both");
  const size_t n = frameNumbers.size();
  if (n > 1 && !outPattern.empty() && !hasFramePlaceholder(outPattern))
    fail("-o", "'", outPattern, "' has no frame placeholder (####, %04d, @) but ", n, " frames are rendered");
  if (n > 1 && !render.deep.empty() && !hasFramePlaceholder(render.deep))
    fail("--deep", "'", render.deep, "' has no frame placeholder (####, %04d, @) but ", n, " frames are rendered");
  resample::requireStores(stores, shutters);  // every store any frame needs
  for (int64_t f : frameNumbers) render.checkOutputs(outPattern.empty() ? "" : expandFramePattern(outPattern, f), f);
}

void noteWritten(const std::string& outPattern, const RenderOptions& render, size_t frames, double seconds) {
  const std::string wrote = outPattern.empty() ? render.deep : render.deep.empty() ? outPattern : outPattern + " and " + render.deep;
  note(cat("wrote ", frames, " frame", frames == 1 ? "" : "s", " (", wrote, ") in ", seconds, " s"));
}

/// The render of frames[i]: its shutter's stores and the command's options, with the stores
/// frames[i + 1] reads kept decoded for it (RenderSpec::keepDecoded).
RenderSpec specOf(store::ShotStores& stores, const std::vector<OutputFrame>& frames, size_t i, const RenderOptions& render) {
  RenderSpec spec = resample::frameSpec(stores, frames[i].shutter);
  render.applyTo(spec);
  if (i + 1 < frames.size())
    for (const auto& src : resample::frameSpec(stores, frames[i + 1].shutter).sources) spec.keepDecoded.push_back(src.store.get());
  return spec;
}

/// Renders a sequence: checks every store and output name first, then renders frame by frame
/// with a progress bar over frames.
int renderSequence(const std::string& storePattern, const std::string& outPattern, const std::vector<OutputFrame>& frames, const RenderOptions& render,
                   const std::string& what) {
  store::ShotStores stores(storePattern, size_t(render.cacheMb * 1e6));
  std::vector<int64_t> numbers;
  for (const auto& f : frames) numbers.push_back(f.frame);
  checkSequence(stores, outPattern, numbers, frames, render, what);
  Progress progress(what, frames.size());
  double seconds = 0;
  for (size_t i = 0; i < frames.size(); ++i) {
    const OutputFrame& f = frames[i];
    RenderSpec spec = specOf(stores, frames, i, render);
    spec.progress = frames.size() == 1;
    std::vector<RenderOptions::View> views = render.renderViews(spec);
    for (RenderOptions::View& v : views) {
      v.result.provenance.frame = f.frame;
      seconds += v.result.stats.wallSeconds;
      if (render.stats)
        std::printf("frame %lld%s\n%s", static_cast<long long>(f.frame), v.name.empty() ? "" : (", view " + v.name).c_str(), v.result.stats.report().c_str());
    }
    render.writeViews(views, outPattern.empty() ? "" : expandFramePattern(outPattern, f.frame), f.frame);
    progress.advance();
  }
  progress.finish();
  noteWritten(outPattern, render, frames.size(), seconds);
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

  resample::FieldShutter fields() const {
    resample::FieldShutter fs;
    fs.firstFieldParity = resample::parseDominance(dominance, "--dominance");
    if (!fieldShutter.empty()) parseInterval(fieldShutter, "--field-shutter", fs.open, fs.close);
    else std::tie(fs.open, fs.close) = resample::angleInterval(fieldAngle, resample::parseShutterPosition(position, "--shutter-position"));
    fs.shape = shutter.parsedShape();
    fs.rolling = shutter.rollingShutter();  // one frame's read-out: target frames are source frames
    return fs;
  }

  int run(const SequenceHook& hook) const {
    std::vector<int64_t> list = parseFrameRange(frames, "--frames");
    if (output.empty() && render.deep.empty()) fail("fields", "nothing to write: give -o OUT.####.exr, --deep DEEP.####.exr or both");
    if (hook) {  // the job's stores are checked before it is submitted, not on the farm
      store::ShotStores stores(input, 0);
      resample::requireStores(stores, resample::fieldFrames(list, fields()));
      return hook({"fields", input, list, output, &render});
    }
    if (!twoPass) return renderSequence(input, output, resample::fieldFrames(list, fields()), render, "fields");
    // The reference semantics: two full progressive renders, rows interlaced afterwards.
    const resample::FieldShutter fs = fields();
    std::vector<OutputFrame> passes;
    for (int64_t f : list) {
      auto [first, second] = resample::fieldPassShutters(f, fs);
      passes.push_back({f, std::move(first)}), passes.push_back({f, std::move(second)});
    }
    store::ShotStores stores(input, size_t(render.cacheMb * 1e6));
    checkSequence(stores, output, list, passes, render, "fields");
    Progress progress("fields (two-pass)", list.size());
    double seconds = 0;
    for (size_t i = 0; i < list.size(); ++i) {
      const int64_t f = list[i];
      // Each view (the store's own camera when none is asked for): two fields, interlaced.
      const std::vector<store::Camera> cams = render.viewCameras(specOf(stores, passes, 2 * i, render).sources.at(0).store->meta());
      std::vector<RenderOptions::View> views;
      for (size_t v = 0; v < std::max<size_t>(1, cams.size()); ++v) {
        RenderResult field[2];
        for (size_t k = 0; k < 2; ++k) {
          RenderSpec spec = specOf(stores, passes, 2 * i + k, render);
          spec.progress = false;
          if (!cams.empty()) spec.camera = cams[v];
          field[k] = resample::render(spec);
        }
        seconds += field[0].stats.wallSeconds + field[1].stats.wallSeconds;
        if (render.stats)
          std::printf("frame %lld, field 1\n%sframe %lld, field 2\n%s", static_cast<long long>(f), field[0].stats.report().c_str(), static_cast<long long>(f),
                      field[1].stats.report().c_str());
        resample::interlaceFields(field[0], field[1], fs.firstFieldParity);
        field[0].provenance.frame = f;
        views.push_back({cams.empty() ? "" : cams[v].name, std::move(field[0])});
      }
      render.writeViews(views, output.empty() ? "" : expandFramePattern(output, f), f);
      progress.advance();
    }
    progress.finish();
    noteWritten(output, render, list.size(), seconds);
    return 0;
  }
};

struct RetimeCommand {
  std::string input, output, frames;
  std::string fromFps, toFps;
  ShutterOptions shutter;
  RenderOptions render;

  int run(const SequenceHook& hook) const {
    std::vector<int64_t> list = parseFrameRange(frames, "--frames");
    resample::RateConversion rc;
    if (!store::parseRational(toFps, rc.to)) fail("--to-fps", "expected a rate like 25, 30000/1001 or 29.97, got '", toFps, "'");
    if (fromFps.empty()) {
      // The shot's own rate, from its first store.
      store::ShotStores probe(input, 0);
      const double near = double(list.front()) * 1.0;  // a guess good enough to find a store
      rc.from = probe.firstMeta(near).fps;
    } else if (!store::parseRational(fromFps, rc.from)) {
      fail("--from-fps", "expected a rate like 24, 24000/1001 or 23.976, got '", fromFps, "'");
    }
    shutter.interval(rc.open, rc.close, 0.0, 0.5);  // default: a 180° shutter opening on the nominal time
    rc.shape = shutter.parsedShape();
    rc.rolling = shutter.rollingShutter();
    if (hook) {  // the job's stores are checked before it is submitted, not on the farm
      store::ShotStores stores(input, 0);
      resample::requireStores(stores, resample::retimeFrames(list, rc));
      return hook({"retime", input, list, output, &render});
    }
    return renderSequence(input, output, resample::retimeFrames(list, rc), render, "retime");
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
    sub->add_flag("--two-pass", cmd->twoPass, "Render each field as a full frame and interlace (the reference; twice the work)")->group("Shutter");
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
    registry.add(sub, [cmd, hook = registry.sequenceHook] { return cmd->run(hook); });
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
    registry.add(sub, [cmd, hook = registry.sequenceHook] { return cmd->run(hook); });
  }
}

}  // namespace reshutter::cli
