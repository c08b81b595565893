// `reshutter shade`: the single shading pass, RIB scene → one store per frame. Also the
// reference mode of accuracy studies: shade at a chosen time and/or restrict the store to a
// target interval.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <memory>

#include "cli/commands.h"
#include "common/error.h"
#include "common/frame_range.h"
#include "common/log.h"
#include "resample/camera_view.h"
#include "shade/rib_scene.h"
#include "shade/shading_pass.h"

namespace reshutter::cli {
namespace {

struct ShadeCommand {
  std::string scene, output, interval, frames, fps = "24";
  double shadeAt = NAN, motionFactor = NAN, rateScale = 1.0, overscan = 0.1;
  int gridSize = 16;
  std::string shadows = "on";
  int shadowSamples = shade::ShadeOptions{}.shadowSamples;
  double shadowRate = 1;
  std::string shadeInTime = "off";
  int shadingTimes = shade::ShadeOptions{}.shadingTimes;
  int timeStride = shade::ShadeOptions{}.timeStride;
  uint64_t primitiveBudget = shade::DiceOptions{}.maxMicropolygonsPerPrimitive;
  std::string stereo;                   // BASELINE[:CONVERGENCE]
  std::vector<std::string> addCameras;  // RIB files, each describing a camera to keep and record
  bool viewDependent = false;

  // --stereo: the pair around the main camera, recorded (and kept) like RIB Camera requests.
  void addStereoCameras(shade::FrameOptions& options) const {
    for (const store::Camera& eye : resample::stereoPair(options.camera, stereo, "--stereo")) addCamera(options, eye);
  }

  // Records `cam` with the scene's named cameras, replacing one of the same name.
  static void addCamera(shade::FrameOptions& options, const store::Camera& cam) {
    if (cam.name == "world" || cam.name == "frame") fail("--add-camera", "camera name '", cam.name, "' is reserved (name the file otherwise)");
    auto& cams = options.namedCameras;
    cams.erase(std::remove_if(cams.begin(), cams.end(), [&](const store::Camera& c) { return c.name == cam.name; }), cams.end());
    cams.push_back(cam);
  }

