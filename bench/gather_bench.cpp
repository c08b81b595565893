// gather_bench: the moving gather kernel (kernels::gatherStrata) alone, on synthetic sample
// planes, to separate its arithmetic from its memory traffic: nanoseconds per gather of a
// one-pixel micropolygon moving up to MOTION px over the shutter, 16 strata, for a region of
// W×W pixels whose sample arrays fit the L1 (W 24) or not (W 98, the default bucket and margin),
// visited in random order (as depth-sorted chunks visit a bucket) or in runs of 64 neighbours
// (as a chunk's micropolygons do); each instruction set this CPU runs. Not a test.
//
//   gather_bench [--gathers 2000000] [--motion 25]
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <string>
#include <vector>

#include "bench/bench_util.h"
#include "common/random.h"
#include "resample/coverage.h"
#include "resample/gather.h"

using namespace reshutter;
using namespace reshutter::resample;

namespace {

struct Setup {
  int W;
  size_t PS;
  std::vector<float> st, sx, sy, z;
};

// Sample planes as the rasterizer lays them out: plane s holds every pixel's stratum-s sample
// (jittered position, time inside the stratum); 30 % of the samples have no surface yet.
Setup makeSamples(int W, int N, uint64_t seed) {
  Setup s{W, 0, {}, {}, {}, {}};
  const size_t P = size_t(W) * W;
  s.PS = (P + 15) / 16 * 16;
  if ((s.PS / 16) % 2 == 0) s.PS += 16;  // an odd number of cache lines apart, as begin() does
  const size_t slots = s.PS * size_t(N) + 64;
  s.st.resize(slots), s.sx.resize(slots), s.sy.resize(slots), s.z.resize(slots);
  Rng rng(seed);
  for (int p = 0; p < N; ++p)
    for (int py = 0; py < W; ++py)
      for (int px = 0; px < W; ++px) {
        const size_t i = size_t(p) * s.PS + size_t(py) * W + size_t(px);
        s.sx[i] = float(px + rng.uniform()), s.sy[i] = float(py + rng.uniform()), s.st[i] = float((p + rng.uniform()) / N);
        s.z[i] = rng.uniform() < 0.3 ? INFINITY : float(5 + 45 * rng.uniform());
      }
  return s;
}

}  // namespace

int main(int argc, char** argv) {
  size_t gathers = 2000000;
  float motion = 25.f;
  for (int i = 1; i + 1 < argc; i += 2) {
    const std::string a = argv[i];
    if (a == "--gathers") gathers = size_t(std::atoll(argv[i + 1]));
    else if (a == "--motion") motion = float(std::atof(argv[i + 1]));
    else {
      std::fprintf(stderr, "usage: gather_bench [--gathers N] [--motion PX]\n");
      return 2;
    }
  }
  if (!kernels::available()) {
    std::fprintf(stderr, "gather_bench: this CPU runs no vector kernels\n");
    return 1;
  }
  const int N = 16;
  std::printf("# %s; one-pixel micropolygons moving up to %g px, %d strata, %zu gathers per row\n", bench::machineLine().c_str(), motion, N, gathers);
  std::printf("| region | order | instruction set | ns per gather | candidates per gather |\n|---|---|---|---|---|\n");
  std::vector<kernels::Isa> isas{kernels::Isa::Avx2};
  if (kernels::available(kernels::Isa::Avx512)) isas.push_back(kernels::Isa::Avx512);
  float u0[64], u1[64];
  for (int s = 0; s < N; ++s) u0[s] = float(s) / N, u1[s] = float(s + 1) / N;
  for (int W : {24, 98}) {
    Setup s = makeSamples(W, N, 1);
    const size_t slots = s.st.size();
    std::vector<uint32_t> ci(slots);
    std::vector<float> ct(slots), cx(slots), cy(slots);
    const kernels::Candidates out{ci.data(), ct.data(), cx.data(), cy.data()};
    const kernels::StrataSpans spans{u0, u1, N, 0, 0, W, W, 1e-3f};
    for (bool runs : {false, true}) {
      // The micropolygons: random places and motions, or runs of 64 in rows of 16 with one motion.
      Rng rng(7);
      std::vector<kernels::MovingBox> boxes(gathers);
      std::vector<float> zCull(gathers);
      float rx = 0, ry = 0, mx = 0, my = 0;
      for (size_t g = 0; g < gathers; ++g) {
        if (!runs || g % 64 == 0) {
          mx = float((rng.uniform() * 2 - 1) * motion), my = float((rng.uniform() * 2 - 1) * motion);
          rx = float(rng.uniform() * W - mx / 2), ry = float(rng.uniform() * W - my / 2);
        }
        const float x = runs ? rx + float(g % 16) : float(rng.uniform() * W - mx / 2);
        const float y = runs ? ry + float(g % 64 / 16) : float(rng.uniform() * W - my / 2);
        if (!runs) mx = float((rng.uniform() * 2 - 1) * motion), my = float((rng.uniform() * 2 - 1) * motion);
        boxes[g] = kernels::MovingBox{x, mx, x + 1.f, mx, y, my, y + 1.f, my, 0.f, 1.f};
        zCull[g] = float(5 + 45 * rng.uniform());
      }
      for (kernels::Isa isa : isas) {
        kernels::SampleRows region{s.st.data(), s.sx.data(), s.sy.data(), 0, size_t(W), W, W, nullptr, 0, N, s.PS, s.z.data(), 0.f};
        double best = INFINITY;
        size_t candidates = 0;
        for (int round = 0; round < 3; ++round) {
          candidates = 0;
          bench::Stopwatch sw;
          for (size_t g = 0; g < gathers; ++g) {
            region.zCull = zCull[g];
            candidates += kernels::gatherStrata(isa, region, spans, boxes[g], out);
          }
          best = std::min(best, sw.seconds());
        }
        std::printf("| %d×%d px | %s | %s | %.1f | %.2f |\n", W, W, runs ? "runs of 64" : "random", isa == kernels::Isa::Avx512 ? "AVX-512" : "AVX2",
                    best / double(gathers) * 1e9, double(candidates) / double(gathers));
      }
    }
  }
  return 0;
}
