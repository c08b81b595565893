// Crop tiles into whole images: the flat and deep OpenEXR tiles of one frame, rendered apart
// with --crop (on a farm, one task per tile), merged into the image the whole-frame render
// writes, byte for byte. That holds because a crop renders exactly the pixels the whole frame
// has there (every pixel's samples and filter support are the same whatever the tiling) and the
// assembled image goes through the same writers with the tiles' own header and options.
#pragma once

#include <string>
#include <vector>

#include "resample/exr_read.h"

namespace reshutter::resample {

/// Merges flat tiles: each must share the display window, channels (names, types), provenance
/// and compression, none may overlap, and together they must fill one rectangle (the data
/// window of the result). `names` label the tiles in errors. Throws Error naming the tile.
FlatExr assembleFlat(std::vector<FlatExr> tiles, const std::vector<std::string>& names);
/// Merges deep tiles under the same rules (the channels may differ only in ZBack and AR AG AB,
/// which the writer adds when any sample needs them). Throws Error naming the tile.
DeepExr assembleDeep(std::vector<DeepExr> tiles, const std::vector<std::string>& names);

/// Reads the tiles, merges them and writes `out` (flat or deep, as the tiles are); returns the
/// number of pixels written.
size_t assembleExrFiles(const std::vector<std::string>& tiles, const std::string& out);

}  // namespace reshutter::resample
