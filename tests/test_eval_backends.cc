// `inhand eval` on both backends: the runs on this machine and as a Slurm job array give the same
// rows; an eval stopped part-way (Ctrl-C, a cancelled Slurm task) is finished by --resume with
// the rows of the eval that was never stopped.
#include <gtest/gtest.h>
#include <signal.h>
#include <unistd.h>

#include <cstdlib>
#include <sstream>
#include <thread>

#include "inhand/core/file_util.h"
#include "inhand/core/json_util.h"
#include "test_util.h"

using namespace inhand;

namespace {

const char* const kQuickConfig = test::quickConfigJson();

std::vector<std::string> splitCsvLine(const std::string& line) {
  std::vector<std::string> out;
  std::stringstream ss(line);
  std::string f;
  while (std::getline(ss, f, ',')) out.push_back(f);
  return out;
}

// results.csv without the wall-clock columns (they differ from run to run).
std::vector<std::string> rows(const fs::path& eval) {
  std::stringstream in(readTextFile(eval / "results.csv"));
  std::string line;
  std::getline(in, line);
  const std::vector<std::string> header = splitCsvLine(line);
  std::vector<std::string> out;
  while (std::getline(in, line)) {
    const std::vector<std::string> f = splitCsvLine(line);
    std::string kept;
    for (size_t i = 0; i < f.size() && i < header.size(); ++i)
      if (header[i] != "planning_s" && header[i] != "grasp_ranking_s" && header[i] != "total_s")
        kept += f[i] + ",";
    out.push_back(kept);
  }
  return out;
}

std::string evalArgs(const test::TempDir& dir) {
  return "--objects builtin:coffee_can --planners ig,random --seeds 1 --max-grasps 1 "
         "--max-views 2 --config " +
         (dir.path() / "quick.json").string();
}

bool waitFor(const std::function<bool()>& done, double seconds) {
  for (int i = 0; i < int(seconds * 50); ++i) {
    if (done()) return true;
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
  }
  return done();
}

// A shell command's status and output.
std::pair<int, std::string> shell(const std::string& cmd, const test::TempDir& dir) {
  const fs::path log = dir.path() / "shell.txt";
  const int st = std::system(("( " + cmd + " ) > " + log.string() + " 2>&1").c_str());
  const std::string out = fs::exists(log) ? readTextFile(log) : std::string();
  fs::remove(log);
  return {WIFEXITED(st) ? WEXITSTATUS(st) : -1, out};
}

}  // namespace

TEST(EvalBackends, LocalEvalStoppedByCtrlCResumesToTheSameRows) {
  test::TempDir dir;
  writeTextAtomically(dir.path() / "quick.json", kQuickConfig);
  const fs::path full = dir.path() / "full", cut = dir.path() / "cut";
  test::CommandResult r = test::runInhand("eval " + evalArgs(dir) + " --out " + full.string(), dir);
  ASSERT_EQ(r.code, 0) << r.output;
  const std::vector<std::string> expected = rows(full);
  ASSERT_EQ(expected.size(), 2u);

  // Ctrl-C reaches the eval and its scans (one process group) once both scans are in their
  // grasp's views: each writes its checkpoint, the eval writes its tables and says how to go on.
  std::vector<std::string> args{"eval", "--out", cut.string()};
  {
    std::stringstream ss(evalArgs(dir));
    std::string w;
    while (ss >> w) args.push_back(w);
  }
  const int pid = test::spawnInhand(args, dir.path() / "cut.log", /*own_group=*/true);
  const fs::path staged = dir.path();  // the eval writes into a staging sibling until it ends
  auto checkpoints = [&] {
    int n = 0;
    try {  // files come and go while the scans run
      for (const auto& e : fs::recursive_directory_iterator(staged))
        n += e.path().filename() == "checkpoint.inhand" &&
             e.path().string().find("/full/") == std::string::npos;
    } catch (const fs::filesystem_error&) {
      return false;
    }
    return n == 2;
  };
  ASSERT_TRUE(waitFor(checkpoints, 120)) << readTextFile(dir.path() / "cut.log");
  kill(-pid, SIGINT);
  ASSERT_EQ(test::waitExit(pid), 130) << readTextFile(dir.path() / "cut.log");
  const std::string log = readTextFile(dir.path() / "cut.log");
  EXPECT_NE(log.find("inhand eval --resume " + cut.string()), std::string::npos) << log;
  EXPECT_TRUE(fs::exists(cut / "results.csv"));
  r = test::runInhand("report " + cut.string(), dir);
  ASSERT_EQ(r.code, 0) << r.output;
  EXPECT_NE(r.output.find("coffee_can random seed 1: interrupted"), std::string::npos) << r.output;

  r = test::runInhand("eval --resume " + cut.string(), dir);
  ASSERT_EQ(r.code, 0) << r.output;
  EXPECT_NE(r.output.find("from their checkpoints"), std::string::npos) << r.output;
  EXPECT_EQ(rows(cut), expected);
  // Nothing left to do: the tables are rebuilt, no run starts.
  r = test::runInhand("eval --resume " + cut.string(), dir);
  ASSERT_EQ(r.code, 0) << r.output;
  EXPECT_NE(r.output.find("every run"), std::string::npos) << r.output;
  // --resume takes no plan options; the backend must be one we know.
  r = test::runInhand("eval --resume " + cut.string() + " --seeds 2", dir);
  EXPECT_NE(r.code, 0);
  r = test::runInhand("eval --resume " + cut.string() + " --backend pbs", dir);
  EXPECT_EQ(r.code, 1);
  EXPECT_NE(r.output.find("--backend"), std::string::npos) << r.output;
}

