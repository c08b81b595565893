// Little-endian binary serialisation with bounds checks. ByteReader never reads past its span:
// an overrun throws Error naming the context given at construction (e.g. "frame.mps: index").
#pragma once

#include <bit>
#include <cstdint>
#include <cstring>
#include <span>
#include <string>
#include <type_traits>
#include <vector>

#include "common/error.h"

namespace reshutter {

static_assert(std::endian::native == std::endian::little, "reshutter's file formats assume a little-endian host");

class ByteWriter {
 public:
  template <typename T>
  requires std::is_trivially_copyable_v<T>
  void put(const T& v) {
    const auto* p = reinterpret_cast<const uint8_t*>(&v);
    bytes_.insert(bytes_.end(), p, p + sizeof(T));
  }
  void putBytes(const void* data, size_t n) {
    const auto* p = static_cast<const uint8_t*>(data);
    bytes_.insert(bytes_.end(), p, p + n);
  }
  void putString(const std::string& s) {
    put<uint32_t>(uint32_t(s.size()));
    putBytes(s.data(), s.size());
  }
  std::vector<uint8_t>& bytes() { return bytes_; }
  size_t size() const { return bytes_.size(); }

 private:
  std::vector<uint8_t> bytes_;
};

class ByteReader {
 public:
  ByteReader(std::span<const uint8_t> data, std::string context) : data_(data), context_(std::move(context)) {}

  template <typename T>
  requires std::is_trivially_copyable_v<T> T get() {
    need(sizeof(T));
    T v;
    std::memcpy(&v, data_.data() + pos_, sizeof(T));
    pos_ += sizeof(T);
    return v;
  }
  void getBytes(void* out, size_t n) {
    need(n);
    std::memcpy(out, data_.data() + pos_, n);
    pos_ += n;
  }
  std::span<const uint8_t> take(size_t n) {
    need(n);
    auto s = data_.subspan(pos_, n);
    pos_ += n;
    return s;
  }
  std::string getString(size_t maxLength = 1u << 20) {
    auto n = get<uint32_t>();
    if (n > maxLength) fail(context_, "string length ", n, " exceeds ", maxLength);
    need(n);
    std::string s(reinterpret_cast<const char*>(data_.data() + pos_), n);
    pos_ += n;
    return s;
  }
  /// Reads a count that is about to size an allocation of `elementSize` bytes each; rejects counts
  /// the remaining bytes cannot possibly hold, so a corrupt count never triggers a huge allocation.
  uint32_t getCount(size_t elementSize) {
    auto n = get<uint32_t>();
    if (elementSize && n > remaining() / elementSize) fail(context_, "count ", n, " exceeds the data present");
    return n;
  }
  size_t position() const { return pos_; }
  size_t remaining() const { return data_.size() - pos_; }
  bool atEnd() const { return pos_ == data_.size(); }
  const std::string& context() const { return context_; }

 private:
  void need(size_t n) const {
    if (n > data_.size() - pos_) fail(context_, "truncated (needs ", n, " bytes at offset ", pos_, ", ", data_.size() - pos_, " left)");
  }
  std::span<const uint8_t> data_;
  size_t pos_ = 0;
  std::string context_;
};

}  // namespace reshutter
