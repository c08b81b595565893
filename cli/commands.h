// The reshutter command's subcommands; each registers itself on the CLI11 app and returns the
// action to run after parsing.
#pragma once

#include <cstdint>
#include <functional>
#include <string>
#include <vector>

#include <CLI/CLI.hpp>

namespace reshutter::cli {

struct RenderOptions;

/// What a rendering command (resample, fields, retime) was asked for, once parsed: handed to
/// Registry::sequenceHook instead of rendering (the farm submits it as a job).
struct SequenceRequest {
  std::string command;          // resample | fields | retime
  std::string stores;           // the store, or the shot's store pattern
  std::vector<int64_t> frames;  // output frames
  std::string output;           // flat EXR (pattern); the deep one is render->deep
  const RenderOptions* render = nullptr;
};
using SequenceHook = std::function<int(const SequenceRequest&)>;

using Action = std::function<int()>;
struct Registry {
  std::vector<std::pair<CLI::App*, Action>> commands;
  void add(CLI::App* sub, Action a) { commands.emplace_back(sub, std::move(a)); }
  /// Set: the rendering commands registered with this registry hand their request here.
  SequenceHook sequenceHook;
  /// The whole command line (main's argv), for commands that pass arguments on (the farm).
  std::vector<std::string> argv;
};

void addStoreCommands(CLI::App& app, Registry& registry);  // info, verify, generate
void addDemoCommand(CLI::App& app, Registry& registry);
void addResampleCommand(CLI::App& app, Registry& registry);
void addRetimeCommands(CLI::App& app, Registry& registry);  // fields, retime
void addIngestCommand(CLI::App& app, Registry& registry);
void addShadeCommand(CLI::App& app, Registry& registry);
void addFarmCommands(CLI::App& app, Registry& registry);  // farm retime|fields|resample, farm task|assemble|status; assemble

/// Formats 1234567 as "1,234,567".
std::string grouped(uint64_t n);
/// Formats bytes as "12.3 MB".
std::string humanBytes(double bytes);

}  // namespace reshutter::cli
