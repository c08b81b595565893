#include "cli/render_options.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <sstream>

#include "common/atomic_file.h"
#include "common/error.h"
#include "common/frame_range.h"
#include "common/log.h"
#include "resample/camera_view.h"
#include "shade/rib_scene.h"
#include "resample/simd.h"

namespace reshutter::cli {

void RenderOptions::addTo(CLI::App* app) {
  auto* s = app->add_option("--spp", spp, "Samples per pixel (default 16), stratified in position and time")->group("Sampling");
  app->add_option("--samples", samples, "Samples per pixel as a grid, e.g. 4x4")->excludes(s)->group("Sampling");
  app->add_option("--filter", filter, "Pixel filter NAME[:WIDTH[xHEIGHT]]: box triangle gaussian catmull-rom sinc blackman-harris mitchell")
      ->capture_default_str()
      ->group("Sampling");
  app->add_option("--seed", seed, "Sample pattern seed (same seed, same image, any thread count)")->capture_default_str()->group("Sampling");
  app->add_option("--aov", aovs,
                  "Output variable NAME[:FILTER], repeatable: a store variable (N, P, s, Cs ...), id (object id) or z;\n"
                  "FILTER is a pixel filter or min max average zmin zmax (closest surface only)")
      ->group("Outputs");
  app->add_option("--res", res, "Output resolution W H (default: the store camera's)")->expected(2)->group("Outputs");
  app->add_option("--crop", crop, "Render only pixels x0 <= x < x1, y0 <= y < y1 (the EXR data window)")->expected(4)->group("Outputs");
  app->add_flag("--half", half, "Write R G B A as half floats")->group("Outputs");
  app->add_option("--compression", compression,
                  "OpenEXR compression: none rle zips zip piz pxr24 b44 b44a dwaa dwab\n"
                  "(piz: lossless; on noisy float renders smaller and faster to write than zip, see bench/RESULTS.md)")
      ->capture_default_str()
      ->group("Outputs");
  app->add_option("--preview", previews, "Also write an 8/16-bit PNG or TIFF: PATH or PATH=CHANNELS (default R,G,B,A; e.g. n.png=N.X,N.Y,N.Z)")
      ->group("Outputs");
  app->add_option("--deep", deep, "Also write a deep OpenEXR (scanline, tidy; see docs/deep.md); %04d-style frame patterns expand")->group("Outputs");
  app->add_option("--deep-compression", deepCompression, "Deep OpenEXR compression: zips rle none")->capture_default_str()->group("Outputs");
  app->add_option("--deep-tolerance", deepTolerance,
                  "Relative depth gap below which one object's fragments form one deep sample (larger: fewer samples, less separation)")
      ->capture_default_str()
      ->check(CLI::Range(0.0, 1e3))
      ->group("Outputs");
  app->add_flag("--deep-all-channels", deepAllChannels,
                "Write ZBack and AR AG AB even where no sample needs them (crop tiles that `reshutter assemble` merges later)")
      ->group("Outputs");
  app->add_option("--quantize", quantize, "Preview quantisation ZERO,ONE,MIN,MAX (MAX > 255 gives 16 bits)")->capture_default_str()->group("Outputs");
  app->add_option("--dither", dither, "Preview dither amplitude")->capture_default_str()->group("Outputs");
  app->add_option("--opacity-threshold", opacityThreshold, "A sample stops once its opacity reaches this")
      ->capture_default_str()
      ->check(CLI::Range(0.0, 1.0))
      ->group("Compositing");
  app->add_flag("--backface-cull", backfaceCull, "Knock out micropolygons facing away (unless two-sided)")->group("Compositing");
  app->add_option("--bucket", bucket,
                  "Bucket size in pixels; 0 (the default) chooses: 64 when nothing reads the samples' times and there is no lens (a motion-free "
                  "store, or an instant), else 96; through a lens 48 to 128 by the typical circle of confusion (larger circles, larger "
                  "buckets; motion adds 32) (measured: bench/RESULTS.md); the image is the same for any size")
      ->capture_default_str()
      ->group("Performance");
  app->add_option("--cache-mb", cacheMb,
                  "Decoded tile cache per store, MB (parts leave it after their last bucket; the budget bounds what a sequence keeps for its next frame)")
      ->capture_default_str()
      ->group("Performance");
  app->add_option("--simd", simd,
                  "Instruction set of the rasterizer's inner loops: auto (the widest this CPU runs), avx512, avx2 or none\n"
                  "(scalar); every choice gives the same image, bit for bit")
      ->capture_default_str()
      ->check(CLI::IsMember({"auto", "avx512", "avx2", "none"}))
      ->group("Performance");
  app->add_option("--volume", volumes,
                  "Add an OpenVDB fog volume in front of and between the surfaces, integrated per sample at its own time: "
                  "FILE.vdb[,density=GRID][,emission=GRID][,velocity=GRID][,color=GRID][,scale=S][,translate=X:Y:Z][,density-scale=K]"
                  "[,emission-color=R:G:B][,albedo=R:G:B][,anisotropy=G] (world units of the store's camera; emission: a float grid such as "
                  "'temperature' times emission-color, or a vec3 grid; color: a vec3 grid such as 'Cd' scaling the albedo; velocity 'vel' or "
                  "'v' is used when present; lit by the lights the store recorded, with self-shadowing). Repeatable")
      ->group("Volumes");
  app->add_option("--volume-step", volumeStep, "Ray-march step in voxels: smaller is more accurate and slower (docs/accuracy.md)")
      ->capture_default_str()
      ->group("Volumes");
  app->add_option("--volume-ray-spacing", volumeRaySpacing,
                  "Share volume rays between samples: one ray per lattice point this many pixels apart, marched once and blended "
                  "bilinearly for every sample around it (0: each sample marches its own ray, exact to the step; volumes that move "
                  "always march per sample). Error against time: docs/accuracy.md")
      ->capture_default_str()
      ->check(CLI::Range(0.0, 64.0))
      ->group("Volumes");
  app->add_option("--volume-shadow-step", volumeShadowStep, "Step of the volumes' shadow rays toward each light, in voxels")
      ->capture_default_str()
      ->group("Volumes");
  app->add_flag("--volume-exact-shadows", volumeExactShadows,
                "March a shadow ray toward each light from every step instead of looking shadows up in the per-render cache (slower)")
      ->group("Volumes");
  app->add_flag("--no-scene-volumes", noSceneVolumes, "Leave out the volumes the scene itself holds (RIB Volume requests the store records)")->group("Volumes");
  app->add_flag("--volume-no-skip", volumeNoSkip, "March through each volume's whole bounding box instead of skipping empty space (to measure it)")
      ->group("Volumes");
  app->add_flag("--stats", stats, "Print sample tests, hits, efficiency and time per phase")->group("Performance");
  // Depth of field, re-focusable after shading: the store keeps camera-space positions, so the
  // lens is sampled here, not in the shading pass.
  auto* fs = app->add_option("--fstop", fstop,
                             "Depth of field: the lens f-stop, replacing the store camera's (RIB DepthOfField); a store shaded without a lens "
                             "needs --focal-length and --focus-distance too")
                 ->group("Lens");
  auto* fl = app->add_option("--focal-length", focalLength, "Depth of field: the lens focal length, in camera-space units (aperture radius = focal length / 2 f-stop)")
                 ->group("Lens");
  auto* fd = app->add_option("--focus-distance", focusDistance, "Depth of field: the camera depth in focus (re-focus a stored frame)")->group("Lens");
  app->add_option("--camera", cameras,
                  "Render from these cameras the store records (RIB Camera requests; 'world' is the one it was shaded from), "
                  "without re-shading: NAME or NAME,NAME,... (several: one multi-view OpenEXR, a view per camera)")
      ->delimiter(',')
      ->group("Camera");
  auto* lf = app->add_option("--look-from", lookFrom,
                             "Render from a camera given after the fact at X,Y,Z (the store camera's world space); X,Y,Z,X,Y,Z: "
                             "moving from the first point at the shutter's open to the second at its close")
                 ->delimiter(',')
                 ->expected(3, 6)
                 ->type_name("X,Y,Z[,X,Y,Z]")
                 ->group("Camera");
  auto* la = app->add_option("--look-at", lookAt, "... looking at X,Y,Z (X,Y,Z,X,Y,Z: at the open, then at the close)")->delimiter(',')->expected(3, 6)->type_name("X,Y,Z[,X,Y,Z]")->group("Camera");
  lf->needs(la), la->needs(lf);
  app->add_option("--up", up, "... with X,Y,Z towards the top of the image (default 0,1,0)")->delimiter(',')->expected(3)->needs(lf)->group("Camera");
  app->add_option("--fov", fov, "... with this field of view in degrees (default: the store camera's)")->needs(lf)->group("Camera");
  app->add_option("--camera-rib", cameraRib,
                  "Render from the camera a RIB file describes (Format, Projection, ScreenWindow, Clipping, DepthOfField and the "
                  "transform before WorldBegin - a camera snippet, or a whole scene whose camera moved), in the store camera's world")
      ->excludes(lf)
      ->group("Camera");
  app->add_option("--stereo", stereo,
                  "Render a stereo pair around the camera (the store's, --camera's or --look-from's): views 'left' and 'right' BASELINE "
                  "apart (camera-space units), parallel, or converged at depth CONVERGENCE (BASELINE:CONVERGENCE, off-axis)")
      ->group("Camera");
  app->add_option("--view-dependent", viewDependent,
                  "From another camera: re-light speculars and headlights for its eye where the store carries what that needs "
                  "(shade --view-dependent), or off: the shading camera's, as shaded (faster; error in docs/accuracy.md)")
      ->capture_default_str()
      ->check(CLI::IsMember({"on", "off"}))
      ->group("Camera");
  app->add_flag("--pinhole", pinhole, "Render without depth of field, whatever lens the store's camera records")->excludes(fs)->excludes(fl)->excludes(fd)->group("Lens");
}

namespace {

resample::Quantize parseQuantize(const std::string& quantize, bool dither) {
  resample::Quantize q;
  if (std::sscanf(quantize.c_str(), "%lf,%lf,%lf,%lf", &q.zero, &q.one, &q.min, &q.max) != 4 || !(q.min <= q.max) || q.max > 65535 || q.min < 0)
    fail("--quantize", "expected ZERO,ONE,MIN,MAX with 0 <= MIN <= MAX <= 65535, got '", quantize, "'");
  q.dither = dither;
  return q;
}

// A --preview value: PATH or PATH=CHANNEL,CHANNEL,...
struct PreviewRequest {
  std::string path;
  std::vector<std::string> channels;
};
PreviewRequest parsePreview(const std::string& p, int64_t frame) {
  std::string path = p, list = "R,G,B,A";
  if (auto eq = p.find('='); eq != std::string::npos) path = p.substr(0, eq), list = p.substr(eq + 1);
  PreviewRequest r{expandFramePattern(path, frame), {}};
  std::stringstream ss(list);
  std::string c;
  while (std::getline(ss, c, ',')) r.channels.push_back(c);
  return r;
}

}  // namespace

void RenderOptions::applyTo(resample::RenderSpec& spec) const {
  spec.viewDependent = viewDependent == "on";
  spec.lens.fstop = fstop, spec.lens.focalLength = focalLength, spec.lens.focalDistance = focusDistance, spec.lens.pinhole = pinhole;
  int nx = 4, ny = 4;
  if (!samples.empty()) {
    if (std::sscanf(samples.c_str(), "%dx%d", &nx, &ny) != 2 || nx < 1 || ny < 1) fail("--samples", "expected NxM, got '", samples, "'");
  } else if (!spp.empty()) {
    int n = 0;
    try {
      n = std::stoi(spp);
    } catch (const std::exception&) {
    }
    if (n < 1 || n > 4096) fail("--spp", "expected 1 to 4096, got '", spp, "'");
    resample::SamplePattern::factor(n, nx, ny);
  }
  spec.samplesX = nx, spec.samplesY = ny;
  spec.seed = seed;
  spec.filter = resample::FilterSpec::parse(filter, "--filter");
  if (spec.filter.special()) fail("--filter", "min max average zmin zmax are for output variables (--aov NAME:zmin)");
  for (const auto& a : aovs) spec.aovs.push_back(resample::AovRequest::parse(a, "--aov"));
  if (res.size() == 2) spec.width = res[0], spec.height = res[1];
  if (crop.size() == 4) spec.cropX0 = crop[0], spec.cropX1 = crop[1], spec.cropY0 = crop[2], spec.cropY1 = crop[3];
  spec.bucketSize = bucket;
  spec.raster.opacityThreshold = float(opacityThreshold);
  spec.raster.backfaceCull = backfaceCull;
  spec.raster.vectorKernels = simd != "none";
  spec.raster.avx512Kernels = simd == "auto" || simd == "avx512";
  if (simd == "avx512" && !resample::kernels::available(resample::kernels::Isa::Avx512))
    fail("--simd", "this CPU does not run AVX-512 (F, BW, DQ, VL); use auto, avx2 or none");
  if (simd == "avx2" && !resample::kernels::available()) fail("--simd", "this CPU does not run AVX2; use auto or none");
  spec.halfColor = half;
  spec.cacheBytes = size_t(cacheMb * 1e6);
  resample::parseExrCompression(compression, "--compression");
  spec.deep = !deep.empty();
  spec.deepOptions.tolerance = float(deepTolerance);
  resample::parseDeepCompression(deepCompression, "--deep-compression");
  parseQuantize(quantize, dither);
  spec.sceneVolumes = !noSceneVolumes;
  resample::VolumeOptions& vo = spec.volumeOptions;
  vo.step = float(volumeStep);
  vo.skipEmpty = !volumeNoSkip;
  vo.shadowStep = float(volumeShadowStep);
  vo.cacheShadows = !volumeExactShadows;
  vo.raySpacing = float(volumeRaySpacing);
  if (!volumes.empty()) {
    if (!loadedVolumes) {
      std::vector<resample::VolumeSpec> specs;
      for (const auto& v : volumes) specs.push_back(resample::VolumeSpec::parse(v, "--volume"));
      loadedVolumes = std::make_shared<const resample::VolumeScene>(specs, vo);
      for (const auto& w : loadedVolumes->warnings()) warn(w);
    }
    spec.volumes = loadedVolumes;
  }
}

namespace {

resample::ExrOptions exrOptionsOf(const RenderOptions& o) {
  resample::ExrOptions eo;
  eo.compression = resample::parseExrCompression(o.compression, "--compression");
  return eo;
}

resample::DeepExrOptions deepExrOptionsOf(const RenderOptions& o) {
  resample::DeepExrOptions deo;
  deo.compression = resample::parseDeepCompression(o.deepCompression, "--deep-compression");
  deo.allChannels = o.deepAllChannels;
  return deo;
}

/// `path` for view `view`: %v replaced by its name, or the name after the file name's stem.
std::string pathForView(const std::string& path, const std::string& view) {
  if (const size_t v = path.find("%v"); v != std::string::npos) return path.substr(0, v) + view + path.substr(v + 2);
  const std::filesystem::path p(path);
  return (p.parent_path() / (p.stem().string() + "_" + view + p.extension().string())).string();
}

}  // namespace

std::vector<store::Camera> RenderOptions::viewCameras(const store::StoreMeta& meta) const {
  std::vector<store::Camera> views;
  for (const std::string& name : cameras) {
    if (name == "world") {
      views.push_back(meta.cameras[0]);
      continue;
    }
    auto it = std::find_if(meta.cameras.begin() + 1, meta.cameras.end(), [&](const store::Camera& c) { return c.name == name; });
    if (it == meta.cameras.end()) {
      std::string have = "world";
      for (size_t i = 1; i < meta.cameras.size(); ++i) have += ", " + meta.cameras[i].name;
      fail("--camera", "the store records no camera '", name, "' (it has ", have, ")");
    }
    views.push_back(*it);
  }
  for (size_t i = 0; i < views.size(); ++i)
    for (size_t j = 0; j < i; ++j)
      if (views[i].name == views[j].name) fail("--camera", "camera '", views[i].name, "' given twice");
  if (!lookFrom.empty()) {
    if (!views.empty()) fail("--look-from", "give either --camera or --look-from");
    const glm::dvec3 u = up.empty() ? glm::dvec3(0, 1, 0) : glm::dvec3(up[0], up[1], up[2]);
    // One point each, or one at the open and one at the close (a camera that moves).
    auto ends = [](const std::vector<double>& v, const char* option, glm::dvec3 out[2]) {
      if (v.size() != 3 && v.size() != 6) fail(option, "expected X,Y,Z or X,Y,Z,X,Y,Z (open, close), got ", v.size(), " numbers");
      out[0] = {v[0], v[1], v[2]};
      out[1] = v.size() == 6 ? glm::dvec3(v[3], v[4], v[5]) : out[0];
    };
    glm::dvec3 from[2], to[2];
    ends(lookFrom, "--look-from", from), ends(lookAt, "--look-at", to);
    views.push_back(resample::movingLookAtCamera(meta.cameras[0], from, to, u, fov, meta.shutterOpen, meta.shutterClose));
  }
  if (!cameraRib.empty()) {
    if (!views.empty()) fail("--camera-rib", "give one of --camera, --look-from and --camera-rib");
    views.push_back(shade::readRibCamera(cameraRib));
  }
  if (!stereo.empty()) {
    if (views.size() > 1) fail("--stereo", "a stereo pair is made around one camera, not ", views.size());
    views = resample::stereoPair(views.empty() ? meta.cameras[0] : views[0], stereo, "--stereo");
  }
  return views;
}

std::vector<RenderOptions::View> RenderOptions::renderViews(const resample::RenderSpec& spec) const {
  const std::vector<store::Camera> cams = viewCameras(spec.sources.at(0).store->meta());
  std::vector<View> out;
  if (cams.empty()) {
    out.push_back({"", resample::render(spec)});
    return out;
  }
  for (const store::Camera& c : cams) {
    resample::RenderSpec one = spec;
    one.camera = c;
    out.push_back({c.name, resample::render(one)});
  }
  return out;
}

void RenderOptions::writeViews(const std::vector<View>& views, const std::string& exrPath, int64_t frame) const {
  if (views.size() == 1) {
    writeOutputs(views[0].result, exrPath, frame);
    return;
  }
  if (!exrPath.empty()) {
    std::vector<resample::ExrView> ev;
    for (const View& v : views) ev.push_back({v.name, &v.result.image, &v.result.provenance});
    resample::writeMultiViewExr(exrPath, ev, exrOptionsOf(*this));
  }
  if (!deep.empty()) {
    std::vector<resample::DeepView> dv;
    for (const View& v : views) dv.push_back({v.name, &v.result.deep, &v.result.provenance});
    resample::writeMultiViewDeepExr(expandFramePattern(deep, frame), dv, deepExrOptionsOf(*this));
  }
  for (const View& v : views) {
    RenderOptions one = *this;
    one.deep.clear();
    for (std::string& p : one.previews) {
      const size_t eq = p.find('=');
      p = pathForView(p.substr(0, eq), v.name) + (eq == std::string::npos ? "" : p.substr(eq));
    }
    one.writeOutputs(v.result, "", frame);
  }
}

void RenderOptions::checkOutputs(const std::string& exrPath, int64_t frame) const {
  if (!exrPath.empty()) checkCanCreate(exrPath);
  if (!deep.empty()) checkCanCreate(expandFramePattern(deep, frame));
  for (const auto& p : previews) checkCanCreate(parsePreview(p, frame).path);
}

void RenderOptions::writeOutputs(const resample::RenderResult& result, const std::string& exrPath, int64_t frame) const {
  if (!exrPath.empty()) resample::writeExr(exrPath, result.image, result.provenance, exrOptionsOf(*this));
  if (!deep.empty()) resample::writeDeepExr(expandFramePattern(deep, frame), result.deep, result.provenance, deepExrOptionsOf(*this));
  writePreviews(result.image, frame);
}

void RenderOptions::writePreviews(const resample::FlatImage& image, int64_t frame) const {
  const resample::Quantize q = parseQuantize(quantize, dither);
  for (const auto& p : previews) {
    const PreviewRequest r = parsePreview(p, frame);
    resample::writePreview(r.path, image, r.channels, q, uint64_t(frame));
  }
}

}  // namespace reshutter::cli
