// The OpenVDB side of volumes (resample/volume.h), as the interface between the re-sampler and
// the plugin that implements it: volume_vdb.cpp, built as libreshutter_volume.so and loaded with
// dlopen the first time a render asks for a volume. Why a plugin: linking OpenVDB (with its Boost
// and Blosc) into the program cost every process about 28 MB of resident memory for relocations
// and static initialisers, volumes or not; loaded on demand, a render without volumes pays
// nothing (bench/RESULTS.md, Volumes).
//
// Only resample/volume.cpp (the loader and the public classes) and the plugin include this file.
// The plugin is built from the same sources by the same compiler, so C++ types cross the
// boundary; kVolumeEngineEntry names the version of this interface and changes with it.
#pragma once

#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "resample/volume.h"

namespace reshutter::resample {

/// Loaded volumes (VolumeScene's engine).
struct VolumeSceneEngine {
  virtual ~VolumeSceneEngine() = default;
  virtual size_t size() const = 0;
};

/// One render's cached lighting (VolumeLighting's engine).
struct VolumeLightingEngine {
  virtual ~VolumeLightingEngine() = default;
  virtual uint64_t buildSteps() const = 0;
};

/// One thread's tracer (VolumeTracer's engine); the calls mean what VolumeTracer's do.
struct VolumeTracerEngine {
  virtual ~VolumeTracerEngine() = default;
  virtual bool touches(double x0, double y0, double x1, double y1) const = 0;
  virtual void beginRegion(int x0, int y0, int w, int h) = 0;
  virtual bool sharesRays() const = 0;
  virtual void integrate(double x, double y, double u, double v, double t, double z0, double z1, VolumeSegment& out, std::vector<VolumeSlice>* slices,
                         double ratio, VolumeStats& stats) = 0;
};

/// The plugin's entry point: makes the engines above.
struct VolumeEngine {
  virtual ~VolumeEngine() = default;
  /// Loads and checks the volumes (VolumeScene's constructor), appending warnings.
  virtual std::unique_ptr<VolumeSceneEngine> load(const std::vector<VolumeSpec>& specs, const VolumeOptions& options,
                                                  std::vector<std::string>& warnings) const = 0;
  /// base's volumes (shared, not loaded again) followed by more's, with base's options.
  virtual std::unique_ptr<VolumeSceneEngine> merge(const VolumeSceneEngine& base, const VolumeSceneEngine& more) const = 0;
  virtual std::unique_ptr<VolumeLightingEngine> light(const VolumeSceneEngine& scene, const VolumeCamera& camera) const = 0;
  virtual std::unique_ptr<VolumeTracerEngine> tracer(const VolumeSceneEngine& scene, const VolumeCamera& camera, double earliest, double latest,
                                                     const VolumeLightingEngine* lighting) const = 0;
  virtual void writeSmokePuff(const std::string& path, const SmokePuff& puff) const = 0;
};

/// The symbol the plugin exports: `const VolumeEngine* NAME()`.
inline constexpr const char* kVolumeEngineEntry = "reshutter_volume_engine_v2";

/// The plugin's engine, loaded on first call (thread-safe) by common/module.h's loadModule():
/// $RESHUTTER_VOLUME_MODULE names another copy. Throws Error saying where it looked when none loads.
const VolumeEngine& volumeEngine();

}  // namespace reshutter::resample
