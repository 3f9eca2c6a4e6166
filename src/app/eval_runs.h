// The runs of an `inhand eval` and how they are carried out: the eval directory's layout
// (eval.json lists every run), one run as an `inhand scan` process, and the two backends that
// run them (threads on this machine, or a Slurm job array).
#pragma once
#include <atomic>
#include <filesystem>
#include <string>
#include <vector>

#include "inhand/core/json_util.h"

namespace inhand::app {

namespace fs = std::filesystem;

// One (object, rest pose, planner, seed) scan of an eval.
struct EvalRun {
  std::string object;  // as `inhand scan --object` takes it (a file as an absolute path)
  std::string name;    // the object's short name, @N for stable pose N
  std::string planner;
  std::string rest_pose = "as-is";
  int seed = 0;
  fs::path rel;  // runs/NAME/PLANNER/seedN, relative to the eval directory

  // What the run left (loadState): its exit status when it ended, its summary when it wrote one.
  bool exited = false;
  int status = -1;
  Json summary;  // null when the run wrote none

  // Done: ended by itself (not interrupted or killed) with a summary.json.
  bool finished() const { return exited && status < 128 && summary.is_object(); }
  fs::path log() const;       // runs/NAME/PLANNER/seedN.log
  fs::path exitFile() const;  // runs/NAME/PLANNER/seedN.exit
};

// What every run is given, besides its own object, planner, seed and rest pose.
struct EvalScanOptions {
  bool config = false;  // the eval directory has config.json (a copy of --config)
  int max_grasps = -1;
  int max_views = -1;
};

// eval.json: what was asked and every run.
struct EvalPlan {
  std::string description;
  std::vector<std::string> objects;  // short names (with @N), in order
  std::vector<std::string> planners;
  int seeds = 0;
  std::string backend = "local";
  EvalScanOptions scan;
  std::vector<EvalRun> runs;
};

void writeEvalPlan(const fs::path& dir, const EvalPlan& plan);
EvalPlan readEvalPlan(const fs::path& dir);  // throws Error naming eval.json

// Reads a run's .exit and summary.json into it.
void loadState(const fs::path& dir, EvalRun* run);

// Carries out one run in the eval directory `dir` with the `inhand` executable `self`: an
// `inhand scan --resume` when the run's directory holds a checkpoint of an interrupted scan,
// else a fresh scan (whatever an earlier attempt left is removed first). Writes the log and
// the .exit file; returns the exit status (128 + signal when the scan was killed).
int executeRun(const fs::path& dir, const std::string& self, const EvalScanOptions& scan,
               const EvalRun& run);

// The absolute path of the running `inhand` executable.
std::string selfExecutable();

// Set by SIGINT/SIGTERM while a command that installed StopOnSignal runs.
class StopOnSignal {
 public:
  StopOnSignal();
  ~StopOnSignal();
  StopOnSignal(const StopOnSignal&) = delete;
  StopOnSignal& operator=(const StopOnSignal&) = delete;
  static bool raised();
};

// Runs `argv` and returns its exit status (128 + signal when killed), with stdout and stderr
// into `log` (appended to when `append`), or into `*captured` when `log` is empty.
int runProcess(const std::vector<std::string>& argv, const fs::path& log, bool append,
               std::string* captured = nullptr);

// --- Slurm ---------------------------------------------------------------------------------

struct SlurmOptions {
  std::string args;  // extra sbatch options, split at spaces ("-p gpu --time=1:00:00")
  int throttle = 0;  // tasks of an array running at once (0: as many as the cluster gives)
};

// Refuses early (before anything is written) when sbatch, squeue or scontrol are not found.
void checkSlurmTools();

// Submits `runs` (indices into the plan's runs) as job arrays (several when there are more than
// the cluster's MaxArraySize), each task `inhand eval-task DIR LIST`; records the job ids in
// DIR/slurm/jobs.json and returns them.
std::vector<std::string> submitSlurm(const fs::path& dir, const std::string& self,
                                     const std::vector<size_t>& runs, const SlurmOptions& o);

// This eval's jobs (DIR/slurm/jobs.json) that Slurm still has queued or running.
std::vector<std::string> activeSlurmJobs(const fs::path& dir);

// `inhand eval-task DIR LIST`: the Slurm array task's run (line SLURM_ARRAY_TASK_ID of LIST).
int runEvalTask(const std::string& dir, const std::string& list);

}  // namespace inhand::app
