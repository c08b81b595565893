// The scene description the shading pass consumes, and the RenderMan-style builder that makes it.
// Owns the graphics state (attributes, transforms that move, motion blocks, cameras, lights,
// displays) and turns every primitive call into a Primitive that carries its own moving
// object→camera transform, deformation keys and attribute snapshot. Both the RIB handler
// (shade/rib_scene.h) and the built-in demo (shade/demo_scene.h) drive this one builder, so the
// two cannot disagree about RenderMan semantics.
//
// Spaces: the builder's current transform always maps object space to camera space (RenderMan's
// CTM); WorldBegin records it as world→camera. Camera motion (motion blocks before WorldBegin)
// is therefore folded into every primitive's transform, and positions come out in the camera
// space of their own knot time.
#pragma once

#include <array>
#include <cstdint>
#include <functional>
#include <map>
#include <memory>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include <glm/mat4x4.hpp>
#include <glm/vec2.hpp>
#include <glm/vec3.hpp>

#include "shade/subdivision.h"
#include "shade/trim.h"
#include "store/model.h"

namespace reshutter::shade {

/// A transform that may move: matrices at strictly increasing times, linear in between (element
/// by element, so transformed points move linearly between knots, as the store assumes).
struct MotionXform {
  std::vector<double> times;     // empty: static
  std::vector<glm::dmat4> mats;  // one per time, or one when static

