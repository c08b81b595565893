#include "bench/dump_rib.h"

#include <charconv>
#include <vector>

#include <zlib.h>

#include "common/error.h"

namespace reshutter::bench {

struct DumpRibWriter::Impl {
  std::string path;
  gzFile gz = nullptr;
  FILE* plain = nullptr;
  std::vector<store::Schedule> schedules{store::Schedule{0.0}};
  std::string buf;
  int ci = -1, oi = -1;

  void flush(bool force = false) {
    if (buf.size() < (1u << 20) && !force) return;
    if (gz) {
      if (gzwrite(gz, buf.data(), unsigned(buf.size())) != int(buf.size())) fail(path, "gzip write failed");
    } else if (std::fwrite(buf.data(), 1, buf.size(), plain) != buf.size()) {
      fail(path, "write failed");
    }
    buf.clear();
  }
  void number(double v) {
    char tmp[32];
    auto r = std::to_chars(tmp, tmp + sizeof tmp, float(v));  // shortest text that reads back exactly
    buf.append(tmp, r.ptr);
    buf += ' ';
  }
  void integer(uint32_t v) {
    char tmp[16];
    auto r = std::to_chars(tmp, tmp + sizeof tmp, v);
    buf.append(tmp, r.ptr);
    buf += ' ';
  }
};

DumpRibWriter::DumpRibWriter(const std::string& path, const store::StoreMeta& meta, bool gzip, int level) : impl_(std::make_unique<Impl>()) {
  auto& I = *impl_;
  I.path = path;
  if (gzip) {
    I.gz = gzopen(path.c_str(), ("wb" + std::to_string(level)).c_str());
    if (!I.gz) fail(path, "cannot create");
  } else {
    I.plain = std::fopen(path.c_str(), "wb");
    if (!I.plain) fail(path, "cannot create");
  }
  I.ci = meta.schema.ci();
  I.oi = meta.schema.oi();
  const auto& c = meta.cameras[0];
  double sw[4];
  c.effectiveScreenWindow(sw);
  I.buf += "##RenderMan RIB\nversion 3.04\n# micropolygon dump: Cs = shaded colour, Os = shaded opacity (premultiplied)\n";
  I.buf += "Declare \"blurP\" \"varying point\"\n";
  I.buf += cat("FrameBegin ", meta.frame, "\nFormat ", c.width, " ", c.height, " ", c.pixelAspect, "\n");
  if (c.projection == store::Projection::Perspective)
    I.buf += cat("Projection \"perspective\" \"fov\" [", c.fovDegrees, "]\n");
  else
    I.buf += "Projection \"orthographic\"\n";
  I.buf += cat("ScreenWindow ", sw[0], " ", sw[1], " ", sw[2], " ", sw[3], "\nClipping ", c.nearClip, " ", c.farClip, "\n");
  I.buf += cat("Shutter ", meta.shutterOpen, " ", meta.shutterClose, "\nWorldBegin\nCoordSysTransform \"camera\"\nSides 2\n");
}

DumpRibWriter::~DumpRibWriter() {
  if (impl_->gz) gzclose(impl_->gz);
  if (impl_->plain) std::fclose(impl_->plain);
}

uint32_t DumpRibWriter::addSchedule(const store::Schedule& k) {
  impl_->schedules.push_back(k);
  return uint32_t(impl_->schedules.size() - 1);
}

void DumpRibWriter::addGrid(const store::GridInput& g) {
  auto& I = *impl_;
  const size_t K = I.schedules.at(g.schedule).size();
  if (K > 2) fail(I.path, "the blurP dump form holds two knots, not ", K);
  const size_t nMp = g.numMicropolygons();
  I.buf += "PointsPolygons [";
  for (size_t m = 0; m < nMp; ++m) I.integer(g.corners[m * 4 + 3] == store::kNoCorner ? 3 : 4);
  I.buf += "] [";
  for (size_t m = 0; m < nMp; ++m)
    for (int j = 0; j < 4; ++j)
      if (g.corners[m * 4 + j] != store::kNoCorner) I.integer(g.corners[m * 4 + j]);
  auto points = [&](const char* name, size_t knot) {
    I.buf += cat("] \"", name, "\" [");
    for (uint32_t v = 0; v < g.numVertices; ++v)
      for (int c = 0; c < 3; ++c) I.number(g.positions[knot * g.numVertices + v][c]);
  };
  points("P", 0);
  for (auto [attr, name] : {std::pair{I.ci, "Cs"}, std::pair{I.oi, "Os"}}) {
    I.buf += cat("] \"", name, "\" [");
    for (float f : g.attrs.at(size_t(attr)).f) I.number(f);
  }
  if (K == 2) points("blurP", 1);
  I.buf += "]\n";
  I.flush();
}

void DumpRibWriter::close() {
  impl_->buf += "WorldEnd\nFrameEnd\n";
  impl_->flush(true);
  if (impl_->gz) {
    if (gzclose(impl_->gz) != Z_OK) fail(impl_->path, "gzip close failed");
    impl_->gz = nullptr;
  }
  if (impl_->plain) {
    std::fclose(impl_->plain);
    impl_->plain = nullptr;
  }
}

}  // namespace reshutter::bench
