// The one dispatch of the vector kernels: which instruction sets this CPU runs, and each kernel's
// call through the chosen set's table (simd_isa.h). Compiled for baseline x86-64 like the rest of
// the program; on other CPUs no set is available and the rasterizer keeps to its scalar loops.
#include "common/check.h"
#include "resample/simd_isa.h"

namespace reshutter::resample::kernels {

#if defined(__x86_64__) || defined(__i386__)

bool available() {
  static const bool ok = __builtin_cpu_supports("avx2") && __builtin_cpu_supports("popcnt");
  return ok;
}

bool available(Isa isa) {
  if (isa == Isa::Avx2) return available();
  static const bool ok = available() && __builtin_cpu_supports("avx512f") && __builtin_cpu_supports("avx512bw") && __builtin_cpu_supports("avx512dq") &&
                         __builtin_cpu_supports("avx512vl") && __builtin_cpu_supports("bmi2");
  return ok;
}

namespace {
const IsaKernels& kernelsFor(Isa isa) { return isa == Isa::Avx512 ? kAvx512Kernels : kAvx2Kernels; }
}  // namespace

#else

bool available() { return false; }
bool available(Isa) { return false; }

namespace {
const IsaKernels& kernelsFor(Isa) {
  static const IsaKernels none{};
  CHECK(false, "vector kernels called on a CPU without them");
  return none;
}
}  // namespace

#endif

size_t gatherInBox(Isa isa, const SampleRows& rows, const MovingBox& box, const Candidates& out, size_t n) {
  return kernelsFor(isa).gatherInBox(rows, box, out, n);
}

size_t gatherLensCells(Isa isa, const LensCells& cells, size_t stride, const LensSearch* searches, size_t count, const LensBox& box, uint32_t* positions,
                       size_t n) {
  return kernelsFor(isa).gatherLensCells(cells, stride, searches, count, box, positions, n);
}

size_t testMovingLens(Isa isa, const MovingLensSetup& setup, size_t n, EdgeHit* hits) { return kernelsFor(isa).testMovingLens(setup, n, hits); }

size_t lensLayerCells(Isa isa, const LensShear& shear, const float* x, const float* y, const float* u, const float* v, const float* depth, const LensRuns& runs,
                      uint32_t key, uint32_t* slot, uint32_t* cell, size_t n) {
  return kernelsFor(isa).lensLayerCells(shear, x, y, u, v, depth, runs, key, slot, cell, n);
}

size_t gatherStrata(Isa isa, const SampleRows& region, const StrataSpans& spans, const MovingBox& box, const Candidates& out) {
  CHECK(spans.strata <= 64, "more than 64 time strata per pixel for the vector kernels");
  return kernelsFor(isa).gatherStrata(region, spans, box, out);
}

size_t filterCandidates(Isa isa, const Candidates& in, size_t begin, size_t end, const MovingBox& box, const Candidates& out, size_t n) {
  return kernelsFor(isa).filterCandidates(in, begin, end, box, out, n);
}

void sortByCell(Isa isa, const CellGrid& g, const Candidates& in, size_t n, const Candidates& out, uint32_t* cellStart, uint16_t* cellOf) {
  kernelsFor(isa).cellsOf(g, in.t, in.x, in.y, n, cellOf);
  const int cells = g.cols * g.rows;
  for (int k = 0; k <= cells; ++k) cellStart[k] = 0;
  for (size_t i = 0; i < n; ++i) ++cellStart[cellOf[i] + 1];
  for (int k = 0; k < cells; ++k) cellStart[k + 1] += cellStart[k];
  // Scatter, counting up from each cell's start (then shifted back by one cell).
  for (size_t i = 0; i < n; ++i) {
    const uint32_t d = cellStart[cellOf[i]]++;
    out.index[d] = in.index[i], out.t[d] = in.t[i], out.x[d] = in.x[i], out.y[d] = in.y[i];
  }
  for (int k = cells; k > 0; --k) cellStart[k] = cellStart[k - 1];
  cellStart[0] = 0;
}

bool projectLerped(Isa isa, const float* a, const float* b, float f, size_t n, const ProjectionScale& scale, float* x, float* y, float* z, float box[4]) {
  return kernelsFor(isa).projectLerped(a, b, f, n, scale, x, y, z, box);
}

void cornerRange(Isa isa, const uint32_t* corners, size_t count, uint32_t& lo, uint32_t& hi) { kernelsFor(isa).cornerRange(corners, count, lo, hi); }
float nearestDepth(Isa isa, const float* xyz, size_t n, float nearest) { return kernelsFor(isa).nearestDepth(xyz, n, nearest); }

void stillAreas(Isa isa, const StillAreaSetup& setup, size_t count, const StillAreas& out) { kernelsFor(isa).stillAreas(setup, count, out); }
void lensDraws(Isa isa, const LensQueueSetup& setup, size_t count, const LensDraws& out) { kernelsFor(isa).lensDraws(setup, count, out); }

void linearEdges(Isa isa, const float* const at[4], const float* const to[4], const RasterScale& scale, LinearEdges& out) {
  kernelsFor(isa).linearEdges(at, to, scale, out);
}

void fixedEdges(Isa isa, const float* const at[4], const RasterScale& scale, LinearEdges& out) { kernelsFor(isa).fixedEdges(at, scale, out); }
void stillLensEdges(Isa isa, const float* const at[4], bool triangle, double invD, const RasterScale& scale, LinearEdges& out) {
  kernelsFor(isa).stillLensEdges(at, triangle, invD, scale, out);
}

size_t testLinearEdges(Isa isa, const EdgeTestSetup& setup, const LinearEdges& edges, size_t n, EdgeHit* hits) {
  const IsaKernels& k = kernelsFor(isa);
  return setup.su ? k.testLensEdges(setup, edges, n, hits) : setup.fixed ? k.testFixedEdges(setup, edges, n, hits) : k.testMovingEdges(setup, edges, n, hits);
}

}  // namespace reshutter::resample::kernels
