// RIB tokenizer: chunked input (zlib for gzip), ASCII tokens and the binary encoding.
#include "rib/lexer.h"

#include <bit>
#include <charconv>
#include <cmath>
#include <cstring>

#include <zlib.h>

#include "common/error.h"

namespace reshutter::rib {

namespace {

constexpr size_t kChunk = size_t(1) << 18;
// A single number or name longer than this is not RIB; refusing it keeps memory bounded.
constexpr size_t kMaxAtom = size_t(1) << 16;

class GzFileSource final : public ByteSource {
 public:
  explicit GzFileSource(const std::string& path) : path_(path) {
    gz_ = gzopen(path.c_str(), "rb");
    if (!gz_) fail(path, "cannot open: ", std::strerror(errno));
    gzbuffer(gz_, 1 << 17);
  }
  ~GzFileSource() override { gzclose(gz_); }
  size_t read(char* dst, size_t n) override {
    int got = gzread(gz_, dst, unsigned(n));
    if (got < 0) {
      int code = 0;
      const char* msg = gzerror(gz_, &code);
      fail(path_, "cannot read (", msg ? msg : "zlib error", ")");
    }
    if (got == 0 && !gzeof(gz_)) {
      int code = 0;
      const char* msg = gzerror(gz_, &code);
      if (code != Z_OK) fail(path_, "cannot read (", msg ? msg : "zlib error", ")");
    }
    return size_t(got);
  }

 private:
  std::string path_;
  gzFile gz_ = nullptr;
};

class PlainMemorySource final : public ByteSource {
 public:
  explicit PlainMemorySource(std::string_view b) : b_(b) {}
  size_t read(char* dst, size_t n) override {
    n = std::min(n, b_.size());
    std::memcpy(dst, b_.data(), n);
    b_.remove_prefix(n);
    return n;
  }

 private:
  std::string_view b_;
};

class GzMemorySource final : public ByteSource {
 public:
  GzMemorySource(std::string_view b, std::string name) : name_(std::move(name)) {
    std::memset(&z_, 0, sizeof z_);
    if (inflateInit2(&z_, 16 + MAX_WBITS) != Z_OK) fail(name_, "zlib initialisation failed");
    z_.next_in = reinterpret_cast<Bytef*>(const_cast<char*>(b.data()));
    z_.avail_in = uInt(b.size());
  }
  ~GzMemorySource() override { inflateEnd(&z_); }
  size_t read(char* dst, size_t n) override {
    if (done_) return 0;
    z_.next_out = reinterpret_cast<Bytef*>(dst);
    z_.avail_out = uInt(n);
    while (z_.avail_out == n) {
      int rc = inflate(&z_, Z_NO_FLUSH);
      if (rc == Z_STREAM_END) {
        // Concatenated gzip members are one stream (as gzread treats them).
        if (z_.avail_in >= 2 && z_.next_in[0] == 0x1f && z_.next_in[1] == 0x8b) {
          inflateReset(&z_);
          continue;
        }
        done_ = true;
        break;
      }
      if (rc != Z_OK) fail(name_, "corrupt gzip data (", z_.msg ? z_.msg : "inflate error", ")");
      if (z_.avail_in == 0 && z_.avail_out == n) fail(name_, "truncated gzip data");
    }
    return n - z_.avail_out;
  }

