// Volumes at re-sample time: OpenVDB fog volumes (a density grid, optional emission and
// velocity grids) placed in world space and integrated along each sample's ray, at the sample's
// own time, up to the surfaces it saw. Owns loading and checking the files, their placement, and
// the ray integration (absorption and emission; OpenVDB's VolumeRayIntersector skips empty
// space, its samplers interpolate). The resolve (hit_buffer.cpp) composites the segments it
// returns between a sample's surfaces, and deep output keeps them as volume samples.
//
// OpenVDB stays behind this header: the classes below hold engines (resample/volume_engine.h)
// that a plugin built with OpenVDB makes, loaded the first time a volume is asked for, so the
// rest of the re-sampler neither compiles nor links against it.
#pragma once

#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include <glm/mat4x4.hpp>
#include <glm/vec3.hpp>

#include "store/model.h"

namespace reshutter::resample {

/// One volume as the user asks for it:
/// "smoke.vdb[,density=GRID][,emission=GRID][,velocity=GRID][,color=GRID][,scale=S][,translate=X:Y:Z]
///  [,density-scale=K][,emission-color=R:G:B][,albedo=R:G:B][,anisotropy=G]".
struct VolumeSpec {
  std::string path;
  std::string density = "density";
  std::string emission;  // float grid (times emissionColour) or vec3 grid; empty = none
  std::string velocity;  // vec3 grid, world units per second; empty = "vel" or "v" if the file has one
  std::string colour;    // vec3 grid scaling the albedo per voxel (Houdini's Cd); empty = none
  double scale = 1;      // placement: world = translate + scale · (the file's own world position)
  glm::dvec3 translate{0.0};
  float densityScale = 1;  // extinction per world unit = densityScale · density
  glm::vec3 emissionColour{1.f, 1.f, 1.f};
  glm::vec3 albedo{1.f, 1.f, 1.f};  // scattering / extinction, per channel
  float anisotropy = 0;             // Henyey-Greenstein g: > 0 scatters forward
  /// A volume of the scene (StoredVolume): placed straight into camera space by these transforms
  /// at these frame-relative times (linear between them, held outside), instead of the world
  /// placement above. Empty: placed in the world.
  std::vector<double> times;
  std::vector<glm::dmat4> fileToCamera;
  /// The store's record of a scene volume, as a spec.
  static VolumeSpec fromStore(const store::StoredVolume& v);
  /// Parses the text above; throws Error naming `where` (an option) on a bad key or value.
  static VolumeSpec parse(const std::string& text, const std::string& where);
};

/// The integration's accuracy knob.
struct VolumeOptions {
  /// Ray-march step in voxels of each volume's density grid. One voxel: RMS error 8e-5 on the
  /// demo's smoke against a 1/16-voxel reference, far below 16-spp sampling noise, at 56 % of the
  /// half-voxel step's time (bench/volume_steps.sh, docs/accuracy.md).
  float step = 1.0f;
  /// Skip empty space with OpenVDB's hierarchical DDA; off: step through each volume's whole
  /// bounding box (the same image to the step's sampling, only slower: to measure what it saves).
  bool skipEmpty = true;
  /// Step of the shadow rays toward each light (single scattering's self-shadowing), in voxels.
  float shadowStep = 1.0f;
  /// Look the in-scattered light up in a per-render cache (VolumeLighting) rather than marching a
  /// shadow ray per light from every step: within the cache's interpolation of the exact rays.
  bool cacheShadows = true;
  /// Shared rays: one ray per point of a screen lattice `raySpacing` pixels apart, marched once
  /// from the eye through every volume and tabulated (optical depth and radiance against depth);
  /// a sample's segment blends the four rays around it bilinearly. 0: every sample marches its
  /// own ray (exact to the step). Only volumes that stay put over the render share rays (no
  /// velocity grid, no moving transform); others are marched per sample.
  float raySpacing = 1.0f;
};

/// What a volume adds over a stretch of a ray: the light it emits toward the camera
/// (premultiplied, as `over` composites it) and its transmittance.
struct VolumeSegment {
  float radiance[3] = {0.f, 0.f, 0.f};
  float transmittance = 1.f;
};

/// One stretch of a volume segment for deep output: the steps whose midpoints fall in depth slice
/// `slice` (camera depths [ratio^slice, ratio^(slice+1)), the deep tolerance's ratio), with what
/// they add over their own extent [zFront, zBack] (radiance premultiplied, relative to the slice's
/// front). Slices are the same for every sample of a render, so the deep image can merge a
/// pixel's samples slice by slice.
struct VolumeSlice {
  int32_t slice = 0;
  float zFront = 0, zBack = 0;
  VolumeSegment segment;
};

/// Object id of volume samples in deep output (their idManifest name is "volumes").
inline constexpr uint32_t kVolumeObjectId = 0xFFFFFFFEu;

struct VolumeSceneEngine;
struct VolumeLightingEngine;
struct VolumeTracerEngine;

/// Loaded volumes, shared read-only by every thread of every render that uses them.
class VolumeScene {
 public:
  /// Loads and checks every volume; throws Error naming the file (and grid) on a missing file or
  /// grid, a grid of the wrong type, or non-uniform voxels.
  VolumeScene(const std::vector<VolumeSpec>& specs, const VolumeOptions& options);
  /// `base`'s volumes (shared, not loaded again) followed by those of `more`, with base's options.
  VolumeScene(const VolumeScene& base, const std::vector<VolumeSpec>& more);
  ~VolumeScene();
  VolumeScene(const VolumeScene&) = delete;
  VolumeScene& operator=(const VolumeScene&) = delete;

