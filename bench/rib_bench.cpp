// RIB reader and ingest benchmark (issue 3). Writes N synthetic micropolygons (store/synthetic.h:
// ~1 px quads in 16x16 grids, 2 knots, per-vertex Ci/Oi) as the reference workflow's dump
// (bench/dump_rib.h: PointsPolygons + Cs + Os + blurP under CoordSysTransform "camera"), plain
// and gzipped, then reports:
//   ASCII parse MB/s on one core (from memory, from the plain file, from the gzipped file), with a
//   handler that takes every request and resolves its parameter list;
//   ingest micropolygons/s (both passes, store written) from the gzipped dump; peak RSS;
//   store size against the gzipped RIB.
// Usage: rib_bench [--mp N] [--dir DIR]
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <functional>
#include <string>

#include <tbb/global_control.h>

#include "bench/bench_util.h"
#include "bench/dump_rib.h"
#include "rib/rib.h"
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

double parseSeconds(const std::function<void(rib::Reader&, ParamHandler&)>& run, uint64_t& bytes) {
  double best = 1e30;
  for (int rep = 0; rep < 3; ++rep) {
    rib::Reader reader;
    ParamHandler h;
    Stopwatch sw;
    run(reader, h);
    best = std::min(best, sw.seconds());
    bytes = reader.bytesRead();
  }
  return best;
}

}  // namespace

int main(int argc, char** argv) {
  uint64_t mp = 2'000'000;
  std::string dir = "/tmp/reshutter-rib-bench";
  for (int i = 1; i < argc; ++i) {
    if (!std::strcmp(argv[i], "--mp") && i + 1 < argc) mp = std::stoull(argv[++i]);
    else if (!std::strcmp(argv[i], "--dir") && i + 1 < argc) dir = argv[++i];
    else {
      std::fprintf(stderr, "usage: rib_bench [--mp N] [--dir DIR]\n");
      return 2;
    }
  }
  std::filesystem::create_directories(dir);
  const std::string plain = dir + "/dump.rib", gz = dir + "/dump.rib.gz", mps = dir + "/dump.mps";
  store::SyntheticOptions so;
  so.micropolygons = mp;
  const store::StoreMeta meta = store::syntheticMeta(so);
  {
    bench::DumpRibWriter a(plain, meta, false);
    store::generateSynthetic(so, a);
    a.close();
    bench::DumpRibWriter b(gz, meta, true);
    store::generateSynthetic(so, b);
    b.close();
  }
  const double plainMB = double(std::filesystem::file_size(plain)) / 1e6, gzMB = double(std::filesystem::file_size(gz)) / 1e6;
  std::printf("machine: %s\n", bench::machineLine().c_str());
  std::printf("dump: %.2f M micropolygons, ASCII %.1f MB, gzipped %.1f MB\n", double(mp) / 1e6, plainMB, gzMB);

  for (int threads : {1, 2}) {
    tbb::global_control limit(tbb::global_control::max_allowed_parallelism, size_t(threads));
    shade::IngestStats st = shade::ingestDump(gz, mps);
    const double total = st.scanSeconds + st.ingestSeconds;
    std::printf("ingest gz, %d thread%s:           %7.2f M mp/s (scan %.2f s + write %.2f s), store %.1f MB = %.1f B/mp, RIB.gz / store = %.2f\n",
                threads, threads > 1 ? "s" : " ", double(st.micropolygons) / 1e6 / total, st.scanSeconds, st.ingestSeconds,
                double(st.write.fileBytes) / 1e6, double(st.write.fileBytes) / double(st.micropolygons), gzMB * 1e6 / double(st.write.fileBytes));
  }
  std::printf("peak RSS after ingest (writer budget 64 MB): %.0f MB\n", double(bench::peakRssBytes()) / 1e6);

  tbb::global_control one(tbb::global_control::max_allowed_parallelism, 1);
  std::string bytes;
  {
    std::ifstream in(plain, std::ios::binary);
    bytes.assign(std::istreambuf_iterator<char>(in), {});
  }
  uint64_t n = 0;
  double tMem = parseSeconds([&](rib::Reader& r, ParamHandler& h) { r.parseBuffer(bytes, "dump.rib", h); }, n);
  std::printf("parse ASCII from memory:        %7.1f MB/s (1 core)\n", double(n) / 1e6 / tMem);
  bytes.clear();
  bytes.shrink_to_fit();
  double tFile = parseSeconds([&](rib::Reader& r, ParamHandler& h) { r.parseFile(plain, h); }, n);
  std::printf("parse ASCII file:               %7.1f MB/s (1 core)\n", double(n) / 1e6 / tFile);
  double tGz = parseSeconds([&](rib::Reader& r, ParamHandler& h) { r.parseFile(gz, h); }, n);
  std::printf("parse gzipped ASCII file:       %7.1f MB/s decompressed (1 core, zlib included)\n", double(n) / 1e6 / tGz);

  std::filesystem::remove(plain);
  std::filesystem::remove(gz);
  std::filesystem::remove(mps);
  return 0;
}
