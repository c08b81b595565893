// RIB reader: real files, every ASCII token kind, binary encoding against ASCII, gzip, archives,
// streaming memory, bad input, and the fuzz corpus as regression cases.
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <map>
#include <random>

#include <zlib.h>

#include <gtest/gtest.h>

#include "common/error.h"
#include "common/log.h"
#include "rib/rib.h"
#include "tests/test_util.h"

using namespace reshutter;
using namespace reshutter::rib;

namespace {

struct Recorded {
  std::string name;
  std::vector<Value> values;
  Location where;
};

/// Records every request; accepts all of them unless `accept` is false.
struct Recorder : RequestHandler {
  std::vector<Recorded> requests;
  bool accept = true;
  bool handle(const Request& r, const Args&) override {
    requests.push_back({std::string(r.name), r.values, r.where});
    return accept;
  }
};

bool sameValue(const Value& a, const Value& b) {
  if (a.kind != b.kind) return false;
  switch (a.kind) {
    case Value::Kind::Number: return std::memcmp(&a.number, &b.number, sizeof(double)) == 0;
    case Value::Kind::String: return a.string == b.string;
    case Value::Kind::NumberArray:
      return a.numbers.size() == b.numbers.size() && (a.numbers.empty() || std::memcmp(a.numbers.data(), b.numbers.data(), a.numbers.size() * 8) == 0);
    case Value::Kind::StringArray: return a.strings == b.strings;
  }
  return false;
}

void expectSameRequests(const std::vector<Recorded>& a, const std::vector<Recorded>& b) {
  ASSERT_EQ(a.size(), b.size());
  for (size_t i = 0; i < a.size(); ++i) {
    EXPECT_EQ(a[i].name, b[i].name) << "request " << i;
    ASSERT_EQ(a[i].values.size(), b[i].values.size()) << a[i].name;
    for (size_t j = 0; j < a[i].values.size(); ++j) EXPECT_TRUE(sameValue(a[i].values[j], b[i].values[j])) << a[i].name << " value " << j;
  }
}

std::vector<Recorded> parse(std::string_view bytes, const std::string& name = "mem.rib") {
  Reader r;
  Recorder rec;
  r.parseBuffer(bytes, name, rec);
  return rec.requests;
}

/// Parses and returns the Error's where and problem; fails the test if nothing is thrown.
std::pair<std::string, std::string> parseError(std::string_view bytes, RequestHandler* handler = nullptr) {
  Reader r;
  Recorder rec;
  try {
    r.parseBuffer(bytes, "bad.rib", handler ? *handler : rec);
  } catch (const Error& e) {
    return {e.where(), e.problem()};
  }
  ADD_FAILURE() << "no error for: " << std::string(bytes.substr(0, 80));
  return {};
}

/// Bad RIB, where its error must point and a part of what it must say.
struct ErrorCase {
  std::string src, where, problemPart;
};
void expectErrors(const std::vector<ErrorCase>& cases) {
  for (const auto& c : cases) {
    auto [where, problem] = parseError(c.src);
    EXPECT_NE(where.find(c.where), std::string::npos) << "where '" << where << "' for " << c.src;
    EXPECT_NE(problem.find(c.problemPart), std::string::npos) << "problem '" << problem << "' for " << c.src;
  }
}

std::string gzipBytes(const std::string& s) {
  uLongf n = compressBound(uLong(s.size())) + 32;
  std::string out(n, '\0');
  z_stream z{};
  deflateInit2(&z, 6, Z_DEFLATED, 16 + MAX_WBITS, 8, Z_DEFAULT_STRATEGY);
  z.next_in = reinterpret_cast<Bytef*>(const_cast<char*>(s.data()));
  z.avail_in = uInt(s.size());
  z.next_out = reinterpret_cast<Bytef*>(out.data());
  z.avail_out = uInt(out.size());
  deflate(&z, Z_FINISH);
  out.resize(z.total_out);
  deflateEnd(&z);
  return out;
}

void writeFile(const std::string& path, const std::string& bytes) { std::ofstream(path, std::ios::binary).write(bytes.data(), std::streamsize(bytes.size())); }

// ---------------------------------------------------------------------------------------------
// A small binary RIB encoder (RISpec 3.2 appendix C), independent of the reader.

struct BinaryWriter {
  std::string out;
  void byte(int b) { out += char(uint8_t(b)); }
  void be(uint64_t v, int bytes) {
    for (int i = bytes - 1; i >= 0; --i) byte(int((v >> (8 * i)) & 0xff));
  }
  /// 0x80 + 4d + w: value * 256^d as a signed (w+1)-byte integer.
  void fixed(double v, int w, int d) {
    int64_t raw = int64_t(std::llround(std::ldexp(v, 8 * d)));
    byte(0x80 + 4 * d + w);
    be(uint64_t(raw), w + 1);
  }
  void f32(float f) {
    byte(0xa4);
    uint32_t u;
    std::memcpy(&u, &f, 4);
    be(u, 4);
  }
  void f64(double d) {
    byte(0xa5);
    uint64_t u;
    std::memcpy(&u, &d, 8);
    be(u, 8);
  }
  void str(const std::string& s) {
    if (s.size() < 16) {
      byte(0x90 + int(s.size()));
    } else {
      int l = s.size() < 256 ? 0 : s.size() < 65536 ? 1 : s.size() < (1u << 24) ? 2 : 3;
      byte(0xa0 + l);
      be(s.size(), l + 1);
    }
    out += s;
  }
  void floatArray(const std::vector<float>& v) {
    int l = v.size() < 256 ? 0 : v.size() < 65536 ? 1 : 2;
    byte(0xc8 + l);
    be(v.size(), l + 1);
    for (float f : v) {
      uint32_t u;
      std::memcpy(&u, &f, 4);
      be(u, 4);
    }
  }
  void defineRequest(int code, const std::string& name) {
    byte(0xcc);
    byte(code);
    str(name);
  }
  void request(int code) {
    byte(0xa6);
    byte(code);
  }
  void defineString(uint32_t id, const std::string& s) {
    int w = id < 256 ? 0 : 1;
    byte(0xcd + w);
    be(id, w + 1);
    str(s);
  }
  void stringRef(uint32_t id) {
    int w = id < 256 ? 0 : 1;
    byte(0xcf + w);
    be(id, w + 1);
  }
  void ascii(const std::string& s) { out += s; }
};

std::string shortestFloat(float f) {
  char buf[64];
  std::snprintf(buf, sizeof buf, "%.9g", double(f));
  return buf;
}

}  // namespace

