// kernel_bench: the re-sampler's inner-loop variants on one store, A/B in one process - the
// scalar loops, the AVX2 and the AVX-512 kernels, each with and without chunk gathers - on one
// thread, rounds interleaved so that every variant sees the same minutes of a noisy machine.
// Prints per variant the render's CPU seconds (min and median of the rounds), sample tests, hits
// and the micropolygons gathered by chunk, and checks that every variant's image is the first's,
// bit for bit (a variant that differs is a bug: exit status 1). An untimed render decodes the
// parts first; the timed ones take them from the store's decoded-part cache (256 MB: all of a
// quarter-frame crop of the 5 M bench store, not quite all of its whole frame).
//
//   kernel_bench STORE [--rounds 5] [--shutter OPEN:CLOSE] [--crop X0 X1 Y0 Y1] [--spp 16]
//   e.g. kernel_bench moving.0001.mps --crop 480 1440 270 810 --shutter 0.25:0.5
#include <algorithm>
#include <cstdio>
#include <cstdlib>
#include <ctime>
#include <string>
#include <vector>

#include <tbb/global_control.h>

#include "bench/bench_util.h"
#include "resample/coverage.h"
#include "resample/gather.h"
#include "resample/resampler.h"
#include "store/reader.h"

using namespace reshutter;
using namespace reshutter::resample;

namespace {

struct Variant {
  std::string name;
  bool vector, avx512, chunks;
  std::vector<double> seconds;
  RasterStats stats;
};

double cpuSeconds() {
  timespec ts{};
  clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &ts);
  return double(ts.tv_sec) + 1e-9 * double(ts.tv_nsec);
}

double median(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  return v.empty() ? 0.0 : v[v.size() / 2];
}

}  // namespace

int main(int argc, char** argv) {
  if (argc < 2) {
    std::fprintf(stderr, "usage: kernel_bench STORE [--rounds N] [--shutter OPEN:CLOSE] [--crop X0 X1 Y0 Y1] [--spp N]\n");
    return 2;
  }
  const std::string path = argv[1];
  int rounds = 5, spp = 16;
  double open = -1, close = -1;
  int crop[4] = {0, 0, 0, 0};
  for (int i = 2; i < argc; ++i) {
    const std::string a = argv[i];
    if (a == "--rounds" && i + 1 < argc) rounds = std::atoi(argv[++i]);
    else if (a == "--spp" && i + 1 < argc) spp = std::atoi(argv[++i]);
    else if (a == "--shutter" && i + 1 < argc) std::sscanf(argv[++i], "%lf:%lf", &open, &close);
    else if (a == "--crop" && i + 4 < argc)
      for (int k = 0; k < 4; ++k) crop[k] = std::atoi(argv[++i]);
    else {
      std::fprintf(stderr, "kernel_bench: unknown argument '%s'\n", a.c_str());
      return 2;
    }
  }
  try {
    tbb::global_control oneThread(tbb::global_control::max_allowed_parallelism, 1);
    auto store = std::make_shared<const store::StoreReader>(path);
    const auto& meta = store->meta();
    if (open < 0) open = meta.shutterOpen, close = meta.shutterClose;
    RenderSpec spec;
    spec.sources = {Source{store, meta.frame}};
    spec.keepDecoded = {store.get()};  // the timed renders find the parts decoded
    const double f = double(meta.frame);
    spec.shutter = ShutterModel::progressive(f + open, f + close);
    SamplePattern::factor(spp, spec.samplesX, spec.samplesY);
    spec.filter = FilterSpec::parse("gaussian:2x2", "kernel_bench");
    spec.cropX0 = crop[0], spec.cropX1 = crop[1], spec.cropY0 = crop[2], spec.cropY1 = crop[3];
    spec.progress = false;

    std::vector<Variant> variants;
    if (kernels::available(kernels::Isa::Avx512)) {
      variants.push_back({"avx512 + chunk gathers", true, true, true, {}, {}});
      variants.push_back({"avx512", true, true, false, {}, {}});
    }
    if (kernels::available()) {
      variants.push_back({"avx2 + chunk gathers", true, false, true, {}, {}});
      variants.push_back({"avx2", true, false, false, {}, {}});
    }
    variants.push_back({"scalar", false, false, false, {}, {}});

    std::printf("# %s: %s; shutter [%g, %g], %d spp, one thread, %d rounds\n", path.c_str(), bench::machineLine().c_str(), open, close, spp, rounds);
    std::vector<resample::PixelVector<float>> reference;
    bool identical = true;
    // One untimed render first: the store's pages and its decoded-part cache then serve every
    // timed render alike (decoding is not what the variants differ in).
    render(spec);
    for (int r = 0; r < rounds; ++r)
      for (Variant& v : variants) {
        spec.raster.vectorKernels = v.vector, spec.raster.avx512Kernels = v.avx512, spec.raster.chunkGathers = v.chunks;
        const double t0 = cpuSeconds();
        const RenderResult result = render(spec);
        v.seconds.push_back(cpuSeconds() - t0);
        v.stats = result.stats.raster;
        std::vector<resample::PixelVector<float>> channels;
        for (const auto& c : result.image.channels) channels.push_back(c.f);
        if (reference.empty()) reference = channels;
        else if (channels != reference) {
          identical = false;
          std::fprintf(stderr, "kernel_bench: %s gives another image than %s\n", v.name.c_str(), variants[0].name.c_str());
        }
      }
    std::printf("| variant | CPU s min | CPU s median | vs first | sample tests | hits | gathered by chunk |\n|---|---|---|---|---|---|---|\n");
    const double base = median(variants[0].seconds);
    for (const Variant& v : variants)
      std::printf("| %s | %.3f | %.3f | %.2fx | %llu | %llu | %llu |\n", v.name.c_str(), *std::min_element(v.seconds.begin(), v.seconds.end()),
                  median(v.seconds), median(v.seconds) / base, (unsigned long long)v.stats.sampleTests, (unsigned long long)v.stats.hits,
                  (unsigned long long)v.stats.chunkGatheredMicropolygons);
    std::printf("images %s\n", identical ? "bit-identical across variants" : "DIFFER");
    return identical ? 0 : 1;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "kernel_bench: %s\n", e.what());
    return 1;
  }
}
