// Re-timing on the shutter model: interlaced fields in one pass against the two-pass reference,
// frame-rate conversion across per-frame stores against analytic coverage, shutter shapes,
// rolling shutter slant, coverage gaps, rate conversion and where frames find their stores.
#include <algorithm>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <tuple>

#include <gtest/gtest.h>

#include "common/check.h"
#include "common/error.h"
#include "common/frame_range.h"
#include "resample/retime.h"
#include "tests/exr_test_util.h"
#include "tests/resample_test_util.h"
#include "tests/retime_test_util.h"
#include "tests/test_util.h"

using namespace reshutter;
using namespace reshutter::resample;
using namespace reshutter::test;
using namespace reshutter::test::retime;

namespace {

RenderSpec baseSpec(std::vector<Source> sources, ShutterModel shutter, int n = 8) {
  RenderSpec spec;
  spec.sources = std::move(sources);
  spec.shutter = std::move(shutter);
  spec.samplesX = spec.samplesY = n;
  spec.filter = FilterSpec::parse("box:1", "t");
  spec.progress = false;
  return spec;
}

bool sameBits(const RenderResult& a, const RenderResult& b) {
  if (a.image.channels.size() != b.image.channels.size()) return false;
  for (size_t c = 0; c < a.image.channels.size(); ++c)
    if (a.image.channels[c].f != b.image.channels[c].f || a.image.channels[c].u != b.image.channels[c].u) return false;
  return true;
}

}  // namespace

TEST(RetimeFields, SinglePassEqualsTwoPassBitForBitWithOneRowFilters) {
  ScratchDir dir;
  Motion m;
  auto s1 = frameStore(m, 3, dir.path("f3.mps"));
  const ShutterGroup f1{3.0, 3.25}, f2{3.5, 3.75};
  for (const char* filter : {"box:1", "gaussian:2x1", "catmull-rom:4x1"})
    for (int parity : {0, 1}) {
      RenderSpec one = baseSpec({Source{s1, 3}}, ShutterModel::fields(f1, f2, parity), 4);
      one.filter = FilterSpec::parse(filter, "t");
      RenderResult single = render(one);
      // The moving square was drawn for both fields at once (raster.cpp's groups together).
      EXPECT_GT(single.stats.raster.groupsTogetherMicropolygons, 0u) << filter;
      RenderResult pass[2];
      for (int k = 0; k < 2; ++k) {
        const ShutterGroup& g = k == 0 ? f1 : f2;
        RenderSpec spec = baseSpec({Source{s1, 3}}, ShutterModel::progressive(g.open, g.close), 4);
        spec.filter = one.filter;
        pass[k] = render(spec);
      }
      // Interlace the two passes: rows of parity `parity` from field 1.
      RenderResult woven = pass[0];
      for (size_t c = 0; c < woven.image.channels.size(); ++c)
        for (int y = 0; y < woven.image.height; ++y)
          if ((y - parity) % 2 != 0)
            for (int x = 0; x < woven.image.width; ++x) {
              const size_t i = size_t(y) * woven.image.width + x;
              woven.image.channels[c].f[i] = pass[1].image.channels[c].f[i];
            }
      EXPECT_TRUE(sameBits(single, woven)) << filter << " parity " << parity;
      // And the fields really differ (the square moved between them).
      EXPECT_FALSE(sameBits(pass[0], pass[1]));
    }
}

