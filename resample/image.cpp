#include "resample/image.h"

#include <algorithm>
#include <cmath>
#include <csetjmp>
#include <filesystem>
#include <functional>
#include <limits>

#include <Imath/half.h>
#include <OpenEXR/ImfChannelList.h>
#include <OpenEXR/ImfDoubleAttribute.h>
#include <OpenEXR/ImfFrameBuffer.h>
#include <OpenEXR/ImfHeader.h>
#include <OpenEXR/ImfIntAttribute.h>
#include <OpenEXR/ImfMatrixAttribute.h>
#include <OpenEXR/ImfMultiView.h>
#include <OpenEXR/ImfOutputFile.h>
#include <OpenEXR/ImfStandardAttributes.h>
#include <OpenEXR/ImfStringAttribute.h>
#include <OpenEXR/ImfThreading.h>
#include <OpenEXR/ImfVecAttribute.h>
#include <png.h>
#include <tiffio.h>

#include "common/atomic_file.h"
#include "common/error.h"
#include "common/random.h"
#include "resample/exr_header.h"

namespace reshutter::resample {

ImageChannel* FlatImage::find(const std::string& name) {
  for (auto& c : channels)
    if (c.name == name) return &c;
  return nullptr;
}
const ImageChannel* FlatImage::find(const std::string& name) const {
  for (const auto& c : channels)
    if (c.name == name) return &c;
  return nullptr;
}
ImageChannel& FlatImage::add(const std::string& name, bool isUInt, bool uninitialised) {
  ImageChannel c;
  c.name = name;
  c.isUInt = isUInt;
  const size_t n = size_t(width) * size_t(height);
  if (uninitialised) {
#if defined(__SANITIZE_ADDRESS__)
    // Under the sanitizers (every CI run) an uninitialised channel starts as NaN or 0xDEADBEEF, so
    // that a pixel its caller fails to write shows in every test that reads the image.
    isUInt ? c.u.assign(n, 0xDEADBEEFu) : c.f.assign(n, std::numeric_limits<float>::quiet_NaN());
#else
    isUInt ? c.u.resize(n) : c.f.resize(n);
#endif
  } else if (isUInt) {
    c.u.assign(n, 0u);
  } else {
    c.f.assign(n, 0.0f);
  }
  channels.push_back(std::move(c));
  return channels.back();
}

void setExrThreads(int threads) { Imf::setGlobalThreadCount(threads); }

ExrCompression parseExrCompression(const std::string& s, const std::string& where) {
  static const std::pair<const char*, ExrCompression> names[] = {
      {"none", ExrCompression::None}, {"rle", ExrCompression::Rle},     {"zips", ExrCompression::Zips}, {"zip", ExrCompression::Zip},
      {"piz", ExrCompression::Piz},   {"pxr24", ExrCompression::Pxr24}, {"b44", ExrCompression::B44},   {"b44a", ExrCompression::B44a},
      {"dwaa", ExrCompression::Dwaa}, {"dwab", ExrCompression::Dwab}};
  for (auto [n, c] : names)
    if (s == n) return c;
  fail(where, "unknown OpenEXR compression '", s, "' (none rle zips zip piz pxr24 b44 b44a dwaa dwab)");
}

namespace {

Imf::Compression toImf(ExrCompression c) {
  switch (c) {
    case ExrCompression::None: return Imf::NO_COMPRESSION;
    case ExrCompression::Rle: return Imf::RLE_COMPRESSION;
    case ExrCompression::Zips: return Imf::ZIPS_COMPRESSION;
    case ExrCompression::Zip: return Imf::ZIP_COMPRESSION;
    case ExrCompression::Piz: return Imf::PIZ_COMPRESSION;
    case ExrCompression::Pxr24: return Imf::PXR24_COMPRESSION;
    case ExrCompression::B44: return Imf::B44_COMPRESSION;
    case ExrCompression::B44a: return Imf::B44A_COMPRESSION;
    case ExrCompression::Dwaa: return Imf::DWAA_COMPRESSION;
    case ExrCompression::Dwab: return Imf::DWAB_COMPRESSION;
  }
  return Imf::ZIP_COMPRESSION;
}

// glm (column vectors) → Imath (row vectors): the same element indices.
Imath::M44f toImath(const glm::dmat4& m) {
  Imath::M44f r;
  for (int i = 0; i < 4; ++i)
    for (int j = 0; j < 4; ++j) r[i][j] = float(m[i][j]);
  return r;
}

}  // namespace

void addProvenanceAttributes(Imf::Header& header, const ImageProvenance& info) {
  Imf::addWorldToCamera(header, toImath(info.worldToCamera));
  Imf::addWorldToNDC(header, toImath(info.worldToNdc));
  Imf::addFramesPerSecond(header, Imf::Rational(int(info.fpsNum), unsigned(info.fpsDen)));
  if (info.fpsNum > 0) Imf::addExpTime(header, float((info.shutterClose - info.shutterOpen) * double(info.fpsDen) / double(info.fpsNum)));
  header.insert("software", Imf::StringAttribute(info.software));
  header.insert("reshutter/frame", Imf::IntAttribute(int(info.frame)));
  header.insert("reshutter/shutter", Imf::StringAttribute(info.shutter));
  header.insert("reshutter/shutterInterval", Imf::V2dAttribute(Imath::V2d(info.shutterOpen, info.shutterClose)));
  if (!info.comments.empty()) Imf::addComments(header, info.comments);
}

namespace {

// Adds `image`'s channels to `header` and `fb`, each under name(channel name); half channels are
// converted into `halves`, which must outlive the write.
void addChannels(const FlatImage& image, Imf::Header& header, Imf::FrameBuffer& fb, std::vector<std::vector<Imath::half>>& halves,
                 const std::function<std::string(const std::string&)>& name) {
  const size_t xs = 1, ys = size_t(image.width);
  for (const auto& c : image.channels) {
    Imf::PixelType type = c.isUInt ? Imf::UINT : (c.half ? Imf::HALF : Imf::FLOAT);
    const std::string n = name(c.name);
    header.channels().insert(n, Imf::Channel(type));
    char* base;
    size_t elem;
    if (c.isUInt) {
      base = reinterpret_cast<char*>(const_cast<uint32_t*>(c.u.data()));
      elem = 4;
    } else if (c.half) {
      halves.emplace_back(c.f.size());
      for (size_t i = 0; i < c.f.size(); ++i) halves.back()[i] = Imath::half(std::clamp(c.f[i], -65504.f, 65504.f));
      base = reinterpret_cast<char*>(halves.back().data());
      elem = 2;
    } else {
      base = reinterpret_cast<char*>(const_cast<float*>(c.f.data()));
      elem = 4;
    }
    // OpenEXR addresses pixels by absolute coordinates: offset the base by the data window origin.
    base -= (ptrdiff_t(image.x0) * ptrdiff_t(xs) + ptrdiff_t(image.y0) * ptrdiff_t(ys)) * ptrdiff_t(elem);
    fb.insert(n, Imf::Slice(type, base, elem * xs, elem * ys));
  }
}

Imf::Header headerFor(const FlatImage& image, const ExrOptions& options) {
  Imath::Box2i display(Imath::V2i(0, 0), Imath::V2i(image.fullWidth - 1, image.fullHeight - 1));
  Imath::Box2i data(Imath::V2i(image.x0, image.y0), Imath::V2i(image.x0 + image.width - 1, image.y0 + image.height - 1));
  return Imf::Header(display, data, 1.0f, Imath::V2f(0, 0), 1.0f, Imf::INCREASING_Y, toImf(options.compression));
}

void writePixels(const std::string& path, const Imf::Header& header, const Imf::FrameBuffer& fb, int height) {
  AtomicFile file(path);
  try {
    Imf::OutputFile out(file.tempPath().c_str(), header);
    out.setFrameBuffer(fb);
    out.writePixels(height);
  } catch (const std::exception& e) {
    fail(path, "OpenEXR write failed: ", e.what());
  }
  file.commit();
}

}  // namespace

void writeExr(const std::string& path, const FlatImage& image, const ImageProvenance& info, const ExrOptions& options) {
  if (image.width <= 0 || image.height <= 0) fail(path, "empty image");
  Imf::Header header = headerFor(image, options);
  std::vector<std::vector<Imath::half>> halves;
  Imf::FrameBuffer fb;
  addChannels(image, header, fb, halves, [](const std::string& n) { return n; });
  addProvenanceAttributes(header, info);
  writePixels(path, header, fb, image.height);
}

std::string viewChannelName(const std::string& channel, const std::string& view) {
  const size_t dot = channel.rfind('.');
  return dot == std::string::npos ? view + "." + channel : channel.substr(0, dot + 1) + view + channel.substr(dot);
}

void writeMultiViewExr(const std::string& path, const std::vector<ExrView>& views, const ExrOptions& options) {
  if (views.empty()) fail(path, "no view to write");
  const FlatImage& first = *views[0].image;
  if (first.width <= 0 || first.height <= 0) fail(path, "empty image");
  Imf::Header header = headerFor(first, options);
  std::vector<std::vector<Imath::half>> halves;
  Imf::FrameBuffer fb;
  Imf::StringVector names;
  for (size_t v = 0; v < views.size(); ++v) {
    const ExrView& view = views[v];
    const FlatImage& im = *view.image;
    if (view.name.empty() || view.name.find('.') != std::string::npos) fail(path, "view name '", view.name, "' must be non-empty and without '.'");
    if (std::find(names.begin(), names.end(), view.name) != names.end()) fail(path, "view '", view.name, "' given twice");
    if (im.x0 != first.x0 || im.y0 != first.y0 || im.width != first.width || im.height != first.height || im.fullWidth != first.fullWidth ||
        im.fullHeight != first.fullHeight)
      fail(path, "view '", view.name, "' has another data window than view '", views[0].name, "': the views of one file share it");
    names.push_back(view.name);
    if (v == 0) {
      addChannels(im, header, fb, halves, [](const std::string& n) { return n; });
      addProvenanceAttributes(header, *view.info);
    } else {
      addChannels(im, header, fb, halves, [&](const std::string& n) { return viewChannelName(n, view.name); });
      // The standard worldToCamera / worldToNDC are the default view's; each other view's go by
      // its name.
      header.insert("reshutter/" + view.name + "/worldToCamera", Imf::M44fAttribute(toImath(view.info->worldToCamera)));
      header.insert("reshutter/" + view.name + "/worldToNDC", Imf::M44fAttribute(toImath(view.info->worldToNdc)));
    }
  }
  Imf::addMultiView(header, names);
  writePixels(path, header, fb, first.height);
}

namespace {

// Quantises one value per the AOV reference's formula, with deterministic dither.
inline uint32_t quantize(double v, const Quantize& q, uint64_t key) {
  double d = q.dither > 0 ? q.dither * (2.0 * toUnitDouble(mix64(key)) - 1.0) : 0.0;
  double x = std::round(q.zero + v * (q.one - q.zero) + d);
  if (!(x >= q.min)) x = q.min;  // NaN → min
  if (x > q.max) x = q.max;
  return uint32_t(x);
}

void writePng(const std::string& tmp, const std::string& path, int w, int h, int comps, int bits, const std::vector<uint32_t>& v) {
  FILE* f = std::fopen(tmp.c_str(), "wb");
  if (!f) fail(path, "cannot write");
  png_structp png = png_create_write_struct(PNG_LIBPNG_VER_STRING, nullptr, nullptr, nullptr);
  png_infop pinfo = png ? png_create_info_struct(png) : nullptr;
  if (!png || !pinfo || setjmp(png_jmpbuf(png))) {
    png_destroy_write_struct(&png, &pinfo);
    std::fclose(f);
    fail(path, "PNG write failed");
  }
  png_init_io(png, f);
  const int type = comps == 1 ? PNG_COLOR_TYPE_GRAY : comps == 2 ? PNG_COLOR_TYPE_GRAY_ALPHA : comps == 3 ? PNG_COLOR_TYPE_RGB : PNG_COLOR_TYPE_RGBA;
  png_set_IHDR(png, pinfo, png_uint_32(w), png_uint_32(h), bits, type, PNG_INTERLACE_NONE, PNG_COMPRESSION_TYPE_DEFAULT, PNG_FILTER_TYPE_DEFAULT);
  png_write_info(png, pinfo);
  std::vector<uint8_t> row(size_t(w) * comps * (bits / 8));
  for (int y = 0; y < h; ++y) {
    for (int i = 0; i < w * comps; ++i) {
      uint32_t x = v[size_t(y) * w * comps + i];
      if (bits == 8) row[size_t(i)] = uint8_t(x);
      else row[size_t(i) * 2] = uint8_t(x >> 8), row[size_t(i) * 2 + 1] = uint8_t(x);
    }
    png_write_row(png, row.data());
  }
  png_write_end(png, nullptr);
  png_destroy_write_struct(&png, &pinfo);
  if (std::fclose(f) != 0) fail(path, "PNG write failed");
}

void writeTiff(const std::string& tmp, const std::string& path, int w, int h, int comps, int bits, const std::vector<uint32_t>& v) {
  TIFFSetWarningHandler(nullptr);
  TIFF* t = TIFFOpen(tmp.c_str(), "w");
  if (!t) fail(path, "cannot write");
  TIFFSetField(t, TIFFTAG_IMAGEWIDTH, uint32_t(w));
  TIFFSetField(t, TIFFTAG_IMAGELENGTH, uint32_t(h));
  TIFFSetField(t, TIFFTAG_SAMPLESPERPIXEL, uint16_t(comps));
  TIFFSetField(t, TIFFTAG_BITSPERSAMPLE, uint16_t(bits));
  TIFFSetField(t, TIFFTAG_PHOTOMETRIC, comps >= 3 ? PHOTOMETRIC_RGB : PHOTOMETRIC_MINISBLACK);
  TIFFSetField(t, TIFFTAG_PLANARCONFIG, PLANARCONFIG_CONTIG);
  TIFFSetField(t, TIFFTAG_COMPRESSION, COMPRESSION_ADOBE_DEFLATE);
  if (comps == 2 || comps == 4) {
    uint16_t extra = EXTRASAMPLE_UNASSALPHA;
    TIFFSetField(t, TIFFTAG_EXTRASAMPLES, 1, &extra);
  }
  std::vector<uint8_t> row(size_t(w) * comps * (bits / 8));
  for (int y = 0; y < h; ++y) {
    for (int i = 0; i < w * comps; ++i) {
      uint32_t x = v[size_t(y) * w * comps + i];
      if (bits == 8) row[size_t(i)] = uint8_t(x);
      else reinterpret_cast<uint16_t*>(row.data())[i] = uint16_t(x);
    }
    if (TIFFWriteScanline(t, row.data(), uint32_t(y), 0) < 0) {
      TIFFClose(t);
      fail(path, "TIFF write failed");
    }
  }
  TIFFClose(t);
}

}  // namespace

void writePreview(const std::string& path, const FlatImage& image, const std::vector<std::string>& channels, const Quantize& q, uint64_t seed) {
  std::string ext = std::filesystem::path(path).extension().string();
  for (char& c : ext) c = char(std::tolower(c));
  const bool tiff = ext == ".tif" || ext == ".tiff";
  if (!tiff && ext != ".png") fail(path, "previews are .png or .tif/.tiff");
  const int comps = int(channels.size());
  if (comps < 1 || comps > 4) fail(path, "a preview takes 1 to 4 channels");
  std::vector<const ImageChannel*> src;
  for (const auto& n : channels) {
    const ImageChannel* c = image.find(n);
    if (!c) fail(path, "no channel '", n, "' to preview");
    src.push_back(c);
  }
  const ImageChannel* alpha = comps == 4 ? src[3] : nullptr;
  const int bits = q.bits();
  std::vector<uint32_t> v(size_t(image.width) * image.height * comps);
  for (int y = 0; y < image.height; ++y)
    for (int x = 0; x < image.width; ++x) {
      const size_t p = size_t(y) * image.width + x;
      const float a = alpha ? alpha->f[p] : 1.f;
      for (int c = 0; c < comps; ++c) {
        double val = src[size_t(c)]->isUInt ? double(src[size_t(c)]->u[p]) : double(src[size_t(c)]->f[p]);
        if (alpha && c < 3) val = a > 0 ? val / a : 0.0;  // straight alpha for the preview
        v[p * comps + c] = quantize(val, q, hashCombine(seed, p * 4 + size_t(c)));
      }
    }
  AtomicFile file(path);
  if (tiff) writeTiff(file.tempPath(), path, image.width, image.height, comps, bits, v);
  else writePng(file.tempPath(), path, image.width, image.height, comps, bits, v);
  file.commit();
}

}  // namespace reshutter::resample
