// The volume plugin's loading (volume_vdb.h): OpenVDB files opened, their grids read and checked,
// non-finite values zeroed, bounds and index maps measured once for the tracers.
#include <cmath>
#include <filesystem>

#include "common/error.h"
#include "resample/volume_vdb.h"

namespace reshutter::resample::vdb {

// A linear grid's world → index map as a glm matrix (column vectors): OpenVDB's matrices act on
// row vectors, world = index · M, so glm's m[i][j] = M(i, j) is M transposed into glm's
// column-major storage, and its inverse maps world to index.
glm::dmat4 indexFromWorld(const openvdb::GridBase& grid) {
  const openvdb::Mat4d M = grid.transform().baseMap()->getAffineMap()->getMat4();
  glm::dmat4 g;
  for (int i = 0; i < 4; ++i)
    for (int j = 0; j < 4; ++j) g[i][j] = M(i, j);
  return glm::inverse(g);
}

namespace {

template <class GridT>
typename GridT::Ptr readGrid(openvdb::io::File& file, const std::string& path, const std::string& name, const char* wanted) {
  if (!file.hasGrid(name)) {
    std::string names;
    for (auto it = file.beginName(); it != file.endName(); ++it) names += (names.empty() ? "" : " ") + it.gridName();
    fail(path, "no grid named '", name, "' (the file has: ", names.empty() ? "no grids" : names, ")");
  }
  openvdb::GridBase::Ptr base = file.readGrid(name);
  typename GridT::Ptr grid = openvdb::gridPtrCast<GridT>(base);
  if (!grid) fail(path, "grid '", name, "' holds ", base->valueType(), " values; a volume's '", name, "' must be a ", wanted, " grid");
  if (!grid->hasUniformVoxels()) fail(path, "grid '", name, "' has non-uniform voxels, which the ray marcher does not support");
  if (!grid->transform().isLinear()) fail(path, "grid '", name, "' has a non-linear (frustum) transform, which the ray marcher does not support");
  return grid;
}

// Non-finite values of a float grid become zero; returns how many there were.
size_t zeroNonFinite(FloatGrid& grid) {
  size_t bad = 0;
  for (auto it = grid.beginValueOn(); it; ++it)
    if (!std::isfinite(*it)) it.setValue(0.f), ++bad;
  return bad;
}

}  // namespace

std::unique_ptr<VdbScene> loadScene(const std::vector<VolumeSpec>& specs, const VolumeOptions& options, std::vector<std::string>& warnings) {
  initialiseOpenVdb();
  auto scene = std::make_unique<VdbScene>();
  scene->opts = options;
  for (const VolumeSpec& spec : specs) {
    const std::string& path = spec.path;
    if (!std::filesystem::exists(path)) fail(path, "no such file");
    VdbScene::Volume v;
    v.spec = spec;
    openvdb::io::File file(path);
    try {
      file.open(false);
    } catch (const std::exception& e) {
      fail(path, "not a readable OpenVDB file (", e.what(), ")");
    }
    try {
      v.density = readGrid<FloatGrid>(file, path, spec.density, "float");
      if (!spec.emission.empty()) {
        if (!file.hasGrid(spec.emission)) readGrid<FloatGrid>(file, path, spec.emission, "float or vec3");  // fails naming the grids
        openvdb::GridBase::Ptr base = file.readGrid(spec.emission);
        v.emissionScalar = openvdb::gridPtrCast<FloatGrid>(base);
        v.emissionColour = openvdb::gridPtrCast<Vec3SGrid>(base);
        if (!v.emissionScalar && !v.emissionColour)
          fail(path, "grid '", spec.emission, "' holds ", base->valueType(), " values; emission must be a float or vec3 grid");
      }
      if (!spec.colour.empty()) v.colour = readGrid<Vec3SGrid>(file, path, spec.colour, "vec3");
      std::string velocityName = spec.velocity;
      if (velocityName.empty()) velocityName = file.hasGrid("vel") ? "vel" : file.hasGrid("v") ? "v" : "";
      if (!velocityName.empty()) v.velocity = readGrid<Vec3SGrid>(file, path, velocityName, "vec3");
    } catch (const Error&) {
      throw;
    } catch (const std::exception& e) {
      fail(path, "reading its grids failed: ", e.what());
    }
    file.close();
    if (const size_t bad = zeroNonFinite(*v.density))
      warnings.push_back(cat(path, ": ", bad, " non-finite density value", bad == 1 ? "" : "s", " set to zero"));
    if (v.emissionScalar) zeroNonFinite(*v.emissionScalar);
    if (v.density->empty() || v.density->activeVoxelCount() == 0) {
      warnings.push_back(cat(path, ": grid '", spec.density, "' has no active voxels; the volume is left out"));
      continue;
    }
    // Dilated by one voxel: trilinear interpolation reaches one voxel beyond the active ones.
    v.intersector = std::make_shared<const Intersector>(*v.density, 1);
    const openvdb::CoordBBox box = v.intersector->bbox();
    glm::dvec3 lo(INFINITY), hi(-INFINITY);
    for (int c = 0; c < 8; ++c) {
      const openvdb::Vec3d corner((c & 1) ? box.max().x() : box.min().x(), (c & 2) ? box.max().y() : box.min().y(), (c & 4) ? box.max().z() : box.min().z());
      const glm::dvec3 w = toGlm(v.density->indexToWorld(corner));
      lo = glm::min(lo, w), hi = glm::max(hi, w);
    }
    v.fileLo = lo, v.fileHi = hi;
    v.voxelSize = v.density->voxelSize()[0];
    v.densityIndex = indexFromWorld(*v.density);
    if (v.emissionScalar) v.emissionIndex = indexFromWorld(*v.emissionScalar);
    if (v.emissionColour) v.emissionIndex = indexFromWorld(*v.emissionColour);
    if (v.velocity) v.velocityIndex = indexFromWorld(*v.velocity);
    if (v.colour) v.colourIndex = indexFromWorld(*v.colour);
    if (v.velocity)
      for (auto it = v.velocity->cbeginValueOn(); it; ++it) {
        const double s = double(it->length());
        if (std::isfinite(s)) v.maxSpeed = std::max(v.maxSpeed, s);
      }
    scene->volumes.push_back(std::move(v));
  }
  return scene;
}

}  // namespace reshutter::resample::vdb
