#include "resample/resampler.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <map>
#include <mutex>
#include <sstream>

#include <tbb/enumerable_thread_specific.h>
#include <tbb/parallel_for.h>

#include "common/error.h"
#include "common/progress.h"

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
  s << "  samples            " << samples << " (" << buckets << " buckets)\n";
  s << "  sample tests       " << raster.sampleTests << "\n";
  s << "  hits               " << raster.hits << "\n";
  s << "  test efficiency    " << ste << " (hits / tests)\n";
  s << "  micropolygons      " << raster.micropolygons << " processed (" << raster.staticMicropolygons << " on the static path, "
    << raster.linearMicropolygons << " bounded from their interval ends, " << raster.chunkGatheredMicropolygons << " of those gathered by chunk, "
    << raster.chunkCulledMicropolygons << " skipped with their chunk), "
    << raster.parts << " parts (" << raster.transparentParts << " transparent)\n";
  s << "  fragments          " << raster.fragments << " transparent\n";
  s << "  parts              " << partsFetched << " fetched, " << partsDecoded << " decoded, " << partsWaited << " waited for (another thread was decoding them)\n";
  s << "  time (thread-sum)  set-up " << setupSeconds << " s, parts " << partsSeconds << " s (decode, or wait for another thread's), rasterize "
    << rasterSeconds << " s, resolve " << resolveSeconds << " s, filter " << filterSeconds << " s\n";
  s << "  wall               " << wallSeconds << " s";
  if (wallSeconds > 0) s << ", " << double(samples) / wallSeconds / 1e6 << " M samples/s";
  s << "\n";
  return s.str();
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

