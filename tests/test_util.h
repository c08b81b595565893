// Helpers shared by the tests: scratch directories, running the CLI, reading files.
#pragma once

#include <cstdint>
#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

#include <gtest/gtest.h>

namespace reshutter::test {

/// A fresh directory under the build tree, removed when the test ends.
class ScratchDir {
 public:
  ScratchDir();
  ~ScratchDir();
  std::string path(const std::string& name) const { return (dir_ / name).string(); }
  const std::filesystem::path& dir() const { return dir_; }

 private:
  std::filesystem::path dir_;
};

struct CommandResult {
  int exitCode = -1;
  std::string out, err;
};
/// Runs the built `reshutter` binary with `args` (a shell-quoted string).
CommandResult runReshutter(const std::string& args);
/// Runs any shell command, capturing stdout and stderr.
CommandResult runCommand(const std::string& command);
/// Runs an OpenImageIO tool (iinfo, idiff, oiiotool) as an independent checker. A hang guard, not
/// a speed check: OpenImageIO 2.4's iinfo can hang on a damaged deep file, so a tool still running
/// after five minutes is killed and reported as a failure (exit 124).
CommandResult runImageTool(const std::string& toolAndArgs);

std::vector<uint8_t> readBytes(const std::string& path);
void writeBytes(const std::string& path, const std::vector<uint8_t>& bytes);

/// The grouped number ("7,215,624") just before `after` in a command's report (0: absent), for
/// the counts `-v` and `--stats` print.
uint64_t numberBefore(const std::string& report, const std::string& after);

/// Path of ../shared relative to the source tree (tests read real inputs from there).
std::string sharedDir();
std::string sourceDir();

}  // namespace reshutter::test
