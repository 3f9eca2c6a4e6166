// End-to-end runs of the `inhand` binary: the commands a user types, their outputs and errors.
#include <gtest/gtest.h>

#include <cstdlib>
#include <fstream>

#include "inhand/core/file_util.h"
#include "inhand/core/json_util.h"
#include "inhand/geometry/mesh_io.h"
#include "test_util.h"

using namespace inhand;

namespace {
struct Result {
  int code;
  std::string output;
};
Result run(const std::string& args, const test::TempDir& dir) {
  fs::path log = dir.path() / "log.txt";
  std::string cmd = std::string(INHAND_BINARY) + " " + args + " > " + log.string() + " 2>&1";
  int status = std::system(cmd.c_str());
  Result r{WIFEXITED(status) ? WEXITSTATUS(status) : -1, readTextFile(log)};
  fs::remove(log);
  return r;
}
}  // namespace

TEST(Cli, RenderThenFuseMakesAClosedColouredModel) {
  test::TempDir dir;
  fs::path frames = dir.path() / "frames";
  Result r = run("render --object builtin:pill_bottle --views 12 --out " + frames.string(), dir);
  ASSERT_EQ(r.code, 0) << r.output;
  EXPECT_TRUE(fs::exists(frames / "frames.json"));
  EXPECT_TRUE(fs::exists(frames / "depth_0011.png"));
  fs::path model = dir.path() / "model.ply";
  r = run("fuse --frames " + frames.string() + " --out " + model.string(), dir);
  ASSERT_EQ(r.code, 0) << r.output;
  Json summary = readJsonFile(dir.path() / "model.json");
  EXPECT_TRUE(summary["closed"].get<bool>());
  EXPECT_GT(summary["observed_fraction"].get<double>(), 0.9);
  EXPECT_GT(summary["vertices"].get<int>(), 1000);
  PlyData ply = readPly(model);
  EXPECT_EQ(ply.mesh.vertices.size(), summary["vertices"].get<size_t>());
  EXPECT_EQ(ply.vertexProperties.count("variance"), 1u);
  // The model lies on the pill bottle (Ø 40 × 80 mm, centred).
  Aabb b = ply.mesh.bounds();
  EXPECT_NEAR(b.size().z(), 0.080, 0.006);
  EXPECT_NEAR(b.size().x(), 0.040, 0.006);
}

TEST(Cli, BadInputIsNamedAndLeavesNoOutput) {
  test::TempDir dir;
  auto expectError = [&](const std::string& args, const std::string& needle) {
    Result r = run(args, dir);
    EXPECT_NE(r.code, 0) << args;
    EXPECT_NE(r.output.find(needle), std::string::npos) << args << "\n" << r.output;
  };
  expectError("render --object builtin:teapot --views 3 --out " + (dir.path() / "a").string(),
              "teapot");
  expectError("render --object /nonexistent/x.obj --views 3 --out " + (dir.path() / "a").string(),
              "/nonexistent/x.obj");
  expectError("render --object builtin:mug --views 0 --out " + (dir.path() / "a").string(),
              "--views");
  expectError(
      "render --object builtin:mug --views 3 --range 0.1 --out " + (dir.path() / "a").string(),
      "--range");
  expectError("fuse --frames " + (dir.path() / "none").string() + " --out " +
                  (dir.path() / "m.ply").string(),
              "none");
  fs::create_directories(dir.path() / "broken");
  writeTextAtomically(dir.path() / "broken" / "frames.json", "{\"frames\": 3}");
  expectError("fuse --frames " + (dir.path() / "broken").string() + " --out " +
                  (dir.path() / "m.ply").string(),
              "frames.json");
  expectError("fuse --frames x --out m.txt", ".ply");
  expectError("render --object builtin:mug --views 3", "--out");  // CLI11 usage error
  // Nothing was left behind: only the broken input directory.
  std::vector<std::string> left;
  for (const auto& e : fs::directory_iterator(dir.path()))
    left.push_back(e.path().filename().string());
  EXPECT_EQ(left, std::vector<std::string>{"broken"});
}

TEST(Cli, VolumeOverBudgetIsRefusedWithSize) {
  test::TempDir dir;
  fs::path frames = dir.path() / "frames";
  ASSERT_EQ(
      run("render --object builtin:coffee_can --views 2 --no-noise --out " + frames.string(), dir)
          .code,
      0);
  Result r = run("fuse --frames " + frames.string() + " --voxel 0.0005 --memory-budget 10 --out " +
                     (dir.path() / "m.ply").string(),
                 dir);
  EXPECT_NE(r.code, 0);
  EXPECT_NE(r.output.find("would need"), std::string::npos) << r.output;
  EXPECT_FALSE(fs::exists(dir.path() / "m.ply"));
  EXPECT_FALSE(fs::exists(dir.path() / "m.json"));
}

