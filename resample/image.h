// Flat images and their writers: OpenEXR (scanline; R G B A Z plus output variables as named
// layers, half or float per channel, any OpenEXR compression, the rendering's camera matrices and
// shutter in the header) and 8/16-bit previews (PNG or TIFF) quantised per the AOV reference:
// value = round(zero + v·(one − zero) + dither·ξ), clamped to [min, max], ξ ∈ [-1, 1).
// Every file is written atomically (temporary + rename).
#pragma once

#include <cstdint>
#include <memory>
#include <string>
#include <utility>
#include <vector>

#include <glm/mat4x4.hpp>

namespace reshutter::resample {

/// An allocator whose vectors leave new elements uninitialised unless given a value, so that an
/// image every pixel of which its renderer writes is not first zero-filled (and its pages
/// first touched) by one thread before the buckets start (FlatImage::add()).
template <class T>
struct UninitialisedAllocator : std::allocator<T> {
  template <class U>
  struct rebind {
    using other = UninitialisedAllocator<U>;
  };
  UninitialisedAllocator() = default;
  template <class U>
  UninitialisedAllocator(const UninitialisedAllocator<U>&) noexcept {}
  template <class U>
  void construct(U* p) noexcept {
    ::new (static_cast<void*>(p)) U;
  }
  template <class U, class... Args>
  void construct(U* p, Args&&... args) {
    ::new (static_cast<void*>(p)) U(std::forward<Args>(args)...);
  }
};
template <class T>
using PixelVector = std::vector<T, UninitialisedAllocator<T>>;

struct ImageChannel {
  std::string name;  // "R", "A", "Z", "N.X", "id"
  bool isUInt = false;
  bool half = false;  // written as half (float channels only)
  PixelVector<float> f;
  PixelVector<uint32_t> u;
};

/// A flat image: the data window [x0, x0+width) × [y0, y0+height) of a fullWidth × fullHeight
/// display window.
struct FlatImage {
  int x0 = 0, y0 = 0, width = 0, height = 0;
  int fullWidth = 0, fullHeight = 0;
  std::vector<ImageChannel> channels;
  ImageChannel* find(const std::string& name);
  const ImageChannel* find(const std::string& name) const;
  /// A channel of width × height pixels, zero unless `uninitialised`: then every pixel is the
  /// caller's to write before anything reads it.
  ImageChannel& add(const std::string& name, bool isUInt = false, bool uninitialised = false);
};

/// What the image header records about how it was made.
struct ImageProvenance {
  /// Column-vector matrices (glm convention); the writer stores them in OpenEXR's row-vector form.
  glm::dmat4 worldToCamera{1.0};
  glm::dmat4 worldToNdc{1.0};  // homogeneous: NDC = (M·p).xy / (M·p).w, (0,0) top-left of the display window
  int64_t frame = 1;
  int64_t fpsNum = 24, fpsDen = 1;
  std::string shutter;                       // human-readable shutter description
  double shutterOpen = 0, shutterClose = 0;  // frames, overall
  std::string software = "reshutter 0.1.0";
  std::string comments;
};

enum class ExrCompression { None, Rle, Zips, Zip, Piz, Pxr24, B44, B44a, Dwaa, Dwab };
ExrCompression parseExrCompression(const std::string& s, const std::string& where);

struct ExrOptions {
  // PIZ by default: on 16-sample float renders it writes ~40 % faster than ZIP, makes files ~10 %
  // smaller and reads about as fast (bench/exr_codec_bench, bench/RESULTS.md).
  ExrCompression compression = ExrCompression::Piz;
};

/// Writes a scanline OpenEXR. Throws Error naming the file on failure; nothing is left under
/// `path` unless the write completes.
void writeExr(const std::string& path, const FlatImage& image, const ImageProvenance& info, const ExrOptions& options = {});
/// One view of a multi-view image: its name ("left") and the image rendered from it.
struct ExrView {
  std::string name;
  const FlatImage* image = nullptr;
  const ImageProvenance* info = nullptr;
};
/// The name of `channel` in view `view` of a multi-view file (OpenEXR's convention: the view is the
/// next-to-last component): R → right.R, N.X → N.right.X.
std::string viewChannelName(const std::string& channel, const std::string& view);
/// Writes `views` as one multi-view OpenEXR (the `multiView` attribute, as Nuke and OpenImageIO
/// read it): the first is the default view, its channels named as writeExr names them, its
/// matrices the standard worldToCamera / worldToNDC; each other view's channels carry its name
/// (viewChannelName), its matrices go in reshutter/VIEW/worldToCamera and .../worldToNDC. The
/// views must share the data and display windows. Atomic, like writeExr.
void writeMultiViewExr(const std::string& path, const std::vector<ExrView>& views, const ExrOptions& options = {});
/// Threads OpenEXR compresses (and decompresses) chunks with, flat and deep; 0 = none (the
/// calling thread does it all). The file's bytes do not depend on it.
void setExrThreads(int threads);

struct Quantize {
  double zero = 0, one = 255, min = 0, max = 255;
  double dither = 0.5;
  int bits() const { return max > 255 ? 16 : 8; }
};

/// Writes channels (1 = grey, 3 = RGB, 4 = RGBA) as PNG or TIFF by extension. Colour channels
/// are un-premultiplied by `alpha` when it is given (previews use straight alpha).
void writePreview(const std::string& path, const FlatImage& image, const std::vector<std::string>& channels, const Quantize& q, uint64_t seed);

}  // namespace reshutter::resample