namespace {

View makeView(const store::Camera& cam, int width, int height) {
  store::Camera c = cam;
  // Same screen window over a different pixel count: a re-sampled resolution.
  double sw[4];
  cam.effectiveScreenWindow(sw);
  std::copy(sw, sw + 4, c.screenWindow);
  c.width = width, c.height = height;
  store::Projector p(c);
  View v;
  v.ax = p.ax, v.bx = p.bx, v.ay = p.ay, v.by = p.by;
  v.perspective = p.perspective;
  v.nearClip = float(cam.nearClip);
  v.farClip = float(std::min(cam.farClip, 1e30));
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
      case FilterKind::ZMin: if (z[i] < bestZ) best = v[i], bestZ = z[i]; break;
      case FilterKind::ZMax: if (z[i] > bestZ) best = v[i], bestZ = z[i]; break;
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

struct ThreadState {
  std::unique_ptr<BucketRasterizer> raster;
  RenderStats stats;
  std::vector<int> patterns;
  std::vector<std::pair<size_t, size_t>> parts;  // (source, entry)
  std::vector<std::shared_ptr<const store::TilePart>> held;  // the bucket's decoded parts
  std::vector<const float*> tapWeights;  // one pixel's filter neighbourhood (accumulateTaps)
  std::vector<size_t> tapOffsets;
};

}  // namespace

RenderResult render(const RenderSpec& spec) {
  using clock = std::chrono::steady_clock;
  const auto wallStart = clock::now();
  if (spec.sources.empty()) fail("resample", "no store to re-sample");
  const store::StoreMeta& meta0 = spec.sources[0].store->meta();
  const store::Camera& cam = meta0.cameras[0];
  for (const auto& s : spec.sources)
    if (!(s.store->meta().schema == meta0.schema))
      fail(s.store->path(), "its output variables differ from ", spec.sources[0].store->path(), "'s; stores of one render must share a schema");
  const int W = spec.width > 0 ? spec.width : cam.width, H = spec.height > 0 ? spec.height : cam.height;
  if (W <= 0 || H <= 0 || W > 65536 || H > 65536) fail("--res", "resolution ", W, "x", H, " out of range");
  int cx0 = 0, cx1 = W, cy0 = 0, cy1 = H;
  if (spec.cropX1 > spec.cropX0 || spec.cropY1 > spec.cropY0) {
    cx0 = std::max(0, spec.cropX0), cx1 = std::min(W, spec.cropX1), cy0 = std::max(0, spec.cropY0), cy1 = std::min(H, spec.cropY1);
    if (cx0 >= cx1 || cy0 >= cy1) fail("--crop", "the crop window ", spec.cropX0, " ", spec.cropX1, " ", spec.cropY0, " ", spec.cropY1, " lies outside the ", W, "x", H, " image");
  }
  if (spec.samplesX < 1 || spec.samplesY < 1 || spec.samplesX * spec.samplesY > 4096) fail("--spp", "samples per pixel must be 1 to 4096");
  if (spec.bucketSize < 4 || spec.bucketSize > 1024) fail("--bucket", "bucket size must be 4 to 1024");

  ShutterModel shutter = spec.shutter;
  RollingShutter rolling = shutter.rolling();
  rolling.height = H;
  shutter.setRolling(rolling);
  checkCoverage(spec.sources, shutter);

  const View view = makeView(cam, W, H);
  const SamplePattern pattern(spec.samplesX, spec.samplesY, spec.seed);
  const int N = pattern.spp();
  const std::vector<AovChannel> aovs = resolveAovs(spec.aovs, meta0.schema, spec.filter);
  const FilterTable mainTable(spec.filter, pattern);
  std::vector<std::unique_ptr<FilterTable>> aovTables;
  int margin = mainTable.margin();
  for (const auto& a : aovs) {
    aovTables.push_back(std::make_unique<FilterTable>(a.filter, pattern));
    margin = std::max(margin, aovTables.back()->margin());
  }

  RenderResult result;
  FlatImage& img = result.image;
  img.x0 = cx0, img.y0 = cy0, img.width = cx1 - cx0, img.height = cy1 - cy0, img.fullWidth = W, img.fullHeight = H;
  for (const char* n : {"R", "G", "B", "A"}) img.add(n).half = spec.halfColor;
  img.add("Z");
  std::vector<std::vector<int>> aovImageChannel(aovs.size());
  for (size_t a = 0; a < aovs.size(); ++a)
    for (const auto& n : channelNames(aovs[a], meta0.schema)) {
      if (img.find(n)) fail("--aov " + aovs[a].name, "channel '", n, "' requested twice");
      aovImageChannel[a].push_back(int(img.channels.size()));
      img.add(n, aovs[a].isUInt);
    }

  // Deep output: the same output variables as the flat image; the object id is always there.
  std::unique_ptr<DeepFormer> deepFormer;
  DeepLayout deepLayout;
  if (spec.deep) {
    for (size_t a = 0; a < aovs.size(); ++a) {
      const auto names = channelNames(aovs[a], meta0.schema);
      if (aovs[a].isUInt) {
        if (aovs[a].builtin != AovChannel::Builtin::ObjectId) deepLayout.uints.push_back({names[0], deepLayout.sourceUInts, false});
        ++deepLayout.sourceUInts;
        continue;
      }
      for (int c = 0; c < aovs[a].components; ++c)
        deepLayout.floats.push_back({names[size_t(c)], deepLayout.sourceFloats + c, aovs[a].composited()});
      deepLayout.sourceFloats += aovs[a].components;
    }
  }

  // Buckets over the data window, row-major.
  struct Bucket {
    int x0, y0, x1, y1;
  };
  std::vector<Bucket> buckets;
  for (int y = cy0; y < cy1; y += spec.bucketSize)
    for (int x = cx0; x < cx1; x += spec.bucketSize)
      buckets.push_back({x, y, std::min(cx1, x + spec.bucketSize), std::min(cy1, y + spec.bucketSize)});
  if (spec.deep) {
    result.deep.reset(cx0, cy0, cx1 - cx0, cy1 - cy0, W, H, deepLayout, buckets.size());  // one block per bucket
    result.deep.objectNames = spec.objectNames.empty() ? objectNamesFromProvenance(meta0.provenance) : spec.objectNames;
    deepFormer = std::make_unique<DeepFormer>(result.deep, mainTable, pattern, spec.deepOptions);
  }

  RasterOptions rasterOptions = spec.raster;
  rasterOptions.surfaceIds = spec.deep;  // only deep output reads them back
  tbb::enumerable_thread_specific<ThreadState> threads;
  Progress progress("resample", buckets.size());
  const bool showProgress = spec.progress;

  auto processBucket = [&](const Bucket& bk) {
    ThreadState& ts = threads.local();
    if (!ts.raster) ts.raster = std::make_unique<BucketRasterizer>(pattern, shutter, view, aovs, rasterOptions);
    BucketRasterizer& r = *ts.raster;
    const int rx0 = bk.x0 - margin, ry0 = bk.y0 - margin, rw = bk.x1 - bk.x0 + 2 * margin, rh = bk.y1 - bk.y0 + 2 * margin;
    auto t0 = clock::now();
    r.begin(rx0, ry0, rw, rh);
    // Gather: every part whose bound over the region's time range touches the region.
    ts.parts.clear();
    for (size_t si = 0; si < spec.sources.size(); ++si) {
      const Source& src = spec.sources[si];
      const auto& m = src.store->meta();
      const double lo = std::max(r.earliestTime() - double(src.frame), m.shutterOpen);
      const double hi = std::min(r.latestTime() - double(src.frame), m.shutterClose);
      if (lo > hi) continue;
      const auto& sc = m.cameras[0];
      const float fx = float(sc.width) / float(W), fy = float(sc.height) / float(H);
      store::RasterRect rect{float(rx0) * fx, float(ry0) * fy, float(rx0 + rw) * fx, float(ry0 + rh) * fy, false};
      src.store->visit(rect, lo, hi, [&](size_t e) { ts.parts.push_back({si, e}); });
    }
    double gather = 0;
    auto t1 = clock::now();
    // Every part is decoded before any is drawn, so that the rasterizer can draw them nearest
    // first - up to a memory budget: past it, what is queued is drawn and released (the image is
    // the same; only exact depth ties could then resolve differently for another bucket size).
    constexpr uint64_t kQueuedBytes = 128ull << 20;
    uint64_t queuedBytes = 0;
    for (auto [si, e] : ts.parts) {
      const Source& src = spec.sources[si];
      const store::TileEntry& entry = src.store->entries()[e];
      if (queuedBytes > 0 && queuedBytes + entry.rawSize > kQueuedBytes) {
        r.rasterizeQueued();
        ts.held.clear(), queuedBytes = 0;
      }
      auto ta = clock::now();
      ts.held.push_back(src.store->part(e));
      gather += std::chrono::duration<double>(clock::now() - ta).count();
      r.add(src, entry, *ts.held.back());
      queuedBytes += entry.rawSize;
    }
    r.rasterizeQueued();
    ts.held.clear();  // the cache may drop them now
    auto t2 = clock::now();
    const double raster = std::chrono::duration<double>(t2 - t1).count() - gather;
    const ResolvedSamples& rs = r.resolve();
    auto t3 = clock::now();

    // Filter the samples into the bucket's pixels.
    ts.patterns.resize(size_t(rw) * rh);
    for (int y = 0; y < rh; ++y)
      for (int x = 0; x < rw; ++x) ts.patterns[size_t(y) * rw + x] = pattern.patternOf(rx0 + x, ry0 + y);
    auto filterInto = [&](const FilterTable& table, const std::vector<const std::vector<float>*>& in, const std::vector<float*>& outPx, int px,
                          int py) {
      const int m = table.margin();
      // Eight partial sums per channel over every neighbour (accumulateTaps), added up once at the end.
      float lanes[8][8] = {};
      float tail[8] = {};
      float wsum = 0;
      const size_t nc = in.size();
      const int taps = table.span() * table.span();
      ts.tapWeights.resize(size_t(taps)), ts.tapOffsets.resize(size_t(taps));
      const float** tapWeight = ts.tapWeights.data();
      size_t* tapOffset = ts.tapOffsets.data();
      for (int dy = -m; dy <= m; ++dy)
        for (int dx = -m; dx <= m; ++dx) {
          const size_t q = size_t(py - ry0 + dy) * rw + size_t(px - rx0 + dx);
          const int pat = ts.patterns[q];
          *tapWeight++ = table.weights(pat, dx, dy);
          *tapOffset++ = q * N;
          wsum += table.weightSum(pat, dx, dy);
        }
      const float* channels[8];
      for (size_t c = 0; c < nc; ++c) channels[c] = in[c]->data();
      accumulateTaps(N, int(nc), channels, ts.tapWeights.data(), ts.tapOffsets.data(), taps, lanes, tail);
      float acc[8];
      for (size_t c = 0; c < nc; ++c) {
        const float* l = lanes[c];
        acc[c] = (((l[0] + l[4]) + (l[1] + l[5])) + ((l[2] + l[6]) + (l[3] + l[7]))) + tail[c];
      }
      const size_t o = size_t(py - cy0) * img.width + size_t(px - cx0);
      if (std::abs(wsum) < 1e-6f * float(N)) {
        // Negative lobes cancelled out: fall back to the pixel's own samples, unweighted.
        const size_t q = size_t(py - ry0) * rw + size_t(px - rx0);
        for (size_t c = 0; c < nc; ++c) {
          double s = 0;
          for (int i = 0; i < N; ++i) s += (*in[c])[q * N + i];
          outPx[c][o] = float(s / N);
        }
        return;
      }
      const float inv = 1.0f / wsum;
      for (size_t c = 0; c < nc; ++c) outPx[c][o] = acc[c] * inv;
    };
    const std::vector<const std::vector<float>*> rgbaIn{&rs.r, &rs.g, &rs.b, &rs.a};
    const std::vector<float*> rgbaOut{img.channels[0].f.data(), img.channels[1].f.data(), img.channels[2].f.data(), img.channels[3].f.data()};
    float* zOut = img.channels[4].f.data();
    int floatBase = 0, uintBase = 0;
    std::vector<int> aovFloatBase(aovs.size()), aovUIntBase(aovs.size());
    for (size_t a = 0; a < aovs.size(); ++a) {
      aovFloatBase[a] = floatBase, aovUIntBase[a] = uintBase;
      if (aovs[a].isUInt) ++uintBase;
      else floatBase += aovs[a].components;
    }
    // Per filtered output variable, its sample arrays and image channels: set up once per bucket,
    // not per pixel.
    std::vector<std::vector<const std::vector<float>*>> aovIn(aovs.size());
    std::vector<std::vector<float*>> aovOut(aovs.size());
    for (size_t a = 0; a < aovs.size(); ++a)
      if (!aovs[a].isUInt && !aovs[a].filter.special())
        for (int c = 0; c < aovs[a].components; ++c) {
          aovIn[a].push_back(&rs.aov[size_t(aovFloatBase[a] + c)]);
          aovOut[a].push_back(img.channels[size_t(aovImageChannel[a][size_t(c)])].f.data());
        }
    for (int py = bk.y0; py < bk.y1; ++py)
      for (int px = bk.x0; px < bk.x1; ++px) {
        filterInto(mainTable, rgbaIn, rgbaOut, px, py);
        const size_t q = size_t(py - ry0) * rw + size_t(px - rx0);
        const size_t o = size_t(py - cy0) * img.width + size_t(px - cx0);
        // Z: the nearest surface any of the pixel's samples saw (zmin).
        float z = view.farClip;
        for (int i = 0; i < N; ++i) z = std::min(z, rs.z[q * N + i]);
        zOut[o] = z;
        for (size_t a = 0; a < aovs.size(); ++a) {
          const AovChannel& ch = aovs[a];
          if (ch.isUInt) {
            img.channels[size_t(aovImageChannel[a][0])].u[o] =
                specialFilterU(ch.filter.kind, rs.aovU[size_t(aovUIntBase[a])].data() + q * N, rs.aovZ.data() + q * N, N);
          } else if (ch.filter.special()) {
            for (int c = 0; c < ch.components; ++c)
              img.channels[size_t(aovImageChannel[a][size_t(c)])].f[o] =
                  specialFilter(ch.filter.kind, rs.aov[size_t(aovFloatBase[a] + c)].data() + q * N, rs.aovZ.data() + q * N, N, 0.f);
          } else {
            filterInto(*aovTables[a], aovIn[a], aovOut[a], px, py);
          }
        }
      }
    // DEEP HOOK: deep output forms its samples here from r.visitFragments() (resample/deep.h).
    if (deepFormer) deepFormer->formBucket(r, size_t(&bk - buckets.data()), bk.x0, bk.y0, bk.x1, bk.y1, rx0, ry0, rw, rh);
    auto t4 = clock::now();
    ts.stats.setupSeconds += std::chrono::duration<double>(t1 - t0).count();
    ts.stats.partsSeconds += gather;
    ts.stats.partsFetched += ts.parts.size();
    ts.stats.rasterSeconds += raster;
    ts.stats.resolveSeconds += std::chrono::duration<double>(t3 - t2).count();
    ts.stats.filterSeconds += std::chrono::duration<double>(t4 - t3).count();
    ts.stats.raster.add(r.stats());
    ts.stats.samples += uint64_t(bk.x1 - bk.x0) * uint64_t(bk.y1 - bk.y0) * uint64_t(N);
    ++ts.stats.buckets;
    if (showProgress) progress.advance();
  };
  std::map<const store::StoreReader*, store::CacheStats> cacheBefore;
  for (const Source& src : spec.sources) cacheBefore.emplace(src.store.get(), src.store->cacheStats());
  tbb::parallel_for(tbb::blocked_range<size_t>(0, buckets.size(), 1), [&](const tbb::blocked_range<size_t>& range) {
    for (size_t b = range.begin(); b != range.end(); ++b) processBucket(buckets[b]);
  });
  progress.finish();

  for (auto& ts : threads) {
    result.stats.raster.add(ts.stats.raster);
    result.stats.buckets += ts.stats.buckets;
    result.stats.samples += ts.stats.samples;
    result.stats.setupSeconds += ts.stats.setupSeconds;
    result.stats.partsSeconds += ts.stats.partsSeconds;
    result.stats.partsFetched += ts.stats.partsFetched;
    result.stats.rasterSeconds += ts.stats.rasterSeconds;
    result.stats.resolveSeconds += ts.stats.resolveSeconds;
    result.stats.filterSeconds += ts.stats.filterSeconds;
  }
  result.stats.wallSeconds = std::chrono::duration<double>(clock::now() - wallStart).count();
  for (const auto& [store, before] : cacheBefore) {
    const store::CacheStats now = store->cacheStats();
    result.stats.partsDecoded += now.misses - before.misses;
    result.stats.partsWaited += now.waits - before.waits;
  }

  ImageProvenance& pv = result.provenance;
  pv.worldToCamera = cam.worldToCamera;
  pv.worldToNdc = cameraToNdc(view, W, H) * cam.worldToCamera;
  pv.frame = spec.sources[0].frame;
  pv.fpsNum = meta0.fps.num, pv.fpsDen = meta0.fps.den;
  pv.shutterOpen = shutter.earliest(), pv.shutterClose = shutter.latest();
  std::ostringstream sh;
  sh.precision(9);
  for (size_t g = 0; g < shutter.groups().size(); ++g) {
    const auto& gr = shutter.groups()[g];
    sh << (g ? "; " : "") << (shutter.groups().size() > 1 ? (g == 0 ? "field 1 " : "field 2 ") : "") << "[" << gr.open << ", " << gr.close
       << "] frames, " << gr.shape.description();
  }
  if (shutter.rolling().duration != 0)
    sh << "; rolling " << shutter.rolling().duration << " frames " << (shutter.rolling().upward ? "upward" : "downward");
  pv.shutter = sh.str();
  return result;
}

}  // namespace reshutter::resample
