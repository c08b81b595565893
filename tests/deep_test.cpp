// Deep output end to end (the unit cases are in deep_units_test.cpp): flattening the deep image
// reproduces the flat image, the file passes OpenEXR's checker and an independent
// reader (OpenImageIO) agrees. Suites named *Hard* hold the numerically nasty cases.
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <memory>

#include <gtest/gtest.h>

#include <OpenEXR/ImfChannelList.h>
#include <OpenEXR/ImfCheckFile.h>
#include <OpenEXR/ImfFrameBuffer.h>
#include <OpenEXR/ImfHeader.h>
#include <OpenEXR/ImfInputFile.h>

#include "common/error.h"
#include "common/random.h"
#include "resample/deep.h"
#include "resample/resampler.h"
#include "store/reader.h"
#include "store/writer.h"
#include "test_util.h"
#include "tests/deep_test_util.h"
#include "tests/exr_test_util.h"

namespace reshutter {
namespace {

using namespace resample;
using test::ScratchDir;
using namespace test::deep;

// ---------------------------------------------------------------------------------------------
// Scenes: rectangles of micropolygons given in raster space at a depth, moving in raster space.

struct Rect {
  uint32_t object = 1;
  double x0 = 0, y0 = 0, x1 = 10, y1 = 10;  // raster, at shutter open
  double z = 10, tilt = 0;                  // depth at the left edge; z grows by tilt per pixel in x
  double dx = 0, dy = 0, dz = 0;            // raster motion (px) and depth motion over the shutter
  float c[3] = {0.5f, 0.5f, 0.5f};          // straight colour
  float o[3] = {1, 1, 1};                   // opacity
  bool matte = false;
  double mpSize = 1.0;  // micropolygon size in pixels
};

store::StoreMeta sceneMeta(int w, int h) {
  store::StoreMeta m;
  m.schema.attrs = {{"Ci", store::AttrType::Color, store::AttrRate::Vertex, store::AttrCodec::Lossless},
                    {"Oi", store::AttrType::Color, store::AttrRate::Vertex, store::AttrCodec::Lossless}};
  m.cameras[0].width = w;
  m.cameras[0].height = h;
  m.cameras[0].fovDegrees = 50;
  m.cameras[0].nearClip = 0.1;
  m.tileSize = 16;
  m.provenance = "deep_test";
  return m;
}

std::shared_ptr<const store::StoreReader> writeScene(const std::string& path, int w, int h, const std::vector<Rect>& rects) {
  store::StoreWriter writer(path, sceneMeta(w, h));
  const store::Projector proj(writer.meta().cameras[0]);
  const uint32_t moving = writer.addSchedule({0.0, 1.0});
  uint32_t gridId = 0;
  for (const Rect& r : rects) {
    const int nu = std::max(1, int(std::ceil((r.x1 - r.x0) / r.mpSize))), nv = std::max(1, int(std::ceil((r.y1 - r.y0) / r.mpSize)));
    const uint32_t nV = uint32_t((nu + 1) * (nv + 1));
    const bool moves = r.dx != 0 || r.dy != 0 || r.dz != 0;
    const int K = moves ? 2 : 1;
    std::vector<glm::vec3> pos(size_t(K) * nV);
    std::vector<float> ci(size_t(nV) * 3), oi(size_t(nV) * 3);
    for (int j = 0; j <= nv; ++j)
      for (int i = 0; i <= nu; ++i) {
        const size_t v = size_t(j) * (nu + 1) + size_t(i);
        const double rx = r.x0 + (r.x1 - r.x0) * i / nu, ry = r.y0 + (r.y1 - r.y0) * j / nv;
        for (int k = 0; k < K; ++k) {
          const double z = r.z + r.tilt * (rx - r.x0) + r.dz * k;
          pos[size_t(k) * nV + v] = glm::vec3(proj.unproject({rx + r.dx * k, ry + r.dy * k}, z));
        }
        for (int c = 0; c < 3; ++c) ci[v * 3 + size_t(c)] = r.c[c] * r.o[c], oi[v * 3 + size_t(c)] = r.o[c];
      }
    std::vector<uint32_t> corners;
    for (int j = 0; j < nv; ++j)
      for (int i = 0; i < nu; ++i) {
        const uint32_t a = uint32_t(j * (nu + 1) + i);
        corners.insert(corners.end(), {a, a + 1, a + 1 + uint32_t(nu + 1), a + uint32_t(nu + 1)});
      }
    store::GridInput g;
    g.schedule = moves ? moving : 0;
    g.numVertices = nV;
    g.positions = pos;
    g.corners = corners;
    g.objectId = r.object;
    g.gridId = gridId++;
    g.flags = r.matte ? store::kMatte : 0;
    g.attrs = {store::AttrValues{ci, {}}, store::AttrValues{oi, {}}};
    writer.addGrid(g);
  }
  writer.close();
  return std::make_shared<const store::StoreReader>(path);
}

RenderResult renderDeep(const std::shared_ptr<const store::StoreReader>& store, const std::string& filter, int spp = 16, float tolerance = 0.01f,
                        std::vector<AovRequest> aovs = {}, const RenderSpec::LensOverride& lens = {}) {
  RenderSpec spec;
  spec.lens = lens;
  spec.sources = {Source{store, store->meta().frame}};
  spec.shutter = ShutterModel::progressive(double(store->meta().frame), double(store->meta().frame) + 1.0, ShutterShape::parse("box", "test"));
  SamplePattern::factor(spp, spec.samplesX, spec.samplesY);
  spec.filter = FilterSpec::parse(filter, "test");
  spec.aovs = std::move(aovs);
  spec.progress = false;
  spec.deep = true;
  spec.deepOptions.tolerance = tolerance;
  spec.bucketSize = 16;
  return render(spec);
}

struct FlattenError {
  double max = 0, mean = 0, p99 = 0;
  int worstX = 0, worstY = 0;
};

// Per pixel, the largest |flat − flattened deep| over R G B A.
FlattenError compareFlatten(const RenderResult& res, bool matteAware = true) {
  const FlatImage& img = res.image;
  const DeepImage& deep = res.deep;
  std::vector<double> errs;
  FlattenError e;
  DeepPixel px;
  for (int y = img.y0; y < img.y0 + img.height; ++y)
    for (int x = img.x0; x < img.x0 + img.width; ++x) {
      deep.getPixel(x, y, px);
      EXPECT_TRUE(isTidy(px)) << "pixel " << x << "," << y;
      const FlatDeepPixel f = flattenDeepPixel(px, deep.layout, matteAware);
      const size_t o = size_t(y - img.y0) * img.width + size_t(x - img.x0);
      const double d = std::max({std::abs(f.r - img.channels[0].f[o]), std::abs(f.g - img.channels[1].f[o]), std::abs(f.b - img.channels[2].f[o]),
                                 std::abs(f.a - img.channels[3].f[o])});
      if (d > e.max) e.max = d, e.worstX = x, e.worstY = y;
      errs.push_back(d);
      e.mean += d;
    }
  e.mean /= double(errs.size());
  // Flat and deep agreeing says nothing if both are empty: every scene compared here covers most
  // of its frame.
  double alpha = 0;
  for (float a : img.channels[3].f) alpha += a;
  EXPECT_GT(alpha, 0.5 * double(errs.size())) << "the flat image is mostly empty";
  std::sort(errs.begin(), errs.end());
  e.p99 = errs[size_t(0.99 * double(errs.size() - 1))];
  return e;
}

std::string describePixel(const RenderResult& res, int x, int y) {
  DeepPixel px;
  res.deep.getPixel(x, y, px);
  std::string s;
  char buf[256];
  const size_t o = size_t(y - res.image.y0) * res.image.width + size_t(x - res.image.x0);
  std::snprintf(buf, sizeof buf, "flat RGBA %.5f %.5f %.5f %.5f; %zu samples:\n", res.image.channels[0].f[o], res.image.channels[1].f[o],
                res.image.channels[2].f[o], res.image.channels[3].f[o], px.size());
  s += buf;
  for (size_t i = 0; i < px.size(); ++i) {
    const float* r = px.at(i);
    std::snprintf(buf, sizeof buf, "  Z %.5f..%.5f RGB %.5f %.5f %.5f A %.5f obj %u flags %u\n", r[kDeepZ], r[kDeepZBack], r[kDeepR], r[kDeepG], r[kDeepB],
                  r[kDeepA], px.uat(i)[kDeepObjectId], px.uat(i)[kDeepFlags]);
    s += buf;
  }
  return s;
}

// A moving semi-transparent scene: overlapping translucent cards in front of an opaque
// background, at distinct depths, some moving, one tilted.
std::vector<Rect> translucentScene() {
  std::vector<Rect> rs;
  Rect bg;
  bg.object = 1, bg.x0 = -4, bg.y0 = -4, bg.x1 = 68, bg.y1 = 52, bg.z = 40, bg.mpSize = 2;
  bg.c[0] = 0.2f, bg.c[1] = 0.4f, bg.c[2] = 0.6f;
  rs.push_back(bg);
  Rect a;
  a.object = 2, a.x0 = 5, a.y0 = 6, a.x1 = 30, a.y1 = 30, a.z = 10, a.dx = 12, a.dy = 3;
  a.c[0] = 0.9f, a.c[1] = 0.2f, a.c[2] = 0.1f;
  a.o[0] = a.o[1] = a.o[2] = 0.5f;
  rs.push_back(a);
  Rect b;
  b.object = 3, b.x0 = 20, b.y0 = 15, b.x1 = 55, b.y1 = 40, b.z = 20, b.tilt = 0.05, b.dx = -6, b.dz = 1;
  b.c[0] = 0.1f, b.c[1] = 0.8f, b.c[2] = 0.3f;
  b.o[0] = b.o[1] = b.o[2] = 0.3f;
  b.mpSize = 0.7;
  rs.push_back(b);
  return rs;
}


// ---------------------------------------------------------------------------------------------
// End to end

TEST(DeepRender, FlattenMatchesFlatBoxFilter) {
  ScratchDir dir;
  auto store = writeScene(dir.path("s.mps"), 64, 48, translucentScene());
  const RenderResult res = renderDeep(store, "box:1", 16);
  const FlattenError e = compareFlatten(res);
  std::printf("box: max %.3g mean %.3g p99 %.3g at %d,%d\n", e.max, e.mean, e.p99, e.worstX, e.worstY);
  // No two volume samples overlap in this scene, so flattening is exact up to float rounding.
  EXPECT_LT(e.max, 1e-5) << describePixel(res, e.worstX, e.worstY);
}

TEST(DeepRender, FlattenMatchesFlatWideFilters) {
  ScratchDir dir;
  auto store = writeScene(dir.path("s.mps"), 64, 48, translucentScene());
  for (const char* filter : {"triangle:2", "gaussian:2", "gaussian:3", "blackman-harris:3"}) {
    const RenderResult res = renderDeep(store, filter, 16);
    const FlattenError e = compareFlatten(res);
    std::printf("%s: max %.3g mean %.3g\n", filter, e.max, e.mean);
    EXPECT_LT(e.max, 1e-5) << filter << "\n" << describePixel(res, e.worstX, e.worstY);
  }
}

TEST(DeepRender, DefocusedFramesFlattenToTheFlatImage) {
  // Depth of field moves every sample's surfaces; the deep pixel still holds what each sample saw.
  ScratchDir dir;
  auto store = writeScene(dir.path("s.mps"), 64, 48, translucentScene());
  RenderSpec::LensOverride lens;
  lens.fstop = 2, lens.focalLength = 1, lens.focalDistance = 20;
  for (const char* filter : {"box:1", "gaussian:2"}) {
    const RenderResult res = renderDeep(store, filter, 16, 0.01f, {}, lens);
    EXPECT_GT(res.stats.raster.lensMicropolygons, 0u);
    const FlattenError e = compareFlatten(res);
    EXPECT_LT(e.max, 1e-5) << filter << "\n" << describePixel(res, e.worstX, e.worstY);
  }
}

// Negative lobes are clamped for deep (alpha must stay in [0, 1]); the flattened deep image is the
// image filtered with the positive part: close to, not equal to, the flat image. Exactly: with
// sample values v_q and filter weights w_q over a pixel's support, flat = Σ w v / Σ w and
// flattened deep = Σ max(w, 0) v / Σ max(w, 0). At one sample per pixel a box:1 render gives every
// sample's value (R G B A), so both sums can be formed here from the filter's definition and held
// to float rounding, in every pixel whose support lies inside the image.
TEST(DeepRender, NegativeLobeFiltersFlattenToTheirPositivePart) {
  ScratchDir dir;
  const int W = 64, H = 48;
  auto store = writeScene(dir.path("s.mps"), W, H, translucentScene());
  const RenderResult res = renderDeep(store, "catmull-rom", 1);
  const RenderResult samples = renderDeep(store, "box:1", 1);  // one sample per pixel: its value
  const FilterSpec filter = FilterSpec::parse("catmull-rom", "test");
  const SamplePattern pattern(1, 1, 0);
  const int M = 2;  // catmull-rom:4 reaches 2 px from the pixel centre
  const FlatImage& flat = res.image;
  double worstDeep = 0, worstFlat = 0, lobeEffect = 0;
  int negativeWeights = 0;
  DeepPixel px;
  for (int y = M; y < H - M; ++y)
    for (int x = M; x < W - M; ++x) {
      double sum[4] = {0, 0, 0, 0}, sumPos[4] = {0, 0, 0, 0}, w = 0, wPos = 0;
      for (int qy = y - M; qy <= y + M; ++qy)
        for (int qx = x - M; qx <= x + M; ++qx) {
          const glm::vec2 o = pattern.offset(pattern.patternOf(qx, qy), 0);
          const double wq = double(filter1D(filter.kind, float(qx) + o.x - float(x) - 0.5f, filter.width)) *
                            double(filter1D(filter.kind, float(qy) + o.y - float(y) - 0.5f, filter.height));
          const size_t q = size_t(qy) * W + size_t(qx);
          w += wq, wPos += std::max(wq, 0.0), negativeWeights += wq < 0;
          for (int c = 0; c < 4; ++c) {
            const double v = samples.image.channels[size_t(c)].f[q];
            sum[c] += wq * v, sumPos[c] += std::max(wq, 0.0) * v;
          }
        }
      res.deep.getPixel(x, y, px);
      const FlatDeepPixel d = flattenDeepPixel(px, res.deep.layout, true);
      const double deep[4] = {d.r, d.g, d.b, d.a};
      for (int c = 0; c < 4; ++c) {
        const double f = flat.channels[size_t(c)].f[size_t(y) * W + size_t(x)];
        worstDeep = std::max(worstDeep, std::abs(deep[c] - sumPos[c] / wPos));
        worstFlat = std::max(worstFlat, std::abs(f - sum[c] / w));
        lobeEffect = std::max(lobeEffect, std::abs(deep[c] - f));
      }
    }
  std::printf("catmull-rom, 1 spp: flattened deep vs positive part %.3g, flat vs signed filter %.3g, deep vs flat %.3g; %d negative weights\n", worstDeep,
              worstFlat, lobeEffect, negativeWeights);
  EXPECT_GT(negativeWeights, 1000);
  EXPECT_LT(worstFlat, 1e-5) << "the sample values or the weights are not the renderer's";
  EXPECT_LT(worstDeep, 1e-5) << "the flattened deep image is not the image filtered with the filter's positive part";
  EXPECT_GT(lobeEffect, 1e-3) << "the negative lobes must matter somewhere in this scene";
  for (const auto* r : {&res, &samples})
    for (int y = 0; y < H; ++y)
      for (int x = 0; x < W; ++x) {
        r->deep.getPixel(x, y, px);
        EXPECT_TRUE(isTidy(px)) << "pixel " << x << "," << y;
        for (size_t i = 0; i < px.size(); ++i) {
          EXPECT_GE(px.at(i)[kDeepA], 0.f);
          EXPECT_LE(px.at(i)[kDeepA], 1.f);
        }
      }
}

// Two translucent cards passing through each other inside pixels: the front sample's depth range is
// cut where the next starts, so the image stays tidy and flattens exactly.
TEST(DeepRender, InterpenetratingSurfacesAreTidyAndClose) {
  ScratchDir dir;
  std::vector<Rect> rs = translucentScene();
  Rect c;
  c.object = 4, c.x0 = 10, c.y0 = 10, c.x1 = 50, c.y1 = 30, c.z = 15, c.tilt = 0.3, c.dy = 4;  // crosses card 3 (z 20-21.75)
  c.o[0] = c.o[1] = c.o[2] = 0.6f;
  c.c[0] = 0.9f, c.c[1] = 0.9f, c.c[2] = 0.1f;
  rs.push_back(c);
  auto store = writeScene(dir.path("s.mps"), 64, 48, rs);
  const RenderResult res = renderDeep(store, "gaussian:2", 16);
  const FlattenError e = compareFlatten(res);
  std::printf("interpenetrating: max %.3g mean %.3g p99 %.3g\n", e.max, e.mean, e.p99);
  EXPECT_LT(e.max, 1e-5) << describePixel(res, e.worstX, e.worstY);
  EXPECT_TRUE(res.deep.anyThick());
}

TEST(DeepRender, MatteHoldsOutAndFlattensLikeTheFlatImage) {
  ScratchDir dir;
  std::vector<Rect> rs = translucentScene();
  Rect m;
  m.object = 9, m.matte = true, m.x0 = 30, m.y0 = 0, m.x1 = 45, m.y1 = 48, m.z = 5, m.dx = 7;
  rs.push_back(m);
  auto store = writeScene(dir.path("s.mps"), 64, 48, rs);
  const RenderResult res = renderDeep(store, "gaussian:2", 16);
  const FlattenError aware = compareFlatten(res, true);
  EXPECT_LT(aware.max, 1e-5) << describePixel(res, aware.worstX, aware.worstY);
  // A plain flatten (what a compositor without matte flags does) gets the same colour and the
  // hold-out's coverage in alpha: inside the matte RGB = 0, A = 1.
  DeepPixel px;
  res.deep.getPixel(38, 20, px);
  const FlatDeepPixel plain = flattenDeepPixel(px, res.deep.layout, false);
  EXPECT_NEAR(plain.r, 0.0, 1e-6);
  EXPECT_NEAR(plain.a, 1.0, 1e-6);
  ASSERT_GE(px.size(), 1u);
  EXPECT_EQ(px.uat(0)[kDeepFlags], kDeepFlagMatte);
}

TEST(DeepRender, ColouredOpacityAndOutputVariables) {
  ScratchDir dir;
  std::vector<Rect> rs = translucentScene();
  rs[1].o[0] = 0.2f, rs[1].o[1] = 0.5f, rs[1].o[2] = 0.8f;
  auto store = writeScene(dir.path("s.mps"), 64, 48, rs);
  const RenderResult res =
      renderDeep(store, "gaussian:2", 16, 0.01f, {AovRequest::parse("Oi", "t"), AovRequest::parse("z:zmin", "t"), AovRequest::parse("id", "t")});
  EXPECT_TRUE(res.deep.anyColouredAlpha());
  const DeepLayout& L = res.deep.layout;
  ASSERT_EQ(L.floats.size(), 4u);  // Oi.R Oi.G Oi.B premultiplied, z by value
  EXPECT_TRUE(L.floats[0].premultiplied);
  EXPECT_FALSE(L.floats[3].premultiplied);
  EXPECT_TRUE(L.uints.empty());  // the id is the objectid channel
  // Colour flattens exactly per channel; the premultiplied output variable flattens to the flat one
  // up to the difference between A (mean opacity) and the per-channel alphas.
  const FlattenError e = compareFlatten(res);
  double auxErr = 0;
  DeepPixel px;
  const ImageChannel* oiR = res.image.find(L.floats[0].name);
  ASSERT_NE(oiR, nullptr);
  for (int y = 0; y < 48; ++y)
    for (int x = 0; x < 64; ++x) {
      res.deep.getPixel(x, y, px);
      const FlatDeepPixel f = flattenDeepPixel(px, L, true);
      auxErr = std::max(auxErr, std::abs(f.aux[0] - oiR->f[size_t(y) * 64 + x]));
    }
  std::printf("coloured: rgba max %.3g, Oi.R max %.3g\n", e.max, auxErr);
  // A is the mean of the per-channel visible alphas, corrected with its own transmittance: exact too.
  EXPECT_LT(e.max, 1e-5);
  EXPECT_LT(auxErr, 1e-5);
}

// The demo scene (shaded by `reshutter demo`): moving, translucent, a matte hold-out, objects that
// touch and pass through each other.
TEST(DeepRender, DemoSceneFlattensToTheFlatImage) {
  ScratchDir dir;
  // The demo is always built: a demo that fails is a failure, not a reason to skip.
  auto r = test::runReshutter("demo -o " + dir.path("demo") + " --res 320 180");
  ASSERT_EQ(r.exitCode, 0) << r.out << r.err;
  ASSERT_TRUE(std::filesystem::exists(dir.path("demo/demo.mps"))) << r.out;
  // Its own deep output passes OpenEXR's checker.
  ASSERT_TRUE(std::filesystem::exists(dir.path("demo/progressive_deep.exr"))) << r.out;
  EXPECT_FALSE(Imf::checkOpenEXRFile(dir.path("demo/progressive_deep.exr").c_str(), false, false, true));
  auto store = std::make_shared<const store::StoreReader>(dir.path("demo/demo.mps"));
  for (const char* filter : {"box", "gaussian:2"}) {
    const RenderResult res = renderDeep(store, filter, 16);
    const FlattenError e = compareFlatten(res);
    std::printf("demo %s: max %.3g mean %.3g p99 %.3g at %d,%d\n%s", filter, e.max, e.mean, e.p99, e.worstX, e.worstY,
                describePixel(res, e.worstX, e.worstY).c_str());
    EXPECT_LT(e.max, 1e-5) << filter;
  }
  const RenderResult res = renderDeep(store, "box", 4);
  EXPECT_EQ(res.deep.objectNames.at(2), "floor");  // names from the shading pass → idManifest
}

// A CLI-generated store: thousands of small translucent grids streaking through each other.
TEST(DeepRender, GeneratedTranslucentStoreFlattensToTheFlatImage) {
  ScratchDir dir;
  auto r = test::runReshutter("generate -n 60000 --width 160 --height 90 --transparent 0.5 -o " + dir.path("g.mps"));
  ASSERT_EQ(r.exitCode, 0) << r.err;
  auto store = std::make_shared<const store::StoreReader>(dir.path("g.mps"));
  for (const char* filter : {"box", "gaussian:2"}) {
    const RenderResult res = renderDeep(store, filter, 16);
    const FlattenError e = compareFlatten(res);
    std::printf("generated %s: max %.3g mean %.3g, %.2f samples/pixel\n", filter, e.max, e.mean, double(res.deep.totalSamples()) / (160 * 90));
    EXPECT_LT(e.max, 1e-5) << filter << "\n" << describePixel(res, e.worstX, e.worstY);
  }
}

// ---------------------------------------------------------------------------------------------
// The file: OpenEXR's checker, read back, header, compressions, an independent reader.

TEST(DeepFile, WritesCheckedTidyScanlineDeep) {
  ScratchDir dir;
  std::vector<Rect> rs = translucentScene();
  rs[2].o[1] = 0.6f;  // coloured: AR AG AB
  auto store = writeScene(dir.path("s.mps"), 64, 48, rs);
  RenderResult res = renderDeep(store, "gaussian:2", 16, 0.01f, {AovRequest::parse("Oi", "t")});
  res.deep.objectNames = {{1, "background"}, {2, "red card"}, {3, "green card"}};
  for (auto comp : {DeepCompression::Zips, DeepCompression::Rle, DeepCompression::None}) {
    const std::string path = dir.path("d.exr");
    DeepExrOptions o;
    o.compression = comp;
    writeDeepExr(path, res.deep, res.provenance, o);
    EXPECT_FALSE(Imf::checkOpenEXRFile(path.c_str(), false, false, true)) << "checkOpenEXRFile reports a problem";
    const test::DeepExr rb = test::readDeepExr(path);
    EXPECT_TRUE(rb.tidyState);
    EXPECT_TRUE(rb.manifest);
    EXPECT_EQ(rb.image.totalSamples(), res.deep.totalSamples());
    for (const char* c : {"R", "G", "B", "A", "Z", "ZBack", "AR", "AG", "AB", "Oi.R", "objectid"})
      EXPECT_NE(std::find(rb.channels.begin(), rb.channels.end(), c), rb.channels.end()) << c;
    DeepPixel px, back;
    for (int y = 0; y < 48; ++y)
      for (int x = 0; x < 64; ++x) {
        res.deep.getPixel(x, y, px);
        rb.image.getPixel(x, y, back);
        ASSERT_EQ(back.size(), px.size());
        for (size_t i = 0; i < px.size(); ++i) {
          for (int f : {kDeepZ, kDeepZBack, kDeepR, kDeepG, kDeepB, kDeepA, kDeepAR, kDeepAG, kDeepAB}) EXPECT_EQ(back.at(i)[f], px.at(i)[f]) << f;
          EXPECT_EQ(back.uat(i)[kDeepObjectId], px.uat(i)[kDeepObjectId]);
        }
      }
  }
}

TEST(DeepFile, FailedWriteLeavesNothing) {
  ScratchDir dir;
  auto store = writeScene(dir.path("s.mps"), 16, 16, translucentScene());
  const RenderResult res = renderDeep(store, "box", 4);
  EXPECT_THROW(writeDeepExr(dir.path("missing/d.exr"), res.deep, res.provenance), Error);
  EXPECT_THROW(parseDeepCompression("piz", "--deep-compression"), Error);
  EXPECT_FALSE(std::filesystem::exists(dir.path("missing/d.exr")));
}

// The CLI writes flat and deep; OpenImageIO reads the deep file and its flattening matches the
// flat image (our deep output is tidy and single-alpha here, where OIIO 2.4's --flatten is right).
TEST(DeepFile, CliAndOpenImageIOAgree) {
  ScratchDir dir;
  auto store = writeScene(dir.path("s.mps"), 64, 48, translucentScene());
  const std::string flat = dir.path("flat.exr"), deep = dir.path("deep.exr");
  auto r = test::runReshutter("resample " + dir.path("s.mps") + " -o " + flat + " --deep " + deep + " --filter gaussian:2 --spp 16");
  ASSERT_EQ(r.exitCode, 0) << r.err;
  EXPECT_FALSE(Imf::checkOpenEXRFile(deep.c_str(), false, false, true));
  // Deep only, and neither.
  r = test::runReshutter("resample " + dir.path("s.mps") + " --deep " + dir.path("only.exr") + " --deep-compression rle --deep-tolerance 0.1");
  EXPECT_EQ(r.exitCode, 0) << r.err;
  EXPECT_TRUE(std::filesystem::exists(dir.path("only.exr")));
  r = test::runReshutter("resample " + dir.path("s.mps"));
  EXPECT_NE(r.exitCode, 0);
  EXPECT_NE(r.err.find("nothing to write"), std::string::npos) << r.err;

  // OpenImageIO is the independent reader here (and in ResampleCli): its absence is a failure, not
  // a reason to skip.
  ASSERT_EQ(test::runCommand("command -v oiiotool && command -v iinfo").exitCode, 0) << "openimageio-tools (oiiotool, iinfo) not installed";
  r = test::runImageTool("iinfo -v --stats " + deep);
  ASSERT_EQ(r.exitCode, 0) << r.err;
  EXPECT_NE(r.out.find("deep"), std::string::npos);
  EXPECT_NE(r.out.find("Stats NanCount: 0 0 0 0"), std::string::npos) << r.out;
  const std::string flattened = dir.path("flattened.exr");
  r = test::runImageTool("oiiotool " + deep + " --flatten --ch R,G,B,A -o " + flattened);
  ASSERT_EQ(r.exitCode, 0) << r.err;
  Imf::InputFile a(flat.c_str()), b(flattened.c_str());
  const Imath::Box2i dw = a.header().dataWindow();
  const int W = dw.max.x - dw.min.x + 1, H = dw.max.y - dw.min.y + 1;
  std::vector<float> fa(size_t(W) * H * 4), fb(size_t(W) * H * 4);
  for (auto [file, buf] : {std::pair{&a, &fa}, {&b, &fb}}) {
    Imf::FrameBuffer frame;
    const char* names[] = {"R", "G", "B", "A"};
    for (int c = 0; c < 4; ++c) frame.insert(names[c], Imf::Slice(Imf::FLOAT, reinterpret_cast<char*>(buf->data() + c), 16, 16 * size_t(W)));
    file->setFrameBuffer(frame);
    file->readPixels(dw.min.y, dw.max.y);
  }
  double maxErr = 0;
  for (size_t i = 0; i < fa.size(); ++i) maxErr = std::max(maxErr, double(std::abs(fa[i] - fb[i])));
  std::printf("oiiotool --flatten vs flat: max %.3g\n", maxErr);
  EXPECT_LT(maxErr, 1e-4);
}

// ---------------------------------------------------------------------------------------------
// Hard cases

TEST(DeepHard, AlphaNearOne) {
  const double a = 1 - 1e-7;
  double back = 1;
  for (int i = 0; i < 10; ++i) back *= 1 - deepSplitAlpha(a, 0.1);
  EXPECT_NEAR(1 - back, a, 1e-12);  // ten tenths composite to the whole
  EXPECT_NEAR(deepSplitScale(a, 0.5) * a, deepSplitAlpha(a, 0.5), 1e-15);
  const double alphas[3] = {a, a, 0.5}, colours[3] = {0.3, 0.6, 0.1};
  double m = 0, c = 0;
  deepMergeAlphas(alphas, colours, 3, 1, m, &c);
  EXPECT_TRUE(std::isfinite(c));
  EXPECT_LE(m, 1.0);
  EXPECT_NEAR(m, 1 - 1e-14 * 0.5, 1e-15);
  // The two near-opaque ones dominate equally, the third still shows: 0.4447..., not the two's
  // plain average 0.45.
  EXPECT_NEAR(c, logWeightedColour({a, a, 0.5}, {0.3, 0.6, 0.1}), 1e-12);
  EXPECT_GT(std::abs(c - 0.45), 1e-3);
  // Float pixel: a sample with alpha 1 - 1e-7 split by a point inside it.
  DeepPixel px;
  addSample(px, 1, 2, float(a), 0.5f, 1);
  addSample(px, 1.5f, 1.5f, 0.5f, 0.25f, 2);
  tidyDeepPixel(px, plainLayout());
  EXPECT_TRUE(isTidy(px));
  const FlatDeepPixel f = flattenDeepPixel(px, plainLayout(), false);
  EXPECT_TRUE(std::isfinite(f.r) && std::isfinite(f.a));
  EXPECT_NEAR(f.a, 1.0, 1e-6);
  EXPECT_NEAR(f.r, 0.5, 0.01);  // nearly all absorbed in front of the point
}

TEST(DeepHard, AlphaNearZero) {
  const double a = 1e-9;
  EXPECT_NEAR(deepSplitAlpha(a, 0.25) / (a * 0.25), 1.0, 1e-6);
  EXPECT_NEAR(deepSplitScale(a, 0.25), 0.25, 1e-9);
  EXPECT_EQ(deepSplitScale(0.0, 0.25), 0.25);
  const double alphas[2] = {a, a}, colours[2] = {2e-9, 4e-9};
  double m = 0, c = 0;
  deepMergeAlphas(alphas, colours, 2, 1, m, &c);
  EXPECT_NEAR(m / 2e-9, 1.0, 1e-6);
  EXPECT_NEAR(c / 6e-9, 1.0, 1e-6);
  // Zero alpha with colour (emission) is additive.
  const double zero[2] = {0, 0}, em[2] = {0.1, 0.2};
  deepMergeAlphas(zero, em, 2, 1, m, &c);
  EXPECT_EQ(m, 0.0);
  EXPECT_NEAR(c, 0.3, 1e-12);
  DeepPixel px;
  addSample(px, 1, 3, 1e-9f, 1e-9f, 1);
  addSample(px, 2, 4, 1e-9f, 1e-9f, 2);
  tidyDeepPixel(px, plainLayout());
  EXPECT_TRUE(isTidy(px));
  const FlatDeepPixel f = flattenDeepPixel(px, plainLayout(), false);
  EXPECT_NEAR(f.a / 2e-9, 1.0, 1e-5);
  EXPECT_NEAR(f.r / 2e-9, 1.0, 1e-5);
}

// Exact composite of weighted samples (the flat image's definition), for checking formation.
FlatDeepPixel flatReference(const std::vector<WeightedSample>& ws) {
  FlatDeepPixel f;
  for (const auto& s : ws) {
    double T[3] = {1, 1, 1}, C[3] = {0, 0, 0}, A[3] = {0, 0, 0};
    for (size_t k = 0; k < s.count; ++k) {
      const SampleFragment& fr = s.fragments[k];
      for (int c = 0; c < 3; ++c) C[c] += T[c] * fr.c[c], A[c] += fr.matte ? 0 : T[c] * fr.o[c], T[c] *= 1 - fr.o[c];
    }
    f.r += s.weight * C[0], f.g += s.weight * C[1], f.b += s.weight * C[2], f.a += s.weight * (A[0] + A[1] + A[2]) / 3;
  }
  return f;
}

TEST(DeepHard, TenThousandFragmentsInOnePixel) {
  // 100 samples × 100 fragments: 40 objects, depths interleaved, opacities from 1e-9 to 1 − 1e-7.
  Rng rng(7);
  const int S = 100, K = 100;
  std::vector<std::vector<SampleFragment>> frags(S);
  std::vector<WeightedSample> ws;
  for (int s = 0; s < S; ++s) {
    for (int k = 0; k < K; ++k) {
      const uint32_t obj = rng.below(40);
      const float z = 10.f + float(obj) + 0.001f * float(rng.below(5)) + (k == 0 ? 0.f : 0.f);
      const double pick = rng.uniform();
      const float o = pick < 0.1 ? 1e-9f : pick < 0.2 ? float(1 - 1e-7) : float(rng.uniform(0.0, 0.05));
      frags[size_t(s)].push_back(frag(z, o, float(rng.uniform()), obj));
    }
    std::sort(frags[size_t(s)].begin(), frags[size_t(s)].end(), [](auto& a, auto& b) { return a.z < b.z; });
    ws.push_back({1.f / S, frags[size_t(s)].data(), frags[size_t(s)].size()});
  }
  DeepPixel px;
  formDeepPixel(ws.data(), ws.size(), plainLayout(), {}, px);
  tidyDeepPixel(px, plainLayout());
  EXPECT_TRUE(isTidy(px));
  for (float v : px.f) EXPECT_TRUE(std::isfinite(v));
  const FlatDeepPixel d = flattenDeepPixel(px, plainLayout(), true), ref = flatReference(ws);
  EXPECT_NEAR(d.r, ref.r, 1e-4);
  EXPECT_NEAR(d.a, ref.a, 1e-4);
  EXPECT_LE(px.size(), 40u);
  // 10 000 raw point samples, many at coincident depths, through tidy directly.
  DeepPixel raw;
  for (int i = 0; i < 10000; ++i) addSample(raw, float(rng.below(500)) * 0.01f, 0, float(rng.uniform(0, 0.01)), 0.001f, 1);
  for (size_t i = 0; i < raw.size(); ++i) raw.at(i)[kDeepZBack] = raw.at(i)[kDeepZ];
  const FlatDeepPixel before = flattenDeepPixel(raw, plainLayout(), false);  // alpha is order-independent
  tidyDeepPixel(raw, plainLayout());
  EXPECT_TRUE(isTidy(raw));
  EXPECT_LE(raw.size(), 500u);
  EXPECT_NEAR(flattenDeepPixel(raw, plainLayout(), false).a, before.a, 1e-5);
}

TEST(DeepHard, CoincidentDepthsOfDifferentSurfaces) {
  std::vector<SampleFragment> s0{frag(5, 0.5f, 1, 1), frag(5, 0.5f, 0, 2), frag(5, 1, 0.5f, 3)};
  std::vector<WeightedSample> ws{{1.f, s0.data(), 3}};
  DeepPixel px;
  formDeepPixel(ws.data(), ws.size(), plainLayout(), {}, px);
  tidyDeepPixel(px, plainLayout());
  ASSERT_EQ(px.size(), 1u);  // three point samples at one depth merge
  EXPECT_TRUE(isTidy(px));
  EXPECT_EQ(px.at(0)[kDeepA], 1.f);
  // ... in the order the sample saw them: the flat composite 0.5 + 0.5·0 + 0.25·0.5, not the
  // opaque one's colour alone (0.5).
  const FlatDeepPixel f = flattenDeepPixel(px, plainLayout(), true), ref = flatReference(ws);
  EXPECT_NEAR(ref.r, 0.625, 1e-12);
  EXPECT_NEAR(f.r, ref.r, 1e-6);
  EXPECT_NEAR(f.g, ref.g, 1e-6);
  EXPECT_NEAR(f.a, ref.a, 1e-6);
}

TEST(DeepHard, PointAtAVolumesFrontAndBack) {
  DeepPixel px;
  addSample(px, 2, 2, 0.5f, 0.1f, 2);  // at the back
  addSample(px, 1, 2, 0.5f, 0.2f, 1);
  addSample(px, 1, 1, 0.5f, 0.3f, 3);  // at the front
  tidyDeepPixel(px, plainLayout());
  ASSERT_EQ(px.size(), 3u);  // touching is not overlapping: nothing to split
  EXPECT_TRUE(isTidy(px));
  EXPECT_EQ(px.uat(0)[kDeepObjectId], 3u);
  EXPECT_EQ(px.uat(1)[kDeepObjectId], 1u);
  EXPECT_EQ(px.uat(2)[kDeepObjectId], 2u);
  const FlatDeepPixel f = flattenDeepPixel(px, plainLayout(), false);
  EXPECT_NEAR(f.r, 0.3 + 0.5 * 0.2 + 0.25 * 0.1, 1e-6);
  // A point strictly inside splits the volume in two.
  DeepPixel in;
  addSample(in, 1, 2, 0.5f, 0.2f, 1);
  addSample(in, 1.25f, 1.25f, 0.5f, 0.3f, 3);
  tidyDeepPixel(in, plainLayout());
  ASSERT_EQ(in.size(), 3u);
  EXPECT_TRUE(isTidy(in));
  EXPECT_NEAR(1 - (1 - in.at(0)[kDeepA]) * (1 - in.at(2)[kDeepA]), 0.5, 1e-6);
  // The two pieces of the volume, composited, give back its colour.
  EXPECT_NEAR(in.at(0)[kDeepR] + (1 - in.at(0)[kDeepA]) * in.at(2)[kDeepR], 0.2, 1e-6);
}

TEST(DeepHard, OpaqueVolumeHidesWhatStartsInsideIt) {
  DeepPixel px;
  addSample(px, 1, 3, 1.f, 0.4f, 1);
  addSample(px, 2, 4, 0.5f, 0.5f, 2);
  tidyDeepPixel(px, plainLayout());
  EXPECT_TRUE(isTidy(px));
  const FlatDeepPixel f = flattenDeepPixel(px, plainLayout(), false);
  EXPECT_NEAR(f.r, 0.4, 1e-6);
  EXPECT_NEAR(f.a, 1.0, 1e-6);
}

}  // namespace
}  // namespace reshutter
