// Helpers of the production-primitive tests (primitives_test.cpp, primitives_nurbs_test.cpp): the
// primitives a builder call makes or the error it throws, de Casteljau's patch, random points, and
// a RIB scene shaded and re-sampled through the command line.
#pragma once

#include <array>
#include <fstream>
#include <functional>
#include <random>
#include <string>
#include <vector>

#include "common/error.h"
#include "resample/image.h"
#include "shade/scene.h"
#include "tests/exr_test_util.h"
#include "tests/test_util.h"

namespace reshutter::shade::testing {

// The primitives one builder call makes (in a world block, identity transform).
inline std::vector<Primitive> primsOf(const std::function<void(Scene&)>& build) {
  std::vector<Primitive> out;
  Scene scene([&](FrameScene& f) { out = std::move(f.prims); });
  scene.worldBegin();
  build(scene);
  scene.worldEnd();
  return out;
}

// The message of the Error a builder call throws ("no error" when it throws none).
inline std::string buildError(const std::function<void(Scene&)>& build) {
  try {
    primsOf(build);
  } catch (const Error& e) {
    return std::string(e.what());
  }
  return std::string("no error");
}

// A bicubic bezier patch at (u, v) by de Casteljau: the definition, not the basis matrix.
inline glm::dvec3 deCasteljau(const std::vector<glm::dvec3>& cv, double u, double v) {
  auto curve = [](std::array<glm::dvec3, 4> p, double t) {
    for (int r = 3; r > 0; --r)
      for (int i = 0; i < r; ++i) p[size_t(i)] = (1 - t) * p[size_t(i)] + t * p[size_t(i + 1)];
    return p[0];
  };
  std::array<glm::dvec3, 4> rows;
  for (size_t l = 0; l < 4; ++l) rows[l] = curve({cv[l * 4], cv[l * 4 + 1], cv[l * 4 + 2], cv[l * 4 + 3]}, u);
  return curve(rows, v);
}

inline std::vector<glm::dvec3> randomPoints(size_t n, uint32_t seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> d(-3, 3);
  std::vector<glm::dvec3> p(n);
  for (auto& x : p) x = glm::dvec3(d(rng), d(rng), d(rng));
  return p;
}

struct Rendered {
  resample::FlatImage image;
  const resample::PixelVector<float>& alpha() const { return image.find("A")->f; }
};

inline Rendered render(const test::ScratchDir& dir, const std::string& name, const std::string& rib, const std::string& resampleArgs) {
  const std::string path = dir.path(name + ".rib");
  std::ofstream(path) << rib;
  auto r = test::runReshutter("-q shade " + path + " -o " + dir.path(name + ".mps"));
  EXPECT_EQ(r.exitCode, 0) << r.err;
  r = test::runReshutter("-q resample " + dir.path(name + ".mps") + " -o " + dir.path(name + ".exr") + " " + resampleArgs);
  EXPECT_EQ(r.exitCode, 0) << r.err;
  return Rendered{test::readFlatExr(dir.path(name + ".exr"))};
}

}  // namespace reshutter::shade::testing
