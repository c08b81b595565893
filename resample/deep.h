// Deep output: the deep image container, deep sample formation from the rasterizer's fragments,
// tidying (sort, split and merge per "Interpreting OpenEXR Deep Pixels"), flattening (the
// reference the tests hold the flat image to) and the scanline deep OpenEXR writer.
//
// Sample formation (see docs/deep.md for the derivation):
//  - Weights. Every sample that the flat pixel filter gives a positive weight contributes, the
//    neighbouring pixels' samples included, with weight w = f / Σ f over the pixel's support
//    (Σ w = 1, the samples that saw nothing included). Negative filter lobes (catmull-rom, sinc,
//    mitchell) are clamped to zero before normalising, because a deep alpha must stay in [0, 1]:
//    for those filters the deep image flattens to the image made with the filter's positive part.
//  - Surfaces. A sample's fragments are grouped by (object id, matte) and, within one object, by
//    depth: fragments chain into one deep sample while the gap to the next depth is at most
//    tolerance · depth (single linkage), so a tilted or moving surface stays one sample however
//    far its depth drifts across the pixel and the shutter, while two layers of one object further
//    apart than the tolerance stay separate. Two halves of an opaque surface are one sample.
//  - Values. Each group gets what it adds to the flat pixel: its visible colour V = Σ w·T·c and
//    visible alpha a = Σ w·T·o over its fragments, T being the transmittance in front of the
//    fragment in its own pixel sample (per channel). In depth order, the deep sample then stores
//    α = a / T_deep and C = V / T_deep, T_deep the transmittance of the deep samples in front
//    (T_deep = 1 − Σ a of those in front). `over` of the samples gives back Σ V and Σ a: the
//    flat image, to float rounding. Where the surfaces of a pixel cover it independently of each
//    other (a translucent card over a background that fills the pixel), a/T_deep is simply
//    coverage · opacity, the textbook deep alpha; where coverages are correlated (disjoint
//    motion-blur streaks, a surface hidden behind part of another) plain coverage alphas would
//    flatten wrong (the over-versus-sum error); this form is exact for flattening, and also
//    right in those cases when another deep image is merged in between or behind, at the price
//    that deleting the samples in front of a surface does not reveal its true coverage. Sample
//    alphas never exceed 1 because Σ a ≤ 1.
//  - Depth. Z and ZBack are the group's nearest and farthest fragment depth: a group whose
//    fragments all lie at one depth is a point sample, otherwise a volume sample. Where surfaces
//    pass through each other inside a pixel their depth ranges overlap; the front sample's ZBack
//    is then cut back to where the next one starts, so the image is tidy in exactly the order the
//    alphas were computed in and flattens exactly (Hillman's split-and-merge would redistribute
//    alpha by depth and undo that). Samples at one depth combine with `over`. tidyDeepPixel
//    (split and merge) still runs on every pixel and is what any other input gets.
//  - Matte objects become samples like any surface but with RGB = 0 (A as above), so a deep merge
//    cuts out whatever lies behind them, and carry the OpenDCX matte flag internally. The flat
//    image leaves matte coverage out of alpha; flattenDeepPixel(matteAware = true) does the same.
//  - Output variables: composited ones (pixel-filtered) are premultiplied like colour; special-
//    filtered ones (min max average zmin zmax) and ids hold the value of the group's nearest
//    fragment. The object id is always written, as the uint channel `objectid`.
#pragma once

#include <cstdint>
#include <map>
#include <memory>
#include <string>
#include <vector>

#include "resample/image.h"
#include "resample/raster.h"

