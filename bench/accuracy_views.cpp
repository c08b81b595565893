// The accuracy study's other-camera curve: the right eye of a stereo pair around the demo's camera,
// from one shading pass kept for both eyes - as shaded (the primary camera's speculars, headlights
// and faceforward sides) or re-lit for the right eye (`shade --view-dependent`) - against shading
// the demo from the right eye itself, at 1-64 samples per pixel.
#include <cstdio>
#include <filesystem>

#include <glm/gtc/matrix_transform.hpp>

#include "bench/accuracy_common.h"
#include "shade/demo_scene.h"

namespace reshutter::accuracy {

using namespace ::reshutter::resample;

namespace {
// The right eye's offset along the camera's x: the demo's objects lie 9 to 13 away, so it sees them
// about 10 degrees around from the primary camera (a wide stereo rig, or a witness camera).
constexpr double kEye = 2.0;
double gShadeOnce = 0, gShadeInputs = 0, gShadeEach = 0;
}  // namespace

void studyViews(const std::string& out) {
  std::fprintf(stderr, "views: the second eye shaded once (as shaded, re-lit) or shaded from that eye\n");
  shade::FrameScene both = shade::demoFrame(kDW, kDH);
  store::Camera right = both.options.camera;
  right.name = "right";
  right.worldToCamera = glm::translate(glm::dmat4(1.0), glm::dvec3(-kEye, 0, 0)) * right.worldToCamera;
  both.options.namedCameras = {right};
  const shade::FrameScene primary = shade::demoFrame(kDW, kDH), fromRight = shade::demoFrame(kDW, kDH, kEye);
  const std::string pOnce = gTmp + "/acc_views_once.mps", pInputs = gTmp + "/acc_views_inputs.mps", pRight = gTmp + "/acc_views_right.mps",
                    pPrimary = gTmp + "/acc_views_primary.mps";
  shade::ShadeOptions plain, inputs;
  inputs.viewDependent = true;
  gShadeOnce = shadeStore(both, plain, pOnce), gShadeInputs = shadeStore(both, inputs, pInputs);
  gShadeEach = shadeStore(primary, plain, pPrimary) + shadeStore(fromRight, plain, pRight);
  auto sOnce = std::make_shared<const store::StoreReader>(pOnce), sInputs = std::make_shared<const store::StoreReader>(pInputs),
       sRight = std::make_shared<const store::StoreReader>(pRight);
  const double F = double(sOnce->meta().frame);
  const ShutterModel shutter = ShutterModel::progressive(F, F + 1);
  const int refSide = gQuick ? 8 : 24;
  const Img ref = toImg(render(demoSpec({sRight}, shutter, refSide, 99)));
  // The right eye from a store shaded once for both eyes: rendered through its recorded camera.
  auto fromStore = [&](const std::shared_ptr<const store::StoreReader>& st, int n) {
    return [&, st, n](uint64_t seed) {
      RenderSpec spec = demoSpec({st}, shutter, n, seed);
      spec.camera = st->meta().cameras.at(1);
      return spec;
    };
  };
  for (int n : sppSides({1, 2, 4, 8})) {
    measure("views", "shade once, as shaded", n * n, fromStore(sOnce, n), ref, 3, gShadeOnce);
    measure("views", "shade once, re-lit for the eye (--view-dependent)", n * n, fromStore(sInputs, n), ref, 3, gShadeInputs);
    measure(
        "views", "re-shade each eye", n * n, [&](uint64_t seed) { return demoSpec({sRight}, shutter, n, seed); }, ref, 3, gShadeEach);
  }
  plot(out, "views", "The second eye (demo 256x144, 2 units to the right): shade once or re-shade");
  gTables << "### Other cameras: the second eye\n\nScene: the built-in demo at " << kDW << "×" << kDH << ", gaussian 2×2, full shutter; the right eye "
          << kEye
          << " to the right of the demo's camera (its objects lie 9 to 13 away: about 10° around them; parallel eyes). *Shade once*: one shading pass kept and diced for "
             "both eyes, the right eye rendered from it with `--camera right` - *as shaded* (speculars, headlights and the side diffuse light "
             "falls on as the primary camera saw them) or *re-lit for the eye* (shaded with `--view-dependent`, re-evaluated per vertex for the "
             "right eye at re-sample time). *Re-shade each eye*: the demo shaded from each eye on its own. Reference: shaded from the right "
             "eye, "
          << refSide * refSide << " spp. Seconds: the shading for both eyes (one pass, best of 3: " << fmt(gShadeOnce, "%.3f") << " s, "
          << fmt(gShadeInputs, "%.3f") << " s with the view-dependent inputs; or one pass per eye: " << fmt(gShadeEach, "%.3f")
          << " s) plus the right eye's render (best of 3 seeds). Store sizes: " << std::filesystem::file_size(pOnce) << " bytes, "
          << std::filesystem::file_size(pInputs) << " with the inputs.\n\n";
  table("views", "spp");
}

std::string viewsHeadline() {
  const Point *a = find("views", "shade once, as shaded", 16), *b = find("views", "shade once, re-lit", 16), *c = find("views", "re-shade", 16);
  if (!a || !b || !c) return "";
  char line[640];
  std::snprintf(line, sizeof line,
                "- **The second eye from one shading pass** (demo, an eye 2 units to the right, 16 spp, against shading from that eye): as shaded "
                "RMSE %.1e with a bias of %.1e (max %.2f: the primary camera's speculars on the metal torus and balls), re-lit for the eye "
                "(`--view-dependent`) %.1e, bias %.1e (max %.2f; the rest is soft-shadow noise of the two passes), re-shading each eye %.1e; "
                "seconds for both eyes' shading and the second eye's render: %.2f, %.2f, %.2f.\n",
                a->rmse, a->bias, a->max, b->rmse, b->bias, b->max, c->rmse, a->seconds, b->seconds, c->seconds);
  return line;
}

}  // namespace reshutter::accuracy
