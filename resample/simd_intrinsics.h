// <immintrin.h> for the vector kernel files (simd_avx2*.cpp, simd_avx512.cpp), without the
// uninitialised-variable warnings GCC raises inside its own intrinsic headers at -O2.
#pragma once

#pragma GCC diagnostic push
#if !defined(__clang__)  // GCC's own warning (clang, the fuzz build's compiler, has no such group)
#pragma GCC diagnostic ignored "-Wmaybe-uninitialized"
#endif
#pragma GCC diagnostic ignored "-Wuninitialized"
#include <immintrin.h>
#pragma GCC diagnostic pop
