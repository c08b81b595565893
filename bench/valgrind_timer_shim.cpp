// Lets valgrind (cachegrind, callgrind) run the shading pass. The demo's textures load
// OpenImageIO's module, which loads libhwy, whose load-time timer calibration executes RDTSCP -
// an instruction valgrind 3.19 cannot decode (SIGILL). Preloaded (LD_PRELOAD), this library's
// definitions take the place of libhwy's calls through its PLT; nothing in reshutter reads
// Highway's timers, so instruction counts are unaffected. bench/shade_in_time.sh uses it.
#include <cstdint>

namespace hwy::platform {
__attribute__((visibility("default"))) uint64_t TimerResolution() { return 1; }
__attribute__((visibility("default"))) double InvariantTicksPerSecond() { return 1e9; }
}  // namespace hwy::platform
