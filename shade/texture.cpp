#include "shade/texture.h"

#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <system_error>
#include <vector>

#include "common/error.h"
#include "common/log.h"
#include "common/module.h"
#include "common/random.h"
#include "shade/texture_backend.h"

namespace reshutter::shade {

namespace {
// The OpenImageIO module, loaded once for the process on first use (texture_backend.h says
// why); RESHUTTER_TEXTURE_MODULE in the environment names another copy of it.
TextureBackend& backend() {
  static TextureBackend* b = [] {
    using Entry = TextureBackend* (*)();
    return reinterpret_cast<Entry>(loadModule("RESHUTTER_TEXTURE_MODULE", "libreshutter_texture.so", RESHUTTER_TEXTURE_MODULE, "reshutter_texture_backend",
                                              "texture"))();
  }();
  return *b;
}
}  // namespace

struct TextureLookup::Impl {
  TextureBackend* backend = nullptr;
  mutable std::mutex mutex;  // guards missing
  mutable std::set<std::string> missing;
  mutable std::atomic<uint64_t> lookups{0};
};

TextureLookup::TextureLookup(const std::string& searchPath) : impl_(std::make_unique<Impl>()) {
  impl_->backend = &backend();
  impl_->backend->setSearchPath(searchPath);  // this scene's (frames are shaded one at a time)
}

TextureLookup::~TextureLookup() = default;

TextureLookup::Map TextureLookup::find(const std::string& name) const {
  int channels = 0;
  std::string why;
  const void* handle = impl_->backend->find(name, channels, why);
  if (!handle) {
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
  float result[3] = {0, 0, 0};
  if (!impl_->backend->lookup(map.handle, std::min(map.channels, 3), s, t, dsdx, dtdx, dsdy, dtdy, result)) return {kMissing[0], kMissing[1], kMissing[2]};
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
  std::vector<float> image(size_t(size) * size * 3);
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
      std::copy_n(joint ? mortar : brick, 3, &image[3 * (size_t(y) * size + size_t(x))]);
    }
  // Written under a name of this process's own, then renamed: a reader never sees half a file.
  const std::filesystem::path tmp =
      std::filesystem::temp_directory_path() / cat("reshutter-demo-bricks-v1.", ::getpid(), ".tmp.tx");  // maketx picks the format by extension
  std::string why;
  if (!backend().makeTexture(image.data(), size, size, tmp.string(), why)) fail(tmp.string(), "cannot write the demo texture: ", why);
  std::filesystem::rename(tmp, path, ec);
  if (ec) fail(path.string(), "cannot write the demo texture: ", ec.message());
  return path.string();
}

}  // namespace reshutter::shade
