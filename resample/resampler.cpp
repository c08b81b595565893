// The re-sampler's render(): validate the spec, plan what every bucket shares (window, shutter,
// view, samples, output variables, filters, buckets), render the buckets in parallel (gather the
// parts that touch each, rasterize, resolve, filter into pixels, form deep pixels), then sum the
// figures and record the image's provenance. resample/resampler.h says what it promises; the
// spec's own checks and the --stats report are render_spec.cpp's.
#include "resample/resampler.h"

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <map>
#include <iomanip>
#include <mutex>
#include <sstream>

#include <tbb/enumerable_thread_specific.h>
#include <tbb/parallel_for.h>

#include "common/check.h"
#include "common/error.h"
#include "common/log.h"
#include "common/progress.h"
#include "resample/bucket_samples.h"
#include "resample/camera_view.h"

namespace reshutter::resample {

namespace {

/// `cam` over another pixel count, its screen window kept: a re-sampled resolution.
store::Camera atResolution(const store::Camera& cam, int width, int height) {
  store::Camera c = cam;
  double sw[4];
  cam.effectiveScreenWindow(sw);
  std::copy(sw, sw + 4, c.screenWindow);
  c.width = width, c.height = height;
  return c;
}

View makeView(const store::Camera& cam, int width, int height, const store::Lens& lens) {
  store::Projector p(atResolution(cam, width, height));
  View v;
  v.ax = p.ax, v.bx = p.bx, v.ay = p.ay, v.by = p.by;
  v.perspective = p.perspective;
  v.nearClip = float(cam.nearClip);
  v.farClip = float(std::min(cam.farClip, 1e30));
  if (lens.active()) {
    // RenderMan's depth of field applies to perspective cameras only.
    if (v.perspective) v.lensRadius = lens.radius(), v.focalDistance = lens.focalDistance;
    else warnOnce("lens-orthographic", "the camera is orthographic: depth of field ignored");
  }
  return v;
}

glm::dmat4 cameraToNdc(const View& v, int width, int height) {
  glm::dmat4 m(0.0);  // m[column][row]
  if (v.perspective) {
    m[0][0] = v.ax / width, m[2][0] = v.bx / width;
    m[1][1] = v.ay / height, m[2][1] = v.by / height;
    m[2][2] = 1.0, m[2][3] = 1.0;
  } else {
    m[0][0] = v.ax / width, m[3][0] = v.bx / width;
    m[1][1] = v.ay / height, m[3][1] = v.by / height;
    m[2][2] = 1.0, m[3][3] = 1.0;
  }
  return m;
}

std::vector<AovChannel> resolveAovs(const std::vector<AovRequest>& requests, const store::Schema& schema, const FilterSpec& pixelFilter) {
  std::vector<AovChannel> out;
  for (const auto& r : requests) {
    AovChannel c;
    c.name = r.name;
    if (r.name == "id") {
      c.builtin = AovChannel::Builtin::ObjectId, c.isUInt = true, c.components = 1;
    } else if (r.name == "z" || r.name == "depth") {
      c.builtin = AovChannel::Builtin::Depth, c.components = 1;
    } else {
      c.schemaIndex = schema.find(r.name);
      if (c.schemaIndex < 0) {
        std::string have;
        for (const auto& a : schema.attrs) have += (have.empty() ? "" : ", ") + a.name;
        fail("--aov " + r.name, "the store has no output variable '", r.name, "' (it has ", have, "; built in: id, z)");
      }
      const auto& d = schema.attrs[size_t(c.schemaIndex)];
      c.isUInt = d.type == store::AttrType::UInt;
      c.components = store::componentCount(d.type);
    }
    c.filter = r.filter ? *r.filter : (c.isUInt ? FilterSpec::parse("zmin", "") : pixelFilter);
    if (c.isUInt && !c.filter.special()) fail("--aov " + r.name, "ids cannot be blended: use min, max, zmin or zmax");
    out.push_back(c);
  }
  return out;
}

std::vector<std::string> channelNames(const AovChannel& c, const store::Schema& schema) {
  if (c.components == 1) return {c.name};
  const bool color = c.schemaIndex >= 0 && schema.attrs[size_t(c.schemaIndex)].type == store::AttrType::Color;
  static const char* const rgb[] = {"R", "G", "B"};
  static const char* const xyz[] = {"X", "Y", "Z"};
  const char* const* suffix = color ? rgb : xyz;
  return {c.name + "." + suffix[0], c.name + "." + suffix[1], c.name + "." + suffix[2]};
}

// Pixel value under a special filter from one pixel's samples (value per sample, depth per sample).
float specialFilter(FilterKind k, const float* v, const float* z, int n, float empty) {
  float best = empty, bestZ = 0;
  int count = 0;
  double sum = 0;
  for (int i = 0; i < n; ++i) {
    if (!std::isfinite(z[i])) continue;  // the sample saw no surface
    if (count == 0) best = v[i], bestZ = z[i];
    switch (k) {
      case FilterKind::Min: best = std::min(best, v[i]); break;
      case FilterKind::Max: best = std::max(best, v[i]); break;
      case FilterKind::ZMin:
        if (z[i] < bestZ) best = v[i], bestZ = z[i];
        break;
      case FilterKind::ZMax:
        if (z[i] > bestZ) best = v[i], bestZ = z[i];
        break;
      default: break;
    }
    sum += v[i];
    ++count;
  }
  if (k == FilterKind::Average) return count ? float(sum / count) : empty;
  return best;
}

uint32_t specialFilterU(FilterKind k, const uint32_t* v, const float* z, int n) {
  uint32_t best = 0;
  float bestZ = 0;
  int count = 0;
  for (int i = 0; i < n; ++i) {
    if (!std::isfinite(z[i])) continue;
    if (count == 0) best = v[i], bestZ = z[i];
    if ((k == FilterKind::Min && v[i] < best) || (k == FilterKind::Max && v[i] > best) || (k == FilterKind::ZMin && z[i] < bestZ) ||
        (k == FilterKind::ZMax && z[i] > bestZ))
      best = v[i], bestZ = z[i];
    ++count;
  }
  return best;
}

// ---------------------------------------------------------------------------------------------
// Validate and plan: what every bucket shares, fixed before the first one starts.

/// Output resolution and data window: [x0, x1) × [y0, y1) of a W × H image.
struct Window {
  int W = 0, H = 0, x0 = 0, x1 = 0, y0 = 0, y1 = 0;
};

/// The checks on the spec itself, before anything is built: shared schema, resolution, crop,
/// samples, bucket size.
Window validateSpec(const RenderSpec& spec) {
  if (spec.sources.empty()) fail("resample", "no store to re-sample");
  const store::StoreMeta& meta0 = spec.sources[0].store->meta();
  const store::Camera& cam = spec.camera ? *spec.camera : meta0.cameras[0];
  for (const auto& s : spec.sources)
    if (!(s.store->meta().schema == meta0.schema))
      fail(s.store->path(), "its output variables differ from ", spec.sources[0].store->path(), "'s; stores of one render must share a schema");
  Window w;
  w.W = spec.width > 0 ? spec.width : cam.width, w.H = spec.height > 0 ? spec.height : cam.height;
  if (w.W <= 0 || w.H <= 0 || w.W > 65536 || w.H > 65536) fail("--res", "resolution ", w.W, "x", w.H, " out of range");
  w.x0 = 0, w.x1 = w.W, w.y0 = 0, w.y1 = w.H;
  if (spec.cropX1 > spec.cropX0 || spec.cropY1 > spec.cropY0) {
    w.x0 = std::max(0, spec.cropX0), w.x1 = std::min(w.W, spec.cropX1), w.y0 = std::max(0, spec.cropY0), w.y1 = std::min(w.H, spec.cropY1);
    if (w.x0 >= w.x1 || w.y0 >= w.y1)
      fail("--crop", "the crop window ", spec.cropX0, " ", spec.cropX1, " ", spec.cropY0, " ", spec.cropY1, " lies outside the ", w.W, "x", w.H, " image");
  }
  if (spec.samplesX < 1 || spec.samplesY < 1 || spec.samplesX * spec.samplesY > 4096) fail("--spp", "samples per pixel must be 1 to 4096");
  if (spec.bucketSize != kAutoBucketSize && (spec.bucketSize < 4 || spec.bucketSize > 1024)) fail("--bucket", "bucket size must be 4 to 1024 (or 0: chosen per render)");
  return w;
}

/// The spec's shutter with its rolling read-out spread over the output's rows.
ShutterModel shutterOverRows(const ShutterModel& given, int height) {
  ShutterModel shutter = given;
  RollingShutter rolling = shutter.rolling();
  rolling.height = height;
  shutter.setRolling(rolling);
  return shutter;
}

struct Bucket {
  int x0, y0, x1, y1;
};

/// Buckets over the data window, row-major.
std::vector<Bucket> planBuckets(const Window& w, int size) {
  std::vector<Bucket> buckets;
  for (int y = w.y0; y < w.y1; y += size)
    for (int x = w.x0; x < w.x1; x += size) buckets.push_back({x, y, std::min(w.x1, x + size), std::min(w.y1, y + size)});
  return buckets;
}

std::vector<std::unique_ptr<FilterTable>> aovFilterTables(const std::vector<AovChannel>& aovs, const SamplePattern& pattern) {
  std::vector<std::unique_ptr<FilterTable>> tables;
  for (const auto& a : aovs) tables.push_back(std::make_unique<FilterTable>(a.filter, pattern));
  return tables;
}

/// The sources with Source::endShared set where another source starts exactly where one ends, so
/// that a time on the boundary (an instant there, or a sample that lands on it) is drawn from one
/// store only.
std::vector<Source> withSharedEnds(std::vector<Source> sources) {
  for (Source& s : sources)
    s.endShared = std::any_of(sources.begin(), sources.end(), [&](const Source& o) { return &o != &s && o.coverStart() == s.coverEnd(); });
  return sources;
}

/// Whether the samples must draw their times (RasterOptions::sampleTimes): not at an instant
/// without a rolling read-out (every sample's time is then its group's, drawn or not), nor when
/// nothing the render draws reads them - no moving part or view, no colours shaded in time, every
/// store covering the whole shutter (retime's do not), no volume (marched at the sample's time).
bool drawsSampleTimes(const std::vector<Source>& sources, const ShutterModel& shutter, const std::vector<std::unique_ptr<const CarriedStore>>& carried,
                      bool volumes) {
  const auto& groups = shutter.groups();
  if (shutter.rolling().duration == 0.0 && std::all_of(groups.begin(), groups.end(), [](const ShutterGroup& g) { return g.length() == 0.0; })) return false;
  if (volumes) return true;
  const double t0 = shutter.earliest(), t1 = shutter.latest();
  for (size_t i = 0; i < sources.size(); ++i) {
    const Source& src = sources[i];
    if (carried[i] && carried[i]->moving()) return true;
    if (!Source::covers(t0, src.coverStart(), src.coverEnd(), src.endShared) || !Source::covers(t1, src.coverStart(), src.coverEnd(), src.endShared)) return true;
    for (const store::TileEntry& e : src.store->entries())
      if (e.effects & (store::kEffectMoving | store::kEffectShadedInTime)) return true;
  }
  return false;
}

/// The circle of confusion a micropolygon typically takes through the view's lens, over every
/// source's parts (ViewBounds::circleTotals()), raster pixels of radius; 0 without a lens.
double typicalCircle(const std::vector<Source>& sources, const std::vector<std::unique_ptr<const CarriedStore>>& carried, const View& view,
                     const store::Lens& lens) {
  if (!view.lens()) return 0.0;
  store::ViewBounds::CircleTotals all;
  for (size_t i = 0; i < sources.size(); ++i) {
    const store::ViewBounds& bounds = carried[i] ? carried[i]->bounds() : sources[i].store->primaryBounds();
    const store::ViewBounds::CircleTotals t = bounds.circleTotals(lens);
    all.weighted += t.weighted, all.micropolygons += t.micropolygons;
  }
  return (all.micropolygons > 0 ? all.weighted / all.micropolygons : 0.0) * std::max(std::abs(view.ax), std::abs(view.ay));
}

/// Everything the buckets read and none writes: the validated window and shutter, the camera's
/// view, the sample pattern, the output variables and their filters, the buckets.
struct Plan {
  Plan(const RenderSpec& spec, const Window& window, const ShutterModel& shutter)
      : spec(spec),
        sources(withSharedEnds(spec.sources)),
        meta0(spec.sources[0].store->meta()),
        cam(spec.camera ? *spec.camera : meta0.cameras[0]),
        win(window),
        shutter(shutter),
        lens(renderLens(cam, spec.lens)),
        view(makeView(cam, win.W, win.H, lens)),
        pattern(spec.samplesX, spec.samplesY, spec.seed),
        N(pattern.spp()),
        aovs(resolveAovs(spec.aovs, meta0.schema, spec.filter)),
        mainTable(spec.filter, pattern),
        aovTables(aovFilterTables(aovs, pattern)) {
    // Samples beyond the bucket: as many pixels as the widest filter reaches.
    margin = mainTable.margin();
    for (const auto& t : aovTables) margin = std::max(margin, t->margin());
    rasterOptions = spec.raster;
    rasterOptions.surfaceIds = spec.deep;  // only deep output reads them back
    if (view.lens()) rasterOptions.lensTimeBlocks = lensTimeBlocks(spec);
    // Another camera: each store whose primary camera stands elsewhere is carried into it.
    const store::Camera output = atResolution(cam, win.W, win.H);
    const store::Projector projector(output);
    for (Source& src : sources) {
      const store::Camera& primary = src.store->meta().cameras[0];
      carried.push_back(spec.camera && !sameView(primary, cam) ? std::make_unique<const CarriedStore>(*src.store, cam, projector, spec.viewDependent) : nullptr);
      if (carried.back() && carried.back()->moving()) src.schedules = &carried.back()->schedules();
    }
    const glm::dmat4 toView = carried[0] ? carried[0]->toView() : glm::dmat4(1.0);
    // Where no shading camera looked: unless the view is one of the store's own cameras.
    const auto& recorded = meta0.cameras;
    if (carried[0] && std::none_of(recorded.begin(), recorded.end(), [&](const store::Camera& c) { return sameView(c, cam); }))
      unseen = unseenPixels(*sources[0].store, output, toView, win.W, win.H);
    // The volumes: those the caller adds, and the scene's own the store records.
    volumes = spec.volumes;
    if (!meta0.volumes.empty() && spec.sceneVolumes) {
      std::vector<VolumeSpec> fromStore;
      for (store::StoredVolume v : meta0.volumes) {
        for (glm::dmat4& m : v.fileToCamera) m = toView * m;
        fromStore.push_back(VolumeSpec::fromStore(v));
      }
      auto scene =
          spec.volumes ? std::make_shared<const VolumeScene>(*spec.volumes, fromStore) : std::make_shared<const VolumeScene>(fromStore, spec.volumeOptions);
      for (size_t w = spec.volumes ? spec.volumes->warnings().size() : 0; w < scene->warnings().size(); ++w) warnOnce("store-volume", scene->warnings()[w]);
      volumes = std::move(scene);
    }
    rasterOptions.sampleTimes = !rasterOptions.skipUnreadTimes || drawsSampleTimes(sources, shutter, carried, volumes != nullptr);
    // What the samples' layout and the lens gain from (kAutoBucketSize's comment), known only now.
    // Through a lens: the bucket size and the depth layers' width from the typical circle of
    // confusion; else the bucket size by the samples' layout.
    const double circle = typicalCircle(sources, carried, view, lens);
    if (view.lens() && !(rasterOptions.lensLayerWidth > 0.f)) rasterOptions.lensLayerWidth = lensLayerWidth(circle);
    bucketSize = spec.bucketSize != kAutoBucketSize                              ? spec.bucketSize
                 : view.lens()                                                   ? lensBucketSize(circle, rasterOptions.sampleTimes)
                 : BucketSamples::pixelMajorFor(rasterOptions.sampleTimes, false) ? kStillBucketSize
                                                                                 : kBucketSize;
    buckets = planBuckets(win, bucketSize);
    if (volumes) {
      volumeCamera.ax = view.ax, volumeCamera.bx = view.bx, volumeCamera.ay = view.ay, volumeCamera.by = view.by;
      volumeCamera.perspective = view.perspective;
      if (view.lens()) volumeCamera.lensRadius = view.lensRadius, volumeCamera.focalDistance = view.focalDistance;
      volumeCamera.worldToCamera = cam.worldToCamera;
      volumeCamera.framesPerSecond = double(meta0.fps.num) / double(meta0.fps.den);
      volumeCamera.referenceFrame = double(spec.sources[0].frame);
      for (const store::StoredLight& l : meta0.lights) volumeCamera.lights.push_back(carriedLight(l, toView));
      if (!meta0.lights.empty() && volumes->options().cacheShadows) volumeLighting = std::make_unique<const VolumeLighting>(*volumes, volumeCamera);
    }
  }
  std::shared_ptr<const VolumeScene> volumes;            // spec.volumes and the store's own
  VolumeCamera volumeCamera;                             // with volumes
  std::unique_ptr<const VolumeLighting> volumeLighting;  // with volumes and lights

