// A minimal JSON *writer* for `--json` outputs. Nothing in reshutter parses JSON, and the Debian
// JSON libraries (nlohmann-json3, rapidjson) would add seconds of compile time per translation
// unit for what is string escaping and commas.
#pragma once

#include <cmath>
#include <cstdio>
#include <string>
#include <vector>

namespace reshutter::cli {

class JsonWriter {
 public:
  std::string str() const { return out_; }
  JsonWriter& beginObject(const char* key = nullptr) { return open(key, '{'); }
  JsonWriter& endObject() { return close('}'); }
  JsonWriter& beginArray(const char* key = nullptr) { return open(key, '['); }
  JsonWriter& endArray() { return close(']'); }
  JsonWriter& value(const char* key, const std::string& v) { return field(key, quote(v)); }
  JsonWriter& value(const char* key, const char* v) { return field(key, quote(v)); }
  JsonWriter& value(const char* key, bool v) { return field(key, v ? "true" : "false"); }
  JsonWriter& value(const char* key, double v) {
    if (!std::isfinite(v)) return field(key, "null");
    char b[40];
    std::snprintf(b, sizeof b, "%.17g", v);
    return field(key, b);
  }
  template <typename I>
  requires std::is_integral_v<I> JsonWriter& value(const char* key, I v) { return field(key, std::to_string(v)); }

 private:
  static std::string quote(const std::string& s) {
    std::string q = "\"";
    for (unsigned char c : s) {
      if (c == '"' || c == '\\') q += '\\', q += char(c);
      else if (c == '\n') q += "\\n";
      else if (c == '\t') q += "\\t";
      else if (c < 0x20) {
        char b[8];
        std::snprintf(b, sizeof b, "\\u%04x", c);
        q += b;
      } else q += char(c);
    }
    return q + "\"";
  }
  void separate(const char* key) {
    if (!first_.empty()) {
      if (!first_.back()) out_ += ",";
      first_.back() = false;
      out_ += '\n';
      out_.append(first_.size() * 2, ' ');  // not "\n" + std::string(...): GCC 12 warns of a bogus overflow there
    }
    if (key) out_ += quote(key) + ": ";
  }
  JsonWriter& field(const char* key, const std::string& raw) {
    separate(key);
    out_ += raw;
    return *this;
  }
  JsonWriter& open(const char* key, char c) {
    separate(key);
    out_ += c;
    first_.push_back(true);
    return *this;
  }
  JsonWriter& close(char c) {
    bool empty = first_.back();
    first_.pop_back();
    if (!empty) out_ += "\n" + std::string(first_.size() * 2, ' ');
    out_ += c;
    return *this;
  }
  std::string out_;
  std::vector<bool> first_;
};

}  // namespace reshutter::cli
