// `reshutter ingest`: a RIB micropolygon dump (the "Cheap Field Rendering" workflow) into a store.
#include <cstdio>
#include <filesystem>
#include <memory>

#include "cli/commands.h"
#include "common/error.h"
#include "common/log.h"
#include "common/progress.h"
#include "shade/ingest.h"

namespace reshutter::cli {

namespace {

struct IngestCommand {
  std::string input, output;
  int64_t frame = 0;
  bool frameGiven = false;
  std::string fps = "24";
  int zstdLevel = 3;
  double memoryMb = 64;

  int run() const {
    shade::IngestOptions opt;
    if (frameGiven) opt.frame = frame;
    if (!store::parseRational(fps, opt.fps)) fail("--fps", "expected a frame rate like 24, 29.97 or 30000/1001, got '", fps, "'");
    opt.writer.zstdLevel = zstdLevel;
    opt.writer.memoryBudget = size_t(memoryMb * 1e6);
    std::error_code ec;
    const uint64_t fileBytes = std::filesystem::file_size(input, ec);
    if (ec) fail(input, "cannot open: ", ec.message());
    // A gzipped dump's decompressed size is unknown up front: its bar fills early and waits.
    std::unique_ptr<Progress> bar;
    int barPass = 0;
    uint64_t last = 0;
    opt.progress = [&](int pass, uint64_t bytes) {
      if (!Progress::enabledForTerminal()) return;
      if (pass != barPass) {
        bar = std::make_unique<Progress>(pass == 1 ? "ingest: scan" : "ingest: write", fileBytes);
        barPass = pass;
        last = 0;
      }
      bar->advance(std::min(bytes, fileBytes) - std::min(last, fileBytes));
      last = bytes;
    };
    shade::IngestStats st = shade::ingestDump(input, output, opt);
    if (bar) bar->finish();
    const double secs = st.scanSeconds + st.ingestSeconds;
    note(cat("wrote ", output, ": ", grouped(st.micropolygons), " micropolygons (", grouped(st.quads), " quads, ", grouped(st.triangles), " triangles; ",
             grouped(st.movingMicropolygons), " moving",
             st.write.stillMicropolygons ? cat(", ", grouped(st.write.stillMicropolygons), " with equal knots stored static") : std::string(), ") from ",
             grouped(st.primitives), " primitives, ", humanBytes(double(st.write.fileBytes)), " (", humanBytes(double(fileBytes)), " RIB, ",
             humanBytes(double(st.ribBytes)), " decompressed) in ", secs, " s"));
    if (st.fannedPolygons || st.earClippedPolygons)
      note(cat("split ", grouped(st.fannedPolygons), " convex polygons into quads and triangulated ", grouped(st.earClippedPolygons), " non-convex ones"));
    return 0;
  }
};

}  // namespace

void addIngestCommand(CLI::App& app, Registry& registry) {
  auto cmd = std::make_shared<IngestCommand>();
  auto* sub = app.add_subcommand("ingest", "Read a RIB micropolygon dump (shaded, moving PointsPolygons) into a store, without shading");
  sub->add_option("dump", cmd->input, "RIB dump: ASCII or binary, plain or gzipped (detected by content)")->required();
  sub->add_option("-o,--output", cmd->output, "Output .mps store (written atomically)")->required();
  sub->add_option("--frame", cmd->frame, "Frame number of the store; with several FrameBegin blocks, the block to read (default: the first)")
      ->each([cmd](const std::string&) { cmd->frameGiven = true; });
  sub->add_option("--fps", cmd->fps, "Frame rate: 24, 25, 29.97, 30000/1001 ...")->capture_default_str();
  sub->add_option("--zstd-level", cmd->zstdLevel, "zstd level")->capture_default_str()->check(CLI::Range(-7, 19));
  sub->add_option("--memory-mb", cmd->memoryMb, "Store writer memory budget in MB")->capture_default_str()->check(CLI::PositiveNumber);
  sub->footer(
      "The dump is the reference workflow's: each shaded grid a PointsPolygons with \"Cs\" (premultiplied colour),\n"
      "\"Os\" (opacity) and \"blurP\" (position at shutter close), or MotionBegin blocks with any number of knots.\n"
      "Camera and shutter come from Format, Projection, ScreenWindow, Clipping and Shutter; every other declared\n"
      "variable becomes an output variable. Polygons with more than four corners are split (convex: into quads;\n"
      "non-convex: triangulated); polygons with holes are rejected.\n\n"
      "Example:\n"
      "  reshutter ingest myrib.rib.gz -o frame.0001.mps --frame 1 --fps 30000/1001\n"
      "  reshutter resample frame.0001.mps -o field1.exr --shutter 0:0.5");
  registry.add(sub, [cmd] { return cmd->run(); });
}

}  // namespace reshutter::cli
