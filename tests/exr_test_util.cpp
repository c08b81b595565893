#include "tests/exr_test_util.h"

#include <stdexcept>

#include <OpenEXR/ImfChannelList.h>
#include <OpenEXR/ImfDeepFrameBuffer.h>
#include <OpenEXR/ImfDeepImageStateAttribute.h>
#include <OpenEXR/ImfDeepScanLineInputFile.h>
#include <OpenEXR/ImfDeepScanLineInputPart.h>
#include <OpenEXR/ImfFrameBuffer.h>
#include <OpenEXR/ImfHeader.h>
#include <OpenEXR/ImfInputFile.h>
#include <OpenEXR/ImfMultiPartInputFile.h>
#include <OpenEXR/ImfStringAttribute.h>
#include <OpenEXR/ImfVecAttribute.h>

namespace reshutter::test {

using namespace reshutter::resample;

FlatImage readFlatExr(const std::string& path) {
  Imf::InputFile in(path.c_str());
  const Imath::Box2i dw = in.header().dataWindow(), disp = in.header().displayWindow();
  FlatImage out;
  out.x0 = dw.min.x, out.y0 = dw.min.y, out.width = dw.max.x - dw.min.x + 1, out.height = dw.max.y - dw.min.y + 1;
  out.fullWidth = disp.max.x - disp.min.x + 1, out.fullHeight = disp.max.y - disp.min.y + 1;
  // OpenEXR addresses pixels absolutely: shift each base by the data window's first pixel.
  const ptrdiff_t origin = ptrdiff_t(out.y0) * out.width + out.x0;
  for (auto it = in.header().channels().begin(); it != in.header().channels().end(); ++it)
    out.add(it.name(), it.channel().type == Imf::UINT).half = it.channel().type == Imf::HALF;
  Imf::FrameBuffer fb;
  for (ImageChannel& c : out.channels) {
    char* base = c.isUInt ? reinterpret_cast<char*>(c.u.data() - origin) : reinterpret_cast<char*>(c.f.data() - origin);
    fb.insert(c.name, Imf::Slice(c.isUInt ? Imf::UINT : Imf::FLOAT, base, 4, 4 * size_t(out.width)));
  }
  in.setFrameBuffer(fb);
  in.readPixels(dw.min.y, dw.max.y);
  return out;
}

namespace {

// A deep scanline file or part, read whole.
template <class Input>
DeepExr readDeep(Input& in) {
  DeepExr out;
  const Imf::Header& h = in.header();
  for (auto it = h.channels().begin(); it != h.channels().end(); ++it) out.channels.push_back(it.name());
  if (auto* a = h.findTypedAttribute<Imf::DeepImageStateAttribute>("deepImageState")) out.tidyState = a->value() == Imf::DIS_TIDY;
  out.manifest = h.find("idManifest") != h.end();
  const Imath::Box2i dw = h.dataWindow(), disp = h.displayWindow();
  const int W = dw.max.x - dw.min.x + 1, H = dw.max.y - dw.min.y + 1;
  const size_t n = size_t(W) * size_t(H);
  const ptrdiff_t origin = ptrdiff_t(dw.min.y) * W + dw.min.x;
  auto present = [&](const char* name) { return h.channels().findChannel(name) != nullptr; };

  // Each channel is a slice into its field of the pixels' DeepPixel records (nf floats, nu uints
  // per sample, so the sample stride is a record). The pointer arrays go into the frame buffer
  // before the sample counts are read and are filled once the counts size the records.
  struct Field {
    int index;
    bool isUInt;
    std::vector<char*> ptrs;
  };
  std::vector<Field> fields;
  std::vector<unsigned> counts(n);
  Imf::DeepFrameBuffer fb;
  fb.insertSampleCountSlice(Imf::Slice(Imf::UINT, reinterpret_cast<char*>(counts.data() - origin), 4, 4 * size_t(W)));
  const int nf = kDeepFixedFloats, nu = kDeepFixedUInts;
  for (auto [name, field] : {std::pair{"R", int(kDeepR)},
                             {"G", kDeepG},
                             {"B", kDeepB},
                             {"A", kDeepA},
                             {"Z", kDeepZ},
                             {"ZBack", kDeepZBack},
                             {"AR", kDeepAR},
                             {"AG", kDeepAG},
                             {"AB", kDeepAB},
                             {"objectid", kDeepObjectId}}) {
    if (!present(name)) continue;
    const bool isUInt = std::string(name) == "objectid";
    Field& f = fields.emplace_back(Field{field, isUInt, std::vector<char*>(n)});
    fb.insert(name, Imf::DeepSlice(isUInt ? Imf::UINT : Imf::FLOAT, reinterpret_cast<char*>(f.ptrs.data() - origin), sizeof(char*), sizeof(char*) * size_t(W),
                                   4 * size_t(isUInt ? nu : nf)));
  }
  in.setFrameBuffer(fb);
  in.readPixelSampleCounts(dw.min.y, dw.max.y);
  std::vector<DeepPixel> pixels(n);
  static uint32_t none[1];  // where a pixel without samples points (nothing is read there)
  for (size_t i = 0; i < n; ++i) {
    pixels[i].f.assign(size_t(counts[i]) * nf, 0.0f), pixels[i].u.assign(size_t(counts[i]) * nu, 0u);
    for (Field& f : fields)
      f.ptrs[i] = counts[i] == 0 ? reinterpret_cast<char*>(none)
                  : f.isUInt     ? reinterpret_cast<char*>(pixels[i].u.data() + f.index)
                                 : reinterpret_cast<char*>(pixels[i].f.data() + f.index);
  }
  in.readPixels(dw.min.y, dw.max.y);

  out.image.reset(dw.min.x, dw.min.y, W, H, disp.max.x - disp.min.x + 1, disp.max.y - disp.min.y + 1, DeepLayout{}, 1);
  out.image.tidy = out.tidyState;
  for (size_t i = 0; i < n; ++i) {
    DeepPixel& px = pixels[i];
    for (size_t s = 0; s < px.size(); ++s) {
      float* r = px.at(s);
      if (!present("ZBack")) r[kDeepZBack] = r[kDeepZ];
      if (!present("AR")) r[kDeepAR] = r[kDeepAG] = r[kDeepAB] = r[kDeepA];
    }
    out.image.setPixel(0, dw.min.x + int(i % size_t(W)), dw.min.y + int(i / size_t(W)), px);
  }
  return out;
}

}  // namespace

DeepExr readDeepExr(const std::string& path) {
  Imf::DeepScanLineInputFile in(path.c_str());
  return readDeep(in);
}

DeepExr readDeepExrPart(const std::string& path, int part, std::string& view) {
  Imf::MultiPartInputFile file(path.c_str());
  Imf::DeepScanLineInputPart in(file, part);
  view = in.header().hasView() ? in.header().view() : "";
  return readDeep(in);
}

ExrShutter readExrShutter(const std::string& path) {
  Imf::MultiPartInputFile in(path.c_str());
  ExrShutter s;
  if (auto* d = in.header(0).findTypedAttribute<Imf::StringAttribute>("reshutter/shutter")) s.description = d->value();
  if (auto* v = in.header(0).findTypedAttribute<Imf::V2dAttribute>("reshutter/shutterInterval")) s.open = v->value().x, s.close = v->value().y;
  return s;
}

}  // namespace reshutter::test
