// The bucket rasterizer's vectorised inner loops: gathering one time stratum's samples that lie in
// a micropolygon's moving box, row by row; the exact double-precision edge test of a list of
// candidates against a micropolygon moving linearly inside one knot segment; and their set-up
// (projecting a chunk's vertices, a micropolygon's edge functions).
//
// They are written with AVX2 intrinsics in functions compiled for AVX2 only, chosen at run time
// (kernels::available()), so the binary still runs on any x86-64 node; raster.cpp keeps the scalar
// loops as the fallback. Both compute every value with the same IEEE operations in the same order
// (no fused multiply-adds: AVX2 does not imply FMA, and the module builds with -ffp-contract=off),
// so the two paths give bit-identical images; ResampleHard.VectorAndScalarKernelsAgree checks it.
// Hand-written rather than through Highway (libhwy-dev) or xsimd (libxsimd-dev), both in Debian:
// these are two loops of a few dozen lines, x86 is the farm's ISA, and the scalar fallback serves
// every other CPU; a SIMD framework's multi-target build machinery would outweigh them.
#pragma once

#include <cmath>
#include <cstddef>
#include <cstdint>

namespace reshutter::resample::kernels {

/// The instruction sets of the kernels: AVX2 for all of them; AVX-512 (F, BW, DQ, VL) for the
/// gathers (sixteen lanes, as four row segments of up to four samples) and the edge test (eight
/// candidates), the set-up kernels staying AVX2. Every set gives the same candidates and hits,
/// so the same image; AVX-512 only where the CPU has it (server x86 since 2017).
enum class Isa : uint8_t { Avx2, Avx512 };

/// True when this CPU runs the AVX2 kernels (checked once).
bool available();
/// True when this CPU runs the kernels of `isa`.
bool available(Isa isa);

/// An axis-aligned box moving linearly over a time span: [x0 + u dx0, x1 + u dx1] ×
/// [y0 + u dy0, y1 + u dy1] at u = clamp((st - thetaA) invLen, 0, 1). A fixed box has zero d's.
struct MovingBox {
  float x0, dx0, x1, dx1, y0, dy0, y1, dy1;
  float thetaA = 0, invLen = 0;
};

/// Strata's samples laid out row-major over the region, one plane per stratum:
/// index = first + plane * planeStride + row * stride + col.
struct SampleRows {
  const float* st;  // sample time offsets
  const float* sx;  // raster positions
  const float* sy;
  size_t first;     // index of the range's first sample
  size_t stride;    // region width
  int cols, rows;
  const uint8_t* rowGroup = nullptr;  // when set: skip rows whose group differs from `group`
  uint8_t group = 0;
  int planes = 1;
  size_t planeStride = 0;
  // Early depth test (required: the gathers always read `depth`): only samples whose nearest
  // surface so far (indexed like st) lies beyond zCull are kept; a surface no nearer than zCull
  // cannot change the others. zCull = -INFINITY keeps every sample.
  const float* depth = nullptr;
  float zCull = -INFINITY;
};

/// A list of candidate samples: each one's index and a copy of its time and position, so that
/// the edge test reads them in order instead of gathering them from the sample arrays.
struct Candidates {
  uint32_t* index;
  float* t;
  float* x;
  float* y;
};

/// Appends to `out` from position n the samples in `rows` (plane by plane; a fixed box of at most
/// 2×2 pixels takes two planes at a time, their candidates interleaved) that lie inside `box` at
/// their own time and pass the early depth test; returns the new count. Reads up to 7 floats
/// past a row's end (arrays need that padding) and writes up to 15 entries past the returned count.
size_t gatherInBox(Isa isa, const SampleRows& rows, const MovingBox& box, const Candidates& out, size_t n);

/// The strata of one moving box: stratum s covers box times u in [u0[s], u1[s]] and its
/// samples are plane s of `rows` (whose first/cols/rows describe the whole region).
struct StrataSpans {
  const float* u0;
  const float* u1;
  int strata;
  int x0, y0, w, h;  // the region, raster pixels
  float margin;      // widening for float rounding of the box (pixelRange's margin or more)
};

/// For each stratum, the pixels its part of the box's path touches, then gatherInBox() over
/// them: one call per micropolygon instead of one per stratum. The same candidates, in an order
/// of its own (small strata share vectors, and the strata are visited kind by kind).
size_t gatherStrata(Isa isa, const SampleRows& region, const StrataSpans& spans, const MovingBox& box, const Candidates& out);

/// Cells for the micropolygons of one chunk, in compensated position: a candidate at raster
/// (x, y) and box time u (MovingBox's u) sits at (x - u dx, y - u dy), taking out a reference
/// motion (dx, dy) that the chunk's micropolygons share more or less, so that each one's box over
/// the whole interval, compensated, stays about its own size. Square cells of `size` pixels.
struct CellGrid {
  float x0, y0;     // compensated position of cell (0, 0)'s corner
  float invSize;    // 1 / cell size
  int cols, rows;   // cols * rows <= 65535
  float dx, dy;     // the reference motion
  float thetaA, invLen;
};

/// Sorts candidates [0, n) of `in` into `out` (same layout, room for n) by their cell, row-major;
/// positions outside the grid clamp to its border cells. cellStart (cols * rows + 1 entries)
/// receives each cell's first position in `out`, and the total at the end; `scratch` needs n + 16
/// entries, `in` 15 readable entries past n.
void sortByCell(Isa isa, const CellGrid& grid, const Candidates& in, size_t n, const Candidates& out, uint32_t* cellStart, uint16_t* scratch);

/// Appends to `out` from position n the candidates [begin, end) of `in` that lie inside `box` at
/// their own time (gatherInBox()'s test) and whose nearest surface so far, depth[index], lies
/// beyond zCull; returns the new count. Reads up to 15 entries past `end`, writes up to 15 past
/// the count.
size_t filterCandidates(Isa isa, const Candidates& in, size_t begin, size_t end, const MovingBox& box, const float* depth, float zCull,
                        const Candidates& out, size_t n);

/// A micropolygon's edges over one knot segment, component-major: edge e's cross product is
/// c[0..2][e] + f (c[3..5][e] + f c[6..8][e]) at segment parameter f (edges 01 12 23 30 02;
/// lanes 5-7 are padding).
struct LinearEdges {
  double c[9][8];
};

/// The camera's map from homogeneous camera space to raster edges, as the rasterizer's
/// toRaster() applies it to a cross product e: (e.x invAx, e.y invAy, (e.z - ex bx) - ey by).
struct RasterScale {
  double invAx, invAy, bx, by;
  bool perspective;  // homogeneous point (x, y, z); otherwise (x, y, 1)
};

/// The edges of the micropolygon with corners at[j] at a knot segment's start and to[j] at its end
/// (camera-space xyz; a triangle passes corner 2 as corner 3, and edges 23 and 30 are then
/// meaningless): E = A_a × A_b + f (A_a × D_b + D_a × A_b) + f² D_a × D_b with D = to - at, in
/// the rasterizer's prepareEdges() operations and order, so bit-identical to it.
void linearEdges(Isa isa, const float* const at[4], const float* const to[4], const RasterScale& scale, LinearEdges& out);
/// A static micropolygon's edges: c[0..2] only (A_a × A_b), the rasterizer's static-path
/// operations and order.
void fixedEdges(Isa isa, const float* const at[4], const RasterScale& scale, LinearEdges& out);

/// The camera's map from camera space to raster, as the rasterizer's project() applies it:
/// x = float(ax (x / z) + bx) with the division as 1 / z in double (perspective), or
/// float(ax x + bx); a point before the near plane, or one that lands off the float range, has
/// no raster position.
struct ProjectionScale {
  double ax, bx, ay, by;
  float nearClip;
  bool perspective;
};

/// Points p_i = a_i + f (b_i - a_i) for i < n (a and b: xyz triples), projected: x[i], y[i] their
/// raster position (x[i] NaN where there is none, y[i] then unspecified), z[i] the depth p_i.z;
/// project()'s operations, bit for bit. Returns whether any x is NaN; box = min x, min y, max x,
/// max y over the others.
bool projectLerped(Isa isa, const float* a, const float* b, float f, size_t n, const ProjectionScale& scale, float* x, float* y, float* z, float box[4]);

struct EdgeTestSetup {
  const float* st;  // the candidates' times and raster positions (Candidates::t, x, y)
  const float* sx;
  const float* sy;
  float fOffset, fScale;  // f = clamp((st + fOffset) fScale, 0, 1)
  bool triangle;          // edges 23 and 30 unused
  bool cullBackFaces;     // back-face knock-out applies to this micropolygon
  bool fixed = false;     // a static micropolygon: the edges are c[e][0..2] at any time (f = 0)
  float za[4] = {}, zb[4] = {};  // corner depths at the segment's two ends (equal when fixed)
};

/// One decided candidate: which triangle it hit (0: p0 p1 p2, 1: p0 p2 p3), its barycentrics
/// and depth; `undecided` when an edge value was exactly zero and the tie rule (which needs the
/// edge vectors) must decide in scalar code. The depth is the scalar paths' float arithmetic at
/// the segment parameter f: zv_j = za_j + f (zb_j - za_j), z = (b0 zv_0 + b1 zv_j1) + b2 zv_j2.
struct EdgeHit {
  uint32_t candidate;  // position in the candidate list
  uint8_t triangle;
  bool undecided;
  float b[3];
  float z;
};

/// Tests candidates 0..n) and appends the hits and undecided ones, in candidate order, to `hits`;
/// returns how many. The list needs room for n + 7 entries, the candidate arrays 7 readable
/// entries past n.
size_t testLinearEdges(Isa isa, const EdgeTestSetup& setup, const LinearEdges& edges, size_t n, EdgeHit* hits);

}  // namespace reshutter::resample::kernels
