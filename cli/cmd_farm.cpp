// `reshutter farm`: a re-sampling command run as a Slurm job - `farm retime|fields|resample`
// take the command's own options plus the farm's (chunk, tiles, sbatch options) and submit a job
// array with a dependent final step; `farm task`, `farm assemble` and `farm status` are what the
// batch scripts run and what a user checks a job with. `reshutter assemble` merges crop tiles by
// hand. The job model is farm/job.h, Slurm farm/slurm.h; this file only reads options.
#include <unistd.h>

#include <algorithm>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>

#include "cli/commands.h"
#include "cli/render_options.h"
#include "common/atomic_file.h"
#include "common/error.h"
#include "common/frame_range.h"
#include "common/log.h"
#include "common/progress.h"
#include "farm/job.h"
#include "farm/slurm.h"
#include "resample/assemble.h"
#include "store/reader.h"
#include "store/shot.h"

namespace reshutter::cli {
namespace {

namespace fs = std::filesystem;

struct FarmOptions {
  int chunk = 1;
  std::string tiles = "1x1";
  std::string jobDir;
  bool dryRun = false, wait = false;
  std::string binary;
  farm::SlurmOptions slurm;
};

// Options with the number of values each takes: the farm's own, and those the farm sets for each
// task. Neither is passed on to the tasks' command line as given.
const std::vector<std::pair<std::string, int>> kNotPassedOn = {
    {"--chunk", 1}, {"--tiles", 1},  {"--job-dir", 1}, {"--dry-run", 0},     {"--wait", 0},     {"--keep-tiles", 0},       {"--partition", 1},
    {"--time", 1},  {"--mem", 1},    {"--sbatch", 1},  {"--max-running", 1}, {"--job-name", 1}, {"--reshutter", 1},        {"--frames", 1},
    {"-o", 1},      {"--output", 1}, {"--deep", 1},    {"--preview", 1},     {"--crop", 4},     {"--deep-all-channels", 0}};

// The command's arguments as given after `farm COMMAND`, less kNotPassedOn.
std::vector<std::string> passedOn(const std::vector<std::string>& argv, const std::string& command) {
  size_t k = 0;
  while (k + 1 < argv.size() && !(argv[k] == "farm" && argv[k + 1] == command)) ++k;
  if (k + 1 >= argv.size()) fail("farm", "cannot find '", command, "' after 'farm' on the command line");
  std::vector<std::string> out;
  for (k += 2; k < argv.size(); ++k) {
    const std::string& tok = argv[k];
    if (tok == "--") {
      out.insert(out.end(), argv.begin() + ptrdiff_t(k), argv.end());
      break;
    }
    std::string name = tok;
    bool inlineValue = false;
    if (tok.rfind("--", 0) == 0 && tok.find('=') != std::string::npos) name = tok.substr(0, tok.find('=')), inlineValue = true;
    else if (tok.size() > 2 && tok[0] == '-' && tok[1] == 'o') name = "-o", inlineValue = true;
    auto it = std::find_if(kNotPassedOn.begin(), kNotPassedOn.end(), [&](const auto& p) { return p.first == name; });
    if (it == kNotPassedOn.end()) {
      out.push_back(tok);
      continue;
    }
    k += size_t(inlineValue ? std::max(0, it->second - 1) : it->second);
  }
  return out;
}

std::string absolute(const std::string& p) { return p.empty() ? p : fs::absolute(p).lexically_normal().string(); }

// The output size the command renders at: --res, or the first store's camera.
farm::Rect imageWindow(const SequenceRequest& req) {
  const RenderOptions& r = *req.render;
  if (r.crop.size() == 4) return {r.crop[0], r.crop[1], r.crop[2], r.crop[3]};
  if (r.res.size() == 2) return {0, r.res[0], 0, r.res[1]};
  store::StoreMeta meta;
  if (req.command == "resample") {
    store::ReaderOptions ro;
    ro.cacheBytes = 0;
    meta = store::StoreReader(expandFramePattern(req.stores, req.frames.front()), ro).meta();
  } else {
    store::ShotStores shot(req.stores, 0);
    meta = shot.firstMeta(double(req.frames.front()));
  }
  const std::vector<store::Camera> views = r.viewCameras(meta);
  if (views.size() > 1) fail("farm", "a job renders one camera: submit one job per view (--camera NAME) rather than ", views.size(), " views in one");
  const store::Camera& cam = views.empty() ? meta.cameras[0] : views[0];
  return {0, cam.width, 0, cam.height};
}

std::string describe(const farm::Job& job, const farm::Job::Task& t) {
  const farm::Rect& c = t.crop;
  return cat("task ", t.index, ": frames ", farm::frameList(t.frames),
             job.tiles() > 1 ? cat(", tile ", t.tile, " [", c.x0, ",", c.x1, ")x[", c.y0, ",", c.y1, ")") : std::string());
}

// Prints what each task did and the final step's state; returns 1 when anything failed.
int reportStatus(const farm::Job& job, size_t logLines) {
  const auto reports = farm::taskReports(job);
  size_t done = 0, failed = 0, waiting = 0;
  for (const auto& r : reports) {
    if (r.state == farm::TaskReport::State::Done) ++done;
    else if (r.state == farm::TaskReport::State::Failed) ++failed;
    else ++waiting;
  }
  size_t final = 0;
  for (int64_t f : job.frames) final += job.frameDone(f);
  std::printf("job %s: %s %s, %zu frames, %zu tasks (chunks of %d frames, %dx%d tiles)\n", job.dir.c_str(), job.command.c_str(),
              farm::frameList(job.frames).c_str(), job.frames.size(), job.tasks(), job.chunk, job.tilesX, job.tilesY);
  std::printf("  tasks   %zu done, %zu failed, %zu pending or running\n", done, failed, waiting);
  for (const auto& r : reports) {
    if (r.state != farm::TaskReport::State::Failed) continue;
    std::printf("  FAILED  %s: exit %d, %zu frames left; log %s\n", describe(job, job.task(r.task)).c_str(), r.exitCode, r.framesLeft,
                job.logOf(r.task).c_str());
    const std::string tail = farm::logTail(job.logOf(r.task), logLines);
    if (!tail.empty()) std::printf("%s", ("    | " + std::string(tail.substr(0, tail.size() - 1))).c_str()), std::printf("\n");
  }
  std::ifstream st(job.dir + "/status/assemble.exit");
  int code = 0;
  const bool ended = bool(st >> code);
  std::printf("  frames  %zu of %zu final\n", final, job.frames.size());
  std::printf("  final   %s\n",
              ended ? (code == 0 ? "done: every frame assembled and read back" : cat("FAILED (exit ", code, "); log ", job.dir, "/logs/assemble.log").c_str())
              : failed ? "not run: it runs once every task has succeeded (fix what failed, then submit the same command again: it resumes)"
                       : "not run yet (it starts when every task has succeeded)");
  if (ended && code != 0) {
    const std::string tail = farm::logTail(job.dir + "/logs/assemble.log", logLines);
    if (!tail.empty()) std::printf("    | %s\n", tail.substr(0, tail.size() - 1).c_str());
  }
  return failed || (ended && code != 0) ? 1 : 0;
}

int submitJob(const SequenceRequest& req, const FarmOptions& fo, const std::vector<std::string>& argv) {
  farm::Job job;
  job.command = req.command;
  job.args = passedOn(argv, req.command);
  job.frames = req.frames;
  job.output = absolute(req.output);
  job.deep = absolute(req.render->deep);
  for (const auto& p : req.render->previews) {
    const size_t eq = p.find('=');
    job.previews.push_back(absolute(p.substr(0, eq)) + (eq == std::string::npos ? "" : p.substr(eq)));
  }
  job.chunk = fo.chunk;
  if (std::sscanf(fo.tiles.c_str(), "%dx%d", &job.tilesX, &job.tilesY) != 2 || job.tilesX < 1 || job.tilesY < 1 || job.tilesX > 64 || job.tilesY > 64)
    fail("--tiles", "expected COLUMNSxROWS such as 2x2 (at most 64x64), got '", fo.tiles, "'");
  if (job.frames.empty()) fail("--frames", "no frames to render");
  for (const auto& [pattern, what] : {std::pair{job.output, "-o"}, {job.deep, "--deep"}})
    if (job.frames.size() > 1 && !pattern.empty() && !hasFramePlaceholder(pattern))
      fail(what, "'", pattern, "' has no frame placeholder (####, %04d, @) but ", job.frames.size(), " frames are rendered");
  for (int64_t f : {job.frames.front()}) {
    if (!job.output.empty()) checkCanCreate(job.finalOutput(f));
    if (!job.deep.empty()) checkCanCreate(job.finalDeep(f));
  }
  job.window = imageWindow(req);
  if (job.window.x1 - job.window.x0 < job.tilesX || job.window.y1 - job.window.y0 < job.tilesY) fail("--tiles", "more tiles than pixels");
  job.reshutter = fo.binary.empty() ? fs::read_symlink("/proc/self/exe").string() : absolute(fo.binary);
  job.workdir = fs::current_path().string();
  std::string dir = fo.jobDir;
  if (dir.empty()) {
    // Beside the outputs, named after them: out/ntsc.####.exr → out/ntsc.farm
    const fs::path first = job.output.empty() ? job.deep : job.output;
    std::string stem = first.filename().string();
    stem = stem.substr(0, stem.find_first_of(".#%@"));
    dir = (first.parent_path() / ((stem.empty() ? std::string("job") : stem) + ".farm")).string();
  }
  job.dir = absolute(dir);
  if (!job.dir.empty() && job.dir.back() == '/') job.dir.pop_back();
  if (fs::exists(job.dir + "/job.txt")) {
    const farm::Job before = farm::Job::load(job.dir);
    if (!before.sameWork(job))
      fail(job.dir, "holds another job (its job.txt differs from this command): give another --job-dir, or remove the directory to start over");
  }
  job.save();

  const std::vector<size_t> tasks = job.unfinishedTasks();
  bool allFinal = true;
  for (int64_t f : job.frames) allFinal = allFinal && job.frameDone(f);
  if (allFinal) {
    note(cat("every frame of the job exists (", job.frames.size(), " frames); nothing submitted. `reshutter farm assemble ", job.dir, "` reads them all back"));
    return 0;
  }
  if (fo.dryRun) {
    if (!tasks.empty()) std::printf("# %s/tasks.sh\n%s\n", job.dir.c_str(), farm::taskScript(job, tasks, fo.slurm).c_str());
    std::printf("# %s/assemble.sh\n%s\n", job.dir.c_str(), farm::assembleScript(job, fo.slurm).c_str());
    std::printf("# submit:\n");
    if (!tasks.empty()) std::printf("#   sbatch --parsable %s/tasks.sh                      -> JOBID\n", job.dir.c_str());
    std::printf("#   sbatch --parsable%s %s/assemble.sh\n", tasks.empty() ? "" : " --dependency=afterok:JOBID --kill-on-invalid-dep=yes", job.dir.c_str());
    std::printf("# %zu of %zu tasks to run; each also runs by hand: %s farm task %s --index N\n", tasks.size(), job.tasks(), job.reshutter.c_str(),
                job.dir.c_str());
    return 0;
  }
  const farm::Submission sub = farm::submit(job, tasks, fo.slurm);
  if (tasks.empty()) note(cat("every task is done; submitted the final step as job ", sub.assembleJob));
  else
    note(cat("submitted ", tasks.size(), " of ", job.tasks(), " tasks as job array ", sub.taskJob, " and the final step as job ", sub.assembleJob,
             " (afterok); follow it with `reshutter farm status ", job.dir, "`"));
  if (!fo.wait) return 0;
  Progress progress("farm", job.tasks() + 1);
  size_t shown = 0;
  farm::waitFor({sub.taskJob, sub.assembleJob}, [&] {
    size_t done = 0;
    for (const auto& r : farm::taskReports(job)) done += r.state != farm::TaskReport::State::Waiting;
    if (done > shown) progress.advance(done - shown), shown = done;
  });
  progress.finish();
  return reportStatus(job, 10);
}

int runTask(const std::string& dir, int64_t indexOption, const std::string& framesOption) {
  const farm::Job job = farm::Job::load(dir);
  int64_t index = indexOption;
  if (index < 0) {
    const char* env = std::getenv("SLURM_ARRAY_TASK_ID");
    if (!env) fail("farm task", "no task index: give --index N, or run it as a Slurm array task (SLURM_ARRAY_TASK_ID)");
    char* end = nullptr;
    index = std::strtoll(env, &end, 10);
    if (!*env || *end || index < 0) fail("SLURM_ARRAY_TASK_ID", "expected a task index, got '", env, "'");
  }
  farm::Job::Task task = job.task(size_t(index));
  if (!framesOption.empty()) {
    // A farm manager that hands out frame ranges (Deadline, OpenCue): the job's frames among
    // those, this tile. A range such as 1-10 given for a job of every other frame is fine.
    const std::vector<int64_t> asked = parseFrameRange(framesOption, "--frames");
    task.frames.clear();
    for (int64_t f : job.frames)
      if (std::find(asked.begin(), asked.end(), f) != asked.end()) task.frames.push_back(f);
    if (task.frames.empty()) fail("--frames", "none of ", framesOption, " is one of the job's frames (", farm::frameList(job.frames), ")");
  }
  const std::vector<int64_t> left = job.framesLeft(task);
  if (left.empty()) {
    note(cat(describe(job, task), ": every frame is done already"));
    return 0;
  }
  const std::vector<std::string> command = job.taskCommand(task, left);
  std::string line;
  for (const auto& a : command) line += (line.empty() ? "" : " ") + a;
  note(cat(describe(job, task), ": ", left.size(), " frame", left.size() == 1 ? "" : "s", " to render in ", job.workdir, "\n  ", line));
  // Relative store paths are the submitting directory's, wherever the manager starts the task.
  std::error_code ec;
  fs::current_path(job.workdir, ec);
  if (ec) fail(job.workdir, "cannot enter the job's working directory: ", ec.message());
  std::fflush(stdout), std::fflush(stderr);
  std::vector<char*> args;
  for (const auto& a : command) args.push_back(const_cast<char*>(a.c_str()));
  args.push_back(nullptr);
  execv(args[0], args.data());
  fail(command[0], "cannot run: ", std::strerror(errno));
}

// Parses the job's own command line as its command would, to get its render options (previews
// of assembled frames use them).
RenderOptions renderOptionsOf(const farm::Job& job) {
  CLI::App app;
  Registry registry;
  RenderOptions captured;
  registry.sequenceHook = [&](const SequenceRequest& r) {
    captured = *r.render;
    return 0;
  };
  if (job.command == "resample") addResampleCommand(app, registry);
  else addRetimeCommands(app, registry);
  std::vector<std::string> args{job.command};
  args.insert(args.end(), job.args.begin(), job.args.end());
  args.insert(args.end(), {"--frames", farm::frameList(job.frames)});
  if (!job.output.empty()) args.insert(args.end(), {"-o", job.output});
  if (!job.deep.empty()) args.insert(args.end(), {"--deep", job.deep});
  for (const auto& p : job.previews) args.insert(args.end(), {"--preview", p});
  std::reverse(args.begin(), args.end());  // CLI11 takes the arguments last first
  try {
    app.parse(args);
  } catch (const CLI::ParseError& e) {
    fail(job.descriptionPath(), "the job's command line no longer parses: ", e.what());
  }
  for (auto& [sub, action] : registry.commands)
    if (sub->parsed()) action();
  return captured;
}

int assembleJob(const std::string& dir, bool keepTiles) {
  const farm::Job job = farm::Job::load(dir);
  farm::AssembledHook previews;
  RenderOptions render;
  if (job.tiles() > 1 && !job.previews.empty()) {
    render = renderOptionsOf(job);
    previews = [&](int64_t frame, const resample::FlatImage& image) { render.writePreviews(image, frame); };
  }
  Progress progress("assemble", 1);
  const auto problems = farm::finishJob(job, keepTiles, previews);
  progress.finish();
  for (const auto& p : problems) std::fprintf(stderr, "reshutter: frame %lld: %s\n", static_cast<long long>(p.frame), p.reason.c_str());
  if (!problems.empty()) fail(job.dir, problems.size(), " of ", job.frames.size(), " frames are missing or do not read (listed above)");
  note(cat(job.frames.size(), " frames of ", job.dir, " are whole and read back",
           job.tiles() > 1 ? cat(" (", job.tiles(), " tiles each, assembled)") : std::string()));
  return 0;
}

}  // namespace

void addFarmCommands(CLI::App& app, Registry& registry) {
  auto* farmApp = app.add_subcommand("farm", "Run retime, fields or resample as a Slurm job: chunks of frames, crop tiles, resumable");
  farmApp->require_subcommand(1);
  farmApp->footer(
      "Submit:   reshutter farm retime shot.####.mps --to-fps 30 --frames 1-1000 -o out/ntsc.####.exr --chunk 10 [--tiles 2x2]\n"
      "Follow:   reshutter farm status out/ntsc.farm\n"
      "Resume:   run the same submit command again: frames already done are skipped\n"
      "See docs/farm.md (other farm managers, planning a long shot).");

  // farm retime|fields|resample: the commands themselves, with the farm's options added and
  // their request handed to submitJob() instead of rendered.
  auto fo = std::make_shared<FarmOptions>();
  Registry submitRegistry;
  submitRegistry.sequenceHook = [fo, &registry](const SequenceRequest& req) { return submitJob(req, *fo, registry.argv); };
  addRetimeCommands(*farmApp, submitRegistry);
  addResampleCommand(*farmApp, submitRegistry);
  for (auto& [sub, action] : submitRegistry.commands) {
    const std::string g = "Farm";
    sub->add_option("--chunk", fo->chunk, "Frames per task")->check(CLI::PositiveNumber)->capture_default_str()->group(g);
    sub->add_option("--tiles", fo->tiles, "Crop tiles per frame, COLUMNSxROWS: one task per tile of each chunk; a final step assembles them")
        ->capture_default_str()
        ->group(g);
    sub->add_option("--job-dir", fo->jobDir, "Job directory: description, batch scripts, logs, tiles (default: beside the output, OUTNAME.farm)")->group(g);
    sub->add_flag("--dry-run", fo->dryRun, "Write the job directory and print the batch scripts; submit nothing")->group(g);
    sub->add_flag("--wait", fo->wait, "Wait for the job to end, then report as `farm status` does")->group(g);
    sub->add_flag("--keep-tiles", fo->slurm.keepTiles, "Keep the tiles after assembling them")->group(g);
    sub->add_option("--partition", fo->slurm.partition, "sbatch --partition")->group(g);
    sub->add_option("--time", fo->slurm.time, "sbatch --time, per task (e.g. 0:30:00)")->group(g);
    sub->add_option("--mem", fo->slurm.mem, "sbatch --mem, per task (e.g. 4G)")->group(g);
    sub->add_option("--sbatch", fo->slurm.extra, "Any other sbatch option, repeatable (e.g. --sbatch=--qos=low)")->allow_extra_args(false)->group(g);
    sub->add_option("--max-running", fo->slurm.maxRunning, "Run at most this many tasks at once (the array's %N)")->check(CLI::NonNegativeNumber)->group(g);
    sub->add_option("--job-name", fo->slurm.name, "Slurm job name")->capture_default_str()->group(g);
    sub->add_option("--reshutter", fo->binary, "The reshutter binary the tasks run (default: this one; it must be visible on the nodes)")->group(g);
    registry.add(sub, action);
  }

  {
    struct TaskOptions {
      std::string dir, frames;
      int64_t index = -1;
    };
    auto o = std::make_shared<TaskOptions>();
    auto* sub = farmApp->add_subcommand("task", "Render one task of a job (what each array task runs; by hand or from another farm manager too)");
    sub->add_option("job-dir", o->dir, "The job directory")->required();
    sub->add_option("--index", o->index, "Task index (default: $SLURM_ARRAY_TASK_ID)")->check(CLI::NonNegativeNumber);
    sub->add_option("--frames", o->frames, "Render these of the job's frames instead of the task's chunk (managers that hand out frame ranges)");
    sub->footer("A task renders the frames of its chunk (its tile of each) that are not done, then exits with the render's status.");
    registry.add(sub, [o] { return runTask(o->dir, o->index, o->frames); });
  }
  {
    struct AssembleOptions {
      std::string dir;
      bool keepTiles = false;
    };
    auto o = std::make_shared<AssembleOptions>();
    auto* sub = farmApp->add_subcommand("assemble", "The final step of a job: assemble tiles into frames, then read every frame back");
    sub->add_option("job-dir", o->dir, "The job directory")->required();
    sub->add_flag("--keep-tiles", o->keepTiles, "Keep the tiles after assembling them");
    registry.add(sub, [o] { return assembleJob(o->dir, o->keepTiles); });
  }
  {
    struct StatusOptions {
      std::string dir;
      size_t lines = 10;
    };
    auto o = std::make_shared<StatusOptions>();
    auto* sub = farmApp->add_subcommand("status", "What each task of a job did: done, failed (with its log), pending; frames final");
    sub->add_option("job-dir", o->dir, "The job directory")->required();
    sub->add_option("--log-lines", o->lines, "Lines of each failed task's log to show")->capture_default_str();
    registry.add(sub, [o] { return reportStatus(farm::Job::load(o->dir), o->lines); });
  }
  {
    struct Options {
      std::vector<std::string> tiles;
      std::string output;
    };
    auto o = std::make_shared<Options>();
    auto* sub = app.add_subcommand("assemble", "Merge crop tiles (flat or deep OpenEXR, rendered with --crop) into one image");
    sub->add_option("tiles", o->tiles, "The tiles: one frame's, all flat or all deep")->required();
    sub->add_option("-o,--output", o->output, "The whole image")->required();
    sub->footer(
        "The tiles must come from one render (same frame, shutter, camera, channels and compression), not overlap,\n"
        "and fill a rectangle. The result is byte for byte the file the render writes for that rectangle in one go.\n"
        "Deep tiles: render them with --deep-all-channels, so that channels only some tiles need come out exact.\n\n"
        "Example:\n"
        "  reshutter resample f.mps --crop 0 960 0 1080 -o left.exr && reshutter resample f.mps --crop 960 1920 0 1080 -o right.exr\n"
        "  reshutter assemble left.exr right.exr -o whole.exr");
    registry.add(sub, [o] {
      const size_t pixels = resample::assembleExrFiles(o->tiles, o->output);
      note(cat("wrote ", o->output, ": ", pixels, " pixels from ", o->tiles.size(), " tiles"));
      return 0;
    });
  }
}

}  // namespace reshutter::cli
