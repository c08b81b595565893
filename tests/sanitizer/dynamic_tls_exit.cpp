// Sanitizer builds: a process whose live thread has a dlopen'd module's dynamic TLS block 16 bytes
// into a page - the block the GCC 12 runtime's __tls_get_addr interceptor mistakes for a
// glibc-2.18 one (common/sanitizer_defaults.cpp) - still gets a working leak check at exit. The
// runtime's default options are linked in as in every executable of the build. The test passes
// when LeakSanitizer reports exactly the one block lost on purpose below: the check ran to the end,
// and the block held from dynamic TLS was not taken for a leak. Without those defaults the tracer
// dies of signal 11 in every run (tests/CMakeLists.txt holds the expected report).
#include <dlfcn.h>
#include <unistd.h>

#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <future>
#include <thread>

namespace {
__attribute__((noinline)) void loseABlock() {
  void* volatile p = std::malloc(77);
  p = nullptr;
  (void)p;
}
// Overwrites the stack that loseABlock() used, so no stale copy of its pointer keeps it reachable.
__attribute__((noinline)) void scrubStack() {
  volatile char pad[8192];
  for (int i = 0; i < 8192; ++i) pad[i] = 0;
  (void)pad[0];
}
}  // namespace

int main() {
  void* module = dlopen(RESHUTTER_DYNAMIC_TLS_MODULE, RTLD_NOW | RTLD_LOCAL);
  auto hold = module ? reinterpret_cast<void* (*)()>(dlsym(module, "holdInDynamicTls")) : nullptr;
  if (!hold) {
    std::fprintf(stderr, "%s: cannot load holdInDynamicTls (%s)\n", RESHUTTER_DYNAMIC_TLS_MODULE, dlerror());
    return 2;
  }
  // Each new thread gets a block of its own; the allocator puts one at page offset 16 about once
  // in 64. That thread stays alive (parked) until exit, so the leak check scans its TLS.
  int threads = 0;
  bool found = false;
  while (!found && threads < 4096) {
    ++threads;
    std::promise<bool> atOffset16;
    std::future<bool> answer = atOffset16.get_future();
    std::thread t([&] {
      const bool hit = (reinterpret_cast<uintptr_t>(hold()) & 4095) == 16;
      atOffset16.set_value(hit);
      while (hit) pause();
    });
    found = answer.get();
    if (found) t.detach();
    else t.join();
  }
  if (!found) {
    std::fprintf(stderr, "no dynamic TLS block at page offset 16 in %d threads: the test cannot check the leak check\n", threads);
    return 3;
  }
  std::fprintf(stderr, "a dynamic TLS block at page offset 16 in thread %d; one block lost on purpose\n", threads);
  loseABlock();
  scrubStack();
  return 0;
}
