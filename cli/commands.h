// The reshutter command's subcommands; each registers itself on the CLI11 app and returns the
// action to run after parsing.
#pragma once

#include <functional>

#include <CLI/CLI.hpp>

namespace reshutter::cli {

using Action = std::function<int()>;
struct Registry {
  std::vector<std::pair<CLI::App*, Action>> commands;
  void add(CLI::App* sub, Action a) { commands.emplace_back(sub, std::move(a)); }
};

void addStoreCommands(CLI::App& app, Registry& registry);  // info, verify, generate
void addDemoCommand(CLI::App& app, Registry& registry);
void addResampleCommand(CLI::App& app, Registry& registry);
void addRetimeCommands(CLI::App& app, Registry& registry);  // fields, retime
void addIngestCommand(CLI::App& app, Registry& registry);
void addShadeCommand(CLI::App& app, Registry& registry);

/// Formats 1234567 as "1,234,567".
std::string grouped(uint64_t n);
/// Formats bytes as "12.3 MB".
std::string humanBytes(double bytes);

}  // namespace reshutter::cli