  const RenderSpec& spec;
  std::vector<Source> sources;  // spec.sources, with the ends they share marked (and carried schedules)
  const store::StoreMeta& meta0;
  const store::Camera cam;  // the camera rendered from (RenderSpec::camera, or the store's primary)
  const Window win;
  const ShutterModel shutter;
  const store::Lens lens;  // the camera's with the spec's overrides (view has it only for a perspective camera)
  const View view;
  const SamplePattern pattern;
  const int N;  // samples per pixel
  const std::vector<AovChannel> aovs;
  const FilterTable mainTable;                                // R G B A
  const std::vector<std::unique_ptr<FilterTable>> aovTables;  // per output variable
  int bucketSize = 0;
  std::vector<Bucket> buckets;
  /// Per source: its parts carried into `cam` when its primary camera stands elsewhere, else null.
  std::vector<std::unique_ptr<const CarriedStore>> carried;
  std::vector<uint8_t> unseen;  // per output pixel (W × H), from another camera: 1 where no shading camera looked
  int margin = 0;
  const AovLayout aovLayout{aovs};  // where each output variable lies among ResolvedSamples::aov / aovU
  RasterOptions rasterOptions;
};

/// The flat image over the data window: R G B A Z, then each output variable's channels.
/// Returns, per output variable, the indices of its channels. The channels start uninitialised:
/// the buckets tile the window and each one's filter (BucketFilter::run()) writes every channel
/// of every pixel it owns, so the zero fill would only have put the first touch of every page on
/// one thread before the buckets start (1-2 % of the motion-free 1080p frame's wall time).
std::vector<std::vector<int>> setUpImage(const Plan& plan, FlatImage& img) {
  const Window& w = plan.win;
  img.x0 = w.x0, img.y0 = w.y0, img.width = w.x1 - w.x0, img.height = w.y1 - w.y0, img.fullWidth = w.W, img.fullHeight = w.H;
  constexpr bool kUninitialised = true;
  for (const char* n : {"R", "G", "B", "A"}) img.add(n, false, kUninitialised).half = plan.spec.halfColor;
  img.add("Z", false, kUninitialised);
  std::vector<std::vector<int>> aovImageChannel(plan.aovs.size());
  for (size_t a = 0; a < plan.aovs.size(); ++a)
    for (const auto& n : channelNames(plan.aovs[a], plan.meta0.schema)) {
      if (img.find(n)) fail("--aov " + plan.aovs[a].name, "channel '", n, "' requested twice");
      aovImageChannel[a].push_back(int(img.channels.size()));
      img.add(n, plan.aovs[a].isUInt, kUninitialised);
    }
  return aovImageChannel;
}

/// Deep output: the same output variables as the flat image; the object id is always there.
DeepLayout deepLayoutOf(const std::vector<AovChannel>& aovs, const store::Schema& schema) {
  DeepLayout layout;
  for (const auto& aov : aovs) {
    const auto names = channelNames(aov, schema);
    if (aov.isUInt) {
      if (aov.builtin != AovChannel::Builtin::ObjectId) layout.uints.push_back({names[0], layout.sourceUInts, false});
      ++layout.sourceUInts;
      continue;
    }
    for (int c = 0; c < aov.components; ++c) layout.floats.push_back({names[size_t(c)], layout.sourceFloats + c, aov.composited()});
    layout.sourceFloats += aov.components;
  }
  return layout;
}

/// The deep image (one block per bucket) and what forms its pixels.
std::unique_ptr<DeepFormer> setUpDeep(const Plan& plan, DeepImage& deep) {
  const Window& w = plan.win;
  deep.reset(w.x0, w.y0, w.x1 - w.x0, w.y1 - w.y0, w.W, w.H, deepLayoutOf(plan.aovs, plan.meta0.schema), plan.buckets.size());
  deep.objectNames = plan.spec.objectNames.empty() ? objectNamesFromProvenance(plan.meta0.provenance) : plan.spec.objectNames;
  if (plan.volumes && !deep.objectNames.empty()) deep.objectNames[kVolumeObjectId] = "volumes";
  return std::make_unique<DeepFormer>(deep, plan.mainTable, plan.pattern, plan.spec.deepOptions);
}

// ---------------------------------------------------------------------------------------------
// Per bucket: gather the parts, rasterize them, resolve the samples, filter them into pixels.

using Clock = std::chrono::steady_clock;

double secondsBetween(Clock::time_point a, Clock::time_point b) { return std::chrono::duration<double>(b - a).count(); }

/// Pixels of the image: a bucket and the filter margin around it.
struct Region {
  int x0, y0, w, h;
};

struct ThreadState {
  std::unique_ptr<BucketRasterizer> raster;
  std::unique_ptr<VolumeTracer> volumes;  // when the render has volumes
  RenderStats stats;
  std::vector<int> patterns;
  std::vector<std::pair<size_t, size_t>> parts;              // (source, entry)
  std::vector<std::shared_ptr<const store::TilePart>> held;  // the bucket's decoded parts
  std::vector<const float*> tapWeights;                      // one pixel's filter neighbourhood (accumulateTaps)
  std::vector<size_t> tapOffsets;

