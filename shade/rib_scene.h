// RIB → Scene: the RequestHandler that turns the scene subset of the RenderMan Interface
// (options, attributes, transforms, motion blocks, the built-in shaders and lights, RIS nodes,
// every quadric, polygons, patches and patch meshes with Pz height fields, NuPatch with
// TrimCurve, subdivision meshes, curves, points, retained objects) into Scene builder calls. Requests outside the subset return
// false, so the reader warns once per kind and skips them; requests that are taken but have no
// effect on a single shading pass (PixelFilter, Option, Hider …) are accepted quietly only where
// ignoring them cannot change what is shaded.
#pragma once

#include <string>

#include "rib/rib.h"
#include "shade/scene.h"

namespace reshutter::shade {

class RibSceneHandler final : public rib::RequestHandler {
 public:
  /// `cullMargin`: what is kept beyond the screen edges, as a fraction of the resolution (the
  /// shading pass's DiceOptions::cullMargin).
  explicit RibSceneHandler(Scene& scene, double cullMargin = 0.1) : scene_(scene), cullMargin_(cullMargin) {}
  bool handle(const rib::Request& request, const rib::Args& args) override;
  /// A delayed archive's bound is culled when, at every knot of the current transform, it lies
  /// wholly behind the eye, wholly beyond the far plane, or wholly past one and the same edge of
  /// the screen (and its margin); the archive is then not read, and the frame counts it.
  bool cullsBound(const std::array<double, 6>& bound) override;

 private:
  Scene& scene_;
  double cullMargin_;
};

/// Parses `path` into `scene` (whose callback receives each WorldEnd's frame).
void readRibScene(const std::string& path, Scene& scene, double cullMargin = 0.1);

/// The camera a RIB file describes - Format, Projection, ScreenWindow, Clipping, DepthOfField and
/// the transform before its first WorldBegin, as WorldBegin freezes them (a snippet without one is
/// read as if it came next), named after the file's stem. Throws Error naming the file.
store::Camera readRibCamera(const std::string& path);

}  // namespace reshutter::shade
