// RIB reader and ingest benchmark (issue 3). Writes N synthetic micropolygons (store/synthetic.h:
// ~1 px quads in 16x16 grids, 2 knots, per-vertex Ci/Oi) as the reference workflow's dump
// (shade/dump_writer.h: PointsPolygons + Cs + Os + blurP under CoordSysTransform "camera"), plain
// and gzipped, then reports:
//   ASCII parse MB/s on one core (from memory, from the plain file, from the gzipped file), with a
//   handler that takes every request and resolves its parameter list;
//   ingest micropolygons/s (both passes, store written) from the gzipped dump; peak RSS;
//   store size against the gzipped RIB.
// Usage: rib_bench [--mp N] [--dir DIR] [--keep]   (--keep leaves dump.rib, dump.rib.gz, dump.mps in DIR)
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <functional>
#include <string>

#include <time.h>

#include <tbb/global_control.h>

#include "bench/bench_util.h"
#include "rib/rib.h"
#include "shade/dump_writer.h"
#include "shade/ingest.h"
#include "store/synthetic.h"

using namespace reshutter;
using reshutter::bench::Stopwatch;

namespace {

struct ParamHandler final : rib::RequestHandler {
  uint64_t requests = 0, values = 0;
  bool handle(const rib::Request& r, const rib::Args& a) override {
    ++requests;
    if (r.name == "PointsPolygons")
      for (const auto& p : a.params(2)) values += p.value->size();
    return true;
  }
};

// CPU seconds of this process: on a shared 2-vCPU VM, wall time measures the neighbours too.
double cpuSeconds() {
  timespec ts;
  clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &ts);
  return double(ts.tv_sec) + 1e-9 * double(ts.tv_nsec);
}

struct Timing {
  double wall = 1e30, cpu = 1e30;
};

Timing parseSeconds(const std::function<void(rib::Reader&, ParamHandler&)>& run, uint64_t& bytes) {
  Timing best;
  for (int rep = 0; rep < 3; ++rep) {
    rib::Reader reader;
    ParamHandler h;
    Stopwatch sw;
    double c0 = cpuSeconds();
    run(reader, h);
    best.cpu = std::min(best.cpu, cpuSeconds() - c0);
    best.wall = std::min(best.wall, sw.seconds());
    bytes = reader.bytesRead();
  }
  return best;
}

}  // namespace

int main(int argc, char** argv) {
  uint64_t mp = 2'000'000;
  std::string dir = "/tmp/reshutter-rib-bench";
  bool keep = false;
  for (int i = 1; i < argc; ++i) {
    if (!std::strcmp(argv[i], "--mp") && i + 1 < argc) mp = std::stoull(argv[++i]);
    else if (!std::strcmp(argv[i], "--dir") && i + 1 < argc) dir = argv[++i];
    else if (!std::strcmp(argv[i], "--keep")) keep = true;
    else {
      std::fprintf(stderr, "usage: rib_bench [--mp N] [--dir DIR] [--keep]\n");
      return 2;
    }
  }
  std::filesystem::create_directories(dir);
  const std::string plain = dir + "/dump.rib", gz = dir + "/dump.rib.gz", mps = dir + "/dump.mps";
  store::SyntheticOptions so;
  so.micropolygons = mp;
  const store::StoreMeta meta = store::syntheticMeta(so);
  {
    shade::DumpRibWriter a(plain, meta, false);
    store::generateSynthetic(so, a);
    a.close();
    shade::DumpRibWriter b(gz, meta, true);
    store::generateSynthetic(so, b);
    b.close();
  }
  const double plainMB = double(std::filesystem::file_size(plain)) / 1e6, gzMB = double(std::filesystem::file_size(gz)) / 1e6;
  std::printf("machine: %s\n", bench::machineLine().c_str());
  std::printf("dump: %.2f M micropolygons, ASCII %.1f MB, gzipped %.1f MB\n", double(mp) / 1e6, plainMB, gzMB);

  for (int threads : {1, 2}) {
    tbb::global_control limit(tbb::global_control::max_allowed_parallelism, size_t(threads));
    const double c0 = cpuSeconds();
    shade::IngestStats st = shade::ingestDump(gz, mps);
    const double cpu = cpuSeconds() - c0;
    const double total = st.scanSeconds + st.ingestSeconds;
    std::printf("ingest gz, %d thread%s: %5.2f M mp/s wall, %5.2f M mp/s per CPU-second (%d pass%s), store %.1f MB = %.1f B/mp, RIB.gz / store = %.2f\n",
                threads, threads > 1 ? "s" : " ", double(st.micropolygons) / 1e6 / total, double(st.micropolygons) / 1e6 / cpu, st.passes,
                st.passes > 1 ? "es" : "", double(st.write.fileBytes) / 1e6, double(st.write.fileBytes) / double(st.micropolygons),
                gzMB * 1e6 / double(st.write.fileBytes));
  }
  std::printf("peak RSS after ingest (writer budget 64 MB): %.0f MB\n", double(bench::peakRssBytes()) / 1e6);

  tbb::global_control one(tbb::global_control::max_allowed_parallelism, 1);
  std::string bytes;
  {
    std::ifstream in(plain, std::ios::binary);
    bytes.assign(std::istreambuf_iterator<char>(in), {});
  }
  uint64_t n = 0;
  auto line = [&](const char* what, Timing t) {
    std::printf("%-32s %7.1f MB/s per CPU-second, %7.1f MB/s wall (1 thread)\n", what, double(n) / 1e6 / t.cpu, double(n) / 1e6 / t.wall);
  };
  line("parse ASCII from memory:", parseSeconds([&](rib::Reader& r, ParamHandler& h) { r.parseBuffer(bytes, "dump.rib", h); }, n));
  bytes.clear();
  bytes.shrink_to_fit();
  line("parse ASCII file:", parseSeconds([&](rib::Reader& r, ParamHandler& h) { r.parseFile(plain, h); }, n));
  line("parse gzipped ASCII (+zlib):", parseSeconds([&](rib::Reader& r, ParamHandler& h) { r.parseFile(gz, h); }, n));

  if (!keep) {
    std::filesystem::remove(plain);
    std::filesystem::remove(gz);
    std::filesystem::remove(mps);
  }
  return 0;
}
