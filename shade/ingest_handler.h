// Dump ingest's insides (not part of shade/'s interface; shade/ingest.h is): the RIB request
// handler that keeps the graphics state a dump needs and turns polygon requests into store grids,
// and the types its parts share. Its definitions are split by what they own:
//   ingest_requests.cpp  the requests that set state: frames, camera options, transforms,
//                        attributes, motion blocks; the store metadata the dump implies
//   ingest_polygons.cpp  polygon requests read into a Prim: counts, positions, faces, variables,
//                        splitting into quads and triangles, the schema they need
//   ingest_grids.cpp     a Prim sent as a grid: knots, positions per knot, corners, attributes
//   ingest.cpp           the passes (one optimistic, or scan then emit) behind shade/ingest.h
// See shade/ingest.h for the semantics and the choices made.
#pragma once

#include <algorithm>
#include <cstdint>
#include <functional>
#include <map>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include <glm/mat4x4.hpp>
#include <glm/vec3.hpp>

#include "rib/rib.h"
#include "shade/ingest.h"
#include "shade/scene.h"
#include "store/model.h"

namespace reshutter::shade::ingest {

// ---------------------------------------------------------------------------------------------
// The state a primitive is ingested under (from the shared graphics state, shade/rib_state.h)

inline bool isIdentity(const glm::dmat4& m) { return m == glm::dmat4(1.0); }

struct Attrs {
  MotionXform ctm;       // object → camera
  bool reverse = false;  // ring order reversed (orientation against the transform's handedness)
  bool twoSided = true, matte = false;
  glm::vec3 color{1.f}, opacity{1.f};  // the first knot's
};

// ---------------------------------------------------------------------------------------------
// Variables → store attributes

struct OutAttr {
  std::string name;
  store::AttrType type;
  int element;  // array element of the RIB variable
};

/// The store attributes one RIB variable becomes; empty when it cannot be stored.
std::vector<OutAttr> outputsFor(const rib::ParamDecl& d);

inline bool perVertexClass(rib::StorageClass c) {
  using rib::StorageClass;
  return c == StorageClass::Vertex || c == StorageClass::Varying || c == StorageClass::FaceVarying || c == StorageClass::FaceVertex;
}
inline bool faceVaryingClass(rib::StorageClass c) { return c == rib::StorageClass::FaceVarying || c == rib::StorageClass::FaceVertex; }

// ---------------------------------------------------------------------------------------------
// Primitives

struct Var {
  rib::ParamDecl decl;
  std::vector<float> values;
};

/// One polygon primitive (all motion copies), ready to become a grid.
struct Prim {
  std::string request;
  std::vector<uint32_t> faceStart, faceCount;  // face-corner ranges (a face's loops one after another)
  std::vector<uint32_t> faceLoops;             // per face: where its loop sizes start in loopSizes (faces with holes only: empty otherwise)
  std::vector<uint32_t> loopSizes;             // the vertex count of each loop of faces with holes
  std::vector<uint32_t> verts;                 // vertex per face-corner
  uint32_t nP = 0;
  std::vector<std::vector<float>> P;  // per copy, 3 · nP, object space
  std::vector<double> times;          // copies' times; empty: static
  std::vector<Var> vars;              // the first copy's
  // Shading per knot: "Cs" / "Os" values of every copy (empty: the same in every copy).
  std::vector<std::vector<float>> knotCs, knotOs;
  // Micropolygons as face-corner indices, 4 each (kNoCorner: triangle), and their source face.
  std::vector<uint32_t> mpCorners, mpFace;
  bool unshare = false;  // one grid vertex per face-corner (facevarying/uniform-per-vertex data)
};

/// A polygon request's face structure, as given.
struct PolygonCounts {
  std::vector<uint32_t> loops;   // per polygon: loop count
  std::vector<uint32_t> nverts;  // per loop: vertex count
  bool explicitVerts = false;    // the request lists vertex indices (PointsPolygons, PointsGeneralPolygons)
  size_t firstParam = 0;         // where its parameter list starts
};

struct SchemaEntry {
  store::AttrType type;
  bool perVertex;
};

/// Thrown in the optimistic single pass when a primitive needs a variable (or a per-vertex rate)
/// the store's schema, fixed at the first primitive, lacks: ingest then falls back to two passes.
struct SchemaGrew {};

/// Modes: scan (collect the schema, no grids), emit (grids against a given schema), optimistic
/// (schema from the first primitive, grids at once; SchemaGrew if a later primitive needs more).
enum class Mode { Scan, Emit, Optimistic };

// ---------------------------------------------------------------------------------------------
// The handler

class DumpHandler final : public rib::RequestHandler {
 public:
  DumpHandler(Mode mode, const std::string& file, const IngestOptions& opt, const store::StoreMeta* meta, store::GridSink* sink, IngestStats* stats)
      : collect_(mode != Mode::Emit),
        emit_(mode != Mode::Scan),
        optimistic_(mode == Mode::Optimistic),
        file_(file),
        opt_(opt),
        meta_(meta),
        sink_(sink),
        stats_(stats) {}
  /// Optimistic mode: opens the sink once the schema is known.
  std::function<store::GridSink*(const store::StoreMeta&)> openSink;
  bool sinkOpen() const { return sink_ != nullptr; }

