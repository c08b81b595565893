// A progress bar for long work, drawn on stderr only when stderr is a terminal (never in logs or
// CI output). Thread-safe: TBB tasks call advance() concurrently; redraws are throttled.
#pragma once

#include <atomic>
#include <chrono>
#include <cstdint>
#include <mutex>
#include <string>

namespace reshutter {

class Progress {
 public:
  Progress(std::string label, uint64_t total);
  ~Progress();
  Progress(const Progress&) = delete;
  Progress& operator=(const Progress&) = delete;

  void advance(uint64_t n = 1);
  /// Erases the bar (called by the destructor too).
  void finish();
  static bool enabledForTerminal();

 private:
  void draw(uint64_t done);
  std::string label_;
  uint64_t total_;
  std::atomic<uint64_t> done_{0};
  std::atomic<int64_t> lastDrawNs_{0};
  std::chrono::steady_clock::time_point start_;
  std::mutex drawMutex_;
  bool enabled_;
  bool finished_ = false;
};

}  // namespace reshutter
