// `reshutter demo`: the main job on built-in content, no files needed. Shades the built-in demo
// scene (shade/demo_scene.h) once into a store, re-samples that store into a progressive frame
// (flat and deep OpenEXR, PNG preview, with a procedural smoke volume added at re-sample time)
// and an interlaced frame (two fields, one pass, no re-shading), and reports where the outputs are
// and how long each stage took.
#include <chrono>
#include <cstdio>
#include <filesystem>

#include "cli/commands.h"
#include "cli/render_options.h"
#include "common/error.h"
#include "resample/volume.h"
#include "shade/demo_scene.h"
#include "shade/shading_pass.h"
#include "store/reader.h"

namespace reshutter::cli {
namespace {

// World position of the demo's smoke puff: in front of the objects, left of centre.
constexpr double kSmokeCentre[3] = {-2.2, 1.1, 1.2};

struct DemoCommand {
  std::string outDir = "demo-output";
  std::vector<int> res{shade::kDemoWidth, shade::kDemoHeight};

  int run() const {
    if (res.size() != 2 || res[0] <= 0 || res[1] <= 0 || res[0] > 16384 || res[1] > 16384) fail("--res", "expected a width and a height, e.g. --res 1920 1080");
    std::error_code ec;
    std::filesystem::create_directories(outDir, ec);
    if (ec) fail(outDir, "cannot create the output directory: ", ec.message());
    const std::string storePath = outDir + "/demo.mps";

    shade::FrameScene frame = shade::demoFrame(res[0], res[1]);
    // Shaded in time (5 times, so the fields' ends are among them): the spinning cube and tumbling
    // torus are lit as at each field's own time, not both fields as at the frame's open
    // (docs/accuracy.md measures the difference).
    shade::ShadeOptions options;
    options.timeTolerance = 0.01;
    shade::StoreResult r = shade::shadeToStore(frame, options, storePath);

    std::printf("reshutter demo (%dx%d)\n", res[0], res[1]);
    std::printf("  store     %s\n", storePath.c_str());
    std::printf("            %s micropolygons in %s grids (%s moving), %s (%.1f bytes/micropolygon)\n", grouped(r.shade.micropolygons).c_str(),
                grouped(r.shade.grids).c_str(), grouped(r.shade.movingGrids).c_str(), humanBytes(double(r.write.fileBytes)).c_str(),
                r.shade.micropolygons ? double(r.write.fileBytes) / double(r.shade.micropolygons) : 0.0);
    std::printf("  shading   %.2f s (one pass, every motion knot kept; %s of %s grids whose lighting changes over the shutter shaded at %zu times)\n",
                r.shade.seconds, grouped(r.shade.timedGrids).c_str(), grouped(r.shade.timeCandidateGrids).c_str(), r.shade.shadingTimes.size());

    // A puff of smoke made now, added at re-sample time: lit by the lights the store recorded,
    // cut by the surfaces, kept as volume samples in the deep image.
    const std::string smokePath = outDir + "/smoke.vdb";
    resample::SmokePuff puff;
    puff.centre = {kSmokeCentre[0], kSmokeCentre[1], kSmokeCentre[2]}, puff.radius = 0.75, puff.voxelSize = 0.04;
    resample::writeSmokePuff(smokePath, puff);

    // Re-sample the one shading pass: no shading from here on.
    auto reader = std::make_shared<const store::StoreReader>(storePath);
    const auto& meta = reader->meta();
    const double F = double(meta.frame);
    // readAgain: the next render reads this store too, so its decoded parts stay cached.
    auto renderWith = [&](resample::ShutterModel shutter, const std::string& filter, const std::string& name, bool deep, bool readAgain) {
      RenderOptions o;
      o.spp = "16";
      o.filter = filter;
      if (deep) o.volumes = {smokePath + ",density-scale=3,albedo=0.9:0.9:0.9"};
      o.previews = {outDir + "/" + name + ".png"};
      if (deep) o.deep = outDir + "/" + name + "_deep.exr";
      resample::RenderSpec spec;
      spec.sources = {resample::Source{reader, meta.frame}};
      spec.shutter = std::move(shutter);
      o.applyTo(spec);
      if (readAgain) spec.keepDecoded = {reader.get()};
      resample::RenderResult result = resample::render(spec);
      o.writeOutputs(result, outDir + "/" + name + ".exr", meta.frame);
      return result.stats.wallSeconds;
    };
    const double progressive =
        renderWith(resample::ShutterModel::progressive(F + meta.shutterOpen, F + meta.shutterClose), "gaussian:2x2", "progressive", true, true);
    // The reference workflow's fields: Shutter 0 0.25 and 0.5 0.75 of the frame, rows alternating.
    const double interlaced = renderWith(resample::ShutterModel::fields(resample::ShutterGroup{F, F + 0.25}, resample::ShutterGroup{F + 0.5, F + 0.75}, 0),
                                         "gaussian:2x1", "interlaced", false, false);
    std::printf("  resample  progressive frame [%g, %g] with a smoke volume (%s): %.2f s -> %s/progressive.exr, progressive_deep.exr, progressive.png\n",
                meta.shutterOpen, meta.shutterClose, smokePath.c_str(), progressive, outDir.c_str());
    std::printf("            interlaced frame, fields [0, 0.25] + [0.5, 0.75], one pass: %.2f s -> %s/interlaced.exr, interlaced.png\n", interlaced,
                outDir.c_str());
    std::printf("  next      reshutter info %s\n", storePath.c_str());
    std::printf("            reshutter resample %s --shutter 0.25:0.5 -o quarter.exr --preview quarter.png\n", storePath.c_str());
    return 0;
  }
};

}  // namespace

void addDemoCommand(CLI::App& app, Registry& registry) {
  auto cmd = std::make_shared<DemoCommand>();
  auto* sub = app.add_subcommand("demo", "Run the main job on built-in content (no input files needed)");
  sub->add_option("-o,--output", cmd->outDir, "Directory for the outputs")->capture_default_str();
  sub->add_option("--res", cmd->res, "Resolution W H of the demo (e.g. 1920 1080)")->expected(2)->capture_default_str();
  registry.add(sub, [cmd] { return cmd->run(); });
}

}  // namespace reshutter::cli