  BucketRasterizer& rasterizer(const Plan& plan) {
    if (!raster) {
      raster = std::make_unique<BucketRasterizer>(plan.pattern, plan.shutter, plan.view, plan.aovs, plan.rasterOptions);
      if (plan.volumes) {
        volumes = std::make_unique<VolumeTracer>(*plan.volumes, plan.volumeCamera, plan.shutter.earliest(), plan.shutter.latest(), plan.volumeLighting.get());
        // Deep volume samples: depth slices four deep tolerances thick (4 % of the depth by
        // default) - enough for holdouts inside the medium, few enough to keep pixels small.
        raster->setVolumes(volumes.get(), 1.0 + 4.0 * std::max(1e-4, double(plan.spec.deepOptions.tolerance)));
      }
    }
    return *raster;
  }
};

/// The samples a bucket rasterizes: the bucket and the filter margin around it.
Region regionOf(const Plan& plan, const Bucket& bk) {
  return {bk.x0 - plan.margin, bk.y0 - plan.margin, bk.x1 - bk.x0 + 2 * plan.margin, bk.y1 - bk.y0 + 2 * plan.margin};
}

/// Lists, into `parts`, every part whose bound over [tMin, tMax] touches the region.
void gatherParts(const Plan& plan, double tMin, double tMax, const Region& rg, std::vector<std::pair<size_t, size_t>>& parts) {
  parts.clear();
  // With a lens, a part's samples reach as far as its circle of confusion.
  const store::Lens lens = plan.view.lens() ? plan.lens : store::Lens{};
  for (size_t si = 0; si < plan.sources.size(); ++si) {
    const Source& src = plan.sources[si];
    const auto& m = src.store->meta();
    const double lo = std::max(tMin - double(src.frame), m.shutterOpen);
    const double hi = std::min(tMax - double(src.frame), m.shutterClose);
    if (lo > hi) continue;
    if (plan.carried[si]) {
      const store::RasterRect rect{float(rg.x0), float(rg.y0), float(rg.x0 + rg.w), float(rg.y0 + rg.h), false};
      plan.carried[si]->bounds().visit(rect, lo, hi, [&](size_t e) { parts.push_back({si, e}); }, lens);
      continue;
    }
    const auto& sc = m.cameras[0];
    const float fx = float(sc.width) / float(plan.win.W), fy = float(sc.height) / float(plan.win.H);
    store::RasterRect rect{float(rg.x0) * fx, float(rg.y0) * fy, float(rg.x0 + rg.w) * fx, float(rg.y0 + rg.h) * fy, false};
    src.store->visit(rect, lo, hi, [&](size_t e) { parts.push_back({si, e}); }, lens);
  }
}

/// How many buckets are still to fetch each part, so that the last one can release it from its
/// store's cache (StoreReader::release). Without this the cache holds every part until its LRU
/// budget is full, and on a large frame each decode then touches fresh pages (page faults cost
/// more than the decode, measured in bench/RESULTS.md) instead of reusing a released part's.
/// A bucket is counted over the shutter's times for its rows, which hold its samples' times: a
/// count can only be too high (the part then stays until the LRU drops it), never too low.
class PartUses {
 public:
  explicit PartUses(const Plan& plan) : storeOf_(plan.sources.size()) {
    std::map<const store::StoreReader*, size_t> stores;
    for (size_t si = 0; si < plan.sources.size(); ++si) {
      const store::StoreReader* st = plan.sources[si].store.get();
      const auto& keep = plan.spec.keepDecoded;
      if (std::find(keep.begin(), keep.end(), st) != keep.end()) {
        storeOf_[si] = kKept;
        continue;
      }
      auto [it, fresh] = stores.emplace(st, stores.size());
      if (fresh) left_.emplace_back(st->entries().size());
      storeOf_[si] = it->second;
    }
    // In parallel: with small buckets the count is as many index walks as the render makes.
    tbb::enumerable_thread_specific<std::vector<std::pair<size_t, size_t>>> partLists;
    tbb::parallel_for(size_t(0), plan.buckets.size(), [&](size_t b) {
      std::vector<std::pair<size_t, size_t>>& parts = partLists.local();
      const Region rg = regionOf(plan, plan.buckets[b]);
      double tMin = INFINITY, tMax = -INFINITY;
      for (int g = 0; g < int(plan.shutter.groups().size()); ++g) {
        double lo, hi;
        plan.shutter.timeRange(g, double(rg.y0), double(rg.y0 + rg.h), 0.0, 1.0, lo, hi);
        tMin = std::min(tMin, lo), tMax = std::max(tMax, hi);
      }
      // The samples' times are stored as floats relative to the frame: allow for their rounding.
      const double slack = 1e-5 * std::max(1.0, std::max(std::abs(tMin), std::abs(tMax)));
      gatherParts(plan, tMin - slack, tMax + slack, rg, parts);
      for (auto [si, e] : parts)
        if (storeOf_[si] != kKept) left_[storeOf_[si]][e].fetch_add(1, std::memory_order_relaxed);
    });
  }