TEST(RetimeFields, TallerFiltersBlendNeighbouringFieldsOnlyNearMotion) {
  ScratchDir dir;
  Motion m;
  auto s1 = frameStore(m, 3, dir.path("f3.mps"));
  const ShutterGroup f1{3.0, 3.25}, f2{3.5, 3.75};
  RenderSpec one = baseSpec({Source{s1, 3}}, ShutterModel::fields(f1, f2, 0), 4);
  one.filter = FilterSpec::parse("gaussian:2x2", "t");
  RenderResult single = render(one);
  RenderSpec p1 = baseSpec({Source{s1, 3}}, ShutterModel::progressive(f1.open, f1.close), 4);
  p1.filter = one.filter;
  RenderResult pass1 = render(p1);
  // Field-1 rows differ from the full field-1 render only where the square moved between the
  // fields; rows far from it are identical.
  const auto &A = channel(single, "A").f, &B = channel(pass1, "A").f;
  int differing = 0;
  for (int y = 0; y < single.image.height; y += 2)
    for (int x = 0; x < single.image.width; ++x) {
      const size_t i = size_t(y) * single.image.width + x;
      if (A[i] != B[i]) ++differing;
      if (y > 30) {
        EXPECT_EQ(A[i], B[i]) << x << "," << y;
      }
    }
  EXPECT_GT(differing, 0);
}

// The two-pass reference interlaces the deep image as it does the flat one: every row's deep
// pixels are its own field's (field 2's rows once wrote field 1's samples), so the deep image
// flattens to the interlaced flat image on every row. A crop starting on an odd row checks that
// the field of a row is the raster row's, not the data window's.
TEST(RetimeFields, TwoPassInterlacesTheDeepImageRowByRow) {
  ScratchDir dir;
  Motion m;
  auto s = frameStore(m, 3, dir.path("f3.mps"));
  for (int parity : {0, 1})
    for (int cropY0 : {0, 5}) {
      FieldShutter fs;
      fs.firstFieldParity = parity;
      const auto passes = fieldPassShutters(3, fs);
      RenderResult field[2];
      for (int k = 0; k < 2; ++k) {
        RenderSpec spec = baseSpec({Source{s, 3}}, k == 0 ? passes.first : passes.second, 4);
        spec.filter = FilterSpec::parse("gaussian:2", "t");  // taller than a row: neighbouring rows mix within each pass
        spec.deep = true;
        spec.cropX0 = 0, spec.cropX1 = 48, spec.cropY0 = cropY0, spec.cropY1 = 36;
        field[k] = render(spec);
      }
      RenderResult woven = field[0];
      interlaceFields(woven, field[1], parity);
      int secondFieldRows = 0, rowsThatShowTheBug = 0;
      DeepPixel a, b, other;
      for (int y = woven.image.y0; y < woven.image.y0 + woven.image.height; ++y) {
        const int k = (y % 2 == parity) ? 0 : 1;  // upper dominance (parity 0): raster row 0 is field 1's
        secondFieldRows += k;
        bool differsFromOtherField = false;
        for (int x = woven.image.x0; x < woven.image.x0 + woven.image.width; ++x) {
          woven.deep.getPixel(x, y, a);
          field[k].deep.getPixel(x, y, b);
          field[1 - k].deep.getPixel(x, y, other);
          ASSERT_TRUE(a.f == b.f && a.u == b.u) << "pixel " << x << "," << y << " holds field " << 2 - k << "'s deep samples, not field " << k + 1 << "'s";
          differsFromOtherField |= a.f != other.f;
        }
        if (k == 1 && differsFromOtherField) ++rowsThatShowTheBug;
        EXPECT_LT(rowFlattenError(woven.deep, woven.image, y), 1e-5) << "row " << y << " (field " << k + 1 << "), parity " << parity;
      }
      EXPECT_GT(secondFieldRows, 0);
      EXPECT_GT(rowsThatShowTheBug, 3) << "the square must move between the fields, or field 1's samples on field 2's rows would pass";
      EXPECT_TRUE(woven.deep.tidy);
      EXPECT_GT(woven.deep.totalSamples(), 0u);
      EXPECT_NE(woven.provenance.shutter.find("two-pass fields"), std::string::npos) << woven.provenance.shutter;
    }
}

