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
  explicit RibSceneHandler(Scene& scene) : scene_(scene) {}
  bool handle(const rib::Request& request, const rib::Args& args) override;

 private:
  Scene& scene_;
};

/// Parses `path` into `scene` (whose callback receives each WorldEnd's frame).
void readRibScene(const std::string& path, Scene& scene);

}  // namespace reshutter::shade
