// Volumes as the re-sampler sees them (resample/volume.h): the specs users write, and the public
// classes, which hand the work to the OpenVDB plugin's engines (resample/volume_engine.h); and
// the plugin's loading, the first time a volume is asked for.
#include "resample/volume_engine.h"

#include <atomic>
#include <cmath>
#include <sstream>

#include "common/error.h"
#include "common/module.h"

namespace reshutter::resample {

namespace {

double parseNumber(const std::string& text, const std::string& where, const std::string& key) {
  try {
    size_t used = 0;
    const double v = std::stod(text, &used);
    if (used == text.size() && std::isfinite(v)) return v;
  } catch (const std::exception&) {
  }
  fail(where, "'", key, "' wants a number, not '", text, "'");
}

glm::dvec3 parseTriple(const std::string& text, const std::string& where, const std::string& key) {
  std::vector<std::string> parts;
  std::stringstream in(text);
  for (std::string p; std::getline(in, p, ':');) parts.push_back(p);
  if (parts.size() != 3) fail(where, "'", key, "' wants three numbers X:Y:Z, not '", text, "'");
  return {parseNumber(parts[0], where, key), parseNumber(parts[1], where, key), parseNumber(parts[2], where, key)};
}

std::atomic<bool> engineLoaded{false};

}  // namespace

VolumeSpec VolumeSpec::parse(const std::string& text, const std::string& where) {
  VolumeSpec s;
  std::vector<std::string> fields;
  std::stringstream in(text);
  for (std::string f; std::getline(in, f, ',');) fields.push_back(f);
  if (fields.empty() || fields[0].empty()) fail(where, "a volume starts with its OpenVDB file: FILE.vdb[,density=GRID][,scale=S]...");
  s.path = fields[0];
  for (size_t i = 1; i < fields.size(); ++i) {
    const size_t eq = fields[i].find('=');
    if (eq == std::string::npos) fail(where, "'", fields[i], "' is not KEY=VALUE");
    const std::string key = fields[i].substr(0, eq), value = fields[i].substr(eq + 1);
    if (key == "density") s.density = value;
    else if (key == "emission") s.emission = value;
    else if (key == "velocity") s.velocity = value;
    else if (key == "color") s.colour = value;
    else if (key == "scale") s.scale = parseNumber(value, where, key);
    else if (key == "translate") s.translate = parseTriple(value, where, key);
    else if (key == "density-scale") s.densityScale = float(parseNumber(value, where, key));
    else if (key == "emission-color") s.emissionColour = glm::vec3(parseTriple(value, where, key));
    else if (key == "albedo") s.albedo = glm::vec3(parseTriple(value, where, key));
    else if (key == "anisotropy") s.anisotropy = float(parseNumber(value, where, key));
    else fail(where, "unknown volume key '", key, "' (density emission velocity color scale translate density-scale emission-color albedo anisotropy)");
  }
  if (s.density.empty()) fail(where, "a volume needs a density grid");
  if (!(s.scale > 0)) fail(where, "'scale' must be positive");
  if (!(s.densityScale >= 0)) fail(where, "'density-scale' must not be negative");
  if (!(s.albedo.x >= 0 && s.albedo.y >= 0 && s.albedo.z >= 0 && s.albedo.x <= 1 && s.albedo.y <= 1 && s.albedo.z <= 1))
    fail(where, "'albedo' must lie in [0, 1]");
  if (!(s.anisotropy > -1 && s.anisotropy < 1)) fail(where, "'anisotropy' must lie in (-1, 1)");
  return s;
}

VolumeSpec VolumeSpec::fromStore(const store::StoredVolume& v) {
  VolumeSpec s;
  s.path = v.path, s.density = v.density;
  s.times = v.times, s.fileToCamera = v.fileToCamera;
  return s;
}

// ------------------------------------------------------------------------------------------
// The plugin

const VolumeEngine& volumeEngine() {
  // A magic static: loaded once, by the first thread to ask; a failure throws and the next call
  // tries again.
  static const VolumeEngine* const engine = [] {
#ifdef RESHUTTER_VOLUME_MODULE_BUILT
    const std::string built = RESHUTTER_VOLUME_MODULE_BUILT;
#else
    const std::string built;
#endif
    using Entry = const VolumeEngine* (*)();
    const auto entry = reinterpret_cast<Entry>(loadModule("RESHUTTER_VOLUME_MODULE", "libreshutter_volume.so", built, kVolumeEngineEntry, "OpenVDB volume"));
    engineLoaded = true;
    return entry();
  }();
  return *engine;
}

bool volumeSupportLoaded() { return engineLoaded; }

// ------------------------------------------------------------------------------------------
// The public classes

VolumeScene::VolumeScene(const std::vector<VolumeSpec>& specs, const VolumeOptions& options) : options_(options) {
  if (!(options_.step > 0)) fail("--volume-step", "the step must be positive");
  if (!(options_.shadowStep > 0)) fail("--volume-shadow-step", "the step must be positive");
  if (!(options_.raySpacing >= 0)) fail("--volume-ray-spacing", "the spacing must not be negative");
  engine_ = volumeEngine().load(specs, options_, warnings_);
}

VolumeScene::VolumeScene(const VolumeScene& base, const std::vector<VolumeSpec>& more) : VolumeScene(more, base.options()) {
  engine_ = volumeEngine().merge(*base.engine_, *engine_);
  warnings_.insert(warnings_.begin(), base.warnings_.begin(), base.warnings_.end());
}

VolumeScene::~VolumeScene() = default;
size_t VolumeScene::size() const { return engine_->size(); }

VolumeLighting::VolumeLighting(const VolumeScene& scene, const VolumeCamera& camera) : engine_(volumeEngine().light(scene.engine(), camera)) {}
VolumeLighting::~VolumeLighting() = default;
uint64_t VolumeLighting::buildSteps() const { return engine_->buildSteps(); }

VolumeTracer::VolumeTracer(const VolumeScene& scene, const VolumeCamera& camera, double earliest, double latest, const VolumeLighting* lighting)
    : engine_(volumeEngine().tracer(scene.engine(), camera, earliest, latest, lighting ? &lighting->engine() : nullptr)) {}
VolumeTracer::~VolumeTracer() = default;
bool VolumeTracer::touches(double x0, double y0, double x1, double y1) const { return engine_->touches(x0, y0, x1, y1); }
void VolumeTracer::beginRegion(int x0, int y0, int w, int h) { engine_->beginRegion(x0, y0, w, h); }
bool VolumeTracer::sharesRays() const { return engine_->sharesRays(); }
void VolumeTracer::integrate(double x, double y, double u, double v, double t, double z0, double z1, VolumeSegment& out, std::vector<VolumeSlice>* slices,
                             double ratio) {
  engine_->integrate(x, y, u, v, t, z0, z1, out, slices, ratio, stats_);
}

void writeSmokePuff(const std::string& path, const SmokePuff& puff) { volumeEngine().writeSmokePuff(path, puff); }

}  // namespace reshutter::resample
