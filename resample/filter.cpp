#include "resample/filter.h"

#include <algorithm>
#include <cmath>
#include <sstream>

#include "common/error.h"

namespace reshutter::resample {

namespace {
struct NamedKind {
  const char* name;
  FilterKind kind;
};
constexpr NamedKind kNames[] = {
    {"box", FilterKind::Box},           {"triangle", FilterKind::Triangle},
    {"gaussian", FilterKind::Gaussian}, {"catmull-rom", FilterKind::CatmullRom},
    {"sinc", FilterKind::Sinc},         {"blackman-harris", FilterKind::BlackmanHarris},
    {"mitchell", FilterKind::Mitchell}, {"min", FilterKind::Min},
    {"max", FilterKind::Max},           {"average", FilterKind::Average},
    {"zmin", FilterKind::ZMin},         {"zmax", FilterKind::ZMax},
};

double sincPi(double x) { return std::abs(x) < 1e-7 ? 1.0 : std::sin(M_PI * x) / (M_PI * x); }

// Mitchell-Netravali cubic, B = C = 1/3, on its natural support |x| < 2.
double mitchell(double x) {
  constexpr double B = 1.0 / 3.0, C = 1.0 / 3.0;
  x = std::abs(x);
  if (x < 1) return ((12 - 9 * B - 6 * C) * x * x * x + (-18 + 12 * B + 6 * C) * x * x + (6 - 2 * B)) / 6;
  if (x < 2) return ((-B - 6 * C) * x * x * x + (6 * B + 30 * C) * x * x + (-12 * B - 48 * C) * x + (8 * B + 24 * C)) / 6;
  return 0;
}

// Catmull-Rom cubic on its natural support |x| < 2 (RenderMan's RiCatmullRomFilter, per axis).
double catmullRom(double x) {
  x = std::abs(x);
  if (x < 1) return 1.5 * x * x * x - 2.5 * x * x + 1;
  if (x < 2) return -0.5 * x * x * x + 2.5 * x * x - 4 * x + 2;
  return 0;
}
}  // namespace

const char* filterName(FilterKind k) {
  for (const auto& n : kNames)
    if (n.kind == k) return n.name;
  return "?";
}

float defaultFilterWidth(FilterKind k) {
  switch (k) {
    case FilterKind::Box: return 1;
    case FilterKind::Triangle: return 2;
    case FilterKind::Gaussian: return 2;
    case FilterKind::CatmullRom: return 4;
    case FilterKind::Sinc: return 4;
    case FilterKind::BlackmanHarris: return 3;
    case FilterKind::Mitchell: return 4;
    default: return 1;
  }
}

std::string FilterSpec::str() const {
  std::ostringstream s;
  s << filterName(kind);
  if (!special()) s << ":" << width << "x" << height;
  return s.str();
}

FilterSpec FilterSpec::parse(const std::string& text, const std::string& where) {
  FilterSpec spec;
  std::string name = text, size;
  if (auto colon = text.find(':'); colon != std::string::npos) name = text.substr(0, colon), size = text.substr(colon + 1);
  bool found = false;
  for (const auto& n : kNames)
    if (name == n.name) spec.kind = n.kind, found = true;
  if (!found) {
    std::string list;
    for (const auto& n : kNames) list += std::string(list.empty() ? "" : ", ") + n.name;
    fail(where, "unknown filter '", name, "' (", list, ")");
  }
  spec.width = spec.height = defaultFilterWidth(spec.kind);
  if (!size.empty()) {
    try {
      size_t used = 0;
      auto x = size.find('x');
      spec.width = std::stof(size.substr(0, x), &used);
      spec.height = x == std::string::npos ? spec.width : std::stof(size.substr(x + 1));
    } catch (const std::exception&) {
      fail(where, "filter size '", size, "' is not WIDTH or WIDTHxHEIGHT");
    }
    if (!(spec.width > 0 && spec.height > 0 && spec.width <= 16 && spec.height <= 16))
      fail(where, "filter width must be in (0, 16] pixels, got ", spec.width, "x", spec.height);
  }
  return spec;
}

float filter1D(FilterKind k, float xf, float width) {
  const double r = width / 2.0, x = xf;
  if (std::abs(x) > r) return 0.0f;
  const double u = x / r;  // [-1, 1] across the support
  switch (k) {
    case FilterKind::Box: return 1.0f;
    case FilterKind::Triangle: return float(1.0 - std::abs(u));
    case FilterKind::Gaussian: return float(std::exp(-2.0 * u * u));  // RenderMan: exp(-2 (2x/width)^2)
    case FilterKind::CatmullRom: return float(catmullRom(2.0 * u));
    case FilterKind::Sinc: return float(sincPi(x) * sincPi(u));  // Lanczos window over the support
    case FilterKind::BlackmanHarris: {
      const double n = 0.5 * (u + 1.0);
      return float(0.35875 - 0.48829 * std::cos(2 * M_PI * n) + 0.14128 * std::cos(4 * M_PI * n) - 0.01168 * std::cos(6 * M_PI * n));
    }
    case FilterKind::Mitchell: return float(mitchell(2.0 * u));
    default: return std::abs(x) <= 0.5 ? 1.0f : 0.0f;
  }
}

FilterTable::FilterTable(const FilterSpec& spec, const SamplePattern& pattern) : spp_(pattern.spp()) {
  const float rx = spec.special() ? 0.5f : spec.width / 2, ry = spec.special() ? 0.5f : spec.height / 2;
  margin_ = int(std::ceil(std::max(rx, ry) - 0.5f));
  if (margin_ < 0) margin_ = 0;
  const int s = span();
  weights_.assign(size_t(SamplePattern::kPatterns) * s * s * spp_, 0.0f);
  sums_.assign(size_t(SamplePattern::kPatterns) * s * s, 0.0f);
  for (int p = 0; p < SamplePattern::kPatterns; ++p)
    for (int dy = -margin_; dy <= margin_; ++dy)
      for (int dx = -margin_; dx <= margin_; ++dx) {
        float* w = const_cast<float*>(weights(p, dx, dy));
        double sum = 0;
        for (int i = 0; i < spp_; ++i) {
          glm::vec2 o = pattern.offset(p, i);
          // Offset of the sample from the target pixel's centre.
          float ox = float(dx) + o.x - 0.5f, oy = float(dy) + o.y - 0.5f;
          if (spec.special()) {
            w[i] = (dx == 0 && dy == 0) ? 1.0f : 0.0f;
          } else {
            w[i] = filter1D(spec.kind, ox, spec.width) * filter1D(spec.kind, oy, spec.height);
          }
          sum += w[i];
        }
        sums_[(size_t(p) * s + size_t(dy + margin_)) * s + size_t(dx + margin_)] = float(sum);
      }
}

namespace {

// accumulateTaps() for a fixed channel count and, when NN > 0, a fixed sample count: the loops
// unroll and the sums live in registers, not in the caller's arrays.
template <int NC, int NN>
inline __attribute__((always_inline)) void accumulateFixed(int nRuntime, const float* const* in, const float* const* w, const size_t* offset, int taps,
                                                           float lanes[8][8], float tail[8]) {
  constexpr int kLanes = 8;
  const int n = NN > 0 ? NN : nRuntime;
  const int vecN = n / kLanes * kLanes;
  float acc[NC][kLanes], rest[NC];
  for (int c = 0; c < NC; ++c) {
    for (int k = 0; k < kLanes; ++k) acc[c][k] = lanes[c][k];
    rest[c] = tail[c];
  }
  for (int j = 0; j < taps; ++j) {
    const float* wt = w[j];
    for (int c = 0; c < NC; ++c) {
      const float* v = in[c] + offset[j];
      for (int i = 0; i < vecN; i += kLanes)
        for (int k = 0; k < kLanes; ++k) acc[c][k] += wt[i + k] * v[i + k];
      for (int i = vecN; i < n; ++i) rest[c] += wt[i] * v[i];
    }
  }
  for (int c = 0; c < NC; ++c) {
    for (int k = 0; k < kLanes; ++k) lanes[c][k] = acc[c][k];
    tail[c] = rest[c];
  }
}

// accumulateFixed<4, 16>() with the four channels' sums held in four vectors of eight and each
// tap's two weight vectors loaded once for all channels; GCC kept the generic loop's sums in
// memory and reloaded the weights per channel (536 instructions a pixel at 9 taps; this: ~190).
// Every lane adds the same products in the same order (tap by tap, samples 0-7 then 8-15), so the
// sums are bit-identical to the generic loop's.
// The loads return vectors by value; inlined, so no call ever passes one (GCC's -Wpsabi note
// about the non-AVX clone's calling convention does not apply).
#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Wpsabi"
inline __attribute__((always_inline)) void accumulateRgba16(const float* const* in, const float* const* w, const size_t* offset, int taps, float lanes[8][8]) {
  typedef float Vec8 __attribute__((vector_size(32)));
  auto load = [](const float* p) {
    Vec8 v;
    __builtin_memcpy(&v, p, sizeof v);
    return v;
  };
  Vec8 acc0 = load(lanes[0]), acc1 = load(lanes[1]), acc2 = load(lanes[2]), acc3 = load(lanes[3]);
  const float *in0 = in[0], *in1 = in[1], *in2 = in[2], *in3 = in[3];
  for (int j = 0; j < taps; ++j) {
    const Vec8 w0 = load(w[j]), w1 = load(w[j] + 8);
    const size_t o = offset[j];
    acc0 += w0 * load(in0 + o), acc0 += w1 * load(in0 + o + 8);
    acc1 += w0 * load(in1 + o), acc1 += w1 * load(in1 + o + 8);
    acc2 += w0 * load(in2 + o), acc2 += w1 * load(in2 + o + 8);
    acc3 += w0 * load(in3 + o), acc3 += w1 * load(in3 + o + 8);
  }
  __builtin_memcpy(lanes[0], &acc0, sizeof acc0), __builtin_memcpy(lanes[1], &acc1, sizeof acc1);
  __builtin_memcpy(lanes[2], &acc2, sizeof acc2), __builtin_memcpy(lanes[3], &acc3, sizeof acc3);
}
#pragma GCC diagnostic pop

}  // namespace

#if defined(__x86_64__) && !defined(__clang__)
__attribute__((target_clones("avx2", "default")))
#endif
void accumulateTaps(int n, int nc, const float* const* in, const float* const* w, const size_t* offset, int taps, float lanes[8][8], float tail[8]) {
  if (n == 16 && nc == 4) return accumulateRgba16(in, w, offset, taps, lanes);  // RGBA at 16 spp, the common case (no tail)
  // Channels never mix, so up to four at a time give the same sums.
  for (int c = 0; c < nc; c += 4) {
    switch (std::min(4, nc - c)) {
      case 1: accumulateFixed<1, 0>(n, in + c, w, offset, taps, lanes + c, tail + c); break;
      case 2: accumulateFixed<2, 0>(n, in + c, w, offset, taps, lanes + c, tail + c); break;
      case 3: accumulateFixed<3, 0>(n, in + c, w, offset, taps, lanes + c, tail + c); break;
      default: accumulateFixed<4, 0>(n, in + c, w, offset, taps, lanes + c, tail + c); break;
    }
  }
}

}  // namespace reshutter::resample
