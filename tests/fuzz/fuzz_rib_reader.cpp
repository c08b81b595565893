// libFuzzer target for the RIB reader and the scene interpreter behind `reshutter shade`: parses
// the input (ASCII, binary, gzip: the reader decides by content) into the shading pass's Scene
// (every request the shading pass takes: options, state, motion blocks, conditionals, objects,
// every primitive's checks and construction, OpenSubdiv's refinement included), then splits
// every primitive of each frame for its camera (made small, and the shading rate at least one
// pixel, so an input cannot ask for millions of micropolygons) and dices its first leaves.
// Only reshutter::Error may escape; anything else is a finding.
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <string_view>

#include "common/error.h"
#include "common/log.h"
#include "rib/rib.h"
#include "shade/dice.h"
#include "shade/rib_scene.h"
#include "shade/scene.h"
#include "shade/split.h"

using namespace reshutter;

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  static bool quiet = (setVerbosity(Verbosity::Quiet), true);
  (void)quiet;
  try {
    shade::Scene scene([](shade::FrameScene& f) {
      // Cameras made small: the fuzzer's resolutions would otherwise dice for minutes.
      auto small = [](store::Camera c) {
        c.width = std::clamp(c.width, 1, 48), c.height = std::clamp(c.height, 1, 36);
        return c;
      };
      const store::Camera cam = small(f.options.camera);
      const bool perspective = cam.projection == store::Projection::Perspective;
      size_t prims = 0;
      for (const shade::Primitive& p : f.prims) {
        if (++prims > 16) break;
        const double rate = p.attrs->shadingRate;
        if (!(rate > 0) || !std::isfinite(rate)) continue;
        shade::DiceOptions o;
        o.shadingRateScale = rate < 1 ? 1 / rate : 1;
        o.maxMicropolygonsPerPrimitive = 20000;
        const auto knots = shade::clipKnots(p, f.options.shutterOpen, f.options.shutterClose);
        std::vector<shade::Leaf> leaves;
        shade::DiceStats stats;
        // The scene's named cameras too (at most two): a piece any of them sees is kept.
        std::vector<store::Camera> others;
        for (size_t i = 0; i < f.options.namedCameras.size() && i < 2; ++i) others.push_back(small(f.options.namedCameras[i]));
        shade::splitPrimitive(p, knots, cam, others, o, leaves, stats);
        shade::DicedGrid grid;
        for (size_t i = 0; i < leaves.size() && i < 4; ++i) shade::diceLeaf(p, leaves[i], knots, knots[0], cam.nearClip, perspective, grid);
      }
    });
    shade::RibSceneHandler handler(scene);
    rib::ReaderOptions opt;
    opt.maxArchiveDepth = 0;  // no file system access from fuzz inputs
    rib::Reader reader(opt);
    reader.parseBuffer(std::string_view(reinterpret_cast<const char*>(data), size), "fuzz.rib", handler);
  } catch (const Error&) {
  }
  return 0;
}
