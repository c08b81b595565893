// Deep output, unit cases: the alpha arithmetic of splitting and merging samples, tidying a
// pixel's samples, and forming them from a sample's fragments.
#include <cmath>

#include <gtest/gtest.h>

#include "resample/deep.h"
#include "tests/deep_test_util.h"

namespace reshutter {
namespace {

using namespace resample;
using namespace test::deep;

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
  // Straight colours 0.8 and 0.2 (with equal straight colours every rule gives the same).
  const double alphas[2] = {0.5, 0.25}, colours[2] = {0.4, 0.05};
  double a = 0, c = 0;
  deepMergeAlphas(alphas, colours, 2, 1, a, &c);
  EXPECT_NEAR(a, 1 - 0.5 * 0.75, 1e-12);
  // The log-weighted rule (0.3900...), not `over` in either order (0.425, 0.35) nor the sum (0.45).
  EXPECT_NEAR(c, logWeightedColour({0.5, 0.25}, {0.4, 0.05}), 1e-12);
  for (double other : {0.425, 0.35, 0.45}) EXPECT_GT(std::abs(c - other), 0.02) << other;
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

TEST(DeepForm, ObjectNamesFromProvenance) {
  const auto names = objectNamesFromProvenance("reshutter shade: x; frame 1; objects: 1=\"backdrop\" 2=\"flag pole\" 13=\"matte holdout\"");
  ASSERT_EQ(names.size(), 3u);
  EXPECT_EQ(names.at(2), "flag pole");
  EXPECT_EQ(names.at(13), "matte holdout");
  EXPECT_TRUE(objectNamesFromProvenance("test").empty());
}

}  // namespace
}  // namespace reshutter