// ---------------------------------------------------------------------------------------------

TEST(RibReaderTest, EveryRealFileParsesWithAHandlerThatTakesNothing) {
  const std::filesystem::path dir = test::sharedDir() + "/data/rib";
  ASSERT_TRUE(std::filesystem::exists(dir)) << dir;
  int files = 0;
  for (const auto& f : std::filesystem::directory_iterator(dir)) {
    Reader r;
    Recorder rec;
    rec.accept = false;
    const size_t before = warningCount();
    ASSERT_NO_THROW(r.parseFile(f.path().string(), rec)) << f.path();
    EXPECT_GT(rec.requests.size(), 5u) << f.path();
    EXPECT_GT(warningCount(), before) << "unsupported requests must warn: " << f.path();
    EXPECT_EQ(r.bytesRead(), std::filesystem::file_size(f.path()));
    ++files;
  }
  EXPECT_EQ(files, 6);
}

TEST(RibReaderTest, RealFilesParameterListsResolveThroughStandardDeclarations) {
  // Where each request's parameter list starts.
  const std::map<std::string, size_t> firstParam = {{"PointsPolygons", 2}, {"Polygon", 0},     {"GeneralPolygon", 1}, {"PointsGeneralPolygons", 3},
                                                    {"Patch", 1},          {"Sphere", 4},      {"Cylinder", 4},       {"Cone", 3},
                                                    {"Disk", 3},           {"Paraboloid", 4},  {"Hyperboloid", 7},    {"Points", 0},
                                                    {"Curves", 3},         {"LightSource", 2}, {"Surface", 1},        {"Displacement", 1},
                                                    {"Attribute", 1},      {"Option", 1},      {"Display", 3},        {"Projection", 1},
                                                    {"Hider", 1}};
  struct Checker : RequestHandler {
    const std::map<std::string, size_t>* first;
    size_t lists = 0, params = 0;
    bool handle(const Request& r, const Args& a) override {
      auto it = first->find(std::string(r.name));
      if (it == first->end()) return true;
      if (r.name == "Curves" && a.count() > 3 && a.string(2) != "periodic" && a.string(2) != "nonperiodic") return true;
      params += a.params(it->second).size();
      ++lists;
      return true;
    }
  } checker;
  checker.first = &firstParam;
  for (const auto& f : std::filesystem::directory_iterator(test::sharedDir() + "/data/rib")) {
    Reader r;
    ASSERT_NO_THROW(r.parseFile(f.path().string(), checker)) << f.path();
  }
  EXPECT_GT(checker.lists, 30u);
  EXPECT_GT(checker.params, 40u);
}

