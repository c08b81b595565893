// RIB reader: groups tokens into requests, resolves parameter declarations (standard names,
// Declare, inline), follows ReadArchive, and dispatches to the RequestHandler.
#include "rib/rib.h"

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <map>
#include <optional>
#include <unordered_map>

#include "common/error.h"
#include "common/log.h"
#include "rib/conditional.h"
#include "rib/lexer.h"

namespace reshutter::rib {

std::string Location::str() const { return binary ? cat(file, ": byte ", byteOffset) : cat(file, ":", line); }

size_t Value::size() const {
  switch (kind) {
    case Kind::Number:
    case Kind::String: return 1;
    case Kind::NumberArray: return numbers.size();
    case Kind::StringArray: return strings.size();
  }
  return 0;
}

int ParamDecl::components() const {
  switch (type) {
    case ParamType::Point:
    case ParamType::Vector:
    case ParamType::Normal:
    case ParamType::Color: return 3;
    case ParamType::HPoint: return 4;
    case ParamType::Matrix: return 16;
    default: return 1;
  }
}

namespace {

std::vector<std::string_view> words(std::string_view s) {
  std::vector<std::string_view> out;
  size_t i = 0;
  while (i < s.size()) {
    while (i < s.size() && (s[i] == ' ' || s[i] == '\t' || s[i] == '\n')) ++i;
    size_t j = i;
    while (j < s.size() && s[j] != ' ' && s[j] != '\t' && s[j] != '\n') ++j;
    if (j > i) out.push_back(s.substr(i, j - i));
    i = j;
  }
  return out;
}

/// Parses "[class] type[[n]] [name]" (Declare's second argument, or an inline declaration when
/// withName). Returns an empty string on success, else the problem.
std::string parseDeclaration(std::string_view text, bool withName, ParamDecl& out) {
  auto w = words(text);
  // "float [2]": join a separate array suffix onto its type.
  for (size_t i = 1; i < w.size(); ++i)
    if (w[i].front() == '[' && w[i - 1].back() != ']') {
      // Both views point into `text`; merge them into one span.
      const char* b = w[i - 1].data();
      w[i - 1] = std::string_view(b, size_t(w[i].data() + w[i].size() - b));
      w.erase(w.begin() + long(i));
      break;
    }
  size_t k = 0;
  ParamDecl d;
  static const std::pair<const char*, StorageClass> classes[] = {{"constant", StorageClass::Constant},       {"uniform", StorageClass::Uniform},
                                                                 {"varying", StorageClass::Varying},         {"vertex", StorageClass::Vertex},
                                                                 {"facevarying", StorageClass::FaceVarying}, {"facevertex", StorageClass::FaceVertex}};
  if (k < w.size())
    for (auto& [n, c] : classes)
      if (w[k] == n) {
        d.storage = c;
        ++k;
        break;
      }
  if (k < w.size() && w[k] == "reference") d.reference = true, ++k;
  if (k >= w.size()) return "no type";
  std::string_view type = w[k++];
  size_t br = type.find('[');
  if (br != std::string_view::npos) {
    std::string_view num = type.substr(br + 1);
    if (num.empty() || num.back() != ']') return cat("malformed array size in '", type, "'");
    num.remove_suffix(1);
    while (!num.empty() && num.front() == ' ') num.remove_prefix(1);
    while (!num.empty() && num.back() == ' ') num.remove_suffix(1);
    int n = 0;
    for (char c : num) {
      if (c < '0' || c > '9' || n > 1000000) return cat("malformed array size in '", type, "'");
      n = n * 10 + (c - '0');
    }
    if (num.empty() || n < 1) return cat("malformed array size in '", type, "'");
    d.arraySize = n;
    type = type.substr(0, br);
    while (!type.empty() && type.back() == ' ') type.remove_suffix(1);
  }
  static const std::pair<const char*, ParamType> types[] = {{"float", ParamType::Float},   {"integer", ParamType::Integer}, {"int", ParamType::Integer},
                                                            {"point", ParamType::Point},   {"vector", ParamType::Vector},   {"normal", ParamType::Normal},
                                                            {"color", ParamType::Color},   {"string", ParamType::String},   {"hpoint", ParamType::HPoint},
                                                            {"matrix", ParamType::Matrix}, {"bool", ParamType::Bool}};
  bool found = false;
  for (auto& [n, t] : types)
    if (type == n) d.type = t, found = true;
  if (!found) return cat("unknown type '", type, "'");
  if (withName) {
    if (k + 1 != w.size()) return k >= w.size() ? "no name" : "more than one name";
    d.name = std::string(w[k]);
  } else if (k != w.size()) {
    return cat("unexpected '", w[k], "'");
  }
  out = std::move(d);
  return {};
}

using DeclMap = std::unordered_map<std::string, ParamDecl>;

DeclMap standardDeclarations() {
  // RISpec 3.2 standard variables and the standard shaders', lights', options' and attributes'
  // parameters, so that real files parse without their own Declare lines.
  static const char* table[][2] = {
      {"P", "vertex point"},
      {"Pw", "vertex hpoint"},
      {"Pz", "vertex float"},
      {"N", "varying normal"},
      {"Np", "uniform normal"},
      {"Cs", "varying color"},
      {"Os", "varying color"},
      {"s", "varying float"},
      {"t", "varying float"},
      {"st", "varying float[2]"},
      {"width", "varying float"},
      {"constantwidth", "constant float"},
      // Shaders and lights.
      {"Ka", "uniform float"},
      {"Kd", "uniform float"},
      {"Ks", "uniform float"},
      {"Kr", "uniform float"},
      {"roughness", "uniform float"},
      {"specularcolor", "uniform color"},
      {"intensity", "uniform float"},
      {"lightcolor", "uniform color"},
      {"from", "uniform point"},
      {"to", "uniform point"},
      {"coneangle", "uniform float"},
      {"conedeltaangle", "uniform float"},
      {"beamdistribution", "uniform float"},
      {"amplitude", "uniform float"},
      {"texturename", "uniform string"},
      {"mindistance", "uniform float"},
      {"maxdistance", "uniform float"},
      {"background", "uniform color"},
      {"distance", "uniform float"},
      {"shadowname", "uniform string"},
      {"__category", "uniform string"},
      {"__nondiffuse", "uniform float"},
      {"__nonspecular", "uniform float"},
      // Cameras, displays, options and attributes.
      {"fov", "uniform float"},
      {"origin", "uniform integer[2]"},
      {"compression", "uniform string"},
      {"quality", "uniform integer"},
      {"bucketsize", "uniform integer[2]"},
      {"gridsize", "uniform integer"},
      {"texturememory", "uniform integer"},
      {"eyesplits", "uniform integer"},
      {"shader", "uniform string"},
      {"texture", "uniform string"},
      {"archive", "uniform string"},
      {"procedural", "uniform string"},
      {"display", "uniform string"},
      {"resource", "uniform string"},
      {"endofframe", "uniform integer"},
      {"filename", "uniform string"},
      {"sphere", "uniform float"},
      {"coordinatesystem", "uniform string"},
      {"name", "uniform string"},
      {"sense", "uniform string"},  // Attribute "trimcurve"
      {"shadows", "uniform string"},
      {"jitter", "uniform integer"},
      {"subpixel", "uniform integer"},
      {"depthfilter", "uniform string"},
      {"motionfactor", "uniform float"},
      {"focusfactor", "uniform float"},
      {"binary", "uniform integer"},
      {"clampmotion", "uniform integer"},
      {"offset", "uniform float"},
      {"sides", "uniform integer"},
      {"quantize", "uniform float[4]"},
      {"dither", "uniform float"},
      {"exposure", "uniform float[2]"},
      {"zthreshold", "uniform color"},
      {"extremedisplacement", "uniform integer"},
      {"emit", "uniform integer"},
      {"interpolateboundary", "uniform integer"},
      {"trace", "uniform integer"},
      {"transmission", "uniform string"},
      {"camera", "uniform integer"},
      {"diffuse", "uniform integer"},
      {"specular", "uniform integer"},
      {"photon", "uniform integer"},
      {"cull", "uniform integer"},
      {"backfacing", "uniform integer"},
      {"hidden", "uniform integer"},
  };
  DeclMap m;
  for (auto& e : table) {
    ParamDecl d;
    std::string problem = parseDeclaration(e[1], false, d);
    (void)problem;
    d.name = e[0];
    m.emplace(e[0], d);
  }
  return m;
}

const DeclMap& standardTable() {
  static const DeclMap m = standardDeclarations();
  return m;
}

bool hasSpace(std::string_view s) { return s.find_first_of(" \t\n") != std::string_view::npos; }

}  // namespace

// ---------------------------------------------------------------------------------------------
// Args

Args::Args(const Request& r, const Reader& reader) : r_(r), reader_(reader) {}

size_t Args::count() const { return r_.values.size(); }

void Args::fail(const std::string& problem) const { throw Error(cat(r_.where.str(), " (", r_.name, ")"), problem); }

double Args::number(size_t i) const {
  if (i >= r_.values.size()) fail(cat("expects at least ", i + 1, " arguments, has ", r_.values.size()));
  const Value& v = r_.values[i];
  if (v.kind == Value::Kind::Number) return v.number;
  if (v.kind == Value::Kind::NumberArray && v.numbers.size() == 1) return v.numbers[0];
  fail(cat("argument ", i + 1, " must be a number"));
}

const std::string& Args::string(size_t i) const {
  if (i >= r_.values.size()) fail(cat("expects at least ", i + 1, " arguments, has ", r_.values.size()));
  const Value& v = r_.values[i];
  if (v.kind == Value::Kind::String) return v.string;
  if (v.kind == Value::Kind::StringArray && v.strings.size() == 1) return v.strings[0];
  fail(cat("argument ", i + 1, " must be a string"));
}

const std::vector<double>& Args::numbers(size_t i) const {
  if (i >= r_.values.size()) fail(cat("expects at least ", i + 1, " arguments, has ", r_.values.size()));
  const Value& v = r_.values[i];
  if (v.kind == Value::Kind::NumberArray) return v.numbers;
  // `[]` is read as an empty number array; any other string array is not numbers.
  fail(cat("argument ", i + 1, " must be an array of numbers"));
}

std::vector<Param> Args::params(size_t first) const {
  std::vector<Param> out;
  const size_t n = r_.values.size();
  for (size_t j = first; j < n; j += 2) {
    const Value& nameValue = r_.values[j];
    if (nameValue.kind != Value::Kind::String) fail(cat("argument ", j + 1, " must be a parameter name (a string)"));
    const std::string& token = nameValue.string;
    if (j + 1 >= n) fail(cat("parameter '", token, "' has no value"));
    Param p;
    if (!reader_.lookup(token, p.decl)) {
      // Exporters write parameters a reader cannot know (a shader's own, another renderer's
      // attributes): the scene goes on without them, with one warning per (request, name).
      const std::string_view bare = hasSpace(token) ? std::string_view(token).substr(token.find_last_of(" \t\n") + 1) : std::string_view(token);
      warnOnce(cat("rib-param:", r_.name, ":", bare),
               cat(r_.where.str(), " (", r_.name, "): parameter '", token, "' ",
                   hasSpace(token) ? "has a declaration this reader does not understand" : "is not declared (Declare or an inline declaration names its type)",
                   "; skipped"));
      continue;
    }
    p.value = &r_.values[j + 1];
    const bool isString = p.decl.type == ParamType::String || p.decl.reference;
    const Value::Kind k = p.value->kind;
    const bool empty = k == Value::Kind::NumberArray && p.value->numbers.empty();
    if (isString && !(k == Value::Kind::String || k == Value::Kind::StringArray || empty)) fail(cat("parameter '", p.decl.name, "' must be given strings"));
    if (!isString && !(k == Value::Kind::Number || k == Value::Kind::NumberArray)) fail(cat("parameter '", p.decl.name, "' must be given numbers"));
    const size_t per = size_t(p.decl.components()) * size_t(p.decl.arraySize);
    if (!isString && p.value->size() % per != 0) fail(cat("parameter '", p.decl.name, "' has ", p.value->size(), " numbers, not a multiple of ", per));
    if (isString && p.value->size() % size_t(p.decl.arraySize) != 0)
      fail(cat("parameter '", p.decl.name, "' has ", p.value->size(), " strings, not a multiple of ", p.decl.arraySize));
    out.push_back(std::move(p));
  }
  return out;
}

// ---------------------------------------------------------------------------------------------
// Reader

struct Reader::Impl {
  ReaderOptions options;
  DeclMap declared;
  uint64_t bytesDone = 0;                  // finished lexers
  std::vector<const Lexer*> active;        // open lexers (ReadArchive nests)
  std::vector<std::vector<double>> spare;  // recycled array storage

