// libFuzzer target for the RIB reader: parses the input (ASCII, binary, gzip: the reader decides
// by content) with a handler that resolves every even-length argument list as parameters, as the
// geometry handlers do. Only reshutter::Error may escape; anything else is a finding.
#include <cstdint>
#include <string_view>

#include "common/error.h"
#include "common/log.h"
#include "rib/rib.h"

using namespace reshutter;

namespace {
struct Handler : rib::RequestHandler {
  bool handle(const rib::Request& r, const rib::Args& a) override {
    if (a.count() % 2 == 0) a.params(0);
    if (a.count() > 0 && r.values[0].isNumber()) a.number(0);
    return r.name.size() % 2 == 0;  // reject some kinds: exercises the warn-once path
  }
};
}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  static bool quiet = (setVerbosity(Verbosity::Quiet), true);
  (void)quiet;
  Handler h;
  try {
    rib::ReaderOptions opt;
    opt.maxArchiveDepth = 0;  // no file system access from fuzz inputs
    rib::Reader reader(opt);
    reader.parseBuffer(std::string_view(reinterpret_cast<const char*>(data), size), "fuzz.rib", h);
  } catch (const Error&) {
  }
  return 0;
}
