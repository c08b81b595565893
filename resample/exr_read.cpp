#include "resample/exr_read.h"

#include <OpenEXR/ImfChannelList.h>
#include <OpenEXR/ImfDeepFrameBuffer.h>
#include <OpenEXR/ImfDeepImageStateAttribute.h>
#include <OpenEXR/ImfDeepScanLineInputFile.h>
#include <OpenEXR/ImfFrameBuffer.h>
#include <OpenEXR/ImfHeader.h>
#include <OpenEXR/ImfIDManifest.h>
#include <OpenEXR/ImfInputFile.h>
#include <OpenEXR/ImfIntAttribute.h>
#include <OpenEXR/ImfMultiPartInputFile.h>
#include <OpenEXR/ImfPartType.h>
#include <OpenEXR/ImfStandardAttributes.h>
#include <OpenEXR/ImfStringAttribute.h>
#include <OpenEXR/ImfVecAttribute.h>

#include "common/error.h"

namespace reshutter::resample {

namespace {

ExrCompression fromImf(Imf::Compression c) {
  switch (c) {
    case Imf::NO_COMPRESSION: return ExrCompression::None;
    case Imf::RLE_COMPRESSION: return ExrCompression::Rle;
    case Imf::ZIPS_COMPRESSION: return ExrCompression::Zips;
    case Imf::ZIP_COMPRESSION: return ExrCompression::Zip;
    case Imf::PIZ_COMPRESSION: return ExrCompression::Piz;
    case Imf::PXR24_COMPRESSION: return ExrCompression::Pxr24;
    case Imf::B44_COMPRESSION: return ExrCompression::B44;
    case Imf::B44A_COMPRESSION: return ExrCompression::B44a;
    case Imf::DWAA_COMPRESSION: return ExrCompression::Dwaa;
    case Imf::DWAB_COMPRESSION: return ExrCompression::Dwab;
    default: return ExrCompression::Zip;
  }
}

// Imath (row vectors) → glm (column vectors): the same element indices (image.cpp's toImath).
glm::dmat4 toGlm(const Imath::M44f& m) {
  glm::dmat4 r(1.0);
  for (int i = 0; i < 4; ++i)
    for (int j = 0; j < 4; ++j) r[i][j] = double(m[i][j]);
  return r;
}

// The header attributes addProvenanceAttributes() writes, read back.
ImageProvenance provenanceOf(const Imf::Header& h) {
  ImageProvenance p;
  if (Imf::hasWorldToCamera(h)) p.worldToCamera = toGlm(Imf::worldToCamera(h));
  if (Imf::hasWorldToNDC(h)) p.worldToNdc = toGlm(Imf::worldToNDC(h));
  if (Imf::hasFramesPerSecond(h)) p.fpsNum = Imf::framesPerSecond(h).n, p.fpsDen = Imf::framesPerSecond(h).d;
  if (auto* a = h.findTypedAttribute<Imf::StringAttribute>("software")) p.software = a->value();
  if (auto* a = h.findTypedAttribute<Imf::IntAttribute>("reshutter/frame")) p.frame = a->value();
  if (auto* a = h.findTypedAttribute<Imf::StringAttribute>("reshutter/shutter")) p.shutter = a->value();
  if (auto* a = h.findTypedAttribute<Imf::V2dAttribute>("reshutter/shutterInterval")) p.shutterOpen = a->value().x, p.shutterClose = a->value().y;
  if (Imf::hasComments(h)) p.comments = Imf::comments(h);
  return p;
}

struct Windows {
  int x0, y0, width, height, fullWidth, fullHeight;
};
Windows windowsOf(const Imf::Header& h, const std::string& path) {
  const Imath::Box2i dw = h.dataWindow(), disp = h.displayWindow();
  if (disp.min.x != 0 || disp.min.y != 0) fail(path, "display window does not start at 0,0 (reshutter writes it so)");
  return {dw.min.x, dw.min.y, dw.max.x - dw.min.x + 1, dw.max.y - dw.min.y + 1, disp.max.x + 1, disp.max.y + 1};
}

}  // namespace

bool isDeepExr(const std::string& path) {
  try {
    Imf::MultiPartInputFile in(path.c_str());
    if (in.parts() != 1) fail(path, "has ", in.parts(), " parts; reshutter reads single-part files");
    return in.header(0).hasType() && Imf::isDeepData(in.header(0).type());
  } catch (const Error&) {
    throw;
  } catch (const std::exception& e) {
    fail(path, "cannot read as OpenEXR: ", e.what());
  }
}

FlatExr readFlatExr(const std::string& path) {
  FlatExr out;
  try {
    Imf::InputFile in(path.c_str());
    const Imf::Header& h = in.header();
    const Windows w = windowsOf(h, path);
    FlatImage& img = out.image;
    img.x0 = w.x0, img.y0 = w.y0, img.width = w.width, img.height = w.height, img.fullWidth = w.fullWidth, img.fullHeight = w.fullHeight;
    for (auto it = h.channels().begin(); it != h.channels().end(); ++it) {
      if (it.channel().xSampling != 1 || it.channel().ySampling != 1) fail(path, "channel '", it.name(), "' is subsampled");
      img.add(it.name(), it.channel().type == Imf::UINT).half = it.channel().type == Imf::HALF;
    }
    // OpenEXR addresses pixels absolutely: shift each base by the data window's first pixel.
    const ptrdiff_t origin = ptrdiff_t(img.y0) * img.width + img.x0;
    Imf::FrameBuffer fb;
    for (ImageChannel& c : img.channels) {
      char* base = c.isUInt ? reinterpret_cast<char*>(c.u.data() - origin) : reinterpret_cast<char*>(c.f.data() - origin);
      fb.insert(c.name, Imf::Slice(c.isUInt ? Imf::UINT : Imf::FLOAT, base, 4, 4 * size_t(img.width)));
    }
    in.setFrameBuffer(fb);
    in.readPixels(h.dataWindow().min.y, h.dataWindow().max.y);
    out.provenance = provenanceOf(h);
    out.options.compression = fromImf(h.compression());
  } catch (const Error&) {
    throw;
  } catch (const std::exception& e) {
    fail(path, "cannot read as a flat OpenEXR: ", e.what());
  }
  return out;
}

DeepExr readDeepExr(const std::string& path) {
  DeepExr out;
  try {
    Imf::DeepScanLineInputFile in(path.c_str());
    const Imf::Header& h = in.header();
    const Windows w = windowsOf(h, path);
    const size_t n = size_t(w.width) * size_t(w.height);
    const ptrdiff_t origin = ptrdiff_t(w.y0) * w.width + w.x0;

    // Which record field each channel fills: the fixed ones by name, every other float channel
    // an output variable of the layout, every other uint channel a uint output variable.
    DeepLayout layout;
    struct Field {
      std::string name;
      int index;
      bool isUInt;
      std::vector<char*> ptrs;
    };
    std::vector<Field> fields;
    static const std::pair<const char*, int> fixed[] = {{"R", kDeepR},         {"G", kDeepG},   {"B", kDeepB},   {"A", kDeepA},  {"Z", kDeepZ},
                                                        {"ZBack", kDeepZBack}, {"AR", kDeepAR}, {"AG", kDeepAG}, {"AB", kDeepAB}};
    for (auto it = h.channels().begin(); it != h.channels().end(); ++it) {
      const std::string name = it.name();
      const bool isUInt = it.channel().type == Imf::UINT;
      int index = -1;
      for (auto [fname, f] : fixed)
        if (name == fname) index = f;
      if (index >= 0 && isUInt) fail(path, "channel '", name, "' is uint; reshutter writes it as float");
      if (name == "objectid") {
        if (!isUInt) fail(path, "channel 'objectid' is not uint");
        index = kDeepObjectId;
      }
      if (index < 0) {
        if (isUInt) {
          index = kDeepFixedUInts + int(layout.uints.size());
          layout.uints.push_back({name, int(layout.uints.size()), false});
        } else {
          index = kDeepFixedFloats + int(layout.floats.size());
          layout.floats.push_back({name, int(layout.floats.size()), true});
        }
      }
      fields.push_back({name, index, isUInt, std::vector<char*>(n)});
    }
    layout.sourceFloats = int(layout.floats.size()), layout.sourceUInts = int(layout.uints.size());
    auto present = [&](const char* name) { return h.channels().findChannel(name) != nullptr; };
    out.hasZBack = present("ZBack");
    out.hasColouredAlpha = present("AR") && present("AG") && present("AB");

    const int nf = layout.nf(), nu = layout.nu();
    std::vector<unsigned> counts(n);
    Imf::DeepFrameBuffer fb;
    fb.insertSampleCountSlice(Imf::Slice(Imf::UINT, reinterpret_cast<char*>(counts.data() - origin), 4, 4 * size_t(w.width)));
    for (Field& f : fields)
      fb.insert(f.name, Imf::DeepSlice(f.isUInt ? Imf::UINT : Imf::FLOAT, reinterpret_cast<char*>(f.ptrs.data() - origin), sizeof(char*),
                                       sizeof(char*) * size_t(w.width), 4 * size_t(f.isUInt ? nu : nf)));
    in.setFrameBuffer(fb);
    in.readPixelSampleCounts(h.dataWindow().min.y, h.dataWindow().max.y);
    // Every sample's record in one array, pixel after pixel: the image's one block.
    std::vector<size_t> first(n + 1, 0);
    for (size_t i = 0; i < n; ++i) first[i + 1] = first[i] + counts[i];
    std::vector<float> recF(first[n] * size_t(nf), 0.f);
    std::vector<uint32_t> recU(first[n] * size_t(nu), 0u);
    static uint32_t none[1];  // where a pixel without samples points (nothing is read there)
    for (size_t i = 0; i < n; ++i)
      for (Field& f : fields)
        f.ptrs[i] = counts[i] == 0 ? reinterpret_cast<char*>(none)
                    : f.isUInt     ? reinterpret_cast<char*>(recU.data() + first[i] * size_t(nu) + size_t(f.index))
                                   : reinterpret_cast<char*>(recF.data() + first[i] * size_t(nf) + size_t(f.index));
    in.readPixels(h.dataWindow().min.y, h.dataWindow().max.y);
    for (size_t s = 0; s < first[n]; ++s) {
      float* r = recF.data() + s * size_t(nf);
      if (!out.hasZBack) r[kDeepZBack] = r[kDeepZ];
      if (!out.hasColouredAlpha) r[kDeepAR] = r[kDeepAG] = r[kDeepAB] = r[kDeepA];
    }

    DeepImage& img = out.image;
    img.reset(w.x0, w.y0, w.width, w.height, w.fullWidth, w.fullHeight, layout, 1);
    if (auto* a = h.findTypedAttribute<Imf::DeepImageStateAttribute>("deepImageState")) img.tidy = a->value() == Imf::DIS_TIDY;
    else img.tidy = false;
    if (Imf::hasIDManifest(h)) {
      const Imf::IDManifest manifest(Imf::idManifest(h));
      for (size_t g = 0; g < manifest.size(); ++g) {
        if (!manifest[g].getChannels().count("objectid")) continue;
        for (auto it = manifest[g].begin(); it != manifest[g].end(); ++it)
          if (!it.text().empty()) img.objectNames[uint32_t(it.id())] = it.text().front();
      }
    }
    DeepPixel px;
    px.nf = nf, px.nu = nu;
    for (size_t i = 0; i < n; ++i) {
      px.f.assign(recF.begin() + ptrdiff_t(first[i] * size_t(nf)), recF.begin() + ptrdiff_t(first[i + 1] * size_t(nf)));
      px.u.assign(recU.begin() + ptrdiff_t(first[i] * size_t(nu)), recU.begin() + ptrdiff_t(first[i + 1] * size_t(nu)));
      img.setPixel(0, w.x0 + int(i % size_t(w.width)), w.y0 + int(i / size_t(w.width)), px);
    }
    out.provenance = provenanceOf(h);
    switch (h.compression()) {
      case Imf::ZIPS_COMPRESSION: out.options.compression = DeepCompression::Zips; break;
      case Imf::RLE_COMPRESSION: out.options.compression = DeepCompression::Rle; break;
      case Imf::NO_COMPRESSION: out.options.compression = DeepCompression::None; break;
      default: fail(path, "deep compression other than zips, rle or none");
    }
  } catch (const Error&) {
    throw;
  } catch (const std::exception& e) {
    fail(path, "cannot read as a deep OpenEXR: ", e.what());
  }
  return out;
}

void verifyExr(const std::string& path) {
  if (isDeepExr(path)) readDeepExr(path);
  else readFlatExr(path);
}

}  // namespace reshutter::resample