TEST(RetimeRate, IntervalsAcrossFrameBoundariesMatchAnalyticCoverage) {
  ScratchDir dir;
  Motion m;
  std::vector<Source> sources;
  // (The name is built with append: "s" + std::to_string(f) makes GCC 12 warn of a bogus memcpy
  // bound, -Wstringop-overflow, once the test body inlines it.)
  for (int64_t f = 0; f <= 4; ++f) sources.push_back(Source{frameStore(m, f, dir.path(std::string("s").append(std::to_string(f)).append(".mps"))), f});
  // 24 → 30 fps, 180°: output frame k covers [0.8k, 0.8k + 0.4] source frames; k = 1 spans 1.0.
  for (int k = 1; k <= 4; ++k) {
    const double a = 0.8 * k, b = a + 0.4;
    RenderResult r = render(baseSpec(sources, ShutterModel::progressive(a, b), 12));
    EXPECT_LT(coverageError(r, m, a, b), 0.01) << "output frame " << k << " [" << a << ", " << b << "]";
  }
  // Only the stores an interval reaches contribute, and each only inside its own coverage: a
  // store of the wrong frame alone cannot serve [1.6, 2.0].
  try {
    render(baseSpec({sources[0]}, ShutterModel::progressive(1.6, 2.0)));
    FAIL() << "expected a coverage error";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("not covered"), std::string::npos) << e.what();
  }
}

TEST(RetimeRate, CoverageGapIsAnErrorNamingTheTimes) {
  ScratchDir dir;
  Motion m;
  // Dumps rendered with a 180° shutter: each store covers [F, F + 0.5].
  std::vector<Source> sources;
  for (int64_t f = 1; f <= 2; ++f) sources.push_back(Source{frameStore(m, f, dir.path("h" + std::to_string(f) + ".mps"), 0, 0.5), f});
  try {
    render(baseSpec(sources, ShutterModel::progressive(1.25, 1.75)));
    FAIL() << "expected a gap error";
  } catch (const Error& e) {
    const std::string msg = e.what();
    EXPECT_NE(msg.find("1.5 to 1.75"), std::string::npos) << msg;
  }
}

TEST(RetimeShape, TrapezoidShutterWeightsTimeAsItOpens) {
  ScratchDir dir;
  Motion m;
  auto s = frameStore(m, 2, dir.path("t.mps"));
  const double a = 2.0, b = 3.0;
  RenderResult r = render(baseSpec({Source{s, 2}}, ShutterModel::progressive(a, b, ShutterShape::trapezoid(0.3, 0.6)), 12));
  const std::vector<double> ts{2.0, 2.3, 2.6, 3.0}, ws{0, 1, 1, 0};
  const double weighted = coverageError(r, m, a, b, ts, ws), boxed = coverageError(r, m, a, b);
  EXPECT_LT(weighted, 0.01);
  EXPECT_GT(boxed, 2 * weighted) << "the shape must matter";
}

TEST(RetimeShape, WarpIsTheInverseOfTheOpeningsCdf) {
  for (ShutterShape shape : {ShutterShape::trapezoid(0.2, 0.7), ShutterShape::trapezoid(0, 1), ShutterShape::trapezoid(0.5, 0.5),
                             ShutterShape::curve({{0, 0}, {0.1, 2}, {0.5, 0.5}, {1, 1}})}) {
    // CDF by fine quadrature of the density, independently of warp()'s closed form.
    const int n = 20000;
    std::vector<double> cdf(n + 1, 0.0);
    for (int i = 0; i < n; ++i) cdf[i + 1] = cdf[i] + 0.5 * (shape.density(double(i) / n) + shape.density(double(i + 1) / n)) / n;
    for (int i = 0; i <= n; i += 997) {
      const double f = double(i) / n, u = cdf[i] / cdf[n];
      EXPECT_NEAR(shape.warp(u), f, 2e-3) << shape.description() << " at " << f;
    }
    EXPECT_EQ(shape.warp(0), 0.0);
    EXPECT_EQ(shape.warp(1), 1.0);
  }
}

