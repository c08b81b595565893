// A module with a 48-byte general-dynamic TLS block: the shape that crashed LeakSanitizer's tracer
// at exit under GCC 12's runtime (common/sanitizer_defaults.cpp says why). Built only in
// sanitizer builds, for dynamic_tls_exit.cpp.
#include <cstdlib>

namespace {
struct alignas(16) Block {
  void* words[6];
};
thread_local Block block;
}  // namespace

// Makes the calling thread's block (a heap block of glibc's, for a dlopen'd module), holds a heap
// block reachable only through it, and returns where it is.
extern "C" __attribute__((visibility("default"))) void* holdInDynamicTls() {
  block.words[0] = std::malloc(100);
  return &block;
}
