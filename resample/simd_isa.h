// Inside the vector kernels: each instruction set's entry points as one table (simd_avx2.cpp and
// simd_avx512.cpp each define theirs), which simd_dispatch.cpp chooses from. Only the kernel
// files and the dispatch include this.
//
// The kernel files are compiled with their instruction set's flags, so any function they share
// with the rest of the program through a header (an inline function or template, emitted as a
// weak symbol when not inlined) could be compiled with those flags and picked by the linker for
// every caller - an illegal instruction on a CPU without them. So they use intrinsics, builtins
// and functions of internal linkage only (no <algorithm>), as writeEdgeHits() below is.
#pragma once

#include <cstddef>
#include <cstdint>

#include "resample/coverage.h"
#include "resample/gather.h"

namespace reshutter::resample::kernels {

// The edge test's kinds of edges (the kernels' template argument): quadratic in a moving
// micropolygon's segment parameter, fixed, or affine in the lens point (a still micropolygon seen
// through a lens).
inline constexpr int kMovingEdges = 0, kFixedEdges = 1, kLensEdges = 2;

struct IsaKernels {
  size_t (*gatherInBox)(const SampleRows& rows, const MovingBox& box, const Candidates& out, size_t n);
  size_t (*gatherStrata)(const SampleRows& region, const StrataSpans& spans, const MovingBox& box, const Candidates& out);
  size_t (*filterCandidates)(const Candidates& in, size_t begin, size_t end, const MovingBox& box, const Candidates& out, size_t n);
  /// sortByCell()'s cell of each of n candidates (times t, positions x, y).
  void (*cellsOf)(const CellGrid& grid, const float* t, const float* x, const float* y, size_t n, uint16_t* cellOf);
  bool (*projectLerped)(const float* a, const float* b, float f, size_t n, const ProjectionScale& scale, float* x, float* y, float* z, float box[4]);
  void (*stillAreas)(const StillAreaSetup& setup, size_t count, const StillAreas& out);
  void (*lensDraws)(const LensQueueSetup& setup, size_t count, const LensDraws& out);
  void (*cornerRange)(const uint32_t* corners, size_t count, uint32_t& lo, uint32_t& hi);
  float (*nearestDepth)(const float* xyz, size_t n, float nearest);
  void (*linearEdges)(const float* const at[4], const float* const to[4], const RasterScale& scale, LinearEdges& out);
  void (*fixedEdges)(const float* const at[4], const RasterScale& scale, LinearEdges& out);
  void (*stillLensEdges)(const float* const at[4], bool triangle, double invD, const RasterScale& scale, LinearEdges& out);
  size_t (*testMovingEdges)(const EdgeTestSetup& setup, const LinearEdges& edges, size_t n, EdgeHit* hits);  // setup.fixed false
  size_t (*testFixedEdges)(const EdgeTestSetup& setup, const LinearEdges& edges, size_t n, EdgeHit* hits);   // setup.fixed true
  size_t (*testLensEdges)(const EdgeTestSetup& setup, const LinearEdges& edges, size_t n, EdgeHit* hits);    // setup.su set
  size_t (*gatherLensCells)(const LensCells& cells, size_t stride, const LensSearch* searches, size_t count, const LensBox& box, uint32_t* positions, size_t n);
  size_t (*testMovingLens)(const MovingLensSetup& setup, size_t n, EdgeHit* hits);
  size_t (*lensLayerCells)(const LensShear& shear, const float* x, const float* y, const float* u, const float* v, const float* depth, const LensRuns& runs,
                          uint32_t key, uint32_t* slot, uint32_t* cell, size_t n);
};

#if defined(__x86_64__) || defined(__i386__)
extern const IsaKernels kAvx2Kernels;
extern const IsaKernels kAvx512Kernels;

// The AVX2 kernels that the AVX-512 table shares.
namespace avx2 {
bool projectLerped(const float* a, const float* b, float f, size_t n, const ProjectionScale& scale, float* x, float* y, float* z, float box[4]);
void stillAreas(const StillAreaSetup& setup, size_t count, const StillAreas& out);
void lensDraws(const LensQueueSetup& setup, size_t count, const LensDraws& out);
void cornerRange(const uint32_t* corners, size_t count, uint32_t& lo, uint32_t& hi);
float nearestDepth(const float* xyz, size_t n, float nearest);
void stillLensEdges(const float* const at[4], bool triangle, double invD, const RasterScale& scale, LinearEdges& out);
}  // namespace avx2
#endif

namespace {

// Writes one group of L candidates' outcomes (candidates i .. i + L - 1) from hits[h]: bz[t][k]
// holds triangle t's barycentrics (k = 0-2) and depth (k = 3) by lane. Every lane is written and
// the count advances by whether it is kept: how many hit is data the predictor cannot learn, and
// which triangle a sample hit is a coin toss, so it indexes rather than branches. (The list has
// room for L - 1 entries past the last kept.)
template <int L>
inline __attribute__((always_inline)) size_t writeEdgeHits(const float (&bz)[2][4][L], unsigned undecided, unsigned hitB, unsigned any, size_t i, EdgeHit* hits,
                                                           size_t h) {
  for (int l = 0; l < L; ++l) {
    EdgeHit& out = hits[h];
    out.candidate = uint32_t(i + size_t(l));
    out.undecided = (undecided >> l) & 1;
    const int tri = (hitB >> l) & 1;
    out.triangle = uint8_t(tri);
    const float(*b)[L] = bz[tri];
    out.b[0] = b[0][l], out.b[1] = b[1][l], out.b[2] = b[2][l];
    out.z = b[3][l];
    h += size_t((any >> l) & 1);
  }
  return h;
}

// Smallest and largest of n floats, the first of equals (std::min_element's and max_element's
// choice), without <algorithm> (see above).
inline float lowest(const float* v, int n) {
  float m = v[0];
  for (int i = 1; i < n; ++i) m = v[i] < m ? v[i] : m;
  return m;
}
inline float highest(const float* v, int n) {
  float m = v[0];
  for (int i = 1; i < n; ++i) m = m < v[i] ? v[i] : m;
  return m;
}
inline int minInt(int a, int b) { return b < a ? b : a; }

// lensLayerCells()' loads, a line of each stream kLensRunsAhead samples ahead of sample i of run
// r (past the run's end, into the next run): a layer's sort reads the bucket's sample planes in
// runs of about a hundred slots, which a hardware prefetcher does not follow far enough ahead
// (measured, bench/RESULTS.md: 64 ahead, -1 to -3 % of the 20 px lens crop; 32 and 128 no better).
inline constexpr size_t kLensRunsAhead = 64;
inline void prefetchLensRuns(const LensRuns& runs, size_t r, size_t i, size_t count, const float* xs, const float* ys, const float* us, const float* vs,
                             const float* depth) {
  size_t at = runs.first[r] + i + kLensRunsAhead;
  if (i + kLensRunsAhead >= count) {
    if (r + 1 >= runs.n) return;
    at = runs.first[r + 1] + (i + kLensRunsAhead - count);
  }
  __builtin_prefetch(xs + at), __builtin_prefetch(ys + at), __builtin_prefetch(us + at), __builtin_prefetch(vs + at), __builtin_prefetch(depth + at);
}

}  // namespace

}  // namespace reshutter::resample::kernels
