#include "common/progress.h"

#include <unistd.h>
#include <algorithm>
#include <cstdio>

#include "common/log.h"

namespace reshutter {

bool Progress::enabledForTerminal() { return ::isatty(2) && verbosity() != Verbosity::Quiet; }

Progress::Progress(std::string label, uint64_t total)
    : label_(std::move(label)), total_(total ? total : 1), start_(std::chrono::steady_clock::now()), enabled_(enabledForTerminal()) {}

Progress::~Progress() { finish(); }

void Progress::advance(uint64_t n) {
  uint64_t done = done_.fetch_add(n) + n;
  if (!enabled_) return;
  int64_t now = std::chrono::duration_cast<std::chrono::nanoseconds>(std::chrono::steady_clock::now() - start_).count();
  int64_t last = lastDrawNs_.load();
  if (now - last < 100'000'000 && done < total_) return;  // at most 10 redraws per second
  if (!lastDrawNs_.compare_exchange_strong(last, now)) return;
  draw(done);
}

void Progress::draw(uint64_t done) {
  std::lock_guard lock(drawMutex_);
  if (finished_) return;
  double fraction = std::min(1.0, double(done) / double(total_));
  constexpr int kWidth = 30;
  int filled = int(fraction * kWidth);
  char bar[kWidth + 1];
  for (int i = 0; i < kWidth; ++i) bar[i] = i < filled ? '#' : '.';
  bar[kWidth] = 0;
  double elapsed = std::chrono::duration<double>(std::chrono::steady_clock::now() - start_).count();
  double eta = fraction > 0.01 ? elapsed * (1 - fraction) / fraction : 0;
  std::fprintf(stderr, "\r%-12s [%s] %5.1f%%  %6.1fs  eta %5.1fs ", label_.c_str(), bar, fraction * 100, elapsed, eta);
  std::fflush(stderr);
}

void Progress::finish() {
  std::lock_guard lock(drawMutex_);
  if (finished_) return;
  finished_ = true;
  if (enabled_ && lastDrawNs_.load() != 0) {
    std::fprintf(stderr, "\r%*s\r", 80, "");
    std::fflush(stderr);
  }
}

}  // namespace reshutter
