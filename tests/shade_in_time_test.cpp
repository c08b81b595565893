// Shading in time (issue #29): grids whose shading changes over the shutter carry their colour at
// several times, and the re-sampler blends each sample's colour at its own time. Every scene is a
// RIB file shaded and re-sampled through the CLI, and the truths come from geometry:
//  - a flat square rotating about a screen axis under a distant light along the view, matte:
//    its colour at time t is the cosine between its normal at t and the light. Transforms are
//    interpolated as matrices, so at t the square is the corners' blend: normal ∝
//    (t sin θ, 0, 1 − t + t cos θ). Re-sampled at an instant it matches the blend of the stored
//    times around t exactly, the truth within that blend's error, which shrinks with more times;
//  - a sphere moving over a floor under a light from straight above: shaded in time, the floor's
//    shadow at the close lies under the sphere's position at the close (the shadow rays see the
//    moving sphere through Embree's motion blur);
//  - what cannot change (constant shaders, rigid translation of a matte surface under a distant
//    light, a still scene) keeps one colour: `shade -v` and `info` count the grids.
#include <algorithm>
#include <cctype>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <string>

#include <gtest/gtest.h>

#include "common/error.h"
#include "store/reader.h"
#include "store/writer.h"
#include "tests/exr_test_util.h"
#include "tests/test_util.h"

