// The interface between shade/texture.cpp and the OpenImageIO module that implements it
// (texture_oiio.cpp, built as its own shared object and loaded on first use). OpenImageIO pulls
// in about 260 shared libraries whose loading and relocation cost every reshutter process
// 0.4 s at start; loading them only when a frame has textures keeps that off every other
// command (resample, fields, retime, farm tasks) and off the test suite's hundreds of runs.
#pragma once

#include <string>

namespace reshutter::shade {

class TextureBackend {
 public:
  virtual ~TextureBackend() = default;
  virtual void setSearchPath(const std::string& searchPath) = 0;
  /// A handle for `name` and its channel count, or null with the reason in `why`.
  virtual const void* find(const std::string& name, int& channels, std::string& why) = 0;
  /// The filtered lookup of up to three channels into `out`; false on failure.
  virtual bool lookup(const void* handle, int channels, float s, float t, float dsdx, float dtdx, float dsdy, float dtdy, float out[3]) = 0;
  /// Writes a mip-mapped texture of `rgb` (width × height, 3 floats a pixel, top row first) to
  /// `path`; false with the reason in `why`.
  virtual bool makeTexture(const float* rgb, int width, int height, const std::string& path, std::string& why) = 0;
};

}  // namespace reshutter::shade

/// The module's one entry point: the process's backend (never destroyed).
extern "C" reshutter::shade::TextureBackend* reshutter_texture_backend();