  MotionXform() : mats{glm::dmat4(1.0)} {}
  explicit MotionXform(const glm::dmat4& m) : mats{m} {}
  MotionXform(std::vector<double> t, std::vector<glm::dmat4> m) : times(std::move(t)), mats(std::move(m)) {}
  bool moving() const { return mats.size() > 1; }
  glm::dmat4 at(double t) const;
  /// this · rhs (rhs applies first); the times are the union of both.
  MotionXform then(const MotionXform& rhs) const;
};

/// Records on `camera` the transform `worldToCamera` gives it: where it stands at the motion's first
/// time, and - when it moves - its transform at each of the motion's times (Camera::clipMotion()
/// keeps a shutter's worth).
void recordCameraMotion(store::Camera& camera, const MotionXform& worldToCamera);

/// Segment i and weight w of time t in increasing `times` (at least two): t lies w of the way
/// from times[i] to times[i + 1], clamped at the ends (RenderMan holds the first and last knot's
/// values outside a motion block).
void locate(const std::vector<double>& times, double t, size_t& i, double& w);

/// A value given at knot times (Color, Opacity and shader parameters inside motion blocks).
template <typename T>
struct Animated {
  std::vector<double> times;  // empty: constant
  std::vector<T> values;      // one per time, or one
  Animated() = default;
  explicit Animated(T v) : values{v} {}
  T at(double t) const;
};

/// The built-in surface shaders (RenderMan standard shaders; shade/shaders.h has the formulas).
enum class SurfaceKind : uint8_t { Constant, Matte, Metal, Plastic, DefaultSurface, PaintedPlastic };

struct SurfaceShader {
  SurfaceKind kind = SurfaceKind::DefaultSurface;
  double Ka = 1, Kd = 0.5, Ks = 0.5, roughness = 0.1;
  glm::dvec3 specularColor{1.0};
  std::string textureName;    // paintedplastic's "texturename", a RIS PxrTexture's "filename": Cs × texture ("" = none)
  bool textureFlipT = false;  // look up at 1 - t (PxrTexture's default "invertT")
  /// A RIS material's own colour and presence: they replace the primitive's Cs and Os (RIS
  /// materials ignore Color and Opacity unless connected to them).
  std::optional<glm::dvec3> color, opacity;
  /// RenderMan's defaults for `name`; false (and defaultsurface) for a shader not built in.
  static bool named(const std::string& name, SurfaceShader& out);
  SurfaceShader lerp(const SurfaceShader& b, double w) const;
};

enum class LightKind : uint8_t { Ambient, Distant, Point, Spot, Uber, Face /* resolved only: a one-sided Point */ };

/// uberlight's controls (Barzel, "Lighting Controls for Computer Cinematography", 1997): a light
/// at the origin of its space shining down +Z, its beam a superellipse cross-section with soft
/// edges, cut on and off along Z, with a distance falloff.
struct UberLight {
  bool omni = false;      // lighttype "omni": no beam shape
  bool parallel = false;  // parallelrays: light along +Z, the cross-section in x, y
  double cuton = 0.01, cutoff = 1e6, nearedge = 0, faredge = 0;
  double falloff = 0, falloffdist = 1, maxintensity = 1;
  double shearx = 0, sheary = 0, width = 1, height = 1, wedge = 0.1, hedge = 0.1, roundness = 1;
  double beamdistribution = 0;
};
/// What a light's shadow rays aim at: its centre (Point), or points spread over an emitter in
/// light space, centred at the origin and facing +Z (RenderMan's RIS lights' convention).
enum class LightShape : uint8_t { Point, Sphere, Disk, Rect };

/// A light source as declared (parameters in its shader space; `xform` maps that to camera space).
struct Light {
  LightKind kind = LightKind::Point;
  double intensity = 1;
  glm::dvec3 color{1.0};
  glm::dvec3 from{0.0}, to{0.0, 0.0, 1.0};
  double coneAngle = 0.5235987755982988;        // radians(30)
  double coneDeltaAngle = 0.08726646259971647;  // radians(5)
  double beamDistribution = 2;
  LightShape shape = LightShape::Point;
  double width = 0, height = 0;  // Sphere, Disk: diameter in `width`; Rect: its sides (light space)
  double angle = 0;              // Distant: the source's angular diameter in radians (soft shadows)
  bool oneSided = false;         // Disk, Rect: emits towards +Z only, with the emitter's cosine
  bool radiance = false;         // intensity is radiance: Cl also scales with the emitter's area
  UberLight uber;                // Uber: its controls
  bool shadows = false;          // traces shadow rays (shade/shadows.h)
  std::string name;              // the shader ("spotlight", "PxrRectLight"), for messages
  MotionXform xform;
  /// RenderMan's defaults for `name`; false for a light not built in.
  static bool named(const std::string& name, Light& out);
};

/// Numeric shader/light parameters by bare name ("Kd", "intensity", "from", "lightcolor").
using ParamMap = std::map<std::string, std::vector<double>>;

/// A RIS request (Bxdf, Light, Pattern, Integrator, DisplayFilter, SampleFilter) as the scene
/// gave it: kept for the shading pass, whose built-in models are what evaluates it.
struct RisNode {
  std::string request, type, handle;
  ParamMap numbers;
  std::map<std::string, std::vector<std::string>> strings;
  std::map<std::string, std::string> references;  // "reference color diffuseColor": "handle:resultRGB"
};
void applyParams(SurfaceShader& s, const ParamMap& params);
void applyParams(Light& l, const ParamMap& params);

/// A cubic basis as RenderMan's Basis gives it: P(u) = [u³ u² u 1] · M · G over four control
/// points G, with `m` row-major (row i: the coefficients of u^(3-i)) and M = scale · m. The
/// built-in bases keep integer `m` and the fraction in `scale`, so the weights at u = 0 and 1 are
/// exact and neighbouring patches of a mesh evaluate bit-identical points on their shared edge.
struct CubicBasis {
  std::array<double, 16> m{-1, 3, -3, 1, 3, -6, 3, 0, -3, 3, 0, 0, 1, 0, 0, 0};  // bezier
  double scale = 1;
  int step = 3;  // control points between the patches of a mesh
  /// RenderMan's named bases ("bezier", "b-spline", "catmull-rom", "hermite", "power") with
  /// their default steps; false for another name.
  static bool named(const std::string& name, CubicBasis& out);
  /// Weights of the four control points at u, and their derivatives.
  void weights(double u, double w[4]) const;
  void derivatives(double u, double d[4]) const;
};

/// The bases a Basis attribute holds (null: RenderMan's default, bezier both ways).
const std::array<CubicBasis, 2>& cubicBases(const std::shared_ptr<const std::array<CubicBasis, 2>>& basis);

/// Attributes captured by each primitive when it is declared.
struct Attributes {
  Animated<glm::dvec3> color{glm::dvec3(1.0)}, opacity{glm::dvec3(1.0)};
  Animated<SurfaceShader> surface{SurfaceShader{}};
  std::vector<uint32_t> lights;  // indices into FrameScene::lights that illuminate
  double shadingRate = 1.0;
  double motionFactor = 0.0;  // GeometricApproximation "motionfactor"
  bool matte = false, twoSided = true;
  bool orientationRH = false;                              // Orientation: "lh" (RenderMan's default, "outside") or "rh"
  bool transmission = true;                                // Attribute "visibility" "transmission": casts shadows
  bool lightShadows = false;                               // Attribute "light" "shadows" "on": lights declared under it cast shadows
  uint32_t objectId = 0;                                   // 0: unnamed; otherwise 1 + index into FrameScene::objectNames
  uint32_t bxdf = 0;                                       // 0: none; otherwise 1 + index into FrameScene::risNodes
  std::shared_ptr<const std::array<CubicBasis, 2>> basis;  // Basis (u, v); null: bezier, bezier
  std::shared_ptr<const TrimLoops> trim;                   // TrimCurve (NuPatch only); null: none
  bool trimKeepsInside = false;                            // Attribute "trimcurve" "sense" "outside"
};

enum class PrimKind : uint8_t { Sphere, Cylinder, Cone, Disk, Torus, Hyperboloid, Paraboloid, Patch, Bicubic, Subdiv, Curve, Point, Nurbs };

/// One deformation key of a primitive's shape.
struct Shape {
  /// Quadric parameters in RenderMan argument order (Sphere: radius zmin zmax thetamax;
  /// Cylinder: radius zmin zmax thetamax; Cone: height radius thetamax; Disk: height radius
  /// thetamax; Torus: rmajor rminor phimin phimax thetamax; Hyperboloid: thetamax, its line from
  /// P[0] to P[1]; Paraboloid: rmax zmin zmax thetamax). Angles in degrees.
  std::array<double, 5> q{};
  /// Bilinear patch corners P00 P10 P01 P11 (RIB order); a triangle repeats P01 as P11.
  std::array<glm::dvec3, 4> P{};
  /// Bicubic patch: its 16 control points, u fastest, in the basis of Primitive::basis.
  std::vector<glm::dvec3> cv;
  /// Subdivision face: the deformation key of Primitive::subdiv (fractional between keys).
  double key = 0;
  /// Curve segment: its control points in `cv` (2 linear, 4 cubic in the v basis), widths at
  /// its ends in q[0], q[1], and (q[2] = 1) ribbon normals at its ends in P[0], P[1].
  /// Point: its centre in P[0], its width in q[0].
  /// Both face the camera: `eye` is the camera in object space (w = 1) or, orthographic, the
  /// direction of view (w = 0), set by Primitive::shapeAt.
  glm::dvec4 eye{0.0, 0.0, 0.0, 1.0};
  /// NURBS span: the order_u x order_v homogeneous control points that shape it, u fastest, as
  /// (x, y, z) in `cv` and w in `cw`.
  std::vector<double> cw;
};

/// One span of a NuPatch: the knots around it and the part of its parameter range it covers.
struct NurbsSpan {
  int orderU = 4, orderV = 4;
  std::vector<double> knotsU, knotsV;     // 2 · order knots each; the span is [knots[order-1], knots[order])
  double u0 = 0, u1 = 1, v0 = 0, v1 = 1;  // the primitive's (0..1) maps onto [u0, u1] × [v0, v1]
};

/// Vertex data of a polygon mesh or patch (N in object space), shared by all the patches its
/// faces become, so a big mesh costs one copy of its data. Each array is empty, one value per
/// point (vertex/varying) or one per face (uniform).
struct MeshData {
  std::vector<glm::dvec3> N, Cs, Os;
  std::vector<glm::dvec2> st;  // empty or per point
  size_t points = 0, faces = 0;
};

/// A parametric surface over (u, v) ∈ [0,1]², ready to dice. Polygons become patches (quads, and
/// triangles as patches whose last edge is collapsed).
struct Primitive {
  PrimKind kind = PrimKind::Patch;
  std::vector<double> times;  // deformation knot times; empty: one key
  std::vector<Shape> keys;
  bool triangle = false;
  std::shared_ptr<const MeshData> mesh;  // patches with vertex data; null otherwise
  std::array<uint32_t, 4> meshPoint{};   // the corners' (P00 P10 P01 P11) points in `mesh`
  uint32_t meshFace = 0;
  std::shared_ptr<const MotionXform> xform;  // object → camera
  std::shared_ptr<const Attributes> attrs;
  std::shared_ptr<const std::array<CubicBasis, 2>> basis;  // Bicubic: the (u, v) bases
  std::shared_ptr<const SubdivSurface> subdiv;             // Subdiv: the limit surface
  int ptexFace = 0;                                        // Subdiv: which of its faces
  bool orthographicView = false;                           // Curve, Point: how they face the camera
  std::shared_ptr<const NurbsSpan> nurbs;                  // Nurbs: its knots and range
  bool flipNormals = false;                                // orientation differs from the coordinate system's handedness

