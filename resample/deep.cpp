// Deep output: sample formation, tidying, flattening and the scanline deep OpenEXR writer (deep.h).
#include "resample/deep.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <numeric>
#include <thread>

#include <OpenEXR/ImfChannelList.h>
#include <OpenEXR/ImfDeepFrameBuffer.h>
#include <OpenEXR/ImfDeepImageState.h>
#include <OpenEXR/ImfDeepScanLineOutputFile.h>
#include <OpenEXR/ImfDeepScanLineOutputPart.h>
#include <OpenEXR/ImfMultiPartOutputFile.h>
#include <OpenEXR/ImfHeader.h>
#include <OpenEXR/ImfIDManifest.h>
#include <OpenEXR/ImfPartType.h>
#include <OpenEXR/ImfStandardAttributes.h>
#include <tbb/enumerable_thread_specific.h>

#include "common/atomic_file.h"
#include "common/error.h"
#include "resample/exr_header.h"

namespace reshutter::resample {

size_t DeepPixel::add() {
  const size_t i = size();
  f.resize(f.size() + size_t(nf), 0.f);
  u.resize(u.size() + size_t(nu), 0u);
  return i;
}

// ---------------------------------------------------------------------------------------------
// Alpha arithmetic

namespace {
constexpr double kTiny = std::numeric_limits<double>::min();
double clamp01(double v) { return v > 0 ? (v < 1 ? v : 1) : 0; }
}  // namespace

double deepSplitAlpha(double a, double x) {
  a = clamp01(a), x = clamp01(x);
  if (a >= 1) return 1;
  if (a <= kTiny) return a * x;  // the limit of -expm1(x·log1p(-a)) as a → 0
  return -std::expm1(x * std::log1p(-a));
}

double deepSplitScale(double a, double x) {
  a = clamp01(a), x = clamp01(x);
  if (a >= 1) return 1;
  if (a <= kTiny) return x;
  return deepSplitAlpha(a, x) / a;
}

void deepMergeAlphas(const double* alphas, const double* colours, size_t n, size_t m, double& alphaOut, double* coloursOut) {
  size_t opaque = 0;
  for (size_t i = 0; i < n; ++i) opaque += alphas[i] >= 1;
  for (size_t k = 0; k < m; ++k) coloursOut[k] = 0;
  if (opaque) {
    // Opaque samples absorb everything at their front: the others do not show.
    alphaOut = 1;
    for (size_t i = 0; i < n; ++i)
      if (alphas[i] >= 1)
        for (size_t k = 0; k < m; ++k) coloursOut[k] += colours[i * m + k];
    for (size_t k = 0; k < m; ++k) coloursOut[k] /= double(opaque);
    return;
  }
  // Summing optical depths u = -log1p(-α) is exact and associative; α itself would lose
  // everything near 1 (1 - α underflows) and near 0 (α·α underflows).
  double U = 0;
  for (size_t i = 0; i < n; ++i) {
    const double a = clamp01(alphas[i]);
    const double u = -std::log1p(-a);
    const double v = a > kTiny ? u / a : 1.0;
    U += u;
    for (size_t k = 0; k < m; ++k) coloursOut[k] += colours[i * m + k] * v;
  }
  alphaOut = -std::expm1(-U);
  const double w = U > kTiny ? alphaOut / U : 1.0;
  for (size_t k = 0; k < m; ++k) coloursOut[k] *= w;
}

// ---------------------------------------------------------------------------------------------
// Tidy

namespace {

// Channels that are premultiplied by one alpha: R by AR, G by AG, B by AB, premultiplied output
// variables by A. Value output variables, ids and flags are carried, not arithmetic.
struct AlphaGroups {
  std::vector<std::pair<int, std::vector<int>>> groups;  // (alpha field, premultiplied fields)
  explicit AlphaGroups(const DeepLayout& L) {
    groups.push_back({kDeepAR, {kDeepR}});
    groups.push_back({kDeepAG, {kDeepG}});
    groups.push_back({kDeepAB, {kDeepB}});
    std::vector<int> aux;
    for (size_t i = 0; i < L.floats.size(); ++i)
      if (L.floats[i].premultiplied) aux.push_back(kDeepFixedFloats + int(i));
    groups.push_back({kDeepA, aux});
  }
};

bool lessDepth(const float* a, const float* b) { return a[kDeepZ] != b[kDeepZ] ? a[kDeepZ] < b[kDeepZ] : a[kDeepZBack] < b[kDeepZBack]; }

// Reorders px by (Z, ZBack); stable, so equal keys keep their formation order.
void sortPixel(DeepPixel& px, DeepPixel& tmp) {
  const size_t n = px.size();
  std::vector<uint32_t> order(n);
  std::iota(order.begin(), order.end(), 0u);
  std::stable_sort(order.begin(), order.end(), [&](uint32_t a, uint32_t b) { return lessDepth(px.at(a), px.at(b)); });
  tmp.nf = px.nf, tmp.nu = px.nu;
  tmp.f.resize(px.f.size()), tmp.u.resize(px.u.size());
  for (size_t i = 0; i < n; ++i) {
    std::copy(px.at(order[i]), px.at(order[i]) + px.nf, tmp.at(i));
    std::copy(px.uat(order[i]), px.uat(order[i]) + px.nu, tmp.uat(i));
  }
  std::swap(px.f, tmp.f), std::swap(px.u, tmp.u);
}

// Whether a sorted pixel has overlapping samples (OpenEXR's definition: a point may sit at a
// volume's front or back; two points may not coincide).
bool overlapsSorted(const DeepPixel& px) {
  float maxBack = -INFINITY;
  for (size_t i = 0; i < px.size(); ++i) {
    const float* s = px.at(i);
    if (s[kDeepZ] < maxBack) return true;
    if (i > 0 && s[kDeepZ] == px.at(i - 1)[kDeepZ] && s[kDeepZBack] == px.at(i - 1)[kDeepZBack]) return true;
    maxBack = std::max(maxBack, s[kDeepZBack]);
  }
  return false;
}

}  // namespace

bool isTidy(const DeepPixel& px) {
  for (size_t i = 1; i < px.size(); ++i)
    if (lessDepth(px.at(i), px.at(i - 1))) return false;
  for (size_t i = 0; i < px.size(); ++i)
    if (!(px.at(i)[kDeepZBack] >= px.at(i)[kDeepZ])) return false;
  return !overlapsSorted(px);
}

void tidyDeepPixel(DeepPixel& px, const DeepLayout& L) {
  const int nf = px.nf, nu = px.nu;
  const AlphaGroups groups(L);
  // Sanitise, and drop samples that contribute nothing.
  size_t kept = 0;
  for (size_t i = 0; i < px.size(); ++i) {
    float* s = px.at(i);
    if (!std::isfinite(s[kDeepZ])) continue;
    for (int k = 0; k < nf; ++k)
      if (!std::isfinite(s[k])) s[k] = k == kDeepZBack ? s[kDeepZ] : 0.f;
    if (!(s[kDeepZBack] >= s[kDeepZ])) s[kDeepZBack] = s[kDeepZ];
    bool empty = true;
    for (const auto& [a, cs] : groups.groups) {
      s[a] = std::clamp(s[a], 0.f, 1.f);
      empty = empty && s[a] == 0.f;
      for (int c : cs) empty = empty && s[c] == 0.f;
    }
    if (empty) continue;
    if (kept != i) {
      std::copy(s, s + nf, px.at(kept));
      std::copy(px.uat(i), px.uat(i) + nu, px.uat(kept));
    }
    ++kept;
  }
  px.f.resize(kept * size_t(nf)), px.u.resize(kept * size_t(nu));
  thread_local DeepPixel tmp;
  sortPixel(px, tmp);
  if (!overlapsSorted(px)) return;

  // Split every volume sample at every depth where another sample starts or ends; the pieces
  // are then either identical in (Z, ZBack) or disjoint.
  std::vector<float> cuts;
  for (size_t i = 0; i < px.size(); ++i) cuts.push_back(px.at(i)[kDeepZ]), cuts.push_back(px.at(i)[kDeepZBack]);
  std::sort(cuts.begin(), cuts.end());
  cuts.erase(std::unique(cuts.begin(), cuts.end()), cuts.end());
  DeepPixel& pieces = tmp;
  pieces.nf = nf, pieces.nu = nu;
  pieces.clear();
  for (size_t i = 0; i < px.size(); ++i) {
    const float* s = px.at(i);
    const float zf = s[kDeepZ], zb = s[kDeepZBack];
    auto it = std::upper_bound(cuts.begin(), cuts.end(), zf);
    if (zb == zf || it == cuts.end() || *it >= zb) {
      const size_t j = pieces.add();
      std::copy(s, s + nf, pieces.at(j));
      std::copy(px.uat(i), px.uat(i) + nu, pieces.uat(j));
      continue;
    }
    const double len = double(zb) - double(zf);
    float a = zf;
    for (; a < zb; ++it) {
      const float b = (it == cuts.end() || *it > zb) ? zb : *it;
      // Each piece from the original sample, not from a remainder: no error accumulates.
      const double x = (double(b) - double(a)) / len;
      const size_t j = pieces.add();
      float* p = pieces.at(j);
      const float* src = px.at(i);  // re-read: add() may reallocate nothing in px, only pieces
      std::copy(src, src + nf, p);
      std::copy(px.uat(i), px.uat(i) + nu, pieces.uat(j));
      p[kDeepZ] = a, p[kDeepZBack] = b;
      for (const auto& [al, cs] : groups.groups) {
        const double scale = deepSplitScale(src[al], x);
        p[al] = float(deepSplitAlpha(src[al], x));
        for (int c : cs) p[c] = float(double(src[c]) * scale);
      }
      a = b;
    }
  }
  DeepPixel sorted;
  sorted.nf = nf, sorted.nu = nu;
  std::swap(pieces.f, px.f), std::swap(pieces.u, px.u);
  sortPixel(px, sorted);
  // Merge runs of identical (Z, ZBack).
  DeepPixel out;
  out.nf = nf, out.nu = nu;
  std::vector<double> alphas, colours, merged;
  for (size_t i = 0; i < px.size();) {
    size_t j = i + 1;
    while (j < px.size() && px.at(j)[kDeepZ] == px.at(i)[kDeepZ] && px.at(j)[kDeepZBack] == px.at(i)[kDeepZBack]) ++j;
    const size_t o = out.add();
    // Carried values (output variables by value, ids, flags) come from the strongest sample.
    size_t best = i;
    for (size_t k = i + 1; k < j; ++k)
      if (px.at(k)[kDeepA] > px.at(best)[kDeepA]) best = k;
    std::copy(px.at(best), px.at(best) + nf, out.at(o));
    std::copy(px.uat(best), px.uat(best) + nu, out.uat(o));
    if (j - i > 1) {
      for (const auto& [al, cs] : groups.groups) {
        alphas.clear(), colours.clear();
        for (size_t k = i; k < j; ++k) {
          alphas.push_back(px.at(k)[al]);
          for (int c : cs) colours.push_back(px.at(k)[c]);
        }
        merged.assign(cs.size(), 0.0);
        double a = 0;
        deepMergeAlphas(alphas.data(), colours.data(), j - i, cs.size(), a, merged.data());
        out.at(o)[al] = float(a);
        for (size_t c = 0; c < cs.size(); ++c) out.at(o)[cs[c]] = float(merged[c]);
      }
    }
    i = j;
  }
  std::swap(px.f, out.f), std::swap(px.u, out.u);
}

FlatDeepPixel flattenDeepPixel(const DeepPixel& px, const DeepLayout& L, bool matteAware) {
  FlatDeepPixel out;
  std::vector<int> aux;
  for (size_t i = 0; i < L.floats.size(); ++i)
    if (L.floats[i].premultiplied) aux.push_back(kDeepFixedFloats + int(i));
  out.aux.assign(aux.size(), 0.0);
  double T[4] = {1, 1, 1, 1};  // transmittance per R G B and for A
  for (size_t i = 0; i < px.size(); ++i) {
    const float* s = px.at(i);
    const bool matte = matteAware && (px.uat(i)[kDeepFlags] & kDeepFlagMatte);
    out.r += T[0] * s[kDeepR], out.g += T[1] * s[kDeepG], out.b += T[2] * s[kDeepB];
    if (!matte) {
      out.a += T[3] * s[kDeepA];
      for (size_t k = 0; k < aux.size(); ++k) out.aux[k] += T[3] * s[aux[k]];
    }
    T[0] *= 1.0 - s[kDeepAR], T[1] *= 1.0 - s[kDeepAG], T[2] *= 1.0 - s[kDeepAB], T[3] *= 1.0 - s[kDeepA];
  }
  return out;
}

// ---------------------------------------------------------------------------------------------
// Formation

namespace {

struct Entry {
  uint32_t object;
  uint32_t matte;
  int64_t slice;  // volume fragments: their depth slice + 1 (a group of its own); surfaces: 0
  float z, zBack;
  uint32_t sample, fragment;
  uint32_t t;  // index of the sample's transmittance in front of this fragment
};

}  // namespace

void formDeepPixel(const WeightedSample* samples, size_t n, const DeepLayout& L, const DeepFormOptions& options, DeepPixel& out) {
  out.nf = L.nf(), out.nu = L.nu();
  out.clear();
  thread_local std::vector<Entry> entries;
  thread_local std::vector<float> trans;  // R G B transmittance in front of each fragment
  thread_local DeepPixel tmp;
  entries.clear(), trans.clear();
  for (size_t s = 0; s < n; ++s) {
    if (!(samples[s].weight > 0)) continue;
    float T[3] = {1, 1, 1};
    for (size_t k = 0; k < samples[s].count; ++k) {
      const SampleFragment& f = samples[s].fragments[k];
      if (std::isfinite(f.z))
        entries.push_back({f.objectId, f.matte ? 1u : 0u, f.volume ? int64_t(f.slice) + (int64_t(1) << 32) : 0, f.z, f.volume ? f.zBack : f.z, uint32_t(s),
                           uint32_t(k), uint32_t(trans.size())});
      trans.insert(trans.end(), T, T + 3);
      for (int c = 0; c < 3; ++c) T[c] *= 1.f - std::clamp(f.o[c], 0.f, 1.f);
    }
  }
  std::sort(entries.begin(), entries.end(), [](const Entry& a, const Entry& b) {
    if (a.matte != b.matte) return a.matte < b.matte;
    if (a.object != b.object) return a.object < b.object;
    if (a.slice != b.slice) return a.slice < b.slice;
    if (a.z != b.z) return a.z < b.z;
    if (a.sample != b.sample) return a.sample < b.sample;
    return a.fragment < b.fragment;
  });
  const float tol = std::max(0.f, options.tolerance);
  const size_t nAux = L.floats.size();
  thread_local std::vector<double> acc;
  acc.resize(6 + nAux);  // visible R G B, visible AR AG AB, visible output variables
  for (size_t i = 0; i < entries.size();) {
    // Single-linkage chain in depth within one (matte, object); a volume's fragments group by
    // depth slice instead.
    size_t j = i + 1;
    float zBack = entries[i].zBack;
    while (j < entries.size() && entries[j].object == entries[i].object && entries[j].matte == entries[i].matte && entries[j].slice == entries[i].slice &&
           (entries[i].slice || entries[j].z - entries[j - 1].z <= tol * std::max(std::abs(entries[j - 1].z), std::abs(entries[j].z))))
      zBack = std::max(zBack, entries[j].zBack), ++j;
    // What this group adds to the flat image: every fragment with the transmittance in front of
    // it in its own sample, weighted by the sample's filter weight.
    std::fill(acc.begin(), acc.end(), 0.0);
    for (size_t e = i; e < j; ++e) {
      const WeightedSample& ws = samples[entries[e].sample];
      const SampleFragment& f = ws.fragments[entries[e].fragment];
      const float* T = trans.data() + entries[e].t;
      const double w = ws.weight;
      for (int k = 0; k < 3; ++k) acc[size_t(k)] += w * T[k] * f.c[k], acc[size_t(3 + k)] += w * T[k] * std::clamp(f.o[k], 0.f, 1.f);
      if (!f.matte && f.aov) {
        const double tAvg = (double(T[0]) + T[1] + T[2]) / 3, oAvg = (double(f.o[0]) + f.o[1] + f.o[2]) / 3;
        for (size_t a = 0; a < nAux; ++a)
          if (L.floats[a].premultiplied) acc[6 + a] += w * tAvg * oAvg * f.aov[L.floats[a].source];
      }
    }
    const size_t o = out.add();
    float* r = out.at(o);
    uint32_t* u = out.uat(o);
    r[kDeepZ] = entries[i].z, r[kDeepZBack] = zBack;
    r[kDeepR] = float(acc[0]), r[kDeepG] = float(acc[1]), r[kDeepB] = float(acc[2]);
    r[kDeepAR] = float(acc[3]), r[kDeepAG] = float(acc[4]), r[kDeepAB] = float(acc[5]);
    r[kDeepA] = float((acc[3] + acc[4] + acc[5]) / 3);
    // The nearest fragment gives the values that cannot be blended.
    const SampleFragment& front = samples[entries[i].sample].fragments[entries[i].fragment];
    for (size_t a = 0; a < nAux; ++a)
      r[kDeepFixedFloats + a] = L.floats[a].premultiplied ? float(acc[6 + a]) : (front.aov ? front.aov[L.floats[a].source] : 0.f);
    u[kDeepFlags] = entries[i].matte ? kDeepFlagMatte : 0u;
    u[kDeepObjectId] = entries[i].object;
    for (size_t a = 0; a < L.uints.size(); ++a) u[kDeepFixedUInts + a] = front.aovU ? front.aovU[L.uints[a].source] : 0u;
    i = j;
  }
  // Visible contributions → deep samples: in depth order, each sample's alpha and premultiplied
  // values are its visible ones divided by the transmittance of the deep samples in front, so
  // that `over` gives back exactly the visible sums (see deep.h).
  sortPixel(out, tmp);
  const AlphaGroups groups(L);
  double T[4] = {1, 1, 1, 1};
  for (size_t i = 0; i < out.size(); ++i) {
    float* r = out.at(i);
    for (size_t g = 0; g < groups.groups.size(); ++g) {
      const auto& [al, cs] = groups.groups[g];
      const double visible = r[al];
      double alpha, scale;
      if (T[g] > 1e-9) {
        alpha = std::min(visible / T[g], 1.0), scale = 1.0 / T[g];
      } else {
        // Everything in front is opaque: what remains is below float resolution anyway.
        alpha = visible > 0 ? 1.0 : 0.0, scale = 0.0;
      }
      r[al] = float(alpha);
      for (int c : cs) r[c] = float(r[c] * scale);
      T[g] *= 1.0 - double(r[al]);
    }
  }
  // Keep that order through tidying: a volume sample ends where the next sample starts (only
  // surfaces passing through each other inside the pixel are affected), and samples at one
  // depth combine with `over` in the order used above, so nothing is left to split or merge.
  for (size_t i = 0; i + 1 < out.size(); ++i) {
    float* r = out.at(i);
    r[kDeepZBack] = std::min(r[kDeepZBack], std::max(r[kDeepZ], out.at(i + 1)[kDeepZ]));
  }
  size_t kept = 0;
  for (size_t i = 0; i < out.size(); ++i) {
    if (kept > 0 && out.at(i)[kDeepZ] == out.at(kept - 1)[kDeepZ] && out.at(i)[kDeepZBack] == out.at(kept - 1)[kDeepZBack]) {
      float* front = out.at(kept - 1);
      const float* back = out.at(i);
      if (back[kDeepA] > front[kDeepA]) std::copy(out.uat(i), out.uat(i) + out.nu, out.uat(kept - 1));
      for (const auto& [al, cs] : groups.groups) {
        const float t = 1.f - front[al];
        for (int c : cs) front[c] += t * back[c];
        front[al] += t * back[al];
      }
      continue;
    }
    if (kept != i) {
      std::copy(out.at(i), out.at(i) + out.nf, out.at(kept));
      std::copy(out.uat(i), out.uat(i) + out.nu, out.uat(kept));
    }
    ++kept;
  }
  out.f.resize(kept * size_t(out.nf)), out.u.resize(kept * size_t(out.nu));
}

// ---------------------------------------------------------------------------------------------
// Image

void DeepImage::reset(int x0_, int y0_, int width_, int height_, int fullWidth_, int fullHeight_, const DeepLayout& layout_, size_t blocks) {
  x0 = x0_, y0 = y0_, width = width_, height = height_, fullWidth = fullWidth_, fullHeight = fullHeight_;
  layout = layout_;
  tidy = true;
  blocks_.assign(blocks, Block{});
  pixels_.assign(size_t(width) * size_t(height), PixelRef{});
}

void DeepImage::setPixel(size_t b, int x, int y, const DeepPixel& px) {
  Block& bl = blocks_[b];
  PixelRef& r = pixels_[size_t(y - y0) * size_t(width) + size_t(x - x0)];
  r.block = uint32_t(b);
  r.first = uint32_t(bl.f.size() / size_t(layout.nf()));
  r.count = uint32_t(px.size());
  bl.f.insert(bl.f.end(), px.f.begin(), px.f.end());
  bl.u.insert(bl.u.end(), px.u.begin(), px.u.end());
}

void DeepImage::getPixel(int x, int y, DeepPixel& out) const {
  const PixelRef& r = ref(x, y);
  const int nf = layout.nf(), nu = layout.nu();
  out.nf = nf, out.nu = nu;
  if (r.count == 0) {
    out.clear();
    return;
  }
  const Block& bl = blocks_[r.block];
  out.f.assign(bl.f.begin() + ptrdiff_t(size_t(r.first) * nf), bl.f.begin() + ptrdiff_t(size_t(r.first + r.count) * nf));
  out.u.assign(bl.u.begin() + ptrdiff_t(size_t(r.first) * nu), bl.u.begin() + ptrdiff_t(size_t(r.first + r.count) * nu));
}

uint64_t DeepImage::totalSamples() const {
  uint64_t n = 0;
  for (const auto& p : pixels_) n += p.count;
  return n;
}

bool DeepImage::anyThick() const {
  const size_t nf = size_t(layout.nf());
  for (const auto& b : blocks_)
    for (size_t i = 0; i + nf <= b.f.size(); i += nf)
      if (b.f[i + kDeepZBack] > b.f[i + kDeepZ]) return true;
  return false;
}

bool DeepImage::anyColouredAlpha() const {
  const size_t nf = size_t(layout.nf());
  for (const auto& b : blocks_)
    for (size_t i = 0; i + nf <= b.f.size(); i += nf)
      if (b.f[i + kDeepAR] != b.f[i + kDeepAG] || b.f[i + kDeepAR] != b.f[i + kDeepAB]) return true;
  return false;
}

// ---------------------------------------------------------------------------------------------
// Former

struct DeepFormer::Impl {
  DeepImage& image;
  const FilterTable& table;
  const SamplePattern& pattern;
  DeepFormOptions options;
  struct Scratch {
    std::vector<std::pair<uint32_t, uint32_t>> slots;  // first fragment, count
    std::vector<SampleFragment> frags;
    std::vector<uint32_t> aovOffset;
    std::vector<float> aovF;
    std::vector<uint32_t> aovU;
    std::vector<int> patterns;
    std::vector<WeightedSample> weighted;
    DeepPixel pixel;
  };
  tbb::enumerable_thread_specific<Scratch> scratch;
  Impl(DeepImage& i, const FilterTable& t, const SamplePattern& p, const DeepFormOptions& o) : image(i), table(t), pattern(p), options(o) {}
};

DeepFormer::DeepFormer(DeepImage& image, const FilterTable& table, const SamplePattern& pattern, const DeepFormOptions& options)
    : impl_(std::make_unique<Impl>(image, table, pattern, options)) {}
DeepFormer::~DeepFormer() = default;

void DeepFormer::formBucket(BucketRasterizer& r, size_t b, int bx0, int by0, int bx1, int by1, int rx0, int ry0, int rw, int rh) {
  Impl& m = *impl_;
  Impl::Scratch& s = m.scratch.local();
  const DeepLayout& L = m.image.layout;
  const int N = m.pattern.spp();
  const size_t slots = size_t(rw) * size_t(rh) * size_t(N);
  s.slots.assign(slots, {0u, 0u});
  s.frags.clear(), s.aovOffset.clear(), s.aovF.clear(), s.aovU.clear();
  const size_t nfa = size_t(L.sourceFloats), nua = size_t(L.sourceUInts);
  // Copy the fragment lists: visitFragments' aov pointers may point at scratch it reuses.
  r.visitFragments([&](size_t slot, const SampleFragment* f, size_t count) {
    s.slots[slot] = {uint32_t(s.frags.size()), uint32_t(count)};
    for (size_t k = 0; k < count; ++k) {
      s.frags.push_back(f[k]);
      s.aovOffset.push_back(uint32_t(s.aovF.size()));
      if (nfa) s.aovF.insert(s.aovF.end(), f[k].aov, f[k].aov + nfa);
      if (nua) s.aovU.insert(s.aovU.end(), f[k].aovU, f[k].aovU + nua);
    }
  });
  for (size_t k = 0; k < s.frags.size(); ++k) {
    s.frags[k].aov = nfa ? s.aovF.data() + s.aovOffset[k] : nullptr;
    s.frags[k].aovU = nua ? s.aovU.data() + k * nua : nullptr;
  }
  s.patterns.resize(size_t(rw) * size_t(rh));
  for (int y = 0; y < rh; ++y)
    for (int x = 0; x < rw; ++x) s.patterns[size_t(y) * rw + x] = m.pattern.patternOf(rx0 + x, ry0 + y);
  const int mg = m.table.margin();
  for (int py = by0; py < by1; ++py)
    for (int px = bx0; px < bx1; ++px) {
      s.weighted.clear();
      double wsum = 0;
      for (int dy = -mg; dy <= mg; ++dy)
        for (int dx = -mg; dx <= mg; ++dx) {
          const size_t q = size_t(py - ry0 + dy) * rw + size_t(px - rx0 + dx);
          const float* wt = m.table.weights(s.patterns[q], dx, dy);
          for (int i = 0; i < N; ++i) {
            if (!(wt[i] > 0)) continue;  // negative lobes: see deep.h
            wsum += wt[i];
            const auto [first, count] = s.slots[q * N + size_t(i)];
            if (count) s.weighted.push_back({wt[i], s.frags.data() + first, count});
          }
        }
      if (!(wsum > 0)) {
        // No positive weight at all (cannot happen for the built-in filters): the pixel's own samples.
        s.weighted.clear();
        wsum = N;
        const size_t q = size_t(py - ry0) * rw + size_t(px - rx0);
        for (int i = 0; i < N; ++i) {
          const auto [first, count] = s.slots[q * N + size_t(i)];
          if (count) s.weighted.push_back({1.f, s.frags.data() + first, count});
        }
      }
      for (auto& w : s.weighted) w.weight = float(double(w.weight) / wsum);
      formDeepPixel(s.weighted.data(), s.weighted.size(), L, m.options, s.pixel);
      tidyDeepPixel(s.pixel, L);
      m.image.setPixel(b, px, py, s.pixel);
    }
}

std::map<uint32_t, std::string> objectNamesFromProvenance(const std::string& provenance) {
  std::map<uint32_t, std::string> names;
  const auto at = provenance.find("objects:");
  if (at == std::string::npos) return names;
  size_t p = at + 8;
  while (p < provenance.size()) {
    while (p < provenance.size() && provenance[p] == ' ') ++p;
    const size_t eq = provenance.find("=\"", p);
    if (eq == std::string::npos || eq == p) break;
    const size_t close = provenance.find('"', eq + 2);
    if (close == std::string::npos) break;
    uint32_t id = 0;
    bool digits = true;
    for (size_t i = p; i < eq; ++i) {
      if (provenance[i] < '0' || provenance[i] > '9') digits = false;
      else id = id * 10 + uint32_t(provenance[i] - '0');
    }
    if (!digits) break;
    names[id] = provenance.substr(eq + 2, close - eq - 2);
    p = close + 1;
  }
  return names;
}

// ---------------------------------------------------------------------------------------------
// Writer

DeepCompression parseDeepCompression(const std::string& s, const std::string& where) {
  if (s == "zips") return DeepCompression::Zips;
  if (s == "rle") return DeepCompression::Rle;
  if (s == "none") return DeepCompression::None;
  fail(where, "deep OpenEXR compression must be zips, rle or none (OpenEXR allows no other for deep data), got '", s, "'");
}

namespace {

struct DeepOut {
  std::string name;
  bool isUInt;
  int field;
};

/// The channels a deep file of `image` holds (writeDeepExr says which).
std::vector<DeepOut> deepChannels(const std::string& path, const DeepImage& image, const DeepExrOptions& options) {
  const DeepLayout& L = image.layout;
  std::vector<DeepOut> outs{{"R", false, kDeepR}, {"G", false, kDeepG}, {"B", false, kDeepB}, {"A", false, kDeepA}, {"Z", false, kDeepZ}};
  if (options.allChannels || image.anyThick()) outs.push_back({"ZBack", false, kDeepZBack});
  if (options.allChannels || image.anyColouredAlpha())
    for (auto [n, f] : {std::pair{"AR", kDeepAR}, {"AG", kDeepAG}, {"AB", kDeepAB}}) outs.push_back({n, false, f});
  for (size_t i = 0; i < L.floats.size(); ++i) outs.push_back({L.floats[i].name, false, kDeepFixedFloats + int(i)});
  outs.push_back({"objectid", true, kDeepObjectId});
  for (size_t i = 0; i < L.uints.size(); ++i) outs.push_back({L.uints[i].name, true, kDeepFixedUInts + int(i)});
  for (size_t i = 0; i < outs.size(); ++i)
    for (size_t j = 0; j < i; ++j)
      if (outs[i].name == outs[j].name) fail(path, "deep channel '", outs[i].name, "' named twice");
  return outs;
}

Imf::Header deepHeader(const DeepImage& image, const ImageProvenance& info, const DeepExrOptions& options, const std::vector<DeepOut>& outs) {
  const Imf::Compression comp = options.compression == DeepCompression::Zips  ? Imf::ZIPS_COMPRESSION
                                : options.compression == DeepCompression::Rle ? Imf::RLE_COMPRESSION
                                                                              : Imf::NO_COMPRESSION;
  Imath::Box2i display(Imath::V2i(0, 0), Imath::V2i(image.fullWidth - 1, image.fullHeight - 1));
  Imath::Box2i data(Imath::V2i(image.x0, image.y0), Imath::V2i(image.x0 + image.width - 1, image.y0 + image.height - 1));
  Imf::Header header(display, data, 1.0f, Imath::V2f(0, 0), 1.0f, Imf::INCREASING_Y, comp);
  header.setType(Imf::DEEPSCANLINE);
  for (const auto& o : outs) header.channels().insert(o.name, Imf::Channel(o.isUInt ? Imf::UINT : Imf::FLOAT));
  addProvenanceAttributes(header, info);
  if (image.tidy) Imf::addDeepImageState(header, Imf::DIS_TIDY);
  if (!image.objectNames.empty()) {
    Imf::IDManifest manifest;
    Imf::IDManifest::ChannelGroupManifest& g = manifest.add("objectid");
    g.setHashScheme(Imf::IDManifest::NOTHASHED);
    g.setEncodingScheme(Imf::IDManifest::ID_SCHEME);
    g.setLifetime(Imf::IDManifest::LIFETIME_SHOT);
    g.setComponent("object");
    for (const auto& [id, name] : image.objectNames) g.insert(uint64_t(id), name);
    Imf::addIDManifest(header, Imf::CompressedIDManifest(manifest));
  }
  return header;
}

/// Writes `image`'s samples through `out` (a deep scanline file or part), 32 rows at a time.
template <class Output>
void writeDeepPixels(Output& out, const DeepImage& image, const std::vector<DeepOut>& outs) {
  const DeepLayout& L = image.layout;
  const int W = image.width;
  const int chunk = 32;
  const size_t nf = size_t(L.nf()), nu = size_t(L.nu());
  std::vector<unsigned int> counts(size_t(W) * chunk);
  std::vector<std::vector<char*>> ptrs(outs.size(), std::vector<char*>(size_t(W) * chunk, nullptr));
  static float dummy[64];
  for (int ys = image.y0; ys < image.y0 + image.height; ys += chunk) {
    const int rows = std::min(chunk, image.y0 + image.height - ys);
    for (int y = ys; y < ys + rows; ++y)
      for (int x = image.x0; x < image.x0 + W; ++x) {
        const size_t i = size_t(y - ys) * W + size_t(x - image.x0);
        const DeepImage::PixelRef& r = image.ref(x, y);
        counts[i] = r.count;
        for (size_t c = 0; c < outs.size(); ++c) {
          if (r.count == 0) {
            ptrs[c][i] = reinterpret_cast<char*>(dummy);
            continue;
          }
          const DeepImage::Block& bl = image.block(r.block);
          ptrs[c][i] = outs[c].isUInt ? reinterpret_cast<char*>(const_cast<uint32_t*>(bl.u.data() + size_t(r.first) * nu + size_t(outs[c].field)))
                                      : reinterpret_cast<char*>(const_cast<float*>(bl.f.data() + size_t(r.first) * nf + size_t(outs[c].field)));
        }
      }
    // OpenEXR addresses pixels absolutely: shift the bases by the chunk's first pixel.
    const ptrdiff_t origin = ptrdiff_t(ys) * W + image.x0;
    Imf::DeepFrameBuffer fb;
    fb.insertSampleCountSlice(Imf::Slice(Imf::UINT, reinterpret_cast<char*>(counts.data() - origin), sizeof(unsigned int), sizeof(unsigned int) * size_t(W)));
    for (size_t c = 0; c < outs.size(); ++c)
      fb.insert(outs[c].name, Imf::DeepSlice(outs[c].isUInt ? Imf::UINT : Imf::FLOAT, reinterpret_cast<char*>(ptrs[c].data() - origin), sizeof(char*),
                                             sizeof(char*) * size_t(W), 4 * (outs[c].isUInt ? nu : nf)));
    out.setFrameBuffer(fb);
    out.writePixels(rows);
  }
}

// zlib dominates a deep write (ZIPS compresses every scanline separately): use every core.
int deepWriteThreads() { return int(std::max(1u, std::thread::hardware_concurrency())); }

}  // namespace

void writeDeepExr(const std::string& path, const DeepImage& image, const ImageProvenance& info, const DeepExrOptions& options) {
  if (image.width <= 0 || image.height <= 0) fail(path, "empty deep image");
  const std::vector<DeepOut> outs = deepChannels(path, image, options);
  const Imf::Header header = deepHeader(image, info, options, outs);
  AtomicFile file(path);
  try {
    Imf::DeepScanLineOutputFile out(file.tempPath().c_str(), header, deepWriteThreads());
    writeDeepPixels(out, image, outs);
  } catch (const std::exception& e) {
    fail(path, "OpenEXR deep write failed: ", e.what());
  }
  file.commit();
}

void writeMultiViewDeepExr(const std::string& path, const std::vector<DeepView>& views, const DeepExrOptions& options) {
  if (views.empty()) fail(path, "no view to write");
  std::vector<std::vector<DeepOut>> outs;
  std::vector<Imf::Header> headers;
  for (const DeepView& v : views) {
    if (v.image->width <= 0 || v.image->height <= 0) fail(path, "view '", v.name, "': empty deep image");
    for (const Imf::Header& h : headers)
      if (h.name() == v.name) fail(path, "view '", v.name, "' given twice");
    outs.push_back(deepChannels(path, *v.image, options));
    headers.push_back(deepHeader(*v.image, *v.info, options, outs.back()));
    headers.back().setName(v.name);
    headers.back().setView(v.name);
  }
  AtomicFile file(path);
  try {
    Imf::MultiPartOutputFile out(file.tempPath().c_str(), headers.data(), int(headers.size()), false, deepWriteThreads());
    for (size_t i = 0; i < views.size(); ++i) {
      Imf::DeepScanLineOutputPart part(out, int(i));
      writeDeepPixels(part, *views[i].image, outs[i]);
    }
  } catch (const std::exception& e) {
    fail(path, "OpenEXR deep write failed: ", e.what());
  }
  file.commit();
}

}  // namespace reshutter::resample
