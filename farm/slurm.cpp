#include "farm/slurm.h"

#include <spawn.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cerrno>
#include <chrono>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <thread>

#include "common/atomic_file.h"
#include "common/error.h"

extern char** environ;

namespace reshutter::farm {

namespace fs = std::filesystem;

namespace {

// A word for sh: single-quoted unless it is plainly safe.
std::string shellWord(const std::string& s) {
  bool plain = !s.empty();
  for (char c : s)
    if (!(isalnum(static_cast<unsigned char>(c)) || std::string_view("/._-+=:,%@").find(c) != std::string_view::npos)) plain = false;
  if (plain) return s;
  std::string out = "'";
  for (char c : s) out += c == '\'' ? std::string("'\\''") : std::string(1, c);
  return out + "'";
}

// The #SBATCH lines both jobs share.
std::string commonDirectives(const Job& job, const SlurmOptions& o) {
  std::ostringstream s;
  s << "#SBATCH --chdir=" << shellWord(job.workdir) << "\n";
  if (!o.partition.empty()) s << "#SBATCH --partition=" << o.partition << "\n";
  if (!o.time.empty()) s << "#SBATCH --time=" << o.time << "\n";
  if (!o.mem.empty()) s << "#SBATCH --mem=" << o.mem << "\n";
  for (const auto& e : o.extra) s << "#SBATCH " << e << "\n";
  return s.str();
}

// Writes the script's exit status where `farm status` reads it (atomically: a rename);
// `statusFile` is a shell word (quoted by the caller).
std::string recordStatus(const std::string& statusFile) {
  return "rc=$?\nprintf '%s\\n' \"$rc\" > " + statusFile + ".tmp && mv -f " + statusFile + ".tmp " + statusFile + "\nexit \"$rc\"\n";
}

void writeScript(const std::string& path, const std::string& text) {
  AtomicFile f(path);
  writeAll(f.fd(), text.data(), text.size(), path);
  f.commit();
  fs::permissions(path, fs::perms::owner_exec | fs::perms::group_exec | fs::perms::others_exec, fs::perm_options::add);
}

std::string firstLine(const std::string& s) {
  std::string l = s.substr(0, s.find('\n'));
  while (!l.empty() && (l.back() == '\r' || l.back() == ' ')) l.pop_back();
  return l;
}

}  // namespace

std::string arraySpec(const std::vector<size_t>& indices, int maxRunning) {
  std::string out;
  for (size_t i = 0; i < indices.size();) {
    size_t j = i;
    while (j + 1 < indices.size() && indices[j + 1] == indices[j] + 1) ++j;
    if (!out.empty()) out += ',';
    out += std::to_string(indices[i]);
    if (j > i) out += "-" + std::to_string(indices[j]);
    i = j + 1;
  }
  if (maxRunning > 0) out += "%" + std::to_string(maxRunning);
  return out;
}

std::string taskScript(const Job& job, const std::vector<size_t>& tasks, const SlurmOptions& o) {
  std::ostringstream s;
  s << "#!/bin/sh\n";
  s << "#SBATCH --job-name=" << shellWord(o.name) << "\n";
  s << "#SBATCH --array=" << arraySpec(tasks, o.maxRunning) << "\n";
  s << "#SBATCH --output=" << shellWord(job.dir + "/logs/task.%a.log") << "\n";
  s << commonDirectives(job, o);
  s << "# reshutter farm job: " << job.command << ", " << job.frames.size() << " frames in " << job.chunks() << " chunks of " << job.chunk << ", " << job.tilesX
    << "x" << job.tilesY << " tiles: " << job.tasks() << " tasks.\n";
  s << "# Each array task renders the frames of its chunk (its tile of each) that are not done yet;\n";
  s << "# the task index is $SLURM_ARRAY_TASK_ID (job.txt maps it to frames and tile).\n";
  s << shellWord(job.reshutter) << " farm task " << shellWord(job.dir) << "\n";
  s << recordStatus(shellWord(job.dir + "/status/task.") + "\"${SLURM_ARRAY_TASK_ID}\".exit");
  return s.str();
}

std::string assembleScript(const Job& job, const SlurmOptions& o) {
  std::ostringstream s;
  s << "#!/bin/sh\n";
  s << "#SBATCH --job-name=" << shellWord(o.name + "-assemble") << "\n";
  s << "#SBATCH --output=" << shellWord(job.dir + "/logs/assemble.log") << "\n";
  s << commonDirectives(job, o);
  s << "# The final step: assembles tiles into whole frames, then reads every frame of the job.\n";
  s << shellWord(job.reshutter) << " farm assemble " << shellWord(job.dir) << (o.keepTiles ? " --keep-tiles" : "") << "\n";
  s << recordStatus(shellWord(job.dir + "/status/assemble.exit"));
  return s.str();
}

int runCommand(const std::vector<std::string>& argv, std::string& out) {
  int pipeFd[2];
  if (pipe(pipeFd) != 0) fail(argv[0], "cannot create a pipe");
  posix_spawn_file_actions_t actions;
  posix_spawn_file_actions_init(&actions);
  posix_spawn_file_actions_adddup2(&actions, pipeFd[1], 1);
  posix_spawn_file_actions_adddup2(&actions, pipeFd[1], 2);
  posix_spawn_file_actions_addclose(&actions, pipeFd[0]);
  std::vector<char*> args;
  for (const auto& a : argv) args.push_back(const_cast<char*>(a.c_str()));
  args.push_back(nullptr);
  pid_t pid = 0;
  const int err = posix_spawnp(&pid, args[0], &actions, nullptr, args.data(), environ);
  posix_spawn_file_actions_destroy(&actions);
  close(pipeFd[1]);
  if (err != 0) {
    close(pipeFd[0]);
    fail(argv[0], "cannot run: ", std::strerror(err), argv[0].find('/') == std::string::npos ? " (is Slurm's client installed and on PATH?)" : "");
  }
  out.clear();
  char buf[4096];
  ssize_t n;
  while ((n = read(pipeFd[0], buf, sizeof buf)) > 0 || (n < 0 && errno == EINTR))
    if (n > 0) out.append(buf, size_t(n));
  close(pipeFd[0]);
  int status = 0;
  while (waitpid(pid, &status, 0) < 0 && errno == EINTR) {
  }
  return WIFEXITED(status) ? WEXITSTATUS(status) : 128 + (WIFSIGNALED(status) ? WTERMSIG(status) : 0);
}

Submission submit(const Job& job, const std::vector<size_t>& tasks, const SlurmOptions& o) {
  Submission sub;
  const std::string taskPath = job.dir + "/tasks.sh", assemblePath = job.dir + "/assemble.sh";
  writeScript(assemblePath, assembleScript(job, o));
  // A resubmitted task's old status would read as this run's until it ends.
  for (size_t t : tasks) std::filesystem::remove(job.statusOf(t));
  std::filesystem::remove(job.dir + "/status/assemble.exit");
  std::string out;
  if (!tasks.empty()) {
    writeScript(taskPath, taskScript(job, tasks, o));
    if (runCommand({"sbatch", "--parsable", taskPath}, out) != 0) {
      const bool array = out.find("array") != std::string::npos;
      fail("sbatch", "the task array was not submitted: ", firstLine(out),
           array ? cat(" (its largest index is ", tasks.back(), "; Slurm's MaxArraySize, `scontrol show config`, must exceed it: raise --chunk)")
                 : std::string());
    }
    sub.taskJob = firstLine(out).substr(0, firstLine(out).find(';'));
  }
  std::vector<std::string> cmd{"sbatch", "--parsable"};
  if (!sub.taskJob.empty()) cmd.insert(cmd.end(), {"--dependency=afterok:" + sub.taskJob, "--kill-on-invalid-dep=yes"});
  cmd.push_back(assemblePath);
  if (runCommand(cmd, out) != 0) fail("sbatch", "the final step was not submitted (the task array ", sub.taskJob, " was): ", firstLine(out));
  sub.assembleJob = firstLine(out).substr(0, firstLine(out).find(';'));
  return sub;
}

void waitFor(const std::vector<std::string>& ids, const std::function<void()>& tick) {
  std::string list;
  for (const auto& id : ids)
    if (!id.empty()) list += (list.empty() ? "" : ",") + id;
  if (list.empty()) return;
  std::string out;
  while (true) {
    // squeue lists array tasks and dependent jobs until they end; a job it no longer knows
    // (ended longer ago than MinJobAge) is an error for it, which also means done.
    const int rc = runCommand({"squeue", "--noheader", "--jobs=" + list, "--format=%i"}, out);
    if (rc != 0 || firstLine(out).empty()) return;
    if (tick) tick();
    std::this_thread::sleep_for(std::chrono::milliseconds(500));
  }
}

std::vector<TaskReport> taskReports(const Job& job) {
  std::vector<TaskReport> reports;
  for (size_t i = 0; i < job.tasks(); ++i) {
    TaskReport r{i, TaskReport::State::Waiting};
    r.framesLeft = job.framesLeft(job.task(i)).size();
    std::ifstream in(job.statusOf(i));
    int code = 0;
    if (in >> code) {
      r.exitCode = code;
      r.state = code == 0 ? TaskReport::State::Done : TaskReport::State::Failed;
    } else if (r.framesLeft == 0) {
      r.state = TaskReport::State::Done;  // done by an earlier submission, or run by hand
    }
    reports.push_back(r);
  }
  return reports;
}

std::string logTail(const std::string& path, size_t lines) {
  std::ifstream in(path);
  if (!in) return "";
  std::vector<std::string> last;
  std::string l;
  while (std::getline(in, l)) {
    last.push_back(l);
    if (last.size() > lines) last.erase(last.begin());
  }
  std::string out;
  for (const auto& x : last) out += x + "\n";
  return out;
}

}  // namespace reshutter::farm
