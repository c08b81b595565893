#include "common/error.h"

namespace reshutter {

namespace {
std::string joined(const std::string& where, const std::string& what) {
  return where.empty() ? what : where + ": " + what;
}
}  // namespace

Error::Error(std::string where, std::string what)
    : std::runtime_error(joined(where, what)), where_(std::move(where)), problem_(std::move(what)) {}

}  // namespace reshutter