// A single-node Slurm cluster for the test: the one already running (sinfo answers), else one
// of the test's own (scripts/slurm-local.sh in a temporary directory, stopped at the end).
class SlurmCluster {
 public:
  explicit SlurmCluster(const test::TempDir& dir) : dir_(dir) {
    if (shell("command -v sbatch && command -v slurmctld && command -v munged", dir).first != 0) {
      skip_ = "Slurm is not installed (INHAND_WITH_SLURM=1 bash scripts/install_deps.sh)";
      return;
    }
    if (shell("sinfo -h", dir).first == 0) {
      checkJobsRun(dir);
      return;
    }
    if (geteuid() != 0) {
      skip_ = "no Slurm cluster answers and starting one needs root";
      return;
    }
    state_ = dir.path() / "slurm";
    const std::string env = "INHAND_SLURM_DIR=" + state_.string() + " INHAND_SLURM_PORT=6917 ";
    const auto [st, out] = shell(
        env + "bash " + std::string(INHAND_SOURCE_DIR) + "/scripts/slurm-local.sh start", dir);
    if (st != 0) {  // e.g. a container that cannot run the daemons: said, not hidden
      skip_ =
          "a single-node Slurm cluster could not be started here (scripts/slurm-local.sh "
          "start): " +
          out;
      return;
    }
    setenv("SLURM_CONF", (state_ / "slurm.conf").c_str(), 1);
    checkJobsRun(dir);
  }
  ~SlurmCluster() {
    if (state_.empty()) return;
    shell("INHAND_SLURM_DIR=" + state_.string() + " bash " + std::string(INHAND_SOURCE_DIR) +
              "/scripts/slurm-local.sh stop",
          dir_);
    unsetenv("SLURM_CONF");
  }
  const std::string& skip() const { return skip_; }

  // A cluster whose node cannot start jobs (a container without the privileges slurmd needs)
  // would leave the eval waiting: a one-line job must end within a minute first.
  void checkJobsRun(const test::TempDir& dir) {
    const auto [st, out] =
        shell("timeout 60 sbatch --wait --parsable --output=/dev/null --wrap true", dir);
    if (st != 0) skip_ = "the Slurm cluster here does not run a trivial job (" + out + ")";
  }

 private:
  const test::TempDir& dir_;
  fs::path state_;
  std::string skip_;
};

