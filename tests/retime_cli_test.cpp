// The `fields` and `retime` commands on sequences of stores: each store decoded once, sequences
// that other tools open, frames equal to `resample` of the same interval, deep output flattening
// to the flat image row by row, and bad input reported before any work.
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

// Pixels where any channel of two images read back differs in its bits (or the images' windows
// or channel lists differ: every pixel).
size_t differingPixels(const FlatImage& a, const FlatImage& b) {
  if (a.x0 != b.x0 || a.y0 != b.y0 || a.width != b.width || a.height != b.height || a.channels.size() != b.channels.size())
    return size_t(a.width) * size_t(a.height);
  size_t n = 0;
  for (size_t i = 0; i < size_t(a.width) * size_t(a.height); ++i) {
    bool same = true;
    for (size_t c = 0; c < a.channels.size(); ++c) {
      const ImageChannel &x = a.channels[c], &y = b.channels[c];
      same &= x.name == y.name && (x.isUInt ? x.u[i] == y.u[i] : std::memcmp(&x.f[i], &y.f[i], sizeof(float)) == 0);
    }
    n += !same;
  }
  return n;
}

}  // namespace

// Decoded parts are released after their last bucket (RenderSpec::keepDecoded) except from the
// stores the next render reads: a two-pass frame's second field decodes nothing the first field
// decoded, and the next frame's first field decodes its own store's parts.
TEST(RetimeCli, TwoPassFieldsDecodeEachStoreOnce) {
  ScratchDir dir;
  Motion m;
  for (int64_t f = 1; f <= 2; ++f) frameStore(m, f, dir.path("shot.000" + std::to_string(f) + ".mps"));
  const std::string shot = dir.path("shot.####.mps");
  CommandResult r = runReshutter("fields " + shot + " --frames 1-2 --spp 4 --two-pass --stats -o " + dir.path("t.####.exr"));
  ASSERT_EQ(r.exitCode, 0) << r.err;
  // Each pass's report: "frame F, field K" then "parts N fetched, M decoded, ...".
  struct PartCounts {
    long fetched = -1, decoded = -1;
  };
  std::vector<PartCounts> pass;
  for (size_t at = r.out.find("parts "); at != std::string::npos; at = r.out.find("parts ", at + 1)) {
    PartCounts p;
    if (std::sscanf(r.out.c_str() + at, "parts %ld fetched, %ld decoded", &p.fetched, &p.decoded) == 2) pass.push_back(p);
  }
  ASSERT_EQ(pass.size(), 4u) << r.out;
  EXPECT_GT(pass[0].decoded, 0) << "frame 1, field 1";
  EXPECT_GT(pass[1].fetched, 0) << "frame 1, field 2";
  EXPECT_EQ(pass[1].decoded, 0) << "frame 1, field 2: its parts were kept from field 1";
  EXPECT_GT(pass[2].decoded, 0) << "frame 2, field 1: another store";
  EXPECT_EQ(pass[3].decoded, 0) << "frame 2, field 2";
}

