// Shading-pass benchmark (issue 4): throughput of split + dice + shade for the built-in demo
// scene at its default resolution and at 1920x1080 (≥ 5 M micropolygons), on 1 thread and on
// every core, into a null sink (the pass alone) and into a StoreWriter (the pass plus
// compression and I/O, what `reshutter shade` costs).
// Usage: shade_bench [--quick] [--dir DIR]      (one line of results per configuration)
//        shade_bench --shadows                    (the demo with shadows off and on)
//        shade_bench --shade-in-time [--quick] [--only once|t0.03|t0.01|t0[,...]] [--threads N] [--res W H] [--repeat N] [--stride N] [--times N]
//                                                  (the demo shaded once and in time, into stores;
//                                                   --quick: 640x360 only)
//        shade_bench --motion-factors DIR          (demo stores for motion factor 0, 0.5, 1, 2, 4 in DIR,
//                                                   for the accuracy study in bench/RESULTS.md)
#include <sys/resource.h>
#include <cinttypes>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <optional>
#include <string>
#include <thread>

#include <tbb/global_control.h>

#include "bench/bench_util.h"
#include "shade/demo_scene.h"
#include "shade/shading_pass.h"
#include "store/writer.h"

using namespace reshutter;
using reshutter::bench::Stopwatch;

namespace {

// CPU seconds of this process (all threads): on a shared machine, throughput per CPU-second is
// the per-core figure that other tenants' load does not distort as much as wall time does.
double cpuSeconds() {
  rusage u{};
  getrusage(RUSAGE_SELF, &u);
  return double(u.ru_utime.tv_sec + u.ru_stime.tv_sec) + 1e-6 * double(u.ru_utime.tv_usec + u.ru_stime.tv_usec);
}

struct NullSink final : store::GridSink {
  uint32_t addSchedule(const store::Schedule&) override { return 1; }
  void addGrid(const store::GridInput&) override {}
};

int timeStride = shade::ShadeOptions{}.timeStride;  // --stride N: ShadeOptions::timeStride

void run(const char* label, int w, int h, double rateScale, int threads, const std::string& storePath, double motionFactor = 0, bool shadows = true,
         double shadowRate = 1, std::optional<double> timeTolerance = {}, int shadingTimes = 3) {
  tbb::global_control gc(tbb::global_control::max_allowed_parallelism, size_t(threads));
  shade::ShadeOptions o;
  o.timeTolerance = timeTolerance;
  o.timeStride = timeStride;
  o.shadingTimes = shadingTimes;
  o.shadows = shadows;
  o.shadowRate = shadowRate;
  o.dice.shadingRateScale = rateScale;
  o.dice.motionFactor = motionFactor;
  Stopwatch build;
  shade::FrameScene f = shade::demoFrame(w, h);
  const double buildSeconds = build.seconds();
  Stopwatch sw;
  const double cpu0 = cpuSeconds();
  shade::ShadeStats st;
  uint64_t bytes = 0;
  if (storePath.empty()) {
    NullSink sink;
    st = shade::shadeFrame(f, o, sink);
  } else {
    auto r = shade::shadeToStore(f, o, storePath);
    st = r.shade;
    bytes = r.write.fileBytes;
  }
  const double s = sw.seconds(), cpu = cpuSeconds() - cpu0;
  const double mps = double(st.micropolygons) / s;
  std::printf("%-6s %4dx%-4d rate x%-3g %2d thr %9" PRIu64 " mp (%" PRIu64 " moving) %6" PRIu64
              " grids %7.3f s wall %7.3f s cpu  %5.2f M mp/s  %5.2f M mp/s per cpu-s  %s  scene %.3f s  peak RSS %.0f MB\n",
              label, w, h, rateScale, threads, st.micropolygons, st.movingMicropolygons, st.grids, s, cpu, mps / 1e6, double(st.micropolygons) / cpu / 1e6,
              storePath.empty() ? "null sink" : (std::to_string(bytes / 1000000) + " MB store").c_str(), buildSeconds, bench::peakRssBytes() / 1e6);
  if (!st.shadingTimes.empty())
    std::printf("       in time: %zu times, %" PRIu64 " of %" PRIu64 " candidate grids kept them (%" PRIu64 " micropolygons), %" PRIu64
                " later vertex shadings kept the first, %" PRIu64 " grid times blended, %" PRIu64 " later vertices shaded, %" PRIu64 " interpolated\n",
                st.shadingTimes.size(), st.timedGrids, st.timeCandidateGrids, st.timedMicropolygons, st.reusedVertices, st.blendedTimes, st.laterVertices,
                st.interpolatedVertices);
  if (st.shadowMicropolygons)
    std::printf("       shadows: %" PRIu64 " rays against %" PRIu64 " micropolygons (%" PRIu64 " moving rigidly in %" PRIu64 " instances), scene built in %.3f s\n",
                st.shadowRays, st.shadowMicropolygons, st.rigidMicropolygons, st.rigidCasters, st.shadowBuildSeconds);
  std::fflush(stdout);
}

}  // namespace

