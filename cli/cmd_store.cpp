// `reshutter info`, `verify` and `generate`: inspect, check and synthesise .mps stores.
#include <chrono>
#include <cinttypes>
#include <cstdio>
#include <map>

#include "cli/commands.h"
#include "cli/json.h"
#include "common/error.h"
#include "common/log.h"
#include "common/progress.h"
#include "resample/volume.h"
#include "store/reader.h"
#include "store/synthetic.h"
#include "store/writer.h"

namespace reshutter::cli {

std::string grouped(uint64_t n) {
  // Appended digit by digit: inserting commas into the string made GCC 12 warn of a bogus
  // memcpy bound (-Wstringop-overflow) once this was inlined into more callers.
  const std::string digits = std::to_string(n);
  std::string s;
  for (size_t i = 0; i < digits.size(); ++i) {
    if (i > 0 && (digits.size() - i) % 3 == 0) s += ',';
    s += digits[i];
  }
  return s;
}

std::string humanBytes(double b) {
  const char* units[] = {"B", "KB", "MB", "GB", "TB"};
  int u = 0;
  while (b >= 1000.0 && u < 4) b /= 1000.0, ++u;
  char buf[32];
  std::snprintf(buf, sizeof buf, u == 0 ? "%.0f %s" : "%.1f %s", b, units[u]);
  return buf;
}

namespace {

using namespace store;

struct Summary {
  uint64_t micropolygons = 0, vertices = 0, parts = 0, tiles = 0, behindCamera = 0;
  uint64_t timedMicropolygons = 0, timedParts = 0, timedBytes = 0, timedColourBytes = 0;  // parts shaded in time
  std::map<std::string, uint64_t> effectParts;                                            // effect name → parts
  RasterRect screen;
};

Summary summarise(const StoreReader& r) {
  Summary s;
  const auto& m = r.meta();
  const auto& entries = r.entries();
  for (size_t i = 0; i < entries.size(); ++i) {
    const auto& e = entries[i];
    s.micropolygons += e.numMicropolygons;
    s.vertices += e.numVertices;
    ++s.parts;
    if (i == 0 || e.tx != entries[i - 1].tx || e.ty != entries[i - 1].ty) ++s.tiles;
    if (e.tx == kBehindCameraTile) s.behindCamera += e.numMicropolygons;
    for (uint32_t bit = 1; bit <= kEffectShadedInTime; bit <<= 1)
      if (e.effects & bit) ++s.effectParts[effectNames(bit)];
    if (e.effects & kEffectShadedInTime) {
      s.timedMicropolygons += e.numMicropolygons, ++s.timedParts, s.timedBytes += e.compressedSize;
      s.timedColourBytes += uint64_t(e.numVertices) * (m.shadingTimes.size() - 1) * 24;  // Ci@k and Oi@k, uncompressed
    }
    s.screen.extend(r.bounds(i, m.shutterOpen, m.shutterClose));
  }
  return s;
}

std::string knotList(const Schedule& k) {
  std::string s = "[";
  for (size_t i = 0; i < k.size(); ++i) s += cat(i ? " " : "", k[i]);
  return s + "]";
}

// Six significant digits: RIB values arrive as floats, and 2.79999995 reads worse than 2.8.
std::string short6(double v) {
  char b[32];
  std::snprintf(b, sizeof b, "%.6g", v);
  return b;
}

std::string cameraLine(const Camera& c) {
  double sw[4];
  c.effectiveScreenWindow(sw);
  std::string p = c.projection == Projection::Perspective ? cat("perspective fov ", c.fovDegrees) : std::string("orthographic");
  return cat(c.name, ": ", p, ", ", c.width, "x", c.height, ", pixel aspect ", c.pixelAspect, ", screen [", sw[0], " ", sw[1], " ", sw[2], " ", sw[3],
             "], clip [", c.nearClip, " ", c.farClip, "]",
             c.lens.active() ? cat(", lens f/", short6(c.lens.fstop), " focal length ", short6(c.lens.focalLength), " focus ", short6(c.lens.focalDistance),
                                   " (aperture radius ", short6(c.lens.radius()), ")")
                             : std::string(", pinhole"),
             c.moving() ? cat(", moving (", c.motionTimes.size(), " times ", c.motionTimes.front(), " to ", c.motionTimes.back(), ")") : std::string());
}

int runInfo(const std::string& path, bool json) {
  StoreReader reader(path, ReaderOptions{0, true});
  const auto& m = reader.meta();
  Summary s = summarise(reader);
  const double perMp = s.micropolygons ? double(reader.fileBytes()) / double(s.micropolygons) : 0.0;
  if (json) {
    JsonWriter j;
    j.beginObject().value("file", path).value("bytes", reader.fileBytes()).value("bytes_per_micropolygon", perMp);
    j.value("frame", m.frame).beginObject("fps").value("num", m.fps.num).value("den", m.fps.den).endObject();
    j.beginArray("shutter").value(nullptr, m.shutterOpen).value(nullptr, m.shutterClose).endArray();
    j.beginArray("schedules");
    for (const auto& k : m.schedules) {
      j.beginArray();
      for (double t : k) j.value(nullptr, t);
      j.endArray();
    }
    j.endArray();
    j.value("micropolygons", s.micropolygons).value("vertices", s.vertices).value("parts", s.parts).value("tiles", s.tiles);
    j.value("behind_camera_micropolygons", s.behindCamera).value("tile_size", m.tileSize);
    j.beginArray("cameras");
    for (const auto& c : m.cameras) {
      double sw[4];
      c.effectiveScreenWindow(sw);
      j.beginObject().value("name", c.name).value("projection", c.projection == Projection::Perspective ? "perspective" : "orthographic");
      j.value("fov", c.fovDegrees).value("width", c.width).value("height", c.height).value("pixel_aspect", c.pixelAspect);
      j.beginArray("screen_window");
      for (double v : sw) j.value(nullptr, v);
      j.endArray().value("near", c.nearClip).value("far", c.farClip);
      j.beginObject("lens").value("pinhole", !c.lens.active());
      if (c.lens.active()) j.value("fstop", c.lens.fstop).value("focal_length", c.lens.focalLength).value("focal_distance", c.lens.focalDistance);
      j.endObject();
      j.beginArray("world_to_camera");
      for (int a = 0; a < 4; ++a)
        for (int b = 0; b < 4; ++b) j.value(nullptr, c.worldToCamera[b][a]);  // row-major
      j.endArray();
      j.beginArray("motion");  // empty for a camera that stands still
      for (size_t k = 0; k < c.motionTimes.size(); ++k) {
        j.beginObject().value("time", c.motionTimes[k]).beginArray("world_to_camera");
        for (int a = 0; a < 4; ++a)
          for (int b = 0; b < 4; ++b) j.value(nullptr, c.motionWorldToCamera[k][b][a]);
        j.endArray().endObject();
      }
      j.endArray().endObject();
    }
    j.endArray().beginArray("schema");
    for (const auto& a : m.schema.attrs)
      j.beginObject().value("name", a.name).value("type", toString(a.type)).value("rate", toString(a.rate)).value("codec", toString(a.codec)).endObject();
    j.endArray().beginObject("screen_bounds");
    if (!s.screen.empty) j.value("x0", double(s.screen.x0)).value("y0", double(s.screen.y0)).value("x1", double(s.screen.x1)).value("y1", double(s.screen.y1));
    j.endObject().beginObject("effect_parts");
    for (const auto& [name, n] : s.effectParts) j.value(name.c_str(), n);
    j.endObject().beginObject("shading_in_time").beginArray("times");
    for (double t : m.shadingTimes) j.value(nullptr, t);
    j.endArray().value("grids", m.shadedInTimeGrids).value("micropolygons", s.timedMicropolygons).value("parts", s.timedParts);
    j.value("part_bytes", s.timedBytes).value("raw_colour_bytes", s.timedColourBytes).endObject();
    j.value("lights", uint64_t(m.lights.size())).beginArray("volumes");
    for (const auto& v : m.volumes) j.beginObject().value("path", v.path).value("density", v.density).value("knots", uint64_t(v.times.size())).endObject();
    j.endArray();
    j.value("provenance", m.provenance).endObject();
    std::printf("%s\n", j.str().c_str());
    return 0;
  }
  std::printf("%s\n", path.c_str());
  std::printf("  size           %s (%.1f bytes per micropolygon)\n", humanBytes(double(reader.fileBytes())).c_str(), perMp);
  std::printf("  frame          %" PRId64 " at %" PRId64 "/%" PRId64 " fps (%.6g), shutter [%g, %g]\n", m.frame, m.fps.num, m.fps.den, m.fps.value(),
              m.shutterOpen, m.shutterClose);
  for (size_t i = 0; i < m.schedules.size(); ++i)
    std::printf("  %-14s %s\n", i == 0 ? "motion knots" : "",
                i == 0 ? "schedule 0: static" : cat("schedule ", i, ": ", m.schedules[i].size(), " knots ", knotList(m.schedules[i])).c_str());
  std::printf("  micropolygons  %s (%s vertices) in %s parts over %s tiles of %d px\n", grouped(s.micropolygons).c_str(), grouped(s.vertices).c_str(),
              grouped(s.parts).c_str(), grouped(s.tiles).c_str(), m.tileSize);
  if (s.behindCamera) std::printf("                 %s never in front of the camera (kept for other cameras)\n", grouped(s.behindCamera).c_str());
  for (size_t i = 0; i < m.cameras.size(); ++i) std::printf("  %-14s %s\n", i == 0 ? "cameras" : "", cameraLine(m.cameras[i]).c_str());
  for (size_t i = 0; i < m.schema.attrs.size(); ++i) {
    const auto& a = m.schema.attrs[i];
    std::printf("  %-14s %-10s %-7s per %-13s %s\n", i == 0 ? "schema" : "", a.name.c_str(), toString(a.type), toString(a.rate), toString(a.codec));
  }
  if (m.shadingTimes.empty()) {
    std::printf("  shading        once\n");
  } else {
    std::printf("  shading        in time at %zu times %s: %s grids (%s micropolygons, %s parts, %s compressed) carry every time\n", m.shadingTimes.size(),
                knotList(m.shadingTimes).c_str(), grouped(m.shadedInTimeGrids).c_str(), grouped(s.timedMicropolygons).c_str(), grouped(s.timedParts).c_str(),
                humanBytes(double(s.timedBytes)).c_str());
  }
  static const char* const kLightKinds[] = {"ambient", "distant", "point", "spot", "area"};
  std::string lights;
  for (const auto& l : m.lights) lights += cat(lights.empty() ? "" : ", ", kLightKinds[size_t(l.kind)]);
  std::printf("  lights         %s\n", lights.empty() ? "none recorded (volumes added at re-sample time only absorb and emit)" : lights.c_str());
  for (size_t i = 0; i < m.volumes.size(); ++i)
    std::printf("  %-14s %s (grid '%s'%s)\n", i == 0 ? "volumes" : "", m.volumes[i].path.c_str(), m.volumes[i].density.c_str(),
                m.volumes[i].times.size() > 1 ? cat(", moving: ", m.volumes[i].times.size(), " knots").c_str() : "");
  if (!s.screen.empty) std::printf("  screen bounds  x [%.1f, %.1f]  y [%.1f, %.1f] over the shutter\n", s.screen.x0, s.screen.x1, s.screen.y0, s.screen.y1);
  std::string eff;
  for (const auto& [name, n] : s.effectParts) eff += cat(eff.empty() ? "" : ", ", name, " ", n);
  std::printf("  effects        %s\n", eff.empty() ? "none (static, opaque)" : (eff + " parts").c_str());
  if (!m.provenance.empty()) std::printf("  provenance     %s\n", m.provenance.c_str());
  return 0;
}

int runVerify(const std::vector<std::string>& paths) {
  for (const auto& path : paths) {
    StoreReader reader(path, ReaderOptions{0, true});
    Progress bar("verify", reader.entries().size());
    VerifyReport rep = reader.verify([&](size_t) { bar.advance(); });
    bar.finish();
    std::printf("%s: OK (%s micropolygons in %s parts; checksums, bounds, tiles and flags verified)\n", path.c_str(), grouped(rep.micropolygons).c_str(),
                grouped(rep.parts).c_str());
  }
  return 0;
}

}  // namespace

void addStoreCommands(CLI::App& app, Registry& registry) {
  {
    auto* sub = app.add_subcommand("info", "Summarise a store: micropolygons, tiles, size, shutter, knots, cameras, schema, bounds, effects");
    auto path = std::make_shared<std::string>();
    auto json = std::make_shared<bool>(false);
    sub->add_option("file", *path, "The .mps store")->required();
    sub->add_flag("--json", *json, "Machine-readable output");
    sub->footer("Example:\n  reshutter info frame.0001.mps\n  reshutter info --json frame.0001.mps | jq .micropolygons");
    registry.add(sub, [=] { return runInfo(*path, *json); });
  }
  {
    auto* sub = app.add_subcommand("verify", "Decode every tile part of a store and check every checksum and invariant");
    auto paths = std::make_shared<std::vector<std::string>>();
    sub->add_option("files", *paths, "One or more .mps stores")->required();
    sub->footer("Exits 0 when every store is intact; otherwise prints the first problem (file and tile) and exits 1.");
    registry.add(sub, [=] { return runVerify(*paths); });
  }
  {
    auto* sub = app.add_subcommand("generate", "Write a synthetic store (benchmarks, tests): N ~1 px micropolygons in 16x16 grids, moving");
    auto opt = std::make_shared<SyntheticOptions>();
    auto out = std::make_shared<std::string>();
    auto level = std::make_shared<int>(3);
    auto budget = std::make_shared<double>(64);
    auto colorCodec = std::make_shared<std::string>("lossless"), opacityCodec = std::make_shared<std::string>("lossless");
    sub->add_option("-o,--output", *out, "Output .mps")->required();
    sub->add_option("-n,--micropolygons", opt->micropolygons, "Micropolygon count")->capture_default_str();
    sub->add_option("--width", opt->width, "Raster width")->capture_default_str();
    sub->add_option("--height", opt->height, "Raster height")->capture_default_str();
    sub->add_option("--motion", opt->maxMotionPx, "Largest motion over the shutter, pixels")->capture_default_str();
    sub->add_option("--knots", opt->knots, "Motion knots (1 = static)")->capture_default_str()->check(CLI::Range(1, 64));
    sub->add_option("--transparent", opt->transparentFraction, "Fraction of grids with opacity < 1")->capture_default_str()->check(CLI::Range(0.0, 1.0));
    sub->add_option("--still", opt->stillFraction, "Fraction of grids that stand still but keep every knot (as P + blurP dumps write static objects)")
        ->capture_default_str()
        ->check(CLI::Range(0.0, 1.0));
    sub->add_option("--texture", opt->texture, "Relative per-vertex colour noise (texture detail)")->capture_default_str()->check(CLI::Range(0.0, 1.0));
    sub->add_option("--seed", opt->seed, "Random seed")->capture_default_str();
    sub->add_option("--zstd-level", *level, "zstd level")->capture_default_str()->check(CLI::Range(-7, 19));
    sub->add_option("--memory-mb", *budget, "Writer memory budget in MB")->capture_default_str();
    sub->add_option("--color-codec", *colorCodec, "Ci codec: lossless or half")->capture_default_str()->check(CLI::IsMember({"lossless", "half"}));
    sub->add_option("--opacity-codec", *opacityCodec, "Oi codec: lossless, half or unorm16")
        ->capture_default_str()
        ->check(CLI::IsMember({"lossless", "half", "unorm16"}));
    sub->footer("Example:\n  reshutter generate -n 2000000 -o synthetic.mps && reshutter info synthetic.mps");
    registry.add(sub, [=] {
      parseAttrCodec(*colorCodec, opt->colorCodec);
      parseAttrCodec(*opacityCodec, opt->opacityCodec);
      WriterOptions wo;
      wo.zstdLevel = *level;
      wo.memoryBudget = size_t(*budget * 1e6);
      auto start = std::chrono::steady_clock::now();
      StoreWriter writer(*out, syntheticMeta(*opt), wo);
      uint64_t n = generateSynthetic(*opt, writer);
      WriteStats st = writer.close();
      double secs = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
      note(cat("wrote ", *out, ": ", grouped(n), " micropolygons, ", humanBytes(double(st.fileBytes)), " (", double(st.fileBytes) / double(n),
               " bytes/micropolygon) in ", secs, " s"));
      return 0;
    });
  }
  {
    auto* sub = app.add_subcommand("smoke", "Write a procedural smoke puff as an OpenVDB file (benchmarks, demos): a noisy sphere of density 1");
    auto puff = std::make_shared<resample::SmokePuff>();
    auto out = std::make_shared<std::string>();
    auto centre = std::make_shared<std::vector<double>>(std::vector<double>{0, 0, 0});
    auto resolution = std::make_shared<int>(64);
    sub->add_option("-o,--output", *out, "Output .vdb")->required();
    sub->add_option("--center", *centre, "Centre X Y Z (world units)")->expected(3)->capture_default_str();
    sub->add_option("--radius", puff->radius, "Radius (world units)")->capture_default_str()->check(CLI::PositiveNumber);
    sub->add_option("--resolution", *resolution, "Voxels across the puff's bounding box")->capture_default_str()->check(CLI::Range(4, 2048));
    sub->add_option("--seed", puff->seed, "Noise seed")->capture_default_str();
    sub->footer("Example:\n  reshutter smoke -o smoke.vdb --center 0 0 20 --radius 3 --resolution 256\n"
                "  reshutter resample frame.mps --volume smoke.vdb,density-scale=2 -o out.exr");
    registry.add(sub, [=] {
      puff->centre = {(*centre)[0], (*centre)[1], (*centre)[2]};
      puff->voxelSize = 2.7 * puff->radius / *resolution;  // the puff reaches 1.35 radii
      resample::writeSmokePuff(*out, *puff);
      note(cat("wrote ", *out, ": a smoke puff of radius ", puff->radius, " in voxels of ", puff->voxelSize));
      return 0;
    });
  }
}

}  // namespace reshutter::cli
