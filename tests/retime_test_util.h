// Helpers of the re-timing tests (retime_test.cpp, retime_cli_test.cpp): a square moving through
// absolute time, its per-frame stores, its exact coverage error, and a row of deep output
// flattened against the flat image.
#pragma once

#include <cmath>
#include <memory>
#include <string>
#include <vector>

#include "resample/retime.h"
#include "tests/resample_test_util.h"
#include "tests/test_util.h"

namespace reshutter::test::retime {

using namespace reshutter::resample;

// A square moving continuously through absolute time: x(t) = x0 + vx·t px (t in frames).
struct Motion {
  double x0 = -20.3, y0 = 6.6, w = 11.7, h = 13.2, vx = 9.35, vy = 1.45, z = 10;
};

// The store of frame F: knots at F + open and F + close (frame-relative open/close).
inline std::shared_ptr<const store::StoreReader> frameStore(const Motion& m, int64_t frame, const std::string& path, double open = 0, double close = 1, int W = 48,
                                                            int H = 36) {
  TestScene s = makeScene(W, H, {open, close});
  s.meta.frame = frame;
  s.meta.shutterOpen = open, s.meta.shutterClose = close;
  TestMp mp;
  for (double t : {open, close}) {
    const double T = double(frame) + t;
    mp.knots.push_back(s.rect(m.x0 + m.vx * T, m.y0 + m.vy * T, m.x0 + m.w + m.vx * T, m.y0 + m.h + m.vy * T, m.z));
  }
  mp.ci = {0.5f, 0.5f, 0.5f};
  s.mps.push_back(mp);
  return writeScene(s, path);
}

inline double coverageError(const FlatImage& img, const Motion& m, double a, double b, const std::vector<double>& shapeT = {},
                     const std::vector<double>& shapeW = {}) {
  const auto& A = img.find("A")->f;
  double sum = 0;
  for (int py = 0; py < img.height; ++py)
    for (int px = 0; px < img.width; ++px) {
      const double d = A[size_t(py) * img.width + px] - analyticCoverage(px, py, m.x0, m.y0, m.w, m.h, m.vx, m.vy, a, b, shapeT, shapeW);
      sum += d * d;
    }
  return std::sqrt(sum / double(A.size()));
}
inline double coverageError(const RenderResult& r, const Motion& m, double a, double b, const std::vector<double>& shapeT = {},
                     const std::vector<double>& shapeW = {}) {
  return coverageError(r.image, m, a, b, shapeT, shapeW);
}

// Largest |flattened deep − flat| over R G B A on row y (absolute) of a render.
inline double rowFlattenError(const DeepImage& deep, const FlatImage& flat, int y) {
  double worst = 0;
  DeepPixel px;
  for (int x = flat.x0; x < flat.x0 + flat.width; ++x) {
    deep.getPixel(x, y, px);
    const FlatDeepPixel f = flattenDeepPixel(px, deep.layout, false);
    const size_t o = size_t(y - flat.y0) * flat.width + size_t(x - flat.x0);
    for (auto [v, name] : {std::pair{f.r, "R"}, {f.g, "G"}, {f.b, "B"}, {f.a, "A"}}) worst = std::max(worst, std::abs(v - double(flat.find(name)->f[o])));
  }
  return worst;
}
}  // namespace reshutter::test::retime
