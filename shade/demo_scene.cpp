// The built-in demo scene (see demo_scene.h for what is in it and why).
#include "shade/demo_scene.h"

#include <cmath>

#include "shade/texture.h"

namespace reshutter::shade {

namespace {

using glm::dvec3;

void checkerFloor(Scene& s) {
  // 1-unit tiles, one colour per face (uniform Cs), so the blur of moving objects reads against
  // a sharp static pattern; wide enough to fill the frame up to the backdrop.
  const int nx = 36, nz = 22;
  const double x0 = -18, x1 = 18, z0 = -6, z1 = 16;
  std::vector<dvec3> P;
  for (int j = 0; j <= nz; ++j)
    for (int i = 0; i <= nx; ++i) P.emplace_back(x0 + (x1 - x0) * i / nx, 0.0, z0 + (z1 - z0) * j / nz);
  std::vector<int> nverts, verts;
  Scene::VertexData vd;
  for (int j = 0; j < nz; ++j)
    for (int i = 0; i < nx; ++i) {
      const int a = j * (nx + 1) + i;
      nverts.push_back(4);
      // Counter-clockwise seen from above (+y) in this left-handed world.
      verts.insert(verts.end(), {a, a + nx + 1, a + nx + 2, a + 1});
      const bool dark = (i + j) % 2;
      vd.Cs.push_back(dark ? dvec3(0.16, 0.17, 0.2) : dvec3(0.78, 0.76, 0.72));
    }
  s.attributeBegin();
  s.identifier("floor");
  s.surface("plastic", {{"Ks", {0.25}}, {"roughness", {0.15}}, {"Kd", {0.8}}, {"Ka", {1}}});
  s.pointsPolygons(nverts, verts, P, vd);
  s.attributeEnd();
}

void backdrop(Scene& s) {
  s.attributeBegin();
  s.identifier("backdrop");
  s.surface("constant", {});
  Scene::VertexData vd;
  const dvec3 low(0.62, 0.55, 0.5), high(0.08, 0.12, 0.28);
  vd.Cs = {low, low, high, high};  // P00 P10 P01 P11: bottom edge, then top edge
  s.patch({dvec3(-18, 0, 16), dvec3(18, 0, 16), dvec3(-18, 12, 16), dvec3(18, 12, 16)}, vd);
  s.attributeEnd();
}

void flyingBall(Scene& s) {
  s.attributeBegin();
  s.identifier("flying ball");
  s.color({1.0, 0.2, 0.1});
  s.surface("plastic", {{"roughness", {0.08}}, {"Ks", {0.8}}, {"Kd", {0.8}}});
  s.motionBegin({0, 1});
  s.translate(-4.0, 0.7, 1.5);
  s.translate(-2.3, 0.95, 1.5);
  s.motionEnd();
  s.sphere(0.7, -0.7, 0.7, 360);
  s.attributeEnd();
}

void spinningCube(Scene& s) {
  s.attributeBegin();
  s.identifier("spinning cube");
  s.surface("plastic", {{"roughness", {0.12}}, {"Ks", {0.5}}});
  s.translate(0.4, 1.1, 4.0);
  s.rotate(-22, 1, 0, 0);
  s.motionBegin({0, 0.25, 0.5, 0.75, 1});
  for (int k = 0; k < 5; ++k) s.rotate(30 + 15 * k, 0, 1, 0);
  s.motionEnd();
  const std::vector<dvec3> P = {{-1, -1, -1}, {1, -1, -1}, {-1, 1, -1}, {1, 1, -1}, {-1, -1, 1}, {1, -1, 1}, {-1, 1, 1}, {1, 1, 1}};
  std::vector<dvec3> scaled;
  for (const auto& p : P) scaled.push_back(0.9 * p);
  // Faces wound so that each normal points out of the cube.
  const std::vector<int> verts = {0, 2, 3, 1, 0, 1, 5, 4, 1, 3, 7, 5, 3, 2, 6, 7, 2, 0, 4, 6, 4, 5, 7, 6};
  Scene::VertexData vd;
  vd.Cs = {{0.95, 0.75, 0.1}, {0.1, 0.45, 0.9}, {0.2, 0.75, 0.3}, {0.9, 0.35, 0.6}, {0.95, 0.95, 0.95}, {0.55, 0.2, 0.85}};
  s.pointsPolygons({4, 4, 4, 4, 4, 4}, verts, scaled, vd);
  s.attributeEnd();
}

void tumblingTorus(Scene& s) {
  s.attributeBegin();
  s.identifier("tumbling torus");
  s.color({1.0, 0.76, 0.33});
  s.surface("metal", {{"roughness", {0.12}}, {"Ks", {1.0}}, {"Ka", {1.0}}});
  s.translate(3.3, 1.45, 3.2);
  s.motionBegin({0, 0.5, 1});
  s.rotate(-10, 1, 0, 0);
  s.rotate(25, 1, 0, 0);
  s.rotate(60, 1, 0, 0);
  s.motionEnd();
  s.torus(0.8, 0.28, 0, 360, 360);
  s.attributeEnd();
}

void flag(Scene& s) {
  s.attributeBegin();
  s.identifier("flag pole");
  s.color({0.7, 0.7, 0.75});
  s.surface("metal", {{"roughness", {0.15}}});
  s.translate(-4.6, 0, 7.5);
  s.rotate(-90, 1, 0, 0);
  s.cylinder(0.06, 0, 4.2, 360);
  s.translate(0, 0, 4.2);
  s.sphere(0.12, -0.12, 0.12, 360);
  s.attributeEnd();

  s.attributeBegin();
  s.identifier("flag");
  s.surface("plastic", {{"Ks", {0.3}}, {"roughness", {0.2}}});
  s.translate(-4.55, 2.6, 7.5);
  const int nx = 14, ny = 7;
  const double w = 2.6, h = 1.5;
  std::vector<int> nverts, verts;
  Scene::VertexData vd;
  for (int j = 0; j < ny; ++j)
    for (int i = 0; i < nx; ++i) {
      const int a = j * (nx + 1) + i;
      nverts.push_back(4);
      verts.insert(verts.end(), {a, a + 1, a + nx + 2, a + nx + 1});
    }
  for (int j = 0; j <= ny; ++j)
    for (int i = 0; i <= nx; ++i) vd.Cs.push_back(j < ny / 2 ? dvec3(0.95, 0.95, 0.9) : dvec3(0.1, 0.3, 0.85));
  const double times[3] = {0, 0.5, 1};
  s.motionBegin({times[0], times[1], times[2]});
  for (double t : times) {
    std::vector<dvec3> P;
    for (int j = 0; j <= ny; ++j)
      for (int i = 0; i <= nx; ++i) {
        const double x = w * i / nx, y = h * j / ny;
        // A travelling wave whose amplitude grows away from the pole.
        const double amp = 0.28 * x / w;
        const double z = amp * std::sin(2.4 * x - 7.0 * t + 0.6 * y);
        P.emplace_back(x, y - 0.15 * x / w * (1 + std::sin(3.0 * t)), z);
      }
    s.pointsPolygons(nverts, verts, P, vd);
  }
  s.motionEnd();
  s.attributeEnd();
}

void glassBall(Scene& s) {
  s.attributeBegin();
  s.identifier("translucent sphere");
  s.color({0.3, 0.85, 0.95});
  s.opacity({0.35, 0.35, 0.35});
  s.surface("plastic", {{"roughness", {0.05}}, {"Ks", {0.9}}, {"Kd", {0.6}}});
  s.motionBegin({0, 1});
  s.translate(-0.9, 0.9, 0.8);
  s.translate(-0.9, 1.4, 0.8);
  s.motionEnd();
  s.sphere(0.8, -0.8, 0.8, 360);
  s.attributeEnd();
}

void holdout(Scene& s) {
  s.attributeBegin();
  s.identifier("matte holdout");
  s.matte(true);
  s.translate(1.9, 0.55, 0.3);
  s.sphere(0.55, -0.55, 0.55, 360);
  s.attributeEnd();
}

void brickWall(Scene& s) {
  s.attributeBegin();
  s.identifier("brick wall");
  s.surface("paintedplastic", {{"Ks", {0.1}}, {"roughness", {0.3}}, {"Kd", {0.9}}}, {{"texturename", demoBrickTexture()}});
  // st runs across the wall and down it, 1.25 texture tiles high (ten courses of bricks).
  Scene::VertexData vd;
  vd.st = {{0.0, 0.0}, {2.5, 0.0}, {0.0, 1.25}, {2.5, 1.25}};
  s.patch({dvec3(5.2, 2.5, 12), dvec3(10.2, 2.5, 12), dvec3(5.2, 0, 12), dvec3(10.2, 0, 12)}, vd);
  s.attributeEnd();
}

void glossyRow(Scene& s) {
  const dvec3 colours[4] = {{0.95, 0.55, 0.1}, {0.25, 0.8, 0.35}, {0.2, 0.35, 0.95}, {0.9, 0.9, 0.92}};
  for (int i = 0; i < 4; ++i) {
    s.attributeBegin();
    s.identifier("glossy ball " + std::to_string(i + 1));
    s.color(colours[i]);
    s.surface("plastic", {{"roughness", {0.03 + 0.04 * i}}, {"Ks", {0.8}}});
    s.translate(2.0 + 1.05 * i, 0.42, 7.5 - 0.6 * i);
    s.sphere(0.42, -0.42, 0.42, 360);
    s.attributeEnd();
  }
}

}  // namespace

void buildDemoScene(Scene& s, int width, int height, double eyeX) {
  const std::string where = s.where;
  s.where = "built-in demo";
  s.format(width, height, 1.0);
  s.frameAspectRatio(16.0 / 9.0);
  s.perspective(32);
  s.clipping(0.1, 1000);
  s.shutter(0, 1);
  s.shadingRate(1.0);
  s.frameBegin(1);
  // Camera at (0, 2.1, -9) in a left-handed, y-up world, pitched down 8° (Rotate first: the
  // CTM is world → camera); an eye offset moves it along its own x.
  if (eyeX != 0) s.translate(-eyeX, 0, 0);
  s.rotate(-8, 1, 0, 0);
  s.translate(0, -2.1, 9);
  s.worldBegin();

  s.lightSource("ambientlight", "ambient", {{"intensity", {0.12}}, {"lightcolor", {0.8, 0.85, 1.0}}});
  // The key and the spot cast ray-traced shadows; the fill does not.
  s.lightSource("shadowdistant", "key", {{"intensity", {0.8}}, {"lightcolor", {1.0, 0.93, 0.82}}, {"from", {-6, 9, -5}}, {"to", {0, 0, 4}}},
                {{"shadowname", "raytrace"}});
  s.lightSource(
      "shadowspot", "spot",
      {{"intensity", {45}}, {"lightcolor", {1.0, 0.95, 0.9}}, {"from", {3, 8, 0}}, {"to", {0.5, 0, 4}}, {"coneangle", {0.55}}, {"conedeltaangle", {0.2}}},
      {{"shadowname", "raytrace"}});
  s.lightSource("pointlight", "fill", {{"intensity", {12}}, {"lightcolor", {0.55, 0.65, 1.0}}, {"from", {-3, 3, -6}}});

  backdrop(s);
  checkerFloor(s);
  flag(s);
  glossyRow(s);
  brickWall(s);
  spinningCube(s);
  tumblingTorus(s);
  flyingBall(s);
  glassBall(s);
  holdout(s);

  s.worldEnd();
  s.frameEnd();
  s.where = where;
}

FrameScene demoFrame(int width, int height, double eyeX) {
  FrameScene out;
  Scene s([&](FrameScene& f) { out = std::move(f); });
  buildDemoScene(s, width, height, eyeX);
  out.source = "built-in demo";
  return out;
}

}  // namespace reshutter::shade
