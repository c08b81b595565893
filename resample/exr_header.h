// Header attributes shared by the flat and the deep OpenEXR writers (image.cpp, deep.cpp): the
// rendering's camera matrices, frame rate, exposure, shutter and software.
#pragma once

#include <OpenEXR/ImfForward.h>

#include "resample/image.h"

namespace reshutter::resample {

/// Adds worldToCamera, worldToNDC, framesPerSecond, expTime, software, comments and the
/// reshutter/frame, reshutter/shutter and reshutter/shutterInterval attributes.
void addProvenanceAttributes(Imf::Header& header, const ImageProvenance& info);

}  // namespace reshutter::resample
