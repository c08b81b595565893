// The volume plugin's procedural smoke puff (resample/volume.h, SmokePuff): fractal value noise
// on a sphere, written as an OpenVDB fog volume; and OpenVDB's one-time initialisation, which
// the plugin's files share.
#include <algorithm>
#include <cmath>
#include <mutex>
#include <string>

#include <openvdb/openvdb.h>
#include <glm/geometric.hpp>

#include "common/atomic_file.h"
#include "common/error.h"
#include "common/random.h"
#include "resample/volume.h"

namespace reshutter::resample {

namespace {

using openvdb::FloatGrid;

// Value noise in [0, 1] on the integer lattice, trilinear with a smoothstep fade.
double valueNoise(const glm::dvec3& p, uint64_t seed) {
  const glm::dvec3 fl = glm::floor(p), f = p - fl;
  const glm::dvec3 u = f * f * (3.0 - 2.0 * f);
  auto at = [&](int dx, int dy, int dz) {
    const uint64_t key = seed ^ (uint64_t(int64_t(fl.x) + dx) * 0x9E3779B97F4A7C15ull) ^ (uint64_t(int64_t(fl.y) + dy) * 0xC2B2AE3D27D4EB4Full) ^
                         (uint64_t(int64_t(fl.z) + dz) * 0x165667B19E3779F9ull);
    return toUnitDouble(mix64(key));
  };
  double x00 = at(0, 0, 0) + u.x * (at(1, 0, 0) - at(0, 0, 0)), x10 = at(0, 1, 0) + u.x * (at(1, 1, 0) - at(0, 1, 0));
  double x01 = at(0, 0, 1) + u.x * (at(1, 0, 1) - at(0, 0, 1)), x11 = at(0, 1, 1) + u.x * (at(1, 1, 1) - at(0, 1, 1));
  const double y0 = x00 + u.y * (x10 - x00), y1 = x01 + u.y * (x11 - x01);
  return y0 + u.z * (y1 - y0);
}

}  // namespace

void initialiseOpenVdb() {
  static std::once_flag once;
  std::call_once(once, [] { openvdb::initialize(); });
}

void writeSmokeVdb(const std::string& path, const SmokePuff& puff) {
  initialiseOpenVdb();
  FloatGrid::Ptr grid = FloatGrid::create(0.f);
  grid->setTransform(openvdb::math::Transform::createLinearTransform(puff.voxelSize));
  grid->setName("density");
  grid->setGridClass(openvdb::GRID_FOG_VOLUME);
  auto acc = grid->getAccessor();
  const double reach = puff.radius * 1.35;
  const int n = int(std::ceil(reach / puff.voxelSize));
  const openvdb::Coord c(int(std::lround(puff.centre.x / puff.voxelSize)), int(std::lround(puff.centre.y / puff.voxelSize)),
                         int(std::lround(puff.centre.z / puff.voxelSize)));
  for (int i = -n; i <= n; ++i)
    for (int j = -n; j <= n; ++j)
      for (int k = -n; k <= n; ++k) {
        const glm::dvec3 q = glm::dvec3(i, j, k) * puff.voxelSize;  // from the centre
        const double r = glm::length(q) / puff.radius;
        if (r > 1.35) continue;
        // Three octaves of noise push the surface in and out by up to a third of the radius.
        const glm::dvec3 at = (puff.centre + q) / puff.radius;
        const double fbm = (valueNoise(at * 2.0, puff.seed) * 4 + valueNoise(at * 4.0, puff.seed + 1) * 2 + valueNoise(at * 8.0, puff.seed + 2)) / 7;
        const double edge = 1.0 - r + 0.35 * (fbm - 0.5) * 2;
        const double d = std::clamp(edge / 0.3, 0.0, 1.0);
        if (d > 1e-3) acc.setValue(c.offsetBy(i, j, k), float(d * d * (3 - 2 * d)));
      }
  AtomicFile file(path);
  try {
    openvdb::io::File(file.tempPath()).write({grid});
  } catch (const std::exception& e) {
    fail(path, "writing the OpenVDB file failed: ", e.what());
  }
  file.commit();
}

}  // namespace reshutter::resample