  /// The shape at time t: keys interpolated; camera-facing kinds get the eye at t.
  Shape shapeAt(double t) const;
  /// The keys interpolated at t, nothing more.
  Shape keyAt(double t) const;
  /// The corner values of one of `mesh`'s arrays (N, Cs, Os); false when it is absent.
  bool corners(const std::vector<glm::dvec3>& data, std::array<glm::dvec3, 4>& out) const;
  bool cornerST(std::array<glm::dvec2, 4>& out) const;
  /// Every knot time of the primitive (transform and deformation), sorted, unique.
  std::vector<double> knotTimes() const;
};

/// Output variables the shading pass can compute, and their store types.
struct OutputVar {
  std::string name;
  store::AttrType type;
};
/// The known output variables ("P", "N", "Ng", "s", "t", "u", "v", "Cs", "Os", "depth",
/// "specular"); "id"/"z" are the store's own object ids and depths.
const std::vector<OutputVar>& knownOutputVars();

/// Options and camera of one frame (RenderMan options, frozen at WorldBegin).
struct FrameOptions {
  int64_t frame = 1;
  store::Camera camera;         // the primary ("world") camera; worldToCamera at shutter open
  double frameAspectRatio = 0;  // 0: from Format
  double shutterOpen = 0, shutterClose = 0;
  std::vector<store::Camera> namedCameras;
  std::vector<std::string> outputs;  // requested output variables, in request order, unique
  int pixelSamples[2] = {1, 1};
  std::vector<RisNode> risOptions;  // Integrator, DisplayFilter, SampleFilter, Hider
  /// Option "searchpath" "texture": ':'-separated directories, "&" already replaced by the
  /// previous path; relative ones are taken from the RIB file's directory ("" = that directory).
  std::string textureSearchPath;
};

/// A volume the scene holds (RIB `Volume "blobbydso:impl_openvdb"`, as RenderMan writes OpenVDB
/// volumes): its file (as given: relative paths are the RIB file's directory's) and density
/// grid, placed by the transform current at the request - the file's world space is the object's
/// space. The shading pass records it in the store; the re-sampler renders it.
struct SceneVolume {
  std::string path, grid = "density";
  MotionXform objectToCamera;
};

/// Everything WorldEnd hands to the shading pass.
struct FrameScene {
  FrameOptions options;
  MotionXform worldToCamera;
  std::vector<Light> lights;
  std::vector<Primitive> prims;
  std::vector<SceneVolume> volumes;
  std::vector<std::string> objectNames;
  std::vector<RisNode> risNodes;       // Bxdf, Light, Pattern of the world block
  std::vector<uint32_t> globalLights;  // lights that illuminate every primitive (RIS lights)
  /// Primitives the scene gave that the shading pass cannot make, by request ("Curves": 3).
  std::map<std::string, uint64_t> skipped;
  uint64_t culledArchives = 0;  // delayed archives whose bound is out of view: never read
  std::string source;           // "scene.rib", "built-in demo"
};

/// The RenderMan-style builder. Calls mirror the RI; inside motionBegin/motionEnd every call of
/// the block is collected and combined at motionEnd (transforms into a moving coordinate
/// system, primitives into deformation keys, Color/Opacity/Surface into animated values).
/// Errors are reshutter::Error naming `where()`, which the RIB handler sets per request.
class Scene {
 public:
  using FrameCallback = std::function<void(FrameScene&)>;
  explicit Scene(FrameCallback onWorldEnd);

