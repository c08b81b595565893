// Texture lookups for the built-in shaders, through OpenImageIO's TextureSystem (mip-mapped,
// filtered by each lookup's st footprint; .tx, .tif, .exr, .png and whatever else OpenImageIO
// reads). Names resolve through the scene's texture search path (`Option "searchpath"
// "texture"`, relative entries taken from the RIB file's directory), as RenderMan resolves them.
// A texture that cannot be read warns once, naming the file, and looks up as a visible default
// (magenta), never an error: a missing map should not stop a frame. One OpenImageIO texture
// system serves the process (its cache outlives a frame); a TextureLookup sets its search path
// and counts one shading pass's lookups.
#pragma once

#include <memory>
#include <mutex>
#include <set>
#include <string>

#include <glm/vec3.hpp>

namespace reshutter::shade {

class TextureLookup {
 public:
  /// `searchPath`: directories separated by ':' (OpenImageIO's own search path). One lookup
  /// object at a time: the search path is the process's texture system's.
  explicit TextureLookup(const std::string& searchPath);
  ~TextureLookup();
  TextureLookup(const TextureLookup&) = delete;
  TextureLookup& operator=(const TextureLookup&) = delete;

  /// A texture resolved once (for a grid's lookups): its handle and channel count; a texture
  /// that cannot be read has none and warns once.
  struct Map {
    const void* handle = nullptr;
    int channels = 0;
  };
  Map find(const std::string& name) const;

  /// The filtered RGB of `map` over the footprint spanned by (dsdx, dtdx) and (dsdy, dtdy) at
  /// (s, t); (0, 0) is the image's top-left corner, as RenderMan's texture(). A one-channel
  /// texture is grey; a missing one magenta. Thread-safe.
  glm::dvec3 rgb(const Map& map, float s, float t, float dsdx, float dtdx, float dsdy, float dtdy) const;

  /// The colour a texture that cannot be read shows.
  static constexpr double kMissing[3] = {1.0, 0.0, 1.0};

  /// Lookups made and textures that could not be read (for stats and tests).
  uint64_t lookups() const;
  std::set<std::string> missing() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

/// A built-in texture for the demo scene (no input files): a brick wall, written once as a
/// mip-mapped .tx in the temporary directory (atomically, so concurrent runs share it); its
/// path. Errors if the file cannot be made.
std::string demoBrickTexture();

}  // namespace reshutter::shade
