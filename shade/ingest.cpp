// Micropolygon-dump ingest: a RIB request handler that keeps the graphics state a dump needs
// (options, moving transforms, orientation, motion blocks) and turns polygon requests into store
// grids. See ingest.h for the semantics and the choices made.
#include "shade/ingest.h"

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <filesystem>
#include <map>
#include <memory>
#include <optional>
#include <set>

#include <glm/gtc/matrix_transform.hpp>
#include <glm/gtc/type_ptr.hpp>
#include <glm/mat3x3.hpp>

#include "common/error.h"
#include "common/log.h"
#include "rib/rib.h"

namespace reshutter::shade {

namespace {

using namespace store;
using rib::Args;
using rib::ParamDecl;
using rib::ParamType;
using rib::Request;
using rib::StorageClass;

// ---------------------------------------------------------------------------------------------
// Moving transforms

struct Motion {
  std::vector<double> times;                   // empty: static
  std::vector<glm::dmat4> mats{glm::dmat4(1)};  // one per time, or one
  bool moving() const { return mats.size() > 1; }
  glm::dmat4 at(double t) const {
    if (mats.size() == 1 || t <= times.front()) return mats.front();
    if (t >= times.back()) return mats.back();
    size_t i = size_t(std::upper_bound(times.begin(), times.end(), t) - times.begin()) - 1;
    double u = (t - times[i]) / (times[i + 1] - times[i]);
    return mats[i] * (1 - u) + mats[i + 1] * u;
  }
};

/// a · b (b applies first), at the union of their times.
Motion concat(const Motion& a, const Motion& b) {
  Motion r;
  if (!a.moving() && !b.moving()) {
    r.mats[0] = a.mats[0] * b.mats[0];
    return r;
  }
  std::set<double> ts(a.times.begin(), a.times.end());
  ts.insert(b.times.begin(), b.times.end());
  r.times.assign(ts.begin(), ts.end());
  r.mats.clear();
  for (double t : r.times) r.mats.push_back(a.at(t) * b.at(t));
  return r;
}

bool isIdentity(const glm::dmat4& m) { return m == glm::dmat4(1.0); }

/// An integer argument in [lo, hi] (converting an out-of-range double to int is undefined).
int64_t integerArg(const Args& a, size_t i, double lo, double hi) {
  const double v = a.number(i);
  if (!(v >= lo && v <= hi) || v != std::trunc(v)) a.fail(cat("argument ", i + 1, " must be an integer in [", lo, ", ", hi, "], not ", v));
  return int64_t(v);
}

enum class Orient : uint8_t { Outside, Inside, LH, RH };

struct Attrs {
  Motion ctm;  // object → camera
  Orient orient = Orient::Outside;
  int sides = 2;
  bool matte = false;
  glm::vec3 color{1.f}, opacity{1.f};
};

// ---------------------------------------------------------------------------------------------
// Variables → store attributes

struct OutAttr {
  std::string name;
  AttrType type;
  int element;  // array element of the RIB variable
};

/// The store attributes one RIB variable becomes; empty when it cannot be stored.
std::vector<OutAttr> outputsFor(const ParamDecl& d) {
  AttrType t;
  switch (d.type) {
    case ParamType::Float:
    case ParamType::Integer: t = AttrType::Float; break;
    case ParamType::Point: t = AttrType::Point; break;
    case ParamType::Vector: t = AttrType::Vector; break;
    case ParamType::Normal: t = AttrType::Normal; break;
    case ParamType::Color: t = AttrType::Color; break;
    default: return {};
  }
  std::string name = d.name == "Cs" ? "Ci" : d.name == "Os" ? "Oi" : d.name;
  std::vector<OutAttr> out;
  if (d.arraySize == 1) {
    out.push_back({name, t, 0});
  } else {
    for (int i = 0; i < d.arraySize; ++i) out.push_back({cat(name, "[", i, "]"), t, i});
  }
  return out;
}

bool perVertexClass(StorageClass c) { return c == StorageClass::Vertex || c == StorageClass::Varying || c == StorageClass::FaceVarying || c == StorageClass::FaceVertex; }
bool faceVaryingClass(StorageClass c) { return c == StorageClass::FaceVarying || c == StorageClass::FaceVertex; }

// ---------------------------------------------------------------------------------------------
// Polygon splitting

struct Vec2 {
  double x, y;
};

double cross2(Vec2 o, Vec2 a, Vec2 b) { return (a.x - o.x) * (b.y - o.y) - (a.y - o.y) * (b.x - o.x); }

/// Projects a polygon onto the plane that keeps most of its area.
std::vector<Vec2> project(const std::vector<glm::dvec3>& p) {
  glm::dvec3 n(0);
  for (size_t i = 0; i < p.size(); ++i) {  // Newell's normal
    const auto& a = p[i];
    const auto& b = p[(i + 1) % p.size()];
    n.x += (a.y - b.y) * (a.z + b.z), n.y += (a.z - b.z) * (a.x + b.x), n.z += (a.x - b.x) * (a.y + b.y);
  }
  int drop = std::fabs(n.x) >= std::fabs(n.y) && std::fabs(n.x) >= std::fabs(n.z) ? 0 : std::fabs(n.y) >= std::fabs(n.z) ? 1 : 2;
  std::vector<Vec2> q;
  for (const auto& v : p) q.push_back(drop == 0 ? Vec2{v.y, v.z} : drop == 1 ? Vec2{v.z, v.x} : Vec2{v.x, v.y});
  return q;
}

/// Convex and simple: every turn the same way (collinear corners allowed), turning once around.
bool convex(const std::vector<Vec2>& q) {
  const size_t n = q.size();
  int sign = 0;
  double turning = 0;
  for (size_t i = 0; i < n; ++i) {
    Vec2 a = q[i], b = q[(i + 1) % n], c = q[(i + 2) % n];
    double cr = cross2(a, b, c);
    int s = cr > 0 ? 1 : cr < 0 ? -1 : 0;
    if (s && sign && s != sign) return false;
    if (s) sign = s;
    double a1 = std::atan2(b.y - a.y, b.x - a.x), a2 = std::atan2(c.y - b.y, c.x - b.x);
    double d = a2 - a1;
    while (d > M_PI) d -= 2 * M_PI;
    while (d < -M_PI) d += 2 * M_PI;
    turning += d;
  }
  return sign != 0 && std::fabs(std::fabs(turning) - 2 * M_PI) < 1e-6;
}

bool segmentsCross(Vec2 a, Vec2 b, Vec2 c, Vec2 d) {
  double d1 = cross2(a, b, c), d2 = cross2(a, b, d), d3 = cross2(c, d, a), d4 = cross2(c, d, b);
  return ((d1 > 0 && d2 < 0) || (d1 < 0 && d2 > 0)) && ((d3 > 0 && d4 < 0) || (d3 < 0 && d4 > 0));
}

/// No two non-adjacent edges cross (ear clipping would make garbage of a polygon that does).
bool simple(const std::vector<Vec2>& q) {
  const size_t n = q.size();
  for (size_t i = 0; i < n; ++i)
    for (size_t j = i + 2; j < n; ++j) {
      if (i == 0 && j == n - 1) continue;
      if (segmentsCross(q[i], q[(i + 1) % n], q[j], q[(j + 1) % n])) return false;
    }
  return true;
}

/// Ear clipping; false if the polygon is not simple enough to clip.
bool earClip(const std::vector<Vec2>& q, std::vector<std::array<uint32_t, 3>>& tris) {
  const size_t n = q.size();
  double area = 0;
  for (size_t i = 0; i < n; ++i) area += q[i].x * q[(i + 1) % n].y - q[(i + 1) % n].x * q[i].y;
  const double orient = area >= 0 ? 1 : -1;
  std::vector<uint32_t> idx(n);
  for (size_t i = 0; i < n; ++i) idx[i] = uint32_t(i);
  size_t guard = 0;
  while (idx.size() > 3) {
    bool clipped = false;
    for (size_t i = 0; i < idx.size(); ++i) {
      uint32_t a = idx[(i + idx.size() - 1) % idx.size()], b = idx[i], c = idx[(i + 1) % idx.size()];
      if (orient * cross2(q[a], q[b], q[c]) <= 0) continue;  // reflex or degenerate corner
      bool inside = false;
      for (uint32_t p : idx) {
        if (p == a || p == b || p == c) continue;
        if (orient * cross2(q[a], q[b], q[p]) >= 0 && orient * cross2(q[b], q[c], q[p]) >= 0 && orient * cross2(q[c], q[a], q[p]) >= 0) {
          inside = true;
          break;
        }
      }
      if (inside) continue;
      tris.push_back({a, b, c});
      idx.erase(idx.begin() + long(i));
      clipped = true;
      break;
    }
    if (!clipped || ++guard > n) return false;
  }
  tris.push_back({idx[0], idx[1], idx[2]});
  return true;
}

// ---------------------------------------------------------------------------------------------

struct Var {
  ParamDecl decl;
  std::vector<float> values;
};

/// One polygon primitive (all motion copies), ready to become a grid.
struct Prim {
  std::string request;
  std::vector<uint32_t> faceStart, faceCount;  // face-corner ranges (outer loops)
  std::vector<uint32_t> verts;                 // vertex per face-corner
  uint32_t nP = 0;
  std::vector<std::vector<float>> P;  // per copy, 3 · nP, object space
  std::vector<double> times;          // copies' times; empty: static
  std::vector<Var> vars;              // the first copy's
  // Micropolygons as face-corner indices, 4 each (kNoCorner: triangle), and their source face.
  std::vector<uint32_t> mpCorners, mpFace;
  bool unshare = false;  // one grid vertex per face-corner (facevarying/uniform-per-vertex data)
};

struct SchemaEntry {
  AttrType type;
  bool perVertex;
};

/// Thrown in the optimistic single pass when a primitive needs a variable (or a per-vertex rate)
/// the store's schema, fixed at the first primitive, lacks: ingest then falls back to two passes.
struct SchemaGrew {};

/// Modes: scan (collect the schema, no grids), emit (grids against a given schema), optimistic
/// (schema from the first primitive, grids at once; SchemaGrew if a later primitive needs more).
enum class Mode { Scan, Emit, Optimistic };

class DumpHandler final : public rib::RequestHandler {
 public:
  DumpHandler(Mode mode, const std::string& file, const IngestOptions& opt, const StoreMeta* meta, GridSink* sink, IngestStats* stats)
      : collect_(mode != Mode::Emit), emit_(mode != Mode::Scan), optimistic_(mode == Mode::Optimistic), file_(file), opt_(opt), meta_(meta),
        sink_(sink), stats_(stats) {
    attrs_.emplace_back();
  }
  /// Optimistic mode: opens the sink once the schema is known.
  std::function<GridSink*(const StoreMeta&)> openSink;
  bool sinkOpen() const { return sink_ != nullptr; }