TEST(RetimeCli, FieldsAndRetimeWriteSequencesThatOpenElsewhere) {
  ScratchDir dir;
  Motion m;
  for (int64_t f = 1; f <= 4; ++f) frameStore(m, f, dir.path("shot." + std::string(4 - std::to_string(f).size(), '0') + std::to_string(f) + ".mps"));
  const std::string shot = dir.path("shot.####.mps");
  CommandResult fields =
      runReshutter("fields " + shot + " --frames 1-3 --spp 4 --filter box:1 -o " + dir.path("f.####.exr") + " --deep " + dir.path("fd.####.exr"));
  ASSERT_EQ(fields.exitCode, 0) << fields.err;
  CommandResult twoPass =
      runReshutter("fields " + shot + " --frames 1-3 --spp 4 --filter box:1 --two-pass -o " + dir.path("t.%04d.exr") + " --deep " + dir.path("td.%04d.exr"));
  ASSERT_EQ(twoPass.exitCode, 0) << twoPass.err;
  for (int f = 1; f <= 3; ++f) {
    const std::string n = std::to_string(f);
    // OpenImageIO, an independent reader, finds the single pass identical to the two-pass one, flat
    // and deep (with a one-row filter no row sees the other field's samples).
    for (auto [a, b] :
         {std::pair{dir.path("f.000" + n + ".exr"), dir.path("t.000" + n + ".exr")}, {dir.path("fd.000" + n + ".exr"), dir.path("td.000" + n + ".exr")}}) {
      ASSERT_TRUE(std::filesystem::exists(a)) << a;
      CommandResult diff = runImageTool("idiff -q -fail 0 -failpercent 0 -warn 0 " + a + " " + b);
      EXPECT_EQ(diff.exitCode, 0) << a << " " << b << "\n" << diff.out << diff.err;
    }
    // Field 1 of frame f is [f, f + 1/4], field 2 [f + 1/2, f + 3/4]: each field's rows are the
    // square's coverage over its own interval, clearly closer than over the other field's.
    const FlatImage img = readFlatExr(dir.path("f.000" + n + ".exr"));
    for (int field : {0, 1}) {
      double own = 0, other = 0;
      for (int y = field; y < img.height; y += 2)
        for (int x = 0; x < img.width; ++x) {
          const double a = img.find("A")->f[size_t(y) * img.width + x];
          own += std::pow(a - analyticCoverage(x, y, m.x0, m.y0, m.w, m.h, m.vx, m.vy, f + 0.5 * field, f + 0.5 * field + 0.25), 2);
          other += std::pow(a - analyticCoverage(x, y, m.x0, m.y0, m.w, m.h, m.vx, m.vy, f + 0.5 * (1 - field), f + 0.5 * (1 - field) + 0.25), 2);
        }
      EXPECT_LT(3 * own, other) << "frame " << f << ", field " << field + 1 << ": rows of the wrong field";
    }
  }
  // 24 → 30 fps, 180°: output frame k exposes [0.8k, 0.8k + 0.4], frame 2 within store 1, frame 4
  // [3.2, 3.6] within store 3; the square's coverage over that interval is known exactly.
  CommandResult retimed = runReshutter("retime " + shot + " --from-fps 24 --to-fps 30 --frames 2-4x2 --spp 64 --filter box:1 -o " + dir.path("r.####.exr"));
  ASSERT_EQ(retimed.exitCode, 0) << retimed.err;
  EXPECT_FALSE(std::filesystem::exists(dir.path("r.0003.exr")));
  for (int k : {2, 4}) {
    const std::string path = dir.path("r.000" + std::to_string(k) + ".exr");
    ASSERT_TRUE(std::filesystem::exists(path)) << path;
    const ExrShutter shutter = readExrShutter(path);
    EXPECT_NEAR(shutter.open, 0.8 * k, 1e-12);
    EXPECT_NEAR(shutter.close, 0.8 * k + 0.4, 1e-12);
    EXPECT_LT(coverageError(readFlatExr(path), m, 0.8 * k, 0.8 * k + 0.4), 0.02) << "output frame " << k;
  }
  CommandResult info = runImageTool("iinfo -v " + dir.path("r.0004.exr"));
  EXPECT_EQ(info.exitCode, 0) << info.err;
  EXPECT_NE(info.out.find("48 x"), std::string::npos) << info.out;
}

