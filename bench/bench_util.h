// Small helpers shared by the benchmark programs: wall clock, peak resident memory, machine line.
#pragma once

#include <chrono>
#include <fstream>
#include <string>
#include <thread>

namespace reshutter::bench {

class Stopwatch {
 public:
  Stopwatch() : start_(std::chrono::steady_clock::now()) {}
  double seconds() const { return std::chrono::duration<double>(std::chrono::steady_clock::now() - start_).count(); }
  void reset() { start_ = std::chrono::steady_clock::now(); }

 private:
  std::chrono::steady_clock::time_point start_;
};

/// Peak resident set size of this process in bytes (VmHWM).
inline size_t peakRssBytes() {
  std::ifstream in("/proc/self/status");
  std::string line;
  while (std::getline(in, line))
    if (line.rfind("VmHWM:", 0) == 0) return size_t(std::stoull(line.substr(6))) * 1024;
  return 0;
}

// The CPU a figure was measured on, with family and model: the VM lands on different hosts
// between sessions under the same model name ("AMD EPYC" for Zen 4 and Zen 5 alike).
inline std::string machineLine() {
  std::ifstream in("/proc/cpuinfo");
  std::string line, model = "unknown CPU", family, number;
  auto value = [&] { return line.substr(line.find(':') + 2); };
  while (std::getline(in, line) && (model == "unknown CPU" || family.empty() || number.empty())) {
    if (line.rfind("model name", 0) == 0) model = value();
    else if (line.rfind("cpu family", 0) == 0) family = value();
    else if (line.rfind("model", 0) == 0 && line.find(':') != std::string::npos) number = value();
  }
  if (!family.empty()) model += " (family " + family + " model " + number + ")";
  return model + ", " + std::to_string(std::thread::hardware_concurrency()) + " hardware threads";
}

}  // namespace reshutter::bench