  bool handle(const Request& r, const Args& a) override;
  void finish(const std::string& file);
  StoreMeta scannedMeta(const std::string& file) const;

 private:
  // Options
  int width_ = 640, height_ = 480;
  double pixelAspect_ = 1, frameAspect_ = 0;
  double screen_[4] = {0, 0, 0, 0};
  bool perspective_ = false;  // RenderMan's default projection is orthographic
  double fov_ = 90;
  double near_ = 1e-4, far_ = 1e30;
  double open_ = 0, close_ = 0;
  bool haveCamera_ = false;
  Camera camera_;
  double cameraOpen_ = 0, cameraClose_ = 0;
  std::optional<int64_t> frameNumber_;

  // Frames
  bool sawFrame_ = false, inFrame_ = false, skipping_ = false, done_ = false, frameFound_ = false;
  std::vector<int64_t> framesSeen_;

  // Graphics state
  std::vector<Attrs> attrs_;
  std::vector<Motion> xformStack_;
  std::map<std::string, Motion> coordSys_;
  Motion worldToCamera_;
  bool inWorld_ = false;

  // Motion blocks
  bool inMotion_ = false;
  std::vector<double> motionTimes_;
  std::string motionRequest_;
  size_t motionCount_ = 0;
  std::vector<glm::dmat4> motionMats_;
  bool motionAbsolute_ = false;
  Prim prim_;

  // Schema (pass 1)
  std::vector<std::string> schemaOrder_;
  std::map<std::string, SchemaEntry> schema_;

