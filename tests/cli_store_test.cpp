// The store commands as a user meets them: info (human and JSON, checked with jq), verify, and
// one-line errors with a non-zero exit for damaged or missing files.
#include <filesystem>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "tests/test_util.h"

using reshutter::test::runCommand;
using reshutter::test::runReshutter;

namespace {
size_t lines(const std::string& s) {
  size_t n = 0;
  for (char c : s) n += c == '\n';
  return n;
}
}  // namespace

TEST(CliStore, GenerateInfoVerify) {
  reshutter::test::ScratchDir dir;
  std::string store = dir.path("s.mps");
  auto gen = runReshutter("generate -n 20000 --width 320 --height 240 -o " + store);
  ASSERT_EQ(gen.exitCode, 0) << gen.err;
  auto info = runReshutter("info " + store);
  ASSERT_EQ(info.exitCode, 0) << info.err;
  EXPECT_NE(info.out.find("micropolygons  20,224"), std::string::npos) << info.out;  // 79 grids of 256
  EXPECT_NE(info.out.find("moving"), std::string::npos);
  EXPECT_NE(info.out.find("320x240"), std::string::npos);

  auto json = runCommand(std::string(RESHUTTER_BINARY) + " info --json " + store +
                         " | jq -e '.micropolygons == 20224 and .cameras[0].width == 320 and (.schema | length) == 2'");
  EXPECT_EQ(json.exitCode, 0) << json.out << json.err;

  auto verify = runReshutter("verify " + store);
  EXPECT_EQ(verify.exitCode, 0) << verify.err;
  EXPECT_NE(verify.out.find("OK"), std::string::npos);
}

TEST(CliStore, DamagedAndMissingFilesGiveOneLineErrors) {
  reshutter::test::ScratchDir dir;
  std::string store = dir.path("s.mps");
  ASSERT_EQ(runReshutter("generate -n 5000 --width 160 --height 120 -o " + store).exitCode, 0);
  auto bytes = reshutter::test::readBytes(store);
  bytes[100] ^= 0xff;
  std::string bad = dir.path("bad.mps");
  reshutter::test::writeBytes(bad, bytes);
  for (const auto& [args, needle] : std::vector<std::pair<std::string, std::string>>{
           {"verify " + bad, "checksum mismatch"},
           {"info " + dir.path("missing.mps"), "cannot open"},
           {"info " + dir.path(""), "not a regular file"},
       }) {
    auto r = runReshutter(args);
    EXPECT_EQ(r.exitCode, 1) << args;
    EXPECT_EQ(lines(r.err), 1u) << r.err;
    EXPECT_EQ(r.err.rfind("reshutter: ", 0), 0u) << r.err;
    EXPECT_NE(r.err.find(needle), std::string::npos) << r.err;
  }
}

TEST(CliStore, UsageErrorsExitTwoAndHelpTeaches) {
  // Missing arguments, unknown options and out-of-range values: one line in the error model's
  // form, exit status 2, and nothing written.
  reshutter::test::ScratchDir dir;
  const std::string out = dir.path("x.mps");
  for (const std::string& args : std::vector<std::string>{"", "info", "resample", "generate -o " + out + " --still 2", "generate -o " + out + " --nonesuch",
                                                          "generate -o " + out + " -n abc"}) {
    auto r = runReshutter(args);
    EXPECT_EQ(r.exitCode, 2) << args;
    EXPECT_EQ(lines(r.err), 1u) << args << ": " << r.err;
    EXPECT_EQ(r.err.rfind("reshutter: ", 0), 0u) << r.err;
    EXPECT_FALSE(std::filesystem::exists(out)) << args;
  }
  auto help = runReshutter("--help");
  EXPECT_EQ(help.exitCode, 0);
  EXPECT_NE(help.out.find("info"), std::string::npos);
  EXPECT_NE(help.out.find("verify"), std::string::npos);
}
