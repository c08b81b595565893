// RIB tokenizer: turns a byte stream (a file read through zlib, so gzip is detected by content,
// or bytes in memory) into tokens, ASCII and binary encoding (RISpec 3.2 appendix C) mixed.
// Reads in fixed-size chunks: memory depends on the longest token, never on the file size.
#pragma once

#include <cstdint>
#include <memory>
#include <string>
#include <string_view>
#include <unordered_map>
#include <vector>

namespace reshutter::rib {

/// A source of decompressed bytes.
class ByteSource {
 public:
  virtual ~ByteSource() = default;
  /// Reads up to n bytes; 0 only at the end. Throws Error on I/O or decompression failure.
  virtual size_t read(char* dst, size_t n) = 0;
};

/// Opens a file; gzip or plain is decided by its first bytes (zlib's transparent mode).
std::unique_ptr<ByteSource> openFileSource(const std::string& path);
/// Bytes held by the caller (not copied); gzip when they start with the gzip magic.
std::unique_ptr<ByteSource> memorySource(std::string_view bytes, const std::string& name);

enum class TokenType : uint8_t { End, Name, Number, String, ArrayOpen, ArrayClose, NumberArray };

class Lexer {
 public:
  Lexer(std::unique_ptr<ByteSource> source, std::string name);

  /// Reads the next token. Name/String text goes to text(), a binary float array to
  /// numbers() (appended), a number to number().
  TokenType next();
  double number() const { return number_; }
  const std::string& text() const { return text_; }
  /// Binary float arrays are appended here; the caller owns clearing it.
  void setArrayTarget(std::vector<double>* target) { arrayTarget_ = target; }

  /// Where the last token started.
  uint64_t tokenLine() const { return tokenLine_; }
  uint64_t tokenOffset() const { return tokenOffset_; }
  bool tokenBinary() const { return tokenBinary_; }
  uint64_t bytesConsumed() const { return base_ + pos_; }
  const std::string& name() const { return name_; }

  /// Context for messages: the request being read (set by the parser).
  void setRequestName(std::string_view r) { request_ = r; }
  [[noreturn]] void fail(const std::string& problem, bool binary) const;

 private:
  bool more();  // compacts and reads; false at the end of input
  int peek() {
    if (pos_ == end_ && !more()) return -1;
    return static_cast<unsigned char>(buf_[pos_]);
  }
  uint8_t binaryByte(const char* what);
  uint64_t binaryUInt(int bytes, const char* what);
  void binaryBytes(size_t n, std::string& out, const char* what);
  template <class Pred>
  size_t span(Pred pred);  // length of the run of pred-bytes at pos_, made contiguous in buf_
  void skipSpace();
  TokenType asciiString();
  TokenType asciiNumber();
  bool binaryToken(uint8_t code, TokenType& out);  // false: a definition, no token
  bool stringToken(const char* what);              // the next token must be a string (for 0xCC/0xCD)

  std::unique_ptr<ByteSource> source_;
  std::string name_;
  std::vector<char> buf_;
  size_t pos_ = 0, end_ = 0;
  uint64_t base_ = 0;  // stream offset of buf_[0]
  bool eof_ = false;
  uint64_t line_ = 1;
  uint64_t tokenLine_ = 1, tokenOffset_ = 0;
  bool tokenBinary_ = false;
  double number_ = 0;
  std::string text_;
  std::vector<double>* arrayTarget_ = nullptr;
  std::string request_;
  std::string requestCodes_[256];
  std::vector<bool> requestDefined_ = std::vector<bool>(256, false);
  std::unordered_map<uint32_t, std::string> strings_;
};

}  // namespace reshutter::rib
