#include "common/error.h"

#include "common/check.h"

namespace reshutter {

namespace {
std::string joined(const std::string& where, const std::string& what) { return where.empty() ? what : where + ": " + what; }
}  // namespace

Error::Error(std::string where, std::string what) : std::runtime_error(joined(where, what)), where_(std::move(where)), problem_(std::move(what)) {}

void failInternal(const char* file, int line, const char* condition, const std::string& what) {
  std::string message = cat(file, ":", line, ": check '", condition, "' failed");
  if (!what.empty()) message += ": " + what;
  throw InternalError(message);
}

}  // namespace reshutter