  const VolumeOptions& options() const { return options_; }
  size_t size() const;
  /// Warnings found while loading (NaN densities set to zero, an empty grid), one line each.
  const std::vector<std::string>& warnings() const { return warnings_; }

  const VolumeSceneEngine& engine() const { return *engine_; }

 private:
  VolumeOptions options_;
  std::vector<std::string> warnings_;
  std::unique_ptr<VolumeSceneEngine> engine_;
};

/// The camera a render looks through, as volume tracing needs it: raster position → camera-space
/// ray, camera → world, and the clock (velocity grids are per second; the volume is where the
/// file puts it at `referenceFrame`).
struct VolumeCamera {
  double ax = 1, bx = 0, ay = 1, by = 0;  // raster = a·(x/z) + b (perspective) or a·x + b
  /// The lights the store recorded (camera space), for single scattering.
  std::vector<store::StoredLight> lights;
  bool perspective = true;
  /// A thin lens (depth of field, perspective only): radius in camera units and focal distance.
  /// A sample with lens point L = lensRadius·(u, v) (u, v on the unit disk) sees along the ray
  /// L + (p − L/d)·z, p the pinhole direction through its raster position: the ray the
  /// rasterizer's lens path tests surfaces against. 0: a pinhole.
  double lensRadius = 0, focalDistance = 1;
  glm::dmat4 worldToCamera{1.0};
  double framesPerSecond = 24;
  double referenceFrame = 0;  // absolute frames
};

/// Counters for --stats.
struct VolumeStats {
  uint64_t rays = 0;           // ray segments that reached a volume's bounds
  uint64_t steps = 0;          // density lookups along them
  uint64_t shadowSteps = 0;    // density lookups along shadow rays (the shadow cache's included)
  uint64_t cachedShadows = 0;  // steps whose in-scattered light came from the cache (VolumeLighting)
  uint64_t sharedRays = 0;     // lattice rays marched (VolumeOptions::raySpacing)
  uint64_t sharedSegments = 0; // segments blended from them instead of marched
  void add(const VolumeStats& o) {
    rays += o.rays, steps += o.steps, shadowSteps += o.shadowSteps, cachedShadows += o.cachedShadows;
    sharedRays += o.sharedRays, sharedSegments += o.sharedSegments;
  }
};

/// One render's lighting of its volumes: the light every light sends through the medium and
/// scatters toward the eye (shadowed, by the phase function), cached on a lattice of twice each
/// volume's voxel size over its active voxels, so that single scattering looks it up instead of
/// marching a shadow ray per light from every step. The direction to the eye is exact for a
/// perspective camera (the eye is camera space's origin). Built once per render, in parallel;
/// volumes that move with a velocity grid are not cached (their light moves with them: their
/// steps march shadow rays).
class VolumeLighting {
 public:
  VolumeLighting(const VolumeScene& scene, const VolumeCamera& camera);
  ~VolumeLighting();
  const VolumeLightingEngine& engine() const { return *engine_; }
  /// Density lookups the cache took to build.
  uint64_t buildSteps() const;

 private:
  std::unique_ptr<VolumeLightingEngine> engine_;
};

/// Traces one thread's rays through a VolumeScene (it holds per-thread accessors and intersector
/// copies, so each thread makes its own).
class VolumeTracer {
 public:
  /// `lighting` (may be null: shadow rays are marched) must outlive the tracer.
  VolumeTracer(const VolumeScene& scene, const VolumeCamera& camera, double earliest, double latest, const VolumeLighting* lighting = nullptr);
  ~VolumeTracer();
  /// Whether any volume may lie behind raster region [x0, x1] × [y0, y1] between the render's
  /// earliest and latest time (conservative: a volume that reaches the eye plane touches all).
  bool touches(double x0, double y0, double x1, double y1) const;
  /// Starts a region of samples [x0, x0+w) × [y0, y0+h) (raster pixels), walked row by row:
  /// the shared rays it needs are traced as its samples ask for them.
  void beginRegion(int x0, int y0, int w, int h);
  /// Whether segments come from shared rays (VolumeOptions::raySpacing) rather than marches.
  bool sharesRays() const;
  /// Integrates the ray through raster (x, y) and lens point (u, v) on the unit disk (0, 0
  /// without a lens) at absolute time t over camera depths [z0, z1] (z1 may be infinite: the
  /// volumes' far side).
  void integrate(double x, double y, double u, double v, double t, double z0, double z1, VolumeSegment& out) {
    integrate(x, y, u, v, t, z0, z1, out, nullptr, 0.0);
  }
  /// The same, also appending the segment's depth slices (ratio > 1) to `slices` (deep output);
  /// `out` is bit for bit what the call without slices gives.
  void integrate(double x, double y, double u, double v, double t, double z0, double z1, VolumeSegment& out, std::vector<VolumeSlice>* slices,
                 double ratio);
  const VolumeStats& stats() const { return stats_; }

 private:
  std::unique_ptr<VolumeTracerEngine> engine_;
  VolumeStats stats_;
};

/// A procedural smoke puff, for the demo and the benchmarks: density 1 inside a sphere whose
/// surface is pushed in and out by fractal value noise, falling off smoothly over its rim;
/// written as an OpenVDB file with one `density` grid (the file's world = the caller's world).
struct SmokePuff {
  glm::dvec3 centre{0.0};
  double radius = 1;
  double voxelSize = 0.05;
  uint64_t seed = 1;
};
/// Throws Error naming the file if it cannot be written.
void writeSmokePuff(const std::string& path, const SmokePuff& puff);

/// Whether this process has loaded OpenVDB (the volume plugin): only a render or command that
/// uses volumes does.
bool volumeSupportLoaded();

}  // namespace reshutter::resample
