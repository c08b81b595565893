// The micropolygon data model shared by every producer (shade, ingest) and consumer (resample):
// attribute schema, cameras, motion schedules and store metadata, the grid a producer hands to
// the writer, and the decoded tile part a reader hands back.
//
// Conventions (RenderMan's): camera space looks down +z, x right, y up; raster space has its origin
// at the top-left pixel corner, x right, y down. Times are in frames relative to the store's frame
// (`Shutter` semantics). Positions are camera-space points, linear in camera space between knots.
#pragma once

#include <cmath>
#include <cstdint>
#include <span>
#include <string>
#include <vector>

#include <glm/mat4x4.hpp>
#include <glm/vec2.hpp>
#include <glm/vec3.hpp>

namespace reshutter::store {

// ---------------------------------------------------------------------------------------------
// Attributes

enum class AttrType : uint8_t { Float = 0, Color = 1, Point = 2, Vector = 3, Normal = 4, UInt = 5 };
/// How often an attribute is given: once per vertex (RenderMan vertex/varying; interpolated
/// bilinearly across the micropolygon) or once per micropolygon (uniform/constant).
enum class AttrRate : uint8_t { Vertex = 0, Micropolygon = 1 };
/// Payload codec per attribute. Lossless is the default; the others are opt-in with the error
/// bounds stated in store/codec.h and asserted by tests/store_codec_test.cpp.
enum class AttrCodec : uint8_t { Lossless = 0, Half = 1, Unorm16 = 2, Oct32 = 3 };

int componentCount(AttrType t);
const char* toString(AttrType t);
const char* toString(AttrRate r);
const char* toString(AttrCodec c);
bool parseAttrType(const std::string& s, AttrType& out);
bool parseAttrCodec(const std::string& s, AttrCodec& out);

struct AttrDecl {
  std::string name;  // "Ci", "Oi", "N", "s", "id", a shader's output variable ...
  AttrType type = AttrType::Float;
  AttrRate rate = AttrRate::Vertex;
  AttrCodec codec = AttrCodec::Lossless;
  bool operator==(const AttrDecl&) const = default;
};

/// Every store has "Ci" (premultiplied colour) and "Oi" (per-channel opacity), both colours;
/// any further attribute is an output variable.
struct Schema {
  static constexpr size_t kMaxAttributes = 64;
  std::vector<AttrDecl> attrs;
  int find(const std::string& name) const;  // -1 when absent
  int ci() const { return find("Ci"); }
  int oi() const { return find("Oi"); }
  bool operator==(const Schema&) const = default;
};

// ---------------------------------------------------------------------------------------------
// Cameras

enum class Projection : uint8_t { Perspective = 0, Orthographic = 1 };

/// A thin lens (RenderMan's `DepthOfField fstop focallength focaldistance`): an aperture of radius
/// focalLength / (2 fstop) in camera-space units, in focus at camera depth focalDistance. The
/// default (fstop 0) is a pinhole; so is an infinite f-stop.
struct Lens {
  double fstop = 0, focalLength = 0, focalDistance = 0;
  bool active() const { return fstop > 0 && std::isfinite(fstop) && focalLength > 0 && focalDistance > 0 && std::isfinite(focalLength) && std::isfinite(focalDistance); }
  double radius() const { return active() ? focalLength / (2.0 * fstop) : 0.0; }
  bool operator==(const Lens&) const = default;
};

struct Camera {
  std::string name = "world";
  Projection projection = Projection::Perspective;
  double fovDegrees = 90.0;       // perspective: full angle across the shorter screen axis
  int width = 640, height = 480;  // raster resolution
  double pixelAspect = 1.0;
  double screenWindow[4] = {0, 0, 0, 0};  // left right bottom top; all zero = RenderMan default
  double nearClip = 1e-4, farClip = 1e30;
  glm::dmat4 worldToCamera{1.0};  // at the shutter's open (for a moving camera, motionWorldToCamera[0])
  Lens lens;                      // format version 4
  /// A moving camera (format version 5): its world-to-camera transform at `motionTimes`
  /// (frame-relative, strictly increasing, from the shutter's open to its close), elementwise
  /// linear between them as RenderMan's moving transforms are. Empty for a camera that stands
  /// still. Positions in the store are in the primary camera's space of their own knot time.
  std::vector<double> motionTimes;
  std::vector<glm::dmat4> motionWorldToCamera;