TEST(RetimeRolling, AVerticalEdgeLeansByThePredictedSlope) {
  ScratchDir dir;
  const int W = 64, H = 48;
  TestScene s = makeScene(W, H, {0.0, 1.0});
  s.meta.frame = 1;
  // A wide opaque slab whose right edge moves at v px/frame.
  const double v = 40, x0 = 10;
  TestMp mp;
  mp.knots = {s.rect(-100, -10, x0, H + 10, 10), s.rect(-100 + v, -10, x0 + v, H + 10, 10)};
  s.mps.push_back(mp);
  auto reader = writeScene(s, dir.path("slab.mps"));
  for (bool up : {false, true}) {
    const double D = 0.5;  // read-out duration, frames
    ShutterModel shutter = ShutterModel::progressive(1.2, 1.2);
    shutter.setRolling(RollingShutter{D, up, H});
    RenderResult r = render(baseSpec({Source{reader, 1}}, shutter, 8));
    // Edge position per row = Σ alpha + 0 (the slab covers from x < 0): fit a line over rows.
    std::vector<double> ys, xs;
    for (int y = 0; y < H; ++y) {
      double sum = 0;
      for (int x = 0; x < W; ++x) sum += channel(r, "A").f[size_t(y) * W + x];
      ys.push_back(y + 0.5), xs.push_back(sum);
    }
    double my = 0, mx = 0, sxy = 0, syy = 0;
    for (size_t i = 0; i < ys.size(); ++i) my += ys[i] / H, mx += xs[i] / H;
    for (size_t i = 0; i < ys.size(); ++i) sxy += (ys[i] - my) * (xs[i] - mx), syy += (ys[i] - my) * (ys[i] - my);
    const double slope = sxy / syy, predicted = (up ? -1 : 1) * v * D / H;
    EXPECT_NEAR(slope, predicted, 0.01 * std::abs(predicted)) << (up ? "upward" : "downward");
    // And the edge at the middle row sits where the middle row's time puts it.
    const double tMid = 0.2 + D * (up ? 1 - my / H : my / H);
    EXPECT_NEAR(mx, x0 + v * tMid, 0.05);
  }
}

// ---------------------------------------------------------------------------------------------
// The library's re-timing arithmetic (resample/retime.h), against intervals worked out by hand.

// Upper dominance puts raster row 0 in field 1, lower in field 2; field 1 of frame N exposes
// [N, N + 1/4], field 2 [N + 1/2, N + 3/4] with the default 180° field shutter (all exact in
// binary, so compared exactly), on every row of the right parity, for any frame number.
TEST(RetimeFieldGroups, DominancePutsEachRowInItsFieldWithItsInterval) {
  for (int64_t N : {int64_t(-3), int64_t(0), int64_t(7), int64_t(1000001)})
    for (int parity : {0, 1}) {
      FieldShutter fs;
      fs.firstFieldParity = parity;
      const ShutterModel m = fieldShutter(N, fs);
      ASSERT_EQ(m.groups().size(), 2u);
      for (int y : {0, 1, 2, 3, 4, 5, 1078, 1079}) {
        const bool field1 = (y % 2 == 0) == (parity == 0);
        const ShutterGroup& g = m.groups()[size_t(m.groupOfRow(y))];
        EXPECT_EQ(g.open, double(N) + (field1 ? 0.0 : 0.5)) << "frame " << N << " row " << y << " parity " << parity;
        EXPECT_EQ(g.close, double(N) + (field1 ? 0.25 : 0.75)) << "frame " << N << " row " << y << " parity " << parity;
        EXPECT_EQ(secondFieldRow(y, parity), !field1) << y;
      }
      // Two-pass renders each field's interval as a whole frame.
      const auto passes = fieldPassShutters(N, fs);
      EXPECT_EQ(passes.first.groups().size(), 1u);
      EXPECT_EQ(passes.first.earliest(), double(N));
      EXPECT_EQ(passes.first.latest(), double(N) + 0.25);
      EXPECT_EQ(passes.second.earliest(), double(N) + 0.5);
      EXPECT_EQ(passes.second.latest(), double(N) + 0.75);
    }
  EXPECT_EQ(parseDominance("upper", "--dominance"), 0);
  EXPECT_EQ(parseDominance("lower", "--dominance"), 1);
  EXPECT_THROW(parseDominance("even", "--dominance"), Error);
}