TEST(Cli, RobotCommandPrintsChainAndReachability) {
  test::TempDir dir;
  const std::string cfg = std::string(INHAND_SOURCE_DIR) + "/data/robots/wam_barretthand.json";
  Result r = run("robot --config " + cfg + " --directions 12 --rolls 3 --grid 1", dir);
  ASSERT_EQ(r.code, 0) << r.output;
  EXPECT_NE(r.output.find("7 DOF"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("wam_j4"), std::string::npos);
  EXPECT_NE(r.output.find("reachable"), std::string::npos);
  Json bad = readJsonFile(cfg);
  bad["urdf"] = std::string(INHAND_SOURCE_DIR) + "/data/robots/wam_barretthand.urdf";
  bad["base_link"] = "wam_bse";
  writeTextAtomically(dir.path() / "bad.json", bad.dump());
  r = run("robot --config " + (dir.path() / "bad.json").string(), dir);
  EXPECT_EQ(r.code, 1);
  EXPECT_NE(r.output.find("base_link: no link named 'wam_bse'"), std::string::npos) << r.output;
  r = run("robot --config " + cfg + " --rolls 0", dir);
  EXPECT_EQ(r.code, 1);
  EXPECT_NE(r.output.find("rolls"), std::string::npos) << r.output;
}

TEST(Cli, ScanWritesModelAndSummaryAndRejectsBadConfig) {
  test::TempDir dir;
  writeTextAtomically(
      dir.path() / "fast.json",
      R"({"voxel_m": 0.003, "initial_views": 2, "planner": {"directions": 40, "rolls": 4},
          "grasp": {"approaches": 16, "rolls": 2, "max_candidates": 6,
                    "ranking": {"directions": 24, "rolls": 2}}})");
  fs::path out = dir.path() / "scan";
  Result r = run("scan --object builtin:coffee_can --max-views 1 --max-grasps 2 --config " +
                     (dir.path() / "fast.json").string() + " --out " + out.string(),
                 dir);
  ASSERT_EQ(r.code, 0) << r.output;
  Json s = readJsonFile(out / "summary.json");
  for (const char* key :
       {"termination", "views", "grasps", "view_evaluations", "view_evaluations_per_s", "timing_s"})
    EXPECT_TRUE(s.contains(key)) << key;
  EXPECT_TRUE(s["timing_s"].contains("total"));
  ASSERT_GE(s["views"].size(), 2u);
  for (const char* key : {"quality", "cost_s", "score", "mean_entropy"})
    EXPECT_TRUE(s["views"][0].contains(key)) << key;
  EXPECT_EQ(s["options"]["planner"]["directions"].get<int>(), 40);
  // Two grasps: the second chosen among ranked candidates, with its quality and stability.
  ASSERT_EQ(s["grasps"].size(), 2u) << s.dump(2);
  EXPECT_EQ(s["termination"], "max_grasps");
  const Json& g2 = s["grasps"][1];
  for (const char* key : {"candidates", "quality", "stability_epsilon", "views", "termination"})
    EXPECT_TRUE(g2.contains(key)) << key;
  EXPECT_GT(g2["candidates"].get<int>(), 0);
  EXPECT_GE(g2["quality"].get<double>(), 0.005);
  EXPECT_GT(g2["stability_epsilon"].get<double>(), 0.0);
  PlyData ply = readPly(out / "model.ply");
  EXPECT_EQ(ply.vertexProperties.count("variance"), 1u);
  // The model lies on the can (object frame = the mesh's own frame): Ø 102 × 139 mm about the
  // origin.
  Aabb b = ply.mesh.bounds();
  EXPECT_NEAR(b.center().z(), 0.0, 0.03);

  writeTextAtomically(dir.path() / "bad.json", R"({"planner": {"directons": 10}})");
  r = run("scan --object builtin:coffee_can --config " + (dir.path() / "bad.json").string() +
              " --out " + (dir.path() / "x").string(),
          dir);
  EXPECT_EQ(r.code, 1);
  EXPECT_NE(r.output.find("planner: unknown option \"directons\""), std::string::npos) << r.output;
  writeTextAtomically(dir.path() / "bad.json", R"({"planner": {"t_q": -1}})");
  r = run("scan --object builtin:coffee_can --config " + (dir.path() / "bad.json").string() +
              " --out " + (dir.path() / "x").string(),
          dir);
  EXPECT_EQ(r.code, 1);
  EXPECT_NE(r.output.find("t_q"), std::string::npos) << r.output;
  r = run("scan --object builtin:coffee_can --max-grasps 0 --out " + (dir.path() / "x").string(),
          dir);
  EXPECT_EQ(r.code, 1);
  EXPECT_NE(r.output.find("max_grasps"), std::string::npos) << r.output;
  EXPECT_FALSE(fs::exists(dir.path() / "x"));
}