  /// A bucket is done with `parts`.
  void done(const Plan& plan, const std::vector<std::pair<size_t, size_t>>& parts) {
    for (auto [si, e] : parts) {
      if (storeOf_[si] == kKept) continue;
      const uint32_t before = left_[storeOf_[si]][e].fetch_sub(1, std::memory_order_acq_rel);
      DCHECK(before > 0, "part ", e, " fetched by more buckets than counted");
      if (before == 1) plan.sources[si].store->release(e);
    }
  }

 private:
  static constexpr size_t kKept = ~size_t(0);             // a store in RenderSpec::keepDecoded
  std::vector<size_t> storeOf_;                           // per source, its store's index in left_ (or kKept)
  std::vector<std::vector<std::atomic<uint32_t>>> left_;  // per store, per entry
};

/// Fetches (decodes) the gathered parts and rasterizes them; returns the seconds spent fetching.
double rasterizeParts(const Plan& plan, BucketRasterizer& r, ThreadState& ts) {
  double fetch = 0;
  // Every part is decoded before any is drawn, so that the rasterizer can draw them nearest
  // first - up to a memory budget: past it, what is queued is drawn and released (the image is
  // the same; only exact depth ties could then resolve differently for another bucket size).
  constexpr uint64_t kQueuedBytes = 128ull << 20;
  uint64_t queuedBytes = 0;
  for (auto [si, e] : ts.parts) {
    const Source& src = plan.sources[si];
    const store::TileEntry& entry = plan.carried[si] ? plan.carried[si]->entry(e) : src.store->entries()[e];
    if (queuedBytes > 0 && queuedBytes + entry.rawSize > kQueuedBytes) {
      r.rasterizeQueued();
      ts.held.clear(), queuedBytes = 0;
    }
    auto ta = Clock::now();
    if (plan.carried[si]) ++ts.stats.partsCarried;
    ts.held.push_back(plan.carried[si] ? plan.carried[si]->part(e, ts.stats.relitVertices) : src.store->part(e));
    fetch += secondsBetween(ta, Clock::now());
    r.add(src, entry, *ts.held.back());
    queuedBytes += entry.rawSize;
  }
  r.rasterizeQueued();
  ts.held.clear();  // the cache may drop them now
  return fetch;
}

/// Filters one bucket's resolved samples into its pixels of the flat image.
class BucketFilter {
 public:
  BucketFilter(const Plan& plan, const std::vector<std::vector<int>>& aovImageChannel, const Region& rg, const ResolvedSamples& rs, ThreadState& ts,
               FlatImage& img)
      : plan_(plan), aovImageChannel_(aovImageChannel), rg_(rg), rs_(rs), ts_(ts), img_(img), N_(plan.N) {
    ts.patterns.resize(size_t(rg.w) * rg.h);
    for (int y = 0; y < rg.h; ++y)
      for (int x = 0; x < rg.w; ++x) ts.patterns[size_t(y) * rg.w + x] = plan.pattern.patternOf(rg.x0 + x, rg.y0 + y);
    // Per filtered output variable, its sample arrays and image channels: set up once per
    // bucket, not per pixel.
    const auto& aovs = plan.aovs;
    aovIn_.resize(aovs.size()), aovOut_.resize(aovs.size());
    for (size_t a = 0; a < aovs.size(); ++a)
      if (!aovs[a].isUInt && !aovs[a].filter.special())
        for (int c = 0; c < aovs[a].components; ++c) {
          aovIn_[a].push_back(&rs.aov[size_t(plan.aovLayout.floatBase[a] + c)]);
          aovOut_[a].push_back(img.channels[size_t(aovImageChannel[a][size_t(c)])].f.data());
        }
  }

