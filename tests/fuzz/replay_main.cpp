// Runs a fuzz target's entry point (LLVMFuzzerTestOneInput) over files without libFuzzer. The normal
// build compiles every fuzz target with it and ctest replays each target's regression corpus
// (tests/corpus/<target>/) through it: a target that no longer compiles, or an input that
// crashes it again, fails the test run - not only the next hand-run of scripts/fuzz.sh.
// Usage: fuzz_replay_<target> FILE_OR_DIRECTORY...
#include <algorithm>
#include <cstdint>
#include <cstdio>
#include <filesystem>
#include <vector>

#include "tests/test_util.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size);

int main(int argc, char** argv) {
  std::vector<std::filesystem::path> files;
  for (int i = 1; i < argc; ++i) {
    const std::filesystem::path arg(argv[i]);
    if (std::filesystem::is_directory(arg)) {
      for (const auto& e : std::filesystem::directory_iterator(arg))
        if (e.is_regular_file()) files.push_back(e.path());
    } else {
      files.push_back(arg);
    }
  }
  std::sort(files.begin(), files.end());
  for (const auto& f : files) {
    const std::vector<uint8_t> bytes = reshutter::test::readBytes(f.string());
    LLVMFuzzerTestOneInput(bytes.data(), bytes.size());
  }
  // No input would make the test pass without running the target.
  if (files.empty()) {
    std::fprintf(stderr, "fuzz replay: no inputs\n");
    return 1;
  }
  std::printf("%zu inputs replayed\n", files.size());
  return 0;
}