  std::string where = "scene";  // prefix for errors and warnings

  // Options
  void format(int width, int height, double pixelAspect);
  void frameAspectRatio(double a);
  void screenWindow(double l, double r, double b, double t);
  void perspective(double fovDegrees);
  void orthographic();
  void clipping(double nearClip, double farClip);
  void depthOfField(double fstop, double focalLength, double focalDistance);
  void shutter(double open, double close);
  void pixelSamples(int x, int y);
  void display(const std::string& name, const std::string& mode);
  void camera(const std::string& name);
  void frameBegin(int64_t n);
  void frameEnd();
  void worldBegin();
  void worldEnd();

  // Attributes and transforms
  void attributeBegin();
  void attributeEnd();
  void transformBegin();
  void transformEnd();
  void identity();
  void transform(const glm::dmat4& m);
  void concatTransform(const glm::dmat4& m);
  void translate(double x, double y, double z);
  void rotate(double degrees, double x, double y, double z);
  void scale(double x, double y, double z);
  void coordinateSystem(const std::string& name);
  void coordSysTransform(const std::string& name);
  void orientation(const std::string& o);
  void reverseOrientation();
  void sides(int n);
  void color(const glm::dvec3& c);
  void opacity(const glm::dvec3& o);
  void surface(const std::string& name, const ParamMap& params, const std::map<std::string, std::string>& strings = {});
  void textureSearchPath(const std::string& path);
  void lightSource(const std::string& name, const std::string& handle, const ParamMap& params, const std::map<std::string, std::string>& strings = {});
  void transmission(bool on);
  void lightShadows(bool on);
  void illuminate(const std::string& handle, bool on);
  void shadingRate(double r);
  void motionFactor(double f);
  void matte(bool on);
  void identifier(const std::string& name);
  /// Retained geometry: primitives between objectBegin and objectEnd are kept under `handle`
  /// (relative to the object's own space) instead of drawn; objectInstance draws them under the
  /// current transform, with the current attributes wherever the definition set none of its own.
  void objectBegin(const std::string& handle);
  void objectEnd();
  void objectInstance(const std::string& handle);
  /// A RIS request: options before WorldBegin, nodes inside (a Bxdf binds to the attributes).
  void ris(RisNode node);
  /// Counts a primitive request the shading pass cannot make (reported per frame).
  void skippedPrimitive(std::string_view request);
  /// An OpenVDB volume under the current transform (SceneVolume).
  void volume(const std::string& path, const std::string& grid);
  /// Counts a delayed archive whose bound was culled (never read).
  void archiveCulled() { ++frame_.culledArchives; }