TEST(RibReaderTest, AsciiTokenKinds) {
  const std::string src =
      "##RenderMan RIB\n"
      "version 3.04 # trailing comment\n"
      "Declare \"myvar\" \"uniform float[2]\"\n"
      "Tokens 1 -2 +3 .5 -.25e1 1e3 16777217 9007199254740993 0.1\n"
      "Strings \"plain\" \"esc\\\"aped\\\\ \\n\\t\\101\\60\" \"multi\nline\" \"cont\\\nued\"\n"
      "Arrays [] [1 2 3] [\"a\" \"b\"] [ ]\n"
      "Params \"myvar\" [1 2] \"varying color Cs\" [1 0 0] \"uniform float[2] x\" [5 6] \"vertex point P\" [0 0 0]\n"
      "   Last\n";
  Reader reader;
  struct H : RequestHandler {
    std::vector<Recorded> reqs;
    std::vector<Param> params;
    std::vector<std::string> paramNames;
    bool handle(const Request& r, const Args& a) override {
      reqs.push_back({std::string(r.name), r.values, r.where});
      if (r.name == "Params") {
        params = a.params(0);
        for (auto& p : params) paramNames.push_back(p.decl.name);
      }
      return true;
    }
  } h;
  reader.parseBuffer(src, "tok.rib", h);
  ASSERT_EQ(h.reqs.size(), 6u);  // Declare is passed on too; version is the reader's
  EXPECT_EQ(h.reqs[0].name, "Declare");
  const auto& t = h.reqs[1];
  EXPECT_EQ(t.name, "Tokens");
  EXPECT_EQ(t.where.line, 4u);
  EXPECT_EQ(t.where.str(), "tok.rib:4");
  ASSERT_EQ(t.values.size(), 9u);
  EXPECT_EQ(t.values[0].number, 1);
  EXPECT_EQ(t.values[1].number, -2);
  EXPECT_EQ(t.values[2].number, 3);
  EXPECT_EQ(t.values[3].number, 0.5);
  EXPECT_EQ(t.values[4].number, -2.5);
  EXPECT_EQ(t.values[5].number, 1000);
  EXPECT_EQ(t.values[6].number, 16777217.0);  // integers exact beyond float precision
  EXPECT_EQ(t.values[7].number, 9007199254740993.0);
  EXPECT_EQ(t.values[8].number, double(0.1f));  // decimals: RtFloat
  const auto& s = h.reqs[2];
  ASSERT_EQ(s.values.size(), 4u);
  EXPECT_EQ(s.values[0].string, "plain");
  EXPECT_EQ(s.values[1].string, "esc\"aped\\ \n\tA0");
  EXPECT_EQ(s.values[2].string, "multi\nline");
  EXPECT_EQ(s.values[3].string, "contued");
  const auto& a = h.reqs[3];
  EXPECT_EQ(a.where.line, 8u);  // the multi-line strings counted their newlines
  ASSERT_EQ(a.values.size(), 4u);
  EXPECT_EQ(a.values[0].kind, Value::Kind::NumberArray);
  EXPECT_EQ(a.values[0].size(), 0u);
  EXPECT_EQ(a.values[1].numbers, (std::vector<double>{1, 2, 3}));
  EXPECT_EQ(a.values[2].kind, Value::Kind::StringArray);
  EXPECT_EQ(a.values[2].strings, (std::vector<std::string>{"a", "b"}));
  ASSERT_EQ(h.paramNames, (std::vector<std::string>{"myvar", "Cs", "x", "P"}));
  EXPECT_EQ(h.params[0].decl.arraySize, 2);
  EXPECT_EQ(h.params[0].decl.storage, StorageClass::Uniform);
  EXPECT_EQ(h.params[1].decl.storage, StorageClass::Varying);
  EXPECT_EQ(h.params[1].decl.type, ParamType::Color);
  EXPECT_EQ(h.params[2].decl.arraySize, 2);
  EXPECT_EQ(h.params[3].decl.storage, StorageClass::Vertex);
  EXPECT_EQ(h.params[3].decl.type, ParamType::Point);
  EXPECT_EQ(h.reqs[5].name, "Last");
  EXPECT_EQ(h.reqs[5].where.line, 10u);

  ParamDecl d;
  EXPECT_TRUE(reader.lookup("myvar", d));
  EXPECT_TRUE(reader.lookup("Cs", d));
  EXPECT_EQ(d.type, ParamType::Color);
  EXPECT_TRUE(reader.lookup("st", d));
  EXPECT_EQ(d.arraySize, 2);
  for (const char* n : {"P",
                        "N",
                        "Os",
                        "s",
                        "t",
                        "Pw",
                        "Np",
                        "fov",
                        "intensity",
                        "lightcolor",
                        "from",
                        "to",
                        "coneangle",
                        "conedeltaangle",
                        "beamdistribution",
                        "Ka",
                        "Kd",
                        "Ks",
                        "roughness",
                        "specularcolor"})
    EXPECT_TRUE(reader.lookup(n, d)) << n;
  EXPECT_FALSE(reader.lookup("nosuchname", d));
  EXPECT_FALSE(reader.lookup("varying colour x", d));
}

TEST(RibReaderTest, GzipIsDetectedByContentNotName) {
  test::ScratchDir dir;
  const std::string src = "WorldBegin\nSphere 1 -1 1 360 \"Cs\" [1 0 0]\nWorldEnd\n";
  writeFile(dir.path("plain.rib.gz"), src);
  writeFile(dir.path("zipped.rib"), gzipBytes(src));
  Recorder a, b, c;
  Reader().parseFile(dir.path("plain.rib.gz"), a);
  Reader().parseFile(dir.path("zipped.rib"), b);
  const std::string gz = gzipBytes(src);
  Reader().parseBuffer(gz, "mem", c);
  expectSameRequests(a.requests, b.requests);
  expectSameRequests(a.requests, c.requests);
  EXPECT_EQ(a.requests.size(), 3u);
  EXPECT_EQ(b.requests[1].where.line, 2u);
}

TEST(RibReaderTest, ReadArchiveIsRelativeToTheIncludingFile) {
  test::ScratchDir dir;
  std::filesystem::create_directories(dir.dir() / "sub" / "deeper");
  writeFile(dir.path("top.rib"), "WorldBegin\nReadArchive \"sub/a.rib\"\nWorldEnd\n");
  writeFile(dir.path("sub/a.rib"), "Declare \"fromA\" \"varying float\"\nA1\nReadArchive \"deeper/b.rib\"\nA2\n");
  writeFile(dir.path("sub/deeper/b.rib"), gzipBytes("B1 \"fromA\" [1]\n"));
  struct H : RequestHandler {
    std::vector<std::string> seen;
    bool handle(const Request& r, const Args& a) override {
      seen.push_back(cat(r.name, "@", std::filesystem::path(r.where.file).filename().string(), ":", r.where.line));
      if (r.name == "B1") {
        EXPECT_EQ(a.params(0).at(0).decl.storage, StorageClass::Varying);  // declarations carry across files
      }
      return true;
    }
  } h;
  Reader().parseFile(dir.path("top.rib"), h);
  EXPECT_EQ(h.seen, (std::vector<std::string>{"WorldBegin@top.rib:1", "Declare@a.rib:1", "A1@a.rib:2", "B1@b.rib:1", "A2@a.rib:4", "WorldEnd@top.rib:3"}));
  // A cycle stops at the depth limit with a clear error.
  writeFile(dir.path("loop.rib"), "ReadArchive \"loop.rib\"\n");
  try {
    Recorder rec;
    Reader().parseFile(dir.path("loop.rib"), rec);
    FAIL();
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("ReadArchive"), std::string::npos) << e.what();
  }
}

