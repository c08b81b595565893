// Lighting in the shaded frame (issue #23): ray-traced shadows (shade/shadows.h) and RIS
// materials and lights mapped onto the built-in models (shade/ris.h). Every scene is a RIB file
// shaded and re-sampled through the CLI, and every figure comes from geometry:
//  - a sphere over a floor lit from straight above: the floor under it gets only the ambient
//    light (at most a third of the open floor), and with shadows off it is the open floor;
//  - an occluder edge under a rectangular area light: the penumbra on the floor spans exactly
//    W·h/(H − h), its visibility linear across it (the shadowed image over the unshadowed one);
//  - a PxrDiffuse red sphere under a PxrDistantLight is red, lit by a light declared anywhere;
//  - PxrTexture feeding diffuseColor shows the texture, t inverted as RIS reads it.
// `shade -v` counts shadow rays, so each test also shows the path it meant was taken.
#include <algorithm>
#include <cctype>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <iterator>

#include <gtest/gtest.h>

#include "tests/exr_test_util.h"
#include "tests/test_util.h"

namespace reshutter {
namespace {

using test::runReshutter;
using test::ScratchDir;

struct Rgb {
  float r, g, b;
};
Rgb pixel(const resample::FlatImage& img, int x, int y) {
  const size_t i = size_t(y - img.y0) * size_t(img.width) + size_t(x - img.x0);
  return {img.find("R")->f[i], img.find("G")->f[i], img.find("B")->f[i]};
}

/// Shades `rib` (extra shade options in `shadeArgs`) and re-samples it; returns the image and
/// the shade command's verbose report.
resample::FlatImage render(ScratchDir& dir, const std::string& name, const std::string& rib, const std::string& shadeArgs, std::string* report = nullptr) {
  std::ofstream(dir.path(name + ".rib")) << rib;
  const auto shade = runReshutter("-v shade " + dir.path(name + ".rib") + " -o " + dir.path(name + ".mps") + " " + shadeArgs);
  EXPECT_EQ(shade.exitCode, 0) << shade.err;
  if (report) *report = shade.err;
  const auto rs = runReshutter("-q resample " + dir.path(name + ".mps") + " --spp 16 --filter box:1 -o " + dir.path(name + ".exr"));
  EXPECT_EQ(rs.exitCode, 0) << rs.err;
  return test::readFlatExr(dir.path(name + ".exr"));
}

std::string fileBytes(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  return {std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
}

uint64_t shadowRays(const std::string& report) { return test::numberBefore(report, " shadow rays"); }
uint64_t shadowMicropolygons(const std::string& report) { return test::numberBefore(report, " micropolygons (scene built"); }

// Floor y = 0, a sphere of radius 0.5 centred 2 above it, a light straight down (world -y). The
// orthographic camera looks down at 50°: the floor point (x, 0, z) is at screen (x, z sin 50°),
// the sphere well above its shadow on screen. 64 px over 4 units.
std::string sphereOverFloor(const std::string& light, const std::string& sphereAttributes = "") {
  return "Format 64 64 1\nProjection \"orthographic\"\nScreenWindow -2 2 -2 2\nShutter 0 1\n"
         "Translate 0 0 10\nRotate -50 1 0 0\nWorldBegin\n"
         "LightSource \"ambientlight\" 1 \"intensity\" [0.1]\n" +
         light +
         "Color [1 1 1]\nSurface \"matte\"\n"
         "Polygon \"P\" [-8 0 -8  -8 0 8  8 0 8  8 0 -8]\n"
         "AttributeBegin\n" +
         sphereAttributes + "Translate 0 2 0\nSphere 0.5 -0.5 0.5 360\nAttributeEnd\nWorldEnd\n";
}

TEST(Shadows, ASphereLitFromAboveShadowsTheFloorUnderIt) {
  ScratchDir dir;
  const std::string light = "LightSource \"shadowdistant\" 2 \"from\" [0 1 0] \"to\" [0 0 0] \"shadowname\" \"raytrace\"\n";
  std::string report;
  const auto on = render(dir, "on", sphereOverFloor(light), "", &report);
  EXPECT_GT(shadowRays(report), 1000u) << report;
  const auto off = render(dir, "off", sphereOverFloor(light), "--shadows off", &report);
  EXPECT_EQ(shadowRays(report), 0u) << report;
  // The shadow's centre, (0, 0, 0) on the floor, is the screen's centre; the open floor is at
  // x = -1.5 on the same row. Matte white: open floor 0.1 + 1 (ambient + N·L), shadow 0.1.
  const Rgb shadow = pixel(on, 32, 32), open = pixel(on, 8, 32);
  EXPECT_NEAR(open.r, 1.1f, 0.01f);
  EXPECT_LE(shadow.r, open.r / 3) << "the floor under the sphere is not in shadow";
  EXPECT_NEAR(shadow.r, 0.1f, 0.01f);
  // Shadows off: the same spot is exactly the open floor.
  EXPECT_NEAR(pixel(off, 32, 32).r, pixel(off, 8, 32).r, 1e-5f);
  EXPECT_NEAR(pixel(off, 8, 32).r, open.r, 1e-5f);
  // A coarser shadow scene (--shadow-rate 4: about a quarter of the micropolygons) casts the
  // same shadow at its centre.
  std::string fine, coarse;
  render(dir, "fine", sphereOverFloor(light), "", &fine);
  const auto coarseImg = render(dir, "coarse", sphereOverFloor(light), "--shadow-rate 4", &coarse);
  EXPECT_LT(shadowMicropolygons(coarse) * 2, shadowMicropolygons(fine)) << coarse;
  EXPECT_GT(shadowMicropolygons(coarse), 0u) << coarse;
  EXPECT_NEAR(pixel(coarseImg, 32, 32).r, 0.1f, 0.01f);
}

TEST(Shadows, EveryWayALightAsksForShadowsTracesThem) {
  ScratchDir dir;
  const struct {
    const char* name;
    std::string light;
  } lights[] = {
      {"attribute", "Attribute \"light\" \"string shadows\" \"on\"\nLightSource \"distantlight\" 2 \"from\" [0 1 0] \"to\" [0 0 0]\n"},
      {"raytraceshadow", "LightSource \"distantlight\" 2 \"from\" [0 1 0] \"to\" [0 0 0] \"float raytraceshadow\" [1]\n"},
      // RIS lights face +Z: Rotate 90 about x turns it to world -y. Shadows are on by default;
      // areaNormalize makes the intensity the irradiance.
      {"ris",
       "AttributeBegin\nRotate 90 1 0 0\nLight \"PxrDistantLight\" \"sun\" \"float intensity\" [1] \"int areaNormalize\" [1] "
       "\"float angleExtent\" [0]\nAttributeEnd\n"},
  };
  for (const auto& l : lights) {
    std::string report;
    const auto img = render(dir, l.name, sphereOverFloor(l.light), "", &report);
    EXPECT_GT(shadowRays(report), 1000u) << l.name << ": " << report;
    EXPECT_LE(pixel(img, 32, 32).r, pixel(img, 8, 32).r / 3) << l.name;
    EXPECT_GT(pixel(img, 8, 32).r, 0.5f) << l.name << ": the open floor is not lit";
  }
  // A plain distantlight asks for no shadows: no rays, no shadow.
  std::string report;
  const auto plain = render(dir, "plain", sphereOverFloor("LightSource \"distantlight\" 2 \"from\" [0 1 0] \"to\" [0 0 0]\n"), "", &report);
  EXPECT_EQ(shadowRays(report), 0u) << report;
  EXPECT_NEAR(pixel(plain, 32, 32).r, pixel(plain, 8, 32).r, 1e-5f);
}

TEST(Shadows, AnObjectWithoutTransmissionCastsNone) {
  ScratchDir dir;
  const std::string light = "LightSource \"shadowdistant\" 2 \"from\" [0 1 0] \"to\" [0 0 0] \"shadowname\" \"raytrace\"\n";
  std::string report;
  const auto img = render(dir, "clear", sphereOverFloor(light, "Attribute \"visibility\" \"int transmission\" [0]\n"), "", &report);
  EXPECT_GT(shadowRays(report), 1000u) << report;
  EXPECT_NEAR(pixel(img, 32, 32).r, pixel(img, 8, 32).r, 1e-5f);
}

// A rectangular light W wide (world x) and 0.05 deep, facing down at height H, its centre at
// x = X0 < 0; an occluder covering x < 0 at height h. The floor point x sees the light's strip
// [X0 - W/2, X0 + W/2] past the edge (0, h) where -Lx·h/(H - h) < x, so its visibility rises
// linearly from 0 at x = -(X0 + W/2)·h/(H - h) to 1 at -(X0 - W/2)·h/(H - h): with H = 4, h = 2,
// W = 2, X0 = -3, from x = 2 to x = 4. The camera looks straight down at x in [0, 6] (16 px a
// unit); the shadowed image over the unshadowed one is the visibility.
std::string penumbraScene() {
  return "Format 96 96 1\nProjection \"orthographic\"\nScreenWindow 0 6 -3 3\nShutter 0 1\n"
         "Rotate -90 1 0 0\nTranslate 0 -10 0\nWorldBegin\n"
         "AttributeBegin\nTranslate -3 4 0\nRotate 90 1 0 0\nScale 2 0.05 1\n"
         "Light \"PxrRectLight\" \"area\" \"float intensity\" [1]\nAttributeEnd\n"
         "Color [1 1 1]\nSurface \"matte\"\n"
         "Polygon \"P\" [-20 0 -20  -20 0 20  20 0 20  20 0 -20]\n"
         "Polygon \"P\" [-20 2 -20  -20 2 20  0 2 20  0 2 -20]\nWorldEnd\n";
}

TEST(Shadows, AnAreaLightsPenumbraHasTheAnalyticWidth) {
  ScratchDir dir;
  std::string report;
  // The occluder reaches far outside the screen: overscan keeps it in the frame's geometry.
  const auto on = render(dir, "on", penumbraScene(), "--overscan 4 --shadow-samples 64", &report);
  EXPECT_GT(shadowRays(report), 100000u) << report;
  const auto off = render(dir, "off", penumbraScene(), "--overscan 4 --shadows off");
  // Visibility along the middle row; where it crosses 0.1 and 0.9, interpolated.
  auto visibility = [&](int x) { return pixel(on, x, 48).r / pixel(off, x, 48).r; };
  auto crossing = [&](double level) {
    for (int x = 1; x < 96; ++x) {
      const double a = visibility(x - 1), b = visibility(x);
      if (a < level && b >= level) return (x - 1) + (level - a) / (b - a) + 0.5;  // pixel centres
    }
    return -1.0;
  };
  const double x10 = crossing(0.1), x90 = crossing(0.9);
  // Analytic: 0.1 at x = 2.2, 0.9 at x = 3.8 (16 px a unit).
  EXPECT_NEAR(x10, 2.2 * 16, 1.0);
  EXPECT_NEAR(x90, 3.8 * 16, 1.0);
  EXPECT_NEAR(visibility(8), 0.0, 0.02);   // x = 0.5: umbra
  EXPECT_NEAR(visibility(88), 1.0, 0.02);  // x = 5.5: fully lit
}

TEST(Shadows, SoftShadowsAreTheSameForAnyThreadCount) {
  ScratchDir dir;
  std::ofstream(dir.path("p.rib")) << penumbraScene();
  for (const char* j : {"1", "2"}) {
    const auto shade = runReshutter(std::string("-q -j ") + j + " shade " + dir.path("p.rib") + " -o " + dir.path(std::string("p") + j + ".mps") +
                                    " --overscan 4 --shadow-samples 8");
    ASSERT_EQ(shade.exitCode, 0) << shade.err;
  }
  EXPECT_EQ(fileBytes(dir.path("p1.mps")), fileBytes(dir.path("p2.mps")));
}

// uberlight at the eye shining down the view onto a wall 10 away: its beam's cross-section at
// unit distance is a superellipse of half-sizes width × height, so on the wall a rectangle
// (roundness 0) of 5 × 2.5 or the ellipse inside it (roundness 1). 4 px a unit.
std::string uberWall(const std::string& params) {
  return "Format 64 64 1\nProjection \"orthographic\"\nScreenWindow -8 8 -8 8\nShutter 0 1\nWorldBegin\n"
         "LightSource \"uberlight\" 1 \"intensity\" [1] \"float width\" [0.5] \"float height\" [0.25] \"float wedge\" [0.005] "
         "\"float hedge\" [0.005] " +
         params + "\nColor [1 1 1]\nSurface \"matte\"\nPolygon \"P\" [-20 -20 10  20 -20 10  20 20 10  -20 20 10]\nWorldEnd\n";
}

TEST(Lights, AnUberlightsBeamIsItsSuperellipse) {
  ScratchDir dir;
  auto at = [](const resample::FlatImage& img, double x, double y) { return pixel(img, int(32 + 4 * x), int(32 - 4 * y)).r; };
  const auto box = render(dir, "box", uberWall("\"float roundness\" [0]"), "");
  EXPECT_GT(at(box, 4.4, 0), 0.005f);  // inside |x| < 5
  EXPECT_EQ(at(box, 5.6, 0), 0.0f);    // outside
  EXPECT_GT(at(box, 0, 2.1), 0.005f);  // inside |y| < 2.5
  EXPECT_EQ(at(box, 0, 2.9), 0.0f);
  EXPECT_GT(at(box, 4.4, 2.1), 0.005f);  // the rectangle's corner
  const auto ellipse = render(dir, "ellipse", uberWall("\"float roundness\" [1]"), "");
  EXPECT_GT(at(ellipse, 4.4, 0), 0.005f);
  EXPECT_EQ(at(ellipse, 4.4, 2.1), 0.0f);    // (4.4/5)² + (2.1/2.5)² > 1: outside the ellipse
  EXPECT_GT(at(ellipse, 3.0, 1.5), 0.005f);  // 0.36 + 0.36 < 1
  // Cut off before the wall: no light reaches it.
  const auto cut = render(dir, "cut", uberWall("\"float roundness\" [0] \"float cutoff\" [9] \"float faredge\" [0.5]"), "");
  EXPECT_EQ(at(cut, 0, 0), 0.0f);
}

// A sphere filling the middle of a 32×32 orthographic view, lit along the view by a RIS light
// declared inside an attribute block before it (RIS lights light everything).
std::string risSphere(const std::string& bxdf) {
  return "Format 32 32 1\nProjection \"orthographic\"\nScreenWindow -1 1 -1 1\nShutter 0 1\nWorldBegin\n"
         "AttributeBegin\nLight \"PxrDistantLight\" \"sun\" \"float intensity\" [3.14159265] \"int areaNormalize\" [1]\nAttributeEnd\n"
         "AttributeBegin\nColor [0 1 0]\n" +
         bxdf + "Translate 0 0 5\nSphere 0.9 -0.9 0.9 360\nAttributeEnd\nWorldEnd\n";
}

TEST(RisShading, APxrDiffuseRedSphereIsRed) {
  ScratchDir dir;
  // Irradiance π at the sphere's centre (the light along the view): radiance = albedo.
  const auto img = render(dir, "red", risSphere("Bxdf \"PxrDiffuse\" \"red\" \"color diffuseColor\" [0.8 0.05 0.05]\n"), "");
  const Rgb c = pixel(img, 16, 16);
  EXPECT_NEAR(c.r, 0.8f, 0.03f);
  EXPECT_NEAR(c.g, 0.05f, 0.01f) << "Color [0 1 0] must not replace the Bxdf's colour";
  EXPECT_NEAR(c.b, 0.05f, 0.01f);
  // Other Bxdfs keep their colour too; an unknown one still renders.
  const struct {
    const char* name;
    std::string bxdf;
    float r, g, b;
  } cases[] = {
      {"surface", "Bxdf \"PxrSurface\" \"s\" \"color diffuseColor\" [0.1 0.6 0.1] \"color specularFaceColor\" [0 0 0]\n", 0.1f, 0.6f, 0.1f},
      {"constant", "Bxdf \"PxrConstant\" \"c\" \"color emitColor\" [0.2 0.3 0.9]\n", 0.2f, 0.3f, 0.9f},
      {"lmdiffuse", "Bxdf \"PxrLMDiffuse\" \"l\" \"color frontColor\" [0.5 0.4 0.3]\n", 0.5f, 0.4f, 0.3f},
  };
  for (const auto& k : cases) {
    const Rgb p = pixel(render(dir, k.name, risSphere(k.bxdf), ""), 16, 16);
    EXPECT_NEAR(p.r, k.r, 0.03f) << k.name;
    EXPECT_NEAR(p.g, k.g, 0.03f) << k.name;
    EXPECT_NEAR(p.b, k.b, 0.03f) << k.name;
  }
}

TEST(RisShading, PxrTextureFeedsTheDiffuseColour) {
  ScratchDir dir;
  // Top half red, bottom half blue in the image; RIS reads t upwards (invertT), so on a patch
  // whose t runs down the screen the blue half comes out on top.
  ASSERT_EQ(test::runImageTool("oiiotool --pattern constant:color=1,0,0 16x8 3 --pattern constant:color=0,0,1 16x8 3 --mosaic 1x2 -o " + dir.path("halves.tif"))
                .exitCode,
            0);
  ASSERT_EQ(test::runImageTool("maketx " + dir.path("halves.tif") + " -o " + dir.path("halves.tx")).exitCode, 0);
  const std::string rib =
      "Format 32 32 1\nProjection \"orthographic\"\nScreenWindow -1 1 -1 1\nShutter 0 1\nWorldBegin\n"
      "Light \"PxrDomeLight\" \"dome\" \"float intensity\" [1]\n"
      "Pattern \"PxrTexture\" \"tex\" \"string filename\" \"halves.tx\"\n"
      "Bxdf \"PxrDiffuse\" \"d\" \"reference color diffuseColor\" [\"tex:resultRGB\"]\n"
      "Patch \"bilinear\" \"P\" [-1.2 1.2 5  1.2 1.2 5  -1.2 -1.2 5  1.2 -1.2 5]\nWorldEnd\n";
  std::string report;
  const auto img = render(dir, "tex", rib, "", &report);
  EXPECT_EQ(report.find(" 0 texture lookups"), std::string::npos) << report;
  const Rgb top = pixel(img, 16, 6), bottom = pixel(img, 16, 26);
  EXPECT_NEAR(top.b, 1.0f, 0.03f);
  EXPECT_NEAR(top.r, 0.0f, 0.03f);
  EXPECT_NEAR(bottom.r, 1.0f, 0.03f);
  EXPECT_NEAR(bottom.b, 0.0f, 0.03f);
}

}  // namespace
}  // namespace reshutter

namespace reshutter {
namespace {

TEST(Shadows, BadShadowOptionsAndAMissingTextureModuleAreClearErrors) {
  ScratchDir dir;
  std::ofstream(dir.path("s.rib")) << sphereOverFloor("LightSource \"shadowdistant\" 2 \"from\" [0 1 0] \"to\" [0 0 0] \"shadowname\" \"raytrace\"\n");
  const struct {
    const char* args;
    const char* names;
  } bad[] = {{"--shadows maybe", "--shadows"}, {"--shadow-samples 0", "--shadow-samples"}, {"--shadow-rate 0.5", "--shadow-rate"}};
  for (const auto& b : bad) {
    const auto r = runReshutter("shade " + dir.path("s.rib") + " -o " + dir.path("bad.mps") + " " + b.args);
    EXPECT_NE(r.exitCode, 0) << b.args;
    EXPECT_NE(r.err.find(b.names), std::string::npos) << r.err;
    EXPECT_FALSE(std::filesystem::exists(dir.path("bad.mps"))) << b.args;
  }
  // A frame with a texture needs the texture module; one that cannot be loaded is one line naming it.
  std::ofstream(dir.path("t.rib")) << "Format 8 8 1\nProjection \"orthographic\"\nWorldBegin\nSurface \"paintedplastic\" \"texturename\" \"x.tx\"\n"
                                      "Patch \"bilinear\" \"P\" [-1 1 5  1 1 5  -1 -1 5  1 -1 5]\nWorldEnd\n";
  const auto r = test::runCommand("RESHUTTER_TEXTURE_MODULE=" + dir.path("nowhere.so") + " " + std::string(RESHUTTER_BINARY) + " shade " + dir.path("t.rib") +
                                  " -o " + dir.path("t.mps"));
  EXPECT_EQ(r.exitCode, 1) << r.err;
  EXPECT_NE(r.err.find("nowhere.so: cannot load the texture module"), std::string::npos) << r.err;
  EXPECT_FALSE(std::filesystem::exists(dir.path("t.mps")));
}

}  // namespace
}  // namespace reshutter
