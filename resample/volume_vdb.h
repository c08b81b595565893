// The volume plugin's own header (only the plugin's files include it; they are the only ones
// that include OpenVDB): the loaded scene that volume_vdb_scene.cpp reads from the files and
// volume_vdb.cpp marches through, and the conversions both use.
#pragma once

#include <memory>
#include <string>
#include <vector>

#include <openvdb/openvdb.h>
#include <openvdb/tools/RayIntersector.h>
#include <glm/mat4x4.hpp>
#include <glm/vec3.hpp>

#include "resample/volume_engine.h"

namespace reshutter::resample {

// Shared by the plugin's files (defined in volume_smoke.cpp).
void initialiseOpenVdb();
void writeSmokeVdb(const std::string& path, const SmokePuff& puff);

namespace vdb {

using openvdb::FloatGrid;
using openvdb::Vec3SGrid;
using Intersector = openvdb::tools::VolumeRayIntersector<FloatGrid>;

inline glm::dvec3 toGlm(const openvdb::Vec3d& v) { return {v.x(), v.y(), v.z()}; }
inline openvdb::Vec3d toVdb(const glm::dvec3& v) { return {v.x, v.y, v.z}; }

// A linear grid's world -> index map as a glm matrix (column vectors).
glm::dmat4 indexFromWorld(const openvdb::GridBase& grid);

// The volumes of a render, read and checked, in their files' world spaces.
struct VdbScene final : VolumeSceneEngine {
  struct Volume {
    VolumeSpec spec;
    FloatGrid::Ptr density;
    FloatGrid::Ptr emissionScalar;
    Vec3SGrid::Ptr emissionColour;
    Vec3SGrid::Ptr colour;  // scales the albedo (Cd)
    Vec3SGrid::Ptr velocity;
    std::shared_ptr<const Intersector> intersector;  // the master the tracers copy (shallowly)
    // The active voxels' bounds (dilated by the interpolation's reach) in the file's world space.
    glm::dvec3 fileLo{0.0}, fileHi{0.0};
    double maxSpeed = 0;                                                   // file world units per second
    double voxelSize = 1;                                                  // file world units
    glm::dmat4 densityIndex{1.0}, emissionIndex{1.0}, velocityIndex{1.0}, colourIndex{1.0};  // file world → each grid's index space
  };
  std::vector<Volume> volumes;
  VolumeOptions opts;
  size_t size() const override { return volumes.size(); }
  const VolumeOptions& options() const { return opts; }
};

/// Reads and checks every volume's grids; a volume without active density is left out with a
/// warning. Throws Error naming the file on anything it cannot use.
std::unique_ptr<VdbScene> loadScene(const std::vector<VolumeSpec>& specs, const VolumeOptions& options, std::vector<std::string>& warnings);

}  // namespace vdb
}  // namespace reshutter::resample