TEST(RibReaderTest, BinaryEncodingParsesLikeAscii) {
  // The same requests, once as ASCII and once in every binary form.
  std::string ascii;
  BinaryWriter bin;
  // Integers in every width, signed.
  const std::vector<std::pair<int64_t, int>> ints = {{0, 0},      {127, 0},     {-128, 0},     {-1, 0},         {300, 1},
                                                     {-32768, 1}, {8388607, 2}, {-8388608, 2}, {2147483647, 3}, {-2147483647 - 1, 3}};
  ascii += "Ints";
  bin.defineRequest(1, "Ints");
  bin.request(1);
  for (auto [v, w] : ints) {
    ascii += cat(" ", v);
    bin.fixed(double(v), w, 0);
  }
  ascii += "\n";
  // Fixed point d = 1..3 (and d > w+1 bytes), incl. negatives; `Scale 1 -1 1` as exporters write it.
  ascii += "Scale 1 -1 1\n";
  bin.ascii("Scale ");
  bin.fixed(1, 0, 0), bin.fixed(-1, 0, 0), bin.fixed(1, 0, 0);
  bin.ascii("\n");
  const std::vector<std::tuple<double, int, int>> fx = {{-1.5, 1, 1}, {0.25, 0, 1},        {-0.00390625, 0, 1}, {123.75, 2, 1},
                                                        {-2.5, 2, 2}, {1.0 / 65536, 1, 2}, {-3.125, 3, 3},      {-5.0 / 16777216, 0, 3}};
  ascii += "Fixed";
  bin.defineRequest(200, "Fixed");
  bin.request(200);
  for (auto [v, w, d] : fx) {
    ascii += " " + shortestFloat(float(v));
    bin.fixed(v, w, d);
  }
  ascii += "\n";
  // All sixteen codes 0x80-0x8F (w+1 bytes, d bytes after the binary point), at the most negative
  // and the most positive raw value of each width. Printed exactly (glibc prints a double's exact
  // decimal expansion), so the ASCII side rounds the same real number to RtFloat.
  ascii += "Widths";
  bin.ascii("Widths");
  for (int w = 0; w < 4; ++w)
    for (int d = 0; d < 4; ++d)
      for (int64_t raw : {-(int64_t(1) << (8 * (w + 1) - 1)), (int64_t(1) << (8 * (w + 1) - 1)) - 1}) {
        const double v = std::ldexp(double(raw), -8 * d);
        char text[128];
        std::snprintf(text, sizeof text, " %.80g", v);
        ascii += text;
        bin.fixed(v, w, d);
      }
  ascii += "\n";
  bin.ascii("\n");
  // float32 and float64.
  ascii += "Floats " + shortestFloat(0.1f) + " " + shortestFloat(-3.4e38f) + " " + shortestFloat(1e-30f) + " " + shortestFloat(float(1.0 / 3)) + "\n";
  bin.ascii("Floats");
  bin.f32(0.1f), bin.f32(-3.4e38f), bin.f64(double(1e-30f)), bin.f64(1.0 / 3);
  bin.ascii("\n");
  // Strings: short, 1-byte and 2-byte lengths, defined strings with 1- and 2-byte ids.
  const std::string longer(40, 'x'), longest(1000, 'y');
  ascii += "Surface \"plastic\" \"Ks\" [0.5] \"" + longer + "\" \"" + longest + "\" \"defined\" \"defined\" \"wide\"\n";
  bin.defineRequest(7, "Surface");
  bin.request(7);
  bin.str("plastic"), bin.str("Ks");
  bin.ascii("[");
  bin.fixed(0.5, 1, 1);  // 128/256 needs two signed bytes
  bin.ascii("]");
  bin.str(longer), bin.str(longest);
  bin.defineString(3, "defined");
  bin.stringRef(3), bin.stringRef(3);
  bin.defineString(4000, "wide");
  bin.stringRef(4000);
  // Float arrays: short and 2-byte count, and a binary float array as a parameter value.
  std::vector<float> small = {0, -1.5f, 2.25f}, big(300);
  for (size_t i = 0; i < big.size(); ++i) big[i] = float(i) * 0.37f - 20;
  auto arrayText = [](const std::vector<float>& v) {
    std::string s = "[";
    for (float f : v) s += shortestFloat(f) + " ";
    return s + "]";
  };
  ascii += "Polygon \"P\" " + arrayText({0, 0, 0, 1, 0, 0, 1, 1, 0}) + " \"Cs\" " + arrayText({1, 0, 0, 0, 1, 0, 0, 0, 1}) + "\n";
  bin.defineRequest(8, "Polygon");
  bin.request(8);
  bin.str("P");
  bin.floatArray({0, 0, 0, 1, 0, 0, 1, 1, 0});
  bin.str("Cs");
  bin.floatArray({1, 0, 0, 0, 1, 0, 0, 0, 1});
  ascii += "Arrays " + arrayText(small) + " " + arrayText(big) + " []\n";
  bin.ascii("Arrays ");
  bin.floatArray(small), bin.floatArray(big), bin.floatArray({});
  // Back to ASCII in the same stream, then a request called twice by code.
  ascii += "WorldEnd\nSurface \"matte\"\n";
  bin.ascii("\nWorldEnd\n");
  bin.request(7);
  bin.str("matte");

  auto a = parse(ascii, "ascii.rib");
  auto b = parse(bin.out, "binary.rib");
  expectSameRequests(a, b);
  ASSERT_EQ(a.size(), 10u);
  EXPECT_EQ(b[0].values[2].number, -128);
  EXPECT_EQ(b[0].values[9].number, -2147483648.0);
  EXPECT_EQ(b[1].values[1].number, -1);  // signed, not 255
  ASSERT_EQ(b[3].name, "Widths");
  ASSERT_EQ(b[3].values.size(), 32u);
  EXPECT_EQ(b[3].values[0].number, -128);  // 0x80: one byte, most negative
  EXPECT_EQ(b[3].values[1].number, 127);
  EXPECT_EQ(b[3].values[2].number, -0.5);                                      // 0x84: -128 / 256
  EXPECT_EQ(b[3].values[30].number, double(float(-2147483648.0 / 16777216)));  // 0x8F
  EXPECT_TRUE(b[0].where.binary);
  EXPECT_EQ(b[0].where.str().find("binary.rib: byte "), 0u);
  EXPECT_FALSE(b[1].where.binary);  // ASCII request name inside a binary file
  EXPECT_EQ(b[7].values[0].numbers.size(), 3u);
  EXPECT_EQ(b[7].values[1].numbers.size(), 300u);

  // Gzipped binary parses the same too.
  expectSameRequests(a, parse(gzipBytes(bin.out), "binary.rib.gz"));
}

