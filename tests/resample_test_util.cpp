#include "tests/resample_test_util.h"

#include <algorithm>
#include <cmath>

#include <gtest/gtest.h>

#include "common/random.h"
#include "resample/deep.h"

namespace reshutter::test {

using namespace reshutter::store;
using namespace reshutter::resample;

glm::dvec3 TestScene::cam(double rx, double ry, double z) const { return Projector(meta.cameras[0]).unproject({rx, ry}, z); }

std::array<glm::dvec3, 4> TestScene::rect(double x0, double y0, double x1, double y1, double z) const {
  return {cam(x0, y0, z), cam(x1, y0, z), cam(x1, y1, z), cam(x0, y1, z)};
}

TestScene makeScene(int width, int height, std::vector<double> knotTimes) {
  TestScene s;
  s.meta.frame = 1;
  s.meta.cameras[0].width = width;
  s.meta.cameras[0].height = height;
  s.meta.cameras[0].fovDegrees = 50;
  s.meta.cameras[0].nearClip = 0.5;
  s.meta.tileSize = 16;
  s.meta.schema.attrs = {{"Ci", AttrType::Color, AttrRate::Vertex, AttrCodec::Lossless},
                         {"Oi", AttrType::Color, AttrRate::Vertex, AttrCodec::Lossless},
                         {"N", AttrType::Normal, AttrRate::Vertex, AttrCodec::Lossless}};
  s.meta.provenance = "resample test";
  s.knotTimes = std::move(knotTimes);
  return s;
}

TestScene randomQuadScene(uint64_t seed, bool someStill) {
  TestScene s = makeScene(40, 28, {0.0, 0.4, 1.0});
  Rng rng(seed);
  for (int i = 0; i < 40; ++i) {
    TestMp mp;
    const double cx = rng.uniform(-5, 45), cy = rng.uniform(-5, 33), size = rng.uniform(1, 9);
    glm::dvec2 vel(rng.uniform(-10, 10), rng.uniform(-10, 10));
    const double z = rng.uniform(3, 30), dz = rng.uniform(-2, 2);
    for (int k = 0; k < 3; ++k) {
      const double t = s.knotTimes[size_t(k)];
      std::array<glm::dvec3, 4> c;
      for (int j = 0; j < 4; ++j) {
        const double ang = j * M_PI / 2 + rng.uniform(-0.3, 0.3) + t * 0.5;
        c[size_t(j)] = s.cam(cx + vel.x * t + size * std::cos(ang), cy + vel.y * t + size * std::sin(ang), z + dz * t + rng.uniform(-0.5, 0.5));
      }
      mp.knots.push_back(c);
    }
    if (someStill && i % 5 == 0) mp.knots.assign(3, mp.knots[0]);
    mp.triangle = i % 4 == 0;
    mp.ci = {float(rng.uniform()), float(rng.uniform()), float(rng.uniform())};
    if (i % 3 == 0) mp.oi = {0.3f, 0.5f, 0.7f}, mp.ci *= 0.3f;
    if (i % 7 == 0) mp.flags = store::kMatte;
    mp.flags |= store::kTwoSided;
    s.mps.push_back(mp);
  }
  return s;
}

std::shared_ptr<const StoreReader> writeScene(const TestScene& scene, const std::string& path, bool asOneGrid) {
  {
    StoreWriter w(path, scene.meta);
    const uint32_t schedule = w.addSchedule(scene.knotTimes);
    const size_t K = scene.knotTimes.size();
    // Each micropolygon's own vertices, appended to the grid being built.
    std::vector<std::vector<glm::vec3>> pos(K);
    std::vector<uint32_t> corners;
    std::vector<float> ci, oi, n;
    auto flush = [&](const TestMp& mp, uint32_t gridId) {
      std::vector<glm::vec3> knotMajor;
      for (const auto& p : pos) knotMajor.insert(knotMajor.end(), p.begin(), p.end());
      GridInput g;
      g.schedule = schedule;
      g.numVertices = uint32_t(pos[0].size());
      g.positions = knotMajor;
      g.corners = corners;
      g.objectId = mp.objectId;
      g.gridId = gridId;
      g.flags = mp.flags;
      g.attrs = {AttrValues{ci, {}}, AttrValues{oi, {}}, AttrValues{n, {}}};
      w.addGrid(g);
      for (auto& p : pos) p.clear();
      corners.clear(), ci.clear(), oi.clear(), n.clear();
    };
    for (size_t i = 0; i < scene.mps.size(); ++i) {
      const TestMp& mp = scene.mps[i];
      EXPECT_EQ(mp.knots.size(), K);
      const int nc = mp.triangle ? 3 : 4;
      const uint32_t v0 = uint32_t(pos[0].size());
      for (size_t k = 0; k < K; ++k)
        for (int j = 0; j < nc; ++j) pos[k].push_back(glm::vec3(mp.knots[k][size_t(j)]));
      corners.insert(corners.end(), {v0, v0 + 1, v0 + 2, mp.triangle ? kNoCorner : v0 + 3});
      for (int j = 0; j < nc; ++j) {
        ci.insert(ci.end(), {mp.ci.x, mp.ci.y, mp.ci.z});
        oi.insert(oi.end(), {mp.oi.x, mp.oi.y, mp.oi.z});
        n.insert(n.end(), {0.f, 0.f, -1.f});
      }
      if (!asOneGrid) flush(mp, mp.gridId ? mp.gridId : uint32_t(i));
    }
    if (asOneGrid && !scene.mps.empty()) flush(scene.mps.front(), 0);
    w.close();
  }
  return std::make_shared<const StoreReader>(path);
}

RenderSpec specFor(std::shared_ptr<const StoreReader> reader, double open, double close, int nx, int ny, uint64_t seed) {
  RenderSpec spec;
  const double F = double(reader->meta().frame);
  spec.sources = {Source{reader, reader->meta().frame}};
  spec.shutter = ShutterModel::progressive(F + open, F + close);
  spec.samplesX = nx, spec.samplesY = ny;
  spec.seed = seed;
  spec.filter = FilterSpec::parse("box:1", "test");
  spec.progress = false;
  return spec;
}

namespace {

glm::dvec3 positionAt(const TestMp& mp, const std::vector<double>& knots, int corner, double tau) {
  const size_t K = knots.size();
  if (K == 1 || tau <= knots[0]) return mp.knots[0][size_t(corner)];
  if (tau >= knots[K - 1]) return mp.knots[K - 1][size_t(corner)];
  size_t k = 0;
  while (k + 2 < K && knots[k + 1] <= tau) ++k;
  const double f = (tau - knots[k]) / (knots[k + 1] - knots[k]);
  return glm::mix(mp.knots[k][size_t(corner)], mp.knots[k + 1][size_t(corner)], f);
}

// Ray from the eye along d = (dx, dy, 1) against triangle (a, b, c): depth of the hit or NaN.
double hitTriangle(const glm::dvec3& d, const glm::dvec3& a, const glm::dvec3& b, const glm::dvec3& c) {
  const double e0 = glm::dot(d, glm::cross(a, b)), e1 = glm::dot(d, glm::cross(b, c)), e2 = glm::dot(d, glm::cross(c, a));
  const bool pos = e0 >= 0 && e1 >= 0 && e2 >= 0, neg = e0 <= 0 && e1 <= 0 && e2 <= 0;
  if (!(pos || neg) || (e0 == 0 && e1 == 0 && e2 == 0)) return NAN;
  const glm::dvec3 n = glm::cross(b - a, c - a);
  const double nd = glm::dot(n, d);
  if (nd == 0) return NAN;
  return glm::dot(n, a) / nd;
}

}  // namespace

SampleReference rayCastSamples(const TestScene& scene, const RenderSpec& spec, int imageHeight, int x0, int y0, int W, int H) {
  const Camera& camera = scene.meta.cameras[0];
  Projector proj(camera);
  SamplePattern pattern(spec.samplesX, spec.samplesY, spec.seed);
  const int N = pattern.spp();
  ShutterModel shutter = spec.shutter;
  RollingShutter rolling = shutter.rolling();
  rolling.height = imageHeight;
  shutter.setRolling(rolling);
  const double tBase = std::floor(shutter.earliest());
  const double F = double(scene.meta.frame);
  SampleReference ref;
  ref.x0 = x0, ref.y0 = y0, ref.width = W, ref.height = H, ref.spp = N;
  ref.r.assign(size_t(W) * H * N, 0), ref.g = ref.r, ref.b = ref.r, ref.a = ref.r;
  std::vector<uint16_t> stratumOf(static_cast<size_t>(N)), lensOf(static_cast<size_t>(N));
  std::vector<float> u(static_cast<size_t>(N));
  std::vector<glm::vec2> disk(static_cast<size_t>(N));
  // A thin lens: each sample's ray leaves the lens at its own point L and passes through the point
  // of the focal plane (z = d) that the pinhole ray through its raster position meets.
  const store::Lens lens = camera.projection == Projection::Perspective ? renderLens(camera, spec.lens) : store::Lens{};
  const double R = lens.radius(), d = lens.focalDistance;
  const int timeBlocks = R > 0 ? lensTimeBlocks(spec) : 1;  // the render's pairing of lens and time strata
  struct Hit {
    double z;
    size_t mp;
  };
  std::vector<Hit> hits;
  for (int py = y0; py < y0 + H; ++py)
    for (int px = x0; px < x0 + W; ++px) {
      const int pat = pattern.patternOf(px, py);
      pattern.times(px, py, stratumOf.data(), u.data());
      if (R > 0) pattern.lensPlanes(px, py, stratumOf.data(), timeBlocks, lensOf.data(), disk.data());
      const int g = shutter.groupOfRow(py);
      for (int i = 0; i < N; ++i) {
        const glm::vec2 o = pattern.offset(pat, i);
        const float x = float(px) + o.x, y = float(py) + o.y;
        const double t = tBase + double(float(shutter.time(g, y, u[size_t(i)]) - tBase));
        const glm::dvec3 pinhole((double(x) - proj.bx) / proj.ax, (double(y) - proj.by) / proj.ay, 1.0);
        // The ray from lens point L (the eye, for a pinhole) with direction z = 1; corners are
        // taken relative to L, so a hit's ray parameter is its camera depth.
        const glm::dvec3 L = R > 0 ? glm::dvec3(R * disk[size_t(i)].x, R * disk[size_t(i)].y, 0.0) : glm::dvec3(0.0);
        const glm::dvec3 dir = R > 0 ? (pinhole * d - L) / d : pinhole;
        hits.clear();
        for (size_t m = 0; m < scene.mps.size(); ++m) {
          const TestMp& mp = scene.mps[m];
          glm::dvec3 c[4];
          for (int j = 0; j < (mp.triangle ? 3 : 4); ++j) c[j] = positionAt(mp, scene.knotTimes, j, t - F) - L;
          double z = hitTriangle(dir, c[0], c[1], c[2]);
          if (!(z >= camera.nearClip && z <= camera.farClip) && !mp.triangle) z = hitTriangle(dir, c[0], c[2], c[3]);
          if (z >= camera.nearClip && z <= camera.farClip) hits.push_back({z, m});
        }
        std::stable_sort(hits.begin(), hits.end(), [](const Hit& a, const Hit& b) { return a.z < b.z; });
        double T[3] = {1, 1, 1}, C[3] = {0, 0, 0}, A[3] = {0, 0, 0};
        for (const Hit& h : hits) {
          const TestMp& mp = scene.mps[h.mp];
          const double ci[3] = {mp.ci.x, mp.ci.y, mp.ci.z}, oi[3] = {mp.oi.x, mp.oi.y, mp.oi.z};
          const bool matte = mp.flags & kMatte;
          for (int k = 0; k < 3; ++k) {
            if (!matte) C[k] += T[k] * ci[k], A[k] += T[k] * oi[k];
            T[k] *= 1 - oi[k];
          }
          if (T[0] <= 1 - spec.raster.opacityThreshold && T[1] <= 1 - spec.raster.opacityThreshold && T[2] <= 1 - spec.raster.opacityThreshold) break;
        }
        const size_t s = ref.at(px, py, i);
        ref.r[s] = C[0], ref.g[s] = C[1], ref.b[s] = C[2], ref.a[s] = (A[0] + A[1] + A[2]) / 3;
      }
    }
  return ref;
}

Reference rayCast(const TestScene& scene, const RenderSpec& spec, int W, int H) {
  const SampleReference s = rayCastSamples(scene, spec, H, 0, 0, W, H);
  const int N = s.spp;
  Reference ref;
  ref.r.assign(size_t(W) * H, 0), ref.g = ref.r, ref.b = ref.r, ref.a = ref.r;
  for (int py = 0; py < H; ++py)
    for (int px = 0; px < W; ++px) {
      double acc[4] = {0, 0, 0, 0};
      for (int i = 0; i < N; ++i) {
        const size_t k = s.at(px, py, i);
        acc[0] += s.r[k], acc[1] += s.g[k], acc[2] += s.b[k], acc[3] += s.a[k];
      }
      const size_t p = size_t(py) * W + size_t(px);
      ref.r[p] = acc[0] / N, ref.g[p] = acc[1] / N, ref.b[p] = acc[2] / N, ref.a[p] = acc[3] / N;
    }
  return ref;
}

double analyticCoverage(int px, int py, double x0, double y0, double w, double h, double vx, double vy, double a, double b,
                        const std::vector<double>& shapeTimes, const std::vector<double>& shapeWeights) {
  auto overlap = [](double lo, double hi, double p) { return std::max(0.0, std::min(hi, p + 1) - std::max(lo, p)); };
  auto area = [&](double t) { return overlap(x0 + vx * t, x0 + w + vx * t, px) * overlap(y0 + vy * t, y0 + h + vy * t, py); };
  auto weight = [&](double t) {
    if (shapeTimes.empty()) return 1.0;
    if (t <= shapeTimes.front()) return shapeWeights.front();
    for (size_t i = 1; i < shapeTimes.size(); ++i)
      if (t <= shapeTimes[i])
        return shapeWeights[i - 1] + (t - shapeTimes[i - 1]) / (shapeTimes[i] - shapeTimes[i - 1]) * (shapeWeights[i] - shapeWeights[i - 1]);
    return shapeWeights.back();
  };
  if (a == b) return area(a);
  std::vector<double> ts{a, b};
  auto crossing = [&](double start, double v, double edge) {
    if (v != 0) {
      const double t = (edge - start) / v;
      if (t > a && t < b) ts.push_back(t);
    }
  };
  for (double e : {double(px), double(px + 1)}) crossing(x0, vx, e), crossing(x0 + w, vx, e);
  for (double e : {double(py), double(py + 1)}) crossing(y0, vy, e), crossing(y0 + h, vy, e);
  for (double t : shapeTimes)
    if (t > a && t < b) ts.push_back(t);
  std::sort(ts.begin(), ts.end());
  double sum = 0, norm = 0;
  for (size_t i = 0; i + 1 < ts.size(); ++i) {
    const double t0 = ts[i], t1 = ts[i + 1], tm = (t0 + t1) / 2;
    // area·weight is at most cubic on a piece: Simpson is exact.
    sum += (t1 - t0) / 6 * (area(t0) * weight(t0) + 4 * area(tm) * weight(tm) + area(t1) * weight(t1));
    norm += (t1 - t0) / 6 * (weight(t0) + 4 * weight(tm) + weight(t1));
  }
  return sum / norm;
}

void expectRayCasterAgrees(const TestScene& s, const RenderSpec& spec, const RenderResult& r, int width, int height, const std::string& what) {
  const Reference ref = rayCast(s, spec, width, height);
  double diff = 0, maxDiff = 0;
  for (size_t p = 0; p < ref.a.size(); ++p)
    for (auto [name, vals] : {std::pair{"R", &ref.r}, std::pair{"G", &ref.g}, std::pair{"B", &ref.b}, std::pair{"A", &ref.a}}) {
      const double d = std::abs(channel(r, name).f[p] - (*vals)[p]);
      diff += d, maxDiff = std::max(maxDiff, d);
    }
  EXPECT_LT(diff / double(ref.a.size()), 2e-3) << what;
  EXPECT_LE(maxDiff, 2.0 / 16 + 1e-5) << what;
}

const ImageChannel& channel(const RenderResult& r, const std::string& name) {
  const ImageChannel* c = r.image.find(name);
  if (!c) throw std::runtime_error("no channel " + name);
  return *c;
}

std::pair<RenderResult, RenderResult> renderCulledAndNot(RenderSpec spec) {
  spec.raster.occlusionCulling = true;
  RenderResult culled = render(spec);
  spec.raster.occlusionCulling = false;
  return {std::move(culled), render(spec)};
}

void expectSameOutputs(const RenderResult& got, const RenderResult& want, const std::string& what) {
  ASSERT_EQ(got.image.channels.size(), want.image.channels.size()) << what;
  for (size_t i = 0; i < want.image.channels.size(); ++i) {
    EXPECT_EQ(got.image.channels[i].f, want.image.channels[i].f) << what << " " << want.image.channels[i].name;
    EXPECT_EQ(got.image.channels[i].u, want.image.channels[i].u) << what << " " << want.image.channels[i].name;
  }
  ASSERT_EQ(got.deep.totalSamples(), want.deep.totalSamples()) << what;
  DeepPixel a, b;
  for (int y = want.deep.y0; y < want.deep.y0 + want.deep.height; ++y)
    for (int x = want.deep.x0; x < want.deep.x0 + want.deep.width; ++x) {
      got.deep.getPixel(x, y, a), want.deep.getPixel(x, y, b);
      ASSERT_EQ(a.f, b.f) << what << " deep pixel " << x << " " << y;
      ASSERT_EQ(a.u, b.u) << what << " deep pixel " << x << " " << y;
    }
}


double diskBelow(double a) {
  if (a <= -1) return 0;
  if (a >= 1) return 1;
  return 1 - (std::acos(a) - a * std::sqrt(1 - a * a)) / M_PI;
}

resample::RenderSpec::LensOverride lensFor(const TestScene& s, double r, double z, double d) {
  const double ax = store::Projector(s.meta.cameras[0]).ax;
  const double radius = r / (ax * std::abs(1 / d - 1 / z));
  resample::RenderSpec::LensOverride o;
  o.focalLength = 1, o.fstop = 1 / (2 * radius), o.focalDistance = d;
  return o;
}

}  // namespace reshutter::test
