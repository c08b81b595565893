// Sanitizer builds' default runtime options, compiled into every executable of a build with
// AddressSanitizer (common/CMakeLists.txt adds it; ASAN_OPTIONS still overrides each one).
//
// intercept_tls_get_addr=0: up to GCC 13 and LLVM 16 (Debian 12 has GCC 12 and clang 14), the
// runtime's __tls_get_addr interceptor takes a dynamic TLS block that starts 16 bytes into a
// page for a glibc-2.18 block with a header, and reads the two words before it as the block's
// bounds; LeakSanitizer's tracer then scans garbage at exit and dies of signal 11. glibc has
// had no such header since 2.25, and ASan's allocator puts a small malloc'd block at that
// offset once per size-class slot cycle, so any process that dlopens a library with a small
// general-dynamic TLS block (the OpenImageIO and OpenVDB modules' trees) could fail after every
// test had passed. Without the interceptor, memory held from dynamic TLS is still reached
// through glibc's DTV, itself a heap block: no false leaks (bench/RESULTS.md, "CI time").
extern "C" const char* __asan_default_options() { return "intercept_tls_get_addr=0"; }