  // Motion
  void motionBegin(const std::vector<double>& times);
  void motionEnd();
  bool inMotion() const { return motion_.active; }

  // Primitives
  void sphere(double radius, double zmin, double zmax, double thetamax);
  void cylinder(double radius, double zmin, double zmax, double thetamax);
  void cone(double height, double radius, double thetamax);
  void disk(double height, double radius, double thetamax);
  void torus(double rmajor, double rminor, double phimin, double phimax, double thetamax);
  void hyperboloid(const glm::dvec3& point1, const glm::dvec3& point2, double thetamax);
  void paraboloid(double rmax, double zmin, double zmax, double thetamax);
  /// Bilinear patch, corners in RIB order P00 P10 P01 P11; optional per-corner Cs/Os/N.
  struct VertexData {
    std::vector<glm::dvec3> N, Cs, Os;
    std::vector<glm::dvec2> st;
  };
  void patch(const std::array<glm::dvec3, 4>& P, const VertexData& vd = {});
  /// Patch meshes (Patch "bicubic" is a 4 × 4 one): nu × nv control points, u fastest, split
  /// into patches by the current Basis steps (bicubic) or one per cell (bilinear). Vertex data
  /// is varying (one value per patch corner) or uniform (one per patch).
  void patchMesh(bool bicubic, int nu, bool uPeriodic, int nv, bool vPeriodic, const std::vector<glm::dvec3>& P, const VertexData& vd = {});
  void basis(const CubicBasis& u, const CubicBasis& v);
  /// TrimCurve: the loops that trim the NuPatches that follow (null: none); `keepInside` is
  /// Attribute "trimcurve" "sense" (trim.h).
  void trimCurve(std::shared_ptr<const TrimLoops> loops);
  void trimSense(bool keepInside);
  /// Curves: one ribbon primitive per segment, `width` wide, facing the camera unless `N` (one
  /// per varying value) orients it; cubic ones use the current v basis and step. `width` holds
  /// one value per varying value (per segment end) or one for all; vertex data is varying or
  /// uniform (per curve).
  void curves(bool cubic, const std::vector<int>& nvertices, bool periodic, const std::vector<glm::dvec3>& P, const std::vector<double>& width,
              const std::vector<glm::dvec3>& N, const VertexData& vd = {});
  /// NuPatch: a non-uniform rational B-spline surface of any orders (RenderMan's arguments;
  /// `Pw` homogeneous, w > 0), one primitive per non-empty knot span inside [umin, umax] ×
  /// [vmin, vmax]; vertex data varying (per span corner) or uniform (per span).
  void nuPatch(int nu, int uorder, const std::vector<double>& uknot, double umin, double umax, int nv, int vorder, const std::vector<double>& vknot,
               double vmin, double vmax, const std::vector<glm::dvec4>& Pw, const VertexData& vd = {});
  /// Points: camera-facing discs, `width` across (one per point or one for all).
  void points(const std::vector<glm::dvec3>& P, const std::vector<double>& width, const VertexData& vd = {});
  /// A subdivision mesh: one primitive per ptex face with a limit surface (subdivision.h);
  /// vertex data per point (varying, interpolated linearly) or per face (uniform).
  void subdivisionMesh(SubdivScheme scheme, const std::vector<int>& nverts, const std::vector<int>& verts, const SubdivTags& tags,
                       const std::vector<glm::dvec3>& P, const VertexData& vd = {});
  /// General polygons: `nverts` per face, `verts` indices into P (and the vertex data).
  void pointsPolygons(const std::vector<int>& nverts, const std::vector<int>& verts, const std::vector<glm::dvec3>& P, const VertexData& vd = {});
  void polygon(const std::vector<glm::dvec3>& P, const VertexData& vd = {});
  /// PointsGeneralPolygons: `nloops` per polygon (the first loop its outline, the others holes),
  /// `nverts` per loop, `verts` indices into P. Polygons with holes are triangulated
  /// (triangulate.h); one-loop polygons are made as pointsPolygons makes them.
  void generalPolygons(const std::vector<int>& nloops, const std::vector<int>& nverts, const std::vector<int>& verts, const std::vector<glm::dvec3>& P,
                       const VertexData& vd = {});