// Field shutters are measured in field durations (half a frame) about each field's nominal time.
TEST(RetimeFieldGroups, AnglesPositionsAndExplicitIntervalsAreInFieldDurations) {
  struct Case {
    double angle;
    ShutterPosition position;
    double open1, close1;  // field 1 of frame 10, worked out by hand; field 2 is half a frame later
  };
  for (const Case& c : {Case{360, ShutterPosition::Start, 10, 10.5}, Case{360, ShutterPosition::Center, 9.75, 10.25}, Case{180, ShutterPosition::End, 9.75, 10},
                        Case{90, ShutterPosition::Center, 9.9375, 10.0625}, Case{0, ShutterPosition::Start, 10, 10}}) {
    FieldShutter fs;
    std::tie(fs.open, fs.close) = angleInterval(c.angle, c.position);
    const auto [g1, g2] = fieldGroups(10, fs);
    EXPECT_EQ(g1.open, c.open1) << c.angle;
    EXPECT_EQ(g1.close, c.close1) << c.angle;
    EXPECT_EQ(g2.open, c.open1 + 0.5) << c.angle;
    EXPECT_EQ(g2.close, c.close1 + 0.5) << c.angle;
  }
  // An explicit interval (--field-shutter -0.5:0.5), a shape and a rolling read-out are carried to
  // both fields, one pass and two.
  FieldShutter fs;
  fs.open = -0.5, fs.close = 0.5;
  fs.shape = ShutterShape::trapezoid(0.25, 0.75);
  fs.rolling = RollingShutter{0.125, true, 1};
  const ShutterModel m = fieldShutter(4, fs);
  EXPECT_EQ(m.groups()[0].open, 3.75);
  EXPECT_EQ(m.groups()[1].close, 4.75);
  EXPECT_EQ(m.groups()[1].shape.description(), fs.shape.description());
  EXPECT_EQ(m.rolling().duration, 0.125);
  EXPECT_TRUE(m.rolling().upward);
  EXPECT_EQ(m.latest(), 4.75 + 0.125) << "the read-out delays the last row";
  const auto passes = fieldPassShutters(4, fs);
  EXPECT_EQ(passes.second.rolling().duration, 0.125);
  EXPECT_FALSE(passes.second.groups()[0].shape.isBox());
  EXPECT_EQ(fieldFrames({4, 6}, fs).size(), 2u);
  EXPECT_EQ(fieldFrames({4, 6}, fs)[1].shutter.groups()[0].open, 5.75);
}

// 24 → 30000/1001 fps: output frame k is nominally at k·24·1001/30000 = 0.8008·k source frames and
// a 180° shutter lasts half a target frame, 0.4004 source frames. Every 1250 output frames are
// exactly 1001 source frames, so those land on whole frames however long the sequence.
TEST(RetimeRateConversion, TwentyFourToNtscGivesTheAnalyticIntervals) {
  RateConversion rc;
  rc.from = {24, 1}, rc.to = {30000, 1001};
  const std::vector<int64_t> ks{1, 2, 5, 24, 1001, 1250, 30000, 125000};
  const auto frames = retimeFrames(ks, rc);
  ASSERT_EQ(frames.size(), ks.size());
  for (size_t i = 0; i < ks.size(); ++i) {
    const double nominal = double(ks[i]) * 24 * 1001 / 30000;
    const auto& g = frames[i].shutter.groups()[0];
    EXPECT_EQ(frames[i].frame, ks[i]);
    EXPECT_NEAR(g.open, nominal, 1e-12 * nominal) << ks[i];
    EXPECT_NEAR(g.close, nominal + 0.4004, 1e-12 * nominal) << ks[i];
    if (ks[i] % 1250 == 0) {
      EXPECT_EQ(g.open, double(ks[i] / 1250 * 1001)) << ks[i];
    }
  }
  // A 90° shutter centred on the nominal time: ±1/8 target frame = ±0.1001 source frames.
  std::tie(rc.open, rc.close) = angleInterval(90, ShutterPosition::Center);
  const auto centred = retimeFrames({5}, rc)[0].shutter.groups()[0];
  EXPECT_NEAR(centred.open, 4.004 - 0.1001, 1e-12);
  EXPECT_NEAR(centred.close, 4.004 + 0.1001, 1e-12);
  // 23.976 → 29.97 is 4:5 exactly, as 24 → 30.
  rc.from = {24000, 1001}, rc.open = 0, rc.close = 1;
  EXPECT_NEAR(double(rc.ratio()), 0.8, 1e-15);
  EXPECT_EQ(retimeFrames({5}, rc)[0].shutter.groups()[0].open, 4.0);
}

