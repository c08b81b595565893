// Reading reshutter's own OpenEXR output back, whole: a flat file as the FlatImage, provenance
// and options its writer took (image.h), a deep file as the DeepImage (deep.h), so that writing
// them again gives the same bytes. The farm's tile assembly (assemble.h) and its check that
// every frame of a job exists and reads are built on it. Other programs' files read too, as far
// as the data model holds them (unknown attributes are dropped).
#pragma once

#include <string>

#include "resample/deep.h"
#include "resample/image.h"

namespace reshutter::resample {

struct FlatExr {
  FlatImage image;  // channels in the header's (alphabetical) order; half channels flagged half
  ImageProvenance provenance;
  ExrOptions options;
};

struct DeepExr {
  DeepImage image;  // one block; ZBack = Z and AR = AG = AB = A where the file has no such channel
  ImageProvenance provenance;
  DeepExrOptions options;
  bool hasZBack = false, hasColouredAlpha = false;  // the file has ZBack / AR AG AB
};

/// Whether `path` is a deep OpenEXR (false: flat). Throws Error naming the file if it is not an
/// OpenEXR file OpenEXR can open.
bool isDeepExr(const std::string& path);
/// Reads every pixel of a flat scanline OpenEXR. Throws Error naming the file on failure.
FlatExr readFlatExr(const std::string& path);
/// Reads every sample of a deep scanline OpenEXR. Throws Error naming the file on failure.
DeepExr readDeepExr(const std::string& path);
/// Reads a flat or deep OpenEXR whole (every pixel decoded, every checksum OpenEXR keeps
/// checked): what "the frame exists and reads" means to the farm. Throws Error naming the file.
void verifyExr(const std::string& path);

}  // namespace reshutter::resample
