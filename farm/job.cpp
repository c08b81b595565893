#include "farm/job.h"

#include <algorithm>
#include <filesystem>
#include <fstream>
#include <sstream>

#include "common/atomic_file.h"
#include "common/error.h"
#include "common/frame_range.h"
#include "resample/assemble.h"

namespace reshutter::farm {

namespace fs = std::filesystem;

std::string frameList(const std::vector<int64_t>& frames) {
  std::string out;
  for (size_t i = 0; i < frames.size();) {
    // The longest run from i with one positive step.
    size_t j = i + 1;
    const int64_t step = j < frames.size() ? frames[j] - frames[i] : 0;
    if (step > 0)
      while (j + 1 < frames.size() && frames[j + 1] - frames[j] == step) ++j;
    if (!out.empty()) out += ',';
    if (step > 0 && (j - i >= 2 || step == 1)) {
      out += std::to_string(frames[i]) + "-" + std::to_string(frames[j]);
      if (step > 1) out += "x" + std::to_string(step);
      i = j + 1;
    } else {
      out += std::to_string(frames[i]);
      ++i;
    }
  }
  return out;
}

Rect Job::tileRect(size_t t) const {
  const int tx = int(t % size_t(tilesX)), ty = int(t / size_t(tilesX));
  const int64_t w = window.x1 - window.x0, h = window.y1 - window.y0;
  Rect r;
  r.x0 = window.x0 + int(w * tx / tilesX), r.x1 = window.x0 + int(w * (tx + 1) / tilesX);
  r.y0 = window.y0 + int(h * ty / tilesY), r.y1 = window.y0 + int(h * (ty + 1) / tilesY);
  return r;
}

Job::Task Job::task(size_t index) const {
  if (index >= tasks()) fail("farm task", "task index ", index, " is out of range: the job has ", tasks(), " tasks (0-", tasks() - 1, ")");
  Task t;
  t.index = index, t.chunk = index / tiles(), t.tile = index % tiles();
  const size_t first = t.chunk * size_t(chunk), last = std::min(frames.size(), first + size_t(chunk));
  t.frames.assign(frames.begin() + ptrdiff_t(first), frames.begin() + ptrdiff_t(last));
  t.crop = tileRect(t.tile);
  return t;
}

namespace {
// Where tile `tile`'s images of kind "flat" or "deep" go: the output pattern's file name (its
// placeholder kept) in the tile's directory.
// Only the file name is expanded: a placeholder-like character in the job directory stays.
std::string tileDirectory(const std::string& dir, size_t tile, const char* kind) { return dir + "/tiles/" + std::to_string(tile) + "/" + kind + "/"; }
std::string tilePattern(const std::string& dir, size_t tile, const char* kind, const std::string& pattern) {
  return tileDirectory(dir, tile, kind) + fs::path(pattern).filename().string();
}
std::string tilePath(const std::string& dir, size_t tile, const char* kind, const std::string& pattern, int64_t frame) {
  return tileDirectory(dir, tile, kind) + expandFramePattern(fs::path(pattern).filename().string(), frame);
}
bool exists(const std::string& p) {
  std::error_code ec;
  return fs::is_regular_file(p, ec);
}
}  // namespace

std::string Job::finalOutput(int64_t frame) const { return output.empty() ? "" : expandFramePattern(output, frame); }
std::string Job::finalDeep(int64_t frame) const { return deep.empty() ? "" : expandFramePattern(deep, frame); }
std::string Job::tileOutput(size_t tile, int64_t frame) const {
  if (output.empty()) return "";
  return tiles() == 1 ? finalOutput(frame) : tilePath(dir, tile, "flat", output, frame);
}
std::string Job::tileDeep(size_t tile, int64_t frame) const {
  if (deep.empty()) return "";
  return tiles() == 1 ? finalDeep(frame) : tilePath(dir, tile, "deep", deep, frame);
}

bool Job::frameDone(int64_t frame) const { return (output.empty() || exists(finalOutput(frame))) && (deep.empty() || exists(finalDeep(frame))); }

bool Job::taskFrameDone(const Task& task, int64_t frame) const {
  if (frameDone(frame)) return true;
  return (output.empty() || exists(tileOutput(task.tile, frame))) && (deep.empty() || exists(tileDeep(task.tile, frame)));
}

std::vector<int64_t> Job::framesLeft(const Task& t) const {
  std::vector<int64_t> left;
  for (int64_t f : t.frames)
    if (!taskFrameDone(t, f)) left.push_back(f);
  return left;
}

std::vector<size_t> Job::unfinishedTasks() const {
  std::vector<size_t> out;
  for (size_t i = 0; i < tasks(); ++i)
    if (!framesLeft(task(i)).empty()) out.push_back(i);
  return out;
}

std::vector<std::string> Job::taskCommand(const Task& t, const std::vector<int64_t>& list) const {
  std::vector<std::string> a{reshutter, command};
  a.insert(a.end(), args.begin(), args.end());
  a.insert(a.end(), {"--frames", frameList(list)});
  const Rect& c = t.crop;
  a.insert(a.end(), {"--crop", std::to_string(c.x0), std::to_string(c.x1), std::to_string(c.y0), std::to_string(c.y1)});
  const bool tiled = tiles() > 1;
  if (!output.empty()) a.insert(a.end(), {"-o", tiled ? tilePattern(dir, t.tile, "flat", output) : output});
  if (!deep.empty()) {
    a.insert(a.end(), {"--deep", tiled ? tilePattern(dir, t.tile, "deep", deep) : deep});
    if (tiled) a.push_back("--deep-all-channels");  // the whole frame may need channels this tile does not
  }
  if (!tiled)
    for (const auto& p : previews) a.insert(a.end(), {"--preview", p});
  return a;
}

// ---------------------------------------------------------------------------------------------
// job.txt: one "key value" per line; values run to the end of the line.

void Job::save() const {
  std::vector<std::string> dirs{dir + "/logs", dir + "/status", dir + "/tiles"};
  for (size_t t = 0; tiles() > 1 && t < tiles(); ++t) {
    if (!output.empty()) dirs.push_back(dir + "/tiles/" + std::to_string(t) + "/flat");
    if (!deep.empty()) dirs.push_back(dir + "/tiles/" + std::to_string(t) + "/deep");
  }
  for (const auto& d : dirs) {
    std::error_code ec;
    fs::create_directories(d, ec);
    if (ec || !fs::is_directory(d)) fail(d, "cannot create the job's directory: ", ec ? ec.message() : "a file is in the way");
  }
  std::ostringstream s;
  s << "reshutter-farm-job 1\n";
  s << "command " << command << "\n";
  for (const auto& a : args) {
    if (a.find('\n') != std::string::npos) fail("farm", "an argument holds a line break: '", a, "'");
    s << "arg " << a << "\n";
  }
  s << "frames " << frameList(frames) << "\n";
  s << "output " << output << "\n";
  s << "deep " << deep << "\n";
  for (const auto& p : previews) s << "preview " << p << "\n";
  s << "chunk " << chunk << "\n";
  s << "tiles " << tilesX << " " << tilesY << "\n";
  s << "window " << window.x0 << " " << window.x1 << " " << window.y0 << " " << window.y1 << "\n";
  s << "reshutter " << reshutter << "\n";
  s << "workdir " << workdir << "\n";
  const std::string text = s.str();
  AtomicFile f(descriptionPath());
  writeAll(f.fd(), text.data(), text.size(), descriptionPath());
  f.commit();
}

Job Job::load(const std::string& dirIn) {
  Job j;
  j.dir = fs::absolute(dirIn).lexically_normal().string();
  if (j.dir.size() > 1 && j.dir.back() == '/') j.dir.pop_back();
  const std::string path = j.descriptionPath();
  std::ifstream in(path);
  if (!in) fail(path, "cannot read the job description (is ", dirIn, " a farm job directory?)");
  std::string line;
  int n = 0;
  bool header = false, sawFrames = false, sawCommand = false;
  while (std::getline(in, line)) {
    ++n;
    const std::string where = path + ":" + std::to_string(n);
    const size_t sp = line.find(' ');
    const std::string key = line.substr(0, sp), value = sp == std::string::npos ? "" : line.substr(sp + 1);
    std::istringstream v(value);
    if (n == 1) {
      if (line != "reshutter-farm-job 1") fail(where, "not a reshutter farm job description (first line '", line, "')");
      header = true;
    } else if (key == "command") {
      if (value != "retime" && value != "fields" && value != "resample") fail(where, "unknown command '", value, "'");
      j.command = value, sawCommand = true;
    } else if (key == "arg") {
      j.args.push_back(value);
    } else if (key == "frames") {
      j.frames = parseFrameRange(value, where), sawFrames = true;
    } else if (key == "output") {
      j.output = value;
    } else if (key == "deep") {
      j.deep = value;
    } else if (key == "preview") {
      j.previews.push_back(value);
    } else if (key == "chunk") {
      if (!(v >> j.chunk) || j.chunk < 1) fail(where, "chunk must be a positive integer");
    } else if (key == "tiles") {
      if (!(v >> j.tilesX >> j.tilesY) || j.tilesX < 1 || j.tilesY < 1) fail(where, "tiles must be two positive integers");
    } else if (key == "window") {
      if (!(v >> j.window.x0 >> j.window.x1 >> j.window.y0 >> j.window.y1) || j.window.x1 <= j.window.x0 || j.window.y1 <= j.window.y0)
        fail(where, "window must be x0 x1 y0 y1 with x0 < x1, y0 < y1");
    } else if (key == "reshutter") {
      j.reshutter = value;
    } else if (key == "workdir") {
      j.workdir = value;
    } else {
      fail(where, "unknown key '", key, "'");
    }
  }
  if (!header || !sawCommand || !sawFrames || j.reshutter.empty() || j.workdir.empty()) fail(path, "incomplete job description");
  if (j.output.empty() && j.deep.empty()) fail(path, "the job writes nothing (no output, no deep)");
  if (int64_t(j.window.x1 - j.window.x0) < j.tilesX || int64_t(j.window.y1 - j.window.y0) < j.tilesY) fail(path, "more tiles than pixels");
  return j;
}

bool Job::sameWork(const Job& o) const {
  Job a = *this;
  a.reshutter = o.reshutter;
  return a == o;
}

// ---------------------------------------------------------------------------------------------
// The final step

std::vector<FrameProblem> finishJob(const Job& job, bool keepTiles, const AssembledHook& assembled) {
  std::vector<FrameProblem> problems;
  for (int64_t f : job.frames) {
    try {
      if (job.tiles() > 1) {
        // Assemble what is not yet final; a final output that exists was assembled before.
        for (int deep = 0; deep < 2; ++deep) {
          const std::string out = deep ? job.finalDeep(f) : job.finalOutput(f);
          if (out.empty() || exists(out)) continue;
          std::vector<std::string> tiles;
          std::vector<std::string> missing;
          for (size_t t = 0; t < job.tiles(); ++t) {
            const std::string p = deep ? job.tileDeep(t, f) : job.tileOutput(t, f);
            (exists(p) ? tiles : missing).push_back(p);
          }
          if (!missing.empty()) fail(missing.front(), "is missing (", missing.size(), " of ", job.tiles(), " tiles of frame ", f, ")");
          if (deep) {
            std::vector<resample::DeepExr> parts;
            for (const auto& p : tiles) parts.push_back(resample::readDeepExr(p));
            resample::DeepExr whole = resample::assembleDeep(std::move(parts), tiles);
            resample::writeDeepExr(out, whole.image, whole.provenance, whole.options);
          } else {
            std::vector<resample::FlatExr> parts;
            for (const auto& p : tiles) parts.push_back(resample::readFlatExr(p));
            resample::FlatExr whole = resample::assembleFlat(std::move(parts), tiles);
            resample::writeExr(out, whole.image, whole.provenance, whole.options);
            if (assembled) assembled(f, whole.image);
          }
        }
      }
      for (const std::string& out : {job.finalOutput(f), job.finalDeep(f)}) {
        if (out.empty()) continue;
        if (!exists(out)) fail(out, "is missing");
        resample::verifyExr(out);
      }
      if (job.tiles() > 1 && !keepTiles)
        for (size_t t = 0; t < job.tiles(); ++t)
          for (const std::string& p : {job.tileOutput(t, f), job.tileDeep(t, f)}) {
            std::error_code ec;
            if (!p.empty()) fs::remove(p, ec);
          }
    } catch (const Error& e) {
      problems.push_back({f, e.what()});
    }
  }
  return problems;
}

}  // namespace reshutter::farm
