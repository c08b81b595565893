#include "common/atomic_file.h"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>
#include <atomic>
#include <cerrno>
#include <csignal>
#include <cstring>
#include <filesystem>

#include "common/error.h"

namespace reshutter {
namespace {

// A fixed table the signal handler can walk without allocating or locking.
constexpr int kSlots = 256;
constexpr int kPathMax = 4096;
char g_paths[kSlots][kPathMax];
std::atomic<bool> g_used[kSlots];

int claimSlot(const std::string& path) {
  if (path.size() >= kPathMax) return -1;
  for (int i = 0; i < kSlots; ++i) {
    bool expected = false;
    if (g_used[i].compare_exchange_strong(expected, true)) {
      std::memcpy(g_paths[i], path.c_str(), path.size() + 1);
      return i;
    }
  }
  return -1;  // more than kSlots files in flight: they lose only the Ctrl-C cleanup
}

void releaseSlot(int slot) {
  if (slot >= 0) g_used[slot] = false;
}

extern "C" void onInterrupt(int sig) {
  for (int i = 0; i < kSlots; ++i)
    if (g_used[i].load()) ::unlink(g_paths[i]);
  std::signal(sig, SIG_DFL);
  std::raise(sig);
}

// The directory an output's temporary goes in; an Error if the path names no file.
std::filesystem::path directoryOf(const std::string& finalPath) {
  const std::filesystem::path target(finalPath);
  if (target.filename().empty()) fail(finalPath, "not a file name");
  return target.parent_path().empty() ? std::filesystem::path(".") : target.parent_path();
}

}  // namespace

void checkCanCreate(const std::string& finalPath) {
  namespace fs = std::filesystem;
  const fs::path target(finalPath), dir = directoryOf(finalPath);
  std::error_code ec;
  if (!fs::is_directory(dir, ec)) fail(finalPath, "cannot create a temporary file in ", dir.string(), ": no such directory");
  if (::access(dir.c_str(), W_OK | X_OK) != 0) fail(finalPath, "cannot create a temporary file in ", dir.string(), ": ", std::strerror(errno));
  if (fs::is_directory(target, ec)) fail(finalPath, "is a directory");
}

AtomicFile::AtomicFile(std::string finalPath) : finalPath_(std::move(finalPath)) {
  namespace fs = std::filesystem;
  const fs::path target(finalPath_), dir = directoryOf(finalPath_);
  std::string pattern = (dir / ("." + target.filename().string() + ".tmp-XXXXXX")).string();
  fd_ = ::mkstemp(pattern.data());
  if (fd_ < 0) fail(finalPath_, "cannot create a temporary file in ", dir.string(), ": ", std::strerror(errno));
  tempPath_ = pattern;
  ::fchmod(fd_, 0644);
  slot_ = claimSlot(tempPath_);
}

AtomicFile::~AtomicFile() { discard(); }

void AtomicFile::commit() {
  if (done_) fail(finalPath_, "already committed or discarded");
  if (::fsync(fd_) != 0) fail(finalPath_, "cannot flush: ", std::strerror(errno));
  ::close(fd_);
  fd_ = -1;
  if (::rename(tempPath_.c_str(), finalPath_.c_str()) != 0) {
    int e = errno;
    discard();
    fail(finalPath_, "cannot move the finished file into place: ", std::strerror(e));
  }
  releaseSlot(slot_);
  slot_ = -1;
  done_ = true;
}

void AtomicFile::discard() {
  if (fd_ >= 0) ::close(fd_);
  fd_ = -1;
  if (!done_ && !tempPath_.empty()) ::unlink(tempPath_.c_str());
  releaseSlot(slot_);
  slot_ = -1;
  done_ = true;
}

void installInterruptCleanup() {
  std::signal(SIGINT, onInterrupt);
  std::signal(SIGTERM, onInterrupt);
}

void writeAll(int fd, const void* data, size_t size, const std::string& path) {
  const auto* p = static_cast<const char*>(data);
  while (size > 0) {
    ssize_t n = ::write(fd, p, size);
    if (n < 0) {
      if (errno == EINTR) continue;
      fail(path, "write failed: ", std::strerror(errno));
    }
    p += n;
    size -= size_t(n);
  }
}

}  // namespace reshutter
