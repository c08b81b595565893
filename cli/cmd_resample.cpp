// `reshutter resample`: one store, one shutter interval, one image (or each frame of a shot from its
// own store, with --frames).
#include <cmath>
#include <cstdio>

#include "cli/commands.h"
#include "cli/render_options.h"
#include "cli/shutter_options.h"
#include "common/error.h"
#include "common/frame_range.h"
#include "common/log.h"
#include "common/progress.h"
#include "store/reader.h"

namespace reshutter::cli {
namespace {

struct ResampleCommand {
  std::string input, output, frames;
  ShutterOptions shutter;
  RenderOptions render;

  int run(const SequenceHook& hook) const {
    if (output.empty() && render.deep.empty()) fail("resample", "nothing to write: give -o OUT.exr, --deep DEEP.exr or both");
    if (frames.empty()) {
      if (hasFramePlaceholder(input)) fail("--frames", "'", input, "' is a store pattern: say which frames to render, e.g. --frames 1-100");
      if (hook) {
        store::ReaderOptions ro;
        ro.cacheBytes = 0;
        return hook({"resample", input, {store::StoreReader(input, ro).meta().frame}, output, &render});
      }
      renderOne(input, nullptr, output, render.deep);
      return 0;
    }
    // A shot: each frame from its own store, into its own outputs.
    const std::vector<int64_t> list = parseFrameRange(frames, "--frames");
    for (const auto& [pattern, what] : {std::pair{input, "store"}, {output, "-o"}, {render.deep, "--deep"}})
      if (list.size() > 1 && !pattern.empty() && !hasFramePlaceholder(pattern))
        fail(what, "'", pattern, "' has no frame placeholder (####, %04d, @) but ", list.size(), " frames are rendered");
    if (hook) return hook({"resample", input, list, output, &render});
    for (int64_t f : list) render.checkOutputs(output.empty() ? "" : expandFramePattern(output, f), f);
    Progress progress("resample", list.size());
    for (int64_t f : list) {
      renderOne(expandFramePattern(input, f), &f, output.empty() ? "" : expandFramePattern(output, f),
                render.deep.empty() ? "" : expandFramePattern(render.deep, f));
      progress.advance();
    }
    progress.finish();
    return 0;
  }

  // Renders store `path` (which must hold `frame` when one is given) into `out` and `deepOut`.
  void renderOne(const std::string& path, const int64_t* frame, const std::string& out, const std::string& deepOut) const {
    store::ReaderOptions ro;
    ro.cacheBytes = size_t(render.cacheMb * 1e6);
    auto reader = std::make_shared<const store::StoreReader>(path, ro);
    const auto& meta = reader->meta();
    if (frame && meta.frame != *frame) fail(path, "holds frame ", meta.frame, ", not frame ", *frame, " (--frames)");
    double open, close;
    shutter.interval(open, close, meta.shutterOpen, meta.shutterClose);
    if (open < meta.shutterOpen - 1e-12 || close > meta.shutterClose + 1e-12)
      fail(shutter.shutter.empty() ? "--shutter-angle" : "--shutter", "the interval [", open, ", ", close, "] lies outside the store's shutter [",
           meta.shutterOpen, ", ", meta.shutterClose, "] (", path, "); intervals across frames need the neighbouring stores: see `reshutter retime`");
    RenderOptions opts = render;
    opts.deep = deepOut;
    opts.checkOutputs(out, meta.frame);  // before the render, not after it
    resample::RenderSpec spec;
    spec.sources = {resample::Source{reader, meta.frame}};
    spec.shutter = resample::ShutterModel::progressive(double(meta.frame) + open, double(meta.frame) + close, shutter.parsedShape());
    shutter.applyRolling(spec.shutter, 1.0);
    opts.applyTo(spec);
    spec.progress = frame == nullptr;
    const std::vector<RenderOptions::View> views = opts.renderViews(spec);
    opts.writeViews(views, out, meta.frame);
    const resample::RenderResult& result = views[0].result;
    const auto& img = result.image;
    const std::string wrote = out.empty() ? deepOut : deepOut.empty() ? out : out + " and " + deepOut;
    note(cat("wrote ", wrote, ": ", img.width, "x", img.height, ", ", spec.samplesX * spec.samplesY, " spp, shutter [", open, ", ", close, "] in ",
             result.stats.wallSeconds, " s", views.size() > 1 ? cat(" (first of ", views.size(), " views)") : std::string()));
    if (render.stats)
      for (const auto& v : views) std::printf("%s%s", v.name.empty() ? "" : ("view " + v.name + ":\n").c_str(), v.result.stats.report().c_str());
  }
};

}  // namespace

void addResampleCommand(CLI::App& app, Registry& registry) {
  auto cmd = std::make_shared<ResampleCommand>();
  auto* sub = app.add_subcommand("resample", "Render a store for any shutter sub-interval into a flat OpenEXR, without re-shading");
  sub->add_option("store", cmd->input, "The .mps store")->required();
  sub->add_option("-o,--output", cmd->output, "Output OpenEXR (optional with --deep); a pattern such as out.####.exr with --frames");
  sub->add_option("--frames", cmd->frames, "Render these frames of a shot, each from its own store (the store argument is then a pattern, e.g. shot.####.mps)");
  cmd->shutter.addTo(sub, true);
  cmd->render.addTo(sub);
  sub->footer(
      "Examples:\n"
      "  reshutter resample frame.mps -o full.exr                         # the whole dumped shutter\n"
      "  reshutter resample frame.mps -o field1.exr --shutter 0:0.25      # a quarter of it\n"
      "  reshutter resample frame.mps -o still.exr --shutter 0.5:0.5      # the instant at mid-frame\n"
      "  reshutter resample frame.mps -o aov.exr --aov N --aov id:zmin --spp 64 --filter catmull-rom\n"
      "  reshutter resample frame.mps -o out.exr --preview out.png --stats\n"
      "  reshutter resample frame.mps -o flat.exr --deep deep.exr         # flat and deep (docs/deep.md)\n"
      "  reshutter resample dof.mps -o far.exr --focus-distance 3.2 --fstop 1.4   # re-focus a frame shaded with DepthOfField\n"
      "  reshutter resample frame.mps -o right.exr --camera right             # from a camera the RIB recorded (Camera \"right\")\n"
      "  reshutter resample frame.mps -o stereo.exr --stereo 0.065:4          # a stereo pair, one multi-view OpenEXR (left, right)\n"
      "  reshutter resample frame.mps -o wide.exr --look-from 3,1,-6 --look-at 0,0,0 --fov 50   # a camera given after the fact\n"
      "  reshutter resample frame.mps -o dolly.exr --look-from 0,0,-1,0,0,-0.5 --look-at 0,0,1   # a camera dollying in over the shutter\n"
      "  reshutter resample frame.mps -o witness.exr --camera-rib witness.rib --stats   # the camera a RIB snippet describes (MotionBegin: moving)\n"
      "  reshutter resample shot.####.mps --frames 1-100 --shutter 0:0.25 -o quarter.####.exr   # every frame of a shot");
  registry.add(sub, [cmd, hook = registry.sequenceHook] { return cmd->run(hook); });
}

}  // namespace reshutter::cli
