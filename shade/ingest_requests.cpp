// Dump ingest, the requests that set state (shade/ingest_handler.h): which frame is read, the
// camera options, transforms and coordinate systems, attributes, motion blocks, and the store
// metadata all of that implies. Polygon requests go to ingest_polygons.cpp.
#include <cmath>
#include <filesystem>
#include <set>

#include <glm/gtc/matrix_transform.hpp>
#include <glm/gtc/type_ptr.hpp>

#include "common/error.h"
#include "common/log.h"
#include "shade/ingest_handler.h"

namespace reshutter::shade::ingest {

using namespace store;
using rib::Args;
using rib::Request;

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

namespace {

/// An integer argument in [lo, hi] (converting an out-of-range double to int is undefined).
int64_t integerArg(const Args& a, size_t i, double lo, double hi) {
  const double v = a.number(i);
  if (!(v >= lo && v <= hi) || v != std::trunc(v)) a.fail(cat("argument ", i + 1, " must be an integer in [", lo, ", ", hi, "], not ", v));
  return int64_t(v);
}

}  // namespace

bool DumpHandler::handle(const Request& r, const Args& a) {
  const std::string_view n = r.name;
  if (done_) return true;
  if (n == "FrameBegin") return beginFrame(a), true;
  if (n == "FrameEnd") return endFrame(), true;
  if (skipping_) return true;
  if (inMotion_ && n != "MotionEnd") {
    if (motionCount_ > 0 && n != motionRequest_) a.fail(cat("a motion block holds copies of one request; found ", n, " after ", motionRequest_));
    motionRequest_ = std::string(n);
  }
  if (cameraOption(n, a) || transform(n, a) || attribute(r, a)) return true;
  if (n == "MotionBegin") return beginMotion(a), true;
  if (n == "MotionEnd") return endMotion(a), true;
  if (n == "PointsPolygons" || n == "PointsGeneralPolygons" || n == "Polygon" || n == "GeneralPolygon") return polygons(r, a);
  return ignored(n);
}

// ---------------------------------------------------------------------------------------------
// Frames: one per store, --frame picks it (default: the first).

void DumpHandler::beginFrame(const Args& a) {
  int64_t f = a.count() ? integerArg(a, 0, -1e15, 1e15) : 0;
  framesSeen_.push_back(f);
  sawFrame_ = true;
  inFrame_ = true;
  skipping_ = opt_.frame ? f != *opt_.frame : frameFound_;
  if (!skipping_) frameFound_ = true, frameNumber_ = f;
}

void DumpHandler::endFrame() {
  if (!skipping_ && frameFound_) done_ = true;  // one frame per store
  inFrame_ = false, skipping_ = false;
}

void DumpHandler::finish(const std::string& file) {
  if (inMotion_) fail(file, "ends inside a motion block (MotionBegin without MotionEnd)");
  if (opt_.frame && sawFrame_ && !frameFound_) {
    std::string seen;
    for (auto f : framesSeen_) seen += cat(seen.empty() ? "" : " ", f);
    fail(file, "has no FrameBegin ", *opt_.frame, " (frames: ", seen, ")");
  }
}

// ---------------------------------------------------------------------------------------------
// Camera and options

bool DumpHandler::cameraOption(std::string_view n, const Args& a) {
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
  if (n == "Projection") return setProjection(a), true;
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
  if (n == "WorldBegin") return beginWorld(), true;
  if (n == "WorldEnd") return inWorld_ = false, true;
  return false;
}

void DumpHandler::setProjection(const Args& a) {
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
}

/// The camera is the options in force at the first WorldBegin.
void DumpHandler::beginWorld() {
  inWorld_ = true;
  worldToCamera_ = cur().ctm;
  coordSys_["world"] = worldToCamera_;
  if (haveCamera_) return;
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

// ---------------------------------------------------------------------------------------------
// Transforms and coordinate systems

bool DumpHandler::transform(std::string_view n, const Args& a) {
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
  return false;
}

/// Inside a motion block, a transform is one knot's copy (applied at MotionEnd).
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

// ---------------------------------------------------------------------------------------------
// Attributes

bool DumpHandler::attribute(const Request& r, const Args& a) {
  const std::string_view n = r.name;
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
  if (n == "Color" || n == "Opacity") return setColorOrOpacity(r, a), true;
  return false;
}

/// Inside a motion block only the first knot's value is kept (a warning says when they differ).
void DumpHandler::setColorOrOpacity(const Request& r, const Args& a) {
  const std::string_view n = r.name;
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
      return;
    }
  }
  (n == "Color" ? cur().color : cur().opacity) = c;
}

// ---------------------------------------------------------------------------------------------
// Motion blocks: n copies of one transform (a moving transform) or of one primitive (its knots).

void DumpHandler::beginMotion(const Args& a) {
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
}

void DumpHandler::endMotion(const Args& a) {
  if (!inMotion_) a.fail("MotionEnd without MotionBegin");
  inMotion_ = false;
  if (motionCount_ == 0) return;
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
}

/// Already-shaded micropolygons need no shading, display or sampling settings: taken and
/// dropped (counting as a motion copy inside a motion block). False for anything else.
bool DumpHandler::ignored(std::string_view n) {
  static const std::set<std::string_view> ignoredRequests = {"Display",
                                                             "DisplayChannel",
                                                             "PixelSamples",
                                                             "PixelFilter",
                                                             "PixelVariance",
                                                             "Exposure",
                                                             "Quantize",
                                                             "Hider",
                                                             "ShadingRate",
                                                             "ShadingInterpolation",
                                                             "Surface",
                                                             "Atmosphere",
                                                             "Interior",
                                                             "Exterior",
                                                             "Displacement",
                                                             "LightSource",
                                                             "AreaLightSource",
                                                             "Illuminate",
                                                             "GeometricApproximation",
                                                             "Option",
                                                             "Attribute",
                                                             "Imager",
                                                             "Declare",
                                                             "DisplayChannel",
                                                             "RelativeDetail"};
  if (!ignoredRequests.count(n)) return false;
  if (inMotion_) ++motionCount_;
  return true;
}

}  // namespace reshutter::shade::ingest
