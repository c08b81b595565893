// Micropolygon-dump ingest: reads a RIB dump of shaded, moving micropolygons (the reference
// workflow's form: motion-blurred PointsPolygons carrying premultiplied "Cs", opacity "Os" and the
// shutter-close position "blurP", under CoordSysTransform "camera") and streams it into a store
// without shading: Ci = Cs, Oi = Os.
//
// A store's schema is fixed before its first grid. Ingest reads the dump once, taking the schema
// from the camera and the first primitive's variables (every grid of a dump carries the same
// ones); if a later primitive brings another variable (or gives per vertex what was per
// micropolygon), it drops that store and reads the dump twice: a scan for camera, shutter and
// every variable, then the grids. Memory is the reader's chunk plus one request plus the store
// writer's budget, whatever the dump's size.
//
// Semantics and the choices made where RenderMan leaves room:
// - Geometry: PointsPolygons, PointsGeneralPolygons, Polygon, GeneralPolygon. Triangles and quads
//   are kept as given; convex polygons with more corners are fanned into quads (and a last
//   triangle); non-convex simple polygons are triangulated by ear clipping; polygons with holes
//   (more than one loop) are triangulated with their holes (shade/triangulate.h), face-varying
//   data following each loop vertex.
// - Motion: MotionBegin [t0 … tn-1] around n copies of a primitive or of transforms; "blurP" (no
//   motion block) is P at shutter close. Knots are the union of the primitive's and its moving
//   transform's times, clipped to the shutter (positions interpolated at the shutter ends), as
//   camera-space positions linear between knots. A grid whose knots are all equal (blurP = P: a
//   static object) is stored static and not counted as moving.
// - Appearance per knot: copies whose Cs or Os differ make the store shade in time (StoreMeta::
//   shadingTimes: the first such block's knots, "Ci@k" / "Oi@k" at Ci's rate; a later block's
//   colours are blended onto those times), and the re-sampler blends each sample's colour at its
//   own time. Of the other variables (N, st, …) the first copy's are kept; if a later copy's
//   differ, a warning says so once. Positions are per knot.
// - Variables: every declared variable of a primitive becomes a store attribute of the same name
//   (Cs → Ci, Os → Oi): per vertex for vertex/varying/facevarying, per micropolygon for
//   uniform/constant (per vertex if another primitive gives it per vertex). Arrays (float[2] st)
//   become one attribute per element, "st[0]" "st[1]"; integers are stored as floats;
//   string, matrix, bool and hpoint variables are skipped with a warning. Point, vector and
//   normal variables are transformed to camera space (normals by the inverse transpose).
// - Graphics state: options, camera, transforms, attributes and motion blocks of transforms are
//   read by the same interpreter as `shade` (shade/rib_state.h), so a dump and a scene with the
//   same header get the same camera (named "world", the options at the first WorldBegin).
// - Orientation: corners are stored in the order that is front-facing in camera space for the
//   orientation in force, as RenderMan defines it: a ring is reversed when the orientation differs
//   from the handedness of the primitive's transform ("inside", ReverseOrientation, or a mirroring
//   transform after the orientation was set). Sides 2 sets the two-sided flag; Matte 1 the matte flag.
// - Frames: with several FrameBegin blocks, --frame N picks block N (default: the first).
#pragma once

#include <cstdint>
#include <functional>
#include <optional>
#include <string>

#include "store/model.h"
#include "store/writer.h"

namespace reshutter::shade {

struct IngestOptions {
  std::optional<int64_t> frame;  // FrameBegin block to read and the store's frame number
  store::Rational fps{24, 1};
  store::WriterOptions writer;
  /// Called now and then with (pass 1 or 2, decompressed bytes read so far).
  std::function<void(int pass, uint64_t bytes)> progress;
};

struct IngestStats {
  uint64_t ribBytes = 0;    // decompressed RIB bytes per pass
  uint64_t primitives = 0;  // polygon requests (motion copies count once)
  uint64_t polygons = 0;    // faces read
  uint64_t micropolygons = 0, quads = 0, triangles = 0;
  uint64_t fannedPolygons = 0, earClippedPolygons = 0;
  uint64_t movingMicropolygons = 0;
  int passes = 1;  // 2 when the schema grew after the first primitive
  double scanSeconds = 0, ingestSeconds = 0;
  store::WriteStats write;
};

/// Pass 1 alone: the store metadata (camera, shutter, schema, frame) the dump implies.
store::StoreMeta scanDump(const std::string& ribPath, const IngestOptions& options = {});

/// Pass 2 alone into any sink, with metadata from scanDump (tests and benchmarks).
void ingestDumpInto(const std::string& ribPath, const store::StoreMeta& meta, store::GridSink& sink, IngestStats& stats, const IngestOptions& options = {});

/// Into a new store at `storePath` (written atomically): one pass, or two when needed (above).
IngestStats ingestDump(const std::string& ribPath, const std::string& storePath, const IngestOptions& options = {});

}  // namespace reshutter::shade
