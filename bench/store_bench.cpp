// Store benchmark (issue: sparse micropolygon store). For N synthetic micropolygons (1920x1080,
// ~1 px quads in 16x16 grids, motion up to 50 px, 2 knots, Ci + Oi) it reports:
//   bytes per micropolygon, write and decode throughput per core, streaming peak memory and time
//   to first tile (in a child process, visiting tiles in bucket order), and the same
//   micropolygons as a gzipped ASCII RIB dump (size and write time; bench/rib_bench.cpp measures parsing it).
// Usage: store_bench [--mp N] [--texture T] [--dir DIR] [--rib]    (one line of results per run)
//        store_bench stream FILE                                   (child: streaming pass)
//        store_bench decode FILE   (every part of an existing store decoded once on one core, the
//                                   re-sampler's decode floor: best of three passes, bytes moved)
#include <sys/wait.h>
#include <unistd.h>
#include <algorithm>
#include <cinttypes>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <string>

#include <tbb/global_control.h>
#include <tbb/parallel_for.h>

#include "bench/bench_util.h"
#include "shade/dump_writer.h"
#include "store/reader.h"
#include "store/synthetic.h"
#include "store/writer.h"

using namespace reshutter;
using namespace reshutter::store;
using reshutter::bench::Stopwatch;

