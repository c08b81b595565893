// The accuracy study's depth-of-field curve: samples per pixel against error and time for the
// 4 × 3 grid of squares at depths from 6 to 30 seen through a lens focused at 10 (circles of
// confusion up to 8 px), still and moving; the reference integrates each square's exact
// time-averaged coverage (analyticCoverage) over the lens disk.
#include <cmath>
#include <cstdio>
#include <numbers>

#include "bench/accuracy_common.h"
#include "store/model.h"

namespace reshutter::accuracy {

using namespace ::reshutter::resample;

namespace {

struct LensSquare {
  double x, y, size, vx, vy, z;
};

LensSquare lensSquare(int cell, bool moving) {
  const double size = 14 + 2 * (cell % 4), z = 6 + 24 * double((cell * 7) % 12) / 11.0, ang = 0.9 * cell;
  const glm::dvec2 v = moving ? glm::dvec2(12 * std::cos(ang), 12 * std::sin(ang)) : glm::dvec2(0.0);
  const glm::dvec2 o = cellCentre(cell) - v / 2.0 - glm::dvec2(size / 2);
  return {o.x, o.y, size, v.x, v.y, z};
}

}  // namespace

void studyLens(const std::string& out) {
  std::fprintf(stderr, "lens: defocused squares, still and moving, integrated over the lens\n");
  const double focus = 10, cocAtEnds = 8;  // px at depths 6 and 30 (|1/10 - 1/z| = 1/15 at both)
  for (bool moving : {false, true}) {
    MotionScene ms;
    ms.corners = [&](int cell, double t) {
      const LensSquare q = lensSquare(cell, moving);
      const double x = q.x + q.vx * t, y = q.y + q.vy * t;
      return Poly{{x, y}, {x + q.size, y}, {x + q.size, y + q.size}, {x, y + q.size}};
    };
    ms.depth = [&](int cell, double) { return lensSquare(cell, moving).z; };
    auto store = writeMotion(ms, 2, moving ? "lens_moving" : "lens_still");
    const double ax = store::Projector(store->meta().cameras[0]).ax;
    const double radius = cocAtEnds / (ax * (1.0 / 6 - 1.0 / focus));  // the aperture (camera space)
    // The reference: per pixel near each square, its coverage averaged over the lens disk
    // (equal-area rings × angles, midpoints) of the square displaced by that lens point.
    Img ref;
    ref.resize(kW, kH);
    const int rings = gQuick ? 12 : 32, angles = gQuick ? 24 : 64;
    for (int cell = 0; cell < 12; ++cell) {
      const LensSquare q = lensSquare(cell, moving);
      const double coc = ax * radius * std::abs(1 / focus - 1 / q.z);
      const glm::dvec3 c = colourOf(cell);
      for (int py = std::max(0, int(q.y - coc - 2 - std::abs(q.vy))); py <= std::min(kH - 1, int(q.y + q.size + std::abs(q.vy) + coc + 2)); ++py)
        for (int px = std::max(0, int(q.x - coc - 2 - std::abs(q.vx))); px <= std::min(kW - 1, int(q.x + q.size + std::abs(q.vx) + coc + 2)); ++px) {
          double a = 0;
          for (int ir = 0; ir < rings; ++ir)
            for (int ia = 0; ia < angles; ++ia) {
              const double rho = coc * std::sqrt((ir + 0.5) / rings), phi = 2 * std::numbers::pi * (ia + 0.5) / angles;
              a += test::analyticCoverage(px, py, q.x + rho * std::cos(phi), q.y + rho * std::sin(phi), q.size, q.size, q.vx, q.vy, 0, 1);
            }
          a /= rings * angles;
          const size_t i = size_t(py) * kW + px;
          ref.c[0][i] += a * c.x, ref.c[1][i] += a * c.y, ref.c[2][i] += a * c.z, ref.c[3][i] += a;
        }
    }
    for (int n : sppSides({1, 2, 4, 8, 16}))
      measure(
          "lens", moving ? "moving squares (12 px)" : "still squares", n * n,
          [&](uint64_t seed) {
            RenderSpec spec = specOf(store, n, seed);
            spec.lens.fstop = 1 / (2 * radius), spec.lens.focalLength = 1, spec.lens.focalDistance = focus;
            return spec;
          },
          ref, 3);
  }
  plot(out, "lens", "Depth of field: samples per pixel (focus 10, circles of confusion up to 8 px)");
  gTables << "### Depth of field\n\nScene: 12 opaque squares (14–20 px) at depths 6 to 30 through a lens focused at 10 (circles of confusion up to "
             "8 px), still and moving 12 px over the shutter, "
          << kW << "×" << kH
          << ", box filter 1×1; reference: each square's exact time-averaged coverage (`analyticCoverage`) averaged over the lens disk "
             "(equal-area rings × angles). 3 seeds per point. Samples are stratified jointly in position, time and lens (5D).\n\n";
  table("lens", "spp");
}

std::string lensHeadline() {
  const Point *a = find("lens", "still", 16), *b = find("lens", "still", 64), *c = find("lens", "moving", 16), *d = find("lens", "moving", 256);
  if (!a || !b || !c || !d) return "";
  char line[512];
  std::snprintf(line, sizeof line,
                "- **Depth of field** (squares through a lens, circles of confusion up to 8 px): still, 16 spp %.3f s with RMSE %.1e, 64 spp %.3f s with "
                "%.1e (noise only: bias %.1e); moving and defocused, 16 spp %.1e, 256 spp %.1e.\n",
                a->seconds, a->rmse, b->seconds, b->rmse, b->bias, c->rmse, d->rmse);
  return line;
}

}  // namespace reshutter::accuracy
