// The RenderMan-style scene builder: graphics state, motion blocks, primitives → FrameScene.
#include "shade/scene.h"

#include <algorithm>
#include <cmath>
#include <span>

#include <glm/gtc/matrix_inverse.hpp>
#include <glm/gtc/matrix_transform.hpp>

#include "common/error.h"
#include "common/log.h"

namespace reshutter::shade {

namespace {

std::vector<double> unionTimes(const std::vector<double>& a, const std::vector<double>& b) {
  std::vector<double> t(a);
  t.insert(t.end(), b.begin(), b.end());
  std::sort(t.begin(), t.end());
  t.erase(std::unique(t.begin(), t.end()), t.end());
  return t;
}

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

glm::dvec3 lerpValue(const glm::dvec3& a, const glm::dvec3& b, double w) { return a + (b - a) * w; }
SurfaceShader lerpValue(const SurfaceShader& a, const SurfaceShader& b, double w) { return a.lerp(b, w); }

bool csIsRightHanded(const MotionXform& x) { return glm::determinant(x.mats[0]) < 0; }

}  // namespace

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

MotionXform MotionXform::then(const MotionXform& rhs) const {
  if (!moving() && !rhs.moving()) return MotionXform(mats[0] * rhs.mats[0]);
  std::vector<double> t = unionTimes(times, rhs.times);
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
  if (name == "ambientlight") l.kind = LightKind::Ambient;
  else if (name == "distantlight") l.kind = LightKind::Distant;
  else if (name == "pointlight") l.kind = LightKind::Point;
  else if (name == "spotlight") l.kind = LightKind::Spot;
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

std::vector<double> Primitive::knotTimes() const { return unionTimes(times, xform->times); }

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
void Scene::shutter(double open, double close) {
  if (!std::isfinite(open) || !std::isfinite(close) || close < open) error(cat("shutter [", open, ", ", close, "] is not an interval"));
  options_.shutterOpen = open, options_.shutterClose = close;
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
  c.worldToCamera = cur_.ctm.at(options_.shutterOpen);
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
  cam.worldToCamera = cur_.ctm.at(options_.shutterOpen);
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
  FrameScene done = std::move(frame_);
  frame_ = FrameScene{};
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
void Scene::surface(const std::string& name, const ParamMap& params) {
  SurfaceShader s;
  if (!SurfaceShader::named(name, s)) warnOnce(cat("surface:", name), cat(where, ": surface shader '", name, "' is not built in; using defaultsurface"));
  applyParams(s, params);
  if (motionTake(Pending::Surface)) return motion_.surfaces.push_back(s);
  mutableAttrs().surface = Animated<SurfaceShader>(s);
}

void Scene::lightSource(const std::string& name, const std::string& handle, const ParamMap& params) {
  Light l;
  if (!Light::named(name, l)) {
    warnOnce(cat("light:", name), cat(where, ": light shader '", name, "' is not built in; skipped"));
    return;
  }
  applyParams(l, params);
  l.xform = cur_.ctm;
  uint32_t idx = uint32_t(frame_.lights.size());
  frame_.lights.push_back(l);
  if (!handle.empty()) lightHandles_[handle] = idx;
  mutableAttrs().lights.push_back(idx);
}

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
void Scene::motionFactor(double f) {
  if (!(f >= 0) || !std::isfinite(f)) error(cat("motion factor ", f, " must be non-negative"));
  mutableAttrs().motionFactor = f;
}
void Scene::matte(bool on) { mutableAttrs().matte = on; }
void Scene::ris(RisNode node) {
  if (!inWorld_) {
    options_.risOptions.erase(std::remove_if(options_.risOptions.begin(), options_.risOptions.end(),
                                             [&](const RisNode& o) { return o.request == node.request && o.request != "DisplayFilter" && o.request != "SampleFilter"; }),
                              options_.risOptions.end());
    options_.risOptions.push_back(std::move(node));
    return;
  }
  const bool bxdf = node.request == "Bxdf";
  frame_.risNodes.push_back(std::move(node));
  if (bxdf) mutableAttrs().bxdf = uint32_t(frame_.risNodes.size());
}

void Scene::skippedPrimitive(std::string_view request) {
  if (recording_) ++recording_->skipped[std::string(request)];
  else if (inWorld_) ++frame_.skipped[std::string(request)];
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

namespace {
void checkFinite(const Scene& s, std::span<const double> v) {
  for (double x : v)
    if (!std::isfinite(x)) fail(s.where, "primitive parameter is not finite");
}
void checkFinite(const Scene& s, std::initializer_list<double> v) { checkFinite(s, std::span<const double>(v.begin(), v.size())); }
}  // namespace

void Scene::quadric(PrimKind kind, const std::array<double, 5>& q, size_t used) {
  checkFinite(*this, std::span<const double>(q.data(), used));
  Primitive p = basePrim(kind);
  Shape s;
  s.q = q;
  p.keys = {s};
  addPrims({std::move(p)});
}
void Scene::sphere(double radius, double zmin, double zmax, double thetamax) { quadric(PrimKind::Sphere, {radius, zmin, zmax, thetamax, 0}, 4); }
void Scene::cylinder(double radius, double zmin, double zmax, double thetamax) { quadric(PrimKind::Cylinder, {radius, zmin, zmax, thetamax, 0}, 4); }
void Scene::cone(double height, double radius, double thetamax) { quadric(PrimKind::Cone, {height, radius, thetamax, 0, 0}, 3); }
void Scene::disk(double height, double radius, double thetamax) { quadric(PrimKind::Disk, {height, radius, thetamax, 0, 0}, 3); }
void Scene::torus(double rmajor, double rminor, double phimin, double phimax, double thetamax) {
  quadric(PrimKind::Torus, {rmajor, rminor, phimin, phimax, thetamax}, 5);
}

void Scene::hyperboloid(const glm::dvec3& point1, const glm::dvec3& point2, double thetamax) {
  checkFinite(*this, {point1.x, point1.y, point1.z, point2.x, point2.y, point2.z, thetamax});
  Primitive p = basePrim(PrimKind::Hyperboloid);
  Shape s;
  s.q[0] = thetamax;
  s.P[0] = point1, s.P[1] = point2;
  p.keys = {s};
  addPrims({std::move(p)});
}
void Scene::paraboloid(double rmax, double zmin, double zmax, double thetamax) {
  if (!(zmax != 0)) error("a paraboloid needs zmax != 0");
  quadric(PrimKind::Paraboloid, {rmax, zmin, zmax, thetamax, 0}, 4);
}

void Scene::patch(const std::array<glm::dvec3, 4>& P, const VertexData& vd) {
  for (const auto& c : P) checkFinite(*this, {c.x, c.y, c.z});
  Primitive p = basePrim(PrimKind::Patch);
  Shape s;
  s.P = P;
  p.keys = {s};
  if (!vd.N.empty() || !vd.Cs.empty() || !vd.Os.empty() || !vd.st.empty()) {
    auto mesh = std::make_shared<MeshData>();
    mesh->N = vd.N, mesh->Cs = vd.Cs, mesh->Os = vd.Os, mesh->st = vd.st;
    mesh->points = 4, mesh->faces = 1;
    p.mesh = std::move(mesh);
    p.meshPoint = {0, 1, 2, 3};
  }
  addPrims({std::move(p)});
}

void Scene::basis(const CubicBasis& u, const CubicBasis& v) {
  for (const CubicBasis* b : {&u, &v}) {
    for (double x : b->m)
      if (!std::isfinite(x)) error("basis matrix element is not finite");
    if (b->step < 1 || b->step > 64) error(cat("basis step ", b->step, " must be 1 to 64"));
  }
  mutableAttrs().basis = std::make_shared<const std::array<CubicBasis, 2>>(std::array<CubicBasis, 2>{u, v});
}

namespace {
/// Patches along one direction of a patch mesh, or 0 when the count does not fit the step.
int patchCount(bool bicubic, int n, bool periodic, int step) {
  if (!bicubic) return periodic ? n : n - 1;
  if (periodic) return n % step == 0 ? n / step : 0;
  return n >= 4 && (n - 4) % step == 0 ? (n - 4) / step + 1 : 0;
}
}  // namespace

void Scene::patchMesh(bool bicubic, int nu, bool uPeriodic, int nv, bool vPeriodic, const std::vector<glm::dvec3>& P, const VertexData& vd) {
  static const std::array<CubicBasis, 2> bezier{};
  const auto& bases = cur_.attrs->basis ? *cur_.attrs->basis : bezier;
  if (nu < 1 || nv < 1 || size_t(nu) * size_t(nv) != P.size())
    error(cat("a ", nu, " x ", nv, " patch mesh needs ", int64_t(nu) * nv, " control points, has ", P.size()));
  for (const auto& c : P) checkFinite(*this, {c.x, c.y, c.z});
  const int su = bicubic ? bases[0].step : 1, sv = bicubic ? bases[1].step : 1;
  const int npu = patchCount(bicubic, nu, uPeriodic, su), npv = patchCount(bicubic, nv, vPeriodic, sv);
  if (npu < 1) error(cat("nu = ", nu, " does not make whole ", uPeriodic ? "periodic " : "", bicubic ? "bicubic" : "bilinear", " patches with a u step of ", su));
  if (npv < 1) error(cat("nv = ", nv, " does not make whole ", vPeriodic ? "periodic " : "", bicubic ? "bicubic" : "bilinear", " patches with a v step of ", sv));
  // Varying values sit at patch corners, uniform ones on patches.
  const int nvu = uPeriodic ? npu : npu + 1, nvv = vPeriodic ? npv : npv + 1;
  const size_t varying = size_t(nvu) * size_t(nvv), uniform = size_t(npu) * size_t(npv);
  std::shared_ptr<const MeshData> mesh;
  {
    auto m = std::make_shared<MeshData>();
    m->points = varying, m->faces = uniform;
    auto take = [&](const auto& in, auto& out, const char* name) {
      if (in.empty()) return;
      if (in.size() == varying || in.size() == uniform) out = in;
      else warnOnce(cat("patchmesh-var:", name), cat(where, ": \"", name, "\" has ", in.size(), " values; a patch mesh takes ", varying, " (varying) or ", uniform, " (uniform); ignored"));
    };
    take(vd.N, m->N, "N"), take(vd.Cs, m->Cs, "Cs"), take(vd.Os, m->Os, "Os");
    if (!vd.st.empty() && vd.st.size() == varying) m->st = vd.st;
    else if (!vd.st.empty()) warnOnce("patchmesh-var:st", cat(where, ": texture coordinates of a patch mesh are varying (", varying, " values); ignored"));
    if (!m->N.empty() || !m->Cs.empty() || !m->Os.empty() || !m->st.empty()) mesh = std::move(m);
  }
  std::vector<Primitive> out;
  out.reserve(uniform);
  for (int pv = 0; pv < npv; ++pv)
    for (int pu = 0; pu < npu; ++pu) {
      Primitive p = basePrim(bicubic ? PrimKind::Bicubic : PrimKind::Patch);
      Shape s;
      auto point = [&](int i, int j) { return P[size_t((j % nv) * nu + (i % nu))]; };
      if (bicubic) {
        p.basis = cur_.attrs->basis;
        s.cv.resize(16);
        for (int l = 0; l < 4; ++l)
          for (int k = 0; k < 4; ++k) s.cv[size_t(l * 4 + k)] = point(pu * su + k, pv * sv + l);
      } else {
        s.P = {point(pu, pv), point(pu + 1, pv), point(pu, pv + 1), point(pu + 1, pv + 1)};
      }
      p.keys = {s};
      if (mesh) {
        p.mesh = mesh;
        auto corner = [&](int i, int j) { return uint32_t((j % nvv) * nvu + (i % nvu)); };
        p.meshPoint = {corner(pu, pv), corner(pu + 1, pv), corner(pu, pv + 1), corner(pu + 1, pv + 1)};
        p.meshFace = uint32_t(pv * npu + pu);
      }
      out.push_back(std::move(p));
    }
  addPrims(std::move(out));
}

void Scene::subdivisionMesh(SubdivScheme scheme, const std::vector<int>& nverts, const std::vector<int>& verts, const SubdivTags& tags,
                            const std::vector<glm::dvec3>& P, const VertexData& vd) {
  auto surface = std::make_shared<const SubdivSurface>(scheme, nverts, verts, tags, std::vector<std::vector<glm::dvec3>>{P}, where);
  const int n = surface->ptexFaces();
  std::vector<size_t> firstVertex(nverts.size() + 1, 0);
  for (size_t f = 0; f < nverts.size(); ++f) firstVertex[f + 1] = firstVertex[f] + size_t(nverts[f]);
  // Varying data as corner values per ptex face: a quad's own, an n-gon sub-face's (its vertex,
  // the two edge midpoints, the centroid), a triangle's with its apex repeated.
  auto cornersOf = [&](int ptex, const auto& data, auto zero) {
    const auto [f, corner] = surface->baseFace(ptex);
    const size_t first = firstVertex[size_t(f)], nv = size_t(nverts[size_t(f)]);
    auto at = [&](size_t i) { return data[size_t(verts[first + (i % nv)])]; };
    if (nv == 3 && scheme == SubdivScheme::Loop) return std::array<decltype(zero), 4>{at(0), at(1), at(2), at(2)};
    if (nv == 4) return std::array<decltype(zero), 4>{at(0), at(1), at(3), at(2)};
    auto centroid = zero;
    for (size_t i = 0; i < nv; ++i) centroid += at(i);
    centroid /= double(nv);
    const size_t c = size_t(corner);
    return std::array<decltype(zero), 4>{at(c), (at(c) + at(c + 1)) * 0.5, (at(c) + at(c + nv - 1)) * 0.5, centroid};
  };
  std::shared_ptr<MeshData> mesh;
  if (!vd.N.empty() || !vd.Cs.empty() || !vd.Os.empty() || !vd.st.empty()) {
    mesh = std::make_shared<MeshData>();
    mesh->points = size_t(n) * 4, mesh->faces = size_t(n);
    auto expand = [&](const std::vector<glm::dvec3>& in, std::vector<glm::dvec3>& out, const char* name) {
      if (in.empty()) return;
      if (in.size() == P.size()) {
        for (int i = 0; i < n; ++i)
          for (const auto& c : cornersOf(i, in, glm::dvec3(0.0))) out.push_back(c);
      } else if (in.size() == nverts.size()) {
        for (int i = 0; i < n; ++i) out.push_back(in[size_t(surface->baseFace(i).first)]);
      } else {
        warnOnce(cat("subdiv-var:", name), cat(where, ": \"", name, "\" has ", in.size(), " values; a subdivision mesh takes ", P.size(), " or ", nverts.size(), "; ignored"));
      }
    };
    expand(vd.Cs, mesh->Cs, "Cs"), expand(vd.Os, mesh->Os, "Os");
    if (vd.st.size() == P.size())
      for (int i = 0; i < n; ++i)
        for (const auto& c : cornersOf(i, vd.st, glm::dvec2(0.0))) mesh->st.push_back(c);
  }
  std::vector<Primitive> out;
  for (int i = 0; i < n; ++i) {
    if (!surface->hasSurface(i)) continue;
    Primitive p = basePrim(PrimKind::Subdiv);
    p.subdiv = surface;
    p.ptexFace = i;
    p.triangle = scheme == SubdivScheme::Loop;
    p.keys = {Shape{}};
    if (mesh) {
      p.mesh = mesh;
      p.meshPoint = {uint32_t(4 * i), uint32_t(4 * i + 1), uint32_t(4 * i + 2), uint32_t(4 * i + 3)};
      p.meshFace = uint32_t(i);
    }
    out.push_back(std::move(p));
  }
  addPrims(std::move(out));
}

void Scene::curves(bool cubic, const std::vector<int>& nvertices, bool periodic, const std::vector<glm::dvec3>& P, const std::vector<double>& width,
                   const std::vector<glm::dvec3>& N, const VertexData& vd) {
  static const std::array<CubicBasis, 2> bezier{};
  const CubicBasis& basis = (cur_.attrs->basis ? *cur_.attrs->basis : bezier)[1];
  const int step = cubic ? basis.step : 1;
  for (const auto& c : P) checkFinite(*this, {c.x, c.y, c.z});
  // Segments and varying values per curve.
  std::vector<int> segments;
  size_t totalVertices = 0, totalVarying = 0;
  for (size_t c = 0; c < nvertices.size(); ++c) {
    const int n = nvertices[c];
    const int seg = patchCount(cubic, n, periodic, step);
    if (n < (cubic ? 4 : 2) || seg < 1) error(cat("curve ", c, " has ", n, " vertices: not whole ", periodic ? "periodic " : "", cubic ? "cubic" : "linear", " segments with a step of ", step));
    segments.push_back(seg);
    totalVertices += size_t(n);
    totalVarying += size_t(periodic ? seg : seg + 1);
  }
  if (totalVertices != P.size()) error(cat("curves name ", totalVertices, " vertices, \"P\" has ", P.size()));
  if (!(width.size() == 1 || width.size() == totalVarying)) error(cat("\"width\" has ", width.size(), " values; the curves take 1 or ", totalVarying, " (varying)"));
  for (double w : width)
    if (!(w >= 0) || !std::isfinite(w)) error(cat("curve width ", w, " must be a finite non-negative number"));
  if (!N.empty() && N.size() != totalVarying) error(cat("\"N\" has ", N.size(), " values; the curves take ", totalVarying, " (varying)"));
  std::shared_ptr<MeshData> mesh;
  if (!vd.Cs.empty() || !vd.Os.empty() || !vd.st.empty()) {
    mesh = std::make_shared<MeshData>();
    mesh->points = totalVarying, mesh->faces = nvertices.size();
    auto take = [&](const auto& in, auto& out, const char* name) {
      if (in.empty()) return;
      if (in.size() == totalVarying || in.size() == nvertices.size()) out = in;
      else warnOnce(cat("curves-var:", name), cat(where, ": \"", name, "\" has ", in.size(), " values; curves take ", totalVarying, " (varying) or ", nvertices.size(), " (uniform); ignored"));
    };
    take(vd.Cs, mesh->Cs, "Cs"), take(vd.Os, mesh->Os, "Os"), take(vd.st, mesh->st, "st");
  }
  const bool ortho = options_.camera.projection == store::Projection::Orthographic;
  std::vector<Primitive> out;
  size_t firstVertex = 0, firstVarying = 0;
  for (size_t c = 0; c < nvertices.size(); ++c) {
    const int n = nvertices[c], seg = segments[c], nVarying = periodic ? seg : seg + 1;
    for (int k = 0; k < seg; ++k) {
      Primitive p = basePrim(PrimKind::Curve);
      p.orthographicView = ortho;
      if (cubic) p.basis = cur_.attrs->basis;
      Shape s;
      for (int i = 0; i < (cubic ? 4 : 2); ++i) s.cv.push_back(P[firstVertex + size_t((k * step + i) % n)]);
      const size_t v0 = firstVarying + size_t(k), v1 = firstVarying + size_t((k + 1) % nVarying);
      s.q[0] = width.size() == 1 ? width[0] : width[v0];
      s.q[1] = width.size() == 1 ? width[0] : width[v1];
      if (!N.empty()) s.q[2] = 1, s.P[0] = N[v0], s.P[1] = N[v1];
      p.keys = {s};
      if (mesh) {
        p.mesh = mesh;
        p.meshPoint = {uint32_t(v0), uint32_t(v0), uint32_t(v1), uint32_t(v1)};  // colour varies along v
        p.meshFace = uint32_t(c);
      }
      out.push_back(std::move(p));
    }
    firstVertex += size_t(n), firstVarying += size_t(nVarying);
  }
  addPrims(std::move(out));
}

void Scene::nuPatch(int nu, int uorder, const std::vector<double>& uknot, double umin, double umax, int nv, int vorder, const std::vector<double>& vknot,
                    double vmin, double vmax, const std::vector<glm::dvec4>& Pw, const VertexData& vd) {
  // The checks RenderMan's definition implies, each a one-line error.
  auto direction = [&](const char* d, int n, int order, const std::vector<double>& knot, double lo, double hi) {
    if (order < 1 || order > 32) error(cat(d, "order ", order, " (1 to 32)"));
    if (n < order) error(cat(d, "order ", order, " is above its ", n, " control points"));
    if (knot.size() != size_t(n + order)) error(cat(d, "knot vector has ", knot.size(), " values; ", n, " points of order ", order, " need ", n + order));
    for (size_t i = 0; i < knot.size(); ++i) {
      if (!std::isfinite(knot[i])) error(cat(d, "knot ", i, " is not finite"));
      if (i && knot[i] < knot[i - 1]) error(cat(d, "knot vector decreases at knot ", i, " (", knot[i - 1], " then ", knot[i], ")"));
    }
    const double first = knot[size_t(order - 1)], last = knot[size_t(n)];
    if (!(lo < hi) || lo < first || hi > last) error(cat(d, "parameter range [", lo, ", ", hi, "] is not inside [", first, ", ", last, "]"));
  };
  direction("u ", nu, uorder, uknot, umin, umax);
  direction("v ", nv, vorder, vknot, vmin, vmax);
  if (Pw.size() != size_t(nu) * size_t(nv)) error(cat("a ", nu, " x ", nv, " NuPatch needs ", int64_t(nu) * nv, " control points, has ", Pw.size()));
  for (const auto& c : Pw) {
    checkFinite(*this, {c.x, c.y, c.z, c.w});
    if (!(c.w > 0)) error(cat("control point weight ", c.w, " must be positive"));
  }
  const int spansU = nu - uorder + 1, spansV = nv - vorder + 1;
  const size_t varying = size_t(spansU + 1) * size_t(spansV + 1), uniform = size_t(spansU) * size_t(spansV);
  std::shared_ptr<MeshData> mesh;
  if (!vd.Cs.empty() || !vd.Os.empty() || !vd.st.empty()) {
    mesh = std::make_shared<MeshData>();
    mesh->points = varying, mesh->faces = uniform;
    auto take = [&](const auto& in, auto& out, const char* name) {
      if (in.empty()) return;
      if (in.size() == varying || in.size() == uniform) out = in;
      else warnOnce(cat("nupatch-var:", name), cat(where, ": \"", name, "\" has ", in.size(), " values; a NuPatch takes ", varying, " (varying) or ", uniform, " (uniform); ignored"));
    };
    take(vd.Cs, mesh->Cs, "Cs"), take(vd.Os, mesh->Os, "Os");
    if (vd.st.size() == varying) mesh->st = vd.st;
  }
  std::vector<Primitive> out;
  for (int sv = 0; sv < spansV; ++sv)
    for (int su = 0; su < spansU; ++su) {
      const int iu = su + uorder - 1, iv = sv + vorder - 1;  // the span [knot[i], knot[i+1]]
      const double a = std::max(uknot[size_t(iu)], umin), b = std::min(uknot[size_t(iu + 1)], umax);
      const double c = std::max(vknot[size_t(iv)], vmin), d = std::min(vknot[size_t(iv + 1)], vmax);
      if (!(a < b) || !(c < d)) continue;  // an empty span, or outside the range drawn
      auto span = std::make_shared<NurbsSpan>();
      span->orderU = uorder, span->orderV = vorder;
      span->knotsU.assign(uknot.begin() + (iu - uorder + 1), uknot.begin() + (iu + uorder + 1));
      span->knotsV.assign(vknot.begin() + (iv - vorder + 1), vknot.begin() + (iv + vorder + 1));
      span->u0 = a, span->u1 = b, span->v0 = c, span->v1 = d;
      Primitive p = basePrim(PrimKind::Nurbs);
      p.nurbs = std::move(span);
      Shape s;
      for (int l = 0; l < vorder; ++l)
        for (int k = 0; k < uorder; ++k) {
          const glm::dvec4& c4 = Pw[size_t((sv + l) * nu + su + k)];
          s.cv.emplace_back(c4.x, c4.y, c4.z);
          s.cw.push_back(c4.w);
        }
      p.keys = {s};
      if (mesh) {
        p.mesh = mesh;
        auto corner = [&](int i, int j) { return uint32_t(j * (spansU + 1) + i); };
        p.meshPoint = {corner(su, sv), corner(su + 1, sv), corner(su, sv + 1), corner(su + 1, sv + 1)};
        p.meshFace = uint32_t(sv * spansU + su);
      }
      out.push_back(std::move(p));
    }
  addPrims(std::move(out));
}

void Scene::points(const std::vector<glm::dvec3>& P, const std::vector<double>& width, const VertexData& vd) {
  for (const auto& c : P) checkFinite(*this, {c.x, c.y, c.z});
  if (!(width.size() == 1 || width.size() == P.size())) error(cat("\"width\" has ", width.size(), " values; the points take 1 or ", P.size()));
  for (double w : width)
    if (!(w >= 0) || !std::isfinite(w)) error(cat("point width ", w, " must be a finite non-negative number"));
  std::shared_ptr<MeshData> mesh;
  if (!vd.Cs.empty() || !vd.Os.empty()) {
    mesh = std::make_shared<MeshData>();
    mesh->points = P.size(), mesh->faces = P.size();
    if (vd.Cs.size() == P.size()) mesh->Cs = vd.Cs;
    if (vd.Os.size() == P.size()) mesh->Os = vd.Os;
  }
  const bool ortho = options_.camera.projection == store::Projection::Orthographic;
  std::vector<Primitive> out;
  out.reserve(P.size());
  for (size_t i = 0; i < P.size(); ++i) {
    Primitive p = basePrim(PrimKind::Point);
    p.orthographicView = ortho;
    Shape s;
    s.P[0] = P[i];
    s.q[0] = width.size() == 1 ? width[0] : width[i];
    p.keys = {s};
    if (mesh) {
      p.mesh = mesh;
      p.meshPoint = {uint32_t(i), uint32_t(i), uint32_t(i), uint32_t(i)};
      p.meshFace = uint32_t(i);
    }
    out.push_back(std::move(p));
  }
  addPrims(std::move(out));
}

void Scene::emitFaces(const std::vector<int>& nverts, const std::vector<int>& verts, const std::vector<glm::dvec3>& P, const VertexData& vd,
                      std::vector<Primitive>& out) {
  size_t total = 0;
  for (int n : nverts) {
    if (n < 0) error("negative vertex count");
    total += size_t(n);
  }
  if (total != verts.size()) error(cat("polygons name ", verts.size(), " vertex indices; their counts add up to ", total));
  for (int v : verts)
    if (v < 0 || size_t(v) >= P.size()) error(cat("vertex index ", v, " out of range (", P.size(), " points)"));
  for (const auto& c : P) checkFinite(*this, {c.x, c.y, c.z});
  const size_t nFaces = nverts.size();
  std::shared_ptr<const MeshData> mesh;
  if (!vd.N.empty() || !vd.Cs.empty() || !vd.Os.empty() || !vd.st.empty()) {
    auto m = std::make_shared<MeshData>();
    m->N = vd.N, m->Cs = vd.Cs, m->Os = vd.Os, m->st = vd.st;
    m->points = P.size(), m->faces = nFaces;
    mesh = std::move(m);
  }
  size_t first = 0;
  for (size_t f = 0; f < nFaces; ++f) {
    const int n = nverts[f];
    const int* idx = verts.data() + first;
    first += size_t(n);
    if (n < 3) continue;
    // A fan of quads (and a closing triangle) from vertex 0; exact for convex planar polygons.
    for (int i = 1; i + 1 < n; i += 2) {
      const bool tri = i + 2 >= n;
      const int ring[4] = {idx[0], idx[i], idx[i + 1], tri ? idx[i + 1] : idx[i + 2]};
      const int rib[4] = {ring[0], ring[1], ring[3], ring[2]};  // ring → P00 P10 P01 P11
      Primitive p = basePrim(PrimKind::Patch);
      p.triangle = tri;
      Shape s;
      for (int c = 0; c < 4; ++c) s.P[c] = P[size_t(rib[c])];
      p.keys = {s};
      if (mesh) {
        p.mesh = mesh;
        for (int c = 0; c < 4; ++c) p.meshPoint[size_t(c)] = uint32_t(rib[c]);
        p.meshFace = uint32_t(f);
      }
      out.push_back(std::move(p));
    }
  }
}

void Scene::pointsPolygons(const std::vector<int>& nverts, const std::vector<int>& verts, const std::vector<glm::dvec3>& P, const VertexData& vd) {
  std::vector<Primitive> out;
  emitFaces(nverts, verts, P, vd, out);
  addPrims(std::move(out));
}

void Scene::polygon(const std::vector<glm::dvec3>& P, const VertexData& vd) {
  std::vector<int> idx(P.size());
  for (size_t i = 0; i < P.size(); ++i) idx[i] = int(i);
  pointsPolygons({int(P.size())}, idx, P, vd);
}

}  // namespace reshutter::shade
