// The farm without a scheduler (the Slurm run itself is tests/farm/farm_slurm_test.sh, label
// `farm`): how a job cuts frames into chunks and the image into tiles, its description file,
// Slurm's array syntax, and the whole path a task takes, run by hand - every task of a tiled
// job rendered with `farm task`, assembled with `farm assemble`, must give the bytes a local
// render writes (flat, deep, previews). Tile assembly's errors name the tile at fault.
#include <algorithm>
#include <filesystem>
#include <fstream>
#include <random>
#include <set>

#include <gtest/gtest.h>

#include "common/error.h"
#include "common/frame_range.h"
#include "farm/job.h"
#include "farm/slurm.h"
#include "tests/test_util.h"

namespace reshutter {
namespace {

using test::readBytes;
using test::runReshutter;
using test::ScratchDir;

TEST(FarmJob, FrameListsReadBackAsTheSameFrames) {
  std::mt19937 rng(7);
  for (int trial = 0; trial < 500; ++trial) {
    std::vector<int64_t> frames;
    int64_t f = int64_t(rng() % 41) - 20;
    const int n = 1 + int(rng() % 30);
    for (int i = 0; i < n; ++i) {
      frames.push_back(f);
      f += rng() % 4 == 0 ? -int64_t(rng() % 5) : int64_t(1 + rng() % 3);  // mostly ascending runs, some repeats and steps back
    }
    const std::string list = farm::frameList(frames);
    EXPECT_EQ(parseFrameRange(list), frames) << list;
  }
  EXPECT_EQ(farm::frameList({1, 2, 3, 4}), "1-4");
  EXPECT_EQ(farm::frameList({1, 3, 5, 6}), "1-5x2,6");
  EXPECT_EQ(farm::frameList({-3, -2, -1}), "-3--1");
}

TEST(FarmJob, TilesCoverTheWindowOnce) {
  for (auto [w, h, tx, ty] : {std::array{160, 90, 2, 1}, {160, 90, 3, 3}, {7, 5, 7, 5}, {1920, 1080, 4, 3}, {100, 1, 5, 1}}) {
    farm::Job job;
    job.window = {10, 10 + w, 3, 3 + h};
    job.tilesX = tx, job.tilesY = ty;
    std::vector<int> hits(size_t(w) * size_t(h), 0);
    for (size_t t = 0; t < job.tiles(); ++t) {
      const farm::Rect r = job.tileRect(t);
      EXPECT_LT(r.x0, r.x1);
      EXPECT_LT(r.y0, r.y1);
      for (int y = r.y0; y < r.y1; ++y)
        for (int x = r.x0; x < r.x1; ++x) ++hits[size_t(y - 3) * size_t(w) + size_t(x - 10)];
    }
    EXPECT_TRUE(std::all_of(hits.begin(), hits.end(), [](int n) { return n == 1; })) << w << "x" << h << " in " << tx << "x" << ty;
  }
}

TEST(FarmJob, TaskIndicesMapChunksAndTiles) {
  farm::Job job;
  job.frames = parseFrameRange("1-10");
  job.chunk = 4, job.tilesX = 2, job.tilesY = 1;
  job.window = {0, 100, 0, 50};
  ASSERT_EQ(job.chunks(), 3u);
  ASSERT_EQ(job.tasks(), 6u);
  std::multiset<std::pair<int64_t, size_t>> covered;  // (frame, tile) rendered by some task
  for (size_t i = 0; i < job.tasks(); ++i) {
    const auto t = job.task(i);
    EXPECT_EQ(t.chunk, i / 2);
    EXPECT_EQ(t.tile, i % 2);
    EXPECT_EQ(t.crop, job.tileRect(t.tile));
    for (int64_t f : t.frames) covered.insert({f, t.tile});
  }
  EXPECT_EQ(covered.size(), 20u);
  for (int64_t f = 1; f <= 10; ++f)
    for (size_t tile = 0; tile < 2; ++tile) EXPECT_EQ(covered.count({f, tile}), 1u) << f << " " << tile;
  EXPECT_EQ(job.task(5).frames, std::vector<int64_t>({9, 10}));  // the last chunk is short
  EXPECT_THROW(job.task(6), Error);
}

TEST(FarmJob, DescriptionReadsBackAndBadOnesNameTheLine) {
  ScratchDir dir;
  farm::Job job;
  job.command = "retime";
  job.args = {"shot.####.mps", "--to-fps", "30000/1001", "--aov", "N:gaussian"};
  job.frames = parseFrameRange("1-10,20-30x5");
  job.output = "/x/out.####.exr", job.deep = "/x/deep.%04d.exr";
  job.previews = {"/x/p.####.png=R,G,B"};
  job.chunk = 3, job.tilesX = 2, job.tilesY = 3;
  job.window = {0, 64, 0, 48};
  job.reshutter = "/usr/bin/reshutter";
  job.workdir = "/shots/a b";
  job.dir = dir.path("job");
  job.save();
  EXPECT_TRUE(farm::Job::load(job.dir) == job);
  farm::Job rebuilt = job, other = job;
  rebuilt.reshutter = "/opt/new/reshutter", other.chunk = 4;
  EXPECT_TRUE(job.sameWork(rebuilt)) << "a resubmission with a new build is the same work";
  EXPECT_FALSE(job.sameWork(other));
  EXPECT_TRUE(std::filesystem::is_directory(job.dir + "/tiles/5/deep"));

  auto loadWith = [&](const std::string& text) {
    std::ofstream(job.dir + "/job.txt") << text;
    try {
      farm::Job::load(job.dir);
    } catch (const Error& e) {
      return std::string(e.what());
    }
    return std::string("no error");
  };
  const std::string head = "reshutter-farm-job 1\ncommand retime\nframes 1-3\noutput /o.####.exr\nreshutter /bin/r\nworkdir /w\n";
  EXPECT_NE(loadWith(head + "chunk 0\n").find("job.txt:7"), std::string::npos);
  EXPECT_NE(loadWith(head + "tiles 2\n").find("job.txt:7"), std::string::npos);
  EXPECT_NE(loadWith(head + "colour blue\n").find("unknown key 'colour'"), std::string::npos);
  EXPECT_NE(loadWith("reshutter-farm-job 2\n").find("job.txt:1"), std::string::npos);
  EXPECT_NE(loadWith("reshutter-farm-job 1\ncommand render\n").find("unknown command"), std::string::npos);
  EXPECT_NE(loadWith("reshutter-farm-job 1\ncommand retime\n").find("incomplete"), std::string::npos);
  EXPECT_NE(loadWith(head + "frames 3-1\n").find("job.txt:7"), std::string::npos);
  EXPECT_EQ(loadWith(head + "window 0 8 0 8\n"), "no error");
}

TEST(FarmJob, FuzzCorpusReadsOrFailsCleanly) {
  // Job descriptions the fuzzer found interesting (tests/corpus/farm/): each reads or throws Error.
  ScratchDir dir;
  size_t files = 0, read = 0;
  for (const auto& f : std::filesystem::directory_iterator(test::sourceDir() + "/tests/corpus/farm")) {
    std::filesystem::copy_file(f.path(), dir.path("job.txt"), std::filesystem::copy_options::overwrite_existing);
    ++files;
    try {
      const farm::Job job = farm::Job::load(dir.dir().string());
      for (size_t i = 0; i < job.tasks() && i < 64; ++i) EXPECT_FALSE(job.task(i).frames.empty()) << f.path();
      ++read;
    } catch (const Error&) {
    }
  }
  EXPECT_GE(files, 2u);
  EXPECT_GE(read, 2u);  // the seeds are valid jobs
}

TEST(FarmSlurm, ArraySpecsAreSlurmsSyntax) {
  EXPECT_EQ(farm::arraySpec({0, 1, 2, 3}, 0), "0-3");
  EXPECT_EQ(farm::arraySpec({0, 1, 2, 5, 7, 8}, 0), "0-2,5,7-8");
  EXPECT_EQ(farm::arraySpec({4}, 2), "4%2");
  farm::Job job;
  job.command = "fields", job.frames = {1, 2}, job.dir = "/jobs/it's here", job.reshutter = "/opt/bin/reshutter", job.workdir = "/shots";
  job.window = {0, 8, 0, 8};
  farm::SlurmOptions o;
  o.partition = "render", o.mem = "4G", o.extra = {"--qos=low"};
  const std::string s = farm::taskScript(job, {0, 1}, o);
  EXPECT_NE(s.find("#SBATCH --array=0-1\n"), std::string::npos) << s;
  EXPECT_NE(s.find("#SBATCH --partition=render\n#SBATCH --mem=4G\n#SBATCH --qos=low\n"), std::string::npos) << s;
  EXPECT_NE(s.find("/opt/bin/reshutter farm task '/jobs/it'\\''s here'\n"), std::string::npos) << s;  // quoted for sh
  // The script is valid sh.
  ScratchDir dir;
  std::ofstream(dir.path("t.sh")) << s;
  EXPECT_EQ(test::runCommand("sh -n " + dir.path("t.sh")).exitCode, 0);
}

// A three-frame shot with a translucent moving ball over a floor (transparency and motion: deep
// pixels with several samples, thick ones where the ball moves).
std::string writeShot(const ScratchDir& dir) {
  std::ofstream rib(dir.path("shot.rib"));
  rib << "Format 96 64 1\nShutter 0 1\nProjection \"perspective\" \"fov\" [40]\n";
  for (int f = 1; f <= 3; ++f)
    rib << "FrameBegin " << f << "\nWorldBegin\nLightSource \"distantlight\" 1 \"intensity\" [1]\nSurface \"plastic\"\n"
        << "AttributeBegin Translate 0 -1 6 Rotate -70 1 0 0 Color [0.3 0.6 0.3] Polygon \"P\" [-4 -4 0 4 -4 0 4 4 0 -4 4 0] AttributeEnd\n"
        << "AttributeBegin Opacity [0.5 0.5 0.5] MotionBegin [0 1] Translate " << -1.5 + 0.5 * f << " 0 5 Translate " << -1 + 0.5 * f
        << " 0 5 MotionEnd Color [1 0.2 0.1] Sphere 0.7 -0.7 0.7 360 AttributeEnd\nWorldEnd\nFrameEnd\n";
  rib.close();
  const auto r = runReshutter("-q shade " + dir.path("shot.rib") + " -o " + dir.path("shot.####.mps"));
  EXPECT_EQ(r.exitCode, 0) << r.err;
  return dir.path("shot.####.mps");
}

TEST(FarmCli, TiledTasksRunByHandAssembleToTheLocalRendersBytes) {
  ScratchDir dir;
  const std::string shot = writeShot(dir);
  const std::string job = dir.path("job");
  const std::string common = "retime " + shot + " --to-fps 30 --frames 2-3 --spp 4";
  auto submit = runReshutter("farm " + common + " -o " + dir.path("f.####.exr") + " --deep " + dir.path("d.####.exr") + " --preview " + dir.path("p.####.png") +
                             " --chunk 1 --tiles 3x2 --job-dir " + job + " --dry-run");
  ASSERT_EQ(submit.exitCode, 0) << submit.err;
  EXPECT_NE(submit.out.find("#SBATCH --array=0-11"), std::string::npos) << submit.out;
  EXPECT_NE(submit.out.find("--dependency=afterok:"), std::string::npos) << submit.out;

  // One task run, then the job resumes without it.
  ASSERT_EQ(runReshutter("-q farm task " + job + " --index 4").exitCode, 0);
  const farm::Job loaded = farm::Job::load(job);
  const auto left = loaded.unfinishedTasks();
  EXPECT_EQ(left.size(), 11u);
  EXPECT_EQ(std::count(left.begin(), left.end(), size_t(4)), 0);
  submit = runReshutter("farm " + common + " -o " + dir.path("f.####.exr") + " --deep " + dir.path("d.####.exr") + " --preview " + dir.path("p.####.png") +
                        " --chunk 1 --tiles 3x2 --job-dir " + job + " --dry-run");
  EXPECT_NE(submit.out.find("#SBATCH --array=0-3,5-11"), std::string::npos) << submit.out;
  // The same job directory with another job is refused.
  const auto other = runReshutter("farm " + common + " -o " + dir.path("f.####.exr") + " --chunk 2 --job-dir " + job + " --dry-run");
  EXPECT_EQ(other.exitCode, 1);
  EXPECT_NE(other.err.find("holds another job"), std::string::npos) << other.err;

  // The final step before every task ran: it names a missing tile and fails.
  auto early = runReshutter("farm assemble " + job);
  EXPECT_EQ(early.exitCode, 1);
  EXPECT_NE(early.err.find("is missing"), std::string::npos) << early.err;

  // Task 4 again does nothing; the others render, under Slurm's variable too.
  const auto again = runReshutter("farm task " + job + " --index 4");
  EXPECT_NE(again.err.find("every frame is done already"), std::string::npos) << again.err;
  for (size_t i = 0; i < 12; ++i) {
    if (i == 4) continue;
    ASSERT_EQ(test::runCommand("SLURM_ARRAY_TASK_ID=" + std::to_string(i) + " " RESHUTTER_BINARY " -q farm task " + job).exitCode, 0) << i;
  }
  const auto assembled = runReshutter("farm assemble " + job);
  ASSERT_EQ(assembled.exitCode, 0) << assembled.err;
  EXPECT_NE(assembled.err.find("6 tiles each, assembled"), std::string::npos) << assembled.err;
  EXPECT_EQ(runReshutter("farm status " + job).exitCode, 0);

  ASSERT_EQ(
      runReshutter("-q " + common + " -o " + dir.path("l.####.exr") + " --deep " + dir.path("ld.####.exr") + " --preview " + dir.path("lp.####.png")).exitCode,
      0);
  for (const char* f : {"0002", "0003"}) {
    const std::string n(f);
    EXPECT_EQ(readBytes(dir.path("f." + n + ".exr")), readBytes(dir.path("l." + n + ".exr"))) << "flat frame " << n;
    EXPECT_EQ(readBytes(dir.path("d." + n + ".exr")), readBytes(dir.path("ld." + n + ".exr"))) << "deep frame " << n;
    EXPECT_EQ(readBytes(dir.path("p." + n + ".png")), readBytes(dir.path("lp." + n + ".png"))) << "preview " << n;
  }
  // The deep frames have what makes assembly non-trivial: pixels of several samples and thick ones.
  const auto info = test::runImageTool("iinfo -v " + dir.path("d.0002.exr"));
  EXPECT_NE(info.out.find("ZBack"), std::string::npos) << info.out;
  // Tiles are gone once assembled.
  size_t files = 0;
  for (const auto& e : std::filesystem::recursive_directory_iterator(job + "/tiles")) files += e.is_regular_file();
  EXPECT_EQ(files, 0u);
}

TEST(FarmCli, TwoPassFieldsRunAsTiles) {
  // fields --two-pass through the farm: each task renders both fields of its tile and interlaces.
  ScratchDir dir;
  const std::string shot = writeShot(dir);
  const std::string args = "fields " + shot + " --frames 2-3 --two-pass --filter gaussian:2x1 --spp 4";
  ASSERT_EQ(runReshutter("-q farm " + args + " -o " + dir.path("f.####.exr") + " --chunk 2 --tiles 1x3 --job-dir " + dir.path("job") + " --dry-run").exitCode,
            0);
  const farm::Job job = farm::Job::load(dir.path("job"));
  EXPECT_EQ(job.tasks(), 3u);
  EXPECT_EQ(std::count(job.args.begin(), job.args.end(), "--two-pass"), 1);
  for (int i = 0; i < 3; ++i) ASSERT_EQ(runReshutter("-q farm task " + dir.path("job") + " --index " + std::to_string(i)).exitCode, 0);
  ASSERT_EQ(runReshutter("-q farm assemble " + dir.path("job")).exitCode, 0);
  ASSERT_EQ(runReshutter("-q " + args + " -o " + dir.path("l.####.exr")).exitCode, 0);
  for (const char* f : {"0002", "0003"})
    EXPECT_EQ(readBytes(dir.path(std::string("f.") + f + ".exr")), readBytes(dir.path(std::string("l.") + f + ".exr"))) << f;
}

TEST(FarmCli, ResampleOfOneStoreRunsAsTiles) {
  // Submitted with paths relative to the shot's directory; the tasks start elsewhere (as a farm
  // manager may start them) and still find the store.
  ScratchDir dir;
  writeShot(dir);
  const std::string in = "cd " + dir.dir().string() + " && " RESHUTTER_BINARY " -q ";
  ASSERT_EQ(test::runCommand(in + "farm resample shot.0002.mps --shutter 0.25:0.5 -o q.exr --tiles 2x2 --job-dir job --dry-run").exitCode, 0);
  for (int i = 0; i < 4; ++i)
    ASSERT_EQ(test::runCommand("cd / && " RESHUTTER_BINARY " -q farm task " + dir.path("job") + " --index " + std::to_string(i)).exitCode, 0) << i;
  ASSERT_EQ(runReshutter("-q farm assemble " + dir.path("job")).exitCode, 0);
  ASSERT_EQ(runReshutter("-q resample " + dir.path("shot.0002.mps") + " --shutter 0.25:0.5 -o " + dir.path("l.exr")).exitCode, 0);
  EXPECT_EQ(readBytes(dir.path("q.exr")), readBytes(dir.path("l.exr")));
  // An independent checker agrees: no pixel differs at all.
  EXPECT_EQ(test::runImageTool("idiff -fail 0 -warn 0 " + dir.path("q.exr") + " " + dir.path("l.exr")).exitCode, 0);
}

TEST(FarmCli, AssembleRefusesTilesThatDoNotMakeOneImage) {
  ScratchDir dir;
  const std::string store = expandFramePattern(writeShot(dir), 2);
  auto crop = [&](const std::string& name, const std::string& rect, const std::string& extra = "") {
    ASSERT_EQ(runReshutter("-q resample " + store + " --crop " + rect + " -o " + dir.path(name) + " " + extra).exitCode, 0) << name;
  };
  crop("a.exr", "0 48 0 64"), crop("b.exr", "48 96 0 64"), crop("c.exr", "40 96 0 64"), crop("s.exr", "48 96 0 64", "--shutter 0:0.5");
  crop("h.exr", "48 96 0 32");
  ASSERT_EQ(runReshutter("-q resample " + store + " -o " + dir.path("whole.exr")).exitCode, 0);
  ASSERT_EQ(runReshutter("assemble " + dir.path("a.exr") + " " + dir.path("b.exr") + " -o " + dir.path("ab.exr")).exitCode, 0);
  EXPECT_EQ(readBytes(dir.path("ab.exr")), readBytes(dir.path("whole.exr")));
  auto refused = [&](const std::string& tiles, const std::string& what) {
    const auto r = runReshutter("assemble " + tiles + " -o " + dir.path("x.exr"));
    EXPECT_EQ(r.exitCode, 1) << tiles;
    EXPECT_NE(r.err.find(what), std::string::npos) << r.err;
    EXPECT_FALSE(std::filesystem::exists(dir.path("x.exr")));
  };
  refused(dir.path("a.exr") + " " + dir.path("c.exr"), "overlaps");
  refused(dir.path("a.exr") + " " + dir.path("h.exr"), "holes");
  refused(dir.path("a.exr") + " " + dir.path("s.exr"), "another render");
  refused(dir.path("a.exr") + " " + dir.path("shot.rib"), "shot.rib");
}

}  // namespace
}  // namespace reshutter
