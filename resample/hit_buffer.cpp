#include "resample/hit_buffer.h"

#include <bit>

#if defined(__SSE2__)
#include <emmintrin.h>
#endif

#include "common/check.h"

namespace reshutter::resample {

namespace {

// Interpolates attribute `ai` for micropolygon m at barycentrics b over triangle verts v.
void attrAt(const store::TilePart& part, const store::Schema& schema, int ai, uint32_t m, const uint32_t v[3], const float b[3], float* outv) {
  const auto& decl = schema.attrs[size_t(ai)];
  const auto& arr = part.attrs[size_t(ai)];
  const int nc = store::componentCount(decl.type);
  if (arr.f.empty()) {
    for (int c = 0; c < nc; ++c) outv[c] = 0.f;
    return;
  }
  if (decl.rate == store::AttrRate::Micropolygon) {
    for (int c = 0; c < nc; ++c) outv[c] = arr.f[size_t(m) * nc + c];
    return;
  }
  for (int c = 0; c < nc; ++c) outv[c] = b[0] * arr.f[size_t(v[0]) * nc + c] + b[1] * arr.f[size_t(v[1]) * nc + c] + b[2] * arr.f[size_t(v[2]) * nc + c];
}

// Sample k's lens point on the unit disk (0 without a lens): where its volume ray leaves the lens.
double lensU(const BucketSamples& samples, size_t k) { return samples.lensPlanes ? double(samples.lx[k]) : 0.0; }
double lensV(const BucketSamples& samples, size_t k) { return samples.lensPlanes ? double(samples.ly[k]) : 0.0; }

}  // namespace

HitBuffer::HitBuffer(const std::vector<AovChannel>& a, const RasterOptions& options, float far, RasterStats& stats)
    : aovs(a), opacityThreshold(options.opacityThreshold), surfaceIds(options.surfaceIds), farClip(far), counters(stats), aovLayout(a) {}

void HitBuffer::reset(size_t slots) {
  hitSlots = slots;
  zbuf.assign(slots + kPad, INFINITY);  // the gathers' early depth test reads up to 7 past a row's end
  colour.resize(slots);
  if (surfaceIds) objectOf.assign(slots, 0), gridOf.assign(slots, 0);
  zAov.assign(slots * size_t(aovLayout.floatCount), 0.f);
  zAovU.assign(slots * size_t(aovLayout.uintCount), 0u);
  frags.clear(), fragAov.clear(), fragAovU.clear();
  fragSeq = 0;
  anyFragments = false;
  fragmentsGrouped = false;
  slicesKept = false;
  timedSlots.meta = nullptr;  // a bucket's stores outlive it; the next bucket's may not be these
}

HitBuffer::HitContext HitBuffer::hitContext(const store::StoreMeta& meta, const store::TileEntry& entry, const store::TilePart& part, const float* sampleTime,
                                            double toLocal) const {
  HitContext hc{&part, &meta.schema, meta.schema.ci(), meta.schema.oi(), (entry.effects & store::kEffectTransparent) != 0};
  hc.timedCi[0] = hc.ci, hc.timedOi[0] = hc.oi;
  if ((entry.effects & store::kEffectShadedInTime) && meta.shadingTimes.size() > 1) {
    // The general path: per-hit time blends (the fast paths read one colour array).
    hc.timed = true;
    hc.numTimes = int(meta.shadingTimes.size());
    hc.shadingTimes = meta.shadingTimes.data();
    // The timed attributes' schema slots, looked up once per store and bucket (this runs per
    // chunk): colour, opacity, and the output variables the store carries in time (slot [1] -1
    // for one it carries at the first time only).
    if (timedSlots.meta != &meta) {
      timedSlots.meta = &meta;
      auto lookUp = [&](int base, int* slots) {
        slots[0] = base;
        for (size_t k = 1; k < meta.shadingTimes.size(); ++k)
          if ((slots[k] = meta.schema.find(store::StoreMeta::timedName(meta.schema.attrs[size_t(base)].name, k))) < 0) slots[1] = -1;
      };
      lookUp(hc.ci, timedSlots.ci), lookUp(hc.oi, timedSlots.oi);
      timedSlots.aov.clear();
      if (aovLayout.floatCount) {
        constexpr size_t K = store::StoreMeta::kMaxShadingTimes;
        timedSlots.aov.assign(aovs.size() * K, -1);
        for (size_t a = 0; a < aovs.size(); ++a)
          if (!aovs[a].isUInt && aovs[a].schemaIndex >= 0 && size_t(aovs[a].schemaIndex) < meta.schema.attrs.size())
            lookUp(aovs[a].schemaIndex, &timedSlots.aov[a * K]);
      }
    }
    std::copy(timedSlots.ci + 1, timedSlots.ci + hc.numTimes, hc.timedCi + 1);
    std::copy(timedSlots.oi + 1, timedSlots.oi + hc.numTimes, hc.timedOi + 1);
    if (!timedSlots.aov.empty()) hc.timedAov = timedSlots.aov.data();
    hc.sampleTime = sampleTime, hc.toLocal = toLocal;
    return hc;
  }
  if (!hc.transparentPart && !aovLayout.floatCount && !aovLayout.uintCount && hc.ci >= 0) {
    const auto& decl = meta.schema.attrs[size_t(hc.ci)];
    const auto& arr = part.attrs[size_t(hc.ci)].f;
    if (decl.rate == store::AttrRate::Vertex && store::componentCount(decl.type) == 3 && !arr.empty()) hc.opaqueFast = true, hc.colour = arr.data();
  }
  if (hc.transparentPart && !aovLayout.floatCount && !aovLayout.uintCount && hc.ci >= 0 && hc.oi >= 0) {
    auto perVertexColour = [&](int ai) {
      const auto& decl = meta.schema.attrs[size_t(ai)];
      const auto& arr = part.attrs[size_t(ai)].f;
      return decl.rate == store::AttrRate::Vertex && store::componentCount(decl.type) == 3 && !arr.empty() ? arr.data() : nullptr;
    };
    hc.colour = perVertexColour(hc.ci), hc.opacity = perVertexColour(hc.oi);
    hc.transparentFast = hc.colour && hc.opacity;
  }
  return hc;
}

void HitBuffer::recordAnyHit(const HitContext& hc, uint32_t sample, uint32_t m, const uint32_t v[3], const float b[3], float z) {
  ++counters.hits;
  ++counters.generalHits;
  const store::TilePart& part = *hc.part;
  const bool matte = part.flags[m] & store::kMatte;
  float o[3] = {1.f, 1.f, 1.f};
  if (hc.transparentPart) shadingAt(hc, hc.timedOi, sample, m, v, b, o);
  const bool opaque = o[0] >= 1.f && o[1] >= 1.f && o[2] >= 1.f;
  if (opaque) {
    if (!(z < zbuf[sample])) return;  // ties keep the surface drawn first (rasterizeQueued)
    float c[3];
    shadingAt(hc, hc.timedCi, sample, m, v, b, c);
    setNearestOpaque(sample, z, c, matte, part, m);
    if (aovLayout.floatCount || aovLayout.uintCount) {
      float fv[64];
      uint32_t uv[16];
      aovValues(hc, sample, m, v, b, z, fv, uv);
      for (int c2 = 0; c2 < aovLayout.floatCount; ++c2) zAov[size_t(c2) * hitSlots + sample] = fv[c2];
      for (int c2 = 0; c2 < aovLayout.uintCount; ++c2) zAovU[size_t(c2) * hitSlots + sample] = uv[c2];
    }
    return;
  }
  if (!(z < zbuf[sample])) return;  // hidden behind an opaque surface already found
  float c[3];
  shadingAt(hc, hc.timedCi, sample, m, v, b, c);
  addFragment(sample, z, c, o, part.objectId[m], part.gridId[m], matte);
  if (aovLayout.floatCount || aovLayout.uintCount) {
    float fv[64];
    uint32_t uv[16];
    aovValues(hc, sample, m, v, b, z, fv, uv);
    fragAov.insert(fragAov.end(), fv, fv + aovLayout.floatCount);
    fragAovU.insert(fragAovU.end(), uv, uv + aovLayout.uintCount);
  }
}

void HitBuffer::shadingAt(const HitContext& hc, const int* slots, uint32_t sample, uint32_t m, const uint32_t v[3], const float b[3], float out[3]) const {
  if (!hc.timed || slots[1] < 0) {  // slots[1] < 0: the store keeps it at the first time only (later opacities that cannot change)
    attrAt(*hc.part, *hc.schema, slots[0], m, v, b, out);
    return;
  }
  timedAt(hc, slots, sample, m, v, b, 3, out);
}

void HitBuffer::timedAt(const HitContext& hc, const int* slots, uint32_t sample, uint32_t m, const uint32_t v[3], const float b[3], int components,
                        float* out) const {
  const double t = double(hc.sampleTime[sample]) + hc.toLocal;
  const double* T = hc.shadingTimes;
  int k = 0;
  while (k + 2 < hc.numTimes && T[k + 1] <= t) ++k;
  const float w = float(std::clamp((t - T[k]) / (T[k + 1] - T[k]), 0.0, 1.0));
  float a[16], c[16];
  attrAt(*hc.part, *hc.schema, slots[k], m, v, b, a);
  attrAt(*hc.part, *hc.schema, slots[k + 1], m, v, b, c);
  for (int j = 0; j < components; ++j) out[j] = a[j] + w * (c[j] - a[j]);
}

void HitBuffer::addFragment(uint32_t sample, float z, const float c[3], const float o[3], uint32_t objectId, uint32_t gridId, bool matte) {
  Fragment f;
  f.z = z;
  for (int k = 0; k < 3; ++k) f.c[k] = c[k], f.o[k] = std::clamp(o[k], 0.f, 1.f);
  f.objectId = objectId, f.gridId = gridId;
  f.seq = fragSeq++;
  f.matte = matte;
  f.sample = sample;
  frags.push_back(f);  // its output variables, if any, are appended next by the caller (at seq)
  anyFragments = true;
  ++counters.fragments;
}

void HitBuffer::groupFragments(const BucketSamples& samples) {
  if (fragmentsGrouped) return;
  fragmentsGrouped = true;
  if (!anyFragments) return;
  const auto& idxOf = samples.idxOf;
  const size_t slots = size_t(samples.P) * samples.N;
  // Counted here rather than as each is recorded: these independent increments overlap their
  // cache misses, where a hit would wait on its own.
  fragCount.assign(hitSlots, 0);
  for (const Fragment& f : frags) ++fragCount[f.sample];
  // Each sample's run starts where the runs of the samples resolved before it end.
  fragEnd.resize(hitSlots);
  uint32_t at = 0;
  for (size_t slot = 0; slot < slots; ++slot) {
    const size_t k = idxOf[slot];
    fragEnd[k] = at;  // its start, while it is being filled
    at += fragCount[k];
  }
  fragScratch.resize(frags.size());
  for (const Fragment& f : frags) fragScratch[fragEnd[f.sample]++] = f;
  frags.swap(fragScratch);
}

void HitBuffer::nearerFragments(size_t k, float zo, std::vector<const Fragment*>& list) const {
  list.clear();
  const uint32_t n = fragCount[k];
  if (!n) return;
  const Fragment* run = frags.data() + (fragEnd[k] - n);
  for (uint32_t i = 0; i < n; ++i)
    if (run[i].z < zo) list.push_back(&run[i]);
  // Front to back; seq (draw order) breaks depth ties. The lists are short: insertion sort.
  auto before = [](const Fragment* a, const Fragment* b) { return a->z != b->z ? a->z < b->z : a->seq < b->seq; };
  for (size_t i = 1; i < list.size(); ++i) {
    const Fragment* f = list[i];
    size_t j = i;
    for (; j > 0 && before(f, list[j - 1]); --j) list[j] = list[j - 1];
    list[j] = f;
  }
}

void HitBuffer::aovValues(const HitContext& hc, uint32_t sample, uint32_t m, const uint32_t v[3], const float b[3], float z, float* f, uint32_t* u) const {
  const store::TilePart& part = *hc.part;
  const store::Schema& schema = *hc.schema;
  for (size_t a = 0; a < aovs.size(); ++a) {
    const auto& ch = aovs[a];
    if (ch.isUInt) {
      uint32_t val = 0;
      if (ch.builtin == AovChannel::Builtin::ObjectId) val = part.objectId[m];
      else if (ch.schemaIndex >= 0 && !part.attrs[size_t(ch.schemaIndex)].u.empty()) {
        const auto& arr = part.attrs[size_t(ch.schemaIndex)].u;
        if (schema.attrs[size_t(ch.schemaIndex)].rate == store::AttrRate::Micropolygon) val = arr[m];
        else val = arr[v[b[1] > b[0] ? (b[2] > b[1] ? 2 : 1) : (b[2] > b[0] ? 2 : 0)]];  // nearest vertex
      }
      u[aovLayout.uintBase[a]] = val;
    } else if (ch.builtin == AovChannel::Builtin::Depth) {
      f[aovLayout.floatBase[a]] = z;
    } else if (hc.timedAov && hc.timedAov[a * store::StoreMeta::kMaxShadingTimes + 1] >= 0) {
      timedAt(hc, &hc.timedAov[a * store::StoreMeta::kMaxShadingTimes], sample, m, v, b, ch.components, f + aovLayout.floatBase[a]);
    } else {
      attrAt(part, schema, ch.schemaIndex, m, v, b, f + aovLayout.floatBase[a]);
    }
  }
}

const ResolvedSamples& HitBuffer::resolve(const BucketSamples& samples) {
  const int P = samples.P, N = samples.N;
  const auto& idxOf = samples.idxOf;
  const size_t slots = size_t(P) * N;
  out.x0 = samples.x0, out.y0 = samples.y0, out.width = samples.w, out.height = samples.h, out.spp = N;
  out.r.resize(slots), out.g.resize(slots), out.b.resize(slots), out.a.resize(slots), out.z.resize(slots);
  out.aov.resize(size_t(aovLayout.floatCount));
  for (auto& v : out.aov) v.assign(slots, 0.f);
  out.aovU.resize(size_t(aovLayout.uintCount));
  for (auto& v : out.aovU) v.assign(slots, 0u);
  const bool anyAovs = aovLayout.floatCount || aovLayout.uintCount;
  // The depths the single-closest filters compare: only when there are output variables.
  if (anyAovs) out.aovZ.assign(slots, INFINITY);
  const float far = farClip;
  if (!anyFragments && !anyAovs && !volumesHere) {
    // Opaque surfaces only, no output variables (the common case): each sample is its nearest
    // surface's colour or empty, as the general loop below computes it, without its branches.
    size_t slot = 0;
#if defined(__SSE2__)
    if (samples.pixelMajor) {
      // The samples in output order (idxOf the identity): four at a time, the colour records
      // transposed into r, g, b and matte; the same values (a hidden channel is +0 either way).
      const __m128 inf = _mm_set1_ps(INFINITY), farZ = _mm_set1_ps(far), one = _mm_set1_ps(1.f);
      const float* z = zbuf.data();
      const float* c = &colour.data()->r;
      for (; slot + 4 <= slots; slot += 4) {
        const __m128 zo = _mm_loadu_ps(z + slot);
        __m128 r = _mm_loadu_ps(c + 4 * slot), g = _mm_loadu_ps(c + 4 * slot + 4), b = _mm_loadu_ps(c + 4 * slot + 8), m = _mm_loadu_ps(c + 4 * slot + 12);
        _MM_TRANSPOSE4_PS(r, g, b, m);
        const __m128 hit = _mm_cmplt_ps(zo, inf);
        const __m128 visible = _mm_and_ps(hit, _mm_castsi128_ps(_mm_cmpeq_epi32(_mm_castps_si128(m), _mm_setzero_si128())));
        _mm_storeu_ps(&out.r[slot], _mm_and_ps(visible, r));
        _mm_storeu_ps(&out.g[slot], _mm_and_ps(visible, g));
        _mm_storeu_ps(&out.b[slot], _mm_and_ps(visible, b));
        _mm_storeu_ps(&out.a[slot], _mm_and_ps(visible, one));
        _mm_storeu_ps(&out.z[slot], _mm_or_ps(_mm_and_ps(hit, zo), _mm_andnot_ps(hit, farZ)));
      }
    }
#endif
    // Without branches: whether a sample was hit, and by a matte surface, is a coin toss that
    // the predictor loses; a hidden channel is +0 (all bits clear) either way.
    auto masked = [](float v, uint32_t mask) { return std::bit_cast<float>(std::bit_cast<uint32_t>(v) & mask); };
    for (; slot < slots; ++slot) {
      prefetchSample(idxOf, slot + kPrefetchAhead, slots);
      const size_t k = idxOf[slot];
      const float zo = zbuf[k];
      const SurfaceColour& nh = colour[k];
      const uint32_t hit = 0u - uint32_t(zo < INFINITY), visible = hit & (0u - uint32_t(nh.matte == 0));
      out.r[slot] = masked(nh.r, visible);
      out.g[slot] = masked(nh.g, visible);
      out.b[slot] = masked(nh.b, visible);
      out.a[slot] = masked(1.f, visible);
      out.z[slot] = std::bit_cast<float>((std::bit_cast<uint32_t>(zo) & hit) | (std::bit_cast<uint32_t>(far) & ~hit));
    }
    return out;
  }
  const float stopT = 1.f - opacityThreshold;
  groupFragments(samples);
  std::vector<const Fragment*> list;
  const bool keepSlices = volumesHere && surfaceIds;  // deep output follows
  keptSlices.clear();
  if (keepSlices) keptSliceStart.assign(slots + 1, 0);
  slicesKept = keepSlices;
  for (size_t slot = 0; slot < slots; ++slot) {
    prefetchSample(idxOf, slot + kPrefetchAhead, slots);
    const size_t k = idxOf[slot];  // the rasterizer keeps samples stratum-major
    const float zo = zbuf[k];
    const SurfaceColour& nh = colour[k];
    const uint8_t s = hitState(k);
    if ((!anyFragments || !fragCount[k]) && !volumesHere) {
      const bool visible = (s & kHitOpaque) && !(s & kHitMatte);
      out.r[slot] = visible ? nh.r : 0.f;
      out.g[slot] = visible ? nh.g : 0.f;
      out.b[slot] = visible ? nh.b : 0.f;
      const float a = visible ? 1.f : 0.f;
      out.a[slot] = a;
      out.z[slot] = (s & kHitOpaque) ? zo : far;
      if ((s & kHitOpaque) && anyAovs) {
        out.aovZ[slot] = zo;
        for (int c = 0; c < aovLayout.floatCount; ++c) out.aov[size_t(c)][slot] = zAov[size_t(c) * hitSlots + k];
        for (int c = 0; c < aovLayout.uintCount; ++c) out.aovU[size_t(c)][slot] = zAovU[size_t(c) * hitSlots + k];
      }
      // Composited AOVs of a matte surface are zero like its colour.
      if ((s & kHitMatte)) zeroCompositedAovs(slot);
      continue;
    }
    if (keepSlices) keptSliceStart[slot] = uint32_t(keptSlices.size());
    // Transparent surfaces in front of the nearest opaque one, front to back.
    if (anyFragments) nearerFragments(k, zo, list);
    else list.clear();
    float T[3] = {1.f, 1.f, 1.f}, C[3] = {0.f, 0.f, 0.f}, A[3] = {0.f, 0.f, 0.f};
    // The volumes between the previous surface (or the near plane) and depth z, composited
    // under what is in front; true once the sample is opaque.
    float zPrev = 0.f;
    auto throughVolumes = [&](float z) {
      if (!volumesHere) return false;
      VolumeSegment v;
      // Deep output will want this segment's slices: kept, ended by a marker holding the whole
      // segment, so visitFragments() need not march the ray again.
      volumes->integrate(double(samples.sx[k]), double(samples.sy[k]), lensU(samples, k), lensV(samples, k), samples.tBase + double(samples.st[k]),
                         double(zPrev), double(z), v, keepSlices ? &keptSlices : nullptr, volumeSliceRatio);
      if (keepSlices) {
        VolumeSlice end;
        end.slice = kSegmentEnd, end.segment = v;
        keptSlices.push_back(end);
      }
      zPrev = z;
      for (int c = 0; c < 3; ++c) C[c] += T[c] * v.radiance[c], A[c] += T[c] * (1.f - v.transmittance), T[c] *= v.transmittance;
      return T[0] <= stopT && T[1] <= stopT && T[2] <= stopT;
    };
    float closestZ = INFINITY;
    bool closestChosen = false;
    float aovAcc[64];
    std::fill_n(aovAcc, aovLayout.floatCount, 0.f);
    bool opaqueReached = false;
    auto takeSingle = [&](const float* fv, const uint32_t* uv, float z) {
      closestChosen = true;
      closestZ = z;
      if (anyAovs) out.aovZ[slot] = z;
      for (size_t a = 0; a < aovs.size(); ++a) {
        if (aovs[a].isUInt) out.aovU[size_t(aovLayout.uintBase[a])][slot] = uv[aovLayout.uintBase[a]];
        else if (!aovs[a].composited())
          for (int c = 0; c < aovs[a].components; ++c) out.aov[size_t(aovLayout.floatBase[a] + c)][slot] = fv[aovLayout.floatBase[a] + c];
      }
    };
    for (const Fragment* f : list) {
      if (throughVolumes(f->z)) {
        opaqueReached = true;
        break;
      }
      const float oAvg = (f->o[0] + f->o[1] + f->o[2]) / 3.f;
      const float tAvg = (T[0] + T[1] + T[2]) / 3.f;
      const float* fv = fragAov.data() + size_t(f->seq) * aovLayout.floatCount;
      const uint32_t* uv = fragAovU.data() + size_t(f->seq) * aovLayout.uintCount;
      if (!f->matte) {
        for (int c = 0; c < 3; ++c) C[c] += T[c] * f->c[c], A[c] += T[c] * f->o[c];
        for (size_t a = 0; a < aovs.size(); ++a)
          if (!aovs[a].isUInt && aovs[a].composited())
            for (int c = 0; c < aovs[a].components; ++c) aovAcc[aovLayout.floatBase[a] + c] += tAvg * oAvg * fv[aovLayout.floatBase[a] + c];
      }
      if (!closestChosen && oAvg >= opacityThreshold) takeSingle(fv, uv, f->z);
      for (int c = 0; c < 3; ++c) T[c] *= 1.f - f->o[c];
      if (T[0] <= stopT && T[1] <= stopT && T[2] <= stopT) {
        opaqueReached = true;
        break;
      }
    }
    if (!opaqueReached && throughVolumes((s & kHitOpaque) ? zo : INFINITY)) opaqueReached = true;
    if (!opaqueReached && (s & kHitOpaque)) {
      const float tAvg = (T[0] + T[1] + T[2]) / 3.f;
      if (!(s & kHitMatte)) {
        C[0] += T[0] * nh.r, C[1] += T[1] * nh.g, C[2] += T[2] * nh.b;
        for (int c = 0; c < 3; ++c) A[c] += T[c];
        for (size_t a = 0; a < aovs.size(); ++a)
          if (!aovs[a].isUInt && aovs[a].composited())
            for (int c = 0; c < aovs[a].components; ++c) aovAcc[aovLayout.floatBase[a] + c] += tAvg * zAov[size_t(aovLayout.floatBase[a] + c) * hitSlots + k];
      }
      if (!closestChosen) {
        float fv[64];
        uint32_t uv[16];
        for (int c = 0; c < aovLayout.floatCount; ++c) fv[c] = zAov[size_t(c) * hitSlots + k];
        for (int c = 0; c < aovLayout.uintCount; ++c) uv[c] = zAovU[size_t(c) * hitSlots + k];
        takeSingle(fv, uv, zo);
      }
    }
    if (keepSlices) keptSliceStart[slot + 1] = uint32_t(keptSlices.size());
    out.r[slot] = C[0], out.g[slot] = C[1], out.b[slot] = C[2];
    out.a[slot] = (A[0] + A[1] + A[2]) / 3.f;
    out.z[slot] = closestChosen ? closestZ : far;
    for (size_t a = 0; a < aovs.size(); ++a)
      if (!aovs[a].isUInt && aovs[a].composited())
        for (int c = 0; c < aovs[a].components; ++c) out.aov[size_t(aovLayout.floatBase[a] + c)][slot] = aovAcc[aovLayout.floatBase[a] + c];
  }
  return out;
}

void HitBuffer::visitFragments(const BucketSamples& samples, const std::function<void(size_t, const SampleFragment*, size_t)>& fn) {
  const int P = samples.P, N = samples.N;
  const auto& idxOf = samples.idxOf;
  CHECK(surfaceIds, "visitFragments() needs RasterOptions::surfaceIds");
  const size_t slots = size_t(P) * N;
  const float stopT = 1.f - opacityThreshold;
  std::vector<const Fragment*> list;
  std::vector<SampleFragment> outList;
  std::vector<float> opaqueAov(static_cast<size_t>(aovLayout.floatCount));
  std::vector<uint32_t> opaqueAovU(static_cast<size_t>(aovLayout.uintCount));
  // A volume has no output variables: zero for composited ones (it has no surface to take them from).
  const std::vector<float> noAov(static_cast<size_t>(aovLayout.floatCount), 0.f);
  const std::vector<uint32_t> noAovU(static_cast<size_t>(aovLayout.uintCount), 0u);
  std::vector<VolumeSlice> slices;
  groupFragments(samples);
  for (size_t slot = 0; slot < slots; ++slot) {
    const size_t k = idxOf[slot];  // the rasterizer keeps samples stratum-major
    const float zo = zbuf[k];
    const SurfaceColour& nh = colour[k];
    const uint8_t s = hitState(k);
    outList.clear();
    if (anyFragments) nearerFragments(k, zo, list);
    else list.clear();
    float T[3] = {1.f, 1.f, 1.f};
    bool opaqueReached = false;
    // The volumes between the previous surface (or the near plane) and depth z, as volume
    // fragments of depth slices; true once the sample is opaque.
    float zPrev = 0.f;
    size_t cursor = slicesKept ? keptSliceStart[slot] : 0, cursorEnd = slicesKept ? keptSliceStart[slot + 1] : 0;
    auto throughVolumes = [&](float z) {
      if (!volumesHere) return false;
      VolumeSegment v;
      slices.clear();
      if (cursor < cursorEnd) {
        // The segment resolve() marched: its slices up to the marker.
        for (; keptSlices[cursor].slice != kSegmentEnd; ++cursor) slices.push_back(keptSlices[cursor]);
        v = keptSlices[cursor++].segment;
      } else {
        volumes->integrate(double(samples.sx[k]), double(samples.sy[k]), lensU(samples, k), lensV(samples, k), samples.tBase + double(samples.st[k]),
                           double(zPrev), double(z), v, &slices, volumeSliceRatio);
      }
      zPrev = z;
      for (const VolumeSlice& vs : slices) {
        SampleFragment sf;
        sf.z = vs.zFront, sf.zBack = vs.zBack, sf.volume = true, sf.slice = vs.slice;
        for (int c = 0; c < 3; ++c) sf.c[c] = vs.segment.radiance[c], sf.o[c] = 1.f - vs.segment.transmittance;
        sf.objectId = kVolumeObjectId;
        sf.aov = noAov.data(), sf.aovU = noAovU.data();
        outList.push_back(sf);
      }
      for (int c = 0; c < 3; ++c) T[c] *= v.transmittance;  // as resolve() composites it
      return T[0] <= stopT && T[1] <= stopT && T[2] <= stopT;
    };
    for (const Fragment* f : list) {
      if (throughVolumes(f->z)) {
        opaqueReached = true;
        break;
      }
      SampleFragment sf;
      sf.z = f->z;
      for (int c = 0; c < 3; ++c) sf.c[c] = f->matte ? 0.f : f->c[c], sf.o[c] = f->o[c];
      sf.objectId = f->objectId, sf.gridId = f->gridId, sf.matte = f->matte;
      sf.aov = fragAov.data() + size_t(f->seq) * aovLayout.floatCount;
      sf.aovU = fragAovU.data() + size_t(f->seq) * aovLayout.uintCount;
      outList.push_back(sf);
      for (int c = 0; c < 3; ++c) T[c] *= 1.f - f->o[c];
      if (T[0] <= stopT && T[1] <= stopT && T[2] <= stopT) {
        opaqueReached = true;
        break;
      }
    }
    if (!opaqueReached && throughVolumes((s & kHitOpaque) ? zo : INFINITY)) opaqueReached = true;
    if (!opaqueReached && (s & kHitOpaque)) {
      SampleFragment sf;
      sf.z = zo;
      const bool matte = s & kHitMatte;
      sf.c[0] = matte ? 0.f : nh.r, sf.c[1] = matte ? 0.f : nh.g, sf.c[2] = matte ? 0.f : nh.b;
      sf.objectId = objectOf[k], sf.gridId = gridOf[k], sf.matte = matte;
      for (int c = 0; c < aovLayout.floatCount; ++c) opaqueAov[size_t(c)] = zAov[size_t(c) * hitSlots + k];
      for (int c = 0; c < aovLayout.uintCount; ++c) opaqueAovU[size_t(c)] = zAovU[size_t(c) * hitSlots + k];
      sf.aov = opaqueAov.data(), sf.aovU = opaqueAovU.data();
      outList.push_back(sf);
    }
    fn(slot, outList.data(), outList.size());
  }
}

void HitBuffer::zeroCompositedAovs(size_t slot) {
  for (size_t a = 0; a < aovs.size(); ++a)
    if (!aovs[a].isUInt && aovs[a].composited())
      for (int c = 0; c < aovs[a].components; ++c) out.aov[size_t(aovLayout.floatBase[a] + c)][slot] = 0.f;
}

}  // namespace reshutter::resample