  // Output
  bool collect_, emit_, optimistic_;
  std::string file_;
  StoreMeta ownMeta_;
  const IngestOptions& opt_;
  const StoreMeta* meta_;
  GridSink* sink_;
  IngestStats* stats_;
  uint32_t gridId_ = 0;
  std::vector<double> lastSchedule_;
  uint32_t lastScheduleIndex_ = 0;
  std::vector<glm::vec3> positions_;
  std::vector<uint32_t> corners_;
  std::vector<std::vector<float>> attrData_;

  Attrs& cur() { return attrs_.back(); }
  void applyTransform(const Args& a, const glm::dmat4& m, bool absolute);
  bool polygons(const Request& r, const Args& a);
  void readPolygons(const Request& r, const Args& a, Prim& p, bool first);
  void split(const Args& a, Prim& p);
  void registerVars(const Args& a, Prim& p);
  void emitPrim(const Prim& p);
};

// ---------------------------------------------------------------------------------------------

void DumpHandler::applyTransform(const Args& a, const glm::dmat4& m, bool absolute) {
  if (inMotion_) {
    if (motionCount_ == 0) motionAbsolute_ = absolute;
    motionMats_.push_back(m);
    ++motionCount_;
    if (motionCount_ > motionTimes_.size()) a.fail(cat("more requests than the ", motionTimes_.size(), " motion knots"));
    return;
  }
  Motion t;
  t.mats[0] = m;
  cur().ctm = absolute ? concat(inWorld_ ? worldToCamera_ : Motion{}, t) : concat(cur().ctm, t);
}

bool DumpHandler::handle(const Request& r, const Args& a) {
  const std::string_view n = r.name;
  if (done_) return true;
  if (n == "FrameBegin") {
    int64_t f = a.count() ? integerArg(a, 0, -1e15, 1e15) : 0;
    framesSeen_.push_back(f);
    sawFrame_ = true;
    inFrame_ = true;
    skipping_ = opt_.frame ? f != *opt_.frame : frameFound_;
    if (!skipping_) frameFound_ = true, frameNumber_ = f;
    return true;
  }
  if (n == "FrameEnd") {
    if (!skipping_ && frameFound_) done_ = true;  // one frame per store
    inFrame_ = false, skipping_ = false;
    return true;
  }
  if (skipping_) return true;
  if (inMotion_ && n != "MotionEnd") {
    if (motionCount_ > 0 && n != motionRequest_) a.fail(cat("a motion block holds copies of one request; found ", n, " after ", motionRequest_));
    motionRequest_ = std::string(n);
  }

  // Camera and options.
  if (n == "Format") {
    width_ = int(integerArg(a, 0, 1, 1 << 20)), height_ = int(integerArg(a, 1, 1, 1 << 20));
    pixelAspect_ = a.count() > 2 ? a.number(2) : 1.0;
    if (width_ < 1 || height_ < 1 || width_ > 1 << 20 || height_ > 1 << 20) a.fail(cat("resolution ", width_, "x", height_, " out of range"));
    if (!(pixelAspect_ > 0)) a.fail("pixel aspect must be positive");
    return true;
  }
  if (n == "FrameAspectRatio") {
    frameAspect_ = a.number(0);
    if (!(frameAspect_ > 0)) a.fail("frame aspect ratio must be positive");
    return true;
  }
  if (n == "ScreenWindow") {
    for (int i = 0; i < 4; ++i) screen_[i] = a.number(size_t(i));
    if (screen_[0] == screen_[1] || screen_[2] == screen_[3]) a.fail("empty screen window");
    return true;
  }
  if (n == "Projection") {
    const std::string& kind = a.string(0);
    if (kind == "perspective") {
      perspective_ = true;
      for (const auto& p : a.params(1))
        if (p.decl.name == "fov") {
          if (!p.value->isNumber() && p.value->numbers.size() != 1) a.fail("\"fov\" takes one number");
          fov_ = p.value->isNumber() ? p.value->number : p.value->numbers[0];
        }
      if (!(fov_ > 0 && fov_ < 180)) a.fail(cat("field of view ", fov_, " not in (0, 180)"));
    } else if (kind == "orthographic") {
      perspective_ = false;
    } else {
      a.fail(cat("projection '", kind, "' is not supported (perspective and orthographic are)"));
    }
    return true;
  }
  if (n == "Clipping") {
    near_ = a.number(0), far_ = a.number(1);
    if (!(near_ > 0) || !(far_ > near_)) a.fail(cat("clipping planes ", near_, " ", far_, " invalid"));
    if (std::isinf(far_)) far_ = 1e30;
    return true;
  }
  if (n == "Shutter") {
    open_ = a.number(0), close_ = a.number(1);
    if (!(close_ >= open_) || !std::isfinite(open_) || !std::isfinite(close_)) a.fail(cat("shutter ", open_, " ", close_, " is not an interval"));
    return true;
  }
  if (n == "WorldBegin") {
    inWorld_ = true;
    worldToCamera_ = cur().ctm;
    coordSys_["world"] = worldToCamera_;
    if (!haveCamera_) {
      haveCamera_ = true;
      camera_ = Camera{};
      camera_.name = "camera";
      camera_.projection = perspective_ ? Projection::Perspective : Projection::Orthographic;
      camera_.fovDegrees = fov_;
      camera_.width = width_, camera_.height = height_, camera_.pixelAspect = pixelAspect_;
      if (screen_[0] != screen_[1]) {
        std::copy(screen_, screen_ + 4, camera_.screenWindow);
      } else if (frameAspect_ > 0) {
        double w[4] = {-1, 1, -1, 1};
        if (frameAspect_ >= 1) w[0] = -frameAspect_, w[1] = frameAspect_;
        else w[2] = -1 / frameAspect_, w[3] = 1 / frameAspect_;
        std::copy(w, w + 4, camera_.screenWindow);
      }
      camera_.nearClip = near_, camera_.farClip = far_;
      camera_.worldToCamera = worldToCamera_.at(open_);
      cameraOpen_ = open_, cameraClose_ = close_;
    }
    return true;
  }
  if (n == "WorldEnd") {
    inWorld_ = false;
    return true;
  }

  // Transforms.
  if (n == "Identity") return applyTransform(a, glm::dmat4(1), true), true;
  if (n == "Transform" || n == "ConcatTransform") {
    const auto& v = a.numbers(0);
    if (v.size() != 16) a.fail(cat("expects 16 numbers, has ", v.size()));
    // RIB matrices are row-vector, row-major: read column-major they are glm's column-vector form.
    glm::dmat4 m = glm::make_mat4(v.data());
    return applyTransform(a, m, n == "Transform"), true;
  }
  if (n == "Translate") return applyTransform(a, glm::translate(glm::dmat4(1), {a.number(0), a.number(1), a.number(2)}), false), true;
  if (n == "Scale") return applyTransform(a, glm::scale(glm::dmat4(1), {a.number(0), a.number(1), a.number(2)}), false), true;
  if (n == "Rotate") {
    glm::dvec3 axis(a.number(1), a.number(2), a.number(3));
    if (glm::length(axis) == 0) a.fail("rotation axis is zero");
    return applyTransform(a, glm::rotate(glm::dmat4(1), glm::radians(a.number(0)), axis), false), true;
  }
  if (n == "TransformBegin") return xformStack_.push_back(cur().ctm), true;
  if (n == "TransformEnd") {
    if (xformStack_.empty()) a.fail("TransformEnd without TransformBegin");
    cur().ctm = xformStack_.back();
    xformStack_.pop_back();
    return true;
  }
  if (n == "AttributeBegin") return attrs_.push_back(cur()), true;
  if (n == "AttributeEnd") {
    if (attrs_.size() < 2) a.fail("AttributeEnd without AttributeBegin");
    attrs_.pop_back();
    return true;
  }
  if (n == "CoordinateSystem") return coordSys_[a.string(0)] = cur().ctm, true;
  if (n == "CoordSysTransform") {
    const std::string& s = a.string(0);
    if (s == "camera") {
      cur().ctm = Motion{};
    } else {
      auto it = coordSys_.find(s);
      if (it == coordSys_.end()) a.fail(cat("unknown coordinate system '", s, "'"));
      cur().ctm = it->second;
    }
    return true;
  }

  // Attributes.
  if (n == "Orientation") {
    const std::string& o = a.string(0);
    if (o == "outside") cur().orient = Orient::Outside;
    else if (o == "inside") cur().orient = Orient::Inside;
    else if (o == "lh") cur().orient = Orient::LH;
    else if (o == "rh") cur().orient = Orient::RH;
    else a.fail(cat("unknown orientation '", o, "'"));
    return true;
  }
  if (n == "ReverseOrientation") {
    Orient& o = cur().orient;
    o = o == Orient::Outside ? Orient::Inside : o == Orient::Inside ? Orient::Outside : o == Orient::LH ? Orient::RH : Orient::LH;
    return true;
  }
  if (n == "Sides") {
    int s = int(integerArg(a, 0, 1, 2));
    if (s != 1 && s != 2) a.fail(cat("Sides ", s, " (1 or 2)"));
    cur().sides = s;
    return true;
  }
  if (n == "Matte") return cur().matte = a.number(0) != 0, true;
  if (n == "Color" || n == "Opacity") {
    glm::vec3 c;
    if (a.count() == 1) {
      const auto& v = a.numbers(0);
      if (v.size() != 3) a.fail(cat("expects 3 numbers, has ", v.size()));
      c = {float(v[0]), float(v[1]), float(v[2])};
    } else {
      c = {float(a.number(0)), float(a.number(1)), float(a.number(2))};
    }
    if (inMotion_) {
      ++motionCount_;
      if (motionCount_ > 1) {
        if (c != (n == "Color" ? cur().color : cur().opacity))
          warnOnce("ingest-appearance-knots", cat(r.where.str(), ": ", n, " changes inside a motion block; ingest keeps the first knot's value"));
        return true;
      }
    }
    (n == "Color" ? cur().color : cur().opacity) = c;
    return true;
  }

  // Motion.
  if (n == "MotionBegin") {
    if (inMotion_) a.fail("MotionBegin inside a motion block");
    motionTimes_ = a.numbers(0);
    if (motionTimes_.empty() || motionTimes_.size() > 64) a.fail(cat(motionTimes_.size(), " motion knots (1 to 64 allowed)"));
    for (size_t i = 0; i < motionTimes_.size(); ++i) {
      if (!std::isfinite(motionTimes_[i])) a.fail("motion knot time is not finite");
      if (i && !(motionTimes_[i] > motionTimes_[i - 1])) a.fail("motion knot times must increase");
    }
    inMotion_ = true;
    motionCount_ = 0;
    motionRequest_.clear();
    motionMats_.clear();
    prim_ = Prim{};
    return true;
  }
  if (n == "MotionEnd") {
    if (!inMotion_) a.fail("MotionEnd without MotionBegin");
    inMotion_ = false;
    if (motionCount_ == 0) return true;
    if (motionCount_ != motionTimes_.size())
      a.fail(cat("the motion block has ", motionTimes_.size(), " knots but ", motionCount_, " copies of ", motionRequest_));
    if (!motionMats_.empty()) {
      Motion t;
      t.times = motionTimes_;
      t.mats = motionMats_;
      if (motionTimes_.size() == 1) t.times.clear();
      cur().ctm = motionAbsolute_ ? concat(inWorld_ ? worldToCamera_ : Motion{}, t) : concat(cur().ctm, t);
    } else if (!prim_.P.empty()) {
      prim_.times = motionTimes_;
      if (emit_) emitPrim(prim_);
    }
    return true;
  }

  // Geometry.
  if (n == "PointsPolygons" || n == "PointsGeneralPolygons" || n == "Polygon" || n == "GeneralPolygon") return polygons(r, a);

  // Already-shaded micropolygons need no shading, display or sampling settings.
  static const std::set<std::string_view> ignored = {
      "Display", "DisplayChannel", "PixelSamples", "PixelFilter", "PixelVariance", "Exposure", "Quantize", "Hider", "ShadingRate",
      "ShadingInterpolation", "Surface", "Atmosphere", "Interior", "Exterior", "Displacement", "LightSource", "AreaLightSource",
      "Illuminate", "GeometricApproximation", "Option", "Attribute", "Imager", "Declare", "DisplayChannel", "RelativeDetail"};
  if (ignored.count(n)) {
    if (inMotion_) ++motionCount_;
    return true;
  }
  return false;
}

bool DumpHandler::polygons(const Request& r, const Args& a) {
  if (!inMotion_) {
    Prim p;
    readPolygons(r, a, p, true);
    if (emit_) emitPrim(p);
    return true;
  }
  const size_t k = motionCount_++;
  if (k >= motionTimes_.size()) a.fail(cat("more copies than the ", motionTimes_.size(), " motion knots"));
  if (k == 0) {
    readPolygons(r, a, prim_, true);
    return true;
  }
  Prim copy;
  readPolygons(r, a, copy, false);
  if (copy.verts != prim_.verts || copy.faceCount != prim_.faceCount || copy.nP != prim_.nP)
    a.fail(cat("motion copy ", k + 1, " has a different topology from the first"));
  // Appearance per knot: the first copy's values are kept.
  bool differs = copy.vars.size() != prim_.vars.size();
  for (size_t i = 0; !differs && i < copy.vars.size(); ++i)
    differs = copy.vars[i].decl.name != prim_.vars[i].decl.name || copy.vars[i].values != prim_.vars[i].values;
  if (differs && collect_)
    warnOnce("ingest-appearance-knots", cat(r.where.str(), " (", r.name, "): variables other than P change between motion copies; ingest keeps the first knot's"));
  prim_.P.push_back(std::move(copy.P[0]));
  return true;
}

void DumpHandler::readPolygons(const Request& r, const Args& a, Prim& p, bool first) {
  p.request = std::string(r.name);
  size_t firstParam = 0;
  std::vector<uint32_t> loops;  // per polygon: loop count
  std::vector<uint32_t> nverts;
  auto count = [&](double v, const char* what) {
    if (!(v >= 0) || v > 4294967295.0 || v != std::trunc(v)) a.fail(cat(what, " must be non-negative integers (found ", v, ")"));
    return uint32_t(v);
  };
  bool explicitVerts = false;
  if (p.request == "Polygon") {
    firstParam = 0;
  } else if (p.request == "GeneralPolygon") {
    for (double v : a.numbers(0)) nverts.push_back(count(v, "loop vertex counts"));
    loops.push_back(uint32_t(nverts.size()));
    firstParam = 1;
  } else if (p.request == "PointsPolygons") {
    for (double v : a.numbers(0)) nverts.push_back(count(v, "vertex counts")), loops.push_back(1);
    for (double v : a.numbers(1)) p.verts.push_back(count(v, "vertex indices"));
    explicitVerts = true;
    firstParam = 2;
  } else {  // PointsGeneralPolygons
    for (double v : a.numbers(0)) loops.push_back(count(v, "loop counts"));
    for (double v : a.numbers(1)) nverts.push_back(count(v, "loop vertex counts"));
    for (double v : a.numbers(2)) p.verts.push_back(count(v, "vertex indices"));
    explicitVerts = true;
    firstParam = 3;
  }
  const std::vector<rib::Param> params = a.params(firstParam);
  const rib::Param* P = nullptr;
  const rib::Param* Pw = nullptr;
  const rib::Param* blurP = nullptr;
  for (const auto& q : params) {
    if (q.decl.name == "P") P = &q;
    else if (q.decl.name == "Pw") Pw = &q;
    else if (q.decl.name == "blurP") blurP = &q;
  }
  if (!P && !Pw) a.fail("needs positions \"P\"");
  auto numbersOf = [](const rib::Param& q) -> std::vector<double> { return q.value->isNumber() ? std::vector<double>{q.value->number} : q.value->numbers; };
  std::vector<float> pos;
  if (P) {
    if (P->decl.type != ParamType::Point) a.fail("\"P\" must be declared as a point");
    for (double v : numbersOf(*P)) pos.push_back(float(v));
  } else {
    if (Pw->decl.type != ParamType::HPoint) a.fail("\"Pw\" must be declared as an hpoint");
    auto v = numbersOf(*Pw);
    for (size_t i = 0; i + 3 < v.size(); i += 4) {
      if (v[i + 3] == 0) a.fail(cat("\"Pw\" vertex ", i / 4, " has w = 0"));
      for (int c = 0; c < 3; ++c) pos.push_back(float(v[i + size_t(c)] / v[i + 3]));
    }
  }
  p.nP = uint32_t(pos.size() / 3);
  if (p.nP == 0) a.fail("has no vertices");
  if (!explicitVerts) {
    if (p.request == "Polygon") nverts = {p.nP}, loops = {1};
    uint32_t total = 0;
    for (uint32_t c : nverts) total += c;
    if (total != p.nP) a.fail(cat("loops name ", total, " vertices but \"P\" has ", p.nP));
    for (uint32_t i = 0; i < p.nP; ++i) p.verts.push_back(i);
  }
  // Faces: holes are rejected (see ingest.h).
  size_t loop = 0, corner = 0;
  for (size_t f = 0; f < loops.size(); ++f) {
    if (loops[f] != 1)
      a.fail(cat("polygon ", f, " has ", loops[f], " loops: polygons with holes are not supported by ingest (triangulate them when dumping)"));
    if (loop >= nverts.size()) a.fail(cat("loop counts name more loops than the ", nverts.size(), " vertex counts"));
    const uint32_t n = nverts[loop++];
    if (n < 3) a.fail(cat("polygon ", f, " has ", n, " vertices (at least 3)"));
    if (corner + n > p.verts.size()) a.fail(cat("vertex counts need ", corner + n, " indices, there are ", p.verts.size()));
    p.faceStart.push_back(uint32_t(corner));
    p.faceCount.push_back(n);
    corner += n;
  }
  if (loop != nverts.size()) a.fail(cat(nverts.size(), " vertex counts but ", loop, " loops"));
  if (corner != p.verts.size()) a.fail(cat("vertex counts sum to ", corner, " but there are ", p.verts.size(), " indices"));
  for (uint32_t v : p.verts)
    if (v >= p.nP) a.fail(cat("vertex index ", v, " but \"P\" has ", p.nP, " vertices"));
  const size_t nFaces = p.faceStart.size(), nCorners = p.verts.size();

  p.P.push_back(std::move(pos));
  if (blurP) {
    if (inMotion_) a.fail("\"blurP\" inside a motion block (give either blurP or motion copies)");
    if (blurP->decl.type != ParamType::Point) a.fail("\"blurP\" must be declared as a point");
    auto v = numbersOf(*blurP);
    if (v.size() != size_t(p.nP) * 3) a.fail(cat("\"blurP\" has ", v.size() / 3, " points, \"P\" has ", p.nP));
    std::vector<float> b(v.size());
    for (size_t i = 0; i < v.size(); ++i) b[i] = float(v[i]);
    p.P.push_back(std::move(b));
    p.times = {open_, close_};
  }
  // Variables, counted against the primitive.
  for (const auto& q : params) {
    const std::string& name = q.decl.name;
    if (name == "P" || name == "Pw" || name == "blurP") continue;
    const size_t per = size_t(q.decl.components()) * size_t(q.decl.arraySize);
    const size_t have = q.value->size() / std::max<size_t>(per, 1);
    size_t want = 0;
    switch (q.decl.storage) {
      case StorageClass::Constant: want = 1; break;
      case StorageClass::Uniform: want = nFaces; break;
      case StorageClass::Varying:
      case StorageClass::Vertex: want = p.nP; break;
      case StorageClass::FaceVarying:
      case StorageClass::FaceVertex: want = nCorners; break;
    }
    if (have != want) a.fail(cat("\"", name, "\" has ", have, " values; a ", p.request, " with ", nFaces, " faces and ", p.nP, " vertices needs ", want));
    if (outputsFor(q.decl).empty()) {
      if (collect_) warnOnce(cat("ingest-skip:", name), cat(r.where.str(), " (", r.name, "): variable \"", name, "\" of this type is not stored"));
      continue;
    }
    Var v;
    v.decl = q.decl;
    for (double x : numbersOf(q)) v.values.push_back(float(x));
    p.vars.push_back(std::move(v));
  }
  if (!first) return;
  split(a, p);
  registerVars(a, p);
  if (stats_) {
    ++stats_->primitives;
    stats_->polygons += nFaces;
  }
}

void DumpHandler::split(const Args& a, Prim& p) {
  const Attrs& s = cur();
  // Ring order: front-facing for Orientation "outside" in camera space (see ingest.h).
  const double det = glm::determinant(s.ctm.at(s.ctm.moving() ? s.ctm.times.front() : 0.0));
  const bool mirrored = det < 0;
  const bool reverse = s.orient == Orient::Inside || (s.orient == Orient::LH && mirrored) || (s.orient == Orient::RH && !mirrored);
  auto add = [&](uint32_t f, std::initializer_list<uint32_t> fc) {
    uint32_t c[4] = {kNoCorner, kNoCorner, kNoCorner, kNoCorner};
    size_t i = 0;
    for (uint32_t x : fc) c[i++] = x;
    if (reverse) {
      if (i == 4) std::swap(c[1], c[3]);
      else std::swap(c[1], c[2]);
    }
    p.mpCorners.insert(p.mpCorners.end(), c, c + 4);
    p.mpFace.push_back(f);
    if (stats_) ++(i == 4 ? stats_->quads : stats_->triangles);
  };
  std::vector<glm::dvec3> ring;
  for (uint32_t f = 0; f < p.faceStart.size(); ++f) {
    const uint32_t b = p.faceStart[f], n = p.faceCount[f];
    if (n == 3) {
      add(f, {b, b + 1, b + 2});
      continue;
    }
    if (n == 4) {
      add(f, {b, b + 1, b + 2, b + 3});
      continue;
    }
    ring.clear();
    for (uint32_t i = 0; i < n; ++i) {
      const float* v = &p.P[0][size_t(p.verts[b + i]) * 3];
      ring.push_back({v[0], v[1], v[2]});
    }
    auto q = project(ring);
    if (convex(q)) {
      uint32_t i = 1;
      for (; i + 2 < n; i += 2) add(f, {b, b + i, b + i + 1, b + i + 2});
      if (i + 1 < n) add(f, {b, b + i, b + i + 1});
      if (stats_) ++stats_->fannedPolygons;
    } else {
      std::vector<std::array<uint32_t, 3>> tris;
      // Ear clipping is cubic in the worst case; dumps hold grids of small polygons.
      if (n > 4096) a.fail(cat("polygon ", f, " is not convex and has ", n, " vertices; ingest triangulates up to 4096"));
      if (!simple(q) || !earClip(q, tris)) a.fail(cat("polygon ", f, " (", n, " vertices) is self-intersecting or degenerate; ingest cannot triangulate it"));
      for (auto& t : tris) add(f, {b + t[0], b + t[1], b + t[2]});
      if (stats_) ++stats_->earClippedPolygons;
    }
  }
}

void DumpHandler::registerVars(const Args& a, Prim& p) {
  bool grew = false;
  if (collect_) {
    for (const auto& v : p.vars) {
      for (const auto& o : outputsFor(v.decl)) {
        const bool perVertex = perVertexClass(v.decl.storage);
        auto it = schema_.find(o.name);
        if (it == schema_.end()) {
          schema_.emplace(o.name, SchemaEntry{o.type, perVertex});
          schemaOrder_.push_back(o.name);
          grew = true;
        } else {
          if (it->second.type != o.type)
            a.fail(cat("\"", v.decl.name, "\" is a ", toString(o.type), " here and a ", toString(it->second.type), " elsewhere"));
          grew |= perVertex && !it->second.perVertex;
          it->second.perVertex |= perVertex;
        }
      }
    }
    // Ci/Oi from Color/Opacity are constant: per micropolygon unless a primitive gives them per vertex.
    for (const char* n : {"Ci", "Oi"})
      if (!schema_.count(n)) {
        schema_.emplace(n, SchemaEntry{AttrType::Color, false});
        schemaOrder_.push_back(n);
        grew = true;
      }
  }
  if (!emit_) return;
  if (optimistic_) {
    if (!sink_) {
      ownMeta_ = scannedMeta(file_);
      meta_ = &ownMeta_;
      sink_ = openSink(ownMeta_);
    } else if (grew) {
      throw SchemaGrew{};
    }
  }
  // Per-vertex storage of per-face values needs a vertex per face corner.
  p.unshare = false;
  for (const auto& v : p.vars) {
    if (faceVaryingClass(v.decl.storage)) p.unshare = true;
    if (v.decl.storage == StorageClass::Uniform)
      for (const auto& o : outputsFor(v.decl)) {
        int i = meta_->schema.find(o.name);
        p.unshare = p.unshare || (i >= 0 && meta_->schema.attrs[size_t(i)].rate == AttrRate::Vertex);
      }
  }
}

void DumpHandler::emitPrim(const Prim& p) {
  const StoreMeta& meta = *meta_;
  const Attrs& s = cur();
  const double open = meta.shutterOpen, close = meta.shutterClose;

  // Knots: the primitive's and its transform's times, clipped to the shutter.
  std::vector<double> knots;
  {
    std::set<double> ts(p.times.begin(), p.times.end());
    ts.insert(s.ctm.times.begin(), s.ctm.times.end());
    if (ts.empty() || !(close > open)) {
      knots = {ts.empty() ? open : std::clamp(open, *ts.begin(), *ts.rbegin())};
    } else {
      const double lo = std::clamp(*ts.begin(), open, close), hi = std::clamp(*ts.rbegin(), open, close);
      knots.push_back(lo);
      for (double t : ts)
        if (t > lo && t < hi) knots.push_back(t);
      if (hi > lo) knots.push_back(hi);
    }
  }
  uint32_t schedule = 0;
  if (knots.size() > 1) {
    if (knots != lastSchedule_) lastSchedule_ = knots, lastScheduleIndex_ = sink_->addSchedule(knots);
    schedule = lastScheduleIndex_;
  }
  const uint32_t K = uint32_t(knots.size());
  const uint32_t nCorners = uint32_t(p.verts.size());
  const uint32_t nV = p.unshare ? nCorners : p.nP;
  auto srcVertex = [&](uint32_t v) { return p.unshare ? p.verts[v] : v; };

  // Positions: geometry at t (linear between copies, exact at the copies' times), then the CTM at t.
  positions_.resize(size_t(K) * nV);
  for (uint32_t k = 0; k < K; ++k) {
    const double t = knots[k];
    size_t i0 = 0, i1 = 0;
    double u = 0;
    if (p.P.size() > 1) {
      if (t <= p.times.front()) {
        i0 = i1 = 0;
      } else if (t >= p.times.back()) {
        i0 = i1 = p.P.size() - 1;
      } else {
        i0 = size_t(std::upper_bound(p.times.begin(), p.times.end(), t) - p.times.begin()) - 1;
        i1 = i0 + 1;
        u = (t - p.times[i0]) / (p.times[i1] - p.times[i0]);
      }
    }
    const glm::dmat4 M = s.ctm.at(t);
    const bool identity = isIdentity(M);
    const float* a = p.P[i0].data();
    const float* b = p.P[i1].data();
    for (uint32_t v = 0; v < nV; ++v) {
      const size_t sv = size_t(srcVertex(v)) * 3;
      glm::dvec3 q(a[sv], a[sv + 1], a[sv + 2]);
      if (u > 0) q = q * (1 - u) + glm::dvec3(b[sv], b[sv + 1], b[sv + 2]) * u;
      positions_[size_t(k) * nV + v] = identity ? glm::vec3(q) : glm::vec3(glm::dvec3(M * glm::dvec4(q, 1.0)));
    }
  }

  // Corners.
  const size_t nMp = p.mpFace.size();
  corners_.resize(nMp * 4);
  for (size_t i = 0; i < nMp * 4; ++i) {
    uint32_t c = p.mpCorners[i];
    corners_[i] = c == kNoCorner ? kNoCorner : p.unshare ? c : p.verts[c];
  }
  // Face of each face-corner (for uniform values stored per vertex).
  std::vector<uint32_t> cornerFace;
  if (p.unshare) {
    cornerFace.resize(nCorners);
    for (uint32_t f = 0; f < p.faceStart.size(); ++f)
      for (uint32_t i = 0; i < p.faceCount[f]; ++i) cornerFace[p.faceStart[f] + i] = f;
  }

  // Attributes, in schema order.
  const glm::dmat4 M0 = s.ctm.at(knots[0]);
  const bool identity = isIdentity(M0);
  const glm::dmat3 L(M0), Ninv = glm::transpose(glm::inverse(glm::dmat3(M0)));
  const auto& attrs = meta.schema.attrs;
  attrData_.resize(attrs.size());
  GridInput g;
  g.attrs.resize(attrs.size());
  for (size_t ai = 0; ai < attrs.size(); ++ai) {
    const AttrDecl& ad = attrs[ai];
    auto& out = attrData_[ai];
    out.clear();
    const Var* var = nullptr;
    int element = 0;
    for (const auto& v : p.vars) {
      for (const auto& o : outputsFor(v.decl))
        if (o.name == ad.name) var = &v, element = o.element;
      if (var) break;
    }
    const int nc = componentCount(ad.type);
    const size_t count = ad.rate == AttrRate::Vertex ? nV : nMp;
    if (!var) {
      if (ad.name != "Ci" && ad.name != "Oi") continue;  // absent in this grid
      const glm::vec3 c = ad.name == "Ci" ? s.color : s.opacity;
      for (size_t i = 0; i < count; ++i) out.insert(out.end(), {c.x, c.y, c.z});
    } else {
      const StorageClass sc = var->decl.storage;
      const size_t stride = size_t(var->decl.components()) * size_t(var->decl.arraySize);
      const bool perVertexSource = perVertexClass(sc);
      if (ad.rate == AttrRate::Micropolygon && perVertexSource) continue;  // cannot happen with one file
      out.resize(count * size_t(nc));
      for (size_t i = 0; i < count; ++i) {
        size_t idx;
        if (sc == StorageClass::Constant) idx = 0;
        else if (ad.rate == AttrRate::Micropolygon) idx = p.mpFace[i];
        else if (faceVaryingClass(sc)) idx = i;
        else if (sc == StorageClass::Uniform) idx = cornerFace[i];
        else idx = srcVertex(uint32_t(i));
        const float* src = &var->values[idx * stride + size_t(element) * size_t(nc)];
        float* dst = &out[i * size_t(nc)];
        if (identity || nc != 3 || ad.type == AttrType::Color) {
          std::copy(src, src + nc, dst);
        } else {
          glm::dvec3 v(src[0], src[1], src[2]);
          v = ad.type == AttrType::Point ? glm::dvec3(M0 * glm::dvec4(v, 1.0)) : ad.type == AttrType::Normal ? Ninv * v : L * v;
          dst[0] = float(v.x), dst[1] = float(v.y), dst[2] = float(v.z);
        }
      }
    }
    g.attrs[ai].f = out;
  }
  g.schedule = schedule;
  g.numVertices = nV;
  g.positions = positions_;
  g.corners = corners_;
  g.gridId = gridId_++;
  g.flags = uint8_t((s.sides == 2 ? kTwoSided : 0) | (s.matte ? kMatte : 0));
  sink_->addGrid(g);
  if (stats_) {
    stats_->micropolygons += nMp;
    if (K > 1 && !g.standsStill()) stats_->movingMicropolygons += nMp;  // the writer stores a still grid static
  }
}

void DumpHandler::finish(const std::string& file) {
  if (inMotion_) fail(file, "ends inside a motion block (MotionBegin without MotionEnd)");
  if (opt_.frame && sawFrame_ && !frameFound_) {
    std::string seen;
    for (auto f : framesSeen_) seen += cat(seen.empty() ? "" : " ", f);
    fail(file, "has no FrameBegin ", *opt_.frame, " (frames: ", seen, ")");
  }
}

StoreMeta DumpHandler::scannedMeta(const std::string& file) const {
  StoreMeta m;
  m.frame = opt_.frame ? *opt_.frame : frameNumber_ ? *frameNumber_ : 1;
  m.fps = opt_.fps;
  if (!haveCamera_) fail(file, "has no WorldBegin: no camera to ingest against");
  m.shutterOpen = cameraOpen_, m.shutterClose = cameraClose_;
  m.cameras = {camera_};
  // Ci and Oi first, then the other variables in order of appearance.
  auto add = [&](const std::string& n) {
    const auto& e = schema_.at(n);
    m.schema.attrs.push_back(AttrDecl{n, e.type, e.perVertex ? AttrRate::Vertex : AttrRate::Micropolygon, AttrCodec::Lossless});
  };
  if (!schema_.count("Ci")) {
    m.schema.attrs.push_back(AttrDecl{"Ci", AttrType::Color, AttrRate::Micropolygon, AttrCodec::Lossless});
    m.schema.attrs.push_back(AttrDecl{"Oi", AttrType::Color, AttrRate::Micropolygon, AttrCodec::Lossless});
  } else {
    add("Ci"), add("Oi");
  }
  for (const auto& n : schemaOrder_)
    if (n != "Ci" && n != "Oi") add(n);
  if (m.schema.attrs.size() > 64) fail(file, "declares ", m.schema.attrs.size(), " output variables; a store holds at most 64");
  m.provenance = cat("reshutter ingest ", std::filesystem::path(file).filename().string());
  m.validate(file);
  return m;
}

void runPass(const std::string& path, DumpHandler& h, int pass, bool warn, const IngestOptions& opt, uint64_t& bytes) {
  rib::ReaderOptions ro;
  ro.warnUnsupported = warn;  // a second pass meets the same requests
  rib::Reader reader(ro);
  reader.declare("blurP", "vertex point");  // dump writers use it without declaring it
  struct Progressing : rib::RequestHandler {
    Progressing(DumpHandler& h, const rib::Reader& r, const IngestOptions& opt, int pass) : h(h), r(r), opt(opt), pass(pass) {}
    DumpHandler& h;
    const rib::Reader& r;
    const IngestOptions& opt;
    int pass;
    uint64_t n = 0;
    bool handle(const Request& req, const Args& a) override {
      if (opt.progress && (++n & 1023) == 0) opt.progress(pass, r.bytesRead());
      return h.handle(req, a);
    }
  } p(h, reader, opt, pass);
  reader.parseFile(path, p);
  bytes = reader.bytesRead();
  h.finish(path);
}

}  // namespace

StoreMeta scanDump(const std::string& ribPath, const IngestOptions& options) {
  DumpHandler h(Mode::Scan, ribPath, options, nullptr, nullptr, nullptr);
  uint64_t bytes = 0;
  runPass(ribPath, h, 1, true, options, bytes);
  return h.scannedMeta(ribPath);
}

void ingestDumpInto(const std::string& ribPath, const StoreMeta& meta, GridSink& sink, IngestStats& stats, const IngestOptions& options) {
  DumpHandler h(Mode::Emit, ribPath, options, &meta, &sink, &stats);
  runPass(ribPath, h, 2, false, options, stats.ribBytes);
}

IngestStats ingestDump(const std::string& ribPath, const std::string& storePath, const IngestOptions& options) {
  using Clock = std::chrono::steady_clock;
  auto t0 = Clock::now();
  {
    // One pass when the first primitive's variables are every primitive's (dumps are uniform).
    IngestStats stats;
    std::unique_ptr<StoreWriter> writer;
    try {
      DumpHandler h(Mode::Optimistic, ribPath, options, nullptr, nullptr, &stats);
      h.openSink = [&](const StoreMeta& m) {
        writer = std::make_unique<StoreWriter>(storePath, m, options.writer);
        return writer.get();
      };
      runPass(ribPath, h, 2, true, options, stats.ribBytes);
      if (!writer) writer = std::make_unique<StoreWriter>(storePath, h.scannedMeta(ribPath), options.writer);
      stats.write = writer->close();
      stats.passes = 1;
      stats.ingestSeconds = std::chrono::duration<double>(Clock::now() - t0).count();
      return stats;
    } catch (const SchemaGrew&) {
      writer.reset();  // removes its temporary file
      note(cat(ribPath, ": later primitives carry more variables than the first; reading the dump twice"));
    }
  }
  IngestStats stats;
  stats.passes = 2;
  auto t1 = Clock::now();
  StoreMeta meta = scanDump(ribPath, options);
  auto t2 = Clock::now();
  StoreWriter writer(storePath, meta, options.writer);
  ingestDumpInto(ribPath, meta, writer, stats, options);
  stats.write = writer.close();
  stats.scanSeconds = std::chrono::duration<double>(t2 - t0).count();  // includes the abandoned first try
  stats.ingestSeconds = std::chrono::duration<double>(Clock::now() - t2).count();
  (void)t1;
  return stats;
}

}  // namespace reshutter::shade