TEST(RibReaderTest, TokensAcrossChunkBoundariesAndLongStrings) {
  // Random requests spanning several 256 KB input chunks; every value must come back exactly.
  std::mt19937 rng(7);
  std::string src;
  std::vector<std::vector<double>> expect;
  for (int r = 0; r < 3000; ++r) {
    src += "Req [";
    std::vector<double> vals;
    int n = 1 + int(rng() % 200);
    for (int i = 0; i < n; ++i) {
      float f = float(int(rng() % 2000000) - 1000000) / 997.f;
      src += shortestFloat(f) + " ";
      vals.push_back(double(f));
    }
    src += "] \"" + std::string(rng() % 3 == 0 ? 70000 : 5, char('a' + r % 26)) + "\"\n";
    expect.push_back(std::move(vals));
  }
  ASSERT_GT(src.size(), size_t(3) << 20);
  auto got = parse(src);
  ASSERT_EQ(got.size(), expect.size());
  for (size_t r = 0; r < got.size(); ++r) {
    ASSERT_EQ(got[r].values[0].numbers, expect[r]) << r;
    EXPECT_EQ(got[r].where.line, r + 1);
  }
}

TEST(RibReaderTest, MemoryDoesNotGrowWithFileSize) {
  // ~64 MB of decompressed RIB read through gzip from disk; the reader's resident memory must
  // stay at its chunk buffers (each ctest case runs in its own process, so VmHWM is ours).
  test::ScratchDir dir;
  const std::string path = dir.path("big.rib.gz");
  {
    gzFile gz = gzopen(path.c_str(), "wb1");
    std::string block;
    for (int i = 0; i < 2000; ++i) block += "PointsPolygons [4] [0 1 2 3] \"P\" [0 0 1 1 0 1 1 1 1 0 1 1] \"Cs\" [0.5 0.25 0.125]\n";
    for (int k = 0; k < 400; ++k) gzwrite(gz, block.data(), unsigned(block.size()));
    gzclose(gz);
  }
  auto hwmKb = [] {
    std::ifstream s("/proc/self/status");
    std::string line;
    while (std::getline(s, line))
      if (line.rfind("VmHWM:", 0) == 0) return std::stol(line.substr(6));
    return 0L;
  };
  const long before = hwmKb();
  struct Count : RequestHandler {
    size_t n = 0;
    bool handle(const Request&, const Args&) override { return ++n, true; }
  } count;
  Reader r;
  r.parseFile(path, count);
  EXPECT_EQ(count.n, 800000u);
  EXPECT_GT(r.bytesRead(), uint64_t(60) << 20);
  EXPECT_LT(hwmKb() - before, 32L * 1024) << "KB of peak resident memory added while parsing";
}

TEST(RibReaderTest, UnknownRequestsWarnOncePerKind) {
  Recorder rec;
  rec.accept = false;
  testing::internal::CaptureStderr();
  const size_t before = warningCount();
  Reader().parseBuffer("Foo 1\nFoo 2\nBar\nFoo 3\n", "w.rib", rec);
  flushWarningCounts();
  std::string err = testing::internal::GetCapturedStderr();
  EXPECT_EQ(warningCount() - before, 4u);
  EXPECT_NE(err.find("w.rib:1: RIB request 'Foo'"), std::string::npos) << err;
  EXPECT_NE(err.find("w.rib:3: RIB request 'Bar'"), std::string::npos) << err;
  EXPECT_EQ(err.find("w.rib:2"), std::string::npos) << err;
  EXPECT_EQ(rec.requests.size(), 4u);
}

