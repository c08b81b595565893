// Output invariance, bit for bit: a cropped render is the same pixels of the whole render (the
// filter's margin reaches past the crop window), and the deep image is the same for any thread
// count and bucket size - flat and deep, read back from the files with OpenEXR (every channel of
// every pixel, every sample of every deep pixel), with OpenImageIO's idiff as a second,
// independent reader of the flat files; and through the library's RenderSpec crop, whose crops
// reach the image's corners and edges.
#include <algorithm>
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <stdexcept>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include <OpenEXR/ImfChannelList.h>
#include <OpenEXR/ImfCheckFile.h>
#include <OpenEXR/ImfDeepFrameBuffer.h>
#include <OpenEXR/ImfDeepScanLineInputFile.h>
#include <OpenEXR/ImfFrameBuffer.h>
#include <OpenEXR/ImfHeader.h>
#include <OpenEXR/ImfInputFile.h>

#include "resample/deep.h"
#include "resample/resampler.h"
#include "store/reader.h"
#include "tests/test_util.h"

namespace reshutter {
namespace {

using namespace resample;
using test::ScratchDir;

// ---------------------------------------------------------------------------------------------
// Reading OpenEXR files back: every value as its 32-bit pattern (float and half channels read as
// float, which represents every half exactly; uint channels as uint), so that equality is bit
// equality, NaN and -0 included.

struct ExrChannel {
  std::string name;
  Imf::PixelType type = Imf::FLOAT;
};

std::vector<ExrChannel> channelsOf(const Imf::Header& h) {
  std::vector<ExrChannel> cs;
  for (auto it = h.channels().begin(); it != h.channels().end(); ++it) cs.push_back({it.name(), it.channel().type});
  return cs;
}

Imf::PixelType readType(Imf::PixelType t) { return t == Imf::UINT ? Imf::UINT : Imf::FLOAT; }

struct FlatExr {
  Imath::Box2i data, display;
  std::vector<ExrChannel> channels;
  std::vector<std::vector<uint32_t>> values;  // per channel, row-major over the data window
  int width() const { return data.max.x - data.min.x + 1; }
  uint32_t at(size_t c, int x, int y) const { return values[c][size_t(y - data.min.y) * size_t(width()) + size_t(x - data.min.x)]; }
};

FlatExr readFlat(const std::string& path) {
  FlatExr img;
  Imf::InputFile in(path.c_str());
  img.data = in.header().dataWindow(), img.display = in.header().displayWindow();
  img.channels = channelsOf(in.header());
  const int W = img.width(), H = img.data.max.y - img.data.min.y + 1;
  Imf::FrameBuffer fb;
  img.values.resize(img.channels.size());
  for (size_t c = 0; c < img.channels.size(); ++c) {
    auto& v = img.values[c];
    v.assign(size_t(W) * size_t(H), 0);
    char* base = reinterpret_cast<char*>(v.data()) - (ptrdiff_t(img.data.min.x) + ptrdiff_t(img.data.min.y) * W) * 4;
    fb.insert(img.channels[c].name.c_str(), Imf::Slice(readType(img.channels[c].type), base, 4, 4 * size_t(W)));
  }
  in.setFrameBuffer(fb);
  in.readPixels(img.data.min.y, img.data.max.y);
  return img;
}

struct DeepExr {
  Imath::Box2i data, display;
  std::vector<ExrChannel> channels;
  std::vector<unsigned> counts;                            // per pixel
  std::vector<std::vector<std::vector<uint32_t>>> values;  // [channel][pixel][sample]
  uint64_t total = 0;
  int width() const { return data.max.x - data.min.x + 1; }
  size_t index(int x, int y) const { return size_t(y - data.min.y) * size_t(width()) + size_t(x - data.min.x); }
};

DeepExr readDeep(const std::string& path) {
  DeepExr img;
  Imf::DeepScanLineInputFile in(path.c_str());
  img.data = in.header().dataWindow(), img.display = in.header().displayWindow();
  img.channels = channelsOf(in.header());
  const int W = img.width(), H = img.data.max.y - img.data.min.y + 1;
  const size_t P = size_t(W) * size_t(H);
  const ptrdiff_t origin = ptrdiff_t(img.data.min.x) + ptrdiff_t(img.data.min.y) * W;
  img.counts.assign(P, 0);
  Imf::DeepFrameBuffer fb;
  fb.insertSampleCountSlice(Imf::Slice(Imf::UINT, reinterpret_cast<char*>(img.counts.data() - origin), 4, 4 * size_t(W)));
  std::vector<std::vector<char*>> pointers(img.channels.size(), std::vector<char*>(P, nullptr));
  for (size_t c = 0; c < img.channels.size(); ++c)
    fb.insert(img.channels[c].name.c_str(), Imf::DeepSlice(readType(img.channels[c].type), reinterpret_cast<char*>(pointers[c].data() - origin), sizeof(char*),
                                                           sizeof(char*) * size_t(W), 4));
  in.setFrameBuffer(fb);
  in.readPixelSampleCounts(img.data.min.y, img.data.max.y);
  img.values.assign(img.channels.size(), std::vector<std::vector<uint32_t>>(P));
  for (size_t c = 0; c < img.channels.size(); ++c)
    for (size_t p = 0; p < P; ++p) {
      img.values[c][p].assign(img.counts[p], 0xdeadbeefu);
      pointers[c][p] = reinterpret_cast<char*>(img.values[c][p].data());
    }
  for (unsigned n : img.counts) img.total += n;
  in.readPixels(img.data.min.y, img.data.max.y);
  return img;
}

std::string channelNames(const std::vector<ExrChannel>& cs) {
  std::string s;
  for (const auto& c : cs) s += (s.empty() ? "" : " ") + c.name + (c.type == Imf::UINT ? "(uint)" : c.type == Imf::HALF ? "(half)" : "");
  return s;
}

float asFloat(uint32_t bits) {
  float f;
  std::memcpy(&f, &bits, 4);
  return f;
}

// The same channels, and got's data window inside want's (else the pixel comparison cannot run).
template <class Exr>
bool sameChannelsWindowInside(const Exr& got, const Exr& want, const std::string& what) {
  EXPECT_EQ(channelNames(got.channels), channelNames(want.channels)) << what;
  EXPECT_TRUE(want.data.intersects(got.data.min) && want.data.intersects(got.data.max)) << what << ": data window outside the whole render's";
  return channelNames(got.channels) == channelNames(want.channels) && want.data.intersects(got.data.min) && want.data.intersects(got.data.max);
}

// Every channel of `got`'s data window equals `want`'s at the same pixels (want's window holds got's).
void expectSameFlatPixels(const FlatExr& got, const FlatExr& want, const std::string& what) {
  if (!sameChannelsWindowInside(got, want, what)) return;
  size_t differing = 0;
  for (size_t c = 0; c < got.channels.size(); ++c)
    for (int y = got.data.min.y; y <= got.data.max.y; ++y)
      for (int x = got.data.min.x; x <= got.data.max.x; ++x) {
        const uint32_t a = got.at(c, x, y), b = want.at(c, x, y);
        if (a == b) continue;
        if (++differing <= 5)
          ADD_FAILURE() << what << ": " << got.channels[c].name << " at " << x << "," << y << ": " << asFloat(a) << " (0x" << std::hex << a << ") against "
                        << asFloat(b) << " (0x" << b << std::dec << ")";
      }
  EXPECT_EQ(differing, 0u) << what << ": values that differ";
}

// Every deep pixel of `got`'s data window has the samples of `want`'s pixel there: the same count
// and every channel's every sample the same bits.
void expectSameDeepPixels(const DeepExr& got, const DeepExr& want, const std::string& what) {
  if (!sameChannelsWindowInside(got, want, what)) return;
  size_t differing = 0;
  for (int y = got.data.min.y; y <= got.data.max.y; ++y)
    for (int x = got.data.min.x; x <= got.data.max.x; ++x) {
      const size_t g = got.index(x, y), w = want.index(x, y);
      if (got.counts[g] != want.counts[w]) {
        if (++differing <= 5) ADD_FAILURE() << what << ": pixel " << x << "," << y << " has " << got.counts[g] << " samples against " << want.counts[w];
        continue;
      }
      for (size_t c = 0; c < got.channels.size(); ++c)
        for (size_t i = 0; i < got.counts[g]; ++i) {
          const uint32_t a = got.values[c][g][i], b = want.values[c][w][i];
          if (a == b) continue;
          if (++differing <= 5)
            ADD_FAILURE() << what << ": " << got.channels[c].name << " of sample " << i << " at " << x << "," << y << ": " << asFloat(a) << " (0x" << std::hex
                          << a << ") against " << asFloat(b) << " (0x" << b << std::dec << ")";
        }
    }
  EXPECT_EQ(differing, 0u) << what << ": pixels or samples that differ";
}

// A moving, partly transparent synthetic store, 128×96 (~2.5 layers deep).
std::string generateStore(const ScratchDir& dir) {
  const std::string path = dir.path("gen.mps");
  const test::CommandResult r = test::runReshutter("generate -n 30000 --width 128 --height 96 --transparent 0.4 --motion 25 --knots 3 --seed 5 -o " + path);
  if (r.exitCode != 0) throw std::runtime_error("reshutter generate failed: " + r.err);
  return path;
}

// Runs `reshutter args`; false (with the command and its error reported) when it fails.
bool runResample(const std::string& args) {
  const test::CommandResult r = test::runReshutter(args);
  EXPECT_EQ(r.exitCode, 0) << args << "\n" << r.err;
  return r.exitCode == 0;
}

// ---------------------------------------------------------------------------------------------
// Crop invariance

// `--crop` writes the whole render's pixels in its data window: flat and deep, over the whole
// shutter and a sub-interval, with filters 3 and 4 px wide (margins of 1 and 2 px past the crop)
// and a crop window whose edges lie inside buckets of the whole render.
TEST(CropInvariance, CroppedFilesHoldTheWholeRendersPixels) {
  ScratchDir dir;
  const std::string store = generateStore(dir);
  const int x0 = 37, x1 = 101, y0 = 21, y1 = 70;  // [x0, x1) × [y0, y1)
  for (auto [shutter, filter] : {std::pair{"0:1", "gaussian:3"}, std::pair{"0.3:0.55", "catmull-rom:4"}}) {
    const std::string what = std::string("shutter ") + shutter + " " + filter;
    const std::string args = std::string(" --spp 9 --seed 3 --aov z --aov id --aov Oi --shutter ") + shutter + " --filter " + filter;
    const std::string whole = dir.path("whole.exr"), wholeDeep = dir.path("whole_deep.exr"), crop = dir.path("crop.exr"), cropDeep = dir.path("crop_deep.exr");
    ASSERT_TRUE(runResample("resample " + store + " -o " + whole + " --deep " + wholeDeep + args));
    ASSERT_TRUE(runResample("resample " + store + " -o " + crop + " --deep " + cropDeep + args + " --crop " + std::to_string(x0) + " " + std::to_string(x1) +
                            " " + std::to_string(y0) + " " + std::to_string(y1)));
    for (const std::string& f : {wholeDeep, cropDeep}) EXPECT_FALSE(Imf::checkOpenEXRFile(f.c_str(), false, false, true)) << f;

    const FlatExr w = readFlat(whole), c = readFlat(crop);
    EXPECT_EQ(c.data, Imath::Box2i(Imath::V2i(x0, y0), Imath::V2i(x1 - 1, y1 - 1))) << what;
    EXPECT_EQ(c.display, w.display) << what;
    EXPECT_EQ(w.data, w.display) << what;
    expectSameFlatPixels(c, w, what);
    // Not a vacuous match: the window is mostly covered.
    double alpha = 0;
    for (size_t ch = 0; ch < c.channels.size(); ++ch)
      if (c.channels[ch].name == "A")
        for (uint32_t v : c.values[ch]) alpha += asFloat(v);
    EXPECT_GT(alpha, 0.5 * (x1 - x0) * (y1 - y0)) << what;

    const DeepExr wd = readDeep(wholeDeep), cd = readDeep(cropDeep);
    EXPECT_EQ(cd.data, c.data) << what;
    expectSameDeepPixels(cd, wd, what);
    EXPECT_GT(cd.total, uint64_t(1.5 * (x1 - x0) * (y1 - y0))) << what << ": a deep image of several layers";

    // An independent reader agrees (once; its start-up is most of this test's time): OpenImageIO
    // cuts the window out of the whole render and finds no pixel different from the cropped file.
    if (std::string(filter) != "catmull-rom:4") continue;
    const std::string cut = dir.path("cut.exr");
    test::CommandResult r = test::runImageTool("oiiotool " + whole + " --crop " + std::to_string(x1 - x0) + "x" + std::to_string(y1 - y0) + "+" +
                                               std::to_string(x0) + "+" + std::to_string(y0) + " -o " + cut);
    ASSERT_EQ(r.exitCode, 0) << r.out << r.err;
    r = test::runImageTool("idiff -q -fail 0 -failpercent 0 -warn 0 " + crop + " " + cut);
    EXPECT_EQ(r.exitCode, 0) << what << ": " << r.out << r.err;
  }
}

// The same through RenderSpec's crop, in process: windows at the image's corners and edges, one
// pixel, and one across the middle, with small buckets so that bucket edges differ between the
// whole render and each crop; flat channels and deep samples alike.
TEST(CropInvariance, RenderSpecCropsAreTheWholeRendersPixels) {
  ScratchDir dir;
  auto reader = std::make_shared<const store::StoreReader>(generateStore(dir));
  for (auto [open, close] : {std::pair{0.0, 1.0}, std::pair{0.6, 0.7}}) {
    RenderSpec spec;
    spec.sources = {Source{reader, reader->meta().frame}};
    const double F = double(reader->meta().frame);
    spec.shutter = ShutterModel::progressive(F + open, F + close);
    spec.samplesX = spec.samplesY = 3;
    spec.seed = 7;
    spec.filter = FilterSpec::parse("mitchell:4", "test");
    spec.aovs = {AovRequest::parse("z", "test"), AovRequest::parse("id", "test")};
    spec.deep = true;
    spec.progress = false;
    spec.bucketSize = 24;
    const RenderResult whole = render(spec);
    ASSERT_EQ(whole.image.width, 128);
    struct Window {
      int x0, x1, y0, y1;
    };
    for (const Window& c : {Window{0, 13, 0, 9}, Window{115, 128, 83, 96}, Window{0, 128, 50, 51}, Window{64, 65, 40, 41}, Window{21, 99, 17, 80}}) {
      RenderSpec cs = spec;
      cs.cropX0 = c.x0, cs.cropX1 = c.x1, cs.cropY0 = c.y0, cs.cropY1 = c.y1;
      cs.bucketSize = 16;
      const RenderResult crop = render(cs);
      const std::string what = "shutter " + std::to_string(open) + ":" + std::to_string(close) + " crop " + std::to_string(c.x0) + " " + std::to_string(c.x1) +
                               " " + std::to_string(c.y0) + " " + std::to_string(c.y1);
      ASSERT_EQ(crop.image.x0, c.x0) << what;
      ASSERT_EQ(crop.image.y0, c.y0) << what;
      ASSERT_EQ(crop.image.width, c.x1 - c.x0) << what;
      ASSERT_EQ(crop.image.height, c.y1 - c.y0) << what;
      ASSERT_EQ(crop.image.channels.size(), whole.image.channels.size()) << what;
      size_t differing = 0;
      for (size_t ch = 0; ch < whole.image.channels.size(); ++ch)
        for (int y = c.y0; y < c.y1; ++y)
          for (int x = c.x0; x < c.x1; ++x) {
            const size_t i = size_t(y - c.y0) * size_t(c.x1 - c.x0) + size_t(x - c.x0), j = size_t(y) * 128 + size_t(x);
            const auto &a = crop.image.channels[ch], &b = whole.image.channels[ch];
            const bool same = a.isUInt ? a.u[i] == b.u[j] : std::memcmp(&a.f[i], &b.f[j], sizeof(float)) == 0;
            if (!same && ++differing <= 3) ADD_FAILURE() << what << ": " << a.name << " differs at " << x << "," << y;
          }
      EXPECT_EQ(differing, 0u) << what;
      DeepPixel a, b;
      uint64_t samples = 0;
      for (int y = c.y0; y < c.y1; ++y)
        for (int x = c.x0; x < c.x1; ++x) {
          crop.deep.getPixel(x, y, a), whole.deep.getPixel(x, y, b);
          samples += a.size();
          ASSERT_EQ(a.size(), b.size()) << what << " deep pixel " << x << "," << y;
          ASSERT_TRUE(a.f.empty() || std::memcmp(a.f.data(), b.f.data(), a.f.size() * sizeof(float)) == 0) << what << " deep pixel " << x << "," << y;
          ASSERT_EQ(a.u, b.u) << what << " deep pixel " << x << "," << y;
        }
      EXPECT_GT(samples, uint64_t((c.x1 - c.x0) * (c.y1 - c.y0))) << what << ": the window must see surfaces";
    }
  }
}

// ---------------------------------------------------------------------------------------------
// Deep output across thread counts and bucket sizes

// The deep file (and the flat one beside it) is the same, sample for sample and bit for bit, for
// one thread and for two and three with other bucket sizes, over the whole shutter and a
// sub-interval, with composited and nearest-surface output variables.
TEST(DeepDeterminism, SameDeepFileForAnyThreadCountAndBucketSize) {
  ScratchDir dir;
  const std::string store = generateStore(dir);
  for (const char* shutter : {"0:1", "0.2:0.45"}) {
    const std::string args = std::string(" --spp 9 --seed 11 --filter gaussian:2 --aov z --aov id --aov Oi --aov Ci:average --shutter ") + shutter;
    std::vector<FlatExr> flats;
    std::vector<DeepExr> deeps;
    std::vector<std::string> names;
    for (auto [threads, bucket] : {std::pair{1, 96}, std::pair{2, 16}, std::pair{3, 37}}) {
      const std::string name = "-j " + std::to_string(threads) + " --bucket " + std::to_string(bucket);
      const std::string flat = dir.path("flat" + std::to_string(threads) + ".exr"), deep = dir.path("deep" + std::to_string(threads) + ".exr");
      ASSERT_TRUE(runResample("-j " + std::to_string(threads) + " resample " + store + " -o " + flat + " --deep " + deep + args + " --bucket " +
                              std::to_string(bucket)));
      EXPECT_FALSE(Imf::checkOpenEXRFile(deep.c_str(), false, false, true)) << name;
      flats.push_back(readFlat(flat)), deeps.push_back(readDeep(deep)), names.push_back(name);
    }
    const DeepExr& first = deeps[0];
    EXPECT_GT(first.total, uint64_t(1.5 * 128 * 96)) << shutter << ": a deep image of several layers";
    std::printf("shutter %s: %llu deep samples; channels %s\n", shutter, (unsigned long long)first.total, channelNames(first.channels).c_str());
    EXPECT_EQ(first.data, Imath::Box2i(Imath::V2i(0, 0), Imath::V2i(127, 95)));
    for (const char* want : {"R", "A", "Z", "ZBack", "z", "Oi.R", "Ci.R", "objectid"})
      EXPECT_TRUE(std::any_of(first.channels.begin(), first.channels.end(), [&](const ExrChannel& c) { return c.name == want; }))
          << want << " not in " << channelNames(first.channels);
    for (size_t i = 1; i < deeps.size(); ++i) {
      const std::string what = std::string("shutter ") + shutter + ", " + names[i] + " against " + names[0];
      EXPECT_EQ(deeps[i].data, first.data) << what;
      EXPECT_EQ(deeps[i].total, first.total) << what;
      expectSameDeepPixels(deeps[i], first, what);
      expectSameFlatPixels(flats[i], flats[0], what);
    }
  }
}

}  // namespace
}  // namespace reshutter