int main(int argc, char** argv) {
  bool quick = false, shadows = false, inTime = false;
  int threadCount = 0;  // --threads N: that many instead of every core
  std::string only;     // --only LABEL[,LABEL...]: those configurations alone (with --shade-in-time: once, t0.03, t0.01, t0)
  int resW = 0, resH = 0;  // --res W H: that frame size alone (with --shade-in-time)
  int repeat = 1;          // --repeat N: each configuration N times in this process (warm: the later runs)
  int shadingTimes = 5;    // --times N: shading times of the in-time configurations
  std::string dir = std::filesystem::temp_directory_path().string(), mfDir;
  for (int i = 1; i < argc; ++i) {
    if (!std::strcmp(argv[i], "--quick")) quick = true;
    else if (!std::strcmp(argv[i], "--motion-factors") && i + 1 < argc) mfDir = argv[++i];
    else if (!std::strcmp(argv[i], "--shadows")) shadows = true;
    else if (!std::strcmp(argv[i], "--shade-in-time")) inTime = true;
    else if (!std::strcmp(argv[i], "--dir") && i + 1 < argc) dir = argv[++i];
    else if (!std::strcmp(argv[i], "--threads") && i + 1 < argc) threadCount = std::atoi(argv[++i]);
    else if (!std::strcmp(argv[i], "--only") && i + 1 < argc) only = argv[++i];
    else if (!std::strcmp(argv[i], "--stride") && i + 1 < argc) timeStride = std::atoi(argv[++i]);
    else if (!std::strcmp(argv[i], "--repeat") && i + 1 < argc) repeat = std::max(1, std::atoi(argv[++i]));
    else if (!std::strcmp(argv[i], "--times") && i + 1 < argc) shadingTimes = std::max(2, std::atoi(argv[++i]));
    else if (!std::strcmp(argv[i], "--res") && i + 2 < argc) resW = std::atoi(argv[i + 1]), resH = std::atoi(argv[i + 2]), i += 2;
    else {
      std::fprintf(stderr, "usage: shade_bench [--quick] [--dir DIR] [--threads N] [--shadows | --shade-in-time [--only LABEL[,LABEL...]] [--res W H] [--repeat N] [--stride N] [--times N]]\n");
      return 2;
    }
  }
  const int cores = int(std::max(1u, std::thread::hardware_concurrency()));
  std::printf("shade_bench: %s\n", bench::machineLine().c_str());
  if (!mfDir.empty()) {
    std::filesystem::create_directories(mfDir);
    for (double mf : {0.0, 0.5, 1.0, 2.0, 4.0}) {
      char label[16];
      std::snprintf(label, sizeof label, "mf%g", mf);
      run(label, 640, 360, 1, cores, mfDir + "/demo-" + label + ".mps", mf);
    }
    return 0;
  }
  if (shadows) {  // what the demo's two shadow-casting lights cost: the pass alone
    for (auto [w, h] : {std::pair{640, 360}, {1920, 1080}})
      for (int threads : {1, cores}) {
        run("off", w, h, 1, threads, "", 0, false);
        run("on", w, h, 1, threads, "", 0, true);
        run("rate4", w, h, 1, threads, "", 0, true, 4);
      }
    return 0;
  }
  const std::string store = dir + "/shade_bench.mps";
  auto wanted = [&](const std::string& label) { return only.empty() || ("," + only + ",").find("," + label + ",") != std::string::npos; };
  if (inTime) {  // what shading in time costs on the demo (into a store: its size too)
    {
      // The demo's textures load OpenImageIO's module, once per process (~0.4 CPU-s on the
      // project's VM: 260 libraries): outside the timings, so that they are the pass alone.
      const double cpu0 = cpuSeconds();
      shade::FrameScene tiny = shade::demoFrame(16, 9);
      NullSink sink;
      shade::shadeFrame(tiny, shade::ShadeOptions{}, sink);
      std::printf("       (the texture module loaded before timing: %.3f CPU-s)\n", cpuSeconds() - cpu0);
    }
    std::vector<std::pair<int, int>> sizes{{640, 360}, {1920, 1080}};
    if (resW > 0 && resH > 0) sizes = {{resW, resH}};
    for (auto [w, h] : sizes) {
      if (quick && w > 640) break;
      const int n = threadCount > 0 ? threadCount : cores;
      for (int r = 0; r < repeat; ++r) {
        if (wanted("once")) run("once", w, h, 1, n, store);
        for (double tol : {0.03, 0.01, 0.0}) {
          char label[16];
          std::snprintf(label, sizeof label, "t%g", tol);
          if (wanted(label)) run(label, w, h, 1, n, store, 0, true, 1, tol, shadingTimes);
        }
      }
    }
    std::filesystem::remove(store);
    return 0;
  }
  run("demo", 640, 360, 1, 1, "");
  run("demo", 640, 360, 1, cores, "");
  run("demo", 640, 360, 1, cores, store);
  if (!quick) {
    run("demo", 1920, 1080, 1, 1, "");
    run("demo", 1920, 1080, 1, cores, "");
    run("demo", 1920, 1080, 1, cores, store);
  }
  std::filesystem::remove(store);
  return 0;
}