// Frame lists as --frames writes them (steps, zero, negative frames, one frame, none), the same
// rate (360° = the whole source frame), a rolling read-out in target frames, and rates that are
// not positive.
TEST(RetimeRateConversion, FrameListsAndEdgeCases) {
  RateConversion rc;
  rc.from = {24, 1}, rc.to = {30, 1};
  EXPECT_TRUE(retimeFrames({}, rc).empty());
  const auto stepped = retimeFrames(parseFrameRange("-5-10x5"), rc);  // -5, 0, 5, 10
  ASSERT_EQ(stepped.size(), 4u);
  const double expected[4][2] = {{-4.0, -3.6}, {0.0, 0.4}, {4.0, 4.4}, {8.0, 8.4}};
  for (size_t i = 0; i < 4; ++i) {
    EXPECT_EQ(stepped[i].frame, -5 + 5 * int64_t(i));
    EXPECT_NEAR(stepped[i].shutter.earliest(), expected[i][0], 1e-12) << stepped[i].frame;
    EXPECT_NEAR(stepped[i].shutter.latest(), expected[i][1], 1e-12) << stepped[i].frame;
  }
  // The same rate at 360°: output frame k is source frame k's whole shutter, exactly.
  RateConversion same;
  same.from = same.to = {25, 1};
  same.open = 0, same.close = 1;
  const auto whole = retimeFrames({3}, same)[0].shutter;
  EXPECT_EQ(whole.earliest(), 3.0);
  EXPECT_EQ(whole.latest(), 4.0);
  // A read-out of half a target frame at 24 → 30 delays the last row by 0.4 source frames.
  rc.rolling = RollingShutter{0.5, true, 1};
  rc.shape = ShutterShape::trapezoid(0.1, 0.9);
  const auto rolled = retimeFrames({10}, rc)[0].shutter;
  EXPECT_NEAR(rolled.rolling().duration, 0.4, 1e-15);
  EXPECT_TRUE(rolled.rolling().upward);
  EXPECT_NEAR(rolled.latest(), 8.4 + 0.4, 1e-12);
  EXPECT_EQ(rolled.groups()[0].shape.description(), rc.shape.description());
  // A rate that parses to zero (too small for six decimals) is the user's error, not a crash.
  rc.to = {0, 1000000};
  try {
    retimeFrames({1}, rc);
    FAIL() << "expected an Error";
  } catch (const Error& e) {
    EXPECT_EQ(e.where(), "rate conversion");
  }
}