  const FrameOptions& options() const { return options_; }
  /// The world block being read: its options and camera as WorldBegin froze them.
  const FrameScene& world() const { return frame_; }
  bool inWorld() const { return inWorld_; }
  /// The state a primitive declared now would carry.
  const MotionXform& currentTransform() const { return cur_.ctm; }
  const Attributes& currentAttributes() const { return *cur_.attrs; }
  /// True when the current orientation is opposite to the handedness of the current transform
  /// (a primitive's normals and ring order are then reversed).
  bool orientationFlipped() const;
  int framesShaded() const { return framesDone_; }

 private:
  enum class Pending : uint8_t { None, Concat, Set, Color, Opacity, Surface, Prim };
  struct Motion {
    bool active = false;
    std::vector<double> times;
    Pending kind = Pending::None;
    std::vector<glm::dmat4> mats;
    std::vector<glm::dvec3> colors;
    std::vector<SurfaceShader> surfaces;
    std::vector<std::vector<Primitive>> prims;  // per key: the primitives one call made
  };
  enum class Block : uint8_t { Attribute, Transform, Frame, World, Object };
  struct ObjectDefinition {
    std::shared_ptr<const Attributes> attrsAtBegin;  // prims still carrying these take the instance's
    std::vector<Primitive> prims;
    std::map<std::string, uint64_t> skipped;  // primitives the definition could not make
  };
  struct State {
    std::shared_ptr<Attributes> attrs;
    MotionXform ctm;
    Block block = Block::Attribute;  // the block whose Begin pushed this state
  };
  void addLight(Light l, const std::string& handle, bool global);
  void push(Block b);
  State pop(Block b, const char* request);

