// Micropolygon-dump ingest, the passes behind shade/ingest.h: one optimistic pass (the schema
// from the first primitive, grids at once), or, when a later primitive brings more variables, a
// scan for the metadata and then a pass that emits the grids. The request handler they drive is
// shade/ingest_handler.h's DumpHandler (requests, polygons and grids in ingest_*.cpp).
#include "shade/ingest.h"

#include <chrono>
#include <memory>
#include <optional>

#include "common/error.h"
#include "common/log.h"
#include "rib/rib.h"
#include "shade/ingest_handler.h"
#include "store/writer.h"

namespace reshutter::shade {

namespace {

using ingest::DumpHandler;
using ingest::Mode;
using rib::Args;
using rib::Request;
using store::GridSink;
using store::StoreMeta;
using store::StoreWriter;
using Clock = std::chrono::steady_clock;

/// Reads the dump once through `h`, reporting progress every 1024 requests.
void runPass(const std::string& path, DumpHandler& h, int pass, bool warn, const IngestOptions& opt, uint64_t& bytes) {
  rib::ReaderOptions ro;
  ro.warnUnsupported = warn;  // a second pass meets the same requests
  rib::Reader reader(ro);
  reader.declare("blurP", "vertex point");  // dump writers use it without declaring it
  struct Progressing : rib::RequestHandler {
    Progressing(DumpHandler& h, const rib::Reader& r, const IngestOptions& opt, int pass) : h(h), r(r), opt(opt), pass(pass) {}
    DumpHandler& h;
    const rib::Reader& r;
    const IngestOptions& opt;
    int pass;
    uint64_t n = 0;
    bool handle(const Request& req, const Args& a) override {
      if (opt.progress && (++n & 1023) == 0) opt.progress(pass, r.bytesRead());
      return h.handle(req, a);
    }
  } p(h, reader, opt, pass);
  reader.parseFile(path, p);
  bytes = reader.bytesRead();
  h.finish(path);
}

}  // namespace

StoreMeta scanDump(const std::string& ribPath, const IngestOptions& options) {
  DumpHandler h(Mode::Scan, ribPath, options, nullptr, nullptr, nullptr);
  uint64_t bytes = 0;
  runPass(ribPath, h, 1, true, options, bytes);
  return h.scannedMeta(ribPath);
}

void ingestDumpInto(const std::string& ribPath, const StoreMeta& meta, GridSink& sink, IngestStats& stats, const IngestOptions& options) {
  DumpHandler h(Mode::Emit, ribPath, options, &meta, &sink, &stats);
  runPass(ribPath, h, 2, false, options, stats.ribBytes);
}

namespace {

/// One pass when the first primitive's variables are every primitive's (dumps are uniform);
/// nothing (and no store) when a later primitive brought more.
std::optional<IngestStats> ingestInOnePass(const std::string& ribPath, const std::string& storePath, const IngestOptions& options, Clock::time_point t0) {
  IngestStats stats;
  std::unique_ptr<StoreWriter> writer;
  try {
    DumpHandler h(Mode::Optimistic, ribPath, options, nullptr, nullptr, &stats);
    h.openSink = [&](const StoreMeta& m) {
      writer = std::make_unique<StoreWriter>(storePath, m, options.writer);
      return writer.get();
    };
    runPass(ribPath, h, 2, true, options, stats.ribBytes);
    if (!writer) writer = std::make_unique<StoreWriter>(storePath, h.scannedMeta(ribPath), options.writer);
    stats.write = writer->close();
    stats.passes = 1;
    stats.ingestSeconds = std::chrono::duration<double>(Clock::now() - t0).count();
    return stats;
  } catch (const ingest::SchemaGrew&) {
    writer.reset();  // removes its temporary file
    note(cat(ribPath, ": later primitives carry more variables than the first; reading the dump twice"));
    return std::nullopt;
  }
}

/// A scan for camera, shutter and every variable, then the grids.
IngestStats ingestInTwoPasses(const std::string& ribPath, const std::string& storePath, const IngestOptions& options, Clock::time_point t0) {
  IngestStats stats;
  stats.passes = 2;
  StoreMeta meta = scanDump(ribPath, options);
  auto t2 = Clock::now();
  StoreWriter writer(storePath, meta, options.writer);
  ingestDumpInto(ribPath, meta, writer, stats, options);
  stats.write = writer.close();
  stats.scanSeconds = std::chrono::duration<double>(t2 - t0).count();  // includes the abandoned first try
  stats.ingestSeconds = std::chrono::duration<double>(Clock::now() - t2).count();
  return stats;
}

}  // namespace

IngestStats ingestDump(const std::string& ribPath, const std::string& storePath, const IngestOptions& options) {
  const auto t0 = Clock::now();
  if (std::optional<IngestStats> stats = ingestInOnePass(ribPath, storePath, options, t0)) return *stats;
  return ingestInTwoPasses(ribPath, storePath, options, t0);
}

}  // namespace reshutter::shade
