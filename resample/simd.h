// The instruction sets the rasterizer's vector kernels are built for, and which of them this CPU
// runs. The kernels themselves are in two groups - sample gathering (resample/gather.h) and the
// exact coverage test (resample/coverage.h) - each written once per instruction set, in its own
// file compiled with that set's flags (simd_avx2.cpp, simd_avx512.cpp), and reached through one
// dispatch (simd_dispatch.cpp) on a table of the set's entry points (simd_isa.h). Every set computes
// every value with the same IEEE operations in the same order (no fused multiply-adds: the module
// builds with -ffp-contract=off), so every set and the scalar loops give bit-identical images;
// ResampleHard.VectorAndScalarKernelsAgree checks it.
//
// Hand-written rather than through Highway (libhwy-dev) or xsimd (libxsimd-dev), both in Debian:
// these are a few loops of a few dozen lines, x86 is the farm's ISA, and the scalar loops serve
// every other CPU; a SIMD framework's multi-target build machinery would outweigh them.
#pragma once

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

}  // namespace reshutter::resample::kernels
