#include "common/log.h"

#include <atomic>
#include <cstdio>
#include <map>
#include <mutex>

namespace reshutter {
namespace {
std::atomic<int> g_verbosity{static_cast<int>(Verbosity::Normal)};
std::atomic<size_t> g_count{0};
std::mutex g_mutex;
std::map<std::string, size_t, std::less<>>& kinds() {
  static std::map<std::string, size_t, std::less<>> k;
  return k;
}
}  // namespace

void setVerbosity(Verbosity v) { g_verbosity = static_cast<int>(v); }
Verbosity verbosity() { return static_cast<Verbosity>(g_verbosity.load()); }

void warn(std::string_view message) {
  ++g_count;
  if (verbosity() == Verbosity::Quiet) return;
  std::lock_guard lock(g_mutex);
  std::fprintf(stderr, "reshutter: warning: %.*s\n", int(message.size()), message.data());
}

void warnOnce(std::string_view kind, std::string_view message) {
  {
    std::lock_guard lock(g_mutex);
    auto it = kinds().find(kind);
    if (it != kinds().end()) {
      ++it->second;
      ++g_count;
      return;
    }
    kinds().emplace(std::string(kind), 1);
  }
  warn(message);
}

void flushWarningCounts() {
  std::lock_guard lock(g_mutex);
  for (const auto& [kind, n] : kinds())
    if (n > 1 && verbosity() != Verbosity::Quiet) std::fprintf(stderr, "reshutter: warning: %s: %zu more like this\n", kind.c_str(), n - 1);
  kinds().clear();
}

size_t warningCount() { return g_count.load(); }

void note(std::string_view message) {
  if (verbosity() == Verbosity::Quiet) return;
  std::lock_guard lock(g_mutex);
  std::fprintf(stderr, "%.*s\n", int(message.size()), message.data());
}

}  // namespace reshutter