  Attributes& mutableAttrs();
  void applyTransform(const glm::dmat4& m, bool set);
  void addPrims(std::vector<Primitive> prims);
  void emitFaces(const std::vector<int>& nverts, const std::vector<int>& verts, const std::vector<glm::dvec3>& P, const VertexData& vd,
                 std::vector<Primitive>& out);
  Primitive basePrim(PrimKind kind);
  /// Sphere, Cylinder, Cone, Disk and Torus: one keyframe of parameters, the first `used` checked finite.
  void quadric(PrimKind kind, const std::array<double, 5>& q, size_t used);
  bool motionTake(Pending kind);
  /// Vertex counts that add up to the indices given, every index one of `points`; errors name `what`.
  void checkIndices(const std::vector<int>& counts, const std::vector<int>& indices, size_t points, const char* what) const;
  /// Vertex data of a mesh whose values sit at `varying` corners or on `uniform` pieces: the
  /// arrays of vd that fit (N only when `withN`; st varying only), one warning naming `what` for
  /// each that does not; null when none fits.
  std::shared_ptr<const MeshData> cornerData(const VertexData& vd, size_t varying, size_t uniform, const char* what, bool withN) const;
  [[noreturn]] void error(const std::string& what) const;

  FrameCallback onWorldEnd_;
  FrameOptions options_, savedFrameOptions_;
  bool inFrame_ = false, inWorld_ = false;
  std::vector<State> stack_;
  State cur_;
  std::shared_ptr<const MotionXform> ctmShared_;
  std::map<std::string, MotionXform> coordSystems_;
  std::map<std::string, uint32_t> lightHandles_;
  std::map<std::string, uint32_t> objectIds_;
  FrameScene frame_;
  Motion motion_;
  std::map<std::string, ObjectDefinition> objects_;
  ObjectDefinition* recording_ = nullptr;  // the object being defined
  int framesDone_ = 0;
};

}  // namespace reshutter::shade
