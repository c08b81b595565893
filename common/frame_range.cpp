#include "common/frame_range.h"

#include <algorithm>
#include <charconv>
#include <cstdio>
#include <filesystem>

#include "common/error.h"

namespace reshutter {
namespace {

int64_t parseInt(const std::string& text, size_t& pos, const std::string& where) {
  size_t start = pos;
  if (pos < text.size() && (text[pos] == '-' || text[pos] == '+')) ++pos;
  while (pos < text.size() && text[pos] >= '0' && text[pos] <= '9') ++pos;
  int64_t v = 0;
  const char* b = text.data() + start + (text[start] == '+' ? 1 : 0);
  auto [end, ec] = std::from_chars(b, text.data() + pos, v);
  if (ec != std::errc() || end != text.data() + pos || pos == start) fail(where, "expected a frame number at position ", start + 1, " of '", text, "'");
  return v;
}

std::string padded(int64_t frame, int width) {
  std::string digits = std::to_string(frame < 0 ? -frame : frame);
  if (int(digits.size()) < width) digits.insert(0, size_t(width) - digits.size(), '0');
  return frame < 0 ? "-" + digits : digits;
}

// Finds the placeholder: returns [begin, end) and the padding width, or begin == npos.
void findPlaceholder(const std::string& p, size_t& begin, size_t& end, int& width) {
  begin = std::string::npos;
  for (size_t i = 0; i < p.size(); ++i) {
    if (p[i] == '#' || p[i] == '@') {
      size_t j = i;
      while (j < p.size() && p[j] == p[i]) ++j;
      begin = i;
      end = j;
      width = p[i] == '@' && j - i == 1 ? 0 : int(j - i);
      return;
    }
    if (p[i] == '%') {
      size_t j = i + 1;
      if (j < p.size() && p[j] == '%') {
        i = j;
        continue;
      }
      int w = 0;
      while (j < p.size() && p[j] >= '0' && p[j] <= '9') w = w * 10 + (p[j++] - '0');
      if (j < p.size() && p[j] == 'd') {
        begin = i;
        end = j + 1;
        width = w;
        return;
      }
    }
  }
}

}  // namespace

std::vector<int64_t> parseFrameRange(const std::string& text, const std::string& where) {
  std::vector<int64_t> frames;
  if (text.empty()) fail(where, "empty frame range");
  size_t pos = 0;
  while (true) {
    int64_t first = parseInt(text, pos, where);
    int64_t last = first, step = 1;
    if (pos < text.size() && text[pos] == '-') {
      ++pos;
      last = parseInt(text, pos, where);
      if (pos < text.size() && (text[pos] == 'x' || text[pos] == ':')) {
        ++pos;
        step = parseInt(text, pos, where);
        if (step <= 0) fail(where, "step must be positive in '", text, "'");
      }
    }
    if (last < first) fail(where, "range ", first, "-", last, " runs backwards");
    if ((last - first) / step > 10'000'000) fail(where, "range '", text, "' has more than ten million frames");
    for (int64_t f = first; f <= last; f += step) frames.push_back(f);
    if (pos == text.size()) break;
    if (text[pos] != ',') fail(where, "unexpected '", text[pos], "' at position ", pos + 1, " of '", text, "'");
    ++pos;
  }
  return frames;
}

bool hasFramePlaceholder(const std::string& pattern) {
  size_t b, e;
  int w;
  findPlaceholder(pattern, b, e, w);
  return b != std::string::npos;
}

std::string expandFramePattern(const std::string& pattern, int64_t frame) {
  size_t b, e;
  int w = 0;
  findPlaceholder(pattern, b, e, w);
  if (b == std::string::npos) return pattern;
  return pattern.substr(0, b) + padded(frame, w) + pattern.substr(e);
}

std::vector<int64_t> framesOnDisk(const std::string& pattern) {
  size_t b, e;
  int w = 0;
  findPlaceholder(pattern, b, e, w);
  std::vector<int64_t> frames;
  if (b == std::string::npos) return frames;
  const std::filesystem::path full(pattern);
  const std::filesystem::path dir = full.has_parent_path() ? full.parent_path() : std::filesystem::path(".");
  // The placeholder must lie in the file name: a frame number in a directory name is not a shot.
  const std::string name = full.filename().string();
  const size_t nameStart = pattern.size() - name.size();
  if (b < nameStart) return frames;
  const std::string prefix = pattern.substr(nameStart, b - nameStart), suffix = pattern.substr(e);
  std::error_code ec;
  for (const auto& entry : std::filesystem::directory_iterator(dir, ec)) {
    const std::string file = entry.path().filename().string();
    if (file.size() <= prefix.size() + suffix.size() || file.compare(0, prefix.size(), prefix) != 0 ||
        file.compare(file.size() - suffix.size(), suffix.size(), suffix) != 0)
      continue;
    const std::string digits = file.substr(prefix.size(), file.size() - prefix.size() - suffix.size());
    const size_t sign = digits[0] == '-' ? 1 : 0;
    if (digits.size() == sign || digits.size() > 18 || !std::all_of(digits.begin() + sign, digits.end(), [](char c) { return c >= '0' && c <= '9'; })) continue;
    const int64_t frame = std::stoll(digits);
    if (expandFramePattern(name, frame) == file) frames.push_back(frame);  // the pattern's own padding
  }
  std::sort(frames.begin(), frames.end());
  return frames;
}

}  // namespace reshutter
