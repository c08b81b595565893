// Dump ingest, the requests that are its own (shade/ingest_handler.h): which frame is read, the
// camera a store is ingested against, polygon motion blocks, the requests a shaded dump has no
// use for, and the store metadata all of that implies. Options, transforms, attributes and motion
// blocks of transforms are the shared graphics state (shade/rib_state.h); polygon requests go to
// ingest_polygons.cpp.
#include <cmath>
#include <filesystem>
#include <set>

#include "common/error.h"
#include "common/log.h"
#include "shade/ingest_handler.h"
#include "shade/rib_state.h"

namespace reshutter::shade::ingest {

using namespace store;
using rib::Args;
using rib::Request;

bool DumpHandler::handle(const Request& r, const Args& a) {
  const std::string_view n = r.name;
  if (done_) return true;
  if (n == "FrameBegin") return beginFrame(r, a), true;
  if (n == "FrameEnd") return endFrame(r, a), true;
  if (skipping_) return true;
  if (inMotion_ && n != "MotionEnd") {
    if (motionCount_ > 0 && n != motionRequest_) a.fail(cat("a motion block holds copies of one request; found ", n, " after ", motionRequest_));
    motionRequest_ = std::string(n);
  }
  if (n == "MotionBegin") return beginMotion(r, a), true;
  if (n == "MotionEnd") return endMotion(r, a), true;
  if (applyStateRequest(scene_, r, a)) {
    if (n == "WorldBegin") beginWorld();
    return true;
  }
  if (n == "PointsPolygons" || n == "PointsGeneralPolygons" || n == "Polygon" || n == "GeneralPolygon") return polygons(r, a);
  return ignored(n);
}

Attrs DumpHandler::cur() const {
  const Attributes& s = scene_.currentAttributes();
  Attrs out;
  out.ctm = scene_.currentTransform();
  out.reverse = scene_.orientationFlipped();
  out.twoSided = s.twoSided, out.matte = s.matte;
  out.color = glm::vec3(s.color.values.front()), out.opacity = glm::vec3(s.opacity.values.front());
  for (const auto* a : {&s.color, &s.opacity})
    for (const glm::dvec3& v : a->values)
      if (v != a->values.front())
        warnOnce("ingest-appearance-knots", cat(scene_.where, ": Color or Opacity changes inside a motion block; ingest keeps the first knot's value"));
  return out;
}

// ---------------------------------------------------------------------------------------------
// Frames: one per store, --frame picks it (default: the first).

void DumpHandler::beginFrame(const Request& r, const Args& a) {
  int64_t f = a.count() ? integerArg(a, 0, -1e15, 1e15) : 0;
  framesSeen_.push_back(f);
  sawFrame_ = true;
  skipping_ = opt_.frame ? f != *opt_.frame : frameFound_;
  if (skipping_) return;
  frameFound_ = true, frameNumber_ = f;
  applyStateRequest(scene_, r, a);
}

void DumpHandler::endFrame(const Request& r, const Args& a) {
  if (!skipping_ && frameFound_) {
    applyStateRequest(scene_, r, a);
    done_ = true;  // one frame per store
  }
  skipping_ = false;
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
// The camera: the options in force at the first WorldBegin.

void DumpHandler::beginWorld() {
  if (haveCamera_) return;
  haveCamera_ = true;
  const FrameScene& w = scene_.world();
  camera_ = w.options.camera;
  cameraOpen_ = w.options.shutterOpen, cameraClose_ = w.options.shutterClose;
}

StoreMeta DumpHandler::scannedMeta(const std::string& file) const {
  StoreMeta m;
  m.frame = opt_.frame ? *opt_.frame : frameNumber_ ? *frameNumber_ : 1;
  m.fps = opt_.fps;
  if (!haveCamera_) fail(file, "has no WorldBegin: no camera to ingest against");
  m.shutterOpen = cameraOpen_, m.shutterClose = cameraClose_;
  m.cameras = {camera_};
  m.cameras[0].clipMotion(m.shutterOpen, m.shutterClose);
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
  // Shading per knot: Ci@k / Oi@k (each at its base's rate), for every knot after the first.
  if (shadingTimes_.size() > 1) {
    m.shadingTimes = shadingTimes_;
    for (size_t k = 1; k < shadingTimes_.size(); ++k)
      for (const char* base : {"Ci", "Oi"})
        m.schema.attrs.push_back(AttrDecl{StoreMeta::timedName(base, k), AttrType::Color, m.schema.attrs[size_t(m.schema.find(base))].rate, AttrCodec::Lossless});
  }
  if (m.schema.attrs.size() > Schema::kMaxAttributes) fail(file, "declares ", m.schema.attrs.size(), " output variables; a store holds at most ", Schema::kMaxAttributes);
  m.provenance = cat("reshutter ingest ", std::filesystem::path(file).filename().string());
  m.validate(file);
  return m;
}

// ---------------------------------------------------------------------------------------------
// Motion blocks: n copies of one primitive (its knots); copies of a transform are the shared
// state's (a moving transform).

void DumpHandler::beginMotion(const Request& r, const Args& a) {
  applyStateRequest(scene_, r, a);  // checks the knots; transform copies go to the shared state
  motionTimes_ = a.count() == 1 ? a.numbers(0) : std::vector<double>{};
  if (a.count() != 1)
    for (size_t i = 0; i < a.count(); ++i) motionTimes_.push_back(a.number(i));
  inMotion_ = true;
  motionCount_ = 0;
  motionRequest_.clear();
  prim_ = Prim{};
}

void DumpHandler::endMotion(const Request& r, const Args& a) {
  applyStateRequest(scene_, r, a);
  inMotion_ = false;
  if (motionCount_ == 0) return;
  if (motionCount_ != motionTimes_.size())
    a.fail(cat("the motion block has ", motionTimes_.size(), " knots but ", motionCount_, " copies of ", motionRequest_));
  if (!prim_.P.empty()) {
    prim_.times = motionTimes_;
    if (!prim_.knotCs.empty() || !prim_.knotOs.empty()) noteShadingPerKnot(a);
    if (emit_) emitPrim(prim_);
  }
}

/// The first primitive whose copies carry their own Cs or Os makes the store shade in time at
/// its knots; later ones are blended onto those times.
void DumpHandler::noteShadingPerKnot(const Args& a) {
  if (!shadingTimes_.empty() || (meta_ && !meta_->shadingTimes.empty())) return;
  if (motionTimes_.size() > StoreMeta::kMaxShadingTimes)
    a.fail(cat("carries colours at ", motionTimes_.size(), " knots; a store holds at most ", StoreMeta::kMaxShadingTimes, " shading times"));
  if (!collect_) return;
  shadingTimes_ = motionTimes_;
  if (optimistic_ && sink_) throw SchemaGrew{};  // the open store has no room for them
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
