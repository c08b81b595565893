// Reading the OpenEXR files the CLI writes back with OpenEXR itself: every channel of a flat file
// as a resample::FlatImage, every sample of a scanline deep file as a resample::DeepImage (so tests flatten it with
// resample::flattenDeepPixel, the reference the deep tests hold renders to), and the header's
// reshutter attributes. Throws on a file OpenEXR cannot read.
#pragma once

#include <string>
#include <vector>

#include "resample/deep.h"
#include "resample/image.h"

namespace reshutter::test {

/// Every channel of a flat OpenEXR (half read as float), in the header's (alphabetical) order.
resample::FlatImage readFlatExr(const std::string& path);

struct DeepExr {
  /// R G B A Z, ZBack (Z where the file has none), AR AG AB (A where it has none), objectid;
  /// output variables are not read (the layout has none), sample flags are 0.
  resample::DeepImage image;
  std::vector<std::string> channels;  // as the header lists them
  bool tidyState = false;             // deepImageState says TIDY
  bool manifest = false;              // an idManifest is present
};
DeepExr readDeepExr(const std::string& path);
/// Part `part` of a multi-part deep OpenEXR, and its `view` attribute ("" when absent).
DeepExr readDeepExrPart(const std::string& path, int part, std::string& view);

/// The reshutter/shutter (description) and reshutter/shutterInterval attributes of a flat or deep OpenEXR.
struct ExrShutter {
  std::string description;
  double open = 0, close = 0;
};
ExrShutter readExrShutter(const std::string& path);

}  // namespace reshutter::test