  bool moving() const { return motionTimes.size() > 1; }
  /// The world-to-camera transform at frame-relative time t (held outside the motion's times).
  glm::dmat4 worldToCameraAt(double t) const;
  /// Keeps the motion over [open, close] only: the transforms at its ends and at the motion's
  /// times between; worldToCamera becomes the one at `open`. Standing still there: no motion.
  void clipMotion(double open, double close);

  /// Screen window after applying RenderMan's default (the frame aspect ratio over [-1,1]).
  void effectiveScreenWindow(double out[4]) const;
  bool operator==(const Camera&) const;
};

/// The largest lens displacement over camera depths [z0, z1] in units of the projection's scale
/// (raster x moves by ax times it): radius · max |1/d - 1/z|. 0 without a lens (or, for a camera,
/// an orthographic one); infinite when the depths reach the eye plane.
double circleOfConfusion(const Lens& lens, double z0, double z1);
double circleOfConfusion(const Camera& camera, double z0, double z1);

/// Camera space → raster space for one camera: x_r = ax·x/z + bx (perspective) or ax·x + bx.
struct Projector {
  double ax = 1, bx = 0, ay = 1, by = 0;
  bool perspective = true;
  double nearClip = 1e-4;
  explicit Projector(const Camera& cam);
  Projector() = default;
  glm::dvec2 project(const glm::dvec3& p) const {
    double iz = perspective ? 1.0 / p.z : 1.0;
    return {ax * p.x * iz + bx, ay * p.y * iz + by};
  }
  /// Inverse for a point at depth z (used by tests and the demo's framing).
  glm::dvec3 unproject(const glm::dvec2& raster, double z) const;
};

// ---------------------------------------------------------------------------------------------
// Time

/// A frame rate as a rational number of frames per second (24/1, 30000/1001 ...).
struct Rational {
  int64_t num = 24, den = 1;
  double value() const { return double(num) / double(den); }
  bool operator==(const Rational&) const = default;
};
/// Parses "24", "29.97" (→ 30000/1001), "30000/1001", "23.976" (→ 24000/1001).
bool parseRational(const std::string& s, Rational& out);

/// Motion knot times of a set of micropolygons. Schedule 0 of every store is the static one (one
/// knot). Each tile part names one schedule; a RIB scene may mix `MotionBegin [0 1]` with
/// `MotionBegin [0 0.5 1]`, and keeping each schedule exact costs one small table entry instead of
/// per-micropolygon times or a resampled union.
using Schedule = std::vector<double>;

/// Every time of `a` and `b`, increasing, each once.
std::vector<double> unionTimes(const std::vector<double>& a, const std::vector<double>& b);
/// `open`, the times of `times` strictly inside (open, close), and `close` (when later than open).
std::vector<double> timesWithin(const std::vector<double>& times, double open, double close);

// ---------------------------------------------------------------------------------------------
// Store metadata

/// A light the shading pass used, as a volume rendered at re-sample time sees it: camera space at
/// the shading time, RenderMan's point / distant / spot / ambient terms (area lights as a point
/// at their centre, the one-sided ones with their emitter's cosine; uberlight as a point).
struct StoredLight {
  enum class Kind : uint8_t { Ambient, Distant, Point, Spot, Face };
  Kind kind = Kind::Point;
  glm::dvec3 position{0.0};
  glm::dvec3 axis{0.0, 0.0, 1.0};  // distant: the direction light travels; spot, face: the cone / emitter axis (unit)
  glm::dvec3 colour{1.0};          // intensity · lightcolor
  double cosOuter = 0, cosInner = 0, beam = 2;
  /// Light arriving at camera-space point P: `L` towards the light (unnormalised; unit for a
  /// distant light), `Cl` its colour there. False for ambient lights and points outside a cone.
  bool illuminate(const glm::dvec3& P, glm::dvec3& L, glm::dvec3& Cl) const;
  bool operator==(const StoredLight&) const = default;
};

/// A volume the scene itself holds (RIB `Volume "blobbydso:impl_openvdb"`): the OpenVDB file and
/// its density grid, placed by the object's transform (the file's world space → camera space) at
/// each of `times` (frame-relative; one entry when it does not move).
struct StoredVolume {
  std::string path, density = "density";
  std::vector<double> times{0.0};
  std::vector<glm::dmat4> fileToCamera{glm::dmat4(1.0)};
  bool operator==(const StoredVolume&) const = default;
};

/// The inputs of the shading's view-dependent terms, which a store carries per vertex when it was
/// shaded for re-evaluation (`shade --view-dependent`) on the grids whose shader has one (a
/// specular lobe, a headlight, or a diffuse term lit on the side facing the eye), so that a render
/// from another camera re-evaluates them for its own eye: with N = ±Nspec facing the eye,
/// Ci = (Cvi or CviBack, the side N is) + Kspec · S(V), where S(V) = Σ_k Lvis.k · Cl_k ·
/// max(0, N·H_k)^(1 / specRoughness) over the stored lights (H_k the half vector), or for
/// specRoughness -1 (defaultsurface's headlight) S(V) = (V·N)², or 0 for specRoughness -2 (no
/// lobe: only the side). specRoughness 0 marks a vertex without these inputs (a grid sharing the
/// part with one that has them), whose Ci stands. Lvis.k is light k's share reaching the vertex
/// (its shadows, and 0 where the light does not light it).
struct ViewTerm {
  static constexpr const char* kViewIndependent = "Cvi";  // colour: the rest of Ci, lit on the side Nspec points to
  static constexpr const char* kBackSide = "CviBack";     // colour: the same lit on the other side
  static constexpr const char* kWeight = "Kspec";         // colour
  static constexpr const char* kNormal = "Nspec";         // normal: the unit shading normal
  static constexpr const char* kRoughness = "specRoughness";
  static constexpr double kHeadlight = -1, kNoLobe = -2;  // specRoughness values besides a lobe's roughness
  static constexpr size_t kMaxLights = 16;  // lights with a visibility attribute (the others count as visible)
  static std::string visibility(size_t light) { return "Lvis." + std::to_string(light); }
};

struct StoreMeta {
  int64_t frame = 1;
  Rational fps{24, 1};
  double shutterOpen = 0.0, shutterClose = 1.0;    // frame-relative, as RenderMan's Shutter
  std::vector<Schedule> schedules{Schedule{0.0}};  // [0] is static
  std::vector<Camera> cameras{Camera{}};           // [0] is the primary: its raster space tiles the store
  Schema schema;
  int tileSize = 32;  // pixels of the primary camera's raster
  std::string provenance;
  /// Shading in time (frame-relative, increasing): empty when the frame was shaded once. Otherwise
  /// "Ci" / "Oi" hold the shading at shadingTimes[0] and the schema declares "Ci@k" / "Oi@k"
  /// (per-vertex colours) for the shading at shadingTimes[k] - and "name@k" for any output
  /// variable carried in time; a part whose grids' shading changed over the shutter carries them
  /// (kEffectShadedInTime), the others only the first.
  std::vector<double> shadingTimes;
  uint64_t shadedInTimeGrids = 0;  // grids that carry shading at every time (counted by the writer)
  static constexpr size_t kMaxShadingTimes = 16;
  /// The lights the shading pass used and the scene's own volumes (format version 3), for volumes
  /// rendered at re-sample time.
  std::vector<StoredLight> lights;
  std::vector<StoredVolume> volumes;
  /// The schema name of attribute `base` ("Ci", "Oi", "N") at shading time k (k = 0: base itself).
  static std::string timedName(const std::string& base, size_t k);
  /// k for a name timedName() makes for k >= 1 ("Ci@2" → 2, "N@3" → 3), 0 for any other name.
  static size_t timedIndex(const std::string& name);
  /// The base of such a name ("N@3" → "N"); the name itself for any other.
  static std::string timedBase(const std::string& name);

