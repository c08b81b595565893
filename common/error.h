// The project's one error model: every failure a user can cause (bad input, bad arguments, I/O)
// is a reshutter::Error carrying *where* (file, file:line, file:tile, option) and *what*, printed
// by the CLI as a single line "reshutter: where: what" with exit status 1. Programming errors
// (broken invariants inside the library) are CHECKs (common/check.h), never Errors: they exit 3
// with "internal error" in the message.
#pragma once

#include <sstream>
#include <stdexcept>
#include <string>
#include <utility>

namespace reshutter {

class Error : public std::runtime_error {
 public:
  Error(std::string where, std::string what);

  /// The place: "shot.0001.mps: tile (3,-2) part 7", "scene.rib:42 (Sphere)", "--shutter".
  const std::string& where() const noexcept { return where_; }
  /// The problem, without the place.
  const std::string& problem() const noexcept { return problem_; }

 private:
  std::string where_;
  std::string problem_;
};

/// Concatenates anything streamable; keeps error construction sites to one line.
template <typename... Args>
std::string cat(Args&&... args) {
  std::ostringstream out;
  out.precision(9);
  (out << ... << std::forward<Args>(args));
  return out.str();
}

template <typename... Args>
[[noreturn]] void fail(std::string where, Args&&... what) {
  throw Error(std::move(where), cat(std::forward<Args>(what)...));
}

}  // namespace reshutter
