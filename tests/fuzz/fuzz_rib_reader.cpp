// libFuzzer target for the RIB reader and the scene interpreter behind `reshutter shade`: parses
// the input (ASCII, binary, gzip: the reader decides by content) into the shading pass's Scene
// (every request the shading pass takes: options, state, motion blocks, conditionals, objects,
// every primitive's checks and construction, OpenSubdiv's refinement included), without dicing.
// Only reshutter::Error may escape; anything else is a finding.
#include <cstdint>
#include <string_view>

#include "common/error.h"
#include "common/log.h"
#include "rib/rib.h"
#include "shade/rib_scene.h"
#include "shade/scene.h"

using namespace reshutter;

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  static bool quiet = (setVerbosity(Verbosity::Quiet), true);
  (void)quiet;
  try {
    shade::Scene scene([](shade::FrameScene&) {});
    shade::RibSceneHandler handler(scene);
    rib::ReaderOptions opt;
    opt.maxArchiveDepth = 0;  // no file system access from fuzz inputs
    rib::Reader reader(opt);
    reader.parseBuffer(std::string_view(reinterpret_cast<const char*>(data), size), "fuzz.rib", handler);
  } catch (const Error&) {
  }
  return 0;
}
