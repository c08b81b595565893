// The accuracy study's instruments (bench/accuracy_common.h): images and their errors, measured
// points, plots and tables, and the moving-square scenes several studies share.
#include "bench/accuracy_common.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <fstream>

#include "bench/bench_util.h"

namespace reshutter::accuracy {

using namespace reshutter::resample;
using reshutter::test::TestMp;
using reshutter::test::TestScene;

std::string gTmp = "/tmp";
bool gQuick = false;

// ---------------------------------------------------------------------------------------------
// Images and errors


Img toImg(const RenderResult& r) {
  Img m;
  m.resize(r.image.width, r.image.height);
  const char* names[4] = {"R", "G", "B", "A"};
  for (int k = 0; k < 4; ++k) {
    const auto& f = test::channel(r, names[k]).f;
    for (size_t i = 0; i < f.size(); ++i) m.c[k][i] = f[i];
  }
  return m;
}

double lum(const Img& m, size_t i) { return 0.2126 * m.c[0][i] + 0.7152 * m.c[1][i] + 0.0722 * m.c[2][i]; }


Err compare(const Img& x, const Img& ref) {
  Err e;
  const size_t n = x.c[0].size();
  double s = 0, sl = 0;
  for (size_t i = 0; i < n; ++i) {
    for (int k = 0; k < 4; ++k) {
      const double d = x.c[k][i] - ref.c[k][i];
      s += d * d, e.max = std::max(e.max, std::abs(d));
    }
    const double dl = lum(x, i) - lum(ref, i);
    sl += dl * dl;
  }
  e.rmse = std::sqrt(s / double(4 * n)), e.lum = std::sqrt(sl / double(n));
  return e;
}

// ---------------------------------------------------------------------------------------------
// Points, studies and output


std::vector<Point> gPoints;

/// Renders `specFor(seed)` for `seeds` seeds; time = best render; errors against `ref`.
Point measure(const std::string& study, const std::string& curve, double knob, const std::function<RenderSpec(uint64_t)>& specFor, const Img& ref, int seeds,
              double extraSeconds) {
  Point p;
  p.study = study, p.curve = curve, p.knob = knob;
  std::vector<Img> imgs;
  double best = 1e30, sumSq = 0, sumMax = 0, sumLum = 0;
  // Every timed render finds the parts decoded (RenderSpec::keepDecoded): the curves time the knob.
  auto keepingParts = [](RenderSpec spec) {
    for (const Source& src : spec.sources) spec.keepDecoded.push_back(src.store.get());
    return spec;
  };
  {  // warm-up (store open, part cache): cheap settings would otherwise time it
    RenderSpec spec = keepingParts(specFor(1));
    if (spec.samplesX * spec.samplesY <= 16) render(spec);
  }
  for (int s = 0; s < seeds; ++s) {
    RenderSpec spec = keepingParts(specFor(uint64_t(s) * 7919 + 1));
    p.spp = spec.samplesX * spec.samplesY;
    RenderResult r;
    for (int rep = 0; rep < (seeds == 1 ? 3 : 1); ++rep) {  // one seed: best of 3 renders
      bench::Stopwatch sw;
      r = render(spec);
      best = std::min(best, sw.seconds());
    }
    imgs.push_back(toImg(r));
    const Err e = compare(imgs.back(), ref);
    sumSq += e.rmse * e.rmse, sumMax += e.max, sumLum += e.lum * e.lum;
  }
  p.seconds = best + extraSeconds;
  p.rmse = std::sqrt(sumSq / seeds), p.max = sumMax / seeds, p.lum = std::sqrt(sumLum / seeds);
  if (seeds > 1) {
    Img mean;
    mean.resize(ref.w, ref.h);
    for (const Img& m : imgs)
      for (int k = 0; k < 4; ++k)
        for (size_t i = 0; i < m.c[k].size(); ++i) mean.c[k][i] += m.c[k][i] / seeds;
    double var = 0;
    for (const Img& m : imgs)
      for (int k = 0; k < 4; ++k)
        for (size_t i = 0; i < m.c[k].size(); ++i) var += (m.c[k][i] - mean.c[k][i]) * (m.c[k][i] - mean.c[k][i]);
    var /= double(seeds - 1) * 4.0 * double(ref.c[0].size());
    const double meanErr = compare(mean, ref).rmse;
    p.noise = std::sqrt(var);
    p.bias = std::sqrt(std::max(0.0, meanErr * meanErr - var / seeds));
  }
  std::fprintf(stderr, "  %-14s %-34s knob %-8g spp %-4d %8.4f s  rmse %.3e  max %.3e  bias %.2e  noise %.2e\n", study.c_str(), curve.c_str(), knob, p.spp,
               p.seconds, p.rmse, p.max, p.bias, p.noise);
  gPoints.push_back(p);
  return p;
}

std::string fmt(double v, const char* f) {
  if (std::isnan(v)) return "–";
  char b[64];
  std::snprintf(b, sizeof b, f, v);
  return b;
}

std::ostringstream gTables;

void markPareto(const std::string& study, bool byBytes) {
  for (Point& p : gPoints) {
    if (p.study != study) continue;
    const double px = byBytes ? p.bytes : p.seconds;
    p.pareto = true;
    for (const Point& q : gPoints) {
      if (q.study != study || &q == &p) continue;
      const double qx = byBytes ? q.bytes : q.seconds;
      if (qx <= px && q.rmse <= p.rmse && (qx < px || q.rmse < p.rmse)) p.pareto = false;
    }
  }
}

/// Writes NAME.dat (one block per curve) and NAME.gp for gnuplot; marks the Pareto front.
void plot(const std::string& outDir, const std::string& study, const std::string& title, bool byBytes, const std::string& yLabel) {
  markPareto(study, byBytes);
  std::vector<std::string> curves;
  for (const Point& p : gPoints)
    if (p.study == study && std::find(curves.begin(), curves.end(), p.curve) == curves.end()) curves.push_back(p.curve);
  std::ofstream dat(outDir + "/" + study + ".dat");
  for (const std::string& c : curves) {
    dat << "# " << c << "\n";
    for (const Point& p : gPoints)
      if (p.study == study && p.curve == c) dat << (byBytes ? p.bytes : p.seconds) << " " << std::max(p.rmse, 1e-9) << " " << p.spp << "\n";
    dat << "\n\n";
  }
  std::vector<const Point*> front;
  for (const Point& p : gPoints)
    if (p.study == study && p.pareto) front.push_back(&p);
  std::sort(front.begin(), front.end(), [&](auto a, auto b) { return (byBytes ? a->bytes : a->seconds) < (byBytes ? b->bytes : b->seconds); });
  dat << "# Pareto front\n";
  for (const Point* p : front) dat << (byBytes ? p->bytes : p->seconds) << " " << std::max(p->rmse, 1e-9) << " " << p->spp << "\n";
  std::ofstream gp(outDir + "/" + study + ".gp");
  gp << "set terminal pngcairo size 640,480 font ',9'\n"
     << "set output '" << outDir << "/" << study << ".png'\n"
     << "set logscale xy\nset grid\nset key below\n"
     << "set title \"" << title << "\"\n"
     << "set xlabel '" << (byBytes ? "store / file bytes" : "wall seconds (best of the seeds)") << "'\n"
     << "set ylabel '" << yLabel << "'\n"
     << "plot ";
  for (size_t i = 0; i < curves.size(); ++i)
    gp << "'" << outDir << "/" << study << ".dat' index " << i << " using 1:2 with linespoints pt " << (i % 12) + 1 << " title \"" << curves[i] << "\", ";
  gp << "'" << outDir << "/" << study << ".dat' index " << curves.size() << " using 1:2 with lines lw 3 lc rgb '#80808080' dt 2 title 'Pareto front', '' index "
     << curves.size() << " using 1:2 with points pt 6 ps 2 lc rgb 'black' notitle\n";
}

/// Every point of a study; `knobName` empty (or "spp", already a column) leaves the knob out.
void table(const std::string& study, const std::string& knobName, bool withBytes, const std::string& bytesName) {
  const bool knob = !knobName.empty() && knobName != "spp";
  gTables << "| curve |" << (knob ? " " + knobName + " |" : "") << " spp | seconds | RMSE | max | luminance RMSE | bias | noise |"
          << (withBytes ? " " + bytesName + " |" : "") << " Pareto |\n|---|" << (knob ? "---|" : "") << "---|---|---|---|---|---|---|"
          << (withBytes ? "---|" : "") << "---|\n";
  for (const Point& p : gPoints) {
    if (p.study != study) continue;
    gTables << "| " << p.curve << " |" << (knob ? " " + fmt(p.knob) + " |" : "") << " " << p.spp << " | " << fmt(p.seconds, "%.4f") << " | "
            << fmt(p.rmse, "%.2e") << " | " << fmt(p.max, "%.2e") << " | " << fmt(p.lum, "%.2e") << " | " << fmt(p.bias, "%.2e") << " | "
            << fmt(p.noise, "%.2e") << " |" << (withBytes ? " " + fmt(p.bytes, "%.0f") + " |" : "") << (p.pareto ? " ★ |" : " |") << "\n";
  }
  gTables << "\n";
}

/// The two time-bound strategies side by side: time at equal error.
void strategyTable(const std::string& study) {
  gTables << "Time at equal error (both strategies make the same image):\n\n| spp | per-stratum s | one bound s | one bound / per-stratum | RMSE |\n"
             "|---|---|---|---|---|\n";
  for (const Point& a : gPoints)
    for (const Point& b : gPoints)
      if (a.study == study && b.study == study && a.spp == b.spp && a.curve[0] == 'p' && b.curve[0] == 'o')
        gTables << "| " << a.spp << " | " << fmt(a.seconds, "%.4f") << " | " << fmt(b.seconds, "%.4f") << " | " << fmt(b.seconds / a.seconds, "%.2f") << " | "
                << fmt(a.rmse, "%.2e") << " |\n";
  gTables << "\n";
}

// ---------------------------------------------------------------------------------------------
// Scenes and references


/// Area of `poly` inside the pixel [x, x+1] × [y, y+1] (Sutherland–Hodgman, then shoelace).
double pixelArea(const Poly& poly, double x, double y) {
  Poly a = poly, b;
  auto clip = [&](auto inside, auto cut) {
    b.clear();
    for (size_t i = 0; i < a.size(); ++i) {
      const glm::dvec2 p = a[i], q = a[(i + 1) % a.size()];
      const bool ip = inside(p), iq = inside(q);
      if (ip) b.push_back(p);
      if (ip != iq) b.push_back(cut(p, q));
    }
    std::swap(a, b);
  };
  auto cx = [](double e) { return [e](glm::dvec2 p, glm::dvec2 q) { return glm::dvec2(e, p.y + (q.y - p.y) * (e - p.x) / (q.x - p.x)); }; };
  auto cy = [](double e) { return [e](glm::dvec2 p, glm::dvec2 q) { return glm::dvec2(p.x + (q.x - p.x) * (e - p.y) / (q.y - p.y), e); }; };
  clip([&](glm::dvec2 p) { return p.x >= x; }, cx(x));
  clip([&](glm::dvec2 p) { return p.x <= x + 1; }, cx(x + 1));
  clip([&](glm::dvec2 p) { return p.y >= y; }, cy(y));
  clip([&](glm::dvec2 p) { return p.y <= y + 1; }, cy(y + 1));
  double s = 0;
  for (size_t i = 0; i < a.size(); ++i) s += a[i].x * a[(i + 1) % a.size()].y - a[(i + 1) % a.size()].x * a[i].y;
  return std::abs(s) / 2;
}

/// Adds the time-averaged coverage (over t ∈ [0, 1], `steps` midpoints) of an opaque polygon
/// of colour `ci` to `ref` (objects must not overlap).
void addSwept(Img& ref, const std::function<Poly(double)>& polyAt, glm::dvec3 ci, int steps) {
  for (int s = 0; s < steps; ++s) {
    const Poly p = polyAt((s + 0.5) / steps);
    double x0 = 1e30, y0 = 1e30, x1 = -1e30, y1 = -1e30;
    for (auto v : p) x0 = std::min(x0, v.x), x1 = std::max(x1, v.x), y0 = std::min(y0, v.y), y1 = std::max(y1, v.y);
    for (int py = std::max(0, int(std::floor(y0))); py <= std::min(ref.h - 1, int(std::floor(y1))); ++py)
      for (int px = std::max(0, int(std::floor(x0))); px <= std::min(ref.w - 1, int(std::floor(x1))); ++px) {
        const double a = pixelArea(p, px, py) / steps;
        const size_t i = size_t(py) * ref.w + px;
        ref.c[0][i] += a * ci.x, ref.c[1][i] += a * ci.y, ref.c[2][i] += a * ci.z, ref.c[3][i] += a;
      }
  }
}

glm::dvec3 colourOf(int i) {
  static const glm::dvec3 palette[] = {{0.9, 0.2, 0.1}, {0.2, 0.8, 0.3}, {0.2, 0.4, 0.95}, {1, 1, 1}, {0.9, 0.8, 0.1}, {0.7, 0.2, 0.8}};
  return palette[i % 6];
}


std::shared_ptr<const store::StoreReader> writeMotion(const MotionScene& ms, int knots, const std::string& name, std::vector<store::AttrCodec> codecs) {
  std::vector<double> times;
  for (int k = 0; k < knots; ++k) times.push_back(knots == 1 ? 0.0 : double(k) / (knots - 1));
  TestScene s = test::makeScene(kW, kH, times);
  for (size_t a = 0; a < codecs.size(); ++a) s.meta.schema.attrs[a].codec = codecs[a];
  for (int cell = 0; cell < 12; ++cell) {
    TestMp mp;
    for (double t : times) {
      if (ms.camCorners) {
        mp.knots.push_back(ms.camCorners(s, cell, t));
      } else {
        const Poly p = ms.corners(cell, t);
        const double z = ms.depth(cell, t);
        mp.knots.push_back({s.cam(p[0].x, p[0].y, z), s.cam(p[1].x, p[1].y, z), s.cam(p[2].x, p[2].y, z), s.cam(p[3].x, p[3].y, z)});
      }
    }
    mp.ci = glm::vec3(colourOf(cell));
    mp.gridId = uint32_t(cell) + 1;
    s.mps.push_back(mp);
  }
  return test::writeScene(s, gTmp + "/acc_" + name + ".mps");
}

Img bruteReference(const std::function<Poly(int, double)>& corners) {
  Img ref;
  ref.resize(kW, kH);
  for (int cell = 0; cell < 12; ++cell)
    addSwept(
        ref, [&](double t) { return corners(cell, t); }, colourOf(cell), gQuick ? 512 : 2048);
  return ref;
}

glm::dvec2 cellCentre(int cell) { return {64.0 * (cell % 4) + 32.0, 64.0 * (cell / 4) + 32.0}; }

RenderSpec specOf(std::shared_ptr<const store::StoreReader> r, int nx, uint64_t seed, const std::string& filter) {
  RenderSpec spec = test::specFor(std::move(r), 0.0, 1.0, nx, nx, seed);
  spec.filter = FilterSpec::parse(filter, "accuracy_study");
  return spec;
}

std::vector<int> sppSides(std::vector<int> sides) {
  if (gQuick) sides.erase(std::remove_if(sides.begin(), sides.end(), [](int s) { return s > 8; }), sides.end());
  return sides;
}

/// Per-stratum time bounds against one bound over the shutter, at 1–256 spp (the single bound
/// only up to `oneBoundMaxSide`² spp): same image, different cost.
void sweepTimeBounds(const std::string& study, std::shared_ptr<const store::StoreReader> store, const Img& ref, int seeds, int oneBoundMaxSide) {
  for (bool per : {true, false})
    for (int n : sppSides({1, 2, 4, 8, 16}))
      if (per || n <= oneBoundMaxSide)
        measure(
            study, per ? "per-stratum time bounds" : "one bound over the shutter", n * n,
            [&](uint64_t seed) {
              RenderSpec spec = specOf(store, n, seed);
              spec.raster.perStratumBounds = per;
              return spec;
            },
            ref, seeds);
}

const Point* find(const std::string& study, const std::string& curvePrefix, int spp, double knob) {
  const Point* best = nullptr;
  for (const Point& p : gPoints)
    if (p.study == study && p.curve.rfind(curvePrefix, 0) == 0 && (spp < 0 || p.spp == spp) && (std::isnan(knob) || p.knob == knob) &&
        (!best || p.spp > best->spp))
      best = &p;
  return best;
}


// ---------------------------------------------------------------------------------------------
// The demo scene

double shadeStore(const shade::FrameScene& scene, const shade::ShadeOptions& o, const std::string& path, uint64_t* mps) {
  double best = 1e30;
  for (int r = 0; r < 3; ++r) {
    bench::Stopwatch sw;
    auto res = shade::shadeToStore(scene, o, path);
    best = std::min(best, sw.seconds());
    if (mps) *mps = res.shade.micropolygons;
  }
  return best;
}

RenderSpec demoSpec(std::vector<std::shared_ptr<const store::StoreReader>> stores, ShutterModel shutter, int n, uint64_t seed) {
  RenderSpec spec;
  for (auto& s : stores) spec.sources.push_back(Source{s, s->meta().frame});
  spec.shutter = std::move(shutter);
  spec.samplesX = spec.samplesY = n;
  spec.seed = seed;
  spec.filter = FilterSpec::parse("gaussian:2", "accuracy_study");
  spec.progress = false;
  return spec;
}

}  // namespace reshutter::accuracy
