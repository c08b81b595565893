// The accuracy study's instruments, shared by its studies (bench/accuracy_study.cpp, and
// bench/accuracy_lens.cpp for depth of field): images and their errors against a reference,
// measured points (time, RMSE, bias and noise over seeds), gnuplot plots and markdown tables, and
// the 4 × 3 grid of moving squares several studies render.
#pragma once

#include <array>
#include <cmath>
#include <functional>
#include <memory>
#include <sstream>
#include <string>
#include <vector>

#include <glm/vec2.hpp>
#include <glm/vec3.hpp>

#include "resample/resampler.h"
#include "shade/shading_pass.h"
#include "store/reader.h"
#include "tests/resample_test_util.h"

namespace reshutter::accuracy {

inline constexpr int kW = 256, kH = 192;  // the study images
extern std::string gTmp;                  // scratch directory for stores
extern bool gQuick;                       // fewer samples and steps (a smoke run)

// ---------------------------------------------------------------------------------------------
// Images and errors

struct Img {
  int w = 0, h = 0;
  std::vector<double> c[4];  // R G B A
  void resize(int W, int H) {
    w = W, h = H;
    for (auto& v : c) v.assign(size_t(W) * size_t(H), 0.0);
  }
};

Img toImg(const resample::RenderResult& r);
double lum(const Img& m, size_t i);

struct Err {
  double rmse = 0, max = 0, lum = 0;
};

Err compare(const Img& x, const Img& ref);

// ---------------------------------------------------------------------------------------------
// Points, plots and tables

struct Point {
  std::string study, curve;
  double knob = 0;  // the knob's value on this curve (spp, M, tolerance ...)
  int spp = 0;
  double seconds = 0, rmse = 0, max = 0, lum = 0, bias = NAN, noise = NAN, bytes = 0;
  bool pareto = false;
};

extern std::vector<Point> gPoints;
extern std::ostringstream gTables;

/// Renders `specFor(seed)` for `seeds` seeds; time = best render; errors against `ref`.
Point measure(const std::string& study, const std::string& curve, double knob, const std::function<resample::RenderSpec(uint64_t)>& specFor, const Img& ref,
              int seeds, double extraSeconds = 0);
std::string fmt(double v, const char* f = "%.3g");
/// Writes NAME.dat (one block per curve) and NAME.gp for gnuplot; marks the Pareto front.
void plot(const std::string& outDir, const std::string& study, const std::string& title, bool byBytes = false,
          const std::string& yLabel = "RMSE vs reference");
/// Every point of a study; `knobName` empty (or "spp", already a column) leaves the knob out.
void table(const std::string& study, const std::string& knobName, bool withBytes = false, const std::string& bytesName = "bytes");
/// The two time-bound strategies side by side: time at equal error.
void strategyTable(const std::string& study);
/// The point of `study` whose curve starts with `curvePrefix` (at `spp`, `knob` when given; else the most samples).
const Point* find(const std::string& study, const std::string& curvePrefix, int spp = -1, double knob = NAN);

// ---------------------------------------------------------------------------------------------
// Scenes and references

using Poly = std::vector<glm::dvec2>;

/// Area of `poly` inside the pixel [x, x+1] × [y, y+1].
double pixelArea(const Poly& poly, double x, double y);
/// Adds the time-averaged coverage (over t ∈ [0, 1], `steps` midpoints) of an opaque polygon
/// of colour `ci` to `ref` (objects must not overlap).
void addSwept(Img& ref, const std::function<Poly(double)>& polyAt, glm::dvec3 ci, int steps);
glm::dvec3 colourOf(int i);

/// One object per cell of a 4 × 3 grid of 64 × 64 cells, each an opaque quad whose raster
/// corners at time t are `corners(cell, t)`, at depth `z(cell, t)` (camera-space linear between
/// the stored knots). The store gets `knots` evenly spaced knots of the exact motion; `ref`
/// (when given) the brute-force coverage of the exact motion with `exactAt` (defaults to the
/// stored path).
struct MotionScene {
  std::function<Poly(int, double)> corners;  // raster corners of the exact motion
  std::function<double(int, double)> depth = [](int, double) { return 5.0; };
  /// Camera-space corners at t when the exact motion is camera-linear between its ends (motion in
  /// depth); empty: unproject the raster corners at depth(t).
  std::function<std::array<glm::dvec3, 4>(const test::TestScene&, int, double)> camCorners;
};

std::shared_ptr<const store::StoreReader> writeMotion(const MotionScene& ms, int knots, const std::string& name, std::vector<store::AttrCodec> codecs = {});
Img bruteReference(const std::function<Poly(int, double)>& corners);
glm::dvec2 cellCentre(int cell);
resample::RenderSpec specOf(std::shared_ptr<const store::StoreReader> r, int nx, uint64_t seed, const std::string& filter = "box:1");
std::vector<int> sppSides(std::vector<int> sides);
/// Per-stratum time bounds against one bound over the shutter, at 1–256 spp (the single bound
/// only up to `oneBoundMaxSide`² spp): same image, different cost.
void sweepTimeBounds(const std::string& study, std::shared_ptr<const store::StoreReader> store, const Img& ref, int seeds, int oneBoundMaxSide);

// ---------------------------------------------------------------------------------------------
// The demo scene (shading-pass studies)

inline constexpr int kDW = 256, kDH = 144;
/// Shades `scene` into `path` three times; the best time. `mps`: the micropolygons it made.
double shadeStore(const shade::FrameScene& scene, const shade::ShadeOptions& o, const std::string& path, uint64_t* mps = nullptr);
/// n × n samples per pixel, gaussian 2, of `stores` over `shutter`.
resample::RenderSpec demoSpec(std::vector<std::shared_ptr<const store::StoreReader>> stores, resample::ShutterModel shutter, int n, uint64_t seed);

// ---------------------------------------------------------------------------------------------
// Studies in files of their own

/// Depth of field (bench/accuracy_lens.cpp): lens samples per pixel against error and time.
void studyLens(const std::string& out);
/// Its headline for docs/accuracy.md (empty when the study did not run).
std::string lensHeadline();
/// Other cameras (bench/accuracy_views.cpp): the second eye of a stereo pair shaded once - as
/// shaded, or re-lit for its eye - against shading it from that eye.
void studyViews(const std::string& out);
std::string viewsHeadline();

}  // namespace reshutter::accuracy
