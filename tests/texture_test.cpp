// Textures in the shaded frame (issue #23): paintedplastic's texturename looked up through
// OpenImageIO's TextureSystem. A texture of four known colour quadrants, mip-mapped by maketx and
// found through Option "searchpath" "texture" relative to the RIB file, lit by an ambient light
// alone (Ci = Cs · texture), must come out with each quadrant's colour where the analytic st
// mapping puts it; a texture that cannot be read warns and shows magenta, and the frame still
// renders. The shading pass's lookup count (shade -v) shows the texture path was taken.
#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>

#include <gtest/gtest.h>

#include "tests/exr_test_util.h"
#include "tests/test_util.h"

namespace reshutter {
namespace {

using test::runReshutter;
using test::ScratchDir;

// A 64×64 orthographic view of a bilinear patch filling the screen: s runs left to right and t
// top to bottom, so texture (s, t) lands on pixel (64 s, 64 t).
std::string sceneWith(const std::string& options, const std::string& texture) {
  return "Format 64 64 1\nProjection \"orthographic\"\nScreenWindow -1 1 -1 1\nShutter 0 1\n" + options +
         "WorldBegin\nLightSource \"ambientlight\" 1 \"intensity\" [1]\nColor [1 1 1]\n"
         "Surface \"paintedplastic\" \"texturename\" \"" +
         texture +
         "\" \"Ka\" [1] \"Kd\" [0] \"Ks\" [0]\n"
         "ShadingRate 0.5\nPatch \"bilinear\" \"P\" [-1.2 1.2 5  1.2 1.2 5  -1.2 -1.2 5  1.2 -1.2 5]\nWorldEnd\n";
}

struct Rgb {
  float r, g, b;
};
Rgb pixel(const resample::FlatImage& img, int x, int y) {
  const size_t i = size_t(y - img.y0) * size_t(img.width) + size_t(x - img.x0);
  return {img.find("R")->f[i], img.find("G")->f[i], img.find("B")->f[i]};
}

TEST(Textures, QuadrantsLandWhereSAndTPutThem) {
  ScratchDir dir;
  std::filesystem::create_directories(dir.path("maps"));
  // Top-left red, top-right green, bottom-left blue, bottom-right yellow (oiiotool's mosaic order).
  ASSERT_EQ(test::runImageTool("oiiotool --pattern constant:color=1,0,0 32x32 3 --pattern constant:color=0,1,0 32x32 3 --pattern constant:color=0,0,1 "
                               "32x32 3 --pattern constant:color=1,1,0 32x32 3 --mosaic 2x2 -o " +
                               dir.path("quadrants.tif"))
                .exitCode,
            0);
  ASSERT_EQ(test::runImageTool("maketx " + dir.path("quadrants.tif") + " -o " + dir.path("maps/quadrants.tx")).exitCode, 0);
  std::ofstream(dir.path("scene.rib")) << sceneWith("Option \"searchpath\" \"texture\" [\"maps:&\"]\n", "quadrants.tx");
  const auto shade = runReshutter("-v shade " + dir.path("scene.rib") + " -o " + dir.path("s.mps"));
  ASSERT_EQ(shade.exitCode, 0) << shade.err;
  EXPECT_EQ(shade.err.find("cannot be read"), std::string::npos) << shade.err;
  EXPECT_EQ(shade.err.find(" 0 texture lookups"), std::string::npos) << shade.err;
  EXPECT_NE(shade.err.find("texture lookups (0 textures missing)"), std::string::npos) << shade.err;
  ASSERT_EQ(runReshutter("-q resample " + dir.path("s.mps") + " --spp 4 --filter box:1 -o " + dir.path("s.exr")).exitCode, 0);
  const resample::FlatImage img = test::readFlatExr(dir.path("s.exr"));
  // The patch spans [-1.2, 1.2]: st = (x/64·2 - 1 + 1.2) / 2.4. Quadrant centres, well inside.
  const struct {
    int x, y;
    Rgb want;
  } checks[] = {{14, 14, {1, 0, 0}}, {50, 14, {0, 1, 0}}, {14, 50, {0, 0, 1}}, {50, 50, {1, 1, 0}}};
  for (const auto& c : checks) {
    const Rgb p = pixel(img, c.x, c.y);
    EXPECT_NEAR(p.r, c.want.r, 0.02) << c.x << "," << c.y;
    EXPECT_NEAR(p.g, c.want.g, 0.02) << c.x << "," << c.y;
    EXPECT_NEAR(p.b, c.want.b, 0.02) << c.x << "," << c.y;
  }
  // The boundary between red and green lies at s = 1/2, the screen's centre column: pixel 31 is
  // red-dominated and pixel 32 green-dominated (the filter blurs the step by under a pixel).
  EXPECT_GT(pixel(img, 30, 14).r, pixel(img, 30, 14).g);
  EXPECT_GT(pixel(img, 33, 14).g, pixel(img, 33, 14).r);
}

TEST(Textures, AMinifiedCheckerFiltersToGrey) {
  // 2-texel black and white checks, 512 texels across 64 pixels: each micropolygon spans several
  // checks, so a lookup filtered over its footprint (a coarser mip level) is the average, 0.5;
  // point sampling would give 0 or 1 per micropolygon.
  ScratchDir dir;
  ASSERT_EQ(test::runImageTool("oiiotool --pattern checker:width=2:height=2:color1=0,0,0:color2=1,1,1 512x512 3 -o " + dir.path("fine.tif")).exitCode, 0);
  ASSERT_EQ(test::runImageTool("maketx " + dir.path("fine.tif") + " -o " + dir.path("fine.tx")).exitCode, 0);
  std::ofstream(dir.path("scene.rib")) << sceneWith("", "fine.tx");
  const auto shade = runReshutter("-q shade " + dir.path("scene.rib") + " -o " + dir.path("s.mps"));
  ASSERT_EQ(shade.exitCode, 0) << shade.err;
  ASSERT_EQ(runReshutter("-q resample " + dir.path("s.mps") + " --spp 4 --filter box:1 -o " + dir.path("s.exr")).exitCode, 0);
  const resample::FlatImage img = test::readFlatExr(dir.path("s.exr"));
  double lo = 1, hi = 0;
  for (int y = 8; y < 56; ++y)
    for (int x = 8; x < 56; ++x) {
      const Rgb p = pixel(img, x, y);
      lo = std::min(lo, double(p.g)), hi = std::max(hi, double(p.g));
    }
  EXPECT_GT(lo, 0.4);
  EXPECT_LT(hi, 0.6);
}

TEST(Textures, AMissingTextureWarnsAndShowsMagenta) {
  ScratchDir dir;
  std::ofstream(dir.path("scene.rib")) << sceneWith("", "no-such-map.tx");
  const auto shade = runReshutter("-v shade " + dir.path("scene.rib") + " -o " + dir.path("s.mps"));
  ASSERT_EQ(shade.exitCode, 0) << shade.err;
  EXPECT_NE(shade.err.find("texture 'no-such-map.tx' cannot be read"), std::string::npos) << shade.err;
  EXPECT_NE(shade.err.find("(1 textures missing)"), std::string::npos) << shade.err;
  ASSERT_EQ(runReshutter("-q resample " + dir.path("s.mps") + " --spp 4 -o " + dir.path("s.exr")).exitCode, 0);
  const Rgb p = pixel(test::readFlatExr(dir.path("s.exr")), 32, 32);
  EXPECT_NEAR(p.r, 1, 0.01);
  EXPECT_NEAR(p.g, 0, 0.01);
  EXPECT_NEAR(p.b, 1, 0.01);
}

}  // namespace
}  // namespace reshutter
