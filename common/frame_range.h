// Frame ranges and file-name patterns as render farms write them:
//   ranges   "7", "1-100", "1-100x2" (every 2nd frame), "1-10,20,30-40x5", "-3--1"
//   patterns "shot.####.mps" (# per digit of zero padding), "shot.%04d.mps" (printf style),
//            "shot.@.mps" (one @ = unpadded; @@@@ = padded to 4).
#pragma once

#include <cstdint>
#include <string>
#include <vector>

namespace reshutter {

/// Parses a range list; throws Error naming `where` (e.g. "--frames") on bad syntax.
std::vector<int64_t> parseFrameRange(const std::string& text, const std::string& where = "--frames");

/// True if `pattern` contains a frame placeholder (#, @ or a %d-style conversion).
bool hasFramePlaceholder(const std::string& pattern);

/// Substitutes `frame` into the placeholder; a pattern without one is returned unchanged.
/// Negative frames keep their sign in front of the padding ("-001").
std::string expandFramePattern(const std::string& pattern, int64_t frame);

/// The frames whose files exist for `pattern`, ascending: every file in the pattern's directory
/// that the pattern expands to for some frame (so "shot.####.mps" finds shot.0007.mps but not
/// shot.7.mps or shot.0007.mps.tmp). Empty when the directory cannot be read.
std::vector<int64_t> framesOnDisk(const std::string& pattern);

}  // namespace reshutter
