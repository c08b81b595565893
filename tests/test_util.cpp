#include "tests/test_util.h"

#include <sys/wait.h>
#include <unistd.h>
#include <algorithm>
#include <array>
#include <cctype>
#include <cstdio>
#include <random>

namespace reshutter::test {

ScratchDir::ScratchDir() {
  const auto* info = ::testing::UnitTest::GetInstance()->current_test_info();
  std::string name = info ? std::string(info->test_suite_name()) + "." + info->name() : "scratch";
  for (char& c : name)
    if (c == '/') c = '_';
  dir_ = std::filesystem::path(RESHUTTER_TEST_TMP) / (name + "." + std::to_string(::getpid()));
  std::filesystem::remove_all(dir_);
  std::filesystem::create_directories(dir_);
}

ScratchDir::~ScratchDir() {
  std::error_code ec;
  std::filesystem::remove_all(dir_, ec);
}

CommandResult runCommand(const std::string& command) {
  CommandResult r;
  char errTemplate[] = "/tmp/reshutter-test-stderr-XXXXXX";
  int errFd = ::mkstemp(errTemplate);
  ::close(errFd);
  std::string full = command + " 2>" + errTemplate;
  FILE* pipe = ::popen(full.c_str(), "r");
  if (!pipe) return r;
  std::array<char, 4096> buf;
  size_t n;
  while ((n = std::fread(buf.data(), 1, buf.size(), pipe)) > 0) r.out.append(buf.data(), n);
  int status = ::pclose(pipe);
  r.exitCode = WIFEXITED(status) ? WEXITSTATUS(status) : 128 + WTERMSIG(status);
  std::ifstream err(errTemplate);
  r.err.assign(std::istreambuf_iterator<char>(err), {});
  std::remove(errTemplate);
  return r;
}

CommandResult runImageTool(const std::string& toolAndArgs) { return runCommand("timeout 300 " + toolAndArgs); }

CommandResult runReshutter(const std::string& args) { return runCommand(std::string(RESHUTTER_BINARY) + " " + args); }

std::vector<uint8_t> readBytes(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  return std::vector<uint8_t>(std::istreambuf_iterator<char>(in), {});
}

void writeBytes(const std::string& path, const std::vector<uint8_t>& bytes) {
  std::ofstream out(path, std::ios::binary);
  out.write(reinterpret_cast<const char*>(bytes.data()), std::streamsize(bytes.size()));
}

std::string sourceDir() { return RESHUTTER_SOURCE_DIR; }

// No std::regex: GCC 12 warns inside <regex> at -O1 (-Wmaybe-uninitialized).
uint64_t numberBefore(const std::string& report, const std::string& after) {
  const size_t at = report.find(after);
  if (at == std::string::npos) return 0;
  size_t from = at;
  while (from > 0 && (std::isdigit(static_cast<unsigned char>(report[from - 1])) || report[from - 1] == ',')) --from;
  std::string digits = report.substr(from, at - from);
  digits.erase(std::remove(digits.begin(), digits.end(), ','), digits.end());
  return digits.empty() ? 0 : std::stoull(digits);
}
std::string sharedDir() { return std::string(RESHUTTER_SOURCE_DIR) + "/../shared"; }

}  // namespace reshutter::test
