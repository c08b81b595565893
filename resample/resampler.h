// The re-sampler: renders the motion-blurred image a renderer would have produced for a shutter
// (any sub-interval, per-row intervals, rolling read-out) from one or more stores, without
// shading anything again. Buckets are processed in parallel (TBB); each gathers only the tile
// parts whose bounds over its time range touch it, rasterizes them (raster.h), composites each
// sample and filters the samples into pixels. Output is bit-identical for any thread count and
// bucket size.
#pragma once

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <functional>
#include <map>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "resample/deep.h"
#include "resample/filter.h"
#include "resample/image.h"
#include "resample/raster.h"
#include "resample/shutter.h"
#include "resample/volume.h"

namespace reshutter::resample {

struct AovRequest {
  std::string name;                  // a store attribute, "id" (object id) or "z" (camera depth)
  std::optional<FilterSpec> filter;  // default: the pixel filter, or zmin for ids
  /// "N", "N:gaussian:2x2", "id:zmin". Throws Error naming `where`.
  static AovRequest parse(const std::string& text, const std::string& where);
};

/// Bucket sizes, measured (bench/RESULTS.md); images are the same for any size. RenderSpec's
/// default, kAutoBucketSize, picks one per render: kStillBucketSize where the samples are
/// pixel-major (no time drawn, no lens: BucketSamples::pixelMajor), whose static path gathers a
/// micropolygon's samples from a few cache lines and gains from a bucket that stays in L2 (64:
/// 5-10 % less render wall than 96); through a lens lensBucketSize(); else kBucketSize (with
/// motion, 10 % less CPU than 64 and 30 % less than 32, within the noise of 48 and 128).
inline constexpr int kBucketSize = 96;
inline constexpr int kStillBucketSize = 64;
inline constexpr int kAutoBucketSize = 0;

/// Through a lens, from the circle of confusion a micropolygon typically takes (radius, raster
/// pixels): a bucket's layer sorts and gathers want it small enough to stay in cache, and each
/// micropolygon is drawn in every bucket its blurred footprint reaches, which wants it large
/// against the circle. Fitted to the 1080p bench frames ("Depth of field" in bench/RESULTS.md):
/// without sample times the best of 32-128 was 48 px at a 5 px circle, 48-80 at 10, 64 at 20, 80
/// at 35, 96 at 50; with motion (its own blur widens each footprint) 96-128 at 5, 96 at 20, 128
/// at 50.
inline int lensBucketSize(double circleRadius, bool sampleTimes) {
  const double fitted = std::round((45.0 + 1.15 * std::min(circleRadius, 1e3)) / 16.0) * 16.0;
  const int still = int(std::clamp(std::isfinite(fitted) ? fitted : 128.0, 48.0, 128.0));
  return sampleTimes ? std::clamp(still + 32, kBucketSize, 128) : still;
}

/// Through a lens, the depth layers' width (RasterOptions::lensLayerWidth) from the same typical
/// circle: narrower layers search less around each micropolygon and sort the bucket's samples
/// more often. On the bench frames 1 px was 2-5 % faster than 2 px at 5-20 px circles (moving 20
/// px: 6.33 against 6.65-6.91 rasterize thread-s) and 4 % slower at 50 px, where 2 px was best
/// and 3 px no better.
inline float lensLayerWidth(double circleRadius) { return float(std::clamp(std::isfinite(circleRadius) ? circleRadius / 25.0 : 2.0, 1.0, 2.0)); }

struct RenderSpec {
  std::vector<Source> sources;  // stores in time order; sources[0] sets camera and schema
  ShutterModel shutter;         // absolute frames
  int width = 0, height = 0;    // 0: the store camera's resolution
  /// Data window [x0, x1) × [y0, y1) in output pixels; empty = the whole image.
  int cropX0 = 0, cropX1 = 0, cropY0 = 0, cropY1 = 0;
  int samplesX = 4, samplesY = 4;
  uint64_t seed = 0;
  FilterSpec filter;  // for R G B A (Z always takes zmin)
  std::vector<AovRequest> aovs;
  RasterOptions raster;
  int bucketSize = kAutoBucketSize;  // pixels; kAutoBucketSize: chosen per render
  size_t cacheBytes = size_t(256) << 20;  // decoded-part cache per store
  /// A decoded part leaves its store's cache once the last bucket that needs it is done with it
  /// (StoreReader::release), so that memory is reused rather than grown to the cache budget.
  /// Stores listed here are left to their LRU instead: those the caller renders from again next
  /// (the next frame of a sequence, a two-pass frame's second field, a benchmark's rounds).
  std::vector<const store::StoreReader*> keepDecoded;
  bool progress = true;
  bool halfColor = false;  // write R G B A as half
  /// Deep output (resample/deep.h): formed alongside the flat image when set.
  bool deep = false;
  DeepFormOptions deepOptions;
  std::map<uint32_t, std::string> objectNames;  // object id → name, for the deep idManifest
  /// Volumes to render in front of and between the stores' surfaces (resample/volume.h), placed
  /// in the world of sources[0]'s camera at sources[0]'s frame; null: none, at no cost.
  std::shared_ptr<const VolumeScene> volumes;
  /// Render the scene's own volumes the store records (RIB `Volume` requests) too.
  bool sceneVolumes = true;
  /// How the store's own volumes are integrated when `volumes` is null (else `volumes`' options).
  VolumeOptions volumeOptions;
  /// Depth of field: the lens the store's camera records (RIB DepthOfField), with any of its
  /// values replaced; `pinhole` renders without it. A store without a lens takes one only when
  /// all three values are given.
  struct LensOverride {
    std::optional<double> fstop, focalLength, focalDistance;
    bool pinhole = false;
  } lens;
  /// The camera to render from: none = sources[0]'s primary camera (the one it was shaded from).
  /// Any other camera of that world - one the store records, or one given after the fact
  /// (resample/camera_view.h) - renders the same stores through it: each store's micropolygons
  /// are carried from its primary camera's space into this camera's. Its resolution is the
  /// default output resolution.
  std::optional<store::Camera> camera;
  /// From another camera: re-light the view-dependent shading for its eye where the store carries
  /// what that needs (shade --view-dependent, store::ViewTerm); off: the primary camera's shading.
  bool viewDependent = true;
};

/// The lens a render uses: the camera's with `o` applied (see RenderSpec::lens); throws Error naming
/// the option at fault.
store::Lens renderLens(const store::Camera& camera, const RenderSpec::LensOverride& o);

/// How a render with a lens pairs its sample planes (RasterOptions::lensTimeBlocks): N / 4 time
/// blocks with the lens's quadrants when at least a twelfth of the stores' micropolygons move
/// over a shutter that is not an instant (and the samples are an even grid of at most 256), else
/// 1 (planes are lens strata: tightest for what stands still).
int lensTimeBlocks(const RenderSpec& spec);

struct RenderStats {
  RasterStats raster;
  int buckets = 0;
  int bucketSize = 0;  // the size the render used (RenderSpec::bucketSize, or the one it chose)
  float lensLayerWidth = 0.f;  // through a lens: the depth layers' width it used, px of circle radius
  // Summed over threads. setup: the bucket's samples and its part list; parts: fetching parts,
  // which is decoding them, or waiting while another thread decodes one both buckets need.
  double setupSeconds = 0, partsSeconds = 0, rasterSeconds = 0, resolveSeconds = 0, filterSeconds = 0;
  uint64_t partsFetched = 0, partsDecoded = 0;  // decoded: the store caches' misses during the render
  uint64_t partsWaited = 0;                     // fetches that waited for another thread's decode
  uint64_t partsCarried = 0;                    // fetches carried into another camera's space (RenderSpec::camera)
  uint64_t relitVertices = 0;                   // vertices of carried parts whose view-dependent shading was re-lit for the view's eye
  /// From another camera: samples that found nothing where no camera the store records looked
  /// (camera_view.h unseenPixels): what is there, the store cannot hold.
  uint64_t unseenSamples = 0;
  bool unseenJudged = false;  // unseenSamples was counted (a camera the store does not record)
  VolumeStats volumes;
  double wallSeconds = 0;
  uint64_t samples = 0;
  std::string report() const;  // the --stats text
};

struct RenderResult {
  FlatImage image;
  RenderStats stats;
  ImageProvenance provenance;
  DeepImage deep;  // when RenderSpec::deep
};

/// Checks that every time the shutter asks for is covered by a source; throws Error naming the
/// uncovered times otherwise ("frames 12.5 to 12.75 are not covered").
void checkCoverage(const std::vector<Source>& sources, const ShutterModel& shutter);

RenderResult render(const RenderSpec& spec);

}  // namespace reshutter::resample
