// What a RenderSpec asks for, read and checked before a render plans anything: output-variable
// requests, the lens with its overrides, how a lens render pairs its sample planes, whether the
// stores cover the shutter - and the figures a render reports (`--stats`).
#include <algorithm>
#include <cmath>
#include <iomanip>
#include <sstream>

#include "common/error.h"
#include "resample/camera_view.h"
#include "resample/resampler.h"

namespace reshutter::resample {

AovRequest AovRequest::parse(const std::string& text, const std::string& where) {
  AovRequest r;
  auto colon = text.find(':');
  r.name = text.substr(0, colon);
  if (r.name.empty()) fail(where, "empty output variable name in '", text, "'");
  if (colon != std::string::npos) r.filter = FilterSpec::parse(text.substr(colon + 1), where);
  return r;
}

std::string RenderStats::report() const {
  std::ostringstream s;
  s.precision(3);
  const double ste = raster.sampleTests ? double(raster.hits) / double(raster.sampleTests) : 0.0;
  s << std::fixed;
  s << "  samples            " << samples << " (" << buckets << " buckets of " << bucketSize << " px)\n";
  if (raster.midIntervalSamples)
    s << "  sample times       none drawn (an instant, or nothing in the render reads them)" << (raster.pixelMajorSamples ? "; samples pixel-major" : "") << "\n";
  s << "  sample tests       " << raster.sampleTests << "\n";
  s << "  hits               " << raster.hits << "\n";
  s << "  test efficiency    " << ste << " (hits / tests)\n";
  s << "  micropolygons      " << raster.micropolygons << " processed (" << raster.staticMicropolygons << " on the static path, " << raster.linearMicropolygons
    << " bounded from their interval ends, " << raster.chunkGatheredMicropolygons << " of those gathered by chunk, " << raster.chunkCulledMicropolygons
    << " skipped with their chunk), " << raster.parts << " parts (" << raster.transparentParts << " transparent)\n";
  if (raster.groupsTogetherMicropolygons) s << "  fields             " << raster.groupsTogetherMicropolygons << " moving micropolygons drawn for both fields in one pass\n";
  if (raster.lensMicropolygons)
    s << "  lens               " << raster.lensMicropolygons << " micropolygons through the lens (depth of field; " << raster.lensCulledMicropolygons << " of them beyond the bucket's reach), " << raster.lensLayers
      << " bucket samplings sorted by depth layer (layers of " << std::setprecision(2) << lensLayerWidth << std::setprecision(3) << " px, "
      << raster.lensSparseLayers << " sparse; " << raster.lensSortVisited << " samples visited), " << raster.lensScanned
      << " samples in their search boxes (" << std::setprecision(1) << double(raster.lensScanned) / double(raster.lensMicropolygons) << std::setprecision(3)
      << " each), " << raster.lensSegmentDraws << " draws of a knot segment of a curved path\n";
  s << "  fragments          " << raster.fragments << " transparent\n";
  if (volumes.rays)
    s << "  volumes            " << volumes.rays << " ray segments marched, " << volumes.steps << " density lookups, " << volumes.shadowSteps
      << " on shadow rays, " << volumes.cachedShadows << " shadows from the cache, " << volumes.sharedSegments << " segments blended from "
      << volumes.sharedRays << " shared rays\n";
  s << "  parts              " << partsFetched << " fetched, " << partsDecoded << " decoded, " << partsWaited
    << " waited for (another thread was decoding them)";
  if (partsCarried) s << ", " << partsCarried << " carried into the view's camera";
  if (relitVertices) s << ", " << relitVertices << " vertices re-lit for its eye (view-dependent shading)";
  s << "\n";
  if (unseenJudged)
    s << "  unseen             " << unseenSamples << " samples (" << std::setprecision(2) << (samples ? 100.0 * double(unseenSamples) / double(samples) : 0.0)
      << std::setprecision(3) << " %) found nothing where no camera the store records looked: what is there, the store cannot hold\n";
  s << "  time (thread-sum)  set-up " << setupSeconds << " s, parts " << partsSeconds << " s (decode, or wait for another thread's), rasterize "
    << rasterSeconds << " s, resolve " << resolveSeconds << " s, filter " << filterSeconds << " s\n";
  s << "  wall               " << wallSeconds << " s";
  if (wallSeconds > 0) s << ", " << double(samples) / wallSeconds / 1e6 << " M samples/s";
  s << "\n";
  return s.str();
}

store::Lens renderLens(const store::Camera& camera, const RenderSpec::LensOverride& o) {
  if (o.pinhole) return {};
  store::Lens lens = camera.lens;
  if (!o.fstop && !o.focalLength && !o.focalDistance) return lens;
  if (!lens.active() && !(o.fstop && o.focalLength && o.focalDistance))
    fail("--fstop", "the store's camera '", camera.name, "' has no lens (no DepthOfField): give --fstop, --focal-length and --focus-distance together");
  if (o.fstop) lens.fstop = *o.fstop;
  if (o.focalLength) lens.focalLength = *o.focalLength;
  if (o.focalDistance) lens.focalDistance = *o.focalDistance;
  if (!(lens.fstop > 0 && std::isfinite(lens.fstop))) fail("--fstop", "f-stop ", lens.fstop, " is not a positive number");
  if (!(lens.focalLength > 0 && std::isfinite(lens.focalLength))) fail("--focal-length", "focal length ", lens.focalLength, " is not a positive number");
  if (!(lens.focalDistance > 0 && std::isfinite(lens.focalDistance)))
    fail("--focus-distance", "focus distance ", lens.focalDistance, " is not a positive number");
  return lens;
}

int lensTimeBlocks(const RenderSpec& spec) {
  const int N = spec.samplesX * spec.samplesY;
  if (spec.samplesX % 2 || spec.samplesY % 2 || N < 8 || N > 256 || spec.sources.empty()) return 1;
  bool interval = false;
  for (const ShutterGroup& g : spec.shutter.groups()) interval = interval || g.length() > 0;
  if (!interval && spec.shutter.rolling().duration == 0) return 1;
  uint64_t moving = 0, all = 0;
  for (const Source& src : spec.sources) {
    // From a camera that moves against the store's, everything moves.
    const store::StoreMeta& m = src.store->meta();
    const bool carriedMoving = spec.camera && !carryTimes(m.cameras[0], *spec.camera, m.shutterOpen, m.shutterClose).empty();
    for (const store::TileEntry& e : src.store->entries()) {
      all += e.numMicropolygons;
      if (carriedMoving || (e.effects & store::kEffectMoving)) moving += e.numMicropolygons;
    }
  }
  // Time blocks cost a still micropolygon four searches of its box (+27 % instructions for the
  // motion-free bench crop) and spare a moving one most of its path (-30 % for the demo, whose
  // 16 % that move sweep tens of pixels): bench/RESULTS.md, "Twenty-ninth session".
  return 12 * moving >= all && moving > 0 ? N / 4 : 1;
}

void checkCoverage(const std::vector<Source>& sources, const ShutterModel& shutter) {
  if (sources.empty()) fail("resample", "no store to re-sample");
  std::vector<std::pair<double, double>> cover;
  for (const auto& s : sources) cover.push_back({s.coverStart(), s.coverEnd()});
  std::sort(cover.begin(), cover.end());
  for (size_t g = 0; g < shutter.groups().size(); ++g) {
    double t0, t1;
    shutter.timeRange(int(g), 0.0, double(shutter.rolling().height), 0.0, 1.0, t0, t1);
    // Walk the needed interval through the sorted coverage; report the first gap.
    double at = t0;
    const double eps = 1e-9 * std::max(1.0, std::abs(t1));
    for (const auto& [a, b] : cover) {
      if (a > at + eps) break;
      at = std::max(at, b);
    }
    if (at + eps < t1 || (t0 == t1 && !std::any_of(cover.begin(), cover.end(), [&](auto c) { return t0 >= c.first - eps && t0 <= c.second + eps; }))) {
      double gapStart = at, gapEnd = t1;
      for (const auto& [a, b] : cover)
        if (a > at + eps) {
          gapEnd = std::min(t1, a);
          break;
        }
      std::ostringstream have;
      for (size_t i = 0; i < sources.size(); ++i)
        have << (i ? ", " : "") << sources[i].store->path() << " [" << sources[i].coverStart() << ", " << sources[i].coverEnd() << "]";
      if (t0 == t1) fail("shutter", "time ", t0, " (frames) is not covered by any store; stores cover ", have.str());
      fail("shutter", "frames ", gapStart, " to ", gapEnd, " are not covered by any store (needed ", t0, " to ", t1, "); stores cover ", have.str());
    }
  }
}

}  // namespace reshutter::resample