  void run(const Bucket& bk) {
    const std::vector<const std::vector<float>*> rgbaIn{&rs_.r, &rs_.g, &rs_.b, &rs_.a};
    const std::vector<float*> rgbaOut{img_.channels[0].f.data(), img_.channels[1].f.data(), img_.channels[2].f.data(), img_.channels[3].f.data()};
    float* zOut = img_.channels[4].f.data();
    const auto& aovs = plan_.aovs;
    const int N = N_;
    for (int py = bk.y0; py < bk.y1; ++py)
      for (int px = bk.x0; px < bk.x1; ++px) {
        filterPixel(plan_.mainTable, rgbaIn, rgbaOut, px, py);
        const size_t q = sampleSlot(px, py);
        const size_t o = imageOffset(px, py);
        // Z: the nearest surface any of the pixel's samples saw (zmin).
        float z = plan_.view.farClip;
        for (int i = 0; i < N; ++i) z = std::min(z, rs_.z[q * N + i]);
        zOut[o] = z;
        for (size_t a = 0; a < aovs.size(); ++a) {
          const AovChannel& ch = aovs[a];
          if (ch.isUInt) {
            img_.channels[size_t(aovImageChannel_[a][0])].u[o] =
                specialFilterU(ch.filter.kind, rs_.aovU[size_t(plan_.aovLayout.uintBase[a])].data() + q * N, rs_.aovZ.data() + q * N, N);
          } else if (ch.filter.special()) {
            for (int c = 0; c < ch.components; ++c)
              img_.channels[size_t(aovImageChannel_[a][size_t(c)])].f[o] =
                  specialFilter(ch.filter.kind, rs_.aov[size_t(plan_.aovLayout.floatBase[a] + c)].data() + q * N, rs_.aovZ.data() + q * N, N, 0.f);
          } else {
            filterPixel(*plan_.aovTables[a], aovIn_[a], aovOut_[a], px, py);
          }
        }
      }
  }