namespace reshutter {
namespace {

using test::runReshutter;
using test::ScratchDir;

float red(const resample::FlatImage& img, int x, int y) { return img.find("R")->f[size_t(y - img.y0) * size_t(img.width) + size_t(x - img.x0)]; }
float alpha(const resample::FlatImage& img, int x, int y) { return img.find("A")->f[size_t(y - img.y0) * size_t(img.width) + size_t(x - img.x0)]; }

using test::numberBefore;

// `scene` with its first `from` replaced by `to` (a failure if it has none).
std::string edited(std::string scene, const std::string& from, const std::string& to) {
  const size_t at = scene.find(from);
  EXPECT_NE(at, std::string::npos) << "no '" << from << "' in the scene";
  return at == std::string::npos ? scene : scene.replace(at, from.size(), to);
}

struct Shaded {
  std::string store, report;
};
Shaded shade(ScratchDir& dir, const std::string& name, const std::string& rib, const std::string& args) {
  std::ofstream(dir.path(name + ".rib")) << rib;
  Shaded s{dir.path(name + ".mps"), ""};
  const auto r = runReshutter("-v shade " + dir.path(name + ".rib") + " -o " + s.store + " " + args);
  EXPECT_EQ(r.exitCode, 0) << r.err;
  s.report = r.out + r.err;
  return s;
}

resample::FlatImage instant(ScratchDir& dir, const std::string& store, double t, const std::string& name) {
  const std::string exr = dir.path(name + ".exr");
  const auto r = runReshutter("-q resample " + store + " --shutter " + std::to_string(t) + ":" + std::to_string(t) + " --spp 4 --filter box:1 -o " + exr);
  EXPECT_EQ(r.exitCode, 0) << r.err;
  return test::readFlatExr(exr);
}

// A 2×2 square facing an orthographic camera 5 units away, rotating 60° about the screen's y axis
// over the shutter; white matte (Kd 1, no ambient) under a distant light along the view.
constexpr double kTheta = 60.0 * 3.14159265358979323846 / 180.0;
const std::string kRotatingSquare =
    "Format 32 32 1\nProjection \"orthographic\"\nScreenWindow -2 2 -2 2\nShutter 0 1\nWorldBegin\n"
    "LightSource \"distantlight\" 1 \"from\" [0 0 0] \"to\" [0 0 1] \"intensity\" [1]\n"
    "Color [1 1 1]\nSurface \"matte\" \"Ka\" [0] \"Kd\" [1]\n"
    "Translate 0 0 5\nMotionBegin [0 1]\nRotate 0 0 1 0\nRotate 60 0 1 0\nMotionEnd\n"
    "Patch \"bilinear\" \"P\" [-1 -1 0  1 -1 0  -1 1 0  1 1 0]\nWorldEnd\n";

double rotatingTruth(double t) {
  const double nx = t * std::sin(kTheta), nz = 1 - t + t * std::cos(kTheta);
  return nz / std::sqrt(nx * nx + nz * nz);
}

// The blend of the truth at the stored times around t (n times spread over [0, 1]).
double storedBlend(double t, int n) {
  const double step = 1.0 / (n - 1);
  const int k = std::min(int(t / step), n - 2);
  const double w = (t - k * step) / step;
  return (1 - w) * rotatingTruth(k * step) + w * rotatingTruth((k + 1) * step);
}

TEST(ShadeInTime, ARotatingSquareMatchesItsShadingAtEachInstant) {
  ScratchDir dir;
  const Shaded once = shade(dir, "once", kRotatingSquare, "");
  const Shaded three = shade(dir, "three", kRotatingSquare, "--shade-in-time 0.01 --shade-times 3");
  const Shaded nine = shade(dir, "nine", kRotatingSquare, "--shade-in-time 0.01 --shade-times 9");
  // The path: the square's grids were candidates and kept every time.
  EXPECT_GT(numberBefore(three.report, " of "), 0u) << three.report;
  EXPECT_EQ(numberBefore(three.report, " of "), numberBefore(three.report, " grids that may change")) << three.report;
  // It rotates rigidly: its later times were carried by its motion, not diced again.
  EXPECT_GT(numberBefore(three.report, " grid times of rigidly moving grids carried"), 0u) << three.report;
  // Its change is the same at every vertex (a flat square under a distant light), so the later
  // times' coarse lattice finds nothing to refine: most vertices take the change interpolated,
  // which for a uniform change is exact (the instants below hold it to the truth).
  EXPECT_GT(numberBefore(three.report, " vertices whose change was interpolated"), numberBefore(three.report, " vertex shadings at later times"))
      << three.report;
  const auto info = runReshutter("info " + three.store);
  EXPECT_NE(info.out.find("in time at 3 times [0 0.5 1]"), std::string::npos) << info.out;
  double blendErr3 = 0, blendErr9 = 0;
  float once1 = 0, three1 = 0;  // the instants at the close, for the checks after the loop
  for (double t : {0.0, 0.125, 0.25, 0.5, 0.6, 0.75, 1.0}) {
    const std::string tag = std::to_string(int(t * 1000));
    const float c1 = red(instant(dir, once.store, t, "once" + tag), 16, 16);
    const float c3 = red(instant(dir, three.store, t, "three" + tag), 16, 16);
    const float c9 = red(instant(dir, nine.store, t, "nine" + tag), 16, 16);
    if (t == 1.0) once1 = c1, three1 = c3;
    // Shaded once: the open's colour at every instant.
    EXPECT_NEAR(c1, rotatingTruth(0), 1e-4) << "t=" << t;
    // In time: exactly the blend of the stored times around t...
    EXPECT_NEAR(c3, storedBlend(t, 3), 2e-4) << "t=" << t;
    EXPECT_NEAR(c9, storedBlend(t, 9), 2e-4) << "t=" << t;
    blendErr3 = std::max(blendErr3, std::abs(c3 - rotatingTruth(t)));
    blendErr9 = std::max(blendErr9, std::abs(c9 - rotatingTruth(t)));
  }
  // ... which is the truth at the stored times, and near it between them, nearer with more times.
  EXPECT_NEAR(three1, rotatingTruth(1.0), 2e-4);
  EXPECT_GT(blendErr3, 0.01) << "the blend of three times should show its error between them";
  EXPECT_LT(blendErr3, 0.05);
  EXPECT_LT(blendErr9, blendErr3 / 4);
  // The shade-once error at the close is the whole change, 1 - cos 60° = 0.5.
  EXPECT_NEAR(once1 - rotatingTruth(1.0), 0.5, 1e-3);
}

// A surface's opacity changes over the shutter only where an opacity (or a shader) is animated:
// elsewhere the store leaves the later opacities out and every instant takes the first's. The
// rotating square at a constant half opacity: its colour still follows time, its alpha stays 0.5.
// With its opacity animated from 1 to 0.2 the store carries the later opacities, and alpha at an
// instant is the blend of the stored times (opacity is linear in time, so exact).
TEST(ShadeInTime, OpacityFollowsTimeOnlyWhereItCanChange) {
  ScratchDir dir;
  const std::string half = edited(kRotatingSquare, "Color [1 1 1]\n", "Color [1 1 1]\nOpacity [0.5 0.5 0.5]\n");
  const Shaded constant = shade(dir, "constant", half, "--shade-in-time 0.01 --shade-times 3");
  EXPECT_EQ(numberBefore(constant.report, " of "), numberBefore(constant.report, " grids that may change")) << constant.report;
  const store::StoreReader reader(constant.store);
  const store::StoreMeta& meta = reader.meta();
  // Shading times are the shutter instants the store carries (no clock is read anywhere here).
  EXPECT_EQ(meta.shadingTimes.size(), 3u);
  EXPECT_GE(meta.schema.find("Ci@2"), 0);
  EXPECT_LT(meta.schema.find("Oi@1"), 0) << "a constant opacity needs no later times";
  const auto open = instant(dir, constant.store, 0.0, "constant-open"), close = instant(dir, constant.store, 1.0, "constant-close");
  EXPECT_NEAR(alpha(open, 16, 16), 0.5f, 1e-4);
  EXPECT_NEAR(alpha(close, 16, 16), 0.5f, 1e-4);
  // The colour at the close against the open: the shading's own change, cos 60° (scaled alike by
  // the opacity).
  EXPECT_NEAR(red(close, 16, 16) / red(open, 16, 16), rotatingTruth(1.0) / rotatingTruth(0.0), 1e-3);

  const std::string fading = edited(kRotatingSquare, "Color [1 1 1]\n", "Color [1 1 1]\nMotionBegin [0 1]\nOpacity [1 1 1]\nOpacity [0.2 0.2 0.2]\nMotionEnd\n");
  const Shaded animated = shade(dir, "animated", fading, "--shade-in-time 0.01 --shade-times 3");
  EXPECT_GE(store::StoreReader(animated.store).meta().schema.find("Oi@2"), 0) << "an animated opacity is carried in time";
  for (double t : {0.0, 0.25, 0.5, 1.0})  // t: a shutter instant (frames), not a duration
    EXPECT_NEAR(alpha(instant(dir, animated.store, t, "animated-" + std::to_string(int(t * 100))), 16, 16), 1.0 - 0.8 * t, 1e-3) << "t=" << t;
}

// Times are refined by bisection: the close, then the middle; a middle within the tolerance of
// its ends' blend lets the span's other times be blended instead of shaded. A 20° rotation: at
// t = 0.5 the truth lies 0.015 off the blend of the open and close, at t = 0.25 0.0039 off the
// blend of the open and the middle.
TEST(ShadeInTime, TimesBetweenShadedOnesAreBlendedWhereTheMiddleAgreesWithTheBlend) {
  ScratchDir dir;
  const std::string gentle = edited(kRotatingSquare, "Rotate 60 0 1 0", "Rotate 20 0 1 0");
  const double theta = 20.0 * 3.14159265358979323846 / 180.0;
  auto truth = [&](double t) {
    const double nx = t * std::sin(theta), nz = 1 - t + t * std::cos(theta);
    return nz / std::sqrt(nx * nx + nz * nz);
  };
  const Shaded loose = shade(dir, "loose", gentle, "--shade-in-time 0.02 --shade-times 5");
  const Shaded tight = shade(dir, "tight", gentle, "--shade-in-time 0.005 --shade-times 5");
  // The path: with 0.02 the middle agreed (0.015 off), so t = 0.25 and 0.75 were blended; with
  // 0.005 it did not, and every time was shaded. Both kept their times (the change, 0.06, is
  // above either tolerance).
  EXPECT_GT(numberBefore(loose.report, " grid times blended"), 0u) << loose.report;
  EXPECT_EQ(numberBefore(tight.report, " grid times blended"), 0u) << tight.report;
  EXPECT_GT(numberBefore(loose.report, " of "), 0u) << loose.report;
  const float blended = red(instant(dir, loose.store, 0.25, "loose-q"), 16, 16);
  const float shaded = red(instant(dir, tight.store, 0.25, "tight-q"), 16, 16);
  EXPECT_NEAR(blended, 0.5 * (truth(0) + truth(0.5)), 2e-4) << "blended between the open and the middle";
  EXPECT_NEAR(shaded, truth(0.25), 2e-4) << "shaded at t = 0.25";
  EXPECT_GT(std::abs(blended - truth(0.25)), 0.003) << "the blend should show its error";
  EXPECT_LT(std::abs(blended - truth(0.25)), 0.02) << "within the tolerance";
  // The middle and the close are shaded in both.
  EXPECT_NEAR(red(instant(dir, loose.store, 0.5, "loose-m"), 16, 16), truth(0.5), 2e-4);
  EXPECT_NEAR(red(instant(dir, loose.store, 1.0, "loose-c"), 16, 16), truth(1.0), 2e-4);
}

// Output variables follow time too: the rotating square's normal N, carried at every shading
// time, is blended at the sample's time like its colour. Unit normals at the stored times, from
// the matrix blend: ∝ (t sin θ, 0, 1 − t + t cos θ) up to sign.
TEST(ShadeInTime, OutputVariablesFollowTimeLikeTheColour) {
  ScratchDir dir;
  const std::string withN = edited(kRotatingSquare, "WorldBegin", "Display \"+n.exr\" \"file\" \"N,s\"\nWorldBegin");
  const Shaded once = shade(dir, "once", withN, "");
  const Shaded timed = shade(dir, "timed", withN, "--shade-in-time 0 --shade-times 3");
  // The schema: N at every time, the parametric s at the first only.
  const store::StoreReader reader(timed.store);
  EXPECT_GE(reader.meta().schema.find("N@2"), 0);
  EXPECT_LT(reader.meta().schema.find("s@1"), 0);
  auto normalX = [&](const std::string& store, double t, const std::string& name) {
    const std::string exr = dir.path(name + ".exr");
    const auto r = runReshutter("-q resample " + store + " --shutter " + std::to_string(t) + ":" + std::to_string(t) +
                                " --spp 4 --filter box:1 --aov N --aov s -o " + exr);
    EXPECT_EQ(r.exitCode, 0) << r.err;
    const auto img = test::readFlatExr(exr);
    const auto* nx = img.find("N.X");
    EXPECT_NE(nx, nullptr);
    return nx ? std::abs(nx->f[size_t(16 - img.y0) * size_t(img.width) + size_t(16 - img.x0)]) : -1.f;
  };
  auto unitX = [](double t) {
    const double nx = t * std::sin(kTheta), nz = 1 - t + t * std::cos(kTheta);
    return nx / std::sqrt(nx * nx + nz * nz);
  };
  EXPECT_NEAR(normalX(timed.store, 1.0, "t10"), unitX(1.0), 2e-4);  // sin 60°
  EXPECT_NEAR(normalX(timed.store, 0.5, "t05"), unitX(0.5), 2e-4);
  EXPECT_NEAR(normalX(timed.store, 0.25, "t025"), 0.5 * (unitX(0) + unitX(0.5)), 2e-4) << "blended between the stored times";
  // Shaded once, the normal is the open's at every instant.
  EXPECT_NEAR(normalX(once.store, 1.0, "o10"), 0.0, 2e-4);
}

TEST(ShadeInTime, EachFieldOfAnInterlacedFrameSeesItsOwnShading) {
  ScratchDir dir;
  const Shaded once = shade(dir, "once", kRotatingSquare, "");
  const Shaded timed = shade(dir, "timed", kRotatingSquare, "--shade-in-time 0.01 --shade-times 3");
  auto fields = [&](const std::string& store, const std::string& name) {
    const std::string exr = dir.path(name + ".exr");
    const auto r = runReshutter("-q fields " + store + " --frames 1 --field-shutter 0:1 --spp 16 --filter box:1 -o " + exr);
    EXPECT_EQ(r.exitCode, 0) << r.err;
    return test::readFlatExr(exr);
  };
  const auto a = fields(once.store, "once"), b = fields(timed.store, "timed");
  // Upper dominance: even rows are the first field [0, 0.5], odd rows the second [0.5, 1]. Each
  // pixel's 16 samples stratify its field's time, over which the stored blend is linear: its
  // mean is the two stored times' mean.
  EXPECT_NEAR(red(b, 16, 16), 0.5 * (rotatingTruth(0) + rotatingTruth(0.5)), 0.01);
  EXPECT_NEAR(red(b, 16, 17), 0.5 * (rotatingTruth(0.5) + rotatingTruth(1)), 0.01);
  // Shaded once, both fields are lit as at the open.
  EXPECT_NEAR(red(a, 16, 16), rotatingTruth(0), 1e-4);
  EXPECT_NEAR(red(a, 16, 17), rotatingTruth(0), 1e-4);
}

TEST(ShadeInTime, TheToleranceDecidesWhichGridsKeepTheirTimes) {
  ScratchDir dir;
  // The square's colour changes by 0.5 over the shutter: kept under 0.4, not under 0.6.
  const Shaded tight = shade(dir, "tight", kRotatingSquare, "--shade-in-time 0.4");
  const Shaded loose = shade(dir, "loose", kRotatingSquare, "--shade-in-time 0.6");
  const uint64_t candidates = numberBefore(loose.report, " grids that may change");
  EXPECT_GT(candidates, 0u) << loose.report;
  EXPECT_EQ(numberBefore(tight.report, " of "), candidates) << tight.report;
  EXPECT_EQ(numberBefore(loose.report, " of "), 0u) << loose.report;
  EXPECT_NEAR(red(instant(dir, loose.store, 1.0, "loose"), 16, 16), rotatingTruth(0), 1e-4);
  EXPECT_NEAR(red(instant(dir, tight.store, 1.0, "tight"), 16, 16), rotatingTruth(1), 2e-4);
}

TEST(ShadeInTime, WhatCannotChangeKeepsOneColour) {
  ScratchDir dir;
  // A constant shader: never a candidate.
  const std::string constant = edited(kRotatingSquare, "Surface \"matte\" \"Ka\" [0] \"Kd\" [1]", "Surface \"constant\"");
  const Shaded c = shade(dir, "constant", constant, "--shade-in-time 0");
  EXPECT_EQ(numberBefore(c.report, " grids that may change"), 0u) << c.report;
  // A matte square translating rigidly under the distant light: never a candidate either, though
  // a tolerance of 0 keeps every candidate.
  const std::string sliding = edited(kRotatingSquare, "Rotate 0 0 1 0\nRotate 60 0 1 0", "Translate 0 0 0\nTranslate 0.5 0 0");
  const Shaded s = shade(dir, "sliding", sliding, "--shade-in-time 0");
  EXPECT_NE(s.report.find("shaded in time"), std::string::npos) << s.report;
  EXPECT_EQ(numberBefore(s.report, " grids that may change"), 0u) << s.report;
  // The rotating square is a candidate, and with tolerance 0 keeps its times.
  const Shaded r = shade(dir, "rotating", kRotatingSquare, "--shade-in-time 0");
  EXPECT_GT(numberBefore(r.report, " of "), 0u) << r.report;
  // A scene where nothing moves: shading in time asks for nothing, and the store is the
  // shade-once store byte for byte (format version 1).
  const std::string still = edited(kRotatingSquare, "MotionBegin [0 1]\nRotate 0 0 1 0\nRotate 60 0 1 0\nMotionEnd\n", "Rotate 30 0 1 0\n");
  std::ofstream(dir.path("still.rib")) << still;
  const Shaded a{dir.path("still-a.mps"), runReshutter("-v shade " + dir.path("still.rib") + " -o " + dir.path("still-a.mps") + " --shade-in-time 0").err};
  const Shaded b{dir.path("still-b.mps"), runReshutter("-v shade " + dir.path("still.rib") + " -o " + dir.path("still-b.mps")).err};
  EXPECT_EQ(test::readBytes(a.store), test::readBytes(b.store));
  EXPECT_TRUE(store::StoreReader(a.store).meta().shadingTimes.empty()) << "a store that does not shade in time carries no shading times";
  EXPECT_EQ(store::StoreReader(r.store).meta().shadingTimes.size(), 5u);
}

// Floor y = 0, a sphere of radius 0.5 two units above it moving from x = -1 to x = +1 over the
// shutter, a shadowing distant light straight down, an orthographic camera looking straight down
// (world (x, y, z) is camera (x, z, 10 - y)), 64 px over 8 units: floor point (x, 0, z) lies in
// pixel (32 + 8x, 32 - 8z).
const std::string kMovingSphereOverFloor =
    "Format 64 64 1\nProjection \"orthographic\"\nScreenWindow -4 4 -4 4\nShutter 0 1\n"
    "Translate 0 0 10\nRotate -90 1 0 0\nWorldBegin\n"
    "LightSource \"ambientlight\" 1 \"intensity\" [0.1]\n"
    "LightSource \"shadowdistant\" 2 \"from\" [0 1 0] \"to\" [0 0 0] \"shadowname\" \"raytrace\"\n"
    "Color [1 1 1]\nSurface \"matte\"\n"
    "Polygon \"P\" [-8 0 -8  -8 0 8  8 0 8  8 0 -8]\n"
    "AttributeBegin\nMotionBegin [0 1]\nTranslate -1 2 0\nTranslate 1 2 0\nMotionEnd\nSphere 0.5 -0.5 0.5 360\nAttributeEnd\nWorldEnd\n";

TEST(ShadeInTime, ShadowsFollowTheCasterThroughTheShutter) {
  ScratchDir dir;
  const Shaded once = shade(dir, "once", kMovingSphereOverFloor, "");
  const Shaded inTime = shade(dir, "inTime", kMovingSphereOverFloor, "--shade-in-time 0.05");
  // The floor is a candidate (a moving caster shadows it) and keeps its times.
  EXPECT_GT(numberBefore(inTime.report, " of "), 0u) << inTime.report;
  // The open's shadow, the floor at (-1, 0, 0): pixel (24, 32). At the close the sphere (and so
  // its shadow, under it) is at x = +1, so the floor there is in the open: white matte, 0.1
  // ambient + 1 from the light = 1.1; in shadow, 0.1.
  const auto onceEnd = instant(dir, once.store, 1.0, "once-end");
  const auto timedEnd = instant(dir, inTime.store, 1.0, "inTime-end");
  const auto timedOpen = instant(dir, inTime.store, 0.0, "inTime-open");
  const float openSpotOnce = red(onceEnd, 24, 32), openSpotTimed = red(timedEnd, 24, 32);
  EXPECT_NEAR(openSpotOnce, 0.1f, 0.02f) << "shaded once, the floor keeps the open's shadow";
  EXPECT_NEAR(openSpotTimed, 1.1f, 0.02f) << "shaded in time, the open's shadow has moved away by the close";
  EXPECT_NEAR(red(timedOpen, 40, 32), 1.1f, 0.02f) << "at the open, the close's shadow spot is lit";
  // The still floor's later times traced only against the moving sphere, and the vertices its
  // shadow never reached kept their first colour without being shaded again.
  EXPECT_GT(numberBefore(inTime.report, " vertex shadings kept from the first time"), 0u) << inTime.report;
  // Floor grids the moving caster might have shadowed (by its bounds) but did not, in some later
  // shading: nothing changed at their coarse points, and the rest kept their first values unblended.
  const std::string& said = inTime.report;
  EXPECT_GT(numberBefore(said, " later grid shadings unchanged at their coarse points"), 0u) << said;
  // The sphere translates rigidly: its micropolygons are one still BVH, instanced with its motion.
  EXPECT_EQ(numberBefore(inTime.report, " rigidly moving shadow casters"), 1u) << inTime.report;
  EXPECT_GT(numberBefore(inTime.report, " moving micropolygons in "), 0u) << inTime.report;
  // Which is exact: at every shading time the floor matches the sphere frozen there, shaded once.
  for (double t : {0.5, 1.0}) {
    const double x = -1 + 2 * t;
    const std::string frozen =
        edited(kMovingSphereOverFloor, "MotionBegin [0 1]\nTranslate -1 2 0\nTranslate 1 2 0\nMotionEnd", "Translate " + std::to_string(x) + " 2 0");
    const std::string tag = std::to_string(int(t * 10));
    const Shaded still = shade(dir, "frozen" + tag, frozen, "");
    const auto a = instant(dir, inTime.store, t, "inTime-at" + tag), b = instant(dir, still.store, t, "frozen-at" + tag);
    int differ = 0;
    for (int y = 0; y < 64; ++y)
      for (int x2 = 0; x2 < 64; ++x2) differ += std::abs(red(a, x2, y) - red(b, x2, y)) > 0.02f;
    // Pixels whose samples straddle the shadow's edge may differ by a sample or two of rounding.
    EXPECT_LT(differ, 12) << "t=" << t;  // the open's shadow kept would differ over ~100 pixels
  }
}

// A second shadowing light, low from the side: the sphere's shadow from it falls far to one side
// (x < -1.5), so floor grids under its path (-1.5 < x < 1.5) the overhead light makes candidates
// but that no moving caster can shadow from the low light send that light's rays past the moving
// micropolygons (counted). Which must change nothing: at each shading time the floor matches the
// sphere frozen there and shaded once.
TEST(ShadeInTime, RaysTowardsALightNoMovingCasterCanShadowFromSkipTheMovingOnes) {
  ScratchDir dir;
  const std::string scene = edited(kMovingSphereOverFloor, "Color [1 1 1]\nSurface \"matte\"\n",
                                   "LightSource \"shadowdistant\" 3 \"from\" [2 1 0] \"to\" [0 0 0] \"intensity\" [0.5] \"shadowname\" \"raytrace\"\n"
                                   "Color [1 1 1]\nSurface \"matte\"\n");
  const Shaded inTime = shade(dir, "inTime", scene, "--shade-in-time 0.05");
  EXPECT_GT(numberBefore(inTime.report, " rays of candidates against them only"), 100u) << inTime.report;
  for (double t : {0.5, 1.0}) {
    const std::string frozen =
        edited(scene, "MotionBegin [0 1]\nTranslate -1 2 0\nTranslate 1 2 0\nMotionEnd", "Translate " + std::to_string(-1 + 2 * t) + " 2 0");
    const std::string tag = std::to_string(int(t * 10));
    const Shaded still = shade(dir, "frozen" + tag, frozen, "");
    const auto a = instant(dir, inTime.store, t, "inTime-at" + tag), b = instant(dir, still.store, t, "frozen-at" + tag);
    int differ = 0, sideShadow = 0;
    for (int y = 0; y < 64; ++y)
      for (int x = 0; x < 64; ++x) {
        differ += std::abs(red(a, x, y) - red(b, x, y)) > 0.02f;
        // In the low light's shadow: 0.1 ambient + 1 overhead, against 1.1 + 0.5 cos(63.4°) lit.
        sideShadow += x < 20 && std::abs(red(b, x, y) - 1.1f) < 0.03f;
      }
    EXPECT_GT(sideShadow, 20) << "t=" << t << ": the low light's shadow of the sphere is on the floor";
    EXPECT_LT(differ, 12) << "t=" << t;
  }
}

// Later times shaded on a coarser lattice (--shade-in-time-stride): the floor's moving shadow
// is a sharp change, which the lattice must find and shade in full; a plastic sphere moving past
// a point light changes smoothly, which the lattice interpolates. Either way each instant must
// match shading every vertex at every time, while far fewer vertices are shaded.
TEST(ShadeInTime, ACoarseLatticeKeepsSharpChangesAndInterpolatesSmoothOnes) {
  ScratchDir dir;
  const std::string lit = edited(kMovingSphereOverFloor, "Color [1 1 1]\nSurface \"matte\"\n",
                                 "LightSource \"pointlight\" 3 \"from\" [0 3 3] \"intensity\" [6]\nColor [1 1 1]\nSurface \"matte\"\n");
  const std::string scene = edited(lit, "WorldEnd",
                                   "AttributeBegin\nSurface \"plastic\" \"roughness\" [0.2]\nMotionBegin [0 1]\nTranslate 2 1.2 2\nTranslate 2 1.2 -1.5\n"
                                   "MotionEnd\nSphere 1.2 -1.2 1.2 360\nAttributeEnd\nWorldEnd");
  const Shaded every = shade(dir, "every", scene, "--shade-in-time 0.01 --shade-in-time-stride 1");
  EXPECT_EQ(numberBefore(every.report, " vertices whose change was interpolated"), 0u) << every.report;
  const uint64_t everyShaded = numberBefore(every.report, " vertex shadings at later times");
  for (int stride : {2, 3}) {
    const std::string name = "stride" + std::to_string(stride);
    const Shaded coarse = shade(dir, name, scene, "--shade-in-time 0.01 --shade-in-time-stride " + std::to_string(stride));
    // The path: vertices were interpolated, and fewer shaded.
    const uint64_t interpolated = numberBefore(coarse.report, " vertices whose change was interpolated");
    EXPECT_GT(interpolated, 1000u) << coarse.report;
    // Every later vertex was shaded or interpolated, once.
    EXPECT_EQ(numberBefore(coarse.report, " vertex shadings at later times") + interpolated, everyShaded) << coarse.report;
    for (double t : {0.5, 1.0}) {
      const std::string tag = name + "-" + std::to_string(int(t * 10));
      const auto a = instant(dir, coarse.store, t, tag), b = instant(dir, every.store, t, "every-" + tag);
      int differ = 0, shadowEdge = 0;
      for (int y = 0; y < 64; ++y)
        for (int x = 0; x < 64; ++x) {
          differ += std::abs(red(a, x, y) - red(b, x, y)) > 0.02f;
          shadowEdge += std::abs(red(b, x, y) - red(b, std::min(x + 1, 63), y)) > 0.5f;
        }
      EXPECT_GT(shadowEdge, 10) << "t=" << t << ": the shadow's edge is in the frame";
      // Interpolating across the shadow's edge instead of shading it would differ over dozens.
      EXPECT_LT(differ, 4) << "stride " << stride << ", t=" << t;
    }
  }
}

// Casters that rotate (rigidly, over three knots) and that deform (a sphere growing: its shape
// changes, so it cannot be instanced) over the floor, under the light from straight above: shaded
// in time, at each shading time the floor matches the casters frozen there and shaded once - the
// frozen ones are plain still micropolygons, so the instanced motion and the per-vertex motion
// are checked against geometry that does not move. A rotating caster's later times are carried by
// its motion (not diced again); the growing sphere's are diced again.
TEST(ShadeInTime, RotatingAndDeformingCastersShadowAsTheyStandAtEachTime) {
  ScratchDir dir;
  // Both fully transparent, so that the camera above sees their shadows under them; the bar's
  // edges off the floor's vertex grid (a vertex exactly under an edge is a tie either way).
  const std::string bar = "AttributeBegin\nOpacity [0 0 0]\nTranslate -1.47 2 1.03\nMotionBegin [0 0.5 1]\nRotate 0 0 1 0\nRotate 40 0 1 0\nRotate 90 0 1 0\nMotionEnd\n"
                          "Polygon \"P\" [-1.5 0 -0.3  -1.5 0 0.3  1.5 0 0.3  1.5 0 -0.3]\nAttributeEnd\n";
  const std::string growing = "AttributeBegin\nOpacity [0 0 0]\nTranslate 1.5 2 -1.5\nMotionBegin [0 1]\nSphere 0.4 -0.4 0.4 360\nSphere 0.9 -0.9 0.9 360\nMotionEnd\nAttributeEnd\n";
  const std::string base = edited(kMovingSphereOverFloor, "AttributeBegin\nMotionBegin [0 1]\nTranslate -1 2 0\nTranslate 1 2 0\nMotionEnd\nSphere 0.5 -0.5 0.5 360\nAttributeEnd\n", "");
  const std::string scene = edited(base, "WorldEnd", bar + growing + "WorldEnd");
  const Shaded inTime = shade(dir, "inTime", scene, "--shade-in-time 0 --shade-times 3");
  EXPECT_EQ(numberBefore(inTime.report, " rigidly moving shadow casters"), 1u) << "the bar alone: " << inTime.report;
  // Its instance also fixed at each shading time, where the shading rays are traced (the report
  // counts the shutter instants it is fixed at; nothing here is timed).
  EXPECT_EQ(numberBefore(inTime.report, " shading times)"), 3u) << inTime.report;
  EXPECT_GT(numberBefore(inTime.report, " grid times of rigidly moving grids carried"), 0u) << inTime.report;
  for (int k : {1, 2}) {
    const double t = 0.5 * k;
    std::string frozen = edited(scene, "MotionBegin [0 0.5 1]\nRotate 0 0 1 0\nRotate 40 0 1 0\nRotate 90 0 1 0\nMotionEnd", k == 1 ? "Rotate 40 0 1 0" : "Rotate 90 0 1 0");
    const double r = 0.4 + 0.5 * t;
    const std::string rs = std::to_string(r);
    frozen = edited(frozen, "MotionBegin [0 1]\nSphere 0.4 -0.4 0.4 360\nSphere 0.9 -0.9 0.9 360\nMotionEnd", "Sphere " + rs + " -" + rs + " " + rs + " 360");
    const Shaded still = shade(dir, "frozen" + std::to_string(k), frozen, "");
    const auto a = instant(dir, inTime.store, t, "inTime" + std::to_string(k)), b = instant(dir, still.store, t, "frozen-at" + std::to_string(k));
    int differ = 0, shadowed = 0;
    for (int y = 0; y < 64; ++y)
      for (int x = 0; x < 64; ++x) {
        differ += std::abs(red(a, x, y) - red(b, x, y)) > 0.02f;
        shadowed += red(b, x, y) < 0.5f;
      }
    EXPECT_GT(shadowed, 150) << "t=" << t << ": the frozen casters shadow the floor";
    // A pixel whose samples straddle a shadow's edge may differ by rounding; the open's shadows
    // kept would differ over hundreds.
    EXPECT_LT(differ, 4) << "t=" << t;
  }
}

// A half turn between two knots blends through a flat matrix: at the middle the bar is a line,
// and its motion has no inverse there, so it cannot enter a BVH of its own through one. It moves
// vertex by vertex instead; at the middle it casts no shadow, at the close the turned bar's.
TEST(ShadeInTime, AHalfTurnBetweenKnotsIsNotTakenForARigidCaster) {
  ScratchDir dir;
  const std::string motion = "MotionBegin [0 1]\nRotate 0 0 1 0\nRotate 180 0 1 0\nMotionEnd\n";
  const std::string bar = "AttributeBegin\nOpacity [0 0 0]\nTranslate -1.47 2 1.03\n" + motion +
                          "Polygon \"P\" [-1.5 0 -0.3  -1.5 0 0.3  1.5 0 0.3  1.5 0 -0.3]\nAttributeEnd\n";
  const std::string base = edited(kMovingSphereOverFloor, "AttributeBegin\nMotionBegin [0 1]\nTranslate -1 2 0\nTranslate 1 2 0\nMotionEnd\nSphere 0.5 -0.5 0.5 360\nAttributeEnd\n", "");
  const std::string scene = edited(base, "WorldEnd", bar + "WorldEnd");
  const Shaded inTime = shade(dir, "inTime", scene, "--shade-in-time 0 --shade-times 3");
  EXPECT_EQ(numberBefore(inTime.report, " rigidly moving shadow casters"), 0u) << inTime.report;
  EXPECT_GT(numberBefore(inTime.report, " of "), 0u) << "the floor under the bar is a candidate: " << inTime.report;
  auto shadowedPixels = [&](const resample::FlatImage& img) {
    int n = 0;
    for (int y = 0; y < 64; ++y)
      for (int x = 0; x < 64; ++x) {
        EXPECT_TRUE(std::isfinite(red(img, x, y))) << x << ", " << y;
        n += red(img, x, y) < 0.5f;
      }
    return n;
  };
  EXPECT_GT(shadowedPixels(instant(dir, inTime.store, 0.0, "open")), 80) << "the bar's shadow at the open";
  EXPECT_EQ(shadowedPixels(instant(dir, inTime.store, 0.5, "middle")), 0) << "a bar flattened into a line casts none";
  const Shaded turned = shade(dir, "turned", edited(scene, motion, "Rotate 180 0 1 0\n"), "");
  const auto a = instant(dir, inTime.store, 1.0, "close"), b = instant(dir, turned.store, 1.0, "turned");
  int differ = 0;
  for (int y = 0; y < 64; ++y)
    for (int x = 0; x < 64; ++x) differ += std::abs(red(a, x, y) - red(b, x, y)) > 0.02f;
  EXPECT_LT(differ, 4);
  EXPECT_GT(shadowedPixels(b), 80);
}

// A still sphere far from the moving one shadows the floor too (fully transparent, so that the
// camera above sees its shadow). The floor there and the still sphere are no candidates (no
// moving caster reaches them), so their rays skip the moving micropolygons: exactly, as the first
// time's image there shows - the same as shading once, bit for bit.
TEST(ShadeInTime, TheFirstTimeIsShadingOnceAndStillShadowsStay) {
  ScratchDir dir;
  const std::string scene =
      edited(kMovingSphereOverFloor, "WorldEnd", "AttributeBegin\nOpacity [0 0 0]\nTranslate 3 1 2\nSphere 0.5 -0.5 0.5 360\nAttributeEnd\nWorldEnd");
  const Shaded once = shade(dir, "once", scene, "");
  const Shaded timed = shade(dir, "timed", scene, "--shade-in-time 0.01");
  EXPECT_GT(numberBefore(timed.report, " rays against still micropolygons only"), 0u) << timed.report;
  const auto a = instant(dir, once.store, 0.0, "once-open"), b = instant(dir, timed.store, 0.0, "timed-open");
  ASSERT_EQ(a.width, b.width);
  // World x >= 2 (pixels x >= 48), beyond where the moving sphere and its shadow ever are.
  int compared = 0;
  for (const char* channel : {"R", "G", "B", "A"})
    for (int y = 0; y < 64; ++y)
      for (int x = 48; x < 64; ++x) {
        const size_t i = size_t(y) * size_t(a.width) + size_t(x);
        EXPECT_EQ(a.find(channel)->f[i], b.find(channel)->f[i]) << channel << " at " << x << ", " << y;
        ++compared;
      }
  EXPECT_EQ(compared, 4 * 64 * 16);
  // The still sphere's shadow, under it: floor (3, 0, 2) is pixel (56, 16).
  EXPECT_NEAR(red(b, 56, 16), 0.1f, 0.02f);
  EXPECT_NEAR(red(b, 56, 24), 1.1f, 0.02f) << "a pixel beside it is lit";
}

TEST(ShadeInTime, TheStoreIsTheSameForAnyThreadCount) {
  ScratchDir dir;
  std::ofstream(dir.path("s.rib")) << kMovingSphereOverFloor;
  const auto one = runReshutter("-j 1 shade " + dir.path("s.rib") + " -o " + dir.path("one.mps") + " --shade-in-time 0.01");
  const auto two = runReshutter("-j 2 shade " + dir.path("s.rib") + " -o " + dir.path("two.mps") + " --shade-in-time 0.01");
  ASSERT_EQ(one.exitCode, 0) << one.err;
  ASSERT_EQ(two.exitCode, 0) << two.err;
  EXPECT_EQ(test::readBytes(dir.path("one.mps")), test::readBytes(dir.path("two.mps")));
}

TEST(ShadeInTime, StoresCheckTheirShadingTimes) {
  ScratchDir dir;
  store::StoreMeta meta;
  meta.schema.attrs = {{"Ci", store::AttrType::Color}, {"Oi", store::AttrType::Color}};
  meta.shadingTimes = {0.0, 1.0};
  // Times without their colours, times out of order: clear errors.
  EXPECT_THROW(meta.validate("m"), Error);
  meta.schema.attrs.push_back({"Ci@1", store::AttrType::Color});
  meta.schema.attrs.push_back({"Oi@1", store::AttrType::Color});
  meta.validate("m");
  // An output variable at a shading time: its base declared alike, at every time, within the
  // store's times.
  auto refused = [](store::StoreMeta m, const std::string& expected) {
    try {
      m.validate("m");
      ADD_FAILURE() << "accepted a schema that should say: " << expected;
    } catch (const Error& e) {
      EXPECT_NE(std::string(e.what()).find(expected), std::string::npos) << e.what();
    }
  };
  store::StoreMeta withN = meta;
  withN.schema.attrs.push_back({"N@1", store::AttrType::Normal});
  refused(withN, "no 'N' in the schema");
  withN.schema.attrs.push_back({"N", store::AttrType::Float});
  refused(withN, "must be declared as 'N' is");
  withN.schema.attrs.back().type = store::AttrType::Normal;
  withN.validate("m");
  withN.schema.attrs.push_back({"N@2", store::AttrType::Normal});
  refused(withN, "is for shading time 2, but the store has 2");
  withN.shadingTimes = {0.0, 0.5, 1.0};
  withN.schema.attrs.push_back({"Ci@2", store::AttrType::Color});
  withN.schema.attrs.push_back({"Oi@2", store::AttrType::Color});
  withN.validate("m");
  withN.schema.attrs.erase(withN.schema.attrs.begin() + withN.schema.find("N@1"));
  refused(withN, "'N' is given at shading time 2 but not at 1");
  // The later opacities may be left out, all of them (the first time's holds throughout).
  store::StoreMeta noLaterOpacity;
  noLaterOpacity.schema.attrs = {{"Ci", store::AttrType::Color}, {"Oi", store::AttrType::Color}, {"Ci@1", store::AttrType::Color}, {"Ci@2", store::AttrType::Color}};
  noLaterOpacity.shadingTimes = {0.0, 0.5, 1.0};
  noLaterOpacity.validate("m");
  noLaterOpacity.schema.attrs.push_back({"Oi@1", store::AttrType::Color});
  refused(noLaterOpacity, "has no 'Oi@2'");
  store::StoreMeta backwards = meta;
  backwards.shadingTimes = {1.0, 0.0};
  try {
    backwards.validate("m");
    ADD_FAILURE() << "accepted decreasing shading times";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("shading times"), std::string::npos) << e.what();
  }
  // A grid that gives some times' colours and not others is refused, naming the grid.
  store::StoreWriter w(dir.path("s.mps"), meta);
  const std::vector<glm::vec3> P = {{-1, -1, 5}, {1, -1, 5}, {1, 1, 5}, {-1, 1, 5}};
  const std::vector<uint32_t> corners = {0, 1, 2, 3};
  const std::vector<float> white(12, 1.f);
  store::GridInput g;
  g.numVertices = 4, g.positions = P, g.corners = corners, g.gridId = 7;
  g.attrs = {{white, {}}, {white, {}}, {white, {}}, {}};
  try {
    w.addGrid(g);
    ADD_FAILURE() << "accepted a grid with Ci@1 but no Oi@1";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("grid 7"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("Oi@1"), std::string::npos) << e.what();
  }
}

TEST(ShadeInTime, AStoreKeepsWhichGridsCarryTheirTimes) {
  ScratchDir dir;
  store::StoreMeta meta;
  meta.schema.attrs = {{"Ci", store::AttrType::Color}, {"Oi", store::AttrType::Color}, {"Ci@1", store::AttrType::Color}, {"Oi@1", store::AttrType::Color}};
  meta.shadingTimes = {0.0, 1.0};
  const std::vector<glm::vec3> P = {{-1, -1, 5}, {1, -1, 5}, {1, 1, 5}, {-1, 1, 5}};
  const std::vector<uint32_t> corners = {0, 1, 2, 3};
  const std::vector<float> white(12, 1.f), grey(12, 0.5f), half(12, 0.5f);
  {
    store::StoreWriter w(dir.path("s.mps"), meta);
    store::GridInput timed;
    timed.numVertices = 4, timed.positions = P, timed.corners = corners, timed.gridId = 0;
    timed.attrs = {{white, {}}, {white, {}}, {grey, {}}, {half, {}}};
    w.addGrid(timed);
    store::GridInput once = timed;
    once.gridId = 1;
    once.attrs = {{white, {}}, {white, {}}, {}, {}};
    w.addGrid(once);
    w.close();
  }
  store::StoreReader r(dir.path("s.mps"));
  EXPECT_EQ(r.meta().shadingTimes, meta.shadingTimes);
  EXPECT_EQ(r.meta().shadedInTimeGrids, 1u);
  int timedParts = 0, onceParts = 0;
  for (size_t i = 0; i < r.entries().size(); ++i) {
    const store::TileEntry& e = r.entries()[i];
    const store::TilePart part = r.decode(i);
    if (e.effects & store::kEffectShadedInTime) {
      ++timedParts;
      EXPECT_EQ(part.gridId.at(0), 0u);
      EXPECT_EQ(part.attrs[2].f, grey);
      // A transparent time makes the part transparent, though Oi at the first time is opaque.
      EXPECT_TRUE(e.effects & store::kEffectTransparent);
    } else {
      ++onceParts;
      EXPECT_EQ(part.gridId.at(0), 1u);
      EXPECT_TRUE(part.attrs[2].f.empty());
      EXPECT_FALSE(e.effects & store::kEffectTransparent);
    }
  }
  EXPECT_EQ(timedParts, 1);
  EXPECT_EQ(onceParts, 1);
  r.verify();
  const auto info = runReshutter("info --json " + dir.path("s.mps"));
  EXPECT_NE(info.out.find("\"grids\": 1"), std::string::npos) << info.out;
}

// A dump whose motion copies carry their own Cs (the RenderMan motion-blur reference lets colour
// change inside a motion block): ingested as shading in time, red at the open to blue at the
// close; a square beside it without colour per copy keeps one colour.
TEST(ShadeInTime, DumpsWithColourPerKnotAreIngestedInTime) {
  ScratchDir dir;
  std::ofstream(dir.path("dump.rib")) << "Format 32 32 1\nProjection \"orthographic\"\nScreenWindow -2 2 -2 2\nShutter 0 1\nWorldBegin\n"
                                         "MotionBegin [0 1]\n"
                                         "PointsPolygons [4] [0 1 2 3] \"P\" [-1.5 -1 5  -0.5 -1 5  -0.5 1 5  -1.5 1 5] \"constant color Cs\" [1 0 0]\n"
                                         "PointsPolygons [4] [0 1 2 3] \"P\" [-1.5 -1 5  -0.5 -1 5  -0.5 1 5  -1.5 1 5] \"constant color Cs\" [0 0 1]\n"
                                         "MotionEnd\n"
                                         "PointsPolygons [4] [0 1 2 3] \"P\" [0.5 -1 5  1.5 -1 5  1.5 1 5  0.5 1 5] \"constant color Cs\" [0 1 0]\n"
                                         "WorldEnd\n";
  const auto in = runReshutter("ingest " + dir.path("dump.rib") + " -o " + dir.path("dump.mps"));
  ASSERT_EQ(in.exitCode, 0) << in.err;
  const auto info = runReshutter("info --json " + dir.path("dump.mps"));
  EXPECT_NE(info.out.find("\"grids\": 1"), std::string::npos) << info.out;
  auto channel = [](const resample::FlatImage& img, const char* c, int x, int y) {
    return img.find(c)->f[size_t(y - img.y0) * size_t(img.width) + size_t(x - img.x0)];
  };
  for (double t : {0.0, 0.3, 1.0}) {
    const auto img = instant(dir, dir.path("dump.mps"), t, "dump" + std::to_string(int(t * 10)));
    EXPECT_NEAR(channel(img, "R", 8, 16), 1 - t, 1e-5) << "t=" << t;
    EXPECT_NEAR(channel(img, "B", 8, 16), t, 1e-5) << "t=" << t;
    EXPECT_NEAR(channel(img, "G", 24, 16), 1, 1e-6) << "t=" << t;
  }
}

TEST(ShadeInTime, BadOptionsAreOneLineErrors) {
  ScratchDir dir;
  std::ofstream(dir.path("s.rib")) << kRotatingSquare;
  const struct {
    const char* args;
    const char* names;
  } cases[] = {{"--shade-in-time maybe", "--shade-in-time"},
               {"--shade-in-time -1", "--shade-in-time"},
               {"--shade-in-time 0.1 --shade-times 1", "--shade-times"},
               {"--shade-in-time 0.1 --shade-times 17", "--shade-times"},
               {"--shade-in-time 0.1 --shade-at 0.5", "--shade-at"},
               {"--shade-in-time 0.1 --shade-in-time-stride 0", "--shade-in-time-stride"},
               {"--shade-in-time 0.1 --shade-in-time-stride 65", "--shade-in-time-stride"}};
  for (const auto& c : cases) {
    const auto r = runReshutter("shade " + dir.path("s.rib") + " -o " + dir.path("bad.mps") + " " + c.args);
    EXPECT_NE(r.exitCode, 0) << c.args;
    EXPECT_NE(r.err.find(c.names), std::string::npos) << c.args << ": " << r.err;
    EXPECT_EQ(std::count(r.err.begin(), r.err.end(), '\n'), 1) << c.args << ": " << r.err;
    EXPECT_FALSE(std::filesystem::exists(dir.path("bad.mps"))) << c.args;
  }
}

}  // namespace
}  // namespace reshutter