  int run() const {
    shade::ShadeOptions opt;
    if (!std::isnan(shadeAt)) opt.shadeAt = shadeAt;
    if (!interval.empty()) {
      double a, b;
      if (std::sscanf(interval.c_str(), "%lf:%lf", &a, &b) != 2 || !std::isfinite(a) || !std::isfinite(b) || b < a)
        fail("--interval", "expected OPEN:CLOSE in frames with OPEN <= CLOSE, got '", interval, "'");
      opt.interval = std::make_pair(a, b);
    }
    if (!std::isnan(motionFactor)) {
      if (!(motionFactor >= 0)) fail("--motion-factor", "must be non-negative");
      opt.dice.motionFactor = motionFactor;
    }
    if (!(rateScale > 0) || !std::isfinite(rateScale)) fail("--rate-scale", "must be positive");
    opt.dice.shadingRateScale = rateScale;
    if (gridSize < 1 || gridSize > 64) fail("--grid-size", "must be 1 to 64");
    opt.dice.maxGridSize = gridSize;
    if (!(overscan >= 0) || overscan > 10) fail("--overscan", "must be 0 to 10 (a fraction of the resolution)");
    opt.dice.cullMargin = overscan;
    if (primitiveBudget < 1) fail("--primitive-budget", "must be at least 1");
    opt.dice.maxMicropolygonsPerPrimitive = primitiveBudget;
    if (shadows != "on" && shadows != "off") fail("--shadows", "expected on or off, got '", shadows, "'");
    opt.shadows = shadows == "on";
    opt.viewDependent = viewDependent;
    if (shadowSamples < 1 || shadowSamples > 4096) fail("--shadow-samples", "must be 1 to 4096");
    opt.shadowSamples = shadowSamples;
    if (!(shadowRate >= 1) || shadowRate > 1024) fail("--shadow-rate", "must be 1 to 1024");
    opt.shadowRate = shadowRate;
    if (shadeInTime != "off") {
      double tol = 0;
      char extra = 0;
      if (std::sscanf(shadeInTime.c_str(), "%lf%c", &tol, &extra) != 1 || !(tol >= 0) || !std::isfinite(tol))
        fail("--shade-in-time", "expected off or a colour tolerance >= 0 (0: every grid that may change), got '", shadeInTime, "'");
      opt.timeTolerance = tol;
    }
    if (shadingTimes < 2 || shadingTimes > int(store::StoreMeta::kMaxShadingTimes)) fail("--shade-times", "must be 2 to ", store::StoreMeta::kMaxShadingTimes);
    opt.shadingTimes = shadingTimes;
    if (timeStride < 1 || timeStride > 64) fail("--shade-in-time-stride", "must be 1 to 64");
    opt.timeStride = timeStride;
    if (!store::parseRational(fps, opt.fps)) fail("--fps", "expected a frame rate such as 24, 25, 29.97 or 30000/1001, got '", fps, "'");
    std::vector<int64_t> wanted;
    if (!frames.empty()) wanted = parseFrameRange(frames, "--frame-range");

    int written = 0;
    shade::Scene sceneBuilder([&](shade::FrameScene& frame) {
      const int64_t n = frame.options.frame;
      if (!wanted.empty() && std::find(wanted.begin(), wanted.end(), n) == wanted.end()) return;
      if (written > 0 && !hasFramePlaceholder(output)) fail("-o", "the scene has several frames: name the outputs with a frame pattern such as shot.####.mps");
      frame.source = scene;
      std::string skipped;
      for (const auto& [request, count] : frame.skipped) skipped += cat(skipped.empty() ? "" : ", ", grouped(count), " ", request);
      if (frame.prims.empty() && frame.volumes.empty() && !skipped.empty()) fail(scene, "frame ", n, ": every primitive was skipped (", skipped, "); nothing to shade");
      for (const std::string& file : addCameras) addCamera(frame.options, shade::readRibCamera(file));
      if (!stereo.empty()) addStereoCameras(frame.options);
      const std::string path = expandFramePattern(output, n);
      shade::StoreResult r = shade::shadeToStore(frame, opt, path);
      ++written;
      const std::string shadedWhen =
          r.shade.shadingTimes.size() > 1
              ? cat("shaded in time (", grouped(r.shade.timedGrids), " of ", grouped(r.shade.timeCandidateGrids), " grids that may change kept ",
                    r.shade.shadingTimes.size(), " times)")
              : cat("shaded at t=", r.shade.shadeAt);
      std::printf("frame %lld: %s micropolygons in %s grids (%s moving), %s in %.2f s -> %s (%s, %.1f bytes/micropolygon)%s\n", (long long)n,
                  grouped(r.shade.micropolygons).c_str(), grouped(r.shade.grids).c_str(), grouped(r.shade.movingGrids).c_str(), shadedWhen.c_str(),
                  r.shade.seconds, path.c_str(), humanBytes(double(r.write.fileBytes)).c_str(),
                  r.shade.micropolygons ? double(r.write.fileBytes) / double(r.shade.micropolygons) : 0.0,
                  skipped.empty() ? "" : cat("; skipped primitives: ", skipped).c_str());
      if (r.shade.primaryCameraDetail)
        std::printf("frame %lld: kept and diced for %zu cameras: geometry detail expansion %.3f (micropolygons for every camera / for the primary alone)\n",
                    (long long)n, frame.options.namedCameras.size() + 1, r.shade.detailExpansion());
      std::fflush(stdout);
      if (r.shade.overBudgetPrimitives)
        warn(cat(scene, ": frame ", n, ": ", r.shade.overBudgetPrimitives, " primitive(s) needed more than ", grouped(opt.dice.maxMicropolygonsPerPrimitive),
                 " micropolygons (seen edge-on under an extreme transform?) and were diced coarser than their shading rate"));
      if (verbosity() == Verbosity::Verbose)
        note(cat("frame ", n, ": ", r.shade.primitives, " primitives, ", r.shade.culledPieces,
                 " pieces culled (off screen, behind the eye or beyond the far plane), ", r.shade.eyeSplits, " eye splits, ", r.shade.droppedMicropolygons,
                 " micropolygons dropped at the near plane, ", r.shade.trimmedMicropolygons, " trimmed away, ", r.shade.forcedCuts,
                 " sides left unfinished by the split depth limit, ", frame.culledArchives, " delayed archives culled by their bound, ", r.shade.vertices,
                 " vertices shaded, ", r.shade.textureLookups, " texture lookups (", r.shade.missingTextures, " textures missing), ",
                 grouped(r.shade.shadowRays), " shadow rays against ", grouped(r.shade.shadowMicropolygons), " micropolygons (scene built in ",
                 cat(std::round(r.shade.shadowBuildSeconds * 100) / 100), " s)",
                 r.shade.shadingTimes.size() > 1 ? cat("; in time: ", r.shade.blendedTimes, " grid times blended between shaded ones, ", r.shade.reusedVertices,
                                                       " vertex shadings kept from the first time (only shadows could change, and did not), ",
                                                       r.shade.stillOnlyRays, " rays against still micropolygons only (no moving caster could block them), ",
                                                       r.shade.candidateStillOnlyRays, " rays of candidates against them only (no moving caster could shadow the grid from the ray's light), ",
                                                       r.shade.carriedTimes, " grid times of rigidly moving grids carried from the first (not diced again), ",
                                                       r.shade.laterVertices, " vertex shadings at later times and ", r.shade.interpolatedVertices,
                                                       " vertices whose change was interpolated between them (--shade-in-time-stride), ",
                                                       r.shade.steadyShadings, " later grid shadings unchanged at their coarse points (the rest kept their first values), ",
                                                       r.shade.rigidMicropolygons, " moving micropolygons in ", r.shade.rigidCasters,
                                                       " rigidly moving shadow casters (a still BVH each, instanced; fixed at ",
                                                       r.shade.fixedCasterInstants, " shading times)")
                                                 : std::string()));
    });
    shade::readRibScene(scene, sceneBuilder, opt.dice.cullMargin);
    if (sceneBuilder.framesShaded() == 0) fail(scene, "no WorldBegin/WorldEnd block: nothing to shade");
    if (written == 0) fail("--frame-range", "no frame of ", scene, " lies in '", frames, "'");
    return 0;
  }
};

}  // namespace

void addShadeCommand(CLI::App& app, Registry& registry) {
  auto cmd = std::make_shared<ShadeCommand>();
  auto* sub = app.add_subcommand("shade", "Shade a RIB scene once (every motion knot kept) into a micropolygon store per frame");
  sub->add_option("scene", cmd->scene, "RIB scene (ASCII, binary or gzipped)")->required();
  sub->add_option("-o,--output", cmd->output, "Output store; several frames need a pattern such as shot.####.mps")->required();
  // NaN stands for "not given" in the command's fields, so a given value must be a finite number.
  const CLI::Validator finite(
      [](std::string& text) {
        double v = 0;
        return CLI::detail::lexical_cast(text, v) && std::isfinite(v) ? std::string() : "expected a finite number, got '" + text + "'";
      },
      "NUMBER");
  sub->add_option("--shade-at", cmd->shadeAt, "Shade every point at this time (frames, default: shutter open)")->check(finite);
  sub->add_option("--interval", cmd->interval,
                  "Restrict the store to OPEN:CLOSE (frames) instead of the scene's Shutter: positions are interpolated at its ends\n"
                  "(reference mode, e.g. each field of an interlaced frame shaded on its own)");
  sub->add_option("--frame-range", cmd->frames, "Only these frames (FrameBegin numbers), e.g. 1-10 or 3,5,7");
  sub->add_option("--fps", cmd->fps, "Frame rate recorded in the store")->capture_default_str();
  sub->add_option("--motion-factor", cmd->motionFactor, "Override GeometricApproximation \"motionfactor\": shading rate x (1 + F x motion in pixels / 16)")
      ->check(finite);
  sub->add_option("--rate-scale", cmd->rateScale, "Multiply every ShadingRate (quality knob)")->capture_default_str();
  sub->add_option("--grid-size", cmd->gridSize, "Largest grid, in micropolygons per side")->capture_default_str();
  sub->add_option("--overscan", cmd->overscan, "Keep geometry this far beyond the screen edges (fraction of the resolution), for re-framing and other cameras")
      ->capture_default_str();
  sub->add_option("--stereo", cmd->stereo,
                  "Also keep, dice for and record a stereo pair around the camera: cameras 'left' and 'right' BASELINE apart, parallel or "
                  "converged at depth CONVERGENCE (BASELINE:CONVERGENCE); `resample --camera left,right` renders both eyes from this one pass");
  sub->add_option("--add-camera", cmd->addCameras,
                  "Also keep, dice for and record the camera a RIB file describes (a snippet of Format, Projection, ScreenWindow and "
                  "transforms, in the scene's world), named after the file: `resample --camera NAME` renders it. Repeatable");
  sub->add_flag("--view-dependent", cmd->viewDependent,
                "Keep what re-lighting speculars and headlights for another eye needs (colour less its view-dependent term, the lobe's "
                "weight, normal and roughness, each light's shadow share), so that renders from other cameras (--camera, --stereo) "
                "re-evaluate the view-dependent term for their own eye (larger stores; error against time in docs/accuracy.md)");
  sub->add_option("--primitive-budget", cmd->primitiveBudget,
                  "Most micropolygons one primitive may take; past it (a surface edge-on under an extreme transform) its remaining pieces are diced "
                  "coarser, with a warning")
      ->capture_default_str();
  sub->add_option("--shadows", cmd->shadows,
                  "Ray-traced shadows for the lights that ask for them (RIS lights, shadowname \"raytrace\", Attribute \"light\" \"shadows\"): on or off")
      ->capture_default_str();
  sub->add_option("--shadow-samples", cmd->shadowSamples, "Rays per shaded point towards an area light or a soft distant light (soft-shadow quality)")
      ->capture_default_str();
  sub->add_option("--shadow-rate", cmd->shadowRate,
                  "Trace shadow rays against micropolygons this many times coarser (area) than the shaded ones: 1 is exact, 4 builds the shadow "
                  "scene about 4x faster (speed knob; error in docs/accuracy.md)")
      ->capture_default_str();
  sub->add_option("--shade-in-time", cmd->shadeInTime,
                  "Shade grids whose shading can change over the shutter (moving under lights or a view-dependent shader, moving lights, animated "
                  "colours) at --shade-times times too, and keep them where the colour changes by more than this tolerance (0: always); re-sampling "
                  "then blends each sample's colour at its own time. off: shade once (error against time in docs/accuracy.md)")
      ->capture_default_str();
  sub->add_option("--shade-times", cmd->shadingTimes, "With --shade-in-time: shading times spread evenly over the interval, its open and close included (4 with tolerance 0.03: 1.27x the single pass on the demo, shading error still under 16-spp noise; 5: a third less error for 1.36x; docs/accuracy.md)")
      ->capture_default_str();
  sub->add_option("--shade-in-time-stride", cmd->timeStride,
                  "With --shade-in-time: shade the later times at every Nth vertex of a grid, and in full only where the change since the open "
                  "is not smooth (by the tolerance); the other vertices take the change interpolated. 1: every vertex (a change thinner than N "
                  "micropolygons can be missed otherwise; error against time in docs/accuracy.md)")
      ->capture_default_str();
  registry.add(sub, [cmd] { return cmd->run(); });
}

}  // namespace reshutter::cli