  Conditionals conditions;

  // Inline archives: each request held with its own copy of the name (a Request's name views
  // the lexer's buffer).
  struct HeldRequest {
    std::string name;
    Request request;
  };
  std::map<std::string, std::vector<HeldRequest>, std::less<>> inlineArchives;
  std::string recording;  // the inline archive being defined; empty: none
  Location recordingFrom;
  size_t heldRequests = 0;
  int inlineDepth = 0;

  void parse(Lexer& lx, RequestHandler& handler, Reader& self, int depth);
  /// IfBegin/ElseIf/Else/IfEnd; false for any other request.
  bool conditional(const Request& req, const Args& args);
  void recordUserOptions(const Args& args);
  /// The archive a Procedural "DelayedReadArchive" (or Procedural2 "DelayedReadArchive2") names,
  /// and its bound where it gives six finite numbers; empty for any other request.
  std::string delayedArchive(const Request& req, const Args& args, std::optional<std::array<double, 6>>& bound);
  void checkClosed(const std::string& file) const {
    if (conditions.open()) fail(file, "ends inside an IfBegin block (IfEnd missing)");
    if (!recording.empty()) fail(recordingFrom.str(), "ArchiveBegin \"", recording, "\" has no ArchiveEnd");
  }
  void dispatch(const Request& req, RequestHandler& handler, Reader& self, const std::string& file, int depth);
};

Reader::Reader(ReaderOptions options) : impl_(std::make_unique<Impl>()) { impl_->options = options; }
Reader::~Reader() = default;

uint64_t Reader::bytesRead() const {
  uint64_t n = impl_->bytesDone;
  for (const Lexer* l : impl_->active) n += l->bytesConsumed();
  return n;
}

bool Reader::lookup(std::string_view token, ParamDecl& out) const {
  if (hasSpace(token)) return parseDeclaration(token, true, out).empty();
  std::string key(token);
  auto it = impl_->declared.find(key);
  if (it != impl_->declared.end()) {
    out = it->second;
    return true;
  }
  const auto& std = standardTable();
  auto jt = std.find(key);
  if (jt == std.end()) return false;
  out = jt->second;
  return true;
}

void Reader::declare(const std::string& name, const std::string& declaration) {
  ParamDecl d;
  std::string problem = parseDeclaration(declaration, false, d);
  if (!problem.empty()) fail(cat("declaration of '", name, "'"), "malformed declaration '", declaration, "': ", problem);
  d.name = name;
  impl_->declared[name] = d;
}

void Reader::parseFile(const std::string& path, RequestHandler& handler) {
  Lexer lx(openFileSource(path), path);
  impl_->parse(lx, handler, *this, 0);
  impl_->checkClosed(path);
}

void Reader::parseBuffer(std::string_view bytes, const std::string& name, RequestHandler& handler) {
  Lexer lx(memorySource(bytes, name), name);
  impl_->parse(lx, handler, *this, 0);
  impl_->checkClosed(name);
}

bool Reader::Impl::conditional(const Request& req, const Args& args) {
  const std::string_view n = req.name;
  auto evaluate = [&]() {
    if (args.count() != 1) args.fail(cat("expects one condition string, has ", args.count(), " arguments"));
    try {
      return conditions.evaluate(args.string(0));
    } catch (const std::invalid_argument& e) {
      args.fail(cat("cannot read the condition '", args.string(0), "': ", e.what()));
    }
  };
  if (n == "IfBegin") return conditions.ifBegin(conditions.active() && evaluate()), true;
  if (n == "ElseIf") {
    const bool value = conditions.elseIfWanted() && evaluate();
    if (!conditions.elseIf(value)) args.fail("ElseIf without IfBegin (or after Else)");
    return true;
  }
  if (n == "Else") {
    if (!conditions.elseBranch()) args.fail("Else without IfBegin (or a second Else)");
    return true;
  }
  if (n == "IfEnd") {
    if (!conditions.ifEnd()) args.fail("IfEnd without IfBegin");
    return true;
  }
  return false;
}

std::string Reader::Impl::delayedArchive(const Request& req, const Args& args, std::optional<std::array<double, 6>>& bound) {
  if ((req.name != "Procedural" && req.name != "Procedural2") || req.values.empty() || !req.values[0].isString()) return {};
  auto take = [&](const std::vector<double>& b) {
    if (b.size() == 6 && std::all_of(b.begin(), b.end(), [](double x) { return std::isfinite(x); }))
      bound = std::array<double, 6>{b[0], b[1], b[2], b[3], b[4], b[5]};
  };
  const std::string& kind = req.values[0].string;
  if (req.name == "Procedural" && kind == "DelayedReadArchive") {
    if (req.values.size() < 2 || req.values[1].kind != Value::Kind::StringArray || req.values[1].strings.empty())
      args.fail("DelayedReadArchive expects [\"archive.rib\"] and a bound");
    if (req.values.size() > 2 && req.values[2].kind == Value::Kind::NumberArray) take(req.values[2].numbers);
    return req.values[1].strings[0];
  }
  if (req.name == "Procedural2" && kind == "DelayedReadArchive2") {
    std::string file;
    for (const Param& p : args.params(2)) {
      if (p.decl.name == "filename" && p.value) {
        if (p.value->kind == Value::Kind::String) file = p.value->string;
        if (p.value->kind == Value::Kind::StringArray && !p.value->strings.empty()) file = p.value->strings[0];
      }
      if (p.decl.name == "bound" && p.value && p.value->kind == Value::Kind::NumberArray) take(p.value->numbers);
    }
    if (file.empty()) args.fail("DelayedReadArchive2 has no \"filename\"");
    return file;
  }
  return {};
}

void Reader::Impl::recordUserOptions(const Args& args) {
  for (const Param& p : args.params(1)) {
    const Value& v = *p.value;
    if (v.kind == Value::Kind::String) conditions.setUser(p.decl.name, v.string, false, 0);
    else if (v.kind == Value::Kind::StringArray && !v.strings.empty()) conditions.setUser(p.decl.name, v.strings[0], false, 0);
    else if (v.kind == Value::Kind::Number) conditions.setUser(p.decl.name, cat(v.number), true, v.number);
    else if (v.kind == Value::Kind::NumberArray && !v.numbers.empty()) conditions.setUser(p.decl.name, cat(v.numbers[0]), true, v.numbers[0]);
  }
}

void Reader::Impl::parse(Lexer& lx, RequestHandler& handler, Reader& self, int depth) {
  active.push_back(&lx);
  struct Pop {
    Impl& I;
    Lexer& lx;
    ~Pop() {
      I.bytesDone += lx.bytesConsumed();
      I.active.pop_back();
    }
  } pop{*this, lx};

  Request req;
  std::string name;
  TokenType t = lx.next();
  auto takeArray = [&]() {
    std::vector<double> v;
    if (!spare.empty()) {
      v = std::move(spare.back());
      spare.pop_back();
      v.clear();
    }
    return v;
  };
  while (t != TokenType::End) {
    if (t != TokenType::Name) {
      lx.setRequestName({});
      lx.fail(t == TokenType::ArrayClose ? "']' without '['" : "a value where a request name was expected", lx.tokenBinary());
    }
    name = lx.text();
    lx.setRequestName(name);
    for (Value& v : req.values)
      if (v.numbers.capacity() > 0 && spare.size() < 64) spare.push_back(std::move(v.numbers));
    req.values.clear();
    req.name = name;
    req.where.file = lx.name();
    req.where.line = lx.tokenLine();
    req.where.byteOffset = lx.tokenOffset();
    req.where.binary = lx.tokenBinary();
    // Binary float arrays land in `pending` (the lexer needs the target before it sees one),
    // and so do the numbers of a bracketed array; either way it then moves into the value.
    std::vector<double> pending = takeArray();
    lx.setArrayTarget(&pending);
    for (;;) {
      t = lx.next();
      if (t == TokenType::Number) {
        Value& v = req.values.emplace_back();
        v.number = lx.number();
      } else if (t == TokenType::String) {
        Value& v = req.values.emplace_back();
        v.kind = Value::Kind::String;
        v.string = lx.text();
      } else if (t == TokenType::NumberArray) {
        Value& v = req.values.emplace_back();
        v.kind = Value::Kind::NumberArray;
        v.numbers = std::move(pending);
        pending = takeArray();
        lx.setArrayTarget(&pending);
      } else if (t == TokenType::ArrayOpen) {
        Value& v = req.values.emplace_back();
        v.kind = Value::Kind::NumberArray;
        bool numbers = false, strings = false;
        for (;;) {
          TokenType e = lx.next();
          if (e == TokenType::ArrayClose) break;
          if (e == TokenType::Number) {
            pending.push_back(lx.number());
            numbers = true;
          } else if (e == TokenType::NumberArray) {
            numbers = true;
          } else if (e == TokenType::String) {
            v.strings.push_back(lx.text());
            strings = true;
          } else if (e == TokenType::End) {
            lx.fail("unterminated array (end of file before ']')", false);
          } else if (e == TokenType::ArrayOpen) {
            lx.fail("'[' inside an array", lx.tokenBinary());
          } else {
            lx.fail(cat("unterminated array ('", lx.text(), "' before ']')"), lx.tokenBinary());
          }
          if (numbers && strings) lx.fail("array mixes numbers and strings", lx.tokenBinary());
        }
        if (strings) {
          v.kind = Value::Kind::StringArray;
        } else {
          v.numbers = std::move(pending);
          pending = takeArray();
          lx.setArrayTarget(&pending);
        }
      } else if (t == TokenType::ArrayClose) {
        lx.fail("']' without '['", lx.tokenBinary());
      } else {
        break;  // the next request, or the end
      }
    }
    if (pending.capacity() > 0 && spare.size() < 64) spare.push_back(std::move(pending));
    lx.setArrayTarget(nullptr);
    lx.setRequestName({});
    dispatch(req, handler, self, lx.name(), depth);
  }
}

void Reader::Impl::dispatch(const Request& req, RequestHandler& handler, Reader& self, const std::string& file, int depth) {
  Args args(req, self);
  const std::string_view n = req.name;
  if (!recording.empty()) {
    // Inside ArchiveBegin/ArchiveEnd everything is held as it is (conditionals included: they
    // are evaluated where the archive is read).
    if (n == "ArchiveBegin") args.fail(cat("inside inline archive \"", recording, "\" (ArchiveBegin does not nest)"));
    if (n == "ArchiveEnd") {
      recording.clear();
      return;
    }
    if (++heldRequests > options.maxInlineRequests) args.fail(cat("inline archives hold more than ", options.maxInlineRequests, " requests"));
    auto& held = inlineArchives[recording].emplace_back();
    held.name = std::string(n);
    held.request = req;
    return;
  }
  if (conditional(req, args) || !conditions.active()) return;
  if (n == "ArchiveBegin") {
    const std::string& name = args.string(0);
    if (name.empty()) args.fail("an inline archive needs a name");
    recording = name, recordingFrom = req.where;
    inlineArchives[name].clear();  // a later definition replaces an earlier one
    return;
  }
  if (n == "ArchiveEnd") args.fail("ArchiveEnd without ArchiveBegin");
  if (n == "version") return;
  if (n == "Option" && args.count() >= 1 && req.values[0].isString() && req.values[0].string == "user") recordUserOptions(args);
  if (n == "Declare") {
    if (args.count() != 2) args.fail(cat("expects a name and a declaration, has ", args.count(), " arguments"));
    const std::string& name = args.string(0);
    const std::string& decl = args.string(1);
    ParamDecl d;
    std::string problem = parseDeclaration(decl, false, d);
    if (!problem.empty()) args.fail(cat("malformed declaration '", decl, "': ", problem));
    if (name.empty() || hasSpace(name)) args.fail(cat("bad parameter name '", name, "'"));
    d.name = name;
    declared[name] = d;
    handler.handle(req, args);  // handlers may want to see declarations; none has to
    return;
  }
  auto readArchive = [&](const std::string& rel) {
    if (depth + 1 > options.maxArchiveDepth) args.fail(cat("archives nested deeper than ", options.maxArchiveDepth, " (a cycle?)"));
    std::filesystem::path p(rel);
    if (p.is_relative()) p = std::filesystem::path(file).parent_path() / p;
    std::error_code ec;
    if (!std::filesystem::is_regular_file(p, ec)) args.fail(cat("cannot open archive '", p.string(), "'"));
    Lexer inner(openFileSource(p.string()), p.string());
    parse(inner, handler, self, depth + 1);
  };
  if (n == "ReadArchive") {
    const auto inlined = inlineArchives.find(args.string(0));
    if (inlined == inlineArchives.end()) return readArchive(args.string(0));
    if (inlineDepth + 1 > options.maxInlineDepth) args.fail(cat("inline archives read inside one another deeper than ", options.maxInlineDepth, " (a cycle?)"));
    ++inlineDepth;
    struct Leave {
      int& depth;
      ~Leave() { --depth; }
    } leave{inlineDepth};
    // Replayed from a copy: the archive may be redefined while it is read.
    const std::vector<HeldRequest> held = inlined->second;
    for (const HeldRequest& h : held) {
      Request r = h.request;
      r.name = h.name;
      dispatch(r, handler, self, file, depth);
    }
    return;
  }
  std::optional<std::array<double, 6>> bound;
  if (const std::string archive = delayedArchive(req, args, bound); !archive.empty()) {
    // A delayed archive is read where it stands, inside an attribute block of its own: what it
    // sets does not leak past it, as with the renderer expanding the procedural; an archive
    // whose bound the handler culls is never opened.
    if (bound && handler.cullsBound(*bound)) return;
    auto bracket = [&](const char* name) {
      Request r;
      r.name = name;
      r.where = req.where;
      handler.handle(r, Args(r, self));
    };
    bracket("AttributeBegin");
    readArchive(archive);
    bracket("AttributeEnd");
    return;
  }
  if (!handler.handle(req, args) && options.warnUnsupported) {
    std::string kind = cat("RIB request '", n, "' skipped");
    warnOnce(kind, cat(req.where.str(), ": RIB request '", n, "' is not supported here; skipped"));
  }
}

}  // namespace reshutter::rib
