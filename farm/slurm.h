// Slurm for a farm job (farm/job.h): the batch scripts (a job array of the job's unfinished
// tasks, and the final step as a job that depends on it with afterok), their submission through
// sbatch, waiting on squeue, and the report of what each task did (its exit status, written by
// its script, and the tail of its log). Runs Slurm's own client commands; no scheduler of its own.
#pragma once

#include <functional>
#include <string>
#include <vector>

#include "farm/job.h"

namespace reshutter::farm {

/// sbatch options passed through to both jobs.
struct SlurmOptions {
  std::string partition, time, mem;  // --partition, --time, --mem ("" = the cluster's default)
  std::vector<std::string> extra;    // any other sbatch option, e.g. "--qos=low"
  int maxRunning = 0;                // array throttle (%N); 0 = none
  std::string name = "reshutter";    // job name
  bool keepTiles = false;            // the final step keeps the tiles it assembled
};

/// Slurm's array syntax for a list of indices: "0-7", "1,3,5-9", and the throttle "%N".
std::string arraySpec(const std::vector<size_t>& indices, int maxRunning);

/// The array job's script: one array task per index of `tasks`; each runs `reshutter farm task`
/// and records its exit status in status/task.<i>.exit.
std::string taskScript(const Job& job, const std::vector<size_t>& tasks, const SlurmOptions& o);
/// The final step's script: `reshutter farm assemble`, its exit status in status/assemble.exit.
std::string assembleScript(const Job& job, const SlurmOptions& o);

struct Submission {
  std::string taskJob, assembleJob;  // Slurm job ids ("" where nothing was submitted)
};
/// Writes tasks.sh and assemble.sh into the job directory and submits them (the array, if any
/// task is left, then the final step with --dependency=afterok on it). Throws Error with sbatch's
/// own message when a submission fails.
Submission submit(const Job& job, const std::vector<size_t>& tasks, const SlurmOptions& o);

/// Waits until none of `ids` is pending or running (squeue), calling `tick` about once a second.
void waitFor(const std::vector<std::string>& ids, const std::function<void()>& tick);

/// What each task did, from the status files its script wrote.
struct TaskReport {
  size_t task;
  enum class State { Done, Failed, Waiting } state;  // Waiting: no status yet (pending, running, or killed before it could write one)
  int exitCode = 0;
  size_t framesLeft = 0;
};
std::vector<TaskReport> taskReports(const Job& job);
/// The last `lines` lines of a log file ("" when it cannot be read).
std::string logTail(const std::string& path, size_t lines);

/// Runs argv (argv[0] found on PATH) and returns its exit status, with stdout and stderr in `out`.
int runCommand(const std::vector<std::string>& argv, std::string& out);

}  // namespace reshutter::farm
