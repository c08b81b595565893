// libFuzzer target for the .mps reader: opens the input as a store (see store_fuzz_input.h),
// verifies it and decodes every part. Only reshutter::Error may escape the library; anything else
// (a crash, a sanitizer report, another exception type) is a finding.
#include <cstdint>
#include <cstring>
#include <string>
#include <vector>

#include <sys/mman.h>
#include <unistd.h>

#include "common/error.h"
#include "common/log.h"
#include "store/codec.h"
#include "store/format.h"
#include "store/reader.h"
#include "tests/fuzz/store_fuzz_input.h"

using namespace reshutter;
using namespace reshutter::store;

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  static bool quiet = (setVerbosity(Verbosity::Quiet), true);
  (void)quiet;
  if (size == 0) return 0;
  std::vector<uint8_t> bytes = storeFromFuzzInput(data, size);
  int fd = ::memfd_create("fuzz.mps", 0);
  if (fd < 0) return 0;
  if (!bytes.empty() && ::write(fd, bytes.data(), bytes.size()) != ssize_t(bytes.size())) {
    ::close(fd);
    return 0;
  }
  std::string path = "/proc/self/fd/" + std::to_string(fd);
  try {
    ReaderOptions opt;
    opt.cacheBytes = 1 << 20;
    StoreReader reader(path, opt);
    reader.verify();
    for (size_t e = 0; e < reader.entries().size(); ++e) reader.part(e);
    reader.visit(RasterRect{0, 0, 100, 100, false}, reader.meta().shutterOpen, reader.meta().shutterClose, [](size_t) {});
  } catch (const Error&) {
  }
  ::close(fd);
  return 0;
}
