// Plugin modules: shared objects the program loads on first use - OpenImageIO's texture system
// (shade/texture_backend.h), OpenVDB's volumes (resample/volume_engine.h) - so that a process
// which needs neither never maps those heavy libraries.
#pragma once

#include <string>

namespace reshutter {

/// Opens a module and returns the address of its entry point `entry`. Looks, in order: at the
/// path in environment variable `envVar` when it is set (and nowhere else), else at `fileName`
/// beside the running program, else at `builtPath` (where the build put it). Throws Error
/// "FIRST PATH: cannot load the WHAT module (each place tried and why)" when none loads.
void* loadModule(const char* envVar, const std::string& fileName, const std::string& builtPath, const char* entry, const std::string& what);

}  // namespace reshutter
