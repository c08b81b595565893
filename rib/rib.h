// RIB reader: streams RenderMan Interface Bytestream files (ASCII, binary encoding per the RISpec
// 3.2 appendix C, mixed; gzip-compressed, detected by content) into requests, one at a time, with
// memory independent of file size. The reader resolves `ReadArchive` (paths relative to the
// including file) and `version`, tracks `Declare`d and inline parameter declarations (a Declare
// is applied, then shown to the handler, whose answer is ignored), reads `Procedural
// "DelayedReadArchive"` archives in place (inside an AttributeBegin/End it hands the handler; other
// procedurals are the handler's to refuse: no program is ever run), evaluates conditional RIB
// (IfBegin/ElseIf/Else/IfEnd on Option "user" values: rib/conditional.h; a branch not taken is
// never handed on), keeps inline archives (ArchiveBegin "name" … ArchiveEnd: the requests are held,
// not handed on, and a later ReadArchive "name" replays them where it stands) and hands every
// other request to a RequestHandler. Requests a handler does not take are warned about once per kind and
// skipped. Errors are reshutter::Error naming file:line (or file:byte N inside binary data) and
// the request.
#pragma once

#include <array>
#include <cstdint>
#include <memory>
#include <string>
#include <string_view>
#include <vector>

namespace reshutter::rib {

/// Where a request starts: file, 1-based line, byte offset (in the decompressed stream).
struct Location {
  std::string file;
  uint64_t line = 1;
  uint64_t byteOffset = 0;
  bool binary = false;      // the request was encoded in binary: messages use the byte offset
  std::string str() const;  // "scene.rib:42" or "scene.rib: byte 1234"
};

/// One value of a request. RIB numbers are RtFloat; integer tokens are kept exactly (up to 2^53)
/// and decimal tokens are rounded once, to float, then widened - so `float(number)` is exactly
/// the float a C parser would produce and vertex indices survive beyond 2^24.
struct Value {
  enum class Kind : uint8_t { Number, String, NumberArray, StringArray };
  Kind kind = Kind::Number;
  double number = 0;
  std::string string;
  std::vector<double> numbers;
  std::vector<std::string> strings;

  bool isNumber() const { return kind == Kind::Number; }
  bool isString() const { return kind == Kind::String; }
  bool isArray() const { return kind == Kind::NumberArray || kind == Kind::StringArray; }
  /// Number count for a number or number array (1 for a single number), string count likewise.
  size_t size() const;
};

/// Storage class and type of a parameter, from `Declare` or an inline declaration
/// ("varying color Cs", "uniform float[2] x", "vertex point P").
enum class StorageClass : uint8_t { Constant, Uniform, Varying, Vertex, FaceVarying, FaceVertex };
enum class ParamType : uint8_t { Float, Integer, Point, Vector, Normal, Color, String, HPoint, Matrix, Bool };
struct ParamDecl {
  std::string name;  // bare name: "Cs"
  StorageClass storage = StorageClass::Uniform;
  ParamType type = ParamType::Float;
  int arraySize = 1;  // [n] in the declaration
  /// "reference color diffuseColor": a RIS connection, its value strings naming "handle:output"
  /// of another node instead of numbers.
  bool reference = false;
  /// Numbers per element: 1 float/integer, 3 point/vector/normal/color, 4 hpoint, 16 matrix.
  int components() const;
};

/// A parameter-list entry after declaration lookup.
struct Param {
  ParamDecl decl;
  const Value* value = nullptr;
};

struct Request {
  std::string_view name;
  std::vector<Value> values;  // everything after the request name, in order
  Location where;
};

/// Per-request argument access with errors that name the request and its location.
class Args {
 public:
  Args(const Request& r, const class Reader& reader);
  size_t count() const;
  double number(size_t i) const;  // a number, or a one-element number array
  const std::string& string(size_t i) const;
  const std::vector<double>& numbers(size_t i) const;  // a number array (a single number is not one)
  /// The parameter list starting at value `first`: name/value pairs, names resolved through
  /// Declare and inline declarations; an undeclared name or a declaration this reader does not
  /// understand is skipped with one warning per (request, name). Values that do not match their
  /// declaration are an error naming the parameter.
  std::vector<Param> params(size_t first) const;
  [[noreturn]] void fail(const std::string& problem) const;  // "file:line (Request): problem"

 private:
  const Request& r_;
  const class Reader& reader_;
};

class RequestHandler {
 public:
  virtual ~RequestHandler() = default;
  /// Returns false for requests this handler does not take: the reader warns once per kind.
  virtual bool handle(const Request& request, const Args& args) = 0;
  /// A delayed archive's bound (xmin xmax ymin ymax zmin zmax in the current object space):
  /// true when nothing inside it can be seen, and the reader then does not read the archive.
  virtual bool cullsBound(const std::array<double, 6>& /*bound*/) { return false; }
};

struct ReaderOptions {
  bool warnUnsupported = true;
  int maxArchiveDepth = 32;                    // files read by ReadArchive, nested (0: none is opened)
  int maxInlineDepth = 32;                     // inline archives replayed inside one another (a cycle stops here)
  size_t maxInlineRequests = size_t(1) << 22;  // requests all inline archives may hold together
};

class Reader {
 public:
  explicit Reader(ReaderOptions options = {});
  ~Reader();
  /// Parses `path` (and the archives it reads) to the end, calling `handler` per request.
  void parseFile(const std::string& path, RequestHandler& handler);
  /// Parses bytes held in memory (tests, fuzzing); `name` appears in messages.
  void parseBuffer(std::string_view bytes, const std::string& name, RequestHandler& handler);
  /// Looks up a parameter name: inline declaration or `Declare`d or predeclared standard name.
  bool lookup(std::string_view token, ParamDecl& out) const;
  /// Declares `name` as `Declare` would ("varying point"); throws Error on a malformed class/type.
  /// Ingest uses it for names a dump writer uses without declaring (blurP).
  void declare(const std::string& name, const std::string& declaration);
  /// Bytes read so far (decompressed), for progress and throughput.
  uint64_t bytesRead() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace reshutter::rib