  /// Throws Error(where, ...) when inconsistent: no cameras, knots not increasing or outside the
  /// shutter, schema without Ci/Oi, duplicate attribute names, non-finite values.
  void validate(const std::string& where) const;
};

// ---------------------------------------------------------------------------------------------
// Producer input: one grid of micropolygons sharing vertices

/// Per-micropolygon flags.
enum MpFlag : uint8_t { kMatte = 1, kTwoSided = 2 };
/// A corner index marking the fourth corner of a triangle.
constexpr uint32_t kNoCorner = 0xffffffffu;

/// Attribute values for one grid; `f` for float-based types, `u` for UInt. Empty = absent.
struct AttrValues {
  std::span<const float> f;
  std::span<const uint32_t> u;
  bool present() const { return !f.empty() || !u.empty(); }
};

/// Corners are in ring order (p0 p1 p2 p3 around the quad); the bilinear quad is
/// P(u,v) = (1-u)(1-v)·p0 + u(1-v)·p1 + u·v·p2 + (1-u)·v·p3, a triangle is (p0 p1 p2).
struct GridInput {
  uint32_t schedule = 0;  // index into StoreMeta::schedules
  uint32_t numVertices = 0;
  std::span<const glm::vec3> positions;  // knots × numVertices, knot-major, camera space
  std::span<const uint32_t> corners;     // 4 per micropolygon; corners[4i+3] == kNoCorner: triangle
  uint32_t objectId = 0;
  uint32_t gridId = 0;
  uint8_t flags = 0;              // MpFlag bits, for every micropolygon of the grid
  std::vector<AttrValues> attrs;  // parallel to Schema::attrs
  size_t numMicropolygons() const { return corners.size() / 4; }
  /// Every knot's positions equal the first's, bit for bit: the grid stands still although it
  /// was given several knots (a P + blurP dump's static objects, a motion block that does not
  /// move). The store writer keeps such a grid as static, so re-sampling takes the static path.
  bool standsStill() const;
};

/// Vertices [first, first + count) of knot-major positions (`stride` vertices per knot) are at
/// every knot where they are at the first, bit for bit: the one rule by which the writer stores a
/// grid static and the re-sampler draws a chunk of a moving part on its static path.
bool verticesStandStill(std::span<const glm::vec3> positions, size_t stride, size_t first, size_t count);

/// Where producers (the shading pass, dump ingest, synthetic scenes) send their grids. The store
/// writer is one; tests and benchmarks plug in others.
class GridSink {
 public:
  virtual ~GridSink() = default;
  /// Registers knot times; returns the index for GridInput::schedule (0 = static).
  virtual uint32_t addSchedule(const Schedule& knotTimes) = 0;
  virtual void addGrid(const GridInput& grid) = 0;
};

// ---------------------------------------------------------------------------------------------
// Reader output: one decoded tile part

struct AttrArray {
  std::vector<float> f;     // components × count, interleaved per element
  std::vector<uint32_t> u;  // for AttrType::UInt
  bool present() const { return !f.empty() || !u.empty(); }
};

struct TilePart {
  uint32_t numVertices = 0, numMicropolygons = 0, numKnots = 1;
  std::vector<glm::vec3> positions;  // knots × numVertices, knot-major
  std::vector<uint32_t> corners;     // 4 per micropolygon
  std::vector<uint32_t> objectId, gridId;
  std::vector<uint8_t> flags;
  std::vector<AttrArray> attrs;  // parallel to Schema::attrs; empty when absent in this part
  size_t memoryBytes() const;
  const glm::vec3& position(uint32_t knot, uint32_t vertex) const { return positions[size_t(knot) * numVertices + vertex]; }
};

}  // namespace reshutter::store
