// `inhand eval`: every (object, rest pose, planner, seed) scan, each in its own `inhand scan`
// process (a run that fails cannot take the others down), on this machine `jobs` at a time or as
// a Slurm job array, then one table of the results; `inhand report` and `inhand eval --resume`.

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <map>
#include <mutex>
#include <sstream>
#include <thread>

#include "commands.h"
#include "eval_runs.h"
#include "inhand/core/error.h"
#include "inhand/core/file_util.h"
#include "inhand/core/json_util.h"
#include "inhand/geometry/builtin_objects.h"
#include "inhand/geometry/stable_poses.h"
#include "inhand/planning/view_selection.h"
#include "inhand/report/html_report.h"

namespace inhand::app {

namespace fs = std::filesystem;

namespace {

std::vector<std::string> splitList(const std::string& s) {
  std::vector<std::string> out;
  std::stringstream ss(s);
  std::string item;
  while (std::getline(ss, item, ','))
    if (!item.empty()) out.push_back(item);
  return out;
}

// A short name for an object spec: builtin:NAME → NAME, a file → its stem.
std::string objectName(const std::string& spec) {
  if (spec.rfind("builtin:", 0) == 0) return spec.substr(8);
  return fs::path(spec).stem().string();
}

// Views (1-based, initial views included) and cumulative trajectory seconds until coverage first
// reaches `level`; NaN when it never does.
std::pair<double, double> firstReaching(const Json& views, double level) {
  for (size_t i = 0; i < views.size(); ++i)
    if (views[i].value("coverage", -1.0) >= level)
      return {double(i + 1), views[i].value("trajectory_s", 0.0)};
  return {NAN, NAN};
}

// Coverage after `n` views (a run that ended earlier keeps its last coverage); NaN without views.
double coverageAfter(const Json& views, size_t n) {
  if (views.empty()) return NAN;
  return views[std::min(n, views.size()) - 1].value("coverage", NAN);
}

struct Stat {
  std::vector<double> v;
  int total = 0;  // runs, reached or not
  void add(double x) {
    ++total;
    if (std::isfinite(x)) v.push_back(x);
  }
  std::string str(int decimals) const {
    if (v.empty()) return total ? "– (0/" + std::to_string(total) + ")" : "–";
    double m = 0;
    for (double x : v) m += x;
    m /= double(v.size());
    double sd = 0;
    for (double x : v) sd += (x - m) * (x - m);
    sd = v.size() > 1 ? std::sqrt(sd / double(v.size() - 1)) : 0;
    char b[96];
    std::snprintf(b, sizeof b, "%.*f ± %.*f", decimals, m, decimals, sd);
    std::string s = b;
    if (int(v.size()) < total)
      s += " (" + std::to_string(v.size()) + "/" + std::to_string(total) + ")";
    return s;
  }
};

std::string csvField(const std::string& s) {
  if (s.find_first_of(",\"\n") == std::string::npos) return s;
  std::string q = "\"";
  for (char c : s) q += c == '"' ? std::string("\"\"") : std::string(1, c);
  return q + "\"";
}

std::string num(double x) {
  if (!std::isfinite(x)) return "";
  char b[32];
  std::snprintf(b, sizeof b, "%.6g", x);
  return b;
}

// One run's row of results.csv and its views' rows of curves.csv and entry of curves.json.
void addRunRows(const EvalRun& r, const std::vector<double>& levels, std::ostringstream& csv,
                std::ostringstream& curves, Json& curvesJson) {
  csv << csvField(r.name) << "," << r.planner << "," << r.seed << "," << r.status << ",";
  if (!r.summary.is_object()) {
    csv << (r.exited ? "error" : "missing") << std::string(23, ',') << "\n";
    return;
  }
  const Json& s = r.summary;
  const Json& views = s["views"];
  auto fs = [&](const char* k) {
    return s.contains("fscore") && s["fscore"].contains(k) ? s["fscore"][k].value("f", NAN) : NAN;
  };
  const Json& t = s["timing_s"];
  csv << s.value("termination", std::string()) << "," << views.size() << "," << s["grasps"].size()
      << "," << num(s.value("coverage", NAN)) << "," << num(s["accuracy_mm"].value("mean", NAN))
      << "," << num(s["accuracy_mm"].value("rms", NAN)) << ","
      << num(s["accuracy_mm"].value("p95", NAN)) << "," << num(fs("2mm")) << "," << num(fs("5mm"))
      << "," << num(fs("10mm")) << "," << num(s.value("mean_entropy", NAN)) << ","
      << num(s.value("observed_fraction", NAN)) << "," << num(s.value("trajectory_s", NAN)) << ","
      << num(t.value("planning", NAN)) << "," << num(t.value("grasp_ranking", NAN)) << ","
      << num(t.value("total", NAN));
  for (double l : levels) csv << "," << num(firstReaching(views, l).first);
  for (double l : levels) csv << "," << num(firstReaching(views, l).second);
  csv << "," << s.value("view_evaluations", 0) << "," << num(s.value("detached_area_m2", NAN))
      << "\n";
  Json c = {{"object", r.name},
            {"planner", r.planner},
            {"seed", r.seed},
            {"report", (r.rel / "report.html").string()}};
  Json cov = Json::array(), ent = Json::array(), traj = Json::array();
  for (size_t i = 0; i < views.size(); ++i) {
    const Json& v = views[i];
    curves << csvField(r.name) << "," << r.planner << "," << r.seed << "," << i + 1 << ","
           << v.value("grasp", 1) << "," << (v.value("initial", false) ? 1 : 0) << ","
           << num(v.value("coverage", NAN)) << "," << num(v.value("mean_entropy", NAN)) << ","
           << num(v.value("trajectory_s", NAN)) << "," << num(v.value("quality", NAN)) << ","
           << num(v.value("cost_s", NAN)) << "\n";
    cov.push_back(v.value("coverage", -1.0));
    ent.push_back(v.value("mean_entropy", 0.0));
    traj.push_back(v.value("trajectory_s", 0.0));
  }
  c["coverage"] = cov;
  c["mean_entropy"] = ent;
  c["trajectory_s"] = traj;
  curvesJson.push_back(c);
}

// results.md's per-object table (mean ± sample standard deviation over the seeds); `overall`
// gathers, per planner: final coverage, coverage after 5 / 7 / 10 views, views to 90%, runs
// reaching 90%, views.
std::string perObjectTable(const std::vector<EvalRun>& runs,
                           const std::vector<std::string>& objects,
                           const std::vector<std::string>& planners,
                           std::map<std::string, std::array<Stat, 7>>* overall) {
  std::ostringstream md;
  md << "| object | planner | views to 90% | views to 95% | views to 99% | trajectory s to 90% | "
        "trajectory s to 95% | trajectory s to 99% | final coverage % | accuracy mean mm | grasps "
        "| "
        "views | planning s |\n"
        "|---|---|---|---|---|---|---|---|---|---|---|---|---|\n";
  for (const std::string& o : objects)
    for (const std::string& p : planners) {
      Stat v90, v95, v99, t90, t95, t99, cov, acc, gr, nv, plan;
      for (const EvalRun& r : runs) {
        if (r.name != o || r.planner != p) continue;
        if (!r.summary.is_object()) {
          for (Stat* st : {&v90, &v95, &v99, &t90, &t95, &t99, &cov, &acc, &gr, &nv, &plan})
            st->add(NAN);
          continue;
        }
        const Json& s = r.summary;
        v90.add(firstReaching(s["views"], 0.90).first);
        v95.add(firstReaching(s["views"], 0.95).first);
        v99.add(firstReaching(s["views"], 0.99).first);
        t90.add(firstReaching(s["views"], 0.90).second);
        t95.add(firstReaching(s["views"], 0.95).second);
        t99.add(firstReaching(s["views"], 0.99).second);
        cov.add(100 * s.value("coverage", NAN));
        acc.add(s["accuracy_mm"].value("mean", NAN));
        gr.add(double(s["grasps"].size()));
        nv.add(double(s["views"].size()));
        plan.add(s["timing_s"].value("planning", NAN) + s["timing_s"].value("grasp_ranking", 0.0));
        auto& ov = (*overall)[p];
        ov[0].add(100 * s.value("coverage", NAN));
        for (int k = 0; k < 3; ++k)
          ov[1 + k].add(100 * coverageAfter(s["views"], 5 + 2 * k + (k == 2)));
        ov[4].add(firstReaching(s["views"], 0.90).first);
        ov[5].add(std::isfinite(firstReaching(s["views"], 0.90).first) ? 1.0 : 0.0);
        ov[6].add(double(s["views"].size()));
      }
      md << "| " << o << " | " << p << " | " << v90.str(1) << " | " << v95.str(1) << " | "
         << v99.str(1) << " | " << t90.str(1) << " | " << t95.str(1) << " | " << t99.str(1) << " | "
         << cov.str(1) << " | " << acc.str(2) << " | " << gr.str(1) << " | " << nv.str(1) << " | "
         << plan.str(1) << " |\n";
    }
  return md.str();
}

// results.csv, results.md, curves.csv and curves.json in `dir` from the runs.
void tabulate(const fs::path& dir, const std::vector<EvalRun>& runs,
              const std::vector<std::string>& objects, const std::vector<std::string>& planners,
              const std::string& description) {
  // results.csv: one row per run.
  const std::vector<double> levels{0.90, 0.95, 0.99};
  std::ostringstream csv;
  csv << "object,planner,seed,exit_status,termination,views,grasps,coverage,accuracy_mean_mm,"
         "accuracy_rms_mm,accuracy_p95_mm,fscore_2mm,fscore_5mm,fscore_10mm,mean_entropy,"
         "observed_fraction,trajectory_s,planning_s,grasp_ranking_s,total_s,views_to_90,"
         "views_to_95,views_to_99,trajectory_s_to_90,trajectory_s_to_95,trajectory_s_to_99,"
         "view_evaluations,detached_area_m2\n";
  std::ostringstream curves;
  curves << "object,planner,seed,view,grasp,initial,coverage,mean_entropy,trajectory_s,quality,"
            "cost_s\n";
  Json curvesJson = Json::array();
  for (const EvalRun& r : runs) addRunRows(r, levels, csv, curves, curvesJson);

  // results.md: per object and planner, mean ± sample standard deviation over the seeds.
  std::map<std::string, std::array<Stat, 7>> overall;
  const std::string perObject = perObjectTable(runs, objects, planners, &overall);
  std::ostringstream head;
  head
      << "# inhand eval\n\n"
      << description
      << ".\nViews count the initial trajectory's views too; \"(k/n)\": only k of n runs reached "
         "the level (the mean is over those); coverage after n views carries a run's last coverage "
         "forward when it stopped earlier.\n\n## Over all objects\n\n"
         "| planner | final coverage % | coverage % after 5 views | after 7 | after 10 | views to "
         "90% | share of runs reaching 90% | views |\n"
         "|---|---|---|---|---|---|---|---|\n";
  for (const std::string& p : planners) {
    auto& ov = overall[p];
    head << "| " << p << " | " << ov[0].str(1) << " | " << ov[1].str(1) << " | " << ov[2].str(1)
         << " | " << ov[3].str(1) << " | " << ov[4].str(1) << " | " << ov[5].str(2) << " | "
         << ov[6].str(1) << " |\n";
  }
  head << "\n## Per object\n\n";
  writeTextAtomically(dir / "results.csv", csv.str());
  writeTextAtomically(dir / "curves.csv", curves.str());
  writeTextAtomically(dir / "curves.json", curvesJson.dump(1) + "\n");
  writeTextAtomically(dir / "results.md", head.str() + perObject);
}

}  // namespace

namespace {

std::string runTitle(const EvalRun& r) {
  return r.name + " " + r.planner + " seed " + std::to_string(r.seed);
}

// One line when a run ends.
void printRunEnd(size_t k, size_t n, const EvalRun& r, double wall_s) {
  char took[32] = "";
  if (wall_s >= 0) std::snprintf(took, sizeof took, " (%.0f s)", wall_s);
  if (r.finished())
    std::fprintf(stderr, "eval: [%zu/%zu] %s: coverage %.1f%%, %zu views, %s%s\n", k, n,
                 runTitle(r).c_str(), 100 * r.summary.value("coverage", 0.0),
                 r.summary["views"].size(),
                 r.summary.value("termination", std::string("?")).c_str(), took);
  else
    std::fprintf(stderr, "eval: [%zu/%zu] %s: %s (exit %d, see %s)%s\n", k, n, runTitle(r).c_str(),
                 r.status == 130 ? "interrupted" : "FAILED", r.status, r.log().c_str(), took);
}

// Why a run has no result, in words.
std::string unfinishedReason(const fs::path& dir, const EvalRun& r) {
  if (!r.exited && !r.summary.is_object() && !fs::exists(dir / r.log())) return "not started";
  if (!r.exited)
    return "no exit status: it did not end (a task killed or cancelled, or still running); "
           "see " +
           r.log().string();
  if (r.status == 130) return "interrupted (exit 130); it goes on from its checkpoint";
  if (r.status > 128) return "killed by signal " + std::to_string(r.status - 128);
  return "failed (exit " + std::to_string(r.status) + "); see " + r.log().string();
}

// Lists the runs that did not finish; returns how many.
int listUnfinished(const std::vector<EvalRun>& runs, const std::string& dir) {
  int n = 0;
  for (const EvalRun& r : runs) n += !r.finished();
  if (n == 0) return 0;
  std::fprintf(stderr, "eval: %d of %zu runs did not finish:\n", n, runs.size());
  for (const EvalRun& r : runs)
    if (!r.finished())
      std::fprintf(stderr, "  %s: %s\n", runTitle(r).c_str(), unfinishedReason(dir, r).c_str());
  std::fprintf(stderr, "eval: run them again with: inhand eval --resume %s\n", dir.c_str());
  return n;
}

// The eval's last words: what did not finish, the count, the exit status (130 when a stop
// signal cut it short, 5 when a run did not finish).
int endOfEval(const EvalPlan& plan, const std::string& dir, bool complete) {
  const int failed = listUnfinished(plan.runs, dir);
  std::printf("eval: %zu runs (%d did not finish) -> %s/results.md\n", plan.runs.size(), failed,
              dir.c_str());
  return !complete ? 130 : failed ? 5 : 0;
}

void writeTables(const fs::path& dir, const EvalPlan& plan) {
  tabulate(dir, plan.runs, plan.objects, plan.planners, plan.description);
  try {
    writeEvalIndex(dir, webDirectory());
  } catch (const Error& e) {
    std::fprintf(stderr, "eval: warning: no index.html: %s\n", e.what());
  }
}

// The runs of `todo` on this machine, `jobs` at a time. A stop signal (Ctrl-C) lets the runs
// under way end (each scan takes the signal too and writes its checkpoint) and starts no more;
// returns false then.
bool runLocally(const fs::path& dir, EvalPlan* plan, const std::vector<size_t>& todo, int jobs) {
  const std::string self = selfExecutable();
  StopOnSignal stop;
  std::atomic<size_t> next{0}, done{0};
  std::mutex printLock;
  auto worker = [&] {
    for (size_t i = next++; i < todo.size() && !StopOnSignal::raised(); i = next++) {
      EvalRun& r = plan->runs[todo[i]];
      const auto ts = std::chrono::steady_clock::now();
      executeRun(dir, self, plan->scan, r);
      loadState(dir, &r);
      const double wall =
          std::chrono::duration<double>(std::chrono::steady_clock::now() - ts).count();
      std::lock_guard<std::mutex> lock(printLock);
      printRunEnd(++done, todo.size(), r, wall);
    }
  };
  std::vector<std::thread> pool;
  for (int j = 1; j < std::min<int>(jobs, int(todo.size())); ++j) pool.emplace_back(worker);
  worker();
  for (auto& t : pool) t.join();
  return !StopOnSignal::raised();
}

// Waits until Slurm has none of the eval's jobs, printing each run of `todo` as it ends. A stop
// signal ends the wait (the jobs go on); returns false then.
bool waitForSlurm(const fs::path& dir, EvalPlan* plan, const std::vector<size_t>& todo) {
  StopOnSignal stop;
  std::vector<bool> seen(todo.size(), false);
  size_t done = 0;
  auto lastNews = std::chrono::steady_clock::now();
  for (;;) {
    const std::vector<std::string> jobs = activeSlurmJobs(dir);
    const bool active = !jobs.empty();
    // A line a minute while nothing ends (jobs pending behind others, or a node that is down).
    if (std::chrono::steady_clock::now() - lastNews > std::chrono::seconds(60) && active) {
      std::string ids;
      for (const std::string& id : jobs) ids += (ids.empty() ? "" : ",") + id;
      std::fprintf(stderr, "eval: waiting for Slurm: %zu of %zu runs ended (squeue -j %s)\n", done,
                   todo.size(), ids.c_str());
      lastNews = std::chrono::steady_clock::now();
    }
    for (size_t i = 0; i < todo.size(); ++i) {
      EvalRun& r = plan->runs[todo[i]];
      if (seen[i] || !fs::exists(dir / r.exitFile())) continue;
      loadState(dir, &r);
      if (!r.exited) continue;
      seen[i] = true;
      printRunEnd(++done, todo.size(), r, -1);
      lastNews = std::chrono::steady_clock::now();
    }
    if (!active) return true;
    for (int k = 0; k < 20; ++k) {
      if (StopOnSignal::raised()) {
        std::fprintf(stderr,
                     "eval: stopped waiting; the Slurm jobs go on. When they end: inhand report "
                     "%s\n",
                     dir.c_str());
        return false;
      }
      std::this_thread::sleep_for(std::chrono::milliseconds(100));
    }
  }
}

int threadsForJobs(int jobs) {
  return jobs > 0 ? jobs : std::max(1u, std::thread::hardware_concurrency());
}

// Submits `todo` to Slurm, then waits and tabulates (or, with --no-wait, says how to go on).
int slurmRunsThenTables(const EvalArgs& args, const fs::path& dir, EvalPlan* plan,
                        const std::vector<size_t>& todo) {
  SlurmOptions so;
  so.args = args.slurm_args;
  so.throttle = args.jobs;
  const std::vector<std::string> ids = submitSlurm(dir, selfExecutable(), todo, so);
  std::string idList;
  for (const std::string& id : ids) idList += (idList.empty() ? "" : ", ") + id;
  std::fprintf(stderr, "eval: submitted %zu runs to Slurm as job array %s (logs in %s/slurm)\n",
               todo.size(), idList.c_str(), dir.c_str());
  if (args.no_wait) {
    std::printf(
        "eval: submitted; when the jobs end (squeue -j %s): inhand report %s; runs that did not "
        "finish: inhand eval --resume %s\n",
        idList.c_str(), dir.c_str(), dir.c_str());
    return 0;
  }
  const bool waited = waitForSlurm(dir, plan, todo);
  for (EvalRun& r : plan->runs) loadState(dir, &r);
  writeTables(dir, *plan);
  if (!waited) return 130;
  return endOfEval(*plan, dir.string(), true);
}

// `inhand eval --resume DIR`: the runs that did not finish, again.
int resumeEval(const EvalArgs& args) {
  const fs::path dir = args.resume;
  if (!fs::is_directory(dir)) throw Error(args.resume + ": not a directory");
  EvalPlan plan = readEvalPlan(dir);
  const std::string backend = args.backend_given ? args.backend : plan.backend;
  if (backend == "slurm") checkSlurmTools();
  if (fs::exists(dir / "slurm" / "jobs.json")) {
    const std::vector<std::string> active = activeSlurmJobs(dir);
    if (!active.empty()) {
      std::string ids;
      for (const std::string& id : active) ids += (ids.empty() ? "" : ", ") + id;
      throw Error(args.resume + ": Slurm job " + ids +
                  " of this eval is still queued or running; wait for it (squeue) or cancel it "
                  "(scancel) first");
    }
  }
  std::vector<size_t> todo;
  int fromCheckpoint = 0;
  for (size_t i = 0; i < plan.runs.size(); ++i) {
    loadState(dir, &plan.runs[i]);
    if (plan.runs[i].finished()) continue;
    todo.push_back(i);
    fromCheckpoint += fs::exists(dir / plan.runs[i].rel / "checkpoint.inhand");
  }
  if (todo.empty()) {
    writeTables(dir, plan);
    std::printf("eval: every run of %s has finished; tables rebuilt -> %s/results.md\n",
                dir.c_str(), dir.c_str());
    return 0;
  }
  std::fprintf(stderr, "eval: %zu of %zu runs again (%d from their checkpoints), %s\n", todo.size(),
               plan.runs.size(), fromCheckpoint,
               backend == "slurm" ? "as a Slurm job array" : "on this machine");
  // The exit statuses of the earlier attempts go: a run is shown as it ends again.
  for (size_t i : todo) {
    std::error_code ec;
    fs::remove(dir / plan.runs[i].exitFile(), ec);
    plan.runs[i].exited = false;
  }
  if (backend != plan.backend) {
    plan.backend = backend;
    writeEvalPlan(dir, plan);
  }
  if (backend == "slurm") return slurmRunsThenTables(args, dir, &plan, todo);
  const bool complete = runLocally(dir, &plan, todo, threadsForJobs(args.jobs));
  writeTables(dir, plan);
  return endOfEval(plan, dir.string(), complete);
}

}  // namespace

namespace {

// The largest stable pose index of --rest-poses (-1: as-is only); each entry checked.
int largestRestPose(const std::vector<std::string>& restPoses) {
  int maxPose = -1;
  for (const std::string& rp : restPoses) {
    if (rp == "as-is") continue;
    char* end = nullptr;
    const long n = std::strtol(rp.c_str(), &end, 10);
    if (rp.empty() || *end != '\0' || n < 0 || n > 1000)
      throw Error("--rest-poses: \"" + rp + "\" is neither as-is nor a stable pose's index");
    maxPose = std::max(maxPose, int(n));
  }
  return maxPose;
}

// Every object loads, their short names are unique, and each has the stable poses asked for;
// else an error naming the object.
void checkObjects(const std::vector<std::string>& objects, int maxPose) {
  std::map<std::string, std::string> names;  // short name → spec (must be unique)
  for (const std::string& o : objects) {
    const TriangleMesh mesh = loadObject(o);  // fails here, naming the object, before any scan
    const std::string n = objectName(o);
    if (names.count(n) && names[n] != o)
      throw Error("--objects: two objects share the name \"" + n + "\"");
    names[n] = o;
    if (maxPose >= 0) {
      size_t count = 0;
      try {
        count = stablePoses(mesh).size();
      } catch (const Error& e) {
        throw Error("--rest-poses: " + o + ": " + e.what());
      }
      if (size_t(maxPose) >= count)
        throw Error("--rest-poses: " + o + " has " + std::to_string(count) + " stable poses (0.." +
                    std::to_string(count - 1) + "), not " + std::to_string(maxPose));
    }
  }
}

// The eval's runs (objects × rest poses × planners × seeds) and its description.
EvalPlan evalPlan(const EvalArgs& args, const std::vector<std::string>& objects,
                  const std::vector<std::string>& restPoses,
                  const std::vector<std::string>& planners) {
  EvalPlan plan;
  plan.planners = planners;
  plan.seeds = args.seeds;
  plan.backend = args.backend;
  plan.scan.config = !args.config.empty();
  plan.scan.max_grasps = args.max_grasps;
  plan.scan.max_views = args.max_views;
  for (const std::string& o : objects)
    for (const std::string& rp : restPoses) {
      const std::string name = objectName(o) + (rp == "as-is" ? "" : "@" + rp);
      plan.objects.push_back(name);
      // A mesh file by its absolute path: the runs may start elsewhere (Slurm, --resume).
      const std::string spec =
          o.rfind("builtin:", 0) == 0 ? o : fs::absolute(o).lexically_normal().string();
      for (const std::string& p : planners)
        for (int s = 1; s <= args.seeds; ++s) {
          EvalRun r;
          r.object = spec;
          r.name = name;
          r.rest_pose = rp;
          r.planner = p;
          r.seed = s;
          r.rel = fs::path("runs") / name / p / ("seed" + std::to_string(s));
          plan.runs.push_back(r);
        }
    }
  std::ostringstream desc;
  desc << plan.runs.size() << " runs: objects " << args.objects << "; planners " << args.planners
       << "; seeds 1.." << args.seeds;
  if (args.rest_poses != "as-is") desc << "; --rest-poses " << args.rest_poses;
  if (args.max_grasps >= 0) desc << "; --max-grasps " << args.max_grasps;
  if (args.max_views >= 0) desc << "; --max-views " << args.max_views;
  if (!args.config.empty()) desc << "; --config " << args.config;
  plan.description = desc.str();
  return plan;
}

}  // namespace

int runEval(const EvalArgs& args) {
  const auto t0 = std::chrono::steady_clock::now();
  if (args.backend != "local" && args.backend != "slurm")
    throw Error("--backend: \"" + args.backend + "\" is neither local nor slurm");
  if (args.backend != "slurm" && !args.slurm_args.empty())
    throw Error("--slurm-args: only with --backend slurm");
  if (args.backend != "slurm" && args.no_wait) throw Error("--no-wait: only with --backend slurm");
  if (args.jobs < 0 || args.jobs > 10000)
    throw Error("--jobs: must be in 0..10000 (0: one per core, or no Slurm limit)");
  if (!args.resume.empty()) return resumeEval(args);
  if (args.objects.empty()) throw Error("--objects is required (or --resume DIR)");
  if (args.out.empty()) throw Error("--out is required (or --resume DIR)");
  const std::vector<std::string> objects = splitList(args.objects);
  const std::vector<std::string> planners = splitList(args.planners);
  if (objects.empty()) throw Error("--objects: give at least one object (comma-separated)");
  if (planners.empty()) throw Error("--planners: give at least one planner (comma-separated)");
  if (args.seeds < 1 || args.seeds > 1000) throw Error("--seeds: must be in 1..1000");
  if (args.backend == "local" && args.jobs > 64)
    throw Error("--jobs: must be in 0..64 on this machine (0: one per core)");
  const std::vector<std::string> known = plannerNames();
  for (const std::string& p : planners)
    if (std::find(known.begin(), known.end(), p) == known.end())
      throw Error("--planners: unknown planner \"" + p + "\"");
  // Rest poses: as-is, or stable pose indices (each object must have that many).
  const std::vector<std::string> restPoses = splitList(args.rest_poses);
  if (restPoses.empty()) throw Error("--rest-poses: give as-is or stable pose indices (0, 1, ...)");
  const int maxPose = largestRestPose(restPoses);
  checkObjects(objects, maxPose);
  if (!args.config.empty()) readJsonFile(args.config);  // readable JSON (scan checks the keys)
  if (args.backend == "slurm") checkSlurmTools();

  EvalPlan plan = evalPlan(args, objects, restPoses, planners);
  std::vector<size_t> all(plan.runs.size());
  for (size_t i = 0; i < all.size(); ++i) all[i] = i;
  const int jobs = threadsForJobs(args.jobs);
  std::fprintf(stderr, "eval: %zu runs (%zu objects × %zu rest poses × %zu planners × %d seeds), ",
               plan.runs.size(), objects.size(), restPoses.size(), planners.size(), args.seeds);
  if (args.backend == "slurm")
    std::fprintf(stderr, "a Slurm job array\n");
  else
    std::fprintf(stderr, "%d at a time\n", jobs);

  if (args.backend == "slurm") {
    // The runs write into the eval directory itself (the tasks may run on other nodes and this
    // command may not wait): it is set up first, and removed again when the submission fails.
    StagedDirectory staged(args.out);
    writeEvalPlan(staged.path(), plan);
    if (!args.config.empty()) fs::copy_file(args.config, staged.path() / "config.json");
    fs::create_directories(staged.path() / "runs");
    staged.commit();
    const fs::path dir = fs::absolute(args.out).lexically_normal();
    try {
      return slurmRunsThenTables(args, dir, &plan, all);
    } catch (const Error&) {
      std::error_code ec;
      if (!fs::exists(dir / "slurm" / "jobs.json")) fs::remove_all(dir, ec);
      throw;
    }
  }

  StagedDirectory out(args.out);
  writeEvalPlan(out.path(), plan);
  if (!args.config.empty()) fs::copy_file(args.config, out.path() / "config.json");
  const bool complete = runLocally(out.path(), &plan, all, jobs);
  writeTables(out.path(), plan);
  out.commit();
  std::fprintf(stderr, "eval: %.0f s\n",
               std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count());
  return endOfEval(plan, args.out, complete);
}

int runReport(const std::string& dir) {
  if (!fs::is_directory(dir)) throw Error(dir + ": not a directory");
  const fs::path web = webDirectory();
  if (fs::exists(fs::path(dir) / "summary.json")) {
    writeScanReport(dir, web);
    std::printf("report: %s/report.html\n", dir.c_str());
  } else if (fs::exists(fs::path(dir) / "eval.json")) {
    // Rebuild the tables from whatever the runs left, then the index.
    EvalPlan plan = readEvalPlan(dir);
    for (EvalRun& r : plan.runs) loadState(dir, &r);
    tabulate(dir, plan.runs, plan.objects, plan.planners, plan.description);
    writeEvalIndex(dir, web);
    listUnfinished(plan.runs, dir);
    std::printf("report: %s/index.html\n", dir.c_str());
  } else {
    throw Error(dir + ": neither a scan (summary.json) nor an eval (eval.json)");
  }
  return 0;
}

}  // namespace inhand::app
