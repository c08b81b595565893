// Helpers of the deep-output tests (deep_test.cpp, deep_units_test.cpp): the documented merge
// rule written out independently, and deep samples and sample fragments made by hand.
#pragma once

#include <cmath>
#include <cstdint>
#include <vector>

#include "resample/deep.h"

namespace reshutter::test::deep {

using namespace reshutter::resample;

// The documented merge of coincident samples (deep.h): α = 1 − Π(1 − αᵢ) and, for colour,
// c = α/U · Σ cᵢ·uᵢ/αᵢ with uᵢ = −log(1 − αᵢ), U = Σ uᵢ - written out here in long double.
inline double logWeightedColour(const std::vector<double>& alphas, const std::vector<double>& colours) {
  long double U = 0, sum = 0, T = 1;
  for (size_t i = 0; i < alphas.size(); ++i) {
    const long double u = -std::log1p(-(long double)alphas[i]);
    U += u, sum += colours[i] * u / alphas[i], T *= 1 - (long double)alphas[i];
  }
  return double((1 - T) / U * sum);
}

inline DeepLayout plainLayout() { return DeepLayout{}; }

inline void addSample(DeepPixel& px, float z, float zb, float a, float c, uint32_t object = 1) {
  const size_t i = px.add();
  float* r = px.at(i);
  r[kDeepZ] = z, r[kDeepZBack] = zb;
  r[kDeepR] = r[kDeepG] = r[kDeepB] = c;
  r[kDeepA] = r[kDeepAR] = r[kDeepAG] = r[kDeepAB] = a;
  px.uat(i)[kDeepObjectId] = object;
}

inline SampleFragment frag(float z, float o, float c, uint32_t object, bool matte = false) {
  SampleFragment f;
  f.z = z;
  for (int k = 0; k < 3; ++k) f.o[k] = o, f.c[k] = matte ? 0.f : c * o;
  f.objectId = object, f.gridId = object;
  f.matte = matte;
  return f;
}

}  // namespace reshutter::test::deep