TEST(RibReaderHardTest, BadInputGivesOneClearErrorNamingFileLineAndRequest) {
  const std::vector<ErrorCase> cases = {
      {"WorldBegin\nSurface \"abc", "bad.rib:2 (Surface)", "unterminated string"},
      {"Polygon \"P\" [0 0 0 1 0 0", "(Polygon)", "unterminated array"},
      {"Polygon \"P\" [0 0 0\nWorldEnd\n", "bad.rib:2 (Polygon)", "unterminated array"},
      {"Polygon \"P\" [0 0 0 \"x\"]", "bad.rib:1 (Polygon)", "mixes numbers and strings"},
      {"Polygon \"P\" [0 [0]]", "bad.rib:1 (Polygon)", "inside an array"},
      {"Translate 1 2 3]\n", "bad.rib:1 (Translate)", "']' without '['"},
      {"Translate 1.2.3 0 0\n", "bad.rib:1 (Translate)", "malformed number"},
      {"Translate 1 @ 0\n", "bad.rib:1 (Translate)", "unexpected character '@'"},
      {"\n1 2 3\n", "bad.rib:2", "request name was expected"},
      {"Declare \"x\" \"varying colour\"\n", "bad.rib:1 (Declare)", "unknown type"},
      {"Declare \"x\"\n", "bad.rib:1 (Declare)", "expects a name and a declaration"},
      {"ReadArchive \"does/not/exist.rib\"\n", "bad.rib:1 (ReadArchive)", "cannot open archive"},
      {"Procedural \"DelayedReadArchive\" [\"does/not/exist.rib\"] [0 1 0 1 0 1]\n", "bad.rib:1 (Procedural)", "cannot open archive"},
      {"Procedural \"DelayedReadArchive\" 3 [0 1 0 1 0 1]\n", "bad.rib:1 (Procedural)", "expects [\"archive.rib\"]"},
      {"Procedural2 \"DelayedReadArchive2\" \"SimpleBound\"\n", "bad.rib:1 (Procedural2)", "no \"filename\""},
      {"Sphere 1 \x95"
       "ab",
       "(Sphere)", "truncated"},
      {"Sphere 1 \x82\x01", "(Sphere)", "truncated"},
      {"Sphere 1 \xa8", "bad.rib: byte 9 (Sphere)", "bad binary code 0xa8"},
      {"Sphere 1 \xff", "bad.rib: byte 9 (Sphere)", "bad binary code 0xff"},
      {"\xa6\x05", "bad.rib: byte", "used before it was defined"},
      {"Sphere \xcf\x09", "bad.rib: byte", "used before it was defined"},
      {"\xcc\x01 3 ", "bad.rib: byte", "must be followed by a string"},
      {"Sphere \xc9\x00", "(Sphere)", "truncated"},
      {"Sphere \xa1\xff\xff"
       "abc",
       "(Sphere)", "truncated"},
      {std::string("\x1f\x8b\x08\x00garbage", 12), "bad.rib", "gzip"},
  };
  expectErrors(cases);
  // A truncated gzip stream.
  const std::string gz = gzipBytes(std::string(5000, ' ') + "WorldBegin\n");
  auto [w, p] = parseError(std::string_view(gz).substr(0, gz.size() / 2));
  EXPECT_NE(p.find("gzip"), std::string::npos) << p;
}

TEST(RibReaderHardTest, ParameterListErrorsNameTheParameter) {
  struct H : RequestHandler {
    bool handle(const Request&, const Args& a) override {
      a.params(0);
      return true;
    }
  } h;
  struct Case {
    std::string src, problemPart;
  };
  const std::vector<Case> cases = {
      {"\n\nPolygon \"P\" [0 0 0 1 0 0 1 1]\n", "'P' has 8 numbers, not a multiple of 3"},
      {"\n\nPolygon \"P\"\n", "'P' has no value"},
      {"\n\nPolygon \"P\" [\"a\" \"b\" \"c\"]\n", "'P' must be given numbers"},
      {"\n\nPolygon 3 [0 0 0]\n", "must be a parameter name"},
      {"\n\nPolygon \"uniform float[2] x\" [1 2 3]\n", "not a multiple of 2"},
      {"\n\nSurface \"texturename\" [1]\n", "must be given strings"},
  };
  for (const auto& c : cases) {
    auto [where, problem] = parseError(c.src, &h);
    EXPECT_EQ(where.substr(0, 9), "bad.rib:3") << where;
    EXPECT_NE(where.find("("), std::string::npos) << where;
    EXPECT_NE(problem.find(c.problemPart), std::string::npos) << problem;
  }
}

TEST(RibReaderHardTest, LongRunsOfDefinitionsNeitherRecurseNorCrash) {
  // A definition's name must be a string; a definition where the name should be is an error,
  // found at the second byte, whatever follows (2 MB of 0xCC overflowed the stack when each
  // definition read its name through the full tokenizer).
  for (char code : {'\xcc', '\xcd'}) {
    auto [where, problem] = parseError(std::string(4 << 20, code));
    EXPECT_NE(problem.find("must be followed by a string"), std::string::npos) << problem;
    EXPECT_NE(where.find("bad.rib: byte"), std::string::npos) << where;
  }
  // Valid definitions, many in a row, still parse: each names a string directly.
  std::string defs;
  for (int i = 0; i < 100000; ++i)
    defs +=
        "\xcd\x01\x92"
        "ab";
  defs +=
      "\xcc\x07\x9a"
      "WorldBegin \xa6\x07";
  struct H : RequestHandler {
    int worldBegins = 0;
    bool handle(const Request& r, const Args&) override { return worldBegins += r.name == "WorldBegin", true; }
  } h;
  Reader().parseBuffer(defs, "defs.rib", h);
  EXPECT_EQ(h.worldBegins, 1);
}

