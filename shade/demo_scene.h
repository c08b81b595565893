// The built-in demo scene: the project's first impression, shaded with no input files.
//
// A small stage under a key light, a spotlight and a cool fill: a checkerboard floor and a
// gradient backdrop (static), a red ball flying across the frame (fast linear motion, 2 knots),
// a colour cube spinning through 90° (5 knots), a gold torus tumbling (3 knots), a flag waving
// (a deforming mesh, 3 knots), a translucent cyan sphere drifting up (opacity 0.35), a matte
// holdout sphere (a cut-out in the alpha), a row of glossy plastic balls (highlights) and a
// brick wall (a texture, made on first use: shade/texture.h). The key and the spot cast
// ray-traced shadows.
// Every object carries an identifier, so object ids come out named.
#pragma once

#include "shade/scene.h"

namespace reshutter::shade {

/// Default demo resolution: shades in a second or two on a laptop core.
constexpr int kDemoWidth = 640, kDemoHeight = 360;

/// Issues the whole demo frame (options, WorldBegin … WorldEnd) into `scene`, whose callback
/// receives it. Shutter [0, 1]; the framing is the same at any resolution of a 16:9 aspect.
/// `eyeX` moves the camera that far along its own x axis (the right eye of a stereo pair: the
/// accuracy study shades each eye on its own as the reference).
void buildDemoScene(Scene& scene, int width = kDemoWidth, int height = kDemoHeight, double eyeX = 0);

/// The demo frame as a value (for tests and benchmarks).
FrameScene demoFrame(int width = kDemoWidth, int height = kDemoHeight, double eyeX = 0);

}  // namespace reshutter::shade
