// Internal invariants: CHECK(cond, what...) always, DCHECK(cond, what...) in debug builds only.
// A failed check is a bug in reshutter, not bad input: it throws InternalError (never an Error),
// which the CLI reports as "reshutter: internal error: file:line: ..." with exit status 3, so a
// user is never told their input is wrong when the code is.
#pragma once

#include <stdexcept>
#include <string>

#include "common/error.h"

namespace reshutter {

class InternalError : public std::logic_error {
 public:
  using std::logic_error::logic_error;
};

[[noreturn]] void failInternal(const char* file, int line, const char* condition, const std::string& what);

}  // namespace reshutter

#define CHECK(condition, ...)                                                                                     \
  do {                                                                                                            \
    if (!(condition)) [[unlikely]]                                                                                \
      ::reshutter::failInternal(__FILE__, __LINE__, #condition, ::reshutter::cat("" __VA_OPT__(, ) __VA_ARGS__)); \
  } while (0)

#ifdef NDEBUG
#define DCHECK(condition, ...) \
  do {                         \
  } while (0)
#else
#define DCHECK(condition, ...) CHECK(condition __VA_OPT__(, ) __VA_ARGS__)
#endif
