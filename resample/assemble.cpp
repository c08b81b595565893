#include "resample/assemble.h"

#include <algorithm>
#include <cstring>

#include "common/error.h"

namespace reshutter::resample {

namespace {

struct Box {
  int x0, y0, x1, y1;  // end exclusive
};

// Checks that the tiles' data windows do not overlap and fill their bounding box; returns it.
Box unionOf(const std::vector<Box>& boxes, const std::vector<std::string>& names) {
  if (boxes.empty()) fail("assemble", "no tiles");
  Box u = boxes[0];
  uint64_t area = 0;
  for (size_t i = 0; i < boxes.size(); ++i) {
    const Box& b = boxes[i];
    u.x0 = std::min(u.x0, b.x0), u.y0 = std::min(u.y0, b.y0), u.x1 = std::max(u.x1, b.x1), u.y1 = std::max(u.y1, b.y1);
    area += uint64_t(b.x1 - b.x0) * uint64_t(b.y1 - b.y0);
    for (size_t j = 0; j < i; ++j) {
      const Box& o = boxes[j];
      if (b.x0 < o.x1 && o.x0 < b.x1 && b.y0 < o.y1 && o.y0 < b.y1)
        fail(names[i], "overlaps tile ", names[j], " (data windows [", b.x0, ",", b.x1, ")x[", b.y0, ",", b.y1, ") and [", o.x0, ",", o.x1, ")x[", o.y0, ",",
             o.y1, "))");
    }
  }
  if (area != uint64_t(u.x1 - u.x0) * uint64_t(u.y1 - u.y0))
    fail("assemble", "the ", boxes.size(), " tiles leave holes in their bounding box [", u.x0, ",", u.x1, ")x[", u.y0, ",", u.y1, "): a tile is missing");
  return u;
}

bool sameProvenance(const ImageProvenance& a, const ImageProvenance& b) {
  return a.worldToCamera == b.worldToCamera && a.worldToNdc == b.worldToNdc && a.frame == b.frame && a.fpsNum == b.fpsNum && a.fpsDen == b.fpsDen &&
         a.shutter == b.shutter && a.shutterOpen == b.shutterOpen && a.shutterClose == b.shutterClose && a.software == b.software && a.comments == b.comments;
}

void checkNames(const std::vector<std::string>& names, size_t n) {
  if (names.size() != n) fail("assemble", "internal: ", n, " tiles but ", names.size(), " names");
}

// The tiles' data windows (checked to fill a rectangle, which is returned), and that tile i
// comes from the render tile 0 does: display window, provenance, compression.
template <class Tile>
Box checkOneRender(const std::vector<Tile>& tiles, const std::vector<std::string>& names) {
  checkNames(names, tiles.size());
  std::vector<Box> boxes;
  for (const Tile& t : tiles) boxes.push_back({t.image.x0, t.image.y0, t.image.x0 + t.image.width, t.image.y0 + t.image.height});
  const Box u = unionOf(boxes, names);
  const Tile& first = tiles[0];
  for (size_t i = 1; i < tiles.size(); ++i) {
    const Tile& t = tiles[i];
    if (t.image.fullWidth != first.image.fullWidth || t.image.fullHeight != first.image.fullHeight)
      fail(names[i], "display window ", t.image.fullWidth, "x", t.image.fullHeight, " differs from ", names[0], "'s ", first.image.fullWidth, "x",
           first.image.fullHeight);
    if (!sameProvenance(t.provenance, first.provenance)) fail(names[i], "comes from another render than ", names[0], " (frame, shutter or camera differ)");
    if (t.options.compression != first.options.compression) fail(names[i], "compression differs from ", names[0], "'s");
  }
  return u;
}

}  // namespace

FlatExr assembleFlat(std::vector<FlatExr> tiles, const std::vector<std::string>& names) {
  const Box u = checkOneRender(tiles, names);
  const FlatExr& first = tiles[0];
  FlatExr out;
  out.provenance = first.provenance, out.options = first.options;
  FlatImage& img = out.image;
  img.x0 = u.x0, img.y0 = u.y0, img.width = u.x1 - u.x0, img.height = u.y1 - u.y0;
  img.fullWidth = first.image.fullWidth, img.fullHeight = first.image.fullHeight;
  for (const ImageChannel& c : first.image.channels) img.add(c.name, c.isUInt).half = c.half;
  for (size_t i = 0; i < tiles.size(); ++i) {
    const FlatImage& t = tiles[i].image;
    if (t.channels.size() != img.channels.size()) fail(names[i], "has ", t.channels.size(), " channels, ", names[0], " has ", img.channels.size());
    for (size_t c = 0; c < t.channels.size(); ++c) {
      const ImageChannel& src = t.channels[c];
      ImageChannel& dst = img.channels[c];
      if (src.name != dst.name || src.isUInt != dst.isUInt || src.half != dst.half)
        fail(names[i], "channel '", src.name, "' differs from ", names[0], "'s channels");
      for (int y = 0; y < t.height; ++y) {
        const size_t from = size_t(y) * size_t(t.width), to = size_t(t.y0 + y - img.y0) * size_t(img.width) + size_t(t.x0 - img.x0);
        if (src.isUInt) std::memcpy(dst.u.data() + to, src.u.data() + from, size_t(t.width) * 4);
        else std::memcpy(dst.f.data() + to, src.f.data() + from, size_t(t.width) * 4);
      }
    }
  }
  return out;
}

DeepExr assembleDeep(std::vector<DeepExr> tiles, const std::vector<std::string>& names) {
  const Box u = checkOneRender(tiles, names);
  const DeepExr& first = tiles[0];
  DeepExr out;
  out.provenance = first.provenance, out.options = first.options;
  DeepImage& img = out.image;
  const DeepLayout& L = first.image.layout;
  img.reset(u.x0, u.y0, u.x1 - u.x0, u.y1 - u.y0, first.image.fullWidth, first.image.fullHeight, L, tiles.size());
  img.objectNames = first.image.objectNames;
  img.tidy = true;
  auto sameAux = [](const std::vector<DeepLayout::Aux>& a, const std::vector<DeepLayout::Aux>& b) {
    if (a.size() != b.size()) return false;
    for (size_t i = 0; i < a.size(); ++i)
      if (a[i].name != b[i].name) return false;
    return true;
  };
  DeepPixel px;
  for (size_t i = 0; i < tiles.size(); ++i) {
    const DeepImage& t = tiles[i].image;
    if (!sameAux(t.layout.floats, L.floats) || !sameAux(t.layout.uints, L.uints)) fail(names[i], "output variables differ from ", names[0], "'s");
    if (t.objectNames != img.objectNames) fail(names[i], "object names (idManifest) differ from ", names[0], "'s");
    // An absent ZBack or AR AG AB was filled in on reading; exact only when the whole image
    // needs no such channel (farm tiles are written with every channel, DeepExrOptions::allChannels).
    out.hasZBack |= tiles[i].hasZBack, out.hasColouredAlpha |= tiles[i].hasColouredAlpha;
    img.tidy = img.tidy && t.tidy;
    for (int y = t.y0; y < t.y0 + t.height; ++y)
      for (int x = t.x0; x < t.x0 + t.width; ++x) {
        t.getPixel(x, y, px);
        img.setPixel(i, x, y, px);
      }
  }
  return out;
}

size_t assembleExrFiles(const std::vector<std::string>& tiles, const std::string& out) {
  if (tiles.empty()) fail("assemble", "no tiles given");
  const bool deep = isDeepExr(tiles[0]);
  for (const auto& t : tiles)
    if (isDeepExr(t) != deep) fail(t, "is ", deep ? "flat" : "deep", " but ", tiles[0], " is ", deep ? "deep" : "flat");
  if (deep) {
    std::vector<DeepExr> parts;
    for (const auto& t : tiles) parts.push_back(readDeepExr(t));
    DeepExr whole = assembleDeep(std::move(parts), tiles);
    writeDeepExr(out, whole.image, whole.provenance, whole.options);
    return size_t(whole.image.width) * size_t(whole.image.height);
  }
  std::vector<FlatExr> parts;
  for (const auto& t : tiles) parts.push_back(readFlatExr(t));
  FlatExr whole = assembleFlat(std::move(parts), tiles);
  writeExr(out, whole.image, whole.provenance, whole.options);
  return size_t(whole.image.width) * size_t(whole.image.height);
}

}  // namespace reshutter::resample