  bool handle(const rib::Request& r, const rib::Args& a) override;
  void finish(const std::string& file);
  store::StoreMeta scannedMeta(const std::string& file) const;

 private:
  // The graphics state: options, camera, transforms, attributes, motion blocks of transforms.
  Scene scene_{nullptr};
  bool haveCamera_ = false;
  store::Camera camera_;
  double cameraOpen_ = 0, cameraClose_ = 0;
  std::optional<int64_t> frameNumber_;

  // Frames
  bool sawFrame_ = false, skipping_ = false, done_ = false, frameFound_ = false;
  std::vector<int64_t> framesSeen_;

  // Motion blocks of primitives: copies of one request, one per knot
  bool inMotion_ = false;
  std::vector<double> motionTimes_;
  std::string motionRequest_;
  size_t motionCount_ = 0;
  Prim prim_;

  // Schema (pass 1)
  std::vector<std::string> schemaOrder_;
  std::map<std::string, SchemaEntry> schema_;
  std::vector<double> shadingTimes_;  // the first primitive with shading per knot sets them

  // Output
  bool collect_, emit_, optimistic_;
  std::string file_;
  store::StoreMeta ownMeta_;
  const IngestOptions& opt_;
  const store::StoreMeta* meta_;
  store::GridSink* sink_;
  IngestStats* stats_;
  uint32_t gridId_ = 0;
  std::vector<double> lastSchedule_;
  uint32_t lastScheduleIndex_ = 0;
  std::vector<glm::vec3> positions_;
  std::vector<uint32_t> corners_;
  std::vector<std::vector<float>> attrData_;

  /// The state a primitive declared now is ingested under.
  Attrs cur() const;

  // ingest_requests.cpp: each takes its requests and returns false for any other.
  void beginFrame(const rib::Request& r, const rib::Args& a);
  void endFrame(const rib::Request& r, const rib::Args& a);
  void beginWorld();
  void beginMotion(const rib::Request& r, const rib::Args& a);
  void endMotion(const rib::Request& r, const rib::Args& a);
  bool ignored(std::string_view n);

  // ingest_polygons.cpp
  bool polygons(const rib::Request& r, const rib::Args& a);
  void readPolygons(const rib::Request& r, const rib::Args& a, Prim& p, bool first);
  void readVariables(const rib::Request& r, const rib::Args& a, const std::vector<rib::Param>& params, Prim& p);
  void split(const rib::Args& a, Prim& p);
  void registerVars(const rib::Args& a, Prim& p);
  bool collectSchema(const rib::Args& a, const Prim& p);
  bool needsVertexPerCorner(const Prim& p) const;

  // ingest_grids.cpp
  void emitPrim(const Prim& p);
  uint32_t scheduleFor(const std::vector<double>& knots);
  void gridAttributes(const Prim& p, const Attrs& s, double firstKnot, store::GridInput& g);
  /// A motion block whose copies carry different Cs or Os: the store shades in time.
  void noteShadingPerKnot(const rib::Args& a);
};

}  // namespace reshutter::shade::ingest
