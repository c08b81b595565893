// Re-timing on the shutter model: interlaced fields in one pass against the two-pass reference,
// frame-rate conversion across per-frame stores against analytic coverage, shutter shapes,
// rolling shutter slant, coverage gaps, and the `fields` / `retime` commands on sequences.
#include <algorithm>
#include <cmath>
#include <filesystem>

#include <gtest/gtest.h>

#include "common/error.h"
#include "resample/retime.h"
#include "tests/exr_test_util.h"
#include "tests/resample_test_util.h"
#include "tests/test_util.h"

using namespace reshutter;
using namespace reshutter::resample;
using namespace reshutter::test;

namespace {

// A square moving continuously through absolute time: x(t) = x0 + vx·t px (t in frames).
struct Motion {
  double x0 = -20.3, y0 = 6.6, w = 11.7, h = 13.2, vx = 9.35, vy = 1.45, z = 10;
};

// The store of frame F: knots at F + open and F + close (frame-relative open/close).
std::shared_ptr<const store::StoreReader> frameStore(const Motion& m, int64_t frame, const std::string& path, double open = 0, double close = 1,
                                                    int W = 48, int H = 36) {
  TestScene s = makeScene(W, H, {open, close});
  s.meta.frame = frame;
  s.meta.shutterOpen = open, s.meta.shutterClose = close;
  TestMp mp;
  for (double t : {open, close}) {
    const double T = double(frame) + t;
    mp.knots.push_back(s.rect(m.x0 + m.vx * T, m.y0 + m.vy * T, m.x0 + m.w + m.vx * T, m.y0 + m.h + m.vy * T, m.z));
  }
  mp.ci = {0.5f, 0.5f, 0.5f};
  s.mps.push_back(mp);
  return writeScene(s, path);
}

double coverageError(const RenderResult& r, const Motion& m, double a, double b, const std::vector<double>& shapeT = {},
                     const std::vector<double>& shapeW = {}) {
  const auto& A = channel(r, "A").f;
  double sum = 0;
  for (int py = 0; py < r.image.height; ++py)
    for (int px = 0; px < r.image.width; ++px) {
      const double d = A[size_t(py) * r.image.width + px] - analyticCoverage(px, py, m.x0, m.y0, m.w, m.h, m.vx, m.vy, a, b, shapeT, shapeW);
      sum += d * d;
    }
  return std::sqrt(sum / double(A.size()));
}

RenderSpec baseSpec(std::vector<Source> sources, ShutterModel shutter, int n = 8) {
  RenderSpec spec;
  spec.sources = std::move(sources);
  spec.shutter = std::move(shutter);
  spec.samplesX = spec.samplesY = n;
  spec.filter = FilterSpec::parse("box:1", "t");
  spec.progress = false;
  return spec;
}

// Largest |flattened deep − flat| over R G B A on row y (absolute) of a render.
double rowFlattenError(const DeepImage& deep, const FlatImage& flat, int y) {
  double worst = 0;
  DeepPixel px;
  for (int x = flat.x0; x < flat.x0 + flat.width; ++x) {
    deep.getPixel(x, y, px);
    const FlatDeepPixel f = flattenDeepPixel(px, deep.layout, false);
    const size_t o = size_t(y - flat.y0) * flat.width + size_t(x - flat.x0);
    for (auto [v, name] : {std::pair{f.r, "R"}, {f.g, "G"}, {f.b, "B"}, {f.a, "A"}}) worst = std::max(worst, std::abs(v - double(flat.find(name)->f[o])));
  }
  return worst;
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
  for (int64_t f = 0; f <= 4; ++f) sources.push_back(Source{frameStore(m, f, dir.path("s" + std::to_string(f) + ".mps")), f});
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

TEST(RetimeCli, FieldsAndRetimeWriteSequencesThatOpenElsewhere) {
  ScratchDir dir;
  Motion m;
  for (int64_t f = 1; f <= 4; ++f) frameStore(m, f, dir.path("shot." + std::string(4 - std::to_string(f).size(), '0') + std::to_string(f) + ".mps"));
  const std::string shot = dir.path("shot.####.mps");
  CommandResult fields = runReshutter("fields " + shot + " --frames 1-3 --spp 4 --filter box:1 -o " + dir.path("f.####.exr"));
  ASSERT_EQ(fields.exitCode, 0) << fields.err;
  CommandResult twoPass = runReshutter("fields " + shot + " --frames 1-3 --spp 4 --filter box:1 --two-pass -o " + dir.path("t.%04d.exr"));
  ASSERT_EQ(twoPass.exitCode, 0) << twoPass.err;
  for (int f = 1; f <= 3; ++f) {
    const std::string a = dir.path("f.000" + std::to_string(f) + ".exr"), b = dir.path("t.000" + std::to_string(f) + ".exr");
    ASSERT_TRUE(std::filesystem::exists(a)) << a;
    // OpenImageIO, an independent reader, finds the single pass identical to the two-pass one.
    CommandResult diff = runImageTool("idiff -q -fail 0 -failpercent 0 -warn 0 " + a + " " + b);
    EXPECT_EQ(diff.exitCode, 0) << diff.out << diff.err;
  }
  CommandResult retime = runReshutter("retime " + shot + " --from-fps 24 --to-fps 30 --frames 2-4x2 --spp 4 -o " + dir.path("r.####.exr"));
  ASSERT_EQ(retime.exitCode, 0) << retime.err;
  EXPECT_TRUE(std::filesystem::exists(dir.path("r.0002.exr")));
  EXPECT_TRUE(std::filesystem::exists(dir.path("r.0004.exr")));
  EXPECT_FALSE(std::filesystem::exists(dir.path("r.0003.exr")));
  CommandResult info = runImageTool("iinfo -v " + dir.path("r.0004.exr"));
  EXPECT_EQ(info.exitCode, 0) << info.err;
  EXPECT_NE(info.out.find("48 x"), std::string::npos) << info.out;
}

// `fields --two-pass --deep`, read back with OpenEXR: on every row the deep file flattens to the
// flat file, and both are that row's field rendered alone (`resample` of the field's interval of
// the frame's store). Field 2's rows of the deep file once held field 1's samples.
TEST(RetimeCli, TwoPassDeepFlattensToTheTwoPassFlatImageOnEveryRow) {
  ScratchDir dir;
  Motion m;
  for (int64_t f = 1; f <= 3; ++f) frameStore(m, f, dir.path("shot.000" + std::to_string(f) + ".mps"));
  const std::string common = " --spp 4 --filter gaussian:2";
  // Frame 2's fields as full frames: [2, 2.25] and [2.5, 2.75], store 2's [0, 0.25] and [0.5, 0.75].
  FlatImage fieldFlat[2];
  DeepExr fieldDeep[2];
  for (int k = 0; k < 2; ++k) {
    const std::string flat = dir.path("field" + std::to_string(k) + ".exr"), deep = dir.path("field" + std::to_string(k) + "d.exr");
    CommandResult r = runReshutter("resample " + dir.path("shot.0002.mps") + " --shutter " + (k == 0 ? "0:0.25" : "0.5:0.75") + common + " -o " + flat +
                                   " --deep " + deep);
    ASSERT_EQ(r.exitCode, 0) << r.err;
    fieldFlat[k] = readFlatExr(flat);
    fieldDeep[k] = readDeepExr(deep);
  }
  for (const char* dominance : {"upper", "lower"}) {
    const int parity = std::string(dominance) == "upper" ? 0 : 1;
    CommandResult r = runReshutter("fields " + dir.path("shot.####.mps") + " --frames 2 --two-pass --dominance " + dominance + common + " -o " +
                                   dir.path("t.####.exr") + " --deep " + dir.path("d.####.exr"));
    ASSERT_EQ(r.exitCode, 0) << r.err;
    const FlatImage flat = readFlatExr(dir.path("t.0002.exr"));
    const DeepExr deep = readDeepExr(dir.path("d.0002.exr"));
    EXPECT_NE(readExrShutter(dir.path("d.0002.exr")).description.find("two-pass fields"), std::string::npos) << "not the two-pass path";
    EXPECT_TRUE(deep.tidyState);
    ASSERT_EQ(flat.height, 36);
    int rowsThatShowTheBug = 0;
    DeepPixel a, b, other;
    for (int y = 0; y < flat.height; ++y) {
      const int k = (y % 2 == parity) ? 0 : 1;
      EXPECT_LT(rowFlattenError(deep.image, flat, y), 1e-5) << dominance << " dominance, row " << y << " (field " << k + 1 << ")";
      bool sameAsField = true, sameAsOther = true;
      for (int x = 0; x < flat.width; ++x) {
        for (const char* c : {"R", "G", "B", "A"}) sameAsField &= flat.find(c)->f[size_t(y) * flat.width + x] == fieldFlat[k].find(c)->f[size_t(y) * flat.width + x];
        deep.image.getPixel(x, y, a);
        fieldDeep[k].image.getPixel(x, y, b);
        fieldDeep[1 - k].image.getPixel(x, y, other);
        sameAsField &= a.f == b.f && a.u == b.u;
        sameAsOther &= a.f == other.f;
      }
      EXPECT_TRUE(sameAsField) << dominance << " dominance, row " << y << " is not field " << k + 1 << "'s";
      if (k == 1 && !sameAsOther) ++rowsThatShowTheBug;
    }
    EXPECT_GT(rowsThatShowTheBug, 3) << "the fields must differ on field 2's rows, or the bug would not show";
  }
}

TEST(RetimeCli, MissingStoresAreReportedAllAtOnceBeforeAnyWork) {
  ScratchDir dir;
  Motion m;
  for (int64_t f : {1, 2, 4, 6}) frameStore(m, f, dir.path("shot.000" + std::to_string(f) + ".mps"));
  CommandResult r = runReshutter("fields " + dir.path("shot.####.mps") + " --frames 1-6 --spp 1 -o " + dir.path("out.####.exr"));
  EXPECT_NE(r.exitCode, 0);
  EXPECT_NE(r.err.find("2 stores are missing"), std::string::npos) << r.err;
  EXPECT_NE(r.err.find("shot.0003.mps"), std::string::npos) << r.err;
  EXPECT_NE(r.err.find("shot.0005.mps"), std::string::npos) << r.err;
  EXPECT_FALSE(std::filesystem::exists(dir.path("out.0001.exr"))) << "no work may start before the check";
}

// A sequence's outputs are all checked before its first frame renders: a deep pattern into a
// missing directory fails before frame 1's flat EXR is written, in one pass and in two.
TEST(RetimeCli, UnwritableOutputFailsBeforeTheFirstFrame) {
  ScratchDir dir;
  Motion m;
  for (int64_t f = 1; f <= 3; ++f) frameStore(m, f, dir.path("shot.000" + std::to_string(f) + ".mps"));
  const std::string shot = dir.path("shot.####.mps"), deep = " --deep " + dir.path("missing/d.####.exr");
  for (const std::string& args : {"fields " + shot + " --frames 1-2 --spp 1 -o " + dir.path("f.####.exr") + deep,
                                 "fields " + shot + " --frames 1-2 --spp 1 --two-pass -o " + dir.path("f.####.exr") + deep,
                                 "retime " + shot + " --to-fps 24 --frames 1-2 --spp 1 -o " + dir.path("f.####.exr") + deep}) {
    CommandResult r = runReshutter(args);
    EXPECT_EQ(r.exitCode, 1) << args;
    EXPECT_NE(r.err.find("missing/d.0001.exr"), std::string::npos) << r.err;
    EXPECT_FALSE(std::filesystem::exists(dir.path("f.0001.exr"))) << args << ": frame 1 was written before the check";
  }
}

TEST(RetimeCli, BadShutterArgumentsGiveOneLineAndNoOutput) {
  ScratchDir dir;
  Motion m;
  frameStore(m, 1, dir.path("shot.0001.mps"));
  const std::string shot = dir.path("shot.####.mps"), out = dir.path("o.####.exr");
  for (const std::string& args : {"fields " + shot + " --frames 1 --field-shutter 0.5:0.1 -o " + out, "fields " + shot + " --frames 1 --field-shutter x -o " + out,
                                 "fields " + shot + " --frames 1", "retime " + shot + " --to-fps 30 --frames 1 --shutter 1:0 -o " + out,
                                 "retime " + shot + " --to-fps 0/0 --frames 1 -o " + out, "fields " + shot + " --frames 1-2 -o " + dir.path("same.exr")}) {
    CommandResult r = runReshutter(args);
    EXPECT_NE(r.exitCode, 0) << args;
    EXPECT_EQ(std::count(r.err.begin(), r.err.end(), '\n'), 1) << args << ": " << r.err;
    EXPECT_EQ(r.err.rfind("reshutter: ", 0), 0u) << r.err;
  }
  EXPECT_FALSE(std::filesystem::exists(dir.path("o.0001.exr")));
  EXPECT_FALSE(std::filesystem::exists(dir.path("same.exr")));
}
