// The flat OpenEXR codec curve: for each compression `--compression` offers (losslessly, plus
// pxr24), the file size and the single-thread time to write and to read back one image. Run it
// on a frame `reshutter resample` wrote (its pixels are what the codecs see: float noise from
// 16 samples per pixel compresses very differently from smooth or half data).
//   exr_codec_bench frame.exr
// Prints a Markdown table; figures go to bench/RESULTS.md.
#include <OpenEXR/ImfChannelList.h>
#include <OpenEXR/ImfFrameBuffer.h>
#include <OpenEXR/ImfHeader.h>
#include <OpenEXR/ImfInputFile.h>
#include <OpenEXR/ImfOutputFile.h>
#include <OpenEXR/ImfThreading.h>

#include <algorithm>
#include <cstdio>
#include <filesystem>
#include <string>
#include <vector>

#include "bench/bench_util.h"

namespace {

// Every channel of a file, in the file's own pixel types, and a frame buffer over them.
struct Pixels {
  Imath::Box2i window;
  std::vector<std::vector<char>> planes;
  Imf::FrameBuffer frameBuffer;
};

Pixels readAll(const std::string& path) {
  Imf::InputFile in(path.c_str());
  Pixels px;
  px.window = in.header().dataWindow();
  const size_t W = size_t(px.window.max.x - px.window.min.x + 1), H = size_t(px.window.max.y - px.window.min.y + 1);
  for (auto it = in.header().channels().begin(); it != in.header().channels().end(); ++it) {
    const size_t bytes = it.channel().type == Imf::HALF ? 2 : 4;
    auto& plane = px.planes.emplace_back(W * H * bytes);
    char* origin = plane.data() - (size_t(px.window.min.x) + size_t(px.window.min.y) * W) * bytes;
    px.frameBuffer.insert(it.name(), Imf::Slice(it.channel().type, origin, bytes, bytes * W));
  }
  in.setFrameBuffer(px.frameBuffer);
  in.readPixels(px.window.min.y, px.window.max.y);
  return px;
}

}  // namespace

int main(int argc, char** argv) {
  if (argc != 2) {
    std::fprintf(stderr, "usage: exr_codec_bench frame.exr\n");
    return 2;
  }
  try {
    Imf::setGlobalThreadCount(0);  // single-thread figures: per-core cost
    const std::string input = argv[1];
    const Pixels source = readAll(input);
    const Imf::Header sourceHeader = Imf::InputFile(input.c_str()).header();
    const std::string scratch = (std::filesystem::temp_directory_path() / "exr_codec_bench.exr").string();
    struct Codec {
      const char* name;
      Imf::Compression compression;
      int zipLevel;
    };
    const Codec codecs[] = {{"none", Imf::NO_COMPRESSION, 4},
                            {"rle", Imf::RLE_COMPRESSION, 4},
                            {"zips", Imf::ZIPS_COMPRESSION, 4},
                            {"zip, level 1", Imf::ZIP_COMPRESSION, 1},
                            {"zip, level 4 (OpenEXR's)", Imf::ZIP_COMPRESSION, 4},
                            {"zip, level 6", Imf::ZIP_COMPRESSION, 6},
                            {"piz", Imf::PIZ_COMPRESSION, 4},
                            {"pxr24 (lossy for float)", Imf::PXR24_COMPRESSION, 4}};
    std::printf("%s\n%s, one thread, best of 3\n\n", reshutter::bench::machineLine().c_str(), input.c_str());
    std::printf("| compression | MB | write s | read s |\n|---|---|---|---|\n");
    for (const Codec& c : codecs) {
      double bestWrite = 1e30, bestRead = 1e30;
      for (int rep = 0; rep < 3; ++rep) {
        Imf::Header h = sourceHeader;
        h.compression() = c.compression;
        h.zipCompressionLevel() = c.zipLevel;
        reshutter::bench::Stopwatch sw;
        {
          Imf::OutputFile out(scratch.c_str(), h);
          out.setFrameBuffer(source.frameBuffer);
          out.writePixels(source.window.max.y - source.window.min.y + 1);
        }
        bestWrite = std::min(bestWrite, sw.seconds());
        sw.reset();
        readAll(scratch);
        bestRead = std::min(bestRead, sw.seconds());
      }
      std::printf("| %s | %.2f | %.3f | %.3f |\n", c.name, double(std::filesystem::file_size(scratch)) / 1e6, bestWrite, bestRead);
    }
    std::filesystem::remove(scratch);
  } catch (const std::exception& e) {
    std::fprintf(stderr, "exr_codec_bench: %s\n", e.what());
    return 1;
  }
  return 0;
}