TEST(RibReaderTest, UnknownParametersWarnOncePerRequestAndNameAndAreSkipped) {
  // What exporters write that no reader can know: a shader's undeclared parameter, an attribute
  // of another renderer, a misspelt type. The request goes on with the parameters it knows; a RIS
  // connection ("reference color") is one of them, its value the "handle:output" it names.
  struct H : RequestHandler {
    std::vector<std::vector<std::string>> names;
    std::vector<std::string> references;
    bool handle(const Request& r, const Args& a) override {
      std::vector<std::string> n;
      for (const Param& p : a.params(r.name == "Bxdf" ? 2 : a.count() % 2)) {
        n.push_back(p.decl.name);
        if (p.decl.reference) references.push_back(p.value->kind == Value::Kind::StringArray ? p.value->strings.at(0) : p.value->string);
      }
      names.push_back(n);
      return true;
    }
  } h;
  const size_t before = warningCount();
  Reader().parseBuffer(
      "Surface \"paintedplastic\" \"mapname\" [\"a.tx\"] \"Kd\" [0.5]\n"
      "Surface \"paintedplastic\" \"mapname\" [\"b.tx\"] \"Ks\" [0.1]\n"
      "Attribute \"identifier\" \"shadinggroup\" [\"g1\"] \"name\" [\"n\"]\n"
      "Bxdf \"PxrDiffuse\" \"d\" \"reference color diffuseColor\" [\"tex:resultRGB\"] \"color diffuseColor\" [1 0 0]\n"
      "Polygon \"P\" [0 0 0 1 0 0 1 1 0] \"varying flot x\" [1 2 3]\n",
      "exporter.rib", h);
  ASSERT_EQ(h.names.size(), 5u);
  EXPECT_EQ(h.names[0], (std::vector<std::string>{"Kd"}));
  EXPECT_EQ(h.names[1], (std::vector<std::string>{"Ks"}));
  EXPECT_EQ(h.names[2], (std::vector<std::string>{"name"}));
  EXPECT_EQ(h.names[3], (std::vector<std::string>{"diffuseColor", "diffuseColor"}));
  EXPECT_EQ(h.references, (std::vector<std::string>{"tex:resultRGB"}));
  EXPECT_EQ(h.names[4], (std::vector<std::string>{"P"}));
  // One per skipped parameter (warnOnce prints a repeated (request, name) once and counts it).
  EXPECT_EQ(warningCount() - before, 4u);
}

namespace {
/// The names of the requests a conditional RIB text hands on (Option requests left out).
std::string takenRequests(const std::string& text) {
  Recorder rec;
  Reader().parseBuffer(text, "cond.rib", rec);
  std::string out;
  for (const auto& r : rec.requests)
    if (r.name != "Option") out += (out.empty() ? "" : " ") + r.name;
  return out;
}
}  // namespace

TEST(RibReaderTest, ConditionalBlocksFollowUserOptions) {
  const std::string passes =
      "IfBegin \"$user:pass == 'beauty'\"\n Sphere 1 -1 1 360\n"
      "ElseIf \"${user:pass} == 'shadow'\"\n Cone 1 1 360\n"
      "Else\n Disk 0 1 360\nIfEnd\nWorldEnd\n";
  EXPECT_EQ(takenRequests("Option \"user\" \"string pass\" [\"beauty\"]\n" + passes), "Sphere WorldEnd");
  EXPECT_EQ(takenRequests("Option \"user\" \"string pass\" [\"shadow\"]\n" + passes), "Cone WorldEnd");
  EXPECT_EQ(takenRequests("Option \"user\" \"string pass\" [\"matte\"]\n" + passes), "Disk WorldEnd");
  EXPECT_EQ(takenRequests(passes), "Disk WorldEnd");  // undefined: the empty string
  // Only the first true branch is taken; nested blocks inside a skipped branch stay skipped.
  EXPECT_EQ(takenRequests("Option \"user\" \"float lod\" [2]\n"
                          "IfBegin \"$lod >= 2\"\n A\n IfBegin \"$lod == 3\"\n B\n Else\n C\n IfEnd\n"
                          "ElseIf \"$lod > 1\"\n D\n"
                          "Else\n IfBegin \"1\"\n E\n IfEnd\nIfEnd\n"),
            "A C");
  // Operators and functions.
  const std::string opts = "Option \"user\" \"string pass\" [\"shadow_key\"] \"integer frame\" [12]\n";
  auto truth = [&](const std::string& cond) { return takenRequests(opts + "IfBegin \"" + cond + "\"\n Yes\nIfEnd\n") == "Yes"; };
  EXPECT_TRUE(truth("defined(user:pass) && !defined(user:nothing)"));
  EXPECT_TRUE(truth("$user:pass =~ '^shadow'"));
  EXPECT_FALSE(truth("$user:pass =~ '^key'"));
  EXPECT_TRUE(truth("match('_key$', $user:pass)"));
  EXPECT_TRUE(truth("$frame > 9 && ($frame < 11 || $frame == 12)"));  // numeric, not by string
  EXPECT_TRUE(truth("concat($pass, '!') == 'shadow_key!'"));
  EXPECT_FALSE(truth("$frame != 12 || 0"));
  // A branch not taken never reads its archives.
  EXPECT_EQ(takenRequests("IfBegin \"0\"\n ReadArchive \"does/not/exist.rib\"\nIfEnd\nWorldEnd\n"), "WorldEnd");
}