namespace {

struct NullSink final : GridSink {
  uint64_t mps = 0;
  uint32_t addSchedule(const Schedule&) override { return 1; }
  void addGrid(const GridInput& g) override { mps += g.numMicropolygons(); }
};

// Streaming pass: buckets of 32x32 px in row-major order over the whole shutter, parts through a
// 32 MB cache, as the resampler will visit them. Prints "first_tile_ms peak_rss_mb mps".
int streamPass(const std::string& path) {
  Stopwatch open;
  ReaderOptions ro;
  ro.cacheBytes = 32u << 20;
  StoreReader reader(path, ro);
  double firstTile = -1;
  uint64_t mps = 0;
  const auto& cam = reader.meta().cameras[0];
  for (int by = 0; by < cam.height; by += 32)
    for (int bx = 0; bx < cam.width; bx += 32) {
      RasterRect bucket{float(bx), float(by), float(bx + 32), float(by + 32), false};
      reader.visit(bucket, reader.meta().shutterOpen, reader.meta().shutterClose, [&](size_t e) {
        auto p = reader.part(e);
        if (firstTile < 0) firstTile = open.seconds() * 1e3;
        mps += p->numMicropolygons;
      });
    }
  std::printf("%.3f %.1f %" PRIu64 "\n", firstTile, bench::peakRssBytes() / 1e6, mps);
  return 0;
}

// Decodes every part of `path` once per pass on this thread (a part is freed before the next is
// decoded, so memory is reused as a steady-state re-sampler reuses it), three passes after one
// that maps the file in; prints the best pass with the bytes each stage moves.
int decodePass(const std::string& path) {
  ReaderOptions ro;
  ro.cacheBytes = 0, ro.releasePages = false;
  StoreReader reader(path, ro);
  const auto& entries = reader.entries();
  uint64_t compressed = 0, raw = 0, decoded = 0;
  for (size_t e = 0; e < entries.size(); ++e) compressed += entries[e].compressedSize, raw += entries[e].rawSize, decoded += reader.decode(e).memoryBytes();
  double best = 1e30;
  for (int pass = 0; pass < 3; ++pass) {
    Stopwatch sw;
    for (size_t e = 0; e < entries.size(); ++e) reader.decode(e);
    best = std::min(best, sw.seconds());
  }
  std::printf("%s: %zu parts, %" PRIu64 " micropolygons; %.1f MB compressed -> %.1f MB raw -> %.1f MB decoded; one core, best of 3: %.3f s (%.1f M micropolygons/s)\n",
              path.c_str(), entries.size(), reader.micropolygonCount(), compressed / 1e6, raw / 1e6, decoded / 1e6, best, reader.micropolygonCount() / best / 1e6);
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  if (argc == 3 && std::string(argv[1]) == "stream") return streamPass(argv[2]);
  if (argc == 3 && std::string(argv[1]) == "decode") return decodePass(argv[2]);
  SyntheticOptions opt;
  std::string dir = "/tmp/reshutter-bench";
  bool rib = false;
  for (int i = 1; i < argc; ++i) {
    std::string a = argv[i];
    if (a == "--mp" && i + 1 < argc) opt.micropolygons = std::stoull(argv[++i]);
    else if (a == "--texture" && i + 1 < argc) opt.texture = std::stod(argv[++i]);
    else if (a == "--dir" && i + 1 < argc) dir = argv[++i];
    else if (a == "--rib") rib = true;
    else {
      std::fprintf(stderr, "usage: store_bench [--mp N] [--texture T] [--dir DIR] [--rib]\n");
      return 2;
    }
  }
  std::filesystem::create_directories(dir);
  const std::string path = dir + "/bench_" + std::to_string(opt.micropolygons) + ".mps";

  // Generation alone (single thread): subtracted from the write timings.
  Stopwatch sw;
  NullSink null;
  generateSynthetic(opt, null);
  const double genSeconds = sw.seconds();
  const double n = double(null.mps);

  double write1 = 0, write2 = 0;
  WriteStats ws;
  {
    tbb::global_control one(tbb::global_control::max_allowed_parallelism, 1);
    sw.reset();
    StoreWriter w(path, syntheticMeta(opt));
    generateSynthetic(opt, w);
    ws = w.close();
    write1 = sw.seconds() - genSeconds;
  }
  {
    sw.reset();
    StoreWriter w(path, syntheticMeta(opt));
    generateSynthetic(opt, w);
    w.close();
    write2 = sw.seconds() - genSeconds;
  }

  double decode1 = 0, decode2 = 0;
  {
    StoreReader reader(path, ReaderOptions{0, false});
    const size_t parts = reader.entries().size();
    sw.reset();
    for (size_t e = 0; e < parts; ++e) reader.decode(e);
    decode1 = sw.seconds();
    sw.reset();
    tbb::parallel_for(size_t(0), parts, [&](size_t e) { reader.decode(e); });
    decode2 = sw.seconds();
  }

  // Streaming in a fresh process so its peak memory is its own.
  double firstTileMs = 0, streamPeakMb = 0;
  {
    std::string cmd = "/proc/self/exe stream " + path;
    FILE* p = ::popen(("\"" + std::string(argv[0]) + "\" stream " + path).c_str(), "r");
    if (p) {
      unsigned long long mps = 0;
      if (std::fscanf(p, "%lf %lf %llu", &firstTileMs, &streamPeakMb, &mps) != 3) firstTileMs = -1;
      ::pclose(p);
    }
  }

  std::printf("machine: %s\n", bench::machineLine().c_str());
  std::printf("micropolygons %.0f, texture %.2f, file %.1f MB\n", n, opt.texture, ws.fileBytes / 1e6);
  std::printf(
      "| micropolygons | bytes/mp | write M mp/s (1 core) | write M mp/s (all cores) | decode M mp/s (1 core) | decode M mp/s (all cores) | stream peak RSS MB "
      "| first tile ms |\n");
  std::printf("| %.0f | %.2f | %.2f | %.2f | %.2f | %.2f | %.1f | %.2f |\n", n, ws.fileBytes / n, n / write1 / 1e6, n / write2 / 1e6, n / decode1 / 1e6,
              n / decode2 / 1e6, streamPeakMb, firstTileMs);

  if (rib) {
    const std::string ribPath = dir + "/bench_" + std::to_string(opt.micropolygons) + ".rib.gz";
    sw.reset();
    shade::DumpRibWriter dump(ribPath, syntheticMeta(opt), true, 6);
    generateSynthetic(opt, dump);
    dump.close();
    double ribWrite = sw.seconds() - genSeconds;
    auto ribBytes = double(std::filesystem::file_size(ribPath));
    std::printf("gzipped ASCII RIB dump: %.1f MB (%.1f bytes/mp, %.1fx the store), written in %.1f s\n", ribBytes / 1e6, ribBytes / n,
                ribBytes / double(ws.fileBytes), ribWrite);
  }
  return 0;
}
