// Warnings and notes for the user. Warnings go to stderr as "reshutter: warning: ...";
// warnOnce() collapses repeats of one kind (e.g. one unsupported RIB request) into the first
// occurrence plus a count printed by flushWarningCounts(). Thread-safe.
#pragma once

#include <string>
#include <string_view>

namespace reshutter {

enum class Verbosity { Quiet = 0, Normal = 1, Verbose = 2 };

void setVerbosity(Verbosity v);
Verbosity verbosity();

void warn(std::string_view message);
/// Warns the first time `kind` is seen; later calls only count.
void warnOnce(std::string_view kind, std::string_view message);
/// Prints "N more like this" for every kind warned more than once, then forgets them.
void flushWarningCounts();
/// Total warnings issued (including suppressed repeats) since start; tests use it.
size_t warningCount();

/// Informational line on stderr (suppressed when Quiet).
void note(std::string_view message);

}  // namespace reshutter
