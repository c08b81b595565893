// RIB graphics-state requests → Scene builder calls (the set is in rib_state.h).
#include "shade/rib_state.h"

#include <cmath>

#include <glm/gtc/type_ptr.hpp>

#include "common/error.h"
#include "common/log.h"

namespace reshutter::shade {

using rib::Args;
using rib::Param;
using rib::Value;

int64_t integerArg(const Args& a, size_t i, double lo, double hi) {
  const double v = a.number(i);
  if (!(v >= lo && v <= hi) || v != std::trunc(v)) a.fail(cat("argument ", i + 1, " must be an integer in [", lo, ", ", hi, "], not ", v));
  return int64_t(v);
}

std::vector<int> intArray(const Args& a, size_t i, double lo, double hi) {
  std::vector<int> out;
  const auto& v = a.numbers(i);
  out.reserve(v.size());
  for (double d : v) {
    if (!(d >= lo && d <= hi) || d != std::trunc(d)) a.fail(cat("argument ", i + 1, " expects integers in [", lo, ", ", hi, "], got ", d));
    out.push_back(int(d));
  }
  return out;
}

glm::dmat4 matrixArg(const Args& a) {
  std::vector<double> v;
  if (a.count() >= 16) {
    for (size_t i = 0; i < 16; ++i) v.push_back(a.number(i));
  } else {
    v = a.numbers(0);
  }
  if (v.size() != 16) a.fail(cat("expects a 4x4 matrix (16 numbers), has ", v.size()));
  for (double x : v)
    if (!std::isfinite(x)) a.fail("matrix element is not finite");
  // RIB matrices are row-major for row vectors: read column-major they are the column-vector
  // matrix glm wants.
  return glm::make_mat4(v.data());
}

namespace {

glm::dvec3 colorArg(const Args& a) {
  if (a.count() >= 3) return {a.number(0), a.number(1), a.number(2)};
  const auto& v = a.numbers(0);
  if (v.size() == 1) return glm::dvec3(v[0]);
  if (v.size() != 3) a.fail(cat("expects a colour of 3 numbers, has ", v.size()));
  return {v[0], v[1], v[2]};
}

/// The first number of a parameter ("fov" [45] or "fov" 45); false when it has none.
bool firstNumber(const Param& p, double& out) {
  if (!p.value) return false;
  if (p.value->kind == Value::Kind::Number) return out = p.value->number, true;
  if (p.value->kind == Value::Kind::NumberArray && !p.value->numbers.empty()) return out = p.value->numbers.front(), true;
  return false;
}

void projection(Scene& s, const Args& a) {
  const std::string& type = a.string(0);
  if (type == "orthographic") return s.orthographic();
  double fov = 90;
  for (const Param& p : a.params(1))
    if (p.decl.name == "fov" && !firstNumber(p, fov)) a.fail("\"fov\" takes one number");
  // RIS cameras (PxrCamera, PxrCylinderCamera …) are perspective projections with a "fov": the
  // pinhole they reduce to is kept, with a warning, rather than dropping the frame.
  if (type != "perspective")
    warnOnce(cat("projection:", type), cat(s.where, ": projection '", type, "' is not built in; using a perspective projection with its \"fov\" (", fov, ")"));
  s.perspective(fov);
}

bool options(Scene& s, std::string_view n, const Args& a) {
  if (n == "Format") return s.format(int(integerArg(a, 0, 1, 1 << 20)), int(integerArg(a, 1, 1, 1 << 20)), a.count() > 2 ? a.number(2) : 1.0), true;
  if (n == "FrameAspectRatio") return s.frameAspectRatio(a.number(0)), true;
  if (n == "ScreenWindow") {
    if (a.count() == 1) {
      const auto& v = a.numbers(0);
      if (v.size() != 4) a.fail(cat("expects 4 numbers, has ", v.size()));
      return s.screenWindow(v[0], v[1], v[2], v[3]), true;
    }
    return s.screenWindow(a.number(0), a.number(1), a.number(2), a.number(3)), true;
  }
  if (n == "Projection") return projection(s, a), true;
  if (n == "Clipping") return s.clipping(a.number(0), a.number(1)), true;
  if (n == "DepthOfField") {
    // No arguments turns the lens off (RenderMan's pinhole); otherwise fstop focallength focaldistance.
    if (a.count() == 0) return s.depthOfField(0, 0, 0), true;
    if (a.count() != 3) a.fail(cat("expects fstop focallength focaldistance, has ", a.count(), " arguments"));
    return s.depthOfField(a.number(0), a.number(1), a.number(2)), true;
  }
  if (n == "Shutter") return s.shutter(a.number(0), a.number(1)), true;
  if (n == "Camera") return s.camera(a.string(0)), true;
  if (n == "FrameBegin") return s.frameBegin(a.count() ? integerArg(a, 0, -1e15, 1e15) : 1), true;
  if (n == "FrameEnd") return s.frameEnd(), true;
  if (n == "WorldBegin") return s.worldBegin(), true;
  if (n == "WorldEnd") return s.worldEnd(), true;
  return false;
}

bool transforms(Scene& s, std::string_view n, const Args& a) {
  if (n == "AttributeBegin") return s.attributeBegin(), true;
  if (n == "AttributeEnd") return s.attributeEnd(), true;
  if (n == "TransformBegin") return s.transformBegin(), true;
  if (n == "TransformEnd") return s.transformEnd(), true;
  if (n == "Identity") return s.identity(), true;
  if (n == "Transform") return s.transform(matrixArg(a)), true;
  if (n == "ConcatTransform") return s.concatTransform(matrixArg(a)), true;
  if (n == "Translate") return s.translate(a.number(0), a.number(1), a.number(2)), true;
  if (n == "Rotate") return s.rotate(a.number(0), a.number(1), a.number(2), a.number(3)), true;
  if (n == "Scale") return s.scale(a.number(0), a.number(1), a.number(2)), true;
  if (n == "CoordinateSystem") return s.coordinateSystem(a.string(0)), true;
  if (n == "CoordSysTransform") return s.coordSysTransform(a.string(0)), true;
  if (n == "MotionBegin") {
    if (a.count() == 1) return s.motionBegin(a.numbers(0)), true;
    std::vector<double> t;
    for (size_t i = 0; i < a.count(); ++i) t.push_back(a.number(i));
    return s.motionBegin(t), true;
  }
  if (n == "MotionEnd") return s.motionEnd(), true;
  return false;
}

bool attributes(Scene& s, std::string_view n, const Args& a) {
  if (n == "Orientation") return s.orientation(a.string(0)), true;
  if (n == "ReverseOrientation") return s.reverseOrientation(), true;
  if (n == "Sides") return s.sides(int(integerArg(a, 0, 1, 2))), true;
  if (n == "Color") return s.color(colorArg(a)), true;
  if (n == "Opacity") return s.opacity(colorArg(a)), true;
  if (n == "Matte") return s.matte(a.number(0) != 0), true;
  return false;
}

}  // namespace

bool applyStateRequest(Scene& s, const rib::Request& r, const Args& a) {
  const std::string_view n = r.name;
  s.where = cat(r.where.str(), " (", n, ")");
  return options(s, n, a) || transforms(s, n, a) || attributes(s, n, a);
}

}  // namespace reshutter::shade
