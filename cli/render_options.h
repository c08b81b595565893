// Options shared by every command that renders images from stores (resample, fields, retime):
// sampling, filters, output variables, crop, outputs and their formats. One definition keeps the
// commands consistent: whatever `resample` accepts, `fields` and `retime` accept too.
#pragma once

#include <memory>
#include <optional>
#include <string>
#include <vector>

#include <CLI/CLI.hpp>

#include "resample/resampler.h"

namespace reshutter::cli {

struct RenderOptions {
  std::string spp;      // "16"
  std::string samples;  // "4x4"
  std::string filter = "gaussian:2x2";
  std::vector<std::string> aovs;
  std::vector<int> res;   // W H
  std::vector<int> crop;  // x0 x1 y0 y1 (pixels, end exclusive)
  uint64_t seed = 0;
  int bucket = resample::kAutoBucketSize;
  double opacityThreshold = 0.996;
  bool backfaceCull = false;
  bool half = false;
  std::string compression = "piz";
  std::vector<std::string> previews;  // PATH or PATH=CHANNELS
  std::string quantize = "0,255,0,255";
  double dither = 0.5;
  bool stats = false;
  double cacheMb = 256;
  std::string simd = "auto";  // inner-loop instruction set: auto avx512 avx2 none
  std::string deep;           // deep OpenEXR path ("" = none)
  std::string deepCompression = "zips";
  double deepTolerance = 0.01;
  bool deepAllChannels = false;  // ZBack and AR AG AB even where no sample needs them (farm tiles)
  std::vector<std::string> volumes;  // --volume specs (resample/volume.h)
  double volumeStep = 1.0;           // voxels
  double volumeShadowStep = 1.0;     // voxels
  double volumeRaySpacing = 1.0;     // pixels between shared rays (0: a ray per sample)
  bool volumeNoSkip = false;         // march through whole bounding boxes (to measure empty-space skipping)
  bool volumeExactShadows = false;   // shadow rays from every step, not the per-render cache
  bool noSceneVolumes = false;       // leave out the store's own volumes
  std::optional<double> fstop, focalLength, focusDistance;  // replace the store camera's lens values
  bool pinhole = false;                                      // render without the store's lens
  // Other cameras (resample/camera_view.h): recorded ones by name, one given after the fact, a
  // stereo pair around either.
  std::vector<std::string> cameras;          // --camera NAME[,NAME...]
  std::vector<double> lookFrom, lookAt, up;  // world space of the store's camera
  std::optional<double> fov;
  std::string cameraRib;  // a RIB file describing the camera
  std::string stereo;     // BASELINE[:CONVERGENCE]
  std::string viewDependent = "on";
  mutable std::shared_ptr<const resample::VolumeScene> loadedVolumes;  // loaded once, by the first applyTo()

  /// One image a render produced: `view` names its camera when the options ask for cameras.
  struct View {
    std::string name;  // "" for the store's own camera
    resample::RenderResult result;
  };

  void addTo(CLI::App* app);
  /// The cameras the options ask for, each named, from a store with this metadata (its recorded
  /// cameras, its primary camera as "world"); empty when none is asked for. Throws Error naming the
  /// option at fault.
  std::vector<store::Camera> viewCameras(const store::StoreMeta& meta) const;
  /// Renders `spec` from each camera viewCameras() names (once, from the store's own, when none).
  std::vector<View> renderViews(const resample::RenderSpec& spec) const;
  /// Writes the views: one as writeOutputs() does; several as one multi-view OpenEXR, one
  /// multi-part deep OpenEXR (a part per view) and previews per view (the view's name replaces %v
  /// in their paths, or follows the file name's stem).
  void writeViews(const std::vector<View>& views, const std::string& exrPath, int64_t frame) const;
  /// Fills sampling, filter, AOV, crop and raster settings of `spec`.
  void applyTo(resample::RenderSpec& spec) const;
  /// Checks, before rendering, what writeOutputs() would otherwise find only after it: every
  /// output's directory exists and is writable (applyTo() validates the compression and quantize
  /// options).
  void checkOutputs(const std::string& exrPath, int64_t frame) const;
  /// Writes the EXR (when exrPath is set), the deep EXR (when --deep is) and any previews.
  void writeOutputs(const resample::RenderResult& result, const std::string& exrPath, int64_t frame) const;
  /// Writes the --preview images of `image` (writeOutputs() does this too).
  void writePreviews(const resample::FlatImage& image, int64_t frame) const;
};

}  // namespace reshutter::cli