// A retime frame whose shutter lies within one store is that store re-sampled over the same
// interval, bit for bit: the instant of a 0° shutter, a 360° frame at the shot's own rate (the
// store's whole shutter), a 180° frame at half the rate (one whole source frame), and the same
// with the rate read from the stores.
TEST(RetimeCli, RetimeFramesEqualResampleOfTheSameInterval) {
  ScratchDir dir;
  Motion m;
  for (int64_t f = 1; f <= 4; ++f) frameStore(m, f, dir.path("shot.000" + std::to_string(f) + ".mps"));
  const std::string shot = dir.path("shot.####.mps"), common = " --spp 64 --filter box:1 --aov id --aov z";
  struct Case {
    std::string args;           // `retime`'s arguments after the stores
    int frame;                  // the output frame compared
    std::string referenceArgs;  // the equivalent `resample` of one store
    double open, close;         // the interval both render (absolute frames)
  };
  // 24 → 32: frame 3 is nominally at 2.25 (exact in binary, as store 2's 0.25 is).
  const Case cases[] = {
      {"--from-fps 24 --to-fps 32 --frames 3 --shutter-angle 0", 3, "shot.0002.mps --shutter 0.25:0.25", 2.25, 2.25},
      {"--from-fps 24 --to-fps 32 --frames 3 --shutter-angle 0 --shutter-position end", 3, "shot.0002.mps --shutter 0.25:0.25", 2.25, 2.25},
      {"--from-fps 24 --to-fps 24 --frames 2-3 --shutter-angle 360", 3, "shot.0003.mps", 3, 4},
      {"--from-fps 24 --to-fps 12 --frames 1 --shutter-angle 180", 1, "shot.0002.mps", 2, 3},
      {"--to-fps 12 --frames 1", 1, "shot.0002.mps --shutter 0:1", 2, 3},
      // The stores' own rate with no store near the output frame number (9 at 48 fps is source time 4.5).
      {"--to-fps 48 --frames 9 --shutter-angle 0", 9, "shot.0004.mps --shutter 0.5:0.5", 4.5, 4.5},
  };
  for (const Case& c : cases) {
    const std::string out = dir.path("r.####.exr"), ref = dir.path("ref.exr");
    CommandResult r = runReshutter("retime " + shot + " " + c.args + common + " -o " + out);
    ASSERT_EQ(r.exitCode, 0) << c.args << ": " << r.err;
    r = runReshutter("resample " + dir.path(c.referenceArgs) + common + " -o " + ref);
    ASSERT_EQ(r.exitCode, 0) << c.referenceArgs << ": " << r.err;
    const std::string frame = dir.path("r.000" + std::to_string(c.frame) + ".exr");
    const ExrShutter a = readExrShutter(frame), b = readExrShutter(ref);
    EXPECT_EQ(a.open, c.open) << c.args;
    EXPECT_EQ(a.close, c.close) << c.args;
    EXPECT_EQ(b.open, c.open) << c.referenceArgs;
    EXPECT_EQ(b.close, c.close) << c.referenceArgs;
    const FlatImage x = readFlatExr(frame), y = readFlatExr(ref);
    EXPECT_EQ(differingPixels(x, y), 0u) << c.args << " against resample " << c.referenceArgs;
    EXPECT_GT(x.channels.size(), 5u) << "R G B A Z, id and z";
    // And the frame is not just any image: the square's coverage over that interval, not over one
    // a tenth of a frame later.
    const double offOwn = coverageError(x, m, c.open, c.close), offLater = coverageError(x, m, c.open + 0.1, c.close + 0.1);
    EXPECT_LT(offOwn, 0.02) << c.args << ": coverage off its own interval";
    EXPECT_GT(offLater, 3 * offOwn) << c.args << ": an interval 0.1 frame later must fit worse";
  }
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
    CommandResult r =
        runReshutter("resample " + dir.path("shot.0002.mps") + " --shutter " + (k == 0 ? "0:0.25" : "0.5:0.75") + common + " -o " + flat + " --deep " + deep);
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
        for (const char* c : {"R", "G", "B", "A"})
          sameAsField &= flat.find(c)->f[size_t(y) * flat.width + x] == fieldFlat[k].find(c)->f[size_t(y) * flat.width + x];
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
  for (const std::string twoPass : {"", " --two-pass"}) {
    CommandResult r = runReshutter("fields " + dir.path("shot.####.mps") + " --frames 1-6 --spp 1" + twoPass + " -o " + dir.path("out.####.exr"));
    EXPECT_NE(r.exitCode, 0) << twoPass;
    EXPECT_NE(r.err.find("2 stores are missing"), std::string::npos) << r.err;
    EXPECT_NE(r.err.find("shot.0003.mps"), std::string::npos) << r.err;
    EXPECT_NE(r.err.find("shot.0005.mps"), std::string::npos) << r.err;
    EXPECT_FALSE(std::filesystem::exists(dir.path("out.0001.exr"))) << twoPass << ": no work may start before the check";
  }
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
  for (const std::string& args :
       {"fields " + shot + " --frames 1 --field-shutter 0.5:0.1 -o " + out, "fields " + shot + " --frames 1 --field-shutter x -o " + out,
        "fields " + shot + " --frames 1", "retime " + shot + " --to-fps 30 --frames 1 --shutter 1:0 -o " + out,
        "retime " + shot + " --to-fps 0/0 --frames 1 -o " + out, "fields " + shot + " --frames 1-2 -o " + dir.path("same.exr"),
        "fields " + shot + " --frames 1-2 --two-pass -o " + dir.path("same.exr")}) {
    CommandResult r = runReshutter(args);
    EXPECT_NE(r.exitCode, 0) << args;
    EXPECT_EQ(std::count(r.err.begin(), r.err.end(), '\n'), 1) << args << ": " << r.err;
    EXPECT_EQ(r.err.rfind("reshutter: ", 0), 0u) << r.err;
  }
  EXPECT_FALSE(std::filesystem::exists(dir.path("o.0001.exr")));
  EXPECT_FALSE(std::filesystem::exists(dir.path("same.exr")));
}
