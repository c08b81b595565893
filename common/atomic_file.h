// Atomic output files: everything reshutter writes (stores, images) goes to a temporary file in
// the destination's directory and is renamed into place only when complete, so a crash, an error
// or Ctrl-C never leaves a half-written output under the final name. Temporary files still open
// when SIGINT/SIGTERM arrives are unlinked by the handler installInterruptCleanup() sets up.
#pragma once

#include <cstdio>
#include <string>

namespace reshutter {

class AtomicFile {
 public:
  /// Creates "<dir>/.<name>.tmp-XXXXXX" next to `finalPath`. Throws Error on failure.
  explicit AtomicFile(std::string finalPath);
  ~AtomicFile();  // unlinks the temporary unless commit() succeeded
  AtomicFile(const AtomicFile&) = delete;
  AtomicFile& operator=(const AtomicFile&) = delete;

  const std::string& finalPath() const { return finalPath_; }
  const std::string& tempPath() const { return tempPath_; }
  /// Open descriptor on the temporary (for writers that take a fd); closed by commit()/destructor.
  int fd() const { return fd_; }

  /// Flushes to disk and renames the temporary over finalPath. Throws Error on failure.
  void commit();
  /// Removes the temporary now (idempotent).
  void discard();

 private:
  std::string finalPath_;
  std::string tempPath_;
  int fd_ = -1;
  int slot_ = -1;
  bool done_ = false;
};

/// Throws the Error AtomicFile(finalPath) would, without creating anything: for checking every
/// output before minutes of work rather than after (a missing or read-only directory, a path
/// that names a directory).
void checkCanCreate(const std::string& finalPath);

/// Installs SIGINT/SIGTERM handlers that unlink live AtomicFile temporaries, then re-raise.
void installInterruptCleanup();

/// Writes `size` bytes to `fd`, retrying short writes; throws Error naming `path` on failure.
void writeAll(int fd, const void* data, size_t size, const std::string& path);

}  // namespace reshutter
