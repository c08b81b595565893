// A render-farm job: one re-sampling command (retime, fields or resample) over a list of output
// frames, cut into tasks of `chunk` frames and, optionally, one crop tile of each frame. Owns the
// job directory's layout and description file, the map from a task index (Slurm's array index,
// or any farm manager's) to its frames and tile, the command line a task runs, what is already
// done (so a job resubmitted resumes), and the final step that assembles tiles and checks that
// every frame exists and reads. Slurm itself is farm/slurm.h; nothing here needs a scheduler.
//
// Job directory:  job.txt (this description)  tasks.sh assemble.sh (batch scripts)
//                 logs/task.<i>.log  status/task.<i>.exit  tiles/<t>/<output names>
#pragma once

#include <cstdint>
#include <functional>
#include <string>
#include <vector>

#include "resample/image.h"

namespace reshutter::farm {

/// A pixel rectangle [x0, x1) × [y0, y1).
struct Rect {
  int x0 = 0, x1 = 0, y0 = 0, y1 = 0;
  bool operator==(const Rect&) const = default;
};

struct Job {
  std::string command;            // retime | fields | resample
  std::vector<std::string> args;  // its arguments, less --frames, -o, --deep, --preview and --crop (the job sets those per task)
  std::vector<int64_t> frames;    // output frames, in order
  std::string output, deep;       // final flat / deep EXR patterns (absolute; either may be empty)
  std::vector<std::string> previews;
  int chunk = 1;               // frames per task
  int tilesX = 1, tilesY = 1;  // crop tiles per frame
  Rect window;                 // the pixels the frames cover (the image, or the user's --crop)
  std::string reshutter;       // the binary tasks run (absolute)
  std::string workdir;         // where the command was given: tasks run there (relative store paths)
  std::string dir;             // the job directory (absolute)

  size_t tiles() const { return size_t(tilesX) * size_t(tilesY); }
  size_t chunks() const { return (frames.size() + size_t(chunk) - 1) / size_t(chunk); }
  size_t tasks() const { return chunks() * tiles(); }

  /// What task `index` (0 ≤ index < tasks()) renders: frames [first, last] of chunk index / tiles(),
  /// tile index % tiles().
  struct Task {
    size_t index = 0, chunk = 0, tile = 0;
    std::vector<int64_t> frames;
    Rect crop;
  };
  Task task(size_t index) const;
  /// Tile t's pixels: the window cut into tilesX × tilesY near-equal rectangles, row-major.
  Rect tileRect(size_t t) const;

  /// Where a tile's flat / deep image of `frame` goes (the final names when there is one tile).
  std::string tileOutput(size_t tile, int64_t frame) const;
  std::string tileDeep(size_t tile, int64_t frame) const;
  std::string finalOutput(int64_t frame) const;  // "" when the job writes no flat image
  std::string finalDeep(int64_t frame) const;    // "" when it writes no deep image

  /// A frame is done when each final output exists (outputs are written atomically, so a file
  /// that exists is whole; the final step reads each one to be sure).
  bool frameDone(int64_t frame) const;
  /// A task's frame is done when the frame is, or its tile's outputs exist.
  bool taskFrameDone(const Task& task, int64_t frame) const;
  /// The task's frames still to render.
  std::vector<int64_t> framesLeft(const Task& task) const;
  /// Task indices with frames left, ascending.
  std::vector<size_t> unfinishedTasks() const;

  /// The argument vector task `t` runs for `frames` (argv[0] = the binary).
  std::vector<std::string> taskCommand(const Task& t, const std::vector<int64_t>& frames) const;

  std::string logOf(size_t task) const { return dir + "/logs/task." + std::to_string(task) + ".log"; }
  std::string statusOf(size_t task) const { return dir + "/status/task." + std::to_string(task) + ".exit"; }
  std::string descriptionPath() const { return dir + "/job.txt"; }

  /// Writes job.txt (atomically) and creates logs/, status/ and tiles/.
  void save() const;
  /// Reads `dir`/job.txt; throws Error naming the file and line on anything malformed.
  static Job load(const std::string& dir);
  bool operator==(const Job&) const = default;
  /// The same work: equal but for the binary that runs it (a resubmission may use a new build).
  bool sameWork(const Job& o) const;
};

/// Frames as the shortest list of ranges: 1-4,6,8-12x2.
std::string frameList(const std::vector<int64_t>& frames);

/// The final step of a job: assembles every tiled frame not yet assembled (then removes its
/// tiles unless keepTiles) and hands each assembled flat image to `assembled` (previews are made
/// there, with the command's own options), then reads every final output whole. Returns the
/// frames that are missing or do not read, each with the reason.
struct FrameProblem {
  int64_t frame;
  std::string reason;
};
using AssembledHook = std::function<void(int64_t frame, const resample::FlatImage& image)>;
std::vector<FrameProblem> finishJob(const Job& job, bool keepTiles, const AssembledHook& assembled);

}  // namespace reshutter::farm
