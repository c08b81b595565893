// `reshutter demo`: the main job on built-in content, no files needed. Writes its outputs to a
// directory and reports where they are and how long each stage took.
#include <chrono>
#include <cstdio>
#include <filesystem>

#include "cli/commands.h"
#include "common/error.h"
#include "store/reader.h"
#include "store/synthetic.h"
#include "store/writer.h"

namespace reshutter::cli {
namespace {

double secondsSince(std::chrono::steady_clock::time_point t) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - t).count();
}

int runDemo(const std::string& outDir, uint64_t micropolygons) {
  std::error_code ec;
  std::filesystem::create_directories(outDir, ec);
  if (ec) fail(outDir, "cannot create the output directory: ", ec.message());
  store::SyntheticOptions opt;
  opt.micropolygons = micropolygons;
  opt.width = 1280;
  opt.height = 720;
  const std::string storePath = outDir + "/demo.mps";

  auto t0 = std::chrono::steady_clock::now();
  store::StoreWriter writer(storePath, store::syntheticMeta(opt));
  uint64_t n = store::generateSynthetic(opt, writer);
  store::WriteStats ws = writer.close();
  double writeSeconds = secondsSince(t0);

  auto t1 = std::chrono::steady_clock::now();
  store::StoreReader reader(storePath);
  store::VerifyReport rep = reader.verify();
  double verifySeconds = secondsSince(t1);

  std::printf("reshutter demo\n");
  std::printf("  store     %s\n", storePath.c_str());
  std::printf("            %s micropolygons, %s (%.1f bytes/micropolygon), %s tiles\n", grouped(n).c_str(), humanBytes(double(ws.fileBytes)).c_str(),
              double(ws.fileBytes) / double(n), grouped(ws.tiles).c_str());
  std::printf("  timings   generate+write %.2f s, decode+verify %.2f s (%s micropolygons checked)\n", writeSeconds, verifySeconds,
              grouped(rep.micropolygons).c_str());
  std::printf("  next      reshutter info %s\n", storePath.c_str());
  return 0;
}

}  // namespace

void addDemoCommand(CLI::App& app, Registry& registry) {
  auto* sub = app.add_subcommand("demo", "Run the main job on built-in content (no input files needed)");
  auto out = std::make_shared<std::string>("demo-output");
  auto n = std::make_shared<uint64_t>(1'000'000);
  sub->add_option("-o,--output", *out, "Directory for the outputs")->capture_default_str();
  sub->add_option("-n,--micropolygons", *n, "Size of the synthetic scene")->capture_default_str();
  registry.add(sub, [=] { return runDemo(*out, *n); });
}

}  // namespace reshutter::cli