TEST(RibReaderHardTest, MalformedConditionalsAreOneLineErrors) {
  const std::vector<ErrorCase> cases = {
      {"IfEnd\n", "bad.rib:1 (IfEnd)", "without IfBegin"},
      {"Else\n", "bad.rib:1 (Else)", "without IfBegin"},
      {"IfBegin \"1\"\nElse\nElse\n", "bad.rib:3 (Else)", "second Else"},
      {"IfBegin \"1\"\nElse\nElseIf \"1\"\n", "bad.rib:3 (ElseIf)", "after Else"},
      {"\nIfBegin \"$pass == \"\n", "bad.rib:2 (IfBegin)", "ends early"},
      {"IfBegin \"(1\"\n", "bad.rib:1 (IfBegin)", "')' was expected"},
      {"IfBegin \"pass == 1\"\n", "bad.rib:1 (IfBegin)", "unknown word 'pass'"},
      {"IfBegin \"a:b\"\n", "bad.rib:1 (IfBegin)", "unknown word 'a:b'"},  // found by the fuzzer: a class-qualified word
      {"IfBegin \"$a =~ '('\"\n", "bad.rib:1 (IfBegin)", "bad regular expression"},
      {"IfBegin \"" + std::string(200, '(') + "\"\n", "bad.rib:1 (IfBegin)", "nested deeper"},
      {"IfBegin 1\n", "bad.rib:1 (IfBegin)", "must be a string"},
      {"IfBegin \"1\"\nSphere 1 -1 1 360\n", "bad.rib", "IfEnd missing"},
  };
  expectErrors(cases);
}

TEST(RibReaderTest, InlineArchivesAreHeldAndReplayedWhereTheyAreRead) {
  // Defining hands nothing on; each ReadArchive replays the requests in order, conditionals
  // evaluated where the archive is read; a file is read only when no inline archive has the name.
  const std::string archive =
      "ArchiveBegin \"part\"\n Translate 1 0 0\n IfBegin \"$user:lod > 1\"\n Sphere 1 -1 1 360\n Else\n Disk 0 1 360\n IfEnd\nArchiveEnd\n";
  EXPECT_EQ(takenRequests(archive + "WorldBegin\n"), "WorldBegin");
  EXPECT_EQ(takenRequests(archive + "Option \"user\" \"float lod\" [2]\nReadArchive \"part\"\nOption \"user\" \"float lod\" [0]\nReadArchive \"part\"\n"),
            "Translate Sphere Translate Disk");
  // The values come through whole (a parameter list, arrays).
  Recorder rec;
  Reader().parseBuffer("ArchiveBegin \"p\"\nPolygon \"P\" [0 0 0 1 0 0 1 1 0]\nArchiveEnd\nReadArchive \"p\"\n", "a.rib", rec);
  ASSERT_EQ(rec.requests.size(), 1u);
  EXPECT_EQ(rec.requests[0].name, "Polygon");
  // A later definition replaces an earlier one.
  EXPECT_EQ(takenRequests("ArchiveBegin \"a\"\nSphere 1 -1 1 360\nArchiveEnd\nArchiveBegin \"a\"\nCone 1 1 360\nArchiveEnd\nReadArchive \"a\"\n"), "Cone");
}

TEST(RibReaderHardTest, BadInlineArchivesAreOneLineErrors) {
  expectErrors({
      {"ArchiveBegin \"a\"\nSphere 1 -1 1 360\n", "bad.rib:1", "has no ArchiveEnd"},
      {"ArchiveEnd\n", "bad.rib:1 (ArchiveEnd)", "without ArchiveBegin"},
      {"ArchiveBegin \"a\"\nArchiveBegin \"b\"\n", "bad.rib:2 (ArchiveBegin)", "does not nest"},
      {"ArchiveBegin \"a\"\nReadArchive \"a\"\nArchiveEnd\nReadArchive \"a\"\n", "bad.rib:2 (ReadArchive)", "a cycle?"},
      {"ArchiveBegin \"\"\n", "bad.rib:1 (ArchiveBegin)", "needs a name"},
  });
}

TEST(RibReaderHardTest, FuzzCorpusNeverCrashes) {
  // Inputs the fuzzer found interesting (tests/corpus/rib/): each parses or throws Error.
  const std::filesystem::path corpus = test::sourceDir() + "/tests/corpus/rib";
  ASSERT_TRUE(std::filesystem::exists(corpus));
  int n = 0;
  for (const auto& f : std::filesystem::directory_iterator(corpus)) {
    auto bytes = test::readBytes(f.path().string());
    struct H : RequestHandler {
      bool handle(const Request&, const Args& a) override {
        if (a.count() > 0 && a.count() % 2 == 0) a.params(0);
        return true;
      }
    } h;
    try {
      Reader().parseBuffer(std::string_view(reinterpret_cast<const char*>(bytes.data()), bytes.size()), f.path().filename().string(), h);
    } catch (const Error&) {
    }
    ++n;
  }
  EXPECT_GT(n, 0);
}