namespace reshutter::resample {

/// Float fields of a sample record, then the layout's float output variables.
enum DeepField : int { kDeepZ = 0, kDeepZBack, kDeepR, kDeepG, kDeepB, kDeepA, kDeepAR, kDeepAG, kDeepAB, kDeepFixedFloats };
/// Uint fields of a sample record, then the layout's uint output variables.
enum DeepUField : int { kDeepFlags = 0, kDeepObjectId, kDeepFixedUInts };
/// Sample flags, OpenDCX's values (spmask.flags).
constexpr uint32_t kDeepFlagMatte = 0x2;

/// Which output variables a deep image carries and where their values come from.
struct DeepLayout {
  struct Aux {
    std::string name;           // channel name
    int source = 0;             // index into SampleFragment::aov (float) or ::aovU (uint)
    bool premultiplied = true;  // float only: composited (premultiplied by A) or the nearest value
  };
  std::vector<Aux> floats, uints;
  /// Sizes of SampleFragment's aov / aovU arrays (every requested output variable).
  int sourceFloats = 0, sourceUInts = 0;
  int nf() const { return kDeepFixedFloats + int(floats.size()); }
  int nu() const { return kDeepFixedUInts + int(uints.size()); }
};

/// The samples of one pixel as two record arrays: nf floats and nu uints per sample.
struct DeepPixel {
  int nf = kDeepFixedFloats, nu = kDeepFixedUInts;
  std::vector<float> f;
  std::vector<uint32_t> u;
  size_t size() const { return nf ? f.size() / size_t(nf) : 0; }
  void clear() { f.clear(), u.clear(); }
  float* at(size_t i) { return f.data() + i * size_t(nf); }
  const float* at(size_t i) const { return f.data() + i * size_t(nf); }
  uint32_t* uat(size_t i) { return u.data() + i * size_t(nu); }
  const uint32_t* uat(size_t i) const { return u.data() + i * size_t(nu); }
  /// Appends a zeroed sample and returns its index.
  size_t add();
};

// ---------------------------------------------------------------------------------------------
// Alpha arithmetic ("Interpreting OpenEXR Deep Pixels"), in double with its guards near 0 and 1.

/// Alpha of the fraction x ∈ [0, 1] of a volume sample of alpha a: -expm1(x·log1p(-a)).
double deepSplitAlpha(double a, double x);
/// Factor for the premultiplied channels of that fraction: α'/α, or x where α is too small to
/// divide by; 1 for an opaque sample (its colour sits at its front).
double deepSplitScale(double a, double x);
/// Merges n coincident samples of one alpha channel: α = 1 − Π(1 − αᵢ); each colour channel
/// k ∈ [0, m) of the premultiplied values c[i·m + k] combines by the log-weighted rule
/// c = α/U · Σ cᵢ·uᵢ/αᵢ, U = Σuᵢ, uᵢ = −log1p(−αᵢ); opaque inputs (α = 1) win, averaged.
void deepMergeAlphas(const double* alphas, const double* colours, size_t n, size_t m, double& alphaOut, double* coloursOut);

/// Makes a pixel tidy: removes empty samples (alpha and every premultiplied value zero), clamps
/// alphas to [0, 1] and non-finite values to 0, splits volume samples at every other sample's
/// Z and ZBack, merges samples with identical Z and ZBack, sorts by (Z, ZBack).
void tidyDeepPixel(DeepPixel& px, const DeepLayout& layout);
/// Whether a pixel satisfies OpenEXR's TIDY (sorted, non-overlapping; see ImfDeepImageState.h).
bool isTidy(const DeepPixel& px);

/// Flattened pixel: R G B A, then one value per premultiplied float output variable.
struct FlatDeepPixel {
  double r = 0, g = 0, b = 0, a = 0;
  std::vector<double> aux;
};
/// Composites a tidy pixel front to back (`over`; R G B with AR AG AB, the rest with A).
/// matteAware: matte samples attenuate what lies behind but add no alpha (the flat image's rule).
FlatDeepPixel flattenDeepPixel(const DeepPixel& px, const DeepLayout& layout, bool matteAware);

// ---------------------------------------------------------------------------------------------
// Formation

/// One pixel sample's fragments (front to back, from BucketRasterizer::visitFragments) and its
/// normalised filter weight for the pixel being formed.
struct WeightedSample {
  float weight = 0;
  const SampleFragment* fragments = nullptr;
  size_t count = 0;
};

struct DeepFormOptions {
  /// Relative depth gap below which fragments of one object chain into one deep sample.
  float tolerance = 0.01f;
};

/// Forms one pixel's deep samples (not yet tidy) from its weighted samples.
void formDeepPixel(const WeightedSample* samples, size_t n, const DeepLayout& layout, const DeepFormOptions& options, DeepPixel& out);

// ---------------------------------------------------------------------------------------------
// Image

/// A deep image over the data window [x0, x0+width) × [y0, y0+height). Samples live in blocks
/// (one per render bucket, so buckets fill the image in parallel without locking); each pixel
/// refers to a run of records in one block.
class DeepImage {
 public:
  int x0 = 0, y0 = 0, width = 0, height = 0, fullWidth = 0, fullHeight = 0;
  DeepLayout layout;
  bool tidy = true;  // every pixel tidy: the writer then says so in deepImageState
  /// Names of object ids for the idManifest; empty: no manifest.
  std::map<uint32_t, std::string> objectNames;