TEST(EvalBackends, SlurmGivesTheLocalRowsAndResumeFinishesACancelledTask) {
  test::TempDir dir;
  SlurmCluster cluster(dir);
  if (!cluster.skip().empty()) GTEST_SKIP() << cluster.skip();
  writeTextAtomically(dir.path() / "quick.json", kQuickConfig);
  const fs::path local = dir.path() / "local", slurm = dir.path() / "slurm-eval",
                 cut = dir.path() / "cut";
  test::CommandResult r =
      test::runInhand("eval " + evalArgs(dir) + " --out " + local.string(), dir);
  ASSERT_EQ(r.code, 0) << r.output;
  const std::vector<std::string> expected = rows(local);
  ASSERT_EQ(expected.size(), 2u);

  r = test::runInhand("eval " + evalArgs(dir) + " --backend slurm --out " + slurm.string(), dir);
  ASSERT_EQ(r.code, 0) << r.output;
  EXPECT_EQ(rows(slurm), expected);
  EXPECT_TRUE(fs::exists(slurm / "index.html"));

  // A task cancelled during its scan (scancel: SIGTERM, the scan writes its checkpoint) is
  // reported, and --resume finishes the sweep with the same rows.
  r = test::runInhand("eval " + evalArgs(dir) + " --backend slurm --no-wait --out " + cut.string(),
                      dir);
  ASSERT_EQ(r.code, 0) << r.output;
  const Json jobs = readJsonFile(cut / "slurm" / "jobs.json");
  ASSERT_EQ(jobs.size(), 1u);
  const std::string job = jobs[0].at("id").get<std::string>();
  // Task 1 is the second run: coffee_can random seed 1.
  const fs::path run = cut / "runs/coffee_can/random/seed1";
  ASSERT_TRUE(waitFor([&] { return fs::exists(run / "checkpoint.inhand"); }, 180));
  ASSERT_EQ(shell("scancel " + job + "_1", dir).first, 0);
  ASSERT_TRUE(waitFor(
      [&] {
        const auto [st, out] = shell("squeue -h -j " + job, dir);
        return st != 0 || out.empty();  // unknown once Slurm forgets it, unlisted once it ended
      },
      180));
  r = test::runInhand("report " + cut.string(), dir);
  ASSERT_EQ(r.code, 0) << r.output;
  EXPECT_NE(r.output.find("1 of 2 runs did not finish"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("coffee_can random seed 1"), std::string::npos) << r.output;

  r = test::runInhand("eval --resume " + cut.string(), dir);
  ASSERT_EQ(r.code, 0) << r.output;
  EXPECT_NE(r.output.find("1 of 2 runs again"), std::string::npos) << r.output;
  EXPECT_EQ(rows(cut), expected);
  EXPECT_EQ(readJsonFile(cut / "slurm" / "jobs.json").size(), 2u);
}

// Refused before anything is written: a backend we do not know, Slurm options without Slurm.
TEST(EvalBackends, BadBackendOptionsAreRefusedAndWriteNothing) {
  test::TempDir dir;
  const fs::path out = dir.path() / "x";
  test::CommandResult r =
      test::runInhand("eval --objects builtin:coffee_can --backend lsf --out " + out.string(), dir);
  EXPECT_EQ(r.code, 1);
  EXPECT_NE(r.output.find("--backend: \"lsf\""), std::string::npos) << r.output;
  r = test::runInhand(
      "eval --objects builtin:coffee_can --slurm-args=--time=1 --out " + out.string(), dir);
  EXPECT_EQ(r.code, 1);
  EXPECT_NE(r.output.find("--slurm-args: only with --backend slurm"), std::string::npos)
      << r.output;
  r = test::runInhand("eval --objects builtin:coffee_can --no-wait --out " + out.string(), dir);
  EXPECT_EQ(r.code, 1);
  r = test::runInhand("eval --resume " + (dir.path() / "none").string(), dir);
  EXPECT_EQ(r.code, 1);
  EXPECT_NE(r.output.find("not a directory"), std::string::npos) << r.output;
  // With Slurm's tools missing from PATH, the slurm backend says so.
  const auto [st, output] =
      shell("PATH=" + (dir.path() / "no-such-dir").string() + " " + std::string(INHAND_BINARY) +
                " eval --objects builtin:coffee_can --backend slurm --out " + out.string(),
            dir);
  EXPECT_EQ(st, 1);
  EXPECT_NE(output.find("sbatch not found on PATH"), std::string::npos) << output;
  EXPECT_FALSE(fs::exists(out));
  EXPECT_TRUE(fs::is_empty(dir.path()));
}
