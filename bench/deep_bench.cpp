// deep_bench: what deep output costs next to the flat image, for one store: render time with and
// without deep formation, write time and file size of the flat EXR and of the deep EXR (ZIPS,
// RLE, none), samples and bytes per pixel, and a depth-tolerance sweep. Prints Markdown rows for
// bench/RESULTS.md ("## Deep EXR").
//
//   deep_bench STORE [--filter gaussian:2] [--spp 16] [--tolerances 0,0.001,0.01,0.1] [--tmp DIR]
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <sstream>
#include <string>
#include <vector>

#include "bench/bench_util.h"
#include "resample/deep.h"
#include "resample/resampler.h"
#include "store/reader.h"

using namespace reshutter;
using namespace reshutter::resample;

namespace {

RenderResult run(const std::shared_ptr<const store::StoreReader>& store, const std::string& filter, int spp, bool deep, float tolerance) {
  RenderSpec spec;
  spec.sources = {Source{store, store->meta().frame}};
  spec.keepDecoded = {store.get()};  // renders after the first find the parts decoded, as before parts were released
  const double f = double(store->meta().frame);
  spec.shutter = ShutterModel::progressive(f + store->meta().shutterOpen, f + store->meta().shutterClose, ShutterShape::parse("box", "bench"));
  SamplePattern::factor(spp, spec.samplesX, spec.samplesY);
  spec.filter = FilterSpec::parse(filter, "--filter");
  spec.progress = false;
  spec.deep = deep;
  spec.deepOptions.tolerance = tolerance;
  return render(spec);
}

}  // namespace

int main(int argc, char** argv) {
  if (argc < 2) {
    std::fprintf(stderr, "usage: deep_bench STORE [--filter F] [--spp N] [--tolerances a,b,c] [--tmp DIR]\n");
    return 2;
  }
  const std::string path = argv[1];
  std::string filter = "gaussian:2", tolerances = "0,0.001,0.01,0.1", tmp = std::filesystem::temp_directory_path().string();
  int spp = 16;
  for (int i = 2; i + 1 < argc; i += 2) {
    const std::string a = argv[i], v = argv[i + 1];
    if (a == "--filter") filter = v;
    else if (a == "--spp") spp = std::atoi(v.c_str());
    else if (a == "--tolerances") tolerances = v;
    else if (a == "--tmp") tmp = v;
  }
  try {
    auto store = std::make_shared<const store::StoreReader>(path);
    std::printf("# %s: %s, %llu micropolygons, filter %s, %d spp\n", path.c_str(), bench::machineLine().c_str(), (unsigned long long)store->micropolygonCount(),
                filter.c_str(), spp);

    bench::Stopwatch sw;
    const RenderResult flat = run(store, filter, spp, false, 0.01f);
    const double flatRender = sw.seconds();
    sw.reset();
    const RenderResult deep = run(store, filter, spp, true, 0.01f);
    const double deepRender = sw.seconds();
    const double pixels = double(deep.deep.width) * deep.deep.height;

    const std::string flatPath = tmp + "/deep_bench_flat.exr", deepPath = tmp + "/deep_bench_deep.exr";
    sw.reset();
    writeExr(flatPath, flat.image, flat.provenance);
    const double flatWrite = sw.seconds();
    const double flatBytes = double(std::filesystem::file_size(flatPath));
    std::printf("render: flat %.2f s, flat + deep %.2f s (deep formation +%.0f %%)\n", flatRender, deepRender, 100.0 * (deepRender - flatRender) / flatRender);
    std::printf("| output | samples/pixel | bytes/pixel | file MB | write s |\n|---|---|---|---|---|\n");
    std::printf("| flat EXR (zip, R G B A Z float) | 1 | %.1f | %.1f | %.2f |\n", flatBytes / pixels, flatBytes / 1e6, flatWrite);
    for (auto [name, comp] : {std::pair{"zips", DeepCompression::Zips}, {"rle", DeepCompression::Rle}, {"none", DeepCompression::None}}) {
      DeepExrOptions o;
      o.compression = comp;
      sw.reset();
      writeDeepExr(deepPath, deep.deep, deep.provenance, o);
      const double t = sw.seconds();
      const double bytes = double(std::filesystem::file_size(deepPath));
      std::printf("| deep EXR (%s) | %.2f | %.1f | %.1f | %.2f |\n", name, double(deep.deep.totalSamples()) / pixels, bytes / pixels, bytes / 1e6, t);
    }
    std::printf("\ntolerance sweep (deep ZIPS):\n| tolerance | samples/pixel | bytes/pixel | render s |\n|---|---|---|---|\n");
    std::stringstream ss(tolerances);
    std::string tok;
    while (std::getline(ss, tok, ',')) {
      const float tol = std::stof(tok);
      sw.reset();
      const RenderResult r = run(store, filter, spp, true, tol);
      const double t = sw.seconds();
      writeDeepExr(deepPath, r.deep, r.provenance);
      const double bytes = double(std::filesystem::file_size(deepPath));
      std::printf("| %g | %.2f | %.1f | %.2f |\n", tol, double(r.deep.totalSamples()) / pixels, bytes / pixels, t);
    }
    std::filesystem::remove(flatPath);
    std::filesystem::remove(deepPath);
    std::printf("peak RSS %.0f MB\n", double(bench::peakRssBytes()) / 1e6);
  } catch (const std::exception& e) {
    std::fprintf(stderr, "deep_bench: %s\n", e.what());
    return 1;
  }
  return 0;
}