  struct Block {
    std::vector<float> f;
    std::vector<uint32_t> u;
  };
  struct PixelRef {
    uint32_t block = 0, first = 0, count = 0;
  };

  void reset(int x0, int y0, int width, int height, int fullWidth, int fullHeight, const DeepLayout& layout, size_t blocks);
  /// Appends pixel (x, y)'s samples to block b. Safe in parallel for distinct blocks and pixels.
  void setPixel(size_t b, int x, int y, const DeepPixel& px);
  /// Copies pixel (x, y) out.
  void getPixel(int x, int y, DeepPixel& out) const;
  const PixelRef& ref(int x, int y) const { return pixels_[size_t(y - y0) * size_t(width) + size_t(x - x0)]; }
  const Block& block(size_t b) const { return blocks_[b]; }
  size_t blockCount() const { return blocks_.size(); }
  uint64_t totalSamples() const;
  /// Whether any sample has thickness (ZBack > Z) / coloured alpha (AR, AG, AB not all equal).
  bool anyThick() const;
  bool anyColouredAlpha() const;

 private:
  std::vector<Block> blocks_;
  std::vector<PixelRef> pixels_;
};

/// Forms the deep pixels of render buckets: owns per-thread scratch; one per render.
class DeepFormer {
 public:
  DeepFormer(DeepImage& image, const FilterTable& table, const SamplePattern& pattern, const DeepFormOptions& options);
  ~DeepFormer();
  /// After r.rasterize(): forms the pixels [bx0, bx1) × [by0, by1) of bucket `b` from the
  /// samples of the rasterizer's region (rx0, ry0, rw, rh), which includes the filter margin.
  void formBucket(BucketRasterizer& r, size_t b, int bx0, int by0, int bx1, int by1, int rx0, int ry0, int rw, int rh);

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

/// Object names recorded by the shading pass in a store's provenance ("...; objects: 1=\"floor\"
/// 2=\"ball\""); empty when there are none. Feeds the deep idManifest.
std::map<uint32_t, std::string> objectNamesFromProvenance(const std::string& provenance);

// ---------------------------------------------------------------------------------------------
// Writer

enum class DeepCompression { Zips, Rle, None };
DeepCompression parseDeepCompression(const std::string& s, const std::string& where);

struct DeepExrOptions {
  DeepCompression compression = DeepCompression::Zips;
  /// Write ZBack and AR AG AB even where no sample needs them: for crop tiles that are assembled
  /// later (resample/assemble.h), whose whole image may need them where the tile does not.
  bool allChannels = false;
};

/// Writes a scanline deep OpenEXR: R G B A Z, ZBack if any sample is thick, AR AG AB if any
/// opacity is coloured (both always with allChannels), the output variables, objectid (uint), idManifest if names are known,
/// deepImageState TIDY when the image is tidy, and the provenance of the flat image. Atomic;
/// throws Error naming the file.
void writeDeepExr(const std::string& path, const DeepImage& image, const ImageProvenance& info, const DeepExrOptions& options = {});

/// One view of a stereo or multi-camera deep image.
struct DeepView {
  std::string name;
  const DeepImage* image = nullptr;
  const ImageProvenance* info = nullptr;
};
/// Writes `views` as one multi-part deep OpenEXR, a part per view named after it with its `view`
/// attribute (OpenEXR's multi-part form of multi-view, which Nuke's DeepRead takes), each part
/// as writeDeepExr writes a single view. Atomic; throws Error naming the file.
void writeMultiViewDeepExr(const std::string& path, const std::vector<DeepView>& views, const DeepExrOptions& options = {});

}  // namespace reshutter::resample
