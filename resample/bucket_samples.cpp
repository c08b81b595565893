#include "resample/bucket_samples.h"

#include <algorithm>
#include <type_traits>

#if defined(__SSE2__)
#include <emmintrin.h>
#endif

namespace reshutter::resample {

void floatRange(const float* v, size_t n, float& lo, float& hi) {
  lo = INFINITY, hi = -INFINITY;
  size_t i = 0;
#if defined(__SSE2__)
  if (n >= 4) {
    __m128 l = _mm_loadu_ps(v), h = l;
    for (i = 4; i + 4 <= n; i += 4) {
      const __m128 x = _mm_loadu_ps(v + i);
      l = _mm_min_ps(l, x), h = _mm_max_ps(h, x);
    }
    alignas(16) float ls[4], hs[4];
    _mm_store_ps(ls, l), _mm_store_ps(hs, h);
    for (int k = 0; k < 4; ++k) lo = std::min(lo, ls[k]), hi = std::max(hi, hs[k]);
  }
#endif
  for (; i < n; ++i) lo = std::min(lo, v[i]), hi = std::max(hi, v[i]);
}

BucketSamples::BucketSamples(const SamplePattern& p, const ShutterModel& s, int lensTimeBlocks, bool drawTimes)
    : pattern(p),
      shutter(s),
      N(p.spp()),
      lensPlanes(lensTimeBlocks >= 1),
      lensTimeBlocks(std::max(lensTimeBlocks, 1)),
      drawTimes(drawTimes || lensTimeBlocks > 1),  // time blocks pair lens points with the time strata
      pixelMajor(pixelMajorFor(this->drawTimes, lensPlanes)),
      tBase(std::floor(s.earliest())) {}

void BucketSamples::prepare(int rx0, int ry0, int rw, int rh) {
  x0 = rx0, y0 = ry0, w = rw, h = rh, P = w * h;
  constexpr size_t kLine = 64 / sizeof(float);
  PS = (size_t(P) + kLine - 1) / kLine * kLine;
  if ((PS / kLine) % 2 == 0) PS += kLine;
  if (pixelMajor) PS = size_t(P);  // no planes to keep apart: N P slots
  const size_t slots = PS * N;
  sampleSlots = slots;
  // The vector kernels read up to 7 floats past a row's end.
  sx.resize(slots + kPad), sy.resize(slots + kPad), st.resize(slots + kPad);
  idxOf.resize(size_t(P) * N);
  rowGroup.resize(size_t(h));
  const int G = int(shutter.groups().size());
  groupPresent.assign(size_t(G), 0);
  for (int r = 0; r < h; ++r) {
    rowGroup[size_t(r)] = uint8_t(shutter.groupOfRow(y0 + r));
    groupPresent[rowGroup[size_t(r)]] = 1;
  }
  multiGroup = G > 1;
  rowParity = G == 2 && h > 0 ? rowGroup[0] : -1;
  for (int r = 0; r < h && rowParity >= 0; ++r)
    if (rowGroup[size_t(r)] != ((rowParity + r) & 1)) rowParity = -1;
  std::vector<uint16_t> stratumOf(static_cast<size_t>(N)), lensOf(static_cast<size_t>(N));
  std::vector<float> u(static_cast<size_t>(N));
  std::vector<glm::vec2> disk(static_cast<size_t>(N));
  if (lensPlanes) {
    lx.resize(slots + kPad), ly.resize(slots + kPad);
  }
  tMin = INFINITY, tMax = -INFINITY;
  // Time range of each stratum over this region's rows (rolling shutter widens it), widened to
  // the samples' stored times: a time rounded to float may leave its stratum's exact range, and
  // a bound that missed it would drop the hit. The widening is taken in the sample loop below.
  stratumLo.assign(size_t(G) * N, 0.0), stratumHi.assign(size_t(G) * N, 0.0);
  for (int g = 0; g < G; ++g)
    for (int s = 0; s < N; ++s) {
      double lo, hi;
      // A lens plane's samples come from its time block (every time stratum, with one block).
      const int perBlock = N / lensTimeBlocks, block = s / perBlock;
      shutter.timeRange(g, double(y0), double(y0 + h), lensPlanes ? double(block) / lensTimeBlocks : double(s) / N,
                        lensPlanes ? double(block + 1) / lensTimeBlocks : double(s + 1) / N, lo, hi);
      stratumLo[size_t(g) * N + s] = lo;
      stratumHi[size_t(g) * N + s] = hi;
    }
  // Without drawn times: planes in sample order, and one time per row, the middle of its interval.
  if (!drawTimes)
    for (int i = 0; i < N; ++i) stratumOf[size_t(i)] = uint16_t(i);
  if (pixelMajor) {
    // Each pixel's samples side by side, in sample order: slot p N + i, so idxOf is the identity
    // and each pixel's samples are written in one run.
    std::vector<int> rowPattern(static_cast<size_t>(w));
    for (int py = 0; py < h; ++py) {
      const int gy = y0 + py;
      const float mid = float(shutter.time(rowGroup[size_t(py)], double(gy) + 0.5, 0.5) - tBase);
      for (int px = 0; px < w; ++px) rowPattern[size_t(px)] = pattern.patternOf(x0 + px, gy);
      const size_t rowAt = size_t(py) * size_t(w) * size_t(N);
      float* __restrict xs = &sx[rowAt];
      float* __restrict ys = &sy[rowAt];
      float* __restrict ts = &st[rowAt];
      uint32_t* __restrict slots = &idxOf[rowAt];
      for (int px = 0; px < w; ++px) {
        const float fx = float(x0 + px), fy = float(gy);
        const float* o = &pattern.offsets(rowPattern[size_t(px)])->x;  // x, y of sample 0, 1, ...
        const size_t first = size_t(px) * size_t(N);
        int i = 0;
#if defined(__SSE2__)
        // Four samples at a time: the offsets' x and y split by two shuffles (the same sums).
        const __m128 fx4 = _mm_set1_ps(fx), fy4 = _mm_set1_ps(fy), mid4 = _mm_set1_ps(mid);
        const __m128i step = _mm_set1_epi32(4);
        __m128i slot4 = _mm_add_epi32(_mm_set1_epi32(int(uint32_t(rowAt + first))), _mm_setr_epi32(0, 1, 2, 3));
        for (; i + 4 <= N; i += 4, slot4 = _mm_add_epi32(slot4, step)) {
          const __m128 a = _mm_loadu_ps(o + 2 * i), b = _mm_loadu_ps(o + 2 * i + 4);
          const size_t at = first + size_t(i);
          _mm_storeu_ps(xs + at, _mm_add_ps(fx4, _mm_shuffle_ps(a, b, _MM_SHUFFLE(2, 0, 2, 0))));
          _mm_storeu_ps(ys + at, _mm_add_ps(fy4, _mm_shuffle_ps(a, b, _MM_SHUFFLE(3, 1, 3, 1))));
          _mm_storeu_ps(ts + at, mid4);
          _mm_storeu_si128(reinterpret_cast<__m128i*>(slots + at), slot4);
        }
#endif
        for (; i < N; ++i) {
          const size_t at = first + size_t(i);
          xs[at] = fx + o[2 * i], ys[at] = fy + o[2 * i + 1], ts[at] = mid;
          slots[at] = uint32_t(rowAt + at);
        }
      }
    }
  }
  for (int py = 0; py < h && (drawTimes || lensPlanes); ++py) {
    const int g = rowGroup[size_t(py)];
    const float mid = drawTimes ? 0.f : float(shutter.time(g, double(y0 + py) + 0.5, 0.5) - tBase);
    for (int px = 0; px < w; ++px) {
      const int p = py * w + px, gx = x0 + px, gy = y0 + py;
      const int pat = pattern.patternOf(gx, gy);
      if (drawTimes) pattern.times(gx, gy, stratumOf.data(), u.data());
      if (lensPlanes) pattern.lensPlanes(gx, gy, stratumOf.data(), lensTimeBlocks, lensOf.data(), disk.data());
      // A global box shutter (the usual case): time() is open + u * length for every sample,
      // the same sum, without its per-sample test.
      const ShutterGroup& group = shutter.groups()[size_t(g)];
      const bool boxTimes = drawTimes && shutter.rolling().duration == 0.0 && group.shape.isBox();
      const double open = group.open, length = group.length();
      // The pixel's choices as compile-time flags, so that the sample loop tests nothing per
      // sample (it had: half its instructions, in the usual moving render).
      auto writeSamples = [&](auto lens, auto box) {
        constexpr bool kLens = decltype(lens)::value, kBox = decltype(box)::value;
        uint32_t* slots = &idxOf[size_t(p) * N];
        for (int i = 0; i < N; ++i) {
          const size_t plane = kLens ? lensOf[size_t(i)] : stratumOf[size_t(i)];
          const size_t idx = plane * PS + size_t(p);
          if constexpr (kLens) {
            const glm::vec2 l = disk[size_t(i)];
            lx[idx] = l.x, ly[idx] = l.y;
          }
          const glm::vec2 o = pattern.offset(pat, i);
          const float x = float(gx) + o.x, y = float(gy) + o.y;
          sx[idx] = x, sy[idx] = y;
          if constexpr (kBox) st[idx] = float(open + double(u[size_t(i)]) * length - tBase);
          else st[idx] = drawTimes ? float(shutter.time(g, y, u[size_t(i)]) - tBase) : mid;
          slots[i] = uint32_t(idx);
        }
      };
      const std::true_type yes;
      const std::false_type no;
      if (lensPlanes) boxTimes ? writeSamples(yes, yes) : writeSamples(yes, no);
      else boxTimes ? writeSamples(no, yes) : writeSamples(no, no);
    }
  }
  if (lensPlanes) {
    lensRange.resize(size_t(N));
    for (int s = 0; s < N && P > 0; ++s) {
      auto& r = lensRange[size_t(s)];
      floatRange(&lx[size_t(s) * PS], size_t(P), r[0], r[1]), floatRange(&ly[size_t(s) * PS], size_t(P), r[2], r[3]);
    }
  }
  if (!drawTimes) {
    // Nothing reads the times: the region's range is its strata's, unwidened.
    for (int g = 0; g < G; ++g)
      if (groupPresent[size_t(g)])
        for (int s = 0; s < N; ++s) tMin = std::min(tMin, stratumLo[size_t(g) * N + s]), tMax = std::max(tMax, stratumHi[size_t(g) * N + s]);
    return;
  }
  // The widening, per stratum plane and row: tBase + double(st) rises with st (rounding is
  // monotonic), so the extreme stored times are those of the extreme st, found row by row.
  for (int s = 0; s < N; ++s)
    for (int py = 0; py < h; ++py) {
      const float* row = &st[size_t(s) * PS + size_t(py) * w];
      float lo, hi;
      floatRange(row, size_t(w), lo, hi);  // times are finite and not -0
      const double tcLo = tBase + double(lo), tcHi = tBase + double(hi);
      const size_t gs = size_t(rowGroup[size_t(py)]) * N + size_t(s);
      stratumLo[gs] = std::min(stratumLo[gs], tcLo), stratumHi[gs] = std::max(stratumHi[gs], tcHi);
      tMin = std::min(tMin, tcLo), tMax = std::max(tMax, tcHi);
    }
}

bool BucketSamples::pointsMissRegion(const float* xs, const float* ys, size_t n, float scale) const {
  float bx0 = INFINITY, by0 = INFINITY, bx1 = -INFINITY, by1 = -INFINITY;
  bool nan = false;
  size_t i = 0;
#if defined(__SSE2__)
  // Four at a time (the compiler will not vectorise a float min without -ffast-math). A NaN
  // anywhere answers false whatever the bounds, so the lanes' order of comparison cannot matter.
  __m128 lo_x = _mm_set1_ps(INFINITY), lo_y = lo_x, hi_x = _mm_set1_ps(-INFINITY), hi_y = hi_x, unordered = _mm_setzero_ps();
  for (; i + 4 <= n; i += 4) {
    const __m128 x = _mm_loadu_ps(xs + i), y = _mm_loadu_ps(ys + i);
    unordered = _mm_or_ps(unordered, _mm_cmpunord_ps(x, x));
    lo_x = _mm_min_ps(x, lo_x), hi_x = _mm_max_ps(x, hi_x), lo_y = _mm_min_ps(y, lo_y), hi_y = _mm_max_ps(y, hi_y);
  }
  nan = _mm_movemask_ps(unordered) != 0;
  alignas(16) float l[2][4], h[2][4];
  _mm_store_ps(l[0], lo_x), _mm_store_ps(l[1], lo_y), _mm_store_ps(h[0], hi_x), _mm_store_ps(h[1], hi_y);
  for (int k = 0; k < 4; ++k) bx0 = std::min(bx0, l[0][k]), by0 = std::min(by0, l[1][k]), bx1 = std::max(bx1, h[0][k]), by1 = std::max(by1, h[1][k]);
#endif
  for (; i < n; ++i) {
    const float x = xs[i], y = ys[i];
    nan |= x != x;
    bx0 = std::min(bx0, x), bx1 = std::max(bx1, x), by0 = std::min(by0, y), by1 = std::max(by1, y);
  }
  return !nan && boxMissesRegion(bx0, by0, bx1, by1, scale);
}

}  // namespace reshutter::resample
