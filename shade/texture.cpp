#include "shade/texture.h"

#include <algorithm>
#include <atomic>

#include <OpenImageIO/texture.h>

#include "common/error.h"
#include "common/log.h"

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

}  // namespace reshutter::shade
