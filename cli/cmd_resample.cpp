// `reshutter resample`: one store, one shutter interval, one image.
#include <cmath>
#include <cstdio>

#include "cli/commands.h"
#include "cli/render_options.h"
#include "cli/shutter_options.h"
#include "common/error.h"
#include "common/log.h"
#include "store/reader.h"

namespace reshutter::cli {
namespace {

struct ResampleCommand {
  std::string input, output;
  ShutterOptions shutter;
  RenderOptions render;

  int run() const {
    if (output.empty() && render.deep.empty()) fail("resample", "nothing to write: give -o OUT.exr, --deep DEEP.exr or both");
    store::ReaderOptions ro;
    ro.cacheBytes = size_t(render.cacheMb * 1e6);
    auto reader = std::make_shared<const store::StoreReader>(input, ro);
    const auto& meta = reader->meta();
    double open, close;
    shutter.interval(open, close, meta.shutterOpen, meta.shutterClose);
    if (open < meta.shutterOpen - 1e-12 || close > meta.shutterClose + 1e-12)
      fail(shutter.shutter.empty() ? "--shutter-angle" : "--shutter", "the interval [", open, ", ", close, "] lies outside the store's shutter [",
           meta.shutterOpen, ", ", meta.shutterClose, "] (", input, "); intervals across frames need the neighbouring stores: see `reshutter retime`");
    render.checkOutputs(output, meta.frame);  // before the render, not after it
    resample::RenderSpec spec;
    spec.sources = {resample::Source{reader, meta.frame}};
    spec.shutter = resample::ShutterModel::progressive(double(meta.frame) + open, double(meta.frame) + close, shutter.parsedShape());
    shutter.applyRolling(spec.shutter, 1.0);
    render.applyTo(spec);
    resample::RenderResult result = resample::render(spec);
    render.writeOutputs(result, output, meta.frame);
    const auto& img = result.image;
    const std::string wrote = output.empty() ? render.deep : render.deep.empty() ? output : output + " and " + render.deep;
    note(cat("wrote ", wrote, ": ", img.width, "x", img.height, ", ", spec.samplesX * spec.samplesY, " spp, shutter [", open, ", ", close, "] in ",
             result.stats.wallSeconds, " s"));
    if (render.stats) std::printf("%s", result.stats.report().c_str());
    return 0;
  }
};

}  // namespace

void addResampleCommand(CLI::App& app, Registry& registry) {
  auto cmd = std::make_shared<ResampleCommand>();
  auto* sub = app.add_subcommand("resample", "Render a store for any shutter sub-interval into a flat OpenEXR, without re-shading");
  sub->add_option("store", cmd->input, "The .mps store")->required();
  sub->add_option("-o,--output", cmd->output, "Output OpenEXR (optional with --deep)");
  cmd->shutter.addTo(sub, true);
  cmd->render.addTo(sub);
  sub->footer(
      "Examples:\n"
      "  reshutter resample frame.mps -o full.exr                         # the whole dumped shutter\n"
      "  reshutter resample frame.mps -o field1.exr --shutter 0:0.25      # a quarter of it\n"
      "  reshutter resample frame.mps -o still.exr --shutter 0.5:0.5      # the instant at mid-frame\n"
      "  reshutter resample frame.mps -o aov.exr --aov N --aov id:zmin --spp 64 --filter catmull-rom\n"
      "  reshutter resample frame.mps -o out.exr --preview out.png --stats\n"
      "  reshutter resample frame.mps -o flat.exr --deep deep.exr         # flat and deep (docs/deep.md)");
  registry.add(sub, [cmd] { return cmd->run(); });
}

}  // namespace reshutter::cli
