// `inhand eval`: every (object, planner, seed) scan, each in its own `inhand scan` process (a run
// that fails cannot take the others down), `jobs` at a time, then one table of the results.
#include <fcntl.h>
#include <spawn.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <map>
#include <mutex>
#include <sstream>
#include <thread>

#include "commands.h"
#include "inhand/core/error.h"
#include "inhand/core/file_util.h"
#include "inhand/core/json_util.h"
#include "inhand/geometry/builtin_objects.h"
#include "inhand/geometry/stable_poses.h"
#include "inhand/planning/view_selection.h"
#include "inhand/report/html_report.h"

extern char** environ;

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

struct Run {
  std::string object, name, planner;
  std::string rest_pose = "as-is";  // passed to `inhand scan --rest-pose`
  int seed = 0;
  fs::path dir, log;
  int status = -1;
  double wall_s = 0;
  Json summary;  // null when the run wrote none
};

// Runs `argv` with stdout and stderr to `log`; returns its exit status (128+signal if killed).
int runProcess(const std::vector<std::string>& argv, const fs::path& log) {
  posix_spawn_file_actions_t fa;
  posix_spawn_file_actions_init(&fa);
  posix_spawn_file_actions_addopen(&fa, 1, log.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
  posix_spawn_file_actions_adddup2(&fa, 1, 2);
  std::vector<char*> args;
  for (const std::string& a : argv) args.push_back(const_cast<char*>(a.c_str()));
  args.push_back(nullptr);
  pid_t pid = 0;
  const int rc = posix_spawn(&pid, argv[0].c_str(), &fa, nullptr, args.data(), environ);
  posix_spawn_file_actions_destroy(&fa);
  if (rc != 0) throw Error("cannot start " + argv[0] + ": " + std::strerror(rc));
  int st = 0;
  while (waitpid(pid, &st, 0) < 0)
    if (errno != EINTR) throw Error("waitpid failed");
  if (WIFEXITED(st)) return WEXITSTATUS(st);
  return 128 + (WIFSIGNALED(st) ? WTERMSIG(st) : 0);
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

// results.csv, results.md, curves.csv and curves.json in `dir` from the runs.
void tabulate(const fs::path& dir, const std::vector<Run>& runs,
              const std::vector<std::string>& objects, const std::vector<std::string>& planners,
              const std::string& description) {
  // results.csv: one row per run.
  const std::vector<double> levels{0.90, 0.95, 0.99};
  std::ostringstream csv;
  csv << "object,planner,seed,exit_status,termination,views,grasps,coverage,accuracy_mean_mm,"
         "accuracy_rms_mm,accuracy_p95_mm,fscore_2mm,fscore_5mm,fscore_10mm,mean_entropy,"
         "observed_fraction,trajectory_s,planning_s,grasp_ranking_s,total_s,views_to_90,"
         "views_to_95,views_to_99,trajectory_s_to_90,trajectory_s_to_95,trajectory_s_to_99,"
         "view_evaluations\n";
  std::ostringstream curves;
  curves << "object,planner,seed,view,grasp,initial,coverage,mean_entropy,trajectory_s,quality,"
            "cost_s\n";
  Json curvesJson = Json::array();
  for (const Run& r : runs) {
    csv << csvField(r.name) << "," << r.planner << "," << r.seed << "," << r.status << ",";
    if (!r.summary.is_object()) {
      csv << "error" << std::string(22, ',') << "\n";
      continue;
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
    csv << "," << s.value("view_evaluations", 0) << "\n";
    Json c = {{"object", r.name},
              {"planner", r.planner},
              {"seed", r.seed},
              {"report", (fs::path("runs") / r.name / r.planner /
                          ("seed" + std::to_string(r.seed)) / "report.html")
                             .string()}};
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

  // results.md: per object and planner, mean ± sample standard deviation over the seeds.
  std::ostringstream md;
  md << "| object | planner | views to 90% | views to 95% | views to 99% | trajectory s to 90% | "
        "trajectory s to 95% | trajectory s to 99% | final coverage % | accuracy mean mm | grasps "
        "| "
        "views | planning s |\n"
        "|---|---|---|---|---|---|---|---|---|---|---|---|---|\n";
  // planner → final coverage, coverage after 5 / 7 / 10 views, views to 90%, runs reaching 90%,
  // views
  std::map<std::string, std::array<Stat, 7>> overall;
  for (const std::string& o : objects)
    for (const std::string& p : planners) {
      Stat v90, v95, v99, t90, t95, t99, cov, acc, gr, nv, plan;
      for (const Run& r : runs) {
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
        auto& ov = overall[p];
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
  writeTextAtomically(dir / "results.md", head.str() + md.str());
}

}  // namespace

int runEval(const EvalArgs& args) {
  const auto t0 = std::chrono::steady_clock::now();
  const std::vector<std::string> objects = splitList(args.objects);
  const std::vector<std::string> planners = splitList(args.planners);
  if (objects.empty()) throw Error("--objects: give at least one object (comma-separated)");
  if (planners.empty()) throw Error("--planners: give at least one planner (comma-separated)");
  if (args.seeds < 1 || args.seeds > 1000) throw Error("--seeds: must be in 1..1000");
  if (args.jobs < 0 || args.jobs > 64) throw Error("--jobs: must be in 0..64 (0: one per core)");
  const std::vector<std::string> known = plannerNames();
  for (const std::string& p : planners)
    if (std::find(known.begin(), known.end(), p) == known.end())
      throw Error("--planners: unknown planner \"" + p + "\"");
  // Rest poses: as-is, or stable pose indices (each object must have that many).
  const std::vector<std::string> restPoses = splitList(args.rest_poses);
  if (restPoses.empty()) throw Error("--rest-poses: give as-is or stable pose indices (0, 1, ...)");
  int maxPose = -1;
  for (const std::string& rp : restPoses) {
    if (rp == "as-is") continue;
    char* end = nullptr;
    const long n = std::strtol(rp.c_str(), &end, 10);
    if (rp.empty() || *end != '\0' || n < 0 || n > 1000)
      throw Error("--rest-poses: \"" + rp + "\" is neither as-is nor a stable pose's index");
    maxPose = std::max(maxPose, int(n));
  }
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
  // One entry per (object, rest pose): its name is the object's, with @N for pose N.
  struct Entry {
    std::string spec, name, rest_pose;
  };
  std::vector<Entry> entries;
  for (const std::string& o : objects)
    for (const std::string& rp : restPoses)
      entries.push_back({o, objectName(o) + (rp == "as-is" ? "" : "@" + rp), rp});
  if (!args.config.empty()) readJsonFile(args.config);  // readable JSON (scan checks the keys)

  char self[4096];
  const ssize_t len = readlink("/proc/self/exe", self, sizeof(self) - 1);
  if (len <= 0) throw Error("cannot find the inhand executable (/proc/self/exe)");
  self[len] = 0;

  StagedDirectory out(args.out);
  std::vector<Run> runs;
  for (const Entry& e : entries)
    for (const std::string& p : planners)
      for (int s = 1; s <= args.seeds; ++s) {
        Run r;
        r.object = e.spec;
        r.name = e.name;
        r.rest_pose = e.rest_pose;
        r.planner = p;
        r.seed = s;
        const fs::path rel = fs::path("runs") / r.name / p / ("seed" + std::to_string(s));
        r.dir = out.path() / rel;
        r.log = out.path() / "runs" / r.name / p / ("seed" + std::to_string(s) + ".log");
        fs::create_directories(r.log.parent_path());
        runs.push_back(r);
      }
  const int jobs = args.jobs > 0 ? args.jobs : std::max(1u, std::thread::hardware_concurrency());
  std::fprintf(stderr,
               "eval: %zu runs (%zu objects × %zu rest poses × %zu planners × %d seeds), %d at a "
               "time\n",
               runs.size(), objects.size(), restPoses.size(), planners.size(), args.seeds, jobs);
  std::atomic<size_t> next{0}, done{0};
  std::mutex printLock;
  auto worker = [&] {
    for (size_t i = next++; i < runs.size(); i = next++) {
      Run& r = runs[i];
      std::vector<std::string> argv{
          self,           "scan",      "--object", r.object, "--out",
          r.dir.string(), "--planner", r.planner,  "--seed", std::to_string(r.seed),
          "--rest-pose",  r.rest_pose};
      if (!args.config.empty()) argv.insert(argv.end(), {"--config", args.config});
      if (args.max_grasps >= 0)
        argv.insert(argv.end(), {"--max-grasps", std::to_string(args.max_grasps)});
      if (args.max_views >= 0)
        argv.insert(argv.end(), {"--max-views", std::to_string(args.max_views)});
      const auto ts = std::chrono::steady_clock::now();
      r.status = runProcess(argv, r.log);
      writeTextAtomically(fs::path(r.log).replace_extension(".exit"),
                          std::to_string(r.status) + "\n");
      r.wall_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - ts).count();
      const fs::path sj = r.dir / "summary.json";
      if (fs::exists(sj)) {
        try {
          r.summary = readJsonFile(sj);
        } catch (const Error&) {
          r.summary = nullptr;
        }
      }
      std::lock_guard<std::mutex> lock(printLock);
      const size_t k = ++done;
      if (r.summary.is_object())
        std::fprintf(stderr,
                     "eval: [%zu/%zu] %s %s seed %d: coverage %.1f%%, %zu views, %s (%.0f s)\n", k,
                     runs.size(), r.name.c_str(), r.planner.c_str(), r.seed,
                     100 * r.summary.value("coverage", 0.0), r.summary["views"].size(),
                     r.summary.value("termination", std::string("?")).c_str(), r.wall_s);
      else
        std::fprintf(stderr, "eval: [%zu/%zu] %s %s seed %d: FAILED (exit %d, see %s)\n", k,
                     runs.size(), r.name.c_str(), r.planner.c_str(), r.seed, r.status,
                     r.log.lexically_relative(out.path()).c_str());
    }
  };
  std::vector<std::thread> pool;
  for (int j = 1; j < std::min<int>(jobs, int(runs.size())); ++j) pool.emplace_back(worker);
  worker();
  for (auto& t : pool) t.join();

  const double total = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  std::ostringstream desc;
  desc << runs.size() << " runs: objects " << args.objects << "; planners " << args.planners
       << "; seeds 1.." << args.seeds;
  if (args.rest_poses != "as-is") desc << "; --rest-poses " << args.rest_poses;
  if (args.max_grasps >= 0) desc << "; --max-grasps " << args.max_grasps;
  if (args.max_views >= 0) desc << "; --max-views " << args.max_views;
  if (!args.config.empty()) desc << "; --config " << args.config;
  std::vector<std::string> objectNames;
  for (const Entry& e : entries) objectNames.push_back(e.name);
  writeTextAtomically(out.path() / "eval.json", Json({{"description", desc.str()},
                                                      {"objects", objectNames},
                                                      {"planners", planners},
                                                      {"seeds", args.seeds}})
                                                        .dump(1) +
                                                    "\n");
  tabulate(out.path(), runs, objectNames, planners, desc.str());
  try {
    writeEvalIndex(out.path(), webDirectory());
  } catch (const Error& e) {
    std::fprintf(stderr, "eval: warning: no index.html: %s\n", e.what());
  }
  out.commit();
  int failed = 0;
  for (const Run& r : runs) failed += !r.summary.is_object();
  std::printf("eval: %zu runs (%d failed) in %.0f s -> %s/results.md\n", runs.size(), failed, total,
              args.out.c_str());
  return failed ? 5 : 0;
}

int runReport(const std::string& dir) {
  if (!fs::is_directory(dir)) throw Error(dir + ": not a directory");
  const fs::path web = webDirectory();
  if (fs::exists(fs::path(dir) / "summary.json")) {
    writeScanReport(dir, web);
    std::printf("report: %s/report.html\n", dir.c_str());
  } else if (fs::exists(fs::path(dir) / "eval.json")) {
    // Rebuild the tables from the runs' own files, then the index.
    const Json e = readJsonFile(fs::path(dir) / "eval.json");
    const auto objects = e.at("objects").get<std::vector<std::string>>();
    const auto planners = e.at("planners").get<std::vector<std::string>>();
    std::vector<Run> runs;
    for (const std::string& o : objects)
      for (const std::string& p : planners)
        for (int sd = 1; sd <= e.at("seeds").get<int>(); ++sd) {
          Run r;
          r.object = r.name = o;
          r.planner = p;
          r.seed = sd;
          const fs::path base = fs::path(dir) / "runs" / o / p;
          r.dir = base / ("seed" + std::to_string(sd));
          const fs::path exitFile = base / ("seed" + std::to_string(sd) + ".exit");
          if (fs::exists(exitFile)) r.status = std::stoi(readTextFile(exitFile));
          if (fs::exists(r.dir / "summary.json")) r.summary = readJsonFile(r.dir / "summary.json");
          runs.push_back(r);
        }
    tabulate(dir, runs, objects, planners, e.at("description").get<std::string>());
    writeEvalIndex(dir, web);
    std::printf("report: %s/index.html\n", dir.c_str());
  } else {
    throw Error(dir + ": neither a scan (summary.json) nor an eval (eval.json)");
  }
  return 0;
}

}  // namespace inhand::app
