#include "shade/texture.h"

#include <algorithm>
#include <atomic>
#include <cmath>
#include <filesystem>
#include <system_error>

#include <OpenImageIO/imagebuf.h>
#include <OpenImageIO/imagebufalgo.h>
#include <OpenImageIO/texture.h>
#include <unistd.h>

#include "common/error.h"
#include "common/log.h"
#include "common/random.h"

namespace reshutter::shade {

struct TextureLookup::Impl {
  OIIO::TextureSystem* ts = nullptr;
  mutable std::mutex mutex;  // guards missing
  mutable std::set<std::string> missing;
  mutable std::atomic<uint64_t> lookups{0};
};

namespace {
// One texture system for the process, kept until exit: its cache then serves every frame of a
// shot. It is never destroyed because OpenImageIO 2.4's TextureSystem::destroy() deletes the
// object through the wrong type (AddressSanitizer: new-delete-type-mismatch); a pointer held
// here is reachable, so it is no leak either.
OIIO::TextureSystem* processTextureSystem() {
  static OIIO::TextureSystem* ts = [] {
    OIIO::TextureSystem* t = OIIO::TextureSystem::create(false);
    t->attribute("max_memory_MB", 512.0f);
    return t;
  }();
  return ts;
}
}  // namespace

TextureLookup::TextureLookup(const std::string& searchPath) : impl_(std::make_unique<Impl>()) {
  impl_->ts = processTextureSystem();
  impl_->ts->attribute("searchpath", searchPath);  // this scene's (frames are shaded one at a time)
}

TextureLookup::~TextureLookup() = default;

TextureLookup::Map TextureLookup::find(const std::string& name) const {
  const OIIO::ustring u(name);
  OIIO::TextureSystem::TextureHandle* handle = impl_->ts->get_texture_handle(u);
  int channels = 0;
  if (!handle || !impl_->ts->good(handle) || !impl_->ts->get_texture_info(handle, nullptr, 0, OIIO::ustring("channels"), OIIO::TypeDesc::INT, &channels) ||
      channels < 1) {
    const std::string why = impl_->ts->geterror();
    std::lock_guard<std::mutex> lock(impl_->mutex);
    if (impl_->missing.insert(name).second)
      warn(cat("texture '", name, "' cannot be read (", why.empty() ? "not found on the texture search path" : why, "); it shows as magenta"));
    return {};
  }
  return {handle, channels};
}

glm::dvec3 TextureLookup::rgb(const Map& map, float s, float t, float dsdx, float dtdx, float dsdy, float dtdy) const {
  if (!map.handle) return {kMissing[0], kMissing[1], kMissing[2]};
  impl_->lookups.fetch_add(1, std::memory_order_relaxed);
  OIIO::TextureOpt opt;
  opt.swrap = opt.twrap = OIIO::TextureOpt::WrapPeriodic;  // RenderMan's default wrap
  float result[3] = {0, 0, 0};
  auto* handle = const_cast<OIIO::TextureSystem::TextureHandle*>(static_cast<const OIIO::TextureSystem::TextureHandle*>(map.handle));
  if (!impl_->ts->texture(handle, nullptr, opt, s, t, dsdx, dtdx, dsdy, dtdy, std::min(map.channels, 3), result))
    return {kMissing[0], kMissing[1], kMissing[2]};
  if (map.channels < 3) return {result[0], result[0], result[0]};  // one channel: grey
  return {result[0], result[1], result[2]};
}

uint64_t TextureLookup::lookups() const { return impl_->lookups.load(); }

std::set<std::string> TextureLookup::missing() const {
  std::lock_guard<std::mutex> lock(impl_->mutex);
  return impl_->missing;
}

std::string demoBrickTexture() {
  // The version in the name changes with the pattern, so an old file is never taken for it.
  const std::filesystem::path path = std::filesystem::temp_directory_path() / "reshutter-demo-bricks-v1.tx";
  std::error_code ec;
  if (std::filesystem::exists(path, ec)) return path.string();
  constexpr int size = 512, rows = 8, perRow = 4;
  OIIO::ImageBuf image(OIIO::ImageSpec(size, size, 3, OIIO::TypeDesc::FLOAT));
  const float mortar[3] = {0.72f, 0.70f, 0.66f};
  for (int y = 0; y < size; ++y)
    for (int x = 0; x < size; ++x) {
      const double v = double(y) / size * rows, row = std::floor(v);
      const double u = double(x) / size * perRow + (int(row) % 2 ? 0.5 : 0.0), col = std::floor(u);
      const double fu = u - col, fv = v - row;
      const bool joint = fu < 0.04 || fu > 0.96 || fv < 0.07 || fv > 0.93;
      // Each brick its own shade of red-brown, from a hash of its place (wrapping with the tile).
      const double h = toUnitDouble(mix64(uint64_t(row) * 131 + uint64_t(int(col) % perRow)));
      const float brick[3] = {float(0.45 + 0.25 * h), float(0.16 + 0.10 * h), float(0.10 + 0.06 * h)};
      image.setpixel(x, y, joint ? mortar : brick, 3);
    }
  // Written under a name of this process's own, then renamed: a reader never sees half a file.
  const std::filesystem::path tmp =
      std::filesystem::temp_directory_path() / cat("reshutter-demo-bricks-v1.", ::getpid(), ".tmp.tx");  // maketx picks the format by extension
  OIIO::ImageSpec config;
  config.attribute("maketx:filtername", "box");
  if (!OIIO::ImageBufAlgo::make_texture(OIIO::ImageBufAlgo::MakeTxTexture, image, tmp.string(), config))
    fail(tmp.string(), "cannot write the demo texture: ", OIIO::geterror());
  std::filesystem::rename(tmp, path, ec);
  if (ec) fail(path.string(), "cannot write the demo texture: ", ec.message());
  return path.string();
}

}  // namespace reshutter::shade
