// The RenderMan-style scene builder: graphics state, motion blocks, retained objects → FrameScene
// (the primitives it makes are scene_primitives.cpp's).
#include "shade/scene.h"

#include <algorithm>
#include <cmath>
#include <span>

#include <glm/gtc/matrix_inverse.hpp>
#include <glm/gtc/matrix_transform.hpp>

#include "common/error.h"
#include "common/log.h"
#include "shade/ris.h"

namespace reshutter::shade {

namespace {

glm::dvec3 lerpValue(const glm::dvec3& a, const glm::dvec3& b, double w) { return a + (b - a) * w; }
SurfaceShader lerpValue(const SurfaceShader& a, const SurfaceShader& b, double w) { return a.lerp(b, w); }

bool csIsRightHanded(const MotionXform& x) { return glm::determinant(x.mats[0]) < 0; }

}  // namespace

// Segment and weight of `t` in increasing `times` (clamped at the ends: RenderMan holds the first
// and last knot's values outside the block).
void locate(const std::vector<double>& times, double t, size_t& i, double& w) {
  if (t <= times.front()) {
    i = 0, w = 0;
    return;
  }
  if (t >= times.back()) {
    i = times.size() - 2, w = 1;
    return;
  }
  i = size_t(std::upper_bound(times.begin(), times.end(), t) - times.begin()) - 1;
  w = (t - times[i]) / (times[i + 1] - times[i]);
}

// ---------------------------------------------------------------------------------------------

glm::dmat4 MotionXform::at(double t) const {
  if (mats.size() == 1) return mats[0];
  size_t i;
  double w;
  locate(times, t, i, w);
  if (w == 0) return mats[i];
  if (w == 1) return mats[i + 1];
  return mats[i] * (1.0 - w) + mats[i + 1] * w;
}

void recordCameraMotion(store::Camera& camera, const MotionXform& worldToCamera) {
  camera.worldToCamera = worldToCamera.at(worldToCamera.times.empty() ? 0.0 : worldToCamera.times.front());
  camera.motionTimes.clear(), camera.motionWorldToCamera.clear();
  if (!worldToCamera.moving()) return;
  camera.motionTimes = worldToCamera.times;
  for (double t : worldToCamera.times) camera.motionWorldToCamera.push_back(worldToCamera.at(t));
}

MotionXform MotionXform::then(const MotionXform& rhs) const {
  if (!moving() && !rhs.moving()) return MotionXform(mats[0] * rhs.mats[0]);
  std::vector<double> t = store::unionTimes(times, rhs.times);
  std::vector<glm::dmat4> m;
  m.reserve(t.size());
  for (double ti : t) m.push_back(at(ti) * rhs.at(ti));
  return MotionXform(std::move(t), std::move(m));
}

template <typename T>
T Animated<T>::at(double t) const {
  if (values.size() == 1) return values[0];
  size_t i;
  double w;
  locate(times, t, i, w);
  return lerpValue(values[i], values[i + 1], w);
}
template struct Animated<glm::dvec3>;
template struct Animated<SurfaceShader>;

bool SurfaceShader::named(const std::string& name, SurfaceShader& s) {
  s = SurfaceShader{};
  if (name == "constant") {
    s.kind = SurfaceKind::Constant;
  } else if (name == "matte") {
    s.kind = SurfaceKind::Matte, s.Ka = 1, s.Kd = 1;
  } else if (name == "metal") {
    s.kind = SurfaceKind::Metal, s.Ka = 1, s.Ks = 1, s.roughness = 0.1;
  } else if (name == "plastic") {
    s.kind = SurfaceKind::Plastic, s.Ka = 1, s.Kd = 0.5, s.Ks = 0.5, s.roughness = 0.1;
  } else if (name == "paintedplastic") {
    s.kind = SurfaceKind::PaintedPlastic, s.Ka = 1, s.Kd = 0.5, s.Ks = 0.5, s.roughness = 0.1;
  } else if (name == "defaultsurface") {
    s.kind = SurfaceKind::DefaultSurface, s.Ka = 0.2, s.Kd = 0.8;
  } else {
    s.kind = SurfaceKind::DefaultSurface, s.Ka = 0.2, s.Kd = 0.8;
    return false;
  }
  return true;
}

SurfaceShader SurfaceShader::lerp(const SurfaceShader& b, double w) const {
  SurfaceShader r = w < 0.5 ? *this : b;  // the kind cannot blend: the nearer key's
  r.Ka = Ka + (b.Ka - Ka) * w;
  r.Kd = Kd + (b.Kd - Kd) * w;
  r.Ks = Ks + (b.Ks - Ks) * w;
  r.roughness = roughness + (b.roughness - roughness) * w;
  r.specularColor = specularColor + (b.specularColor - specularColor) * w;
  return r;
}

bool CubicBasis::named(const std::string& name, CubicBasis& b) {
  b = CubicBasis{};
  if (name == "bezier") return true;
  if (name == "b-spline" || name == "bspline") {
    b.m = {-1, 3, -3, 1, 3, -6, 3, 0, -3, 0, 3, 0, 1, 4, 1, 0}, b.scale = 1.0 / 6.0, b.step = 1;
  } else if (name == "catmull-rom" || name == "catmullrom") {
    b.m = {-1, 3, -3, 1, 2, -5, 4, -1, -1, 0, 1, 0, 0, 2, 0, 0}, b.scale = 0.5, b.step = 1;
  } else if (name == "hermite") {
    b.m = {2, 1, -2, 1, -3, -2, 3, -1, 0, 1, 0, 0, 1, 0, 0, 0}, b.step = 2;
  } else if (name == "power") {
    b.m = {1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1}, b.step = 4;
  } else {
    return false;
  }
  return true;
}

bool Light::named(const std::string& name, Light& l) {
  l = Light{};
  l.name = name;
  // The shadow* lights are their plain lights with a shadow map; here they trace rays instead.
  if (name == "ambientlight") l.kind = LightKind::Ambient;
  else if (name == "distantlight" || name == "shadowdistant") l.kind = LightKind::Distant;
  else if (name == "pointlight" || name == "shadowpoint") l.kind = LightKind::Point;
  else if (name == "spotlight" || name == "shadowspot") l.kind = LightKind::Spot;
  else if (name == "uberlight") l.kind = LightKind::Uber, l.from = glm::dvec3(0.0), l.to = glm::dvec3(0, 0, 1);
  else return false;
  return true;
}

namespace {
bool get1(const ParamMap& p, const char* name, double& out) {
  auto it = p.find(name);
  if (it == p.end() || it->second.empty()) return false;
  out = it->second[0];
  return true;
}
bool get3(const ParamMap& p, const char* name, glm::dvec3& out) {
  auto it = p.find(name);
  if (it == p.end() || it->second.empty()) return false;
  const auto& v = it->second;
  out = v.size() >= 3 ? glm::dvec3(v[0], v[1], v[2]) : glm::dvec3(v[0]);
  return true;
}
}  // namespace

void applyParams(SurfaceShader& s, const ParamMap& p) {
  get1(p, "Ka", s.Ka);
  get1(p, "Kd", s.Kd);
  get1(p, "Ks", s.Ks);
  get1(p, "roughness", s.roughness);
  get3(p, "specularcolor", s.specularColor);
}

void applyParams(Light& l, const ParamMap& p) {
  get1(p, "intensity", l.intensity);
  get3(p, "lightcolor", l.color);
  get3(p, "from", l.from);
  get3(p, "to", l.to);
  get1(p, "coneangle", l.coneAngle);
  get1(p, "conedeltaangle", l.coneDeltaAngle);
  get1(p, "beamdistribution", l.beamDistribution);
  if (l.kind == LightKind::Uber) {
    UberLight& u = l.uber;
    double parallel = 0;
    get1(p, "parallelrays", parallel);
    u.parallel = parallel != 0;
    for (auto [name, field] : {std::pair{"cuton", &u.cuton},
                               {"cutoff", &u.cutoff},
                               {"nearedge", &u.nearedge},
                               {"faredge", &u.faredge},
                               {"falloff", &u.falloff},
                               {"falloffdist", &u.falloffdist},
                               {"maxintensity", &u.maxintensity},
                               {"shearx", &u.shearx},
                               {"sheary", &u.sheary},
                               {"width", &u.width},
                               {"height", &u.height},
                               {"wedge", &u.wedge},
                               {"hedge", &u.hedge},
                               {"roundness", &u.roundness},
                               {"beamdistribution", &u.beamdistribution}})
      get1(p, name, *field);
  }
}

Shape Primitive::shapeAt(double t) const {
  Shape s = keyAt(t);
  if (kind == PrimKind::Curve || kind == PrimKind::Point) {
    const glm::dmat4 toObject = glm::inverse(xform->at(t));
    s.eye = orthographicView ? toObject * glm::dvec4(0, 0, 1, 0) : toObject * glm::dvec4(0, 0, 0, 1);
  }
  return s;
}

Shape Primitive::keyAt(double t) const {
  if (keys.size() == 1) return keys[0];
  size_t i;
  double w;
  locate(times, t, i, w);
  Shape s;
  for (size_t k = 0; k < s.q.size(); ++k) s.q[k] = keys[i].q[k] + (keys[i + 1].q[k] - keys[i].q[k]) * w;
  for (size_t k = 0; k < 4; ++k) s.P[k] = keys[i].P[k] + (keys[i + 1].P[k] - keys[i].P[k]) * w;
  s.key = keys[i].key + (keys[i + 1].key - keys[i].key) * w;
  s.cv.resize(keys[i].cv.size());
  for (size_t k = 0; k < s.cv.size(); ++k) s.cv[k] = keys[i].cv[k] + (keys[i + 1].cv[k] - keys[i].cv[k]) * w;
  s.cw.resize(keys[i].cw.size());
  for (size_t k = 0; k < s.cw.size(); ++k) s.cw[k] = keys[i].cw[k] + (keys[i + 1].cw[k] - keys[i].cw[k]) * w;
  return s;
}

bool Primitive::corners(const std::vector<glm::dvec3>& data, std::array<glm::dvec3, 4>& out) const {
  if (!mesh || data.empty()) return false;
  if (data.size() == mesh->points) {
    for (int c = 0; c < 4; ++c) out[size_t(c)] = data[meshPoint[size_t(c)]];
    return true;
  }
  if (data.size() == mesh->faces) {
    out.fill(data[meshFace]);
    return true;
  }
  return false;
}

bool Primitive::cornerST(std::array<glm::dvec2, 4>& out) const {
  if (!mesh || mesh->st.size() != mesh->points) return false;
  for (int c = 0; c < 4; ++c) out[size_t(c)] = mesh->st[meshPoint[size_t(c)]];
  return true;
}

std::vector<double> Primitive::knotTimes() const { return store::unionTimes(times, xform->times); }

const std::vector<OutputVar>& knownOutputVars() {
  using store::AttrType;
  static const std::vector<OutputVar> vars = {{"P", AttrType::Point},  {"N", AttrType::Normal},    {"Ng", AttrType::Normal},     {"s", AttrType::Float},
                                              {"t", AttrType::Float},  {"u", AttrType::Float},     {"v", AttrType::Float},       {"Cs", AttrType::Color},
                                              {"Os", AttrType::Color}, {"depth", AttrType::Float}, {"specular", AttrType::Color}};
  return vars;
}

// ---------------------------------------------------------------------------------------------
// Scene

Scene::Scene(FrameCallback onWorldEnd) : onWorldEnd_(std::move(onWorldEnd)) {
  cur_.attrs = std::make_shared<Attributes>();
  // RenderMan's default projection is orthographic; its default near plane is RI_EPSILON.
  options_.camera.projection = store::Projection::Orthographic;
  options_.camera.nearClip = 1e-4;
  options_.camera.farClip = 1e30;
}

void Scene::error(const std::string& what) const { fail(where, what); }

Attributes& Scene::mutableAttrs() {
  if (cur_.attrs.use_count() > 1) cur_.attrs = std::make_shared<Attributes>(*cur_.attrs);
  return *cur_.attrs;
}

void Scene::format(int w, int h, double pa) {
  if (w <= 0 || h <= 0 || w > (1 << 20) || h > (1 << 20)) error(cat("resolution ", w, "x", h, " out of range"));
  options_.camera.width = w, options_.camera.height = h;
  options_.camera.pixelAspect = pa > 0 ? pa : 1.0;
}
void Scene::frameAspectRatio(double a) {
  if (!(a > 0)) error("frame aspect ratio must be positive");
  options_.frameAspectRatio = a;
}
void Scene::screenWindow(double l, double r, double b, double t) {
  if (l == r || b == t) error("screen window is empty");
  double* sw = options_.camera.screenWindow;
  sw[0] = l, sw[1] = r, sw[2] = b, sw[3] = t;
}
void Scene::perspective(double fov) {
  if (!(fov > 0 && fov < 180)) error(cat("field of view ", fov, " not in (0, 180)"));
  options_.camera.projection = store::Projection::Perspective;
  options_.camera.fovDegrees = fov;
}
void Scene::orthographic() { options_.camera.projection = store::Projection::Orthographic; }
void Scene::clipping(double n, double f) {
  if (!(n > 0) || !(f > n)) error(cat("clipping planes ", n, " ", f, " invalid"));
  options_.camera.nearClip = n, options_.camera.farClip = std::min(f, 1e30);
}
void Scene::depthOfField(double fstop, double focalLength, double focalDistance) {
  store::Lens lens{fstop, focalLength, focalDistance};
  const bool off = (fstop == 0 && focalLength == 0 && focalDistance == 0) || std::isinf(fstop);
  if (!off && !lens.active())
    error(cat("DepthOfField ", fstop, " ", focalLength, " ", focalDistance, ": f-stop, focal length and focal distance must be positive and finite"));
  options_.camera.lens = off ? store::Lens{} : lens;
}
void Scene::shutter(double open, double close) {
  if (!std::isfinite(open) || !std::isfinite(close) || close < open) error(cat("shutter [", open, ", ", close, "] is not an interval"));
  options_.shutterOpen = open, options_.shutterClose = close;
}
void Scene::textureSearchPath(const std::string& path) {
  // "&" stands for the path so far (RenderMan's convention).
  std::string out;
  for (size_t i = 0; i < path.size(); ++i) out += path[i] == '&' ? options_.textureSearchPath : std::string(1, path[i]);
  options_.textureSearchPath = out;
}

void Scene::pixelSamples(int x, int y) {
  options_.pixelSamples[0] = std::max(1, x);
  options_.pixelSamples[1] = std::max(1, y);
}

void Scene::display(const std::string& name, const std::string& mode) {
  (void)name;
  // Each comma-separated token of the mode is a variable; "color rightCi"-style declarations
  // name it last. The primary colour and alpha, depth and ids need no extra store attribute.
  size_t start = 0;
  while (start <= mode.size()) {
    size_t comma = mode.find(',', start);
    std::string tok = mode.substr(start, comma == std::string::npos ? std::string::npos : comma - start);
    start = comma == std::string::npos ? mode.size() + 1 : comma + 1;
    auto sp = tok.find_last_of(" \t");
    if (sp != std::string::npos) tok = tok.substr(sp + 1);
    if (tok.empty()) continue;
    static const char* builtin[] = {"rgb", "rgba", "rgbz", "rgbaz", "a", "z", "r", "g", "b", "Ci", "Oi", "id", "Z", "A"};
    if (std::find_if(std::begin(builtin), std::end(builtin), [&](const char* b) { return tok == b; }) != std::end(builtin)) continue;
    const auto& known = knownOutputVars();
    if (std::none_of(known.begin(), known.end(), [&](const OutputVar& v) { return v.name == tok; })) {
      warnOnce(cat("outputvar:", tok), cat(where, ": output variable '", tok, "' is not computed by the built-in shaders; skipped"));
      continue;
    }
    if (std::find(options_.outputs.begin(), options_.outputs.end(), tok) == options_.outputs.end()) options_.outputs.push_back(tok);
  }
}

void Scene::camera(const std::string& name) {
  if (inWorld_) error("Camera is an option: it must come before WorldBegin");
  // RIS-era exporters name the main camera "world": it is the one WorldBegin freezes, so the
  // request declares nothing more.
  if (name == "world") return;
  if (name == "frame") error(cat("camera name '", name, "' is reserved"));
  store::Camera c = options_.camera;
  c.name = name;
  recordCameraMotion(c, cur_.ctm);
  c.clipMotion(options_.shutterOpen, options_.shutterClose);
  auto& cams = options_.namedCameras;
  cams.erase(std::remove_if(cams.begin(), cams.end(), [&](const store::Camera& o) { return o.name == name; }), cams.end());
  cams.push_back(c);
  coordSystems_[name] = cur_.ctm;
}

void Scene::push(Block b) {
  stack_.push_back(cur_);
  stack_.back().block = b;
}

Scene::State Scene::pop(Block b, const char* request) {
  // World and frame ends close whatever the scene left open (with a warning); attribute and
  // transform ends must match exactly.
  if (b == Block::World || b == Block::Frame) {
    size_t open = 0;
    while (!stack_.empty() && stack_.back().block != b && stack_.back().block != Block::World && stack_.back().block != Block::Frame) stack_.pop_back(), ++open;
    if (open) warn(cat(where, ": ", open, " AttributeBegin/TransformBegin without End at ", request));
  }
  if (stack_.empty() || stack_.back().block != b) error(cat(request, " without a matching begin"));
  State s = std::move(stack_.back());
  stack_.pop_back();
  ctmShared_.reset();
  return s;
}

void Scene::frameBegin(int64_t n) {
  if (inFrame_ || inWorld_) error("FrameBegin inside a frame or world block");
  savedFrameOptions_ = options_;
  push(Block::Frame);
  options_.frame = n;
  inFrame_ = true;
}

void Scene::frameEnd() {
  if (!inFrame_ || inWorld_) error("FrameEnd without FrameBegin");
  options_ = savedFrameOptions_;
  cur_ = pop(Block::Frame, "FrameEnd");
  inFrame_ = false;
}

void Scene::worldBegin() {
  if (inWorld_) error("WorldBegin inside a world block");
  if (motion_.active) error("WorldBegin inside a motion block");
  frame_.options = options_;
  store::Camera& cam = frame_.options.camera;
  if (options_.frameAspectRatio > 0 && cam.screenWindow[0] == cam.screenWindow[1]) {
    double a = options_.frameAspectRatio;
    double* sw = cam.screenWindow;
    if (a >= 1) sw[0] = -a, sw[1] = a, sw[2] = -1, sw[3] = 1;
    else sw[0] = -1, sw[1] = 1, sw[2] = -1 / a, sw[3] = 1 / a;
  }
  cam.name = "world";
  recordCameraMotion(cam, cur_.ctm);
  cam.clipMotion(options_.shutterOpen, options_.shutterClose);
  frame_.worldToCamera = cur_.ctm;
  push(Block::World);
  coordSystems_["world"] = cur_.ctm;
  inWorld_ = true;
}

void Scene::worldEnd() {
  if (!inWorld_) error("WorldEnd without WorldBegin");
  if (motion_.active) error("WorldEnd inside a motion block");
  cur_ = pop(Block::World, "WorldEnd");
  inWorld_ = false;
  FrameScene done;
  std::swap(done, frame_);  // frame_ starts afresh (a swap: GCC 12 misreads assigning a temporary here as uninitialised use)
  lightHandles_.clear();
  objectIds_.clear();
  // Light indices point into this frame's list, which is gone now.
  if (!cur_.attrs->lights.empty()) mutableAttrs().lights.clear();
  if (onWorldEnd_) onWorldEnd_(done);
  ++framesDone_;
}

void Scene::attributeBegin() { push(Block::Attribute); }
void Scene::attributeEnd() { cur_ = pop(Block::Attribute, "AttributeEnd"); }
void Scene::transformBegin() { push(Block::Transform); }
void Scene::transformEnd() { cur_.ctm = pop(Block::Transform, "TransformEnd").ctm; }

bool Scene::motionTake(Pending kind) {
  if (!motion_.active) return false;
  if (motion_.kind != Pending::None && motion_.kind != kind) error("a motion block must hold requests of one kind");
  motion_.kind = kind;
  size_t have = motion_.mats.size() + motion_.colors.size() + motion_.surfaces.size() + motion_.prims.size();
  if (have >= motion_.times.size()) error(cat("motion block has more requests than its ", motion_.times.size(), " times"));
  return true;
}

void Scene::applyTransform(const glm::dmat4& m, bool set) {
  if (motionTake(set ? Pending::Set : Pending::Concat)) {
    motion_.mats.push_back(m);
    return;
  }
  if (set) cur_.ctm = (inWorld_ ? frame_.worldToCamera : MotionXform()).then(MotionXform(m));
  else cur_.ctm = cur_.ctm.then(MotionXform(m));
  ctmShared_.reset();
}

void Scene::identity() { applyTransform(glm::dmat4(1.0), true); }
void Scene::transform(const glm::dmat4& m) { applyTransform(m, true); }
void Scene::concatTransform(const glm::dmat4& m) { applyTransform(m, false); }
void Scene::translate(double x, double y, double z) { applyTransform(glm::translate(glm::dmat4(1.0), glm::dvec3(x, y, z)), false); }
void Scene::rotate(double deg, double x, double y, double z) {
  glm::dvec3 axis(x, y, z);
  if (glm::dot(axis, axis) == 0) error("Rotate about a zero axis");
  applyTransform(glm::rotate(glm::dmat4(1.0), glm::radians(deg), axis), false);
}
void Scene::scale(double x, double y, double z) { applyTransform(glm::scale(glm::dmat4(1.0), glm::dvec3(x, y, z)), false); }
void Scene::coordinateSystem(const std::string& name) { coordSystems_[name] = cur_.ctm; }
void Scene::coordSysTransform(const std::string& name) {
  if (name == "camera") {
    cur_.ctm = MotionXform();
    ctmShared_.reset();
    return;
  }
  auto it = coordSystems_.find(name);
  if (it == coordSystems_.end()) error(cat("unknown coordinate system '", name, "'"));
  cur_.ctm = it->second;
  ctmShared_.reset();
}
void Scene::orientation(const std::string& o) {
  bool rh = csIsRightHanded(cur_.ctm);
  if (o == "lh") mutableAttrs().orientationRH = false;
  else if (o == "rh") mutableAttrs().orientationRH = true;
  else if (o == "outside") mutableAttrs().orientationRH = rh;
  else if (o == "inside") mutableAttrs().orientationRH = !rh;
  else error(cat("unknown orientation '", o, "'"));
}
void Scene::reverseOrientation() { mutableAttrs().orientationRH = !cur_.attrs->orientationRH; }
void Scene::sides(int n) {
  if (n != 1 && n != 2) error(cat("Sides ", n, ": must be 1 or 2"));
  mutableAttrs().twoSided = n == 2;
}

void Scene::color(const glm::dvec3& c) {
  if (motionTake(Pending::Color)) return motion_.colors.push_back(c);
  mutableAttrs().color = Animated<glm::dvec3>(c);
}
void Scene::opacity(const glm::dvec3& o) {
  if (motionTake(Pending::Opacity)) return motion_.colors.push_back(o);
  mutableAttrs().opacity = Animated<glm::dvec3>(o);
}
void Scene::surface(const std::string& name, const ParamMap& params, const std::map<std::string, std::string>& strings) {
  SurfaceShader s;
  if (!SurfaceShader::named(name, s)) warnOnce(cat("surface:", name), cat(where, ": surface shader '", name, "' is not built in; using defaultsurface"));
  applyParams(s, params);
  if (s.kind == SurfaceKind::PaintedPlastic)
    if (auto it = strings.find("texturename"); it != strings.end()) s.textureName = it->second;
  if (motionTake(Pending::Surface)) return motion_.surfaces.push_back(s);
  mutableAttrs().surface = Animated<SurfaceShader>(s);
}

void Scene::lightSource(const std::string& name, const std::string& handle, const ParamMap& params, const std::map<std::string, std::string>& strings) {
  Light l;
  if (!Light::named(name, l)) {
    warnOnce(cat("light:", name), cat(where, ": light shader '", name, "' is not built in; skipped"));
    return;
  }
  applyParams(l, params);
  // Shadows where the light asks for them: a shadow map name ("raytrace", or a map this pass
  // cannot read, so rays stand in for it), "raytraceshadow", or Attribute "light" "shadows".
  l.shadows = cur_.attrs->lightShadows;
  if (auto it = strings.find("lighttype"); l.kind == LightKind::Uber && it != strings.end()) l.uber.omni = it->second == "omni" || it->second == "arealight";
  for (const char* map : {"shadowname", "shadowmap", "sfpx", "sfnx", "sfpy", "sfny", "sfpz", "sfnz"})
    if (auto it = strings.find(map); it != strings.end() && !it->second.empty()) {
      l.shadows = true;
      if (it->second != "raytrace")
        warnOnce(cat("shadowmap:", name), cat(where, ": ", name, " shadow map '", it->second, "' is not read; its shadows are ray traced instead"));
    }
  if (auto it = params.find("raytraceshadow"); it != params.end() && !it->second.empty() && it->second[0] != 0) l.shadows = true;
  addLight(std::move(l), handle, false);
}

void Scene::addLight(Light l, const std::string& handle, bool global) {
  l.xform = cur_.ctm;
  const auto idx = uint32_t(frame_.lights.size());
  frame_.lights.push_back(std::move(l));
  if (!handle.empty()) lightHandles_[handle] = idx;
  if (global) frame_.globalLights.push_back(idx);
  else mutableAttrs().lights.push_back(idx);
}

void Scene::transmission(bool on) { mutableAttrs().transmission = on; }
void Scene::lightShadows(bool on) { mutableAttrs().lightShadows = on; }

void Scene::illuminate(const std::string& handle, bool on) {
  auto it = lightHandles_.find(handle);
  if (it == lightHandles_.end()) {
    warnOnce("illuminate", cat(where, ": Illuminate names unknown light '", handle, "'"));
    return;
  }
  auto& ls = mutableAttrs().lights;
  auto pos = std::find(ls.begin(), ls.end(), it->second);
  if (on && pos == ls.end()) ls.push_back(it->second);
  if (!on && pos != ls.end()) ls.erase(pos);
}

void Scene::shadingRate(double r) {
  if (!(r > 0) || !std::isfinite(r)) error(cat("shading rate ", r, " must be positive"));
  mutableAttrs().shadingRate = r;
}
void Scene::trimCurve(std::shared_ptr<const TrimLoops> loops) { mutableAttrs().trim = std::move(loops); }
void Scene::trimSense(bool keepInside) { mutableAttrs().trimKeepsInside = keepInside; }
void Scene::motionFactor(double f) {
  if (!(f >= 0) || !std::isfinite(f)) error(cat("motion factor ", f, " must be non-negative"));
  mutableAttrs().motionFactor = f;
}
void Scene::matte(bool on) { mutableAttrs().matte = on; }
void Scene::ris(RisNode node) {
  if (!inWorld_) {
    options_.risOptions.erase(
        std::remove_if(options_.risOptions.begin(), options_.risOptions.end(),
                       [&](const RisNode& o) { return o.request == node.request && o.request != "DisplayFilter" && o.request != "SampleFilter"; }),
        options_.risOptions.end());
    options_.risOptions.push_back(std::move(node));
    return;
  }
  // RIS materials and lights become the built-in ones (shade/ris.h). A RIS light lights every
  // primitive, declared before it or after, as RIS lights do.
  if (node.request == "Bxdf") {
    const SurfaceShader s = risMaterial(node, frame_.risNodes, where);
    if (motionTake(Pending::Surface)) motion_.surfaces.push_back(s);
    else mutableAttrs().surface = Animated<SurfaceShader>(s);
    mutableAttrs().bxdf = uint32_t(frame_.risNodes.size() + 1);
  } else if (node.request == "Light") {
    Light l;
    if (risLight(node, l, where)) addLight(std::move(l), node.handle, true);
  }
  frame_.risNodes.push_back(std::move(node));
}

void Scene::skippedPrimitive(std::string_view request) {
  if (recording_) ++recording_->skipped[std::string(request)];
  else if (inWorld_) ++frame_.skipped[std::string(request)];
}

void Scene::volume(const std::string& path, const std::string& grid) {
  if (!inWorld_) error("Volume outside a world block");
  if (path.empty()) error("Volume without an OpenVDB file");
  if (recording_) {
    warnOnce("volume-instance", cat(where, ": a Volume inside an object definition is not instanced; skipped"));
    ++recording_->skipped["Volume"];
    return;
  }
  frame_.volumes.push_back({path, grid.empty() ? "density" : grid, cur_.ctm});
}

void Scene::identifier(const std::string& name) {
  auto [it, fresh] = objectIds_.try_emplace(name, uint32_t(frame_.objectNames.size() + 1));
  if (fresh) frame_.objectNames.push_back(name);
  mutableAttrs().objectId = it->second;
}

void Scene::motionBegin(const std::vector<double>& times) {
  if (motion_.active) error("MotionBegin inside a motion block");
  if (times.empty() || times.size() > 64) error(cat("MotionBegin with ", times.size(), " times (1 to 64 allowed)"));
  for (size_t i = 0; i < times.size(); ++i) {
    if (!std::isfinite(times[i])) error("MotionBegin time is not finite");
    if (i && !(times[i] > times[i - 1])) error("MotionBegin times must increase");
  }
  motion_ = Motion{};
  motion_.active = true;
  motion_.times = times;
}

void Scene::motionEnd() {
  if (!motion_.active) error("MotionEnd without MotionBegin");
  Motion m = std::move(motion_);
  motion_ = Motion{};
  if (m.kind == Pending::None) return;
  size_t n = m.mats.size() + m.colors.size() + m.surfaces.size() + m.prims.size();
  if (n != m.times.size()) error(cat("motion block has ", n, " requests for ", m.times.size(), " times"));
  // A one-time block is a plain request at that time.
  std::vector<double> times = m.times.size() > 1 ? m.times : std::vector<double>{};
  switch (m.kind) {
    case Pending::Concat:
      cur_.ctm = cur_.ctm.then(MotionXform(times, m.times.size() > 1 ? m.mats : std::vector<glm::dmat4>{m.mats[0]}));
      ctmShared_.reset();
      break;
    case Pending::Set:
      cur_.ctm = (inWorld_ ? frame_.worldToCamera : MotionXform()).then(MotionXform(times, m.times.size() > 1 ? m.mats : std::vector<glm::dmat4>{m.mats[0]}));
      ctmShared_.reset();
      break;
    case Pending::Color:
    case Pending::Opacity: {
      Animated<glm::dvec3> a;
      a.times = times;
      a.values = times.empty() ? std::vector<glm::dvec3>{m.colors[0]} : m.colors;
      (m.kind == Pending::Color ? mutableAttrs().color : mutableAttrs().opacity) = a;
      break;
    }
    case Pending::Surface: {
      Animated<SurfaceShader> a;
      a.times = times;
      a.values = times.empty() ? std::vector<SurfaceShader>{m.surfaces[0]} : m.surfaces;
      mutableAttrs().surface = a;
      break;
    }
    case Pending::Prim: {
      std::vector<Primitive> out = std::move(m.prims[0]);
      // A subdivision mesh's keys are its surface's: one surface gets every copy's points.
      std::map<const SubdivSurface*, std::shared_ptr<const SubdivSurface>> merged;
      for (size_t i = 0; i < out.size(); ++i) {
        if (out[i].kind != PrimKind::Subdiv || merged.count(out[i].subdiv.get())) continue;
        std::vector<std::vector<glm::dvec3>> more;
        for (size_t k = 1; k < m.prims.size(); ++k) {
          if (m.prims[k].size() != out.size() || m.prims[k][i].kind != PrimKind::Subdiv) error("deformation keys of a motion block are different primitives");
          more.push_back(m.prims[k][i].subdiv->basePoints(0));
        }
        merged[out[i].subdiv.get()] = out[i].subdiv->withKeys(more);
      }
      for (size_t k = 1; k < m.prims.size(); ++k) {
        if (m.prims[k].size() != out.size()) error("deformation keys of a motion block differ in topology");
        for (size_t i = 0; i < out.size(); ++i) {
          if (m.prims[k][i].kind != out[i].kind || m.prims[k][i].triangle != out[i].triangle || m.prims[k][i].keys[0].cv.size() != out[i].keys[0].cv.size() ||
              (out[i].nurbs && (m.prims[k][i].nurbs->knotsU != out[i].nurbs->knotsU || m.prims[k][i].nurbs->knotsV != out[i].nurbs->knotsV)))
            error("deformation keys of a motion block are different primitives");
          out[i].keys.push_back(m.prims[k][i].keys[0]);
          if (out[i].kind == PrimKind::Subdiv) out[i].keys.back().key = double(k);
        }
      }
      for (auto& p : out)
        if (p.kind == PrimKind::Subdiv) p.subdiv = merged.at(p.subdiv.get());
      for (auto& p : out) p.times = times;
      frame_.prims.insert(frame_.prims.end(), std::make_move_iterator(out.begin()), std::make_move_iterator(out.end()));
      break;
    }
    case Pending::None: break;
  }
}

bool Scene::orientationFlipped() const { return cur_.attrs->orientationRH != csIsRightHanded(cur_.ctm); }

Primitive Scene::basePrim(PrimKind kind) {
  // Primitives declared under one transform share it.
  if (!ctmShared_) ctmShared_ = std::make_shared<const MotionXform>(cur_.ctm);
  Primitive p;
  p.kind = kind;
  p.attrs = cur_.attrs;
  p.xform = ctmShared_;
  p.flipNormals = orientationFlipped();
  return p;
}

void Scene::objectBegin(const std::string& handle) {
  if (recording_) error("ObjectBegin inside an object definition");
  if (motion_.active) error("ObjectBegin inside a motion block");
  push(Block::Object);
  cur_.ctm = MotionXform();  // the object's own space
  ctmShared_.reset();
  ObjectDefinition& d = objects_[handle];
  d = ObjectDefinition{};
  d.attrsAtBegin = cur_.attrs;
  recording_ = &d;
}

void Scene::objectEnd() {
  if (!recording_) error("ObjectEnd without ObjectBegin");
  recording_ = nullptr;
  cur_ = pop(Block::Object, "ObjectEnd");
}

void Scene::objectInstance(const std::string& handle) {
  auto it = objects_.find(handle);
  if (it == objects_.end()) error(cat("ObjectInstance of undefined object '", handle, "'"));
  if (recording_ == &it->second) error(cat("object '", handle, "' instances itself"));
  for (const auto& [request, count] : it->second.skipped) {
    if (recording_) recording_->skipped[request] += count;
    else if (inWorld_) frame_.skipped[request] += count;
  }
  std::vector<Primitive> out = it->second.prims;
  std::map<const MotionXform*, std::shared_ptr<const MotionXform>> placed;  // prims sharing a transform share its instance
  for (Primitive& p : out) {
    if (p.attrs == it->second.attrsAtBegin) p.attrs = cur_.attrs;
    auto& x = placed[p.xform.get()];
    if (!x) x = std::make_shared<const MotionXform>(cur_.ctm.then(*p.xform));
    p.xform = x;
    p.flipNormals = p.attrs->orientationRH != csIsRightHanded(*p.xform);
  }
  addPrims(std::move(out));
}

void Scene::addPrims(std::vector<Primitive> prims) {
  if (recording_ && !motion_.active) {
    recording_->prims.insert(recording_->prims.end(), std::make_move_iterator(prims.begin()), std::make_move_iterator(prims.end()));
    return;
  }
  if (!inWorld_) {
    warnOnce("prim-outside-world", cat(where, ": geometry outside WorldBegin/WorldEnd; skipped"));
    return;
  }
  if (motionTake(Pending::Prim)) {
    motion_.prims.push_back(std::move(prims));
    return;
  }
  frame_.prims.insert(frame_.prims.end(), std::make_move_iterator(prims.begin()), std::make_move_iterator(prims.end()));
}

}  // namespace reshutter::shade
