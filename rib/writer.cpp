// The dump writer: RIB text built in a buffer and written (through zlib or not) a megabyte at a
// time.
#include "rib/writer.h"

#include <charconv>
#include <cstdio>

#include <zlib.h>

#include "common/check.h"
#include "common/error.h"

namespace reshutter::rib {

struct DumpWriter::Impl {
  std::string path;
  gzFile gz = nullptr;
  FILE* plain = nullptr;
  std::string buf;

  void flush(bool force = false) {
    if (buf.size() < (1u << 20) && !force) return;
    if (gz) {
      if (gzwrite(gz, buf.data(), unsigned(buf.size())) != int(buf.size())) fail(path, "gzip write failed");
    } else if (std::fwrite(buf.data(), 1, buf.size(), plain) != buf.size()) {
      fail(path, "write failed");
    }
    buf.clear();
  }
  void number(float v) {
    char tmp[32];
    auto r = std::to_chars(tmp, tmp + sizeof tmp, v);  // shortest text that reads back exactly
    buf.append(tmp, r.ptr);
    buf += ' ';
  }
  void integer(uint32_t v) {
    char tmp[16];
    auto r = std::to_chars(tmp, tmp + sizeof tmp, v);
    buf.append(tmp, r.ptr);
    buf += ' ';
  }
  /// Closes the previous array and opens the parameter `name`'s.
  void array(const char* name, std::span<const float> values) {
    buf += cat("] \"", name, "\" [");
    for (float f : values) number(f);
  }
};

DumpWriter::DumpWriter(const std::string& path, const DumpHeader& h, bool gzip, int level) : impl_(std::make_unique<Impl>()) {
  auto& I = *impl_;
  I.path = path;
  if (gzip) {
    I.gz = gzopen(path.c_str(), ("wb" + std::to_string(level)).c_str());
    if (!I.gz) fail(path, "cannot create");
  } else {
    I.plain = std::fopen(path.c_str(), "wb");
    if (!I.plain) fail(path, "cannot create");
  }
  const double* sw = h.screenWindow;
  I.buf += "##RenderMan RIB\nversion 3.04\n# micropolygon dump: Cs = shaded colour, Os = shaded opacity (premultiplied)\n";
  I.buf += "Declare \"blurP\" \"varying point\"\n";
  I.buf += cat("FrameBegin ", h.frame, "\nFormat ", h.width, " ", h.height, " ", h.pixelAspect, "\n");
  if (h.perspective) I.buf += cat("Projection \"perspective\" \"fov\" [", h.fovDegrees, "]\n");
  else I.buf += "Projection \"orthographic\"\n";
  I.buf += cat("ScreenWindow ", sw[0], " ", sw[1], " ", sw[2], " ", sw[3], "\nClipping ", h.nearClip, " ", h.farClip, "\n");
  I.buf += cat("Shutter ", h.shutterOpen, " ", h.shutterClose, "\nWorldBegin\nCoordSysTransform \"camera\"\nSides 2\n");
}

DumpWriter::~DumpWriter() {
  if (impl_->gz) gzclose(impl_->gz);
  if (impl_->plain) std::fclose(impl_->plain);
}

const std::string& DumpWriter::path() const { return impl_->path; }

void DumpWriter::addGrid(const DumpGrid& g) {
  auto& I = *impl_;
  CHECK(g.P.size() == size_t(g.numVertices) * 3 && (g.blurP.empty() || g.blurP.size() == g.P.size()) && g.corners.size() % 4 == 0, I.path, ": a grid of ",
        g.numVertices, " vertices with ", g.P.size(), " P, ", g.blurP.size(), " blurP numbers and ", g.corners.size(), " corners");
  const size_t nMp = g.corners.size() / 4;
  I.buf += "PointsPolygons [";
  for (size_t m = 0; m < nMp; ++m) I.integer(g.corners[m * 4 + 3] == kNoCorner ? 3 : 4);
  I.buf += "] [";
  for (size_t m = 0; m < nMp; ++m)
    for (int j = 0; j < 4; ++j)
      if (g.corners[m * 4 + j] != kNoCorner) I.integer(g.corners[m * 4 + j]);
  I.array("P", g.P);
  I.array("Cs", g.Cs);
  I.array("Os", g.Os);
  if (!g.blurP.empty()) I.array("blurP", g.blurP);
  I.buf += "]\n";
  I.flush();
}

void DumpWriter::close() {
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

}  // namespace reshutter::rib