 private:
  std::string name_;
  z_stream z_;
  bool done_ = false;
};

inline bool isSpace(unsigned char c) { return c == ' ' || c == '\t' || c == '\r' || c == '\n' || c == '\f' || c == '\v' || c == 0; }
inline bool isNameStart(unsigned char c) { return (c >= 'a' && c <= 'z') || (c >= 'A' && c <= 'Z') || c == '_'; }
inline bool isNameChar(unsigned char c) { return isNameStart(c) || (c >= '0' && c <= '9'); }
inline bool isNumberChar(unsigned char c) { return (c >= '0' && c <= '9') || c == '.' || c == '-' || c == '+' || c == 'e' || c == 'E'; }

// RtFloat semantics: integers stay exact (vertex indices beyond 2^24), everything else is a float.
inline double asRtFloat(double v) {
  if (v == std::trunc(v) && std::fabs(v) <= 9007199254740992.0) return v;
  return double(float(v));
}

}  // namespace

std::unique_ptr<ByteSource> openFileSource(const std::string& path) { return std::make_unique<GzFileSource>(path); }

std::unique_ptr<ByteSource> memorySource(std::string_view bytes, const std::string& name) {
  if (bytes.size() >= 2 && uint8_t(bytes[0]) == 0x1f && uint8_t(bytes[1]) == 0x8b) return std::make_unique<GzMemorySource>(bytes, name);
  return std::make_unique<PlainMemorySource>(bytes);
}

// The buffer starts small and grows to kChunk over the first reads: small archives (and fuzz
// inputs) do not pay for zeroing a full chunk.
Lexer::Lexer(std::unique_ptr<ByteSource> source, std::string name) : source_(std::move(source)), name_(std::move(name)), buf_(4096) {}

void Lexer::fail(const std::string& problem, bool binary) const {
  std::string where = binary ? cat(name_, ": byte ", base_ + pos_) : cat(name_, ":", line_);
  if (!request_.empty()) where += cat(" (", request_, ")");
  throw Error(where, problem);
}

bool Lexer::more() {
  if (eof_) return false;
  if (pos_ > 0) {
    std::memmove(buf_.data(), buf_.data() + pos_, end_ - pos_);
    end_ -= pos_;
    base_ += pos_;
    pos_ = 0;
  }
  if (buf_.size() < kChunk) buf_.resize(std::min(kChunk, buf_.size() * 4));
  if (end_ == buf_.size()) buf_.resize(buf_.size() * 2);  // a long token; span() caps atoms
  size_t got = source_->read(buf_.data() + end_, buf_.size() - end_);
  if (got == 0) {
    eof_ = true;
    return false;
  }
  end_ += got;
  return true;
}

template <class Pred>
size_t Lexer::span(Pred pred) {
  size_t i = pos_;
  for (;;) {
    while (i < end_ && pred(static_cast<unsigned char>(buf_[i]))) ++i;
    if (i < end_ || eof_) break;
    size_t off = i - pos_;
    if (off > kMaxAtom) fail("token longer than 64 KB", false);
    if (!more()) {
      i = pos_ + off;
      break;
    }
    i = pos_ + off;
  }
  return i - pos_;
}

void Lexer::skipSpace() {
  for (;;) {
    while (pos_ < end_) {
      unsigned char c = static_cast<unsigned char>(buf_[pos_]);
      if (c == '\n') {
        ++line_, ++pos_;
      } else if (isSpace(c)) {
        ++pos_;
      } else if (c == '#') {
        // A comment runs to the end of the line; structure comments (##) are comments too.
        for (;;) {
          const char* nl = static_cast<const char*>(std::memchr(buf_.data() + pos_, '\n', end_ - pos_));
          if (nl) {
            pos_ = size_t(nl - buf_.data());
            break;
          }
          pos_ = end_;
          if (!more()) return;
        }
      } else {
        return;
      }
    }
    if (!more()) return;
  }
}

uint8_t Lexer::binaryByte(const char* what) {
  int c = peek();
  if (c < 0) fail(cat("binary data truncated in ", what), true);
  ++pos_;
  return uint8_t(c);
}

uint64_t Lexer::binaryUInt(int bytes, const char* what) {
  uint64_t v = 0;
  for (int i = 0; i < bytes; ++i) v = (v << 8) | binaryByte(what);
  return v;
}

void Lexer::binaryBytes(size_t n, std::string& out, const char* what) {
  out.clear();
  while (n > 0) {
    if (pos_ == end_ && !more()) fail(cat("binary data truncated in ", what), true);
    size_t take = std::min(n, end_ - pos_);
    out.append(buf_.data() + pos_, take);
    pos_ += take;
    n -= take;
  }
}

// A definition's name is read here, never through next(): next() would take a further
// definition as part of this one and recurse once per 0xCC/0xCD byte (a file of them overflowed
// the stack). Only a string token is accepted; anything else is the error it is.
bool Lexer::stringToken(const char* what) {
  skipSpace();
  const int c = peek();
  if (c == '"') {
    ++pos_;
    asciiString();
    return true;
  }
  const bool binaryString = (c >= 0x90 && c <= 0xa3) || c == 0xcf || c == 0xd0;
  if (!binaryString) fail(cat(what, " must be followed by a string"), true);
  ++pos_;
  TokenType t;
  binaryToken(uint8_t(c), t);
  return true;
}

TokenType Lexer::next() {
  int c;
  for (;;) {
    skipSpace();
    tokenLine_ = line_;
    tokenOffset_ = base_ + pos_;
    tokenBinary_ = false;
    c = peek();
    if (c < 0) return TokenType::End;
    if (c < 0x80) break;
    tokenBinary_ = true;
    ++pos_;
    TokenType t;
    // Definitions (0xCC, 0xCD) produce no token: loop rather than recurse, so that a long run of
    // them cannot exhaust the stack.
    if (binaryToken(uint8_t(c), t)) return t;
  }
  if (c == '"') {
    ++pos_;
    return asciiString();
  }
  if (c == '[') {
    ++pos_;
    return TokenType::ArrayOpen;
  }
  if (c == ']') {
    ++pos_;
    return TokenType::ArrayClose;
  }
  if ((c >= '0' && c <= '9') || c == '-' || c == '+' || c == '.') return asciiNumber();
  if (isNameStart(uint8_t(c))) {
    size_t n = span(isNameChar);
    if (n > 256) fail("request name longer than 256 characters", false);
    text_.assign(buf_.data() + pos_, n);
    pos_ += n;
    return TokenType::Name;
  }
  if (c >= 0x20 && c < 0x7f) fail(cat("unexpected character '", char(c), "'"), false);
  fail(cat("unexpected byte 0x", "0123456789abcdef"[c >> 4], "0123456789abcdef"[c & 15]), false);
}

TokenType Lexer::asciiNumber() {
  size_t n = span(isNumberChar);
  const char* s = buf_.data() + pos_;
  const char* e = s + n;
  bool integer = n > 0 && n <= 16;
  for (size_t i = (s[0] == '-' || s[0] == '+') ? 1 : 0; i < n && integer; ++i) integer = s[i] >= '0' && s[i] <= '9';
  if (integer && n == 1 && (s[0] == '-' || s[0] == '+')) integer = false;
  if (integer) {
    bool neg = s[0] == '-';
    int64_t v = 0;
    for (const char* p = s + ((s[0] == '-' || s[0] == '+') ? 1 : 0); p < e; ++p) v = v * 10 + (*p - '0');
    number_ = neg && v == 0 ? -0.0 : double(neg ? -v : v);  // "-0" keeps its sign, as a float would
  } else {
    const char* b = s[0] == '+' ? s + 1 : s;
    double d = 0;
    auto r = std::from_chars(b, e, d, std::chars_format::general);
    if (r.ec == std::errc::result_out_of_range) {
      // Overflow and underflow are RtFloat's to report: let the float conversion saturate.
      d = std::strtod(std::string(b, e).c_str(), nullptr);
    } else if (r.ec != std::errc() || r.ptr != e) {
      fail(cat("malformed number '", std::string(s, std::min<size_t>(n, 40)), "'"), false);
    }
    number_ = asRtFloat(d);
  }
  pos_ += n;
  return TokenType::Number;
}

TokenType Lexer::asciiString() {
  text_.clear();
  const uint64_t startLine = line_;
  for (;;) {
    if (pos_ == end_ && !more()) {
      line_ = startLine;
      fail("unterminated string", false);
    }
    // Copy the run up to the next quote or backslash in one go.
    size_t i = pos_;
    while (i < end_ && buf_[i] != '"' && buf_[i] != '\\') {
      if (buf_[i] == '\n') ++line_;
      ++i;
    }
    text_.append(buf_.data() + pos_, i - pos_);
    pos_ = i;
    if (pos_ == end_) continue;
    if (buf_[pos_] == '"') {
      ++pos_;
      if (text_.size() > (size_t(1) << 30)) fail("string longer than 1 GB", false);
      return TokenType::String;
    }
    ++pos_;  // backslash
    int c = peek();
    if (c < 0) continue;
    ++pos_;
    switch (c) {
      case 'n': text_ += '\n'; break;
      case 'r': text_ += '\r'; break;
      case 't': text_ += '\t'; break;
      case 'b': text_ += '\b'; break;
      case 'f': text_ += '\f'; break;
      case '\n': ++line_; break;  // line continuation
      case '\r':
        if (peek() == '\n') ++pos_, ++line_;
        break;
      default:
        if (c >= '0' && c <= '7') {
          int v = c - '0';
          for (int k = 0; k < 2; ++k) {
            int d = peek();
            if (d < '0' || d > '7') break;
            v = v * 8 + (d - '0');
            ++pos_;
          }
          text_ += char(v & 0xff);
        } else {
          text_ += char(c);  // \\ \" and any other escaped character stand for themselves
        }
    }
  }
}

bool Lexer::binaryToken(uint8_t code, TokenType& out) {
  if (code <= 0x8f) {
    const int w = code & 3, d = (code >> 2) & 3;
    uint64_t raw = binaryUInt(w + 1, "a binary number");
    const int bits = 8 * (w + 1);
    int64_t v = int64_t(raw);
    if (raw & (uint64_t(1) << (bits - 1))) v -= int64_t(uint64_t(1) << bits);  // two's complement
    number_ = d == 0 ? double(v) : asRtFloat(std::ldexp(double(v), -8 * d));
    return out = TokenType::Number, true;
  }
  if (code <= 0x9f) {
    binaryBytes(code - 0x90, text_, "a binary string");
    return out = TokenType::String, true;
  }
  if (code <= 0xa3) {
    uint64_t len = binaryUInt(code - 0xa0 + 1, "a binary string length");
    if (len > (uint64_t(1) << 30)) fail(cat("binary string of ", len, " bytes"), true);
    binaryBytes(size_t(len), text_, "a binary string");
    return out = TokenType::String, true;
  }
  if (code == 0xa4) {
    uint32_t u = uint32_t(binaryUInt(4, "a binary float32"));
    number_ = asRtFloat(double(std::bit_cast<float>(u)));
    return out = TokenType::Number, true;
  }
  if (code == 0xa5) {
    uint64_t u = binaryUInt(8, "a binary float64");
    number_ = asRtFloat(std::bit_cast<double>(u));
    return out = TokenType::Number, true;
  }
  if (code == 0xa6) {
    uint8_t id = binaryByte("a binary request call");
    if (!requestDefined_[id]) fail(cat("binary request code ", int(id), " used before it was defined (0xCC)"), true);
    text_ = requestCodes_[id];
    return out = TokenType::Name, true;
  }
  if (code >= 0xc8 && code <= 0xcb) {
    uint64_t count = binaryUInt(code - 0xc8 + 1, "a binary float array length");
    if (!arrayTarget_) fail("binary float array where no value is allowed", true);
    if (count > (uint64_t(1) << 28)) fail(cat("binary float array of ", count, " elements"), true);
    arrayTarget_->reserve(arrayTarget_->size() + size_t(count));
    for (uint64_t i = 0; i < count; ++i) {
      uint32_t u = uint32_t(binaryUInt(4, "a binary float array"));
      arrayTarget_->push_back(asRtFloat(double(std::bit_cast<float>(u))));
    }
    return out = TokenType::NumberArray, true;
  }
  if (code == 0xcc) {
    uint8_t id = binaryByte("a binary request definition");
    stringToken("a binary request definition (0xCC)");
    bool ok = !text_.empty() && isNameStart(uint8_t(text_[0]));
    for (char ch : text_) ok = ok && isNameChar(uint8_t(ch));
    if (!ok) fail(cat("binary request definition names '", text_.substr(0, 40), "', not a request"), true);
    requestCodes_[id] = text_;
    requestDefined_[id] = true;
    return false;
  }
  if (code == 0xcd || code == 0xce) {
    uint32_t id = uint32_t(binaryUInt(code - 0xcd + 1, "a binary string definition"));
    stringToken("a binary string definition (0xCD)");
    if (strings_.size() >= 65536 && !strings_.count(id)) fail("more than 65536 defined strings", true);
    strings_[id] = text_;
    return false;
  }
  if (code == 0xcf || code == 0xd0) {
    uint32_t id = uint32_t(binaryUInt(code - 0xcf + 1, "a binary string reference"));
    auto it = strings_.find(id);
    if (it == strings_.end()) fail(cat("binary string token ", id, " used before it was defined (0xCD)"), true);
    text_ = it->second;
    return out = TokenType::String, true;
  }
  --pos_;
  fail(cat("bad binary code 0x", "0123456789abcdef"[code >> 4], "0123456789abcdef"[code & 15],
           code == 0xff ? " (end of RunProgram block outside one)" : " (reserved)"),
       true);
}

}  // namespace reshutter::rib