// The two-pass interlace on hand-made images: rows are chosen by their raster row (the data
// window here starts on an odd row), every flat channel (float and uint) and every deep pixel
// (sample counts too) comes from its own field, and images that do not match are a CHECK.
TEST(RetimeInterlace, RowsComeFromTheirFieldByRasterRow) {
  const int x0 = 2, y0 = 3, W = 3, H = 5;
  auto make = [&](float base, size_t samples) {
    RenderResult r;
    r.image.x0 = x0, r.image.y0 = y0, r.image.width = W, r.image.height = H, r.image.fullWidth = 8, r.image.fullHeight = 10;
    ImageChannel& red = r.image.add("R");
    for (size_t i = 0; i < red.f.size(); ++i) red.f[i] = base + float(i);
    ImageChannel& id = r.image.add("id", true);
    for (size_t i = 0; i < id.u.size(); ++i) id.u[i] = uint32_t(base) + uint32_t(i);
    r.deep.reset(x0, y0, W, H, 8, 10, DeepLayout{}, 1);
    DeepPixel px;
    for (int y = y0; y < y0 + H; ++y)
      for (int x = x0; x < x0 + W; ++x) {
        px.clear();
        for (size_t s = 0; s < samples; ++s) px.at(px.add())[kDeepR] = base + float(y * 10 + x);
        r.deep.setPixel(0, x, y, px);
      }
    r.provenance.shutter = base < 2000 ? "first" : "second";
    r.provenance.shutterOpen = 1, r.provenance.shutterClose = base < 2000 ? 1.25 : 1.75;
    return r;
  };
  for (int parity : {0, 1}) {
    RenderResult woven = make(1000, 1);
    const RenderResult second = make(2000, 2);
    interlaceFields(woven, second, parity);
    DeepPixel px;
    for (int y = y0; y < y0 + H; ++y) {
      const bool field2 = (y % 2 == parity) == false;
      const float base = field2 ? 2000 : 1000;
      for (int x = x0; x < x0 + W; ++x) {
        const size_t i = size_t(y - y0) * W + size_t(x - x0);
        EXPECT_EQ(woven.image.find("R")->f[i], base + float(i)) << x << "," << y << " parity " << parity;
        EXPECT_EQ(woven.image.find("id")->u[i], uint32_t(base) + uint32_t(i)) << x << "," << y;
        woven.deep.getPixel(x, y, px);
        ASSERT_EQ(px.size(), field2 ? 2u : 1u) << x << "," << y << " parity " << parity;
        EXPECT_EQ(px.at(0)[kDeepR], base + float(y * 10 + x));
      }
    }
    // Rows 3 5 7 and 4 6: upper dominance puts the odd ones in field 2 (two samples a pixel).
    EXPECT_EQ(woven.deep.totalSamples(), uint64_t(W) * (parity == 0 ? 2 * 1 + 3 * 2 : 3 * 1 + 2 * 2));
    EXPECT_EQ(woven.provenance.shutter, "two-pass fields: first / second");
    EXPECT_EQ(woven.provenance.shutterClose, 1.75);
  }
  // The woven image is tidy only when both fields are (the deep writer then says TIDY).
  RenderResult tidy = make(1000, 1), untidy = make(2000, 1);
  untidy.deep.tidy = false;
  interlaceFields(tidy, untidy, 0);
  EXPECT_FALSE(tidy.deep.tidy);
  RenderResult a = make(1000, 1), b = make(2000, 1);
  b.image.y0 = 4;
  EXPECT_THROW(interlaceFields(a, b, 0), InternalError);
  RenderResult c = make(1000, 1), d = make(2000, 1);
  d.deep = DeepImage{};
  EXPECT_THROW(interlaceFields(c, d, 0), InternalError);
}

