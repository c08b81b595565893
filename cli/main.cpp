// reshutter: shade once, re-sample for any shutter. A thin front end over the libraries: parses
// arguments, runs one subcommand, turns every reshutter::Error into one line and a non-zero exit.
#include <algorithm>
#include <cstdio>
#include <memory>
#include <thread>

#include <tbb/global_control.h>

#include "cli/commands.h"
#include "common/atomic_file.h"
#include "common/check.h"
#include "common/error.h"
#include "common/log.h"
#include "resample/image.h"

int main(int argc, char** argv) {
  using namespace reshutter;
  installInterruptCleanup();
  CLI::App app{
      "reshutter: shade a frame once, keep every shaded, moving micropolygon in a sparse tile store,\n"
      "then re-sample that store for any shutter: sub-intervals, interlaced fields, other frame rates,\n"
      "rolling shutter, flat and deep OpenEXR.\n\n"
      "Start with `reshutter demo`, or `reshutter <command> --help` for one command.",
      "reshutter"};
  app.require_subcommand(1);
  app.set_version_flag("--version", "reshutter 0.1.0");
  int threads = 0;
  bool quiet = false, verbose = false;
  app.add_option("--threads,-j", threads, "Worker threads (default: all cores)")->check(CLI::NonNegativeNumber);
  app.add_flag("--quiet,-q", quiet, "Only errors");
  app.add_flag("--verbose,-v", verbose, "More detail");

  cli::Registry registry;
  registry.argv.assign(argv, argv + argc);
  cli::addDemoCommand(app, registry);
  cli::addShadeCommand(app, registry);
  cli::addResampleCommand(app, registry);
  cli::addRetimeCommands(app, registry);
  cli::addIngestCommand(app, registry);
  cli::addStoreCommands(app, registry);
  cli::addFarmCommands(app, registry);

  try {
    app.parse(argc, argv);
  } catch (const CLI::Success& e) {  // --help, --help-all, --version
    return app.exit(e);
  } catch (const CLI::ParseError& e) {
    // A usage error: one line in the error model's form and exit status 2 (as getopt tools),
    // not CLI11's two lines and its own codes (105, 106, ...).
    std::string what = e.what();
    std::replace(what.begin(), what.end(), '\n', ' ');
    std::fprintf(stderr, "reshutter: %s (--help explains every option)\n", what.c_str());
    return 2;
  }
  setVerbosity(quiet ? Verbosity::Quiet : verbose ? Verbosity::Verbose : Verbosity::Normal);
  std::unique_ptr<tbb::global_control> limit;
  if (threads > 0) limit = std::make_unique<tbb::global_control>(tbb::global_control::max_allowed_parallelism, size_t(threads));
  // EXR chunks compress in parallel too: the write of a 1080p float frame is ~1 s on one core.
  resample::setExrThreads(threads > 0 ? threads : int(std::max(1u, std::thread::hardware_concurrency())));

  for (auto& [sub, action] : registry.commands) {
    if (!sub->parsed()) continue;
    try {
      int rc = action();
      flushWarningCounts();
      return rc;
    } catch (const Error& e) {
      flushWarningCounts();
      std::fprintf(stderr, "reshutter: %s\n", e.what());
      return 1;
    } catch (const std::bad_alloc&) {
      std::fprintf(stderr, "reshutter: out of memory\n");
      return 1;
    } catch (const InternalError& e) {  // a broken invariant (common/check.h): reshutter's bug
      flushWarningCounts();
      std::fprintf(stderr, "reshutter: internal error: %s\n", e.what());
      return 3;
    } catch (const std::exception& e) {
      std::fprintf(stderr, "reshutter: internal error: %s\n", e.what());
      return 3;
    }
  }
  return 2;
}
