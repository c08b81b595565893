#include "resample/camera_view.h"

#include <algorithm>
#include <cmath>
#include <cstdio>

#include <glm/geometric.hpp>
#include <glm/mat3x3.hpp>

#include "common/error.h"

namespace reshutter::resample {

store::Camera lookAtCamera(const store::Camera& base, const glm::dvec3& from, const glm::dvec3& to, const glm::dvec3& up, std::optional<double> fovDegrees) {
  const glm::dvec3 forward = to - from;
  if (!(glm::length(forward) > 0) || !std::isfinite(glm::length(forward))) fail("--look-at", "the camera looks from where it looks at (or at a non-finite point)");
  const glm::dvec3 z = glm::normalize(forward);
  const glm::dvec3 side = glm::cross(up, z);
  if (!(glm::length(side) > 1e-9 * glm::length(up))) fail("--up", "the up vector is parallel to the view direction (or zero)");
  // RenderMan's camera space: x right, y up, z forward - left-handed when the world is.
  glm::dvec3 x = glm::normalize(side);
  const glm::dvec3 y = glm::cross(z, x);
  if (glm::determinant(glm::dmat3(base.worldToCamera)) < 0) x = -x;
  glm::dmat4 m(1.0);  // m[column][row]
  for (int c = 0; c < 3; ++c) m[c][0] = x[c], m[c][1] = y[c], m[c][2] = z[c];
  m[3][0] = -glm::dot(x, from), m[3][1] = -glm::dot(y, from), m[3][2] = -glm::dot(z, from);
  store::Camera cam = base;
  cam.name = "look-at";
  cam.worldToCamera = m;
  if (fovDegrees) {
    if (!(*fovDegrees > 0 && *fovDegrees < 180)) fail("--fov", "the field of view must lie in (0, 180) degrees, got ", *fovDegrees);
    if (base.projection != store::Projection::Perspective) fail("--fov", "the camera is orthographic: it has no field of view");
    cam.fovDegrees = *fovDegrees;
  }
  return cam;
}

std::vector<store::Camera> stereoPair(const store::Camera& centre, double baseline, double convergence) {
  if (!(baseline > 0) || !std::isfinite(baseline)) fail("stereo", "the baseline must be a positive distance, got ", baseline);
  if (!(convergence > 0)) fail("stereo", "the convergence distance must be positive, got ", convergence);
  std::vector<store::Camera> eyes;
  double sw[4];
  centre.effectiveScreenWindow(sw);
  const store::Projector p(centre);
  for (const double side : {-1.0, 1.0}) {
    store::Camera eye = centre;
    eye.name = side < 0 ? "left" : "right";
    const double dx = side * 0.5 * baseline;  // the eye's x in the centre camera's space
    glm::dmat4 shift(1.0);
    shift[3][0] = -dx;
    eye.worldToCamera = shift * centre.worldToCamera;
    if (std::isfinite(convergence) && centre.projection == store::Projection::Perspective) {
      // A point on the centre's axis at the convergence depth is at x = -dx for this eye: screen
      // x -dx / convergence · scale. Shifting the window by that much puts it back in the middle.
      const double scale = p.ax * (sw[1] - sw[0]) / centre.width;  // screen units per unit of x/z
      const double s = -dx / convergence * scale;
      eye.screenWindow[0] = sw[0] + s, eye.screenWindow[1] = sw[1] + s, eye.screenWindow[2] = sw[2], eye.screenWindow[3] = sw[3];
    }
    eyes.push_back(eye);
  }
  return eyes;
}

std::vector<store::Camera> stereoPair(const store::Camera& centre, const std::string& rig, const std::string& where) {
  double baseline = 0, convergence = INFINITY;
  char extra = 0;
  const int n = std::sscanf(rig.c_str(), "%lf:%lf%c", &baseline, &convergence, &extra);
  if (n < 1 || n > 2 || (n == 1 && rig.find(':') != std::string::npos))
    fail(where, "expected BASELINE or BASELINE:CONVERGENCE (camera-space units), got '", rig, "'");
  try {
    return stereoPair(centre, baseline, convergence);
  } catch (const Error& e) {
    fail(where, e.problem());
  }
}

glm::dmat4 primaryToView(const store::Camera& primary, const store::Camera& view) { return view.worldToCamera * glm::inverse(primary.worldToCamera); }

bool sameView(const store::Camera& primary, const store::Camera& view) {
  double a[4], b[4];
  primary.effectiveScreenWindow(a), view.effectiveScreenWindow(b);
  return primary.worldToCamera == view.worldToCamera && primary.projection == view.projection && primary.fovDegrees == view.fovDegrees &&
         std::equal(a, a + 4, b) && primary.nearClip == view.nearClip && double(primary.width) * view.height == double(view.width) * primary.height;
}

CarriedStore::CarriedStore(const store::StoreReader& reader, const store::Camera& view, const store::Projector& projector)
    : reader_(reader),
      toView_(primaryToView(reader.meta().cameras[0], view)),
      entries_(store::carriedEntries(reader.entries(), toView_, store::Projector(reader.meta().cameras[0]), projector)),
      bounds_(entries_, reader.meta().schedules, projector, reader.meta().shutterOpen, reader.meta().shutterClose) {}

std::shared_ptr<const store::TilePart> CarriedStore::part(size_t entry) const {
  return std::make_shared<const store::TilePart>(store::carriedPart(*reader_.part(entry), toView_, reader_.meta().schema));
}

store::StoredLight carriedLight(const store::StoredLight& light, const glm::dmat4& toView) {
  store::StoredLight l = light;
  l.position = glm::dvec3(toView * glm::dvec4(light.position, 1.0));
  const glm::dvec3 axis = glm::dmat3(toView) * light.axis;
  if (glm::length(axis) > 0) l.axis = glm::normalize(axis);
  return l;
}

}  // namespace reshutter::resample