// The stores a sequence reaches: a frame's spec gets the stores its shutter overlaps (both across
// a boundary), and every store any frame needs is checked before any work, all missing ones
// named at once.
// Consecutive whole-frame stores share their boundary: frame 1's covers [1, 2], frame 2's [2, 3].
// A translucent surface at an instant on that boundary - or any sample that lands on it - must be
// drawn from one store, not composited over itself (alpha 0.6 + 0.4 * 0.6 = 0.84 instead of 0.6);
// at the last store's own end, with no store after it, it must still be drawn.
TEST(RetimeSources, AnInstantOnAFrameBoundaryDrawsEachSurfaceOnce) {
  ScratchDir dir;
  const Motion m;
  auto translucent = [&](int64_t frame) {
    TestScene s = makeScene(48, 36, {0.0, 1.0});
    s.meta.frame = frame;
    TestMp mp;
    for (double t : {0.0, 1.0}) {
      const double T = double(frame) + t;
      mp.knots.push_back(s.rect(m.x0 + 30 + m.vx * T, m.y0 + m.vy * T, m.x0 + 30 + m.w + m.vx * T, m.y0 + m.h + m.vy * T, m.z));
    }
    mp.oi = {0.6f, 0.6f, 0.6f}, mp.ci = {0.3f, 0.3f, 0.3f};
    s.mps.push_back(mp);
    return writeScene(s, dir.path("t" + std::to_string(frame) + ".mps"));
  };
  const auto s1 = translucent(1), s2 = translucent(2);
  for (double t : {2.0, 3.0, 1.0, 1.5}) {
    SCOPED_TRACE("instant " + std::to_string(t));
    const RenderResult r = render(baseSpec({Source{s1, 1}, Source{s2, 2}}, ShutterModel::progressive(t, t), 4));
    const auto& A = r.image.find("A")->f;
    const float most = *std::max_element(A.begin(), A.end());
    EXPECT_NEAR(most, 0.6f, 1e-6f);  // full pixels of the square: one layer of 0.6
    size_t full = 0;
    for (float a : A) full += std::abs(a - 0.6f) < 1e-6f;
    EXPECT_GT(full, 50u);  // the square (11.7 x 13.2 px) is on screen at this instant
    // Every hit is a sample's only one: hits = the covered samples (16 per full pixel and fewer at
    // the edges), not twice as many.
    double coveredSamples = 0;
    for (float a : A) coveredSamples += a / 0.6 * 16;
    EXPECT_NEAR(double(r.stats.raster.hits), coveredSamples, 0.5);
  }
}

TEST(RetimeSources, FramesReachTheStoresTheirShuttersNeed) {
  ScratchDir dir;
  Motion m;
  const std::string pattern = dir.path("s.####.mps");
  store::ShotStores shot(pattern, 0);
  for (int64_t f : {1, 2, 4}) frameStore(m, f, shot.pathOf(f));
  RateConversion rc;
  rc.from = {24, 1}, rc.to = {30, 1};
  RenderSpec spec = frameSpec(shot, retimeFrames({2}, rc)[0].shutter);  // [1.6, 2.0]: store 2 starts where it ends
  ASSERT_EQ(spec.sources.size(), 1u);
  EXPECT_EQ(spec.sources[0].frame, 1);
  EXPECT_NEAR(spec.shutter.earliest(), 1.6, 1e-12);
  rc.close = 1;                                              // 360°
  spec = frameSpec(shot, retimeFrames({2}, rc)[0].shutter);  // [1.6, 2.4]
  ASSERT_EQ(spec.sources.size(), 2u);
  EXPECT_EQ(spec.sources[0].frame, 1);
  EXPECT_EQ(spec.sources[1].frame, 2);
  EXPECT_EQ(spec.sources[1].store->path(), shot.pathOf(2));
  EXPECT_NO_THROW(requireStores(shot, retimeFrames({2, 5}, rc)));  // [1.6, 2.4] and [4.0, 4.8]
  const auto open = shot.openFrames();
  try {
    requireStores(shot, retimeFrames({2, 3, 4, 5, 6}, rc));  // frames 3 and 4 need store 3, frame 6 stores 4 and 5
    FAIL() << "expected an Error";
  } catch (const Error& e) {
    EXPECT_EQ(e.where(), pattern);
    EXPECT_NE(e.problem().find("2 stores are missing: " + shot.pathOf(3) + ", " + shot.pathOf(5)), std::string::npos) << e.what();
  }
  EXPECT_EQ(shot.openFrames(), open) << "the check opens nothing";
}