 private:
  const Plan& plan_;
  const std::vector<std::vector<int>>& aovImageChannel_;
  const Region rg_;
  const ResolvedSamples& rs_;
  ThreadState& ts_;
  FlatImage& img_;
  const int N_;
  std::vector<std::vector<const std::vector<float>*>> aovIn_;
  std::vector<std::vector<float*>> aovOut_;

  /// The pixel's first sample in the region's sample arrays (times N).
  size_t sampleSlot(int px, int py) const { return size_t(py - rg_.y0) * rg_.w + size_t(px - rg_.x0); }
  size_t imageOffset(int px, int py) const { return size_t(py - plan_.win.y0) * img_.width + size_t(px - plan_.win.x0); }

  /// One pixel of the channels `in` through `table` into `outPx`.
  void filterPixel(const FilterTable& table, const std::vector<const std::vector<float>*>& in, const std::vector<float*>& outPx, int px, int py) {
    const int N = N_;
    const int m = table.margin();
    // Eight partial sums per channel over every neighbour (accumulateTaps), added up once at the end.
    const size_t nc = in.size();
    float lanes[8][8];
    float tail[8];
    for (size_t c = 0; c < nc; ++c) std::fill_n(lanes[c], 8, 0.f), tail[c] = 0.f;
    float wsum = 0;
    const int span = table.span(), taps = span * span;
    ts_.tapWeights.resize(size_t(taps)), ts_.tapOffsets.resize(size_t(taps));
    const float** tapWeight = ts_.tapWeights.data();
    size_t* tapOffset = ts_.tapOffsets.data();
    // Taps in (dy, dx) order, as the table numbers them.
    size_t rowStart = size_t(py - rg_.y0 - m) * rg_.w + size_t(px - rg_.x0 - m);
    for (int tap = 0, row = 0; row < span; ++row, rowStart += size_t(rg_.w))
      for (int col = 0; col < span; ++col, ++tap) {
        const size_t q = rowStart + size_t(col);
        const int pat = ts_.patterns[q];
        tapWeight[tap] = table.tapWeights(pat, tap);
        tapOffset[tap] = q * N;
        wsum += table.tapWeightSum(pat, tap);
      }
    const float* channels[8];
    for (size_t c = 0; c < nc; ++c) channels[c] = in[c]->data();
    accumulateTaps(N, int(nc), channels, ts_.tapWeights.data(), ts_.tapOffsets.data(), taps, lanes, tail);
    float acc[8];
    for (size_t c = 0; c < nc; ++c) {
      const float* l = lanes[c];
      acc[c] = (((l[0] + l[4]) + (l[1] + l[5])) + ((l[2] + l[6]) + (l[3] + l[7]))) + tail[c];
    }
    const size_t o = imageOffset(px, py);
    if (std::abs(wsum) < 1e-6f * float(N)) {
      // Negative lobes cancelled out: fall back to the pixel's own samples, unweighted.
      const size_t q = sampleSlot(px, py);
      for (size_t c = 0; c < nc; ++c) {
        double s = 0;
        for (int i = 0; i < N; ++i) s += (*in[c])[q * N + i];
        outPx[c][o] = float(s / N);
      }
      return;
    }
    const float inv = 1.0f / wsum;
    for (size_t c = 0; c < nc; ++c) outPx[c][o] = acc[c] * inv;
  }
};

/// The bucket's samples that found nothing in pixels no shading camera looked into.
uint64_t unseenSamples(const Plan& plan, const Bucket& bk, const Region& rg, const ResolvedSamples& rs) {
  uint64_t n = 0;
  for (int py = bk.y0; py < bk.y1; ++py)
    for (int px = bk.x0; px < bk.x1; ++px) {
      if (!plan.unseen[size_t(py) * size_t(plan.win.W) + size_t(px)]) continue;
      const size_t first = (size_t(py - rg.y0) * size_t(rg.w) + size_t(px - rg.x0)) * size_t(plan.N);
      // A sample that found nothing resolves to the far plane's depth.
      for (int i = 0; i < plan.N; ++i) n += !(rs.z[first + size_t(i)] < plan.view.farClip);
    }
  return n;
}

/// One bucket, start to end: its pixels of the flat (and deep) image, its figures in ts.stats.
void renderBucket(const Plan& plan, const std::vector<std::vector<int>>& aovImageChannel, size_t b, ThreadState& ts, PartUses& uses, FlatImage& img,
                  DeepFormer* deepFormer) {
  const Bucket& bk = plan.buckets[b];
  BucketRasterizer& r = ts.rasterizer(plan);
  const Region rg = regionOf(plan, bk);
  const auto t0 = Clock::now();
  r.begin(rg.x0, rg.y0, rg.w, rg.h);
  gatherParts(plan, r.earliestTime(), r.latestTime(), rg, ts.parts);
  const auto t1 = Clock::now();
  const double fetch = rasterizeParts(plan, r, ts);
  uses.done(plan, ts.parts);
  const auto t2 = Clock::now();
  const ResolvedSamples& rs = r.resolve();
  if (!plan.unseen.empty()) ts.stats.unseenSamples += unseenSamples(plan, bk, rg, rs);
  const auto t3 = Clock::now();
  BucketFilter(plan, aovImageChannel, rg, rs, ts, img).run(bk);
  // Deep output forms its samples from r.visitFragments() (resample/deep.h).
  if (deepFormer) deepFormer->formBucket(r, b, bk.x0, bk.y0, bk.x1, bk.y1, rg.x0, rg.y0, rg.w, rg.h);
  const auto t4 = Clock::now();

  RenderStats& s = ts.stats;
  s.setupSeconds += secondsBetween(t0, t1);
  s.partsSeconds += fetch;
  s.partsFetched += ts.parts.size();
  s.rasterSeconds += secondsBetween(t1, t2) - fetch;
  s.resolveSeconds += secondsBetween(t2, t3);
  s.filterSeconds += secondsBetween(t3, t4);
  s.raster.add(r.stats());
  s.samples += uint64_t(bk.x1 - bk.x0) * uint64_t(bk.y1 - bk.y0) * uint64_t(plan.N);
  ++s.buckets;
}

// ---------------------------------------------------------------------------------------------
// Output: the figures and the image's record of how it was made.

void addThreadStats(const tbb::enumerable_thread_specific<ThreadState>& threads, RenderStats& total) {
  for (const auto& ts : threads) {
    total.raster.add(ts.stats.raster);
    total.buckets += ts.stats.buckets;
    total.samples += ts.stats.samples;
    total.setupSeconds += ts.stats.setupSeconds;
    total.partsSeconds += ts.stats.partsSeconds;
    total.partsFetched += ts.stats.partsFetched;
    total.partsCarried += ts.stats.partsCarried;
    total.relitVertices += ts.stats.relitVertices;
    total.unseenSamples += ts.stats.unseenSamples;
    total.rasterSeconds += ts.stats.rasterSeconds;
    total.resolveSeconds += ts.stats.resolveSeconds;
    total.filterSeconds += ts.stats.filterSeconds;
    if (ts.volumes) total.volumes.add(ts.volumes->stats());
  }
}

using CacheCounts = std::map<const store::StoreReader*, store::CacheStats>;

CacheCounts cacheCounts(const std::vector<Source>& sources) {
  CacheCounts counts;
  for (const Source& src : sources) counts.emplace(src.store.get(), src.store->cacheStats());
  return counts;
}

/// Parts decoded and waited for since `before`: the store caches' misses and waits.
void addCacheStats(const CacheCounts& before, RenderStats& stats) {
  for (const auto& [store, was] : before) {
    const store::CacheStats now = store->cacheStats();
    stats.partsDecoded += now.misses - was.misses;
    stats.partsWaited += now.waits - was.waits;
  }
}

std::string describeShutter(const ShutterModel& shutter) {
  std::ostringstream sh;
  sh.precision(9);
  for (size_t g = 0; g < shutter.groups().size(); ++g) {
    const auto& gr = shutter.groups()[g];
    sh << (g ? "; " : "") << (shutter.groups().size() > 1 ? (g == 0 ? "field 1 " : "field 2 ") : "") << "[" << gr.open << ", " << gr.close << "] frames, "
       << gr.shape.description();
  }
  if (shutter.rolling().duration != 0) sh << "; rolling " << shutter.rolling().duration << " frames " << (shutter.rolling().upward ? "upward" : "downward");
  return sh.str();
}

ImageProvenance provenanceOf(const Plan& plan) {
  ImageProvenance pv;
  pv.worldToCamera = plan.cam.worldToCamera;
  pv.worldToNdc = cameraToNdc(plan.view, plan.win.W, plan.win.H) * plan.cam.worldToCamera;
  pv.frame = plan.spec.sources[0].frame;
  pv.fpsNum = plan.meta0.fps.num, pv.fpsDen = plan.meta0.fps.den;
  pv.shutterOpen = plan.shutter.earliest(), pv.shutterClose = plan.shutter.latest();
  pv.shutter = describeShutter(plan.shutter);
  return pv;
}

}  // namespace

RenderResult render(const RenderSpec& spec) {
  const auto wallStart = Clock::now();
  const Window window = validateSpec(spec);
  const ShutterModel shutter = shutterOverRows(spec.shutter, window.H);
  checkCoverage(spec.sources, shutter);
  const Plan plan(spec, window, shutter);

  RenderResult result;
  const std::vector<std::vector<int>> aovImageChannel = setUpImage(plan, result.image);
  const std::unique_ptr<DeepFormer> deepFormer = spec.deep ? setUpDeep(plan, result.deep) : nullptr;

  tbb::enumerable_thread_specific<ThreadState> threads;
  Progress progress("resample", plan.buckets.size());
  const CacheCounts cacheBefore = cacheCounts(spec.sources);
  PartUses uses(plan);
  tbb::parallel_for(tbb::blocked_range<size_t>(0, plan.buckets.size(), 1), [&](const tbb::blocked_range<size_t>& range) {
    for (size_t b = range.begin(); b != range.end(); ++b) {
      renderBucket(plan, aovImageChannel, b, threads.local(), uses, result.image, deepFormer.get());
      if (spec.progress) progress.advance();
    }
  });
  progress.finish();

  addThreadStats(threads, result.stats);
  result.stats.bucketSize = plan.bucketSize;
  if (plan.view.lens()) result.stats.lensLayerWidth = plan.rasterOptions.lensLayerWidth;
  if (plan.volumeLighting) result.stats.volumes.shadowSteps += plan.volumeLighting->buildSteps();
  result.stats.wallSeconds = secondsBetween(wallStart, Clock::now());
  addCacheStats(cacheBefore, result.stats);
  result.provenance = provenanceOf(plan);
  result.stats.unseenJudged = !plan.unseen.empty();
  return result;
}

}  // namespace reshutter::resample
