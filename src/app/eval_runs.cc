#include "eval_runs.h"

#include <fcntl.h>
#include <signal.h>
#include <spawn.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cerrno>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <sstream>
#include <thread>

#include "inhand/core/error.h"
#include "inhand/core/file_util.h"

extern char** environ;

namespace inhand::app {

namespace {

std::string seedName(const EvalRun& r) { return "seed" + std::to_string(r.seed); }

std::string trim(const std::string& s) {
  const size_t a = s.find_first_not_of(" \t\r\n");
  if (a == std::string::npos) return "";
  return s.substr(a, s.find_last_not_of(" \t\r\n") - a + 1);
}

std::vector<std::string> splitWords(const std::string& s) {
  std::vector<std::string> out;
  std::istringstream in(s);
  std::string w;
  while (in >> w) out.push_back(w);
  return out;
}

// A word for /bin/sh, quoted.
std::string shellQuote(const std::string& s) {
  std::string q = "'";
  for (char c : s) q += c == '\'' ? std::string("'\\''") : std::string(1, c);
  return q + "'";
}

std::string findInPath(const std::string& name) {
  const char* path = std::getenv("PATH");
  std::istringstream in(path ? path : "/usr/bin:/bin");
  std::string d;
  while (std::getline(in, d, ':')) {
    if (d.empty()) continue;
    const fs::path p = fs::path(d) / name;
    if (access(p.c_str(), X_OK) == 0) return p.string();
  }
  return "";
}

std::atomic<int> g_stop{0};
extern "C" void onEvalStop(int sig) { g_stop = sig; }
struct sigaction g_oldInt {
}, g_oldTerm{};

}  // namespace

fs::path EvalRun::log() const { return rel.parent_path() / (seedName(*this) + ".log"); }
fs::path EvalRun::exitFile() const { return rel.parent_path() / (seedName(*this) + ".exit"); }

void writeEvalPlan(const fs::path& dir, const EvalPlan& plan) {
  Json runs = Json::array();
  for (const EvalRun& r : plan.runs)
    runs.push_back({{"object", r.object},
                    {"name", r.name},
                    {"planner", r.planner},
                    {"rest_pose", r.rest_pose},
                    {"seed", r.seed},
                    {"dir", r.rel.string()}});
  const Json j = {{"description", plan.description},
                  {"objects", plan.objects},
                  {"planners", plan.planners},
                  {"seeds", plan.seeds},
                  {"backend", plan.backend},
                  {"scan",
                   {{"config", plan.scan.config ? Json("config.json") : Json()},
                    {"max_grasps", plan.scan.max_grasps},
                    {"max_views", plan.scan.max_views}}},
                  {"runs", runs}};
  writeTextAtomically(dir / "eval.json", j.dump(1) + "\n");
}

EvalPlan readEvalPlan(const fs::path& dir) {
  const fs::path file = dir / "eval.json";
  if (!fs::exists(file))
    throw Error(dir.string() + ": no eval.json (not an `inhand eval` directory)");
  const Json j = readJsonFile(file);
  EvalPlan p;
  try {
    p.description = j.at("description").get<std::string>();
    p.objects = j.at("objects").get<std::vector<std::string>>();
    p.planners = j.at("planners").get<std::vector<std::string>>();
    p.seeds = j.at("seeds").get<int>();
    p.backend = j.value("backend", std::string("local"));
    if (j.contains("scan")) {
      const Json& s = j["scan"];
      p.scan.config = s.value("config", Json()).is_string();
      p.scan.max_grasps = s.value("max_grasps", -1);
      p.scan.max_views = s.value("max_views", -1);
    }
    if (j.contains("runs")) {
      for (const Json& r : j["runs"]) {
        EvalRun run;
        run.object = r.at("object").get<std::string>();
        run.name = r.at("name").get<std::string>();
        run.planner = r.at("planner").get<std::string>();
        run.rest_pose = r.at("rest_pose").get<std::string>();
        run.seed = r.at("seed").get<int>();
        run.rel = r.at("dir").get<std::string>();
        if (run.rel.is_absolute() || run.rel.lexically_normal().string().rfind("runs/", 0) != 0)
          throw Error(file.string() + ": a run's dir must lie under runs/");
        p.runs.push_back(run);
      }
    } else {
      // An eval written before eval.json listed its runs: objects × planners × seeds.
      for (const std::string& o : p.objects)
        for (const std::string& pl : p.planners)
          for (int s = 1; s <= p.seeds; ++s) {
            EvalRun run;
            run.object = run.name = o;
            run.planner = pl;
            run.seed = s;
            run.rel = fs::path("runs") / o / pl / ("seed" + std::to_string(s));
            p.runs.push_back(run);
          }
    }
  } catch (const Json::exception& e) {
    throw Error(file.string() + ": " + e.what());
  }
  return p;
}

void loadState(const fs::path& dir, EvalRun* run) {
  run->exited = false;
  run->status = -1;
  run->summary = nullptr;
  const fs::path exitFile = dir / run->exitFile();
  if (fs::exists(exitFile)) {
    const std::string t = trim(readTextFile(exitFile));
    char* end = nullptr;
    const long v = std::strtol(t.c_str(), &end, 10);
    if (!t.empty() && *end == '\0') {
      run->exited = true;
      run->status = int(v);
    }
  }
  const fs::path sj = dir / run->rel / "summary.json";
  if (fs::exists(sj)) {
    try {
      run->summary = readJsonFile(sj);
    } catch (const Error&) {
      run->summary = nullptr;
    }
  }
}

int executeRun(const fs::path& dir, const std::string& self, const EvalScanOptions& scan,
               const EvalRun& run) {
  const fs::path out = dir / run.rel;
  std::error_code ec;
  fs::remove(dir / run.exitFile(), ec);
  const bool resume = fs::exists(out / "checkpoint.inhand");
  // A killed scan's staging directories (.seedN.partial.*, .seedN.old.*) go.
  const std::string prefix = "." + seedName(run) + ".";
  std::vector<fs::path> stale;
  for (const auto& e : fs::directory_iterator(out.parent_path(), ec))
    if (e.path().filename().string().rfind(prefix, 0) == 0) stale.push_back(e.path());
  for (const fs::path& p : stale) fs::remove_all(p, ec);
  std::vector<std::string> argv;
  if (resume) {
    argv = {self, "scan", "--resume", out.string()};
  } else {
    // What an earlier attempt left without a checkpoint goes too.
    fs::remove_all(out, ec);
    fs::create_directories(out.parent_path(), ec);
    argv = {self,          "scan",       "--object",  run.object, "--out",
            out.string(),  "--planner",  run.planner, "--seed",   std::to_string(run.seed),
            "--rest-pose", run.rest_pose};
    if (scan.config) argv.insert(argv.end(), {"--config", (dir / "config.json").string()});
    if (scan.max_grasps >= 0)
      argv.insert(argv.end(), {"--max-grasps", std::to_string(scan.max_grasps)});
    if (scan.max_views >= 0)
      argv.insert(argv.end(), {"--max-views", std::to_string(scan.max_views)});
  }
  const int status = runProcess(argv, dir / run.log(), /*append=*/resume);
  writeTextAtomically(dir / run.exitFile(), std::to_string(status) + "\n");
  return status;
}

std::string selfExecutable() {
  char self[4096];
  const ssize_t len = readlink("/proc/self/exe", self, sizeof(self) - 1);
  if (len <= 0) throw Error("cannot find the inhand executable (/proc/self/exe)");
  self[len] = 0;
  return self;
}

StopOnSignal::StopOnSignal() {
  g_stop = 0;
  struct sigaction a {};
  a.sa_handler = onEvalStop;
  a.sa_flags = SA_RESETHAND;  // a second signal: the default action
  sigemptyset(&a.sa_mask);
  sigaction(SIGINT, &a, &g_oldInt);
  sigaction(SIGTERM, &a, &g_oldTerm);
}
StopOnSignal::~StopOnSignal() {
  sigaction(SIGINT, &g_oldInt, nullptr);
  sigaction(SIGTERM, &g_oldTerm, nullptr);
}
bool StopOnSignal::raised() { return g_stop != 0; }

int runProcess(const std::vector<std::string>& argv, const fs::path& log, bool append,
               std::string* captured) {
  int pipefd[2] = {-1, -1};
  posix_spawn_file_actions_t fa;
  posix_spawn_file_actions_init(&fa);
  if (log.empty()) {
    if (pipe2(pipefd, O_CLOEXEC) != 0) throw Error("cannot create a pipe");
    posix_spawn_file_actions_adddup2(&fa, pipefd[1], 1);
  } else {
    posix_spawn_file_actions_addopen(&fa, 1, log.c_str(),
                                     O_WRONLY | O_CREAT | (append ? O_APPEND : O_TRUNC), 0644);
  }
  posix_spawn_file_actions_adddup2(&fa, 1, 2);
  // The child starts with the default actions for the stop signals, whatever this process does
  // with them (the scan installs its own: it checkpoints).
  posix_spawnattr_t attr;
  posix_spawnattr_init(&attr);
  sigset_t def;
  sigemptyset(&def);
  sigaddset(&def, SIGINT);
  sigaddset(&def, SIGTERM);
  posix_spawnattr_setsigdefault(&attr, &def);
  posix_spawnattr_setflags(&attr, POSIX_SPAWN_SETSIGDEF);
  std::vector<char*> args;
  for (const std::string& a : argv) args.push_back(const_cast<char*>(a.c_str()));
  args.push_back(nullptr);
  pid_t pid = 0;
  const int rc = posix_spawn(&pid, argv[0].c_str(), &fa, &attr, args.data(), environ);
  posix_spawn_file_actions_destroy(&fa);
  posix_spawnattr_destroy(&attr);
  if (pipefd[1] >= 0) close(pipefd[1]);
  if (rc != 0) {
    if (pipefd[0] >= 0) close(pipefd[0]);
    throw Error("cannot start " + argv[0] + ": " + std::strerror(rc));
  }
  if (pipefd[0] >= 0) {
    char buf[4096];
    for (;;) {
      const ssize_t n = read(pipefd[0], buf, sizeof buf);
      if (n > 0) {
        if (captured) captured->append(buf, size_t(n));
      } else if (n == 0 || errno != EINTR) {
        break;
      }
    }
    close(pipefd[0]);
  }
  int st = 0;
  while (waitpid(pid, &st, 0) < 0)
    if (errno != EINTR) throw Error("waitpid failed");
  if (WIFEXITED(st)) return WEXITSTATUS(st);
  return 128 + (WIFSIGNALED(st) ? WTERMSIG(st) : 0);
}

// --- Slurm ---------------------------------------------------------------------------------

void checkSlurmTools() {
  for (const char* tool : {"sbatch", "squeue", "scontrol"})
    if (findInPath(tool).empty())
      throw Error(std::string("--backend slurm: ") + tool +
                  " not found on PATH (install Slurm's client tools: Debian's slurm-client; for "
                  "a cluster on this machine, scripts/slurm-local.sh)");
}

namespace {

// The cluster's MaxArraySize (task ids run 0..MaxArraySize-1); Slurm's default when unknown.
size_t maxArraySize() {
  std::string out;
  if (runProcess({findInPath("scontrol"), "show", "config"}, {}, false, &out) == 0) {
    std::istringstream in(out);
    std::string line;
    while (std::getline(in, line)) {
      if (line.rfind("MaxArraySize", 0) != 0) continue;
      const size_t eq = line.find('=');
      if (eq == std::string::npos) break;
      const long v = std::strtol(line.c_str() + eq + 1, nullptr, 10);
      if (v >= 1) return size_t(v);
    }
  }
  return 1001;
}

Json readJobs(const fs::path& dir) {
  const fs::path f = dir / "slurm" / "jobs.json";
  if (!fs::exists(f)) return Json::array();
  const Json j = readJsonFile(f);
  if (!j.is_array()) throw Error(f.string() + ": expected an array of jobs");
  return j;
}

}  // namespace

std::vector<std::string> submitSlurm(const fs::path& dir, const std::string& self,
                                     const std::vector<size_t>& runs, const SlurmOptions& o) {
  const fs::path sd = fs::absolute(dir / "slurm");
  fs::create_directories(sd);
  // The task script: one line, the same `inhand` at the same path on every node.
  const fs::path script = sd / "task.sh";
  writeTextAtomically(script,
                      "#!/bin/sh\n"
                      "# An `inhand eval` run as a Slurm array task: the run on line "
                      "$SLURM_ARRAY_TASK_ID of the list file $1.\n"
                      "exec " +
                          shellQuote(self) + " eval-task " +
                          shellQuote(fs::absolute(dir).string()) + " \"$1\"\n");
  fs::permissions(script, fs::perms::owner_all | fs::perms::group_read | fs::perms::others_read);
  const size_t chunk = maxArraySize();
  Json jobs = readJobs(dir);
  const std::string sbatch = findInPath("sbatch");
  std::vector<std::string> ids;
  for (size_t begin = 0; begin < runs.size(); begin += chunk) {
    const size_t end = std::min(runs.size(), begin + chunk);
    const fs::path list = sd / ("tasks-" + std::to_string(jobs.size()) + ".txt");
    std::string lines;
    for (size_t i = begin; i < end; ++i) lines += std::to_string(runs[i]) + "\n";
    writeTextAtomically(list, lines);
    std::string array = "--array=0-" + std::to_string(end - begin - 1);
    if (o.throttle > 0) array += "%" + std::to_string(o.throttle);
    std::vector<std::string> argv{sbatch, "--parsable", "--job-name=inhand-eval", array,
                                  "--output=" + (sd / "%A_%a.out").string()};
    for (const std::string& w : splitWords(o.args)) argv.push_back(w);
    argv.push_back(script.string());
    argv.push_back(list.string());
    std::string out;
    const int st = runProcess(argv, {}, false, &out);
    // --parsable prints "ID" or "ID;CLUSTER".
    std::string id = trim(out.substr(0, out.find(';')));
    if (st != 0 || id.empty() || id.find_first_not_of("0123456789") != std::string::npos) {
      fs::remove(list);
      throw Error("sbatch failed (exit " + std::to_string(st) + "): " + trim(out));
    }
    jobs.push_back({{"id", id}, {"list", list.filename().string()}, {"tasks", end - begin}});
    writeTextAtomically(sd / "jobs.json", jobs.dump(1) + "\n");
    ids.push_back(id);
  }
  return ids;
}

std::vector<std::string> activeSlurmJobs(const fs::path& dir) {
  std::vector<std::string> active;
  const Json jobs = readJobs(dir);
  if (jobs.empty()) return active;
  const std::string squeue = findInPath("squeue");
  if (squeue.empty())
    throw Error(dir.string() + ": the eval has Slurm jobs and squeue is not found on PATH");
  for (const Json& j : jobs) {
    const std::string id = j.value("id", std::string());
    // squeue lists a job while it is pending or running; a job that ended is listed no more, or
    // is unknown once Slurm has forgotten it.
    std::string out;
    int st = -1;
    for (int attempt = 0; attempt < 10; ++attempt) {
      out.clear();
      st = runProcess({squeue, "-h", "-j", id, "-o", "%i"}, {}, false, &out);
      if (st == 0 || out.find("Invalid job id") != std::string::npos) break;
      std::this_thread::sleep_for(std::chrono::seconds(1));
    }
    if (st != 0 && out.find("Invalid job id") == std::string::npos)
      throw Error("squeue failed for job " + id + ": " + trim(out));
    if (st == 0 && !trim(out).empty()) active.push_back(id);
  }
  return active;
}

int runEvalTask(const std::string& dirArg, const std::string& listArg) {
  const char* task = std::getenv("SLURM_ARRAY_TASK_ID");
  if (!task)
    throw Error("eval-task: SLURM_ARRAY_TASK_ID is not set (a Slurm array task runs this)");
  const fs::path dir = dirArg;
  const EvalPlan plan = readEvalPlan(dir);
  std::vector<size_t> indices;
  {
    std::istringstream in(readTextFile(listArg));
    std::string line;
    while (std::getline(in, line))
      if (!trim(line).empty()) indices.push_back(std::stoul(trim(line)));
  }
  char* end = nullptr;
  const unsigned long k = std::strtoul(task, &end, 10);
  if (*end != '\0' || k >= indices.size() || indices[k] >= plan.runs.size())
    throw Error("eval-task: task " + std::string(task) + " has no run in " + listArg);
  // The scan uses the CPUs Slurm gave the task.
  if (!std::getenv("INHAND_THREADS"))
    if (const char* cpus = std::getenv("SLURM_CPUS_PER_TASK")) setenv("INHAND_THREADS", cpus, 1);
  // A cancelled task's scan gets SIGTERM and writes its checkpoint; this process waits for it
  // and records its exit status (130) rather than dying first.
  signal(SIGTERM, SIG_IGN);
  signal(SIGINT, SIG_IGN);
  const EvalRun& run = plan.runs[indices[k]];
  std::fprintf(stderr, "eval-task: %s %s seed %d -> %s\n", run.name.c_str(), run.planner.c_str(),
               run.seed, (dir / run.rel).c_str());
  const int status = executeRun(dir, selfExecutable(), plan.scan, run);
  std::fprintf(stderr, "eval-task: exit %d\n", status);
  return status;
}

}  // namespace inhand::app
