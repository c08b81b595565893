// The texture backend on OpenImageIO's TextureSystem (shade/texture_backend.h says why it is a
// module of its own).
#include <OpenImageIO/imagebuf.h>
#include <OpenImageIO/imagebufalgo.h>
#include <OpenImageIO/texture.h>

#include "shade/texture_backend.h"

namespace reshutter::shade {
namespace {

class OiioBackend final : public TextureBackend {
 public:
  // One texture system for the process, kept until exit: its cache then serves every frame of
  // a shot. It is never destroyed because OpenImageIO 2.4's TextureSystem::destroy() deletes
  // the object through the wrong type (AddressSanitizer: new-delete-type-mismatch); a pointer
  // held here is reachable, so it is no leak either.
  OiioBackend() : ts_(OIIO::TextureSystem::create(false)) { ts_->attribute("max_memory_MB", 512.0f); }

  void setSearchPath(const std::string& searchPath) override { ts_->attribute("searchpath", searchPath); }

  const void* find(const std::string& name, int& channels, std::string& why) override {
    OIIO::TextureSystem::TextureHandle* handle = ts_->get_texture_handle(OIIO::ustring(name));
    channels = 0;
    if (!handle || !ts_->good(handle) || !ts_->get_texture_info(handle, nullptr, 0, OIIO::ustring("channels"), OIIO::TypeDesc::INT, &channels) ||
        channels < 1) {
      why = ts_->geterror();
      return nullptr;
    }
    return handle;
  }

  bool lookup(const void* handle, int channels, float s, float t, float dsdx, float dtdx, float dsdy, float dtdy, float out[3]) override {
    OIIO::TextureOpt opt;
    opt.swrap = opt.twrap = OIIO::TextureOpt::WrapPeriodic;  // RenderMan's default wrap
    auto* h = const_cast<OIIO::TextureSystem::TextureHandle*>(static_cast<const OIIO::TextureSystem::TextureHandle*>(handle));
    return ts_->texture(h, nullptr, opt, s, t, dsdx, dtdx, dsdy, dtdy, channels, out);
  }

  bool makeTexture(const float* rgb, int width, int height, const std::string& path, std::string& why) override {
    OIIO::ImageBuf image(OIIO::ImageSpec(width, height, 3, OIIO::TypeDesc::FLOAT));
    for (int y = 0; y < height; ++y)
      for (int x = 0; x < width; ++x) image.setpixel(x, y, rgb + 3 * (size_t(y) * size_t(width) + size_t(x)), 3);
    OIIO::ImageSpec config;
    config.attribute("maketx:filtername", "box");
    if (OIIO::ImageBufAlgo::make_texture(OIIO::ImageBufAlgo::MakeTxTexture, image, path, config)) return true;
    why = OIIO::geterror();
    return false;
  }

 private:
  OIIO::TextureSystem* ts_;
};

}  // namespace
}  // namespace reshutter::shade

extern "C" reshutter::shade::TextureBackend* reshutter_texture_backend() {
  static auto* backend = new reshutter::shade::OiioBackend();
  return backend;
}
