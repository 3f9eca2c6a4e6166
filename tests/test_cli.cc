// End-to-end runs of the `inhand` binary: the commands a user types, their outputs and errors.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <fstream>
#include <functional>
#include <map>
#include <optional>

#include <fcntl.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include "inhand/core/file_util.h"
#include "inhand/core/json_util.h"
#include "inhand/eval/metrics.h"
#include "inhand/geometry/builtin_objects.h"
#include "inhand/geometry/mesh_io.h"
#include "inhand/geometry/primitives.h"
#include "inhand/geometry/surface_distance.h"
#include "inhand/sensor/depth_image.h"
#include "test_util.h"

using namespace inhand;

namespace {
using Result = test::CommandResult;
Result run(const std::string& args, const test::TempDir& dir) { return test::runInhand(args, dir); }
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
  // --surface observed: the measured triangles alone (no σ = 5 cm vertex), an open mesh whose
  // area is the closed model's minus its hole area. Two views leave holes.
  fs::path two = dir.path() / "two";
  ASSERT_EQ(run("render --object builtin:pill_bottle --views 2 --out " + two.string(), dir).code,
            0);
  ASSERT_EQ(
      run("fuse --frames " + two.string() + " --out " + (dir.path() / "c.ply").string(), dir).code,
      0);
  fs::path observed = dir.path() / "o.ply";
  r = run("fuse --frames " + two.string() + " --surface observed --out " + observed.string(), dir);
  ASSERT_EQ(r.code, 0) << r.output;
  const Json sc = readJsonFile(dir.path() / "c.json"), so = readJsonFile(dir.path() / "o.json");
  EXPECT_EQ(so["surface"], "observed");
  EXPECT_GT(sc["hole_area_m2"].get<double>(), 1e-3);
  EXPECT_NEAR(so["surface_area_m2"].get<double>(),
              sc["surface_area_m2"].get<double>() - sc["hole_area_m2"].get<double>(), 1e-6);
  EXPECT_EQ(so["hole_area_m2"].get<double>(), 0.0);
  EXPECT_FALSE(so["closed"].get<bool>());
  EXPECT_LT(readPly(observed).mesh.vertices.size(),
            readPly(dir.path() / "c.ply").mesh.vertices.size());
  r = run("fuse --frames " + frames.string() + " --surface open --out " +
              (dir.path() / "x.ply").string(),
          dir);
  EXPECT_EQ(r.code, 1);
  EXPECT_NE(r.output.find("--surface: must be closed or observed"), std::string::npos) << r.output;
  EXPECT_FALSE(fs::exists(dir.path() / "x.ply"));
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
  // Rest poses: a flat mesh has none; an index beyond the object's count is refused.
  TriangleMesh flat;
  flat.vertices = {{0, 0, 0}, {0.1f, 0, 0}, {0, 0.1f, 0}, {0.1f, 0.1f, 0}};
  flat.triangles = {{0, 1, 2}, {1, 3, 2}};
  writePly(dir.path() / "flat.ply", flat);
  expectError("scan --object " + (dir.path() / "flat.ply").string() + " --rest-pose 0 --out " +
                  (dir.path() / "a").string(),
              "flat.ply: the mesh spans no volume");
  expectError("scan --object builtin:coffee_can --rest-pose 3 --out " + (dir.path() / "a").string(),
              "builtin:coffee_can has 3 stable poses (0..2), not 3");
  expectError(
      "scan --object builtin:coffee_can --rest-pose on-side --out " + (dir.path() / "a").string(),
      "--rest-pose: must be as-is or a stable pose's index");
  expectError(
      "scan --object builtin:coffee_can --tracking maybe --out " + (dir.path() / "a").string(),
      "--tracking: must be on or off");
  expectError(
      "scan --object builtin:coffee_can --physics maybe --out " + (dir.path() / "a").string(),
      "--physics: must be on or off");
  expectError(
      "scan --object builtin:coffee_can --arm-error 0.5 --out " + (dir.path() / "a").string(),
      "arm_error_m must be in [0, 0.2] (is 0.5)");
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
  // A value CLI11 cannot convert is bad input too: status 1, the option named, nothing written.
  {
    const Result r = run(
        "render --object builtin:mug --views 3 --range abc --out " + (dir.path() / "u").string(),
        dir);
    EXPECT_EQ(r.code, 1) << r.output;
    EXPECT_NE(r.output.find("--range"), std::string::npos) << r.output;
    EXPECT_FALSE(fs::exists(dir.path() / "u"));
  }
  // Nothing was left behind: only the inputs (the broken frames directory, the flat mesh).
  std::vector<std::string> left;
  for (const auto& e : fs::directory_iterator(dir.path()))
    left.push_back(e.path().filename().string());
  std::sort(left.begin(), left.end());
  EXPECT_EQ(left, (std::vector<std::string>{"broken", "flat.ply"}));
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
  // The open BarrettHand's flat fingers: slabs up to 100 mm wide come down to the knuckles,
  // 10 mm above the palm face, 31 mm below the raised distal links' tips.
  EXPECT_NE(r.output.find("slab across palm x: 10 mm wide 31,"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("90 mm wide 31, 100 mm wide 31"), std::string::npos) << r.output;
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
  Result r =
      run("scan --object builtin:cracker_box --max-views 1 --max-grasps 2 --physics off "
          "--config " +
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
  // --physics off: the kinematic simulator, with none of what physics implies.
  EXPECT_FALSE(s["options"]["sim"]["physics"]["enabled"].get<bool>());
  EXPECT_FALSE(s["options"]["tracking"]["in_hand"].get<bool>());
  EXPECT_EQ(s["options"]["grasp"]["settle_s"].get<double>(), 0.0);
  // Two grasps: the second chosen among ranked candidates, with its quality and stability.
  ASSERT_EQ(s["grasps"].size(), 2u) << s.dump(2);
  EXPECT_EQ(s["termination"], "max_grasps");
  const Json& g2 = s["grasps"][1];
  for (const char* key :
       {"candidates", "quality", "t_q", "stability_epsilon", "views", "termination"})
    EXPECT_TRUE(g2.contains(key)) << key;
  EXPECT_GT(g2["candidates"].get<int>(), 0);
  // Its best view's quality clears the threshold the scan stops at (t_q, relative to the area).
  EXPECT_GT(g2["t_q"].get<double>(), 0.0);
  EXPECT_GE(g2["quality"].get<double>(), g2["t_q"].get<double>());
  EXPECT_GT(g2["stability_epsilon"].get<double>(), 0.0);
  // The scan began on the table: the fitted table plane is the true one (the box stands upright
  // with frame O's z up; its bottom at z = −h/2 lies on the table), the first grasp was made on
  // the table-top model (force closure there), the object's points are the box's.
  EXPECT_EQ(s["start"], "table");
  const Json& tt = s["table_top"];
  const auto plane = tt["table_plane_O"].get<std::vector<double>>();
  EXPECT_GT(plane[2], std::cos(M_PI / 180));
  EXPECT_NEAR(-plane[3] / plane[2], loadObject("builtin:cracker_box").bounds().min.z(), 0.003);
  EXPECT_GT(tt["object_points"].get<int>(), 1000);
  EXPECT_GT(tt["grasp_poses_reachable"].get<int>(), 0);
  EXPECT_GT(s["grasps"][0]["stability_epsilon"].get<double>(), 0.0);           // force closure
  EXPECT_NEAR(tt["principal_axes"][0]["axis_O"][2].get<double>(), 1.0, 1e-6);  // upright
  PlyData ply = readPly(out / "model.ply");
  EXPECT_EQ(ply.vertexProperties.count("variance"), 1u);
  // The model lies on the box (object frame = the mesh's own frame): 60 × 158 × 210 mm about the
  // origin.
  Aabb b = ply.mesh.bounds();
  EXPECT_NEAR(b.center().z(), 0.0, 0.03);

  // A bad config is refused with its field named (exit 1), before any output is written.
  auto rejects = [&](const std::string& json, const std::string& message) {
    writeTextAtomically(dir.path() / "bad.json", json);
    const auto bad =
        run("scan --object builtin:coffee_can --config " + (dir.path() / "bad.json").string() +
                " --out " + (dir.path() / "x").string(),
            dir);
    EXPECT_EQ(bad.code, 1) << json;
    EXPECT_NE(bad.output.find(message), std::string::npos) << json << "\n" << bad.output;
  };
  rejects(R"({"planner": {"directons": 10}})", "planner: unknown option \"directons\"");
  rejects(R"({"planner": {"t_q": -1}})", "t_q");
  rejects(R"({"planner": {"quality": {"visibility": "z"}}})",
          "planner.quality.visibility: must be auto, raster or ray_cast");
  rejects(R"({"planner": {"ik_solver": "analytic"}})", "planner.ik_solver: must be dls or kdl_lma");
  rejects(R"({"planner": {"prescreen_stride": 0}})",
          "option planner.prescreen_stride must be in 1..16 (is 0)");
  rejects(R"({"grasp": {"approach": "slide"}})", "grasp.approach: must be palm or first_contact");
  rejects(R"({"sim": {"pick_up": "grab"}})", "sim.pick_up: must be palm or first_contact");
  rejects(R"({"grasp": {"edge_inset_m": 0.2}})",
          "option grasp.edge_inset_m must be in [0, 0.05) (is 0.2)");
  rejects(R"({"table_top": {"edge_inset_m": 0.005}})",
          "table_top: unknown option \"edge_inset_m\"");
  rejects(R"({"grasp": {"preshapes": [0, 1.5]}})",
          "option grasp.preshapes must be in [0, 1) each (is 1.5)");
  rejects(R"({"sim": {"friction": 0}})", "option sim.friction must be in (0, 2] (is 0)");
  rejects(R"({"grasp": {"edge_spreads": "x"}})", "grasp.edge_spreads: expected an array");
  r = run("scan --object builtin:coffee_can --max-grasps 0 --out " + (dir.path() / "x").string(),
          dir);
  EXPECT_EQ(r.code, 1);
  EXPECT_NE(r.output.find("max_grasps"), std::string::npos) << r.output;
  EXPECT_FALSE(fs::exists(dir.path() / "x"));
}

namespace {
const char* const kQuickConfig = test::quickConfigJson();
}  // namespace

// --scale multiplies the object's coordinates (a mesh in millimetres: 0.001); a scale that is not
// a positive number is refused before anything is written.
TEST(Cli, ScaleResizesTheObjectAndRefusesNonsense) {
  test::TempDir dir;
  writeTextAtomically(dir.path() / "held.json", R"({"start": "held", "voxel_m": 0.004,
    "initial_views": 1, "sim": {"frame_subsample": 10, "physics": {"enabled": false}},
    "eval": {"samples": 2000}})");
  for (const char* bad : {"0", "-1", "nan"}) {
    const fs::path out = dir.path() / (std::string("bad") + bad);
    Result r = run(
        std::string("scan --object builtin:pill_bottle --scale ") + bad + " --out " + out.string(),
        dir);
    EXPECT_EQ(r.code, 1) << r.output;
    EXPECT_NE(r.output.find("--scale"), std::string::npos) << r.output;
    EXPECT_FALSE(fs::exists(out));
  }
  const fs::path out = dir.path() / "half";
  Result r =
      run("scan --object builtin:pill_bottle --scale 0.5 --max-grasps 1 --max-views 0 "
          "--config " +
              (dir.path() / "held.json").string() + " --out " + out.string(),
          dir);
  ASSERT_EQ(r.code, 0) << r.output;
  const Vec3 full = loadObject("builtin:pill_bottle").bounds().size();
  const Vec3 half = readPly(out / "truth.ply").mesh.bounds().size();
  EXPECT_NEAR((half - 0.5 * full).cwiseAbs().maxCoeff(), 0.0, 1e-6);
  EXPECT_EQ(readJsonFile(out / "summary.json").at("object_scale").get<double>(), 0.5);
}

// A scan with the colour camera on: its report in headless Chromium draws the model, the curves,
// the candidates, and the textured model.glb as three.js's glTF loader reads it.
TEST(Cli, ScanReportOpensInHeadlessChromium) {
  test::TempDir dir;
  Json quick = Json::parse(kQuickConfig);
  quick["sim"]["colour"]["enabled"] = true;
  writeTextAtomically(dir.path() / "quick.json", quick.dump());
  const fs::path out = dir.path() / "scan";
  Result r = run("scan --object builtin:cracker_box --max-views 1 --max-grasps 2 --config " +
                     (dir.path() / "quick.json").string() + " --out " + out.string(),
                 dir);
  ASSERT_EQ(r.code, 0) << r.output;
  ASSERT_TRUE(fs::exists(out / "report.html")) << r.output;
  const Json s = readJsonFile(out / "summary.json");
  // Self-contained: no script or style fetched from anywhere.
  const std::string html = readTextFile(out / "report.html");
  for (const char* ref : {"src=\"http", "src='http", "href=\"http", "@import"})
    EXPECT_EQ(html.find(ref), std::string::npos) << ref;
  // `inhand report` rebuilds it from the scan's files.
  fs::remove(out / "report.html");
  r = run("report " + out.string(), dir);
  ASSERT_EQ(r.code, 0) << r.output;
  ASSERT_TRUE(fs::exists(out / "report.html"));

  const char* chromium = "/usr/bin/chromium";
  if (!fs::exists(chromium))
    GTEST_SKIP() << "Chromium is not installed (apt-get install chromium): the report was written "
                    "but not opened in a browser";
  const fs::path dom = dir.path() / "dom.html";
  const std::string cmd = std::string("timeout 300 ") + chromium +
                          " --headless --no-sandbox --disable-gpu --enable-unsafe-swiftshader "
                          "--use-angle=swiftshader --window-size=1200,900 "
                          "--virtual-time-budget=20000 --dump-dom 'file://" +
                          fs::absolute(out / "report.html").string() + "#selftest' > " +
                          dom.string() + " 2>/dev/null";
  ASSERT_EQ(std::system(cmd.c_str()), 0) << cmd;
  const std::string page = readTextFile(dom);
  const std::string tag = "<pre id=\"inhand-selftest\">";
  const size_t at = page.find(tag);
  ASSERT_NE(at, std::string::npos) << "the page did not finish drawing (script error?)";
  const size_t end = page.find("</pre>", at);
  const std::string raw = page.substr(at + tag.size(), end - at - tag.size());
  std::string text;  // the DOM dump escapes quotes
  for (size_t i = 0; i < raw.size(); ++i) {
    if (raw.compare(i, 6, "&quot;") == 0) {
      text += '"';
      i += 5;
    } else {
      text += raw[i];
    }
  }
  const Json t = Json::parse(text);
  EXPECT_TRUE(t["errors"].empty()) << t["errors"].dump();
  // The 3-D view drew the model: well over 1% of the canvas is not background.
  EXPECT_GT(t["nonBackground"].get<double>(), 0.01);
  // Every chart has one point per view.
  const size_t views = s["views"].size();
  EXPECT_EQ(t["views"].get<size_t>(), views);
  for (const char* chart : {"entropy", "coverage", "quality", "cost"}) {
    ASSERT_TRUE(t["charts"].contains(chart)) << chart;
    for (const Json& n : t["charts"][chart]) EXPECT_EQ(n.get<size_t>(), views) << chart;
  }
  // The manipulation timeline: every pick-up attempt of the summary, and every slip found.
  size_t attempts = s["failed_regrasp_attempts"].size();
  for (const Json& g : s["grasps"]) attempts += g["pick_up_attempts"].size();
  EXPECT_GT(attempts, 0u);
  EXPECT_EQ(t["attempts"].get<size_t>(), attempts);
  EXPECT_EQ(t["slips"].get<size_t>(), s["slips_found"].size());
  // The second grasp's candidates drawn, one thumbnail each.
  EXPECT_EQ(t["thumbnails"].get<size_t>(), s["grasps"][1]["ranked"].size());
  EXPECT_GT(t["thumbnails"].get<size_t>(), 0u);
  // model.glb: loaded by three.js, every triangle of model.ply, its texture, drawn.
  ASSERT_TRUE(t["glb"].is_object()) << t.dump();
  ASSERT_FALSE(t["glb"].contains("error")) << t["glb"].dump();
  EXPECT_EQ(t["glb"]["triangles"].get<size_t>(), readPly(out / "model.ply").mesh.triangles.size());
  EXPECT_TRUE(t["glb"]["textured"].get<bool>());
  EXPECT_GT(t["glb"]["nonBackground"].get<double>(), 0.01);
}

TEST(Cli, BaselinePlannerStillRegraspsOnEq9Ranking) {
  // The re-grasp decision compares eq. 9 ranking qualities with the ranking planner's t_q, not
  // with a baseline view planner's threshold (300 voxels here, which no eq. 9 value reaches).
  test::TempDir dir;
  writeTextAtomically(dir.path() / "quick.json", kQuickConfig);
  const fs::path out = dir.path() / "scan";
  Result r =
      run("scan --object builtin:cracker_box --planner unobserved-voxels --max-views 1 "
          "--max-grasps 2 --config " +
              (dir.path() / "quick.json").string() + " --out " + out.string(),
          dir);
  ASSERT_EQ(r.code, 0) << r.output;
  const Json s = readJsonFile(out / "summary.json");
  EXPECT_EQ(s["planner"], "unobserved-voxels");
  EXPECT_EQ(s["grasps"].size(), 2u) << s["termination"];
  EXPECT_EQ(s["termination"], "max_grasps");
}

// A short object: the pill bottle (74 mm) is picked from the table and the scan leaves almost
// nothing unknown; a re-grasp, where one is taken, never adds any.
TEST(Cli, ShortObjectIsPickedFromTheTableAndScannedAlmostWhole) {
  test::TempDir dir;
  writeTextAtomically(dir.path() / "c.json",
                      R"({"voxel_m": 0.003, "planner": {"directions": 150, "rolls": 4},
          "grasp": {"approaches": 32, "rolls": 2, "ranking": {"directions": 32, "rolls": 2}},
          "sim": {"physics": {"enabled": false}}})");
  const fs::path out = dir.path() / "scan";
  Result r = run("scan --object builtin:pill_bottle --config " + (dir.path() / "c.json").string() +
                     " --out " + out.string(),
                 dir);
  ASSERT_EQ(r.code, 0) << r.output;
  const Json s = readJsonFile(out / "summary.json");
  EXPECT_EQ(s["start"], "table");
  ASSERT_GE(s["grasps"].size(), 1u) << s["termination"];
  EXPECT_EQ(s["table_top"]["pick_up_attempts"].back()["outcome"], "picked");
  double previous = 1.0;
  for (const Json& g : s["grasps"]) {
    const double a = g["unknown_area_m2"].get<double>();
    EXPECT_LE(a, previous + 1e-4);
    previous = a;
  }
  EXPECT_LT(previous, 0.001);
  EXPECT_GT(s["views"].back()["observed_fraction"].get<double>(), 0.95);
}

// The demonstration, with every default (physics on: MuJoCo simulates every pick-up, hold and
// put-down): the cracker box is picked from the table with a grasp that holds, at most 3 grasps
// cover it (99 % of the true surface), and since no finger ever starts inside the object nor the
// arm swings through it, the model has no surface inside it.
TEST(Cli, CrackerBoxIsScannedWholeFromTheTable) {
  test::TempDir dir;
  const fs::path out = dir.path() / "scan";
  Result r = run("scan --object builtin:cracker_box --out " + out.string(), dir);
  ASSERT_EQ(r.code, 0) << r.output;
  const Json s = readJsonFile(out / "summary.json");
  ASSERT_GE(s["grasps"].size(), 1u) << s["termination"];
  EXPECT_LE(s["grasps"].size(), 3u);
  EXPECT_GT(s["coverage"].get<double>(), 0.99);
  EXPECT_EQ(s["table_top"]["pick_up_attempts"].back()["outcome"], "picked");
  EXPECT_EQ(s["options"]["grasp"]["approach"], "first_contact");
  EXPECT_EQ(s["options"]["sim"]["pick_up"], "first_contact");
  EXPECT_TRUE(s["options"]["sim"]["physics"]["enabled"].get<bool>());  // MuJoCo by default
  EXPECT_GT(s["physics"]["simulated_s"].get<double>(), 1.0);
  const Aabb b = loadObject("builtin:cracker_box").bounds();
  const PlyData ply = readPly(out / "model.ply");
  const std::vector<float>& variance = ply.vertexProperties.at("variance");
  size_t inside = 0, outside = 0;
  for (size_t i = 0; i < ply.mesh.vertices.size(); ++i) {
    const Vec3 p = ply.mesh.vertices[i].cast<double>();
    const double depth = std::min((p - b.min).minCoeff(), (b.max - p).minCoeff());
    inside += depth > 0.003;
    // Measured (σ < 1 cm) and more than 3 mm outside: tufts beside the fingers, where a ray that
    // grazed the box's edge on the table wrote its band beyond the edge and the finger hid the
    // face beyond it from every later view (241 such vertices before the robot's pixels pulled
    // the voxels more than μ in front of them out; 52 after).
    outside += variance[i] < 1e-4 && (b.min - p).cwiseMax(p - b.max).cwiseMax(0.0).norm() > 0.003;
  }
  EXPECT_LT(double(inside), 1e-3 * double(ply.mesh.vertices.size()))
      << inside << " of " << ply.mesh.vertices.size() << " vertices lie inside the box";
  EXPECT_LT(outside, 120u) << outside << " measured vertices lie more than 3 mm outside the box";
}

TEST(Cli, EvalTabulatesEveryRunAndRejectsUnknownPlanners) {
  test::TempDir dir;
  writeTextAtomically(dir.path() / "quick.json", kQuickConfig);
  const fs::path out = dir.path() / "eval";
  Result r =
      run("eval --objects builtin:juice_bottle --planners ig,random --seeds 2 --max-grasps 1 "
          "--max-views 1 --config " +
              (dir.path() / "quick.json").string() + " --out " + out.string(),
          dir);
  ASSERT_EQ(r.code, 0) << r.output;
  const std::string csv = readTextFile(out / "results.csv");
  EXPECT_EQ(std::count(csv.begin(), csv.end(), '\n'), 5);  // header + 2 planners × 2 seeds
  EXPECT_NE(csv.find("juice_bottle,random,2,0,"), std::string::npos) << csv;
  const std::string md = readTextFile(out / "results.md");
  EXPECT_NE(md.find("| juice_bottle | ig |"), std::string::npos) << md;
  EXPECT_NE(md.find("| juice_bottle | random |"), std::string::npos) << md;
  const Json curves = readJsonFile(out / "curves.json");
  ASSERT_EQ(curves.size(), 4u);
  for (const Json& c : curves) EXPECT_GE(c["coverage"].size(), 2u);  // initial views + 1
  EXPECT_TRUE(fs::exists(out / "index.html"));
  EXPECT_TRUE(fs::exists(out / "runs/juice_bottle/ig/seed1/summary.json"));
  EXPECT_NE(md.find("trajectory s to 99%"), std::string::npos) << md;
  // `inhand report` rebuilds the tables and the index from the runs' files.
  fs::remove(out / "results.md");
  fs::remove(out / "index.html");
  r = run("report " + out.string(), dir);
  ASSERT_EQ(r.code, 0) << r.output;
  EXPECT_EQ(readTextFile(out / "results.md"), md);
  EXPECT_TRUE(fs::exists(out / "index.html"));

  r = run(
      "eval --objects builtin:juice_bottle --planners ig,best --out " + (dir.path() / "x").string(),
      dir);
  EXPECT_EQ(r.code, 1);
  EXPECT_NE(r.output.find("unknown planner \"best\""), std::string::npos) << r.output;
  r = run("eval --objects builtin:nothing --out " + (dir.path() / "x").string(), dir);
  EXPECT_EQ(r.code, 1);
  EXPECT_NE(r.output.find("nothing"), std::string::npos) << r.output;
  EXPECT_FALSE(fs::exists(dir.path() / "x"));
}

// Grasps that must hold: with almost no friction (μ = 0.05) the simulator lets most grasps drop
// the object at the lift. The scan sees it (the object's points are not in the hand, they are
// still on the table), lets go and tries the next candidate; a drop never ends in a scan of an
// empty hand: either a later candidate holds and the scan covers the box, or it ends with
// pick_up_failed (exit 4) and says so.
TEST(Cli, AGraspThatDoesNotHoldDropsTheObjectAndTheScanTriesTheNext) {
  test::TempDir dir;
  // The table-top model closed down to the table behind the box (under_measured_only off): its
  // first candidate drops at this friction; with the option's model the first holds.
  writeTextAtomically(dir.path() / "c.json",
                      R"({"sim": {"friction": 0.05, "physics": {"enabled": false}}, "max_views": 3,
    "table_top": {"under_measured_only": false}})");
  const fs::path out = dir.path() / "scan";
  Result r = run("scan --object builtin:cracker_box --max-grasps 1 --config " +
                     (dir.path() / "c.json").string() + " --out " + out.string(),
                 dir);
  const Json s = readJsonFile(out / "summary.json");
  const Json& attempts = s["table_top"]["pick_up_attempts"];
  ASSERT_FALSE(attempts.empty());
  EXPECT_EQ(attempts.front()["outcome"], "dropped") << r.output;
  EXPECT_EQ(attempts.front()["rank"], 0);
  if (attempts.back()["outcome"] == "picked") {
    EXPECT_EQ(r.code, 0) << r.output;
    EXPECT_GT(s["coverage"].get<double>(), 0.9);
  } else {
    EXPECT_EQ(r.code, 4) << r.output;
    EXPECT_EQ(s["termination"], "pick_up_failed");
  }
}

// A pick-up budget: with every pick-up failing (the hand reaches nothing), the scan tries
// grasp.max_failed_pick_ups candidates, no more, and ends with pick_up_failed (exit 4) and the
// table-top model written.
TEST(Cli, FailedPickUpsStopAtTheBudget) {
  test::TempDir dir;
  writeTextAtomically(dir.path() / "c.json", R"({"grasp": {"max_failed_pick_ups": 2},
    "sim": {"faults": {"failed_pickups": 1.0}, "physics": {"enabled": false}}})");
  const fs::path out = dir.path() / "scan";
  const Result r = run("scan --object builtin:coffee_can --config " +
                           (dir.path() / "c.json").string() + " --out " + out.string(),
                       dir);
  EXPECT_EQ(r.code, 4) << r.output;
  const Json s = readJsonFile(out / "summary.json");
  EXPECT_EQ(s["termination"], "pick_up_failed");
  EXPECT_EQ(s["table_top"]["pick_up_attempts"].size(), 2u);
  EXPECT_TRUE(fs::exists(out / "model.ply"));
}

// A scan that made its first grasp exits 0 whatever ended it: the object dropped during a view
// with no re-grasp left ends object_lost, with the model so far written (the scan starts with the
// object in the hand: the drop comes in its third motion whatever the pick-ups do).
TEST(Cli, AnObjectLostAfterTheFirstGraspExitsZeroWithTheModel) {
  test::TempDir dir;
  writeTextAtomically(dir.path() / "c.json",
                      R"({"voxel_m": 0.003, "planner": {"directions": 40, "rolls": 4},
    "start": "held", "sim": {"faults": {"drop_in_motion": 2}, "physics": {"enabled": false}}})");
  const fs::path out = dir.path() / "scan";
  const Result r = run("scan --object builtin:coffee_can --max-grasps 1 --config " +
                           (dir.path() / "c.json").string() + " --out " + out.string(),
                       dir);
  EXPECT_EQ(r.code, 0) << r.output;
  const Json s = readJsonFile(out / "summary.json");
  EXPECT_EQ(s["termination"], "object_lost");
  EXPECT_EQ(s["grasps"].size(), 1u);
  EXPECT_TRUE(fs::exists(out / "model.ply"));
}

// An object the open BarrettHand cannot span (a 290 mm cube: the flat fingers reach 302 mm tip
// to tip) ends cleanly: no force-closure grasp, object_too_large_for_hand, exit 4, with the
// table-top model written.
TEST(Cli, AnObjectTooLargeForTheHandEndsCleanly) {
  test::TempDir dir;
  writePly(dir.path() / "big.ply", makeBox(Vec3(0.29, 0.29, 0.29)));
  const fs::path out = dir.path() / "scan";
  Result r =
      run("scan --object " + (dir.path() / "big.ply").string() + " --out " + out.string(), dir);
  EXPECT_EQ(r.code, 4) << r.output;
  const Json s = readJsonFile(out / "summary.json");
  EXPECT_EQ(s["termination"], "object_too_large_for_hand") << r.output;
  EXPECT_EQ(s["table_top"]["grasp_poses_stable"], 0);
  EXPECT_TRUE(fs::exists(out / "model.ply"));
}

// `eval --rest-poses`: each object is scanned in each of its requested stable poses (names
// NAME@N), the pose reaching `inhand scan --rest-pose`; a pose an object does not have is
// refused before any scan, naming the object and its count.
TEST(Cli, EvalScansEachRequestedRestPose) {
  test::TempDir dir;
  writeTextAtomically(dir.path() / "quick.json", kQuickConfig);
  const fs::path out = dir.path() / "eval";
  Result r =
      run("eval --objects builtin:cracker_box --planners random --seeds 1 --rest-poses 0,2 "
          "--max-grasps 1 --max-views 1 --config " +
              (dir.path() / "quick.json").string() + " --out " + out.string(),
          dir);
  ASSERT_EQ(r.code, 0) << r.output;
  const std::string csv = readTextFile(out / "results.csv");
  // (The scan's outcome in each pose is the grasping's business: the quick config's 16
  // approaches may find no candidate that holds the box standing on its end.)
  EXPECT_NE(csv.find("cracker_box@0,random,1,"), std::string::npos) << csv;
  EXPECT_NE(csv.find("cracker_box@2,random,1,"), std::string::npos) << csv;
  for (int pose : {0, 2}) {
    const Json s = readJsonFile(out / ("runs/cracker_box@" + std::to_string(pose)) /
                                "random/seed1/summary.json");
    EXPECT_EQ(s["rest_pose"]["pose"].get<int>(), pose);
    EXPECT_GT(s["rest_pose"]["probability"].get<double>(), 0.05);
  }
  r = run("eval --objects builtin:cracker_box --planners random --rest-poses 6 --out " +
              (dir.path() / "e2").string(),
          dir);
  EXPECT_EQ(r.code, 1);
  EXPECT_NE(r.output.find("builtin:cracker_box has 6 stable poses (0..5), not 6"),
            std::string::npos)
      << r.output;
  EXPECT_FALSE(fs::exists(dir.path() / "e2"));
}

// `inhand scan` gives the same scan for the same seed as recorded in tests/data/scan_golden.json:
// the views (direction, frames, quality), the grasps, the model's size and the figures of merit.
// The record was written by this test with INHAND_WRITE_GOLDEN=1; rewrite it only for a change
// that is meant to change the scan (and say so in the commit).
//
// The scan's decisions (views, frames, grasps, termination, how many views were evaluated) are
// compared exactly (numbers to 1e-6). The model's fine detail is compared to a tolerance: Embree
// and glibc's libm pick their kernels by CPU at run time, and the record was seen to move on
// another CPU by 0.8 % in triangles and 0.5 % in a view's quality with every decision the same.
// On one machine a scan is reproduced byte for byte (test_determinism, test_checkpoint).
// The whole scan of the cracker box, judged by its outcome against the true mesh (what holds on
// any CPU: a last bit that flips one argmax changes the views and grasps, not whether the scan
// succeeds): an allowed termination, coverage and accuracy in voxels, views and grasps within
// their bounds, the summary's counts consistent with each other, a closed model.
TEST(Cli, ScanOfTheCrackerBoxMeetsItsOutcomeBounds) {
  test::TempDir dir;
  const fs::path config = dir.path() / "fast.json";
  writeTextAtomically(config, R"({"voxel_m": 0.003, "planner": {"directions": 80, "rolls": 4},
    "max_views": 3, "grasp": {"approaches": 32}, "sim": {"physics": {"enabled": false}}})");
  const fs::path out = dir.path() / "scan";
  const Result r = run("scan --object builtin:cracker_box --max-grasps 2 --seed 3 --config " +
                           config.string() + " --export mjcf,urdf --out " + out.string(),
                       dir);
  ASSERT_EQ(r.code, 0) << r.output;
  const Json s = readJsonFile(out / "summary.json");
  const std::string t = s["termination"].get<std::string>();
  EXPECT_TRUE(t == "no_grasp_above_threshold" || t == "max_grasps" ||
              t == "no_view_above_threshold")
      << t;
  EXPECT_GE(s["coverage"].get<double>(), 0.97);
  // The kinematic simulator holds the object where the grasp put it: a creep followed is an
  // alignment that slid (tracking.creep_turn_deg).
  EXPECT_EQ(s["creeps_followed"].get<int>(), 0);
  EXPECT_EQ(s["tracking"].at("creep_grasp_error_mm").size(),
            size_t(s["creeps_followed"].get<int>()));
  const double voxel = 0.003;
  EXPECT_LE(s["accuracy_mm"]["mean"].get<double>(), 1000 * voxel / 3);
  EXPECT_LE(s["accuracy_mm"]["p95"].get<double>(), 1000 * voxel);
  const int grasps = int(s["grasps"].size());
  EXPECT_GE(grasps, 1);
  EXPECT_LE(grasps, 2);
  // At most the initial views plus max_views per grasp; every view's frames add up.
  const int views = int(s["views"].size());
  EXPECT_GE(views, 1);
  EXPECT_LE(views, grasps * 3 + s["options"]["initial_views"].get<int>());
  int frames = 0;
  for (const Json& v : s["views"]) {
    frames += v["frames"].get<int>();
    EXPECT_GE(v["grasp"].get<int>(), 1);  // 1-based
    EXPECT_LE(v["grasp"].get<int>(), grasps);
  }
  EXPECT_LE(frames, s["frames"].get<int>());
  const PlyData ply = readPly(out / "model.ply");
  EXPECT_TRUE(ply.mesh.isWatertight());
  EXPECT_GT(ply.mesh.vertices.size(), 1000u);
  EXPECT_EQ(ply.mesh.vertices.size(), s["vertices"].get<size_t>());
  // --export: the asset beside the model; its mass that of the true box at the config's
  // density within 10 %; the grasps the scan tried, the one it scanned with among them, held.
  const Json asset = readJsonFile(out / "asset" / "asset.json");
  const Vec3 size = loadObject("builtin:cracker_box").bounds().size();
  const double density = s["options"]["sim"]["physics"]["density_kg_m3"].get<double>();
  EXPECT_NEAR(asset["mass_kg"].get<double>(), density * size.prod(), 0.1 * density * size.prod());
  EXPECT_TRUE(fs::exists(out / "asset" / "object.xml"));
  EXPECT_TRUE(fs::exists(out / "asset" / "object.urdf"));
  EXPECT_FALSE(fs::exists(out / "asset" / "object.sdf"));
  const Json graspSet = readJsonFile(out / "asset" / "grasps.json");
  int tried = 0, held = 0, listed = 0, ranked = 0;
  for (const Json& g : s["grasps"]) tried += int(g["pick_up_attempts"].size());
  for (const Json& g : graspSet) {
    EXPECT_EQ(g["T_O_palm"].size(), 16u);
    EXPECT_FALSE(g["preshape"].empty());
    if (g["source"] == "tried") {
      ++listed;
      held += g["outcome"] == "held";
    } else {
      EXPECT_EQ(g["source"], "ranked");
      EXPECT_NE(g["outcome"].get<std::string>().find("held"), std::string::npos);
      ++ranked;
    }
  }
  EXPECT_EQ(listed, tried + int(s["failed_regrasp_attempts"].size()));
  EXPECT_GE(held, 1);
  EXPECT_LE(ranked, 4 * 10);  // at most --ranked per stable pose, in up to 4 poses
}

TEST(Cli, ExportRefusesBadInputByNameAndWritesNothing) {
  test::TempDir dir;
  const fs::path out = dir.path() / "asset";
  TriangleMesh sheet;  // an open mesh: no enclosed volume
  sheet.vertices = {Vec3f(0, 0, 0), Vec3f(0.1f, 0, 0), Vec3f(0, 0.1f, 0)};
  sheet.triangles = {Tri(0, 1, 2)};
  writePly(dir.path() / "sheet.ply", sheet);
  writePly(dir.path() / "box.ply", makeBox(Vec3(0.05, 0.04, 0.03)));
  fs::create_directories(dir.path() / "empty");
  const std::vector<std::pair<std::string, std::string>> cases{
      {"export " + (dir.path() / "missing").string(), "no such mesh file"},
      {"export " + (dir.path() / "empty").string(), "no model.ply"},
      {"export " + (dir.path() / "sheet.ply").string(), "encloses no volume"},
      {"export " + (dir.path() / "box.ply").string() + " --format mjcf,gltf", "'gltf'"},
      {"export " + (dir.path() / "box.ply").string() + " --density -3", "density"},
      {"export " + (dir.path() / "box.ply").string() + " --name 'a b'", "name"},
      {"export " + (dir.path() / "box.ply").string() + " --ranked 200", "--ranked"},
      {"scan --object builtin:cracker_box --export obj", "'obj'"}};
  for (const auto& [args, message] : cases) {
    const Result r = run(args + " --out " + out.string(), dir);
    EXPECT_EQ(r.code, 1) << args << "\n" << r.output;
    EXPECT_NE(r.output.find(message), std::string::npos) << args << "\n" << r.output;
    EXPECT_FALSE(fs::exists(out)) << args;
  }
  // A closed mesh file exports: the box's mass at 200 kg/m³.
  const Result r = run("export " + (dir.path() / "box.ply").string() +
                           " --density 200 --format sdf --ranked 0 --out " + out.string(),
                       dir);
  ASSERT_EQ(r.code, 0) << r.output;
  EXPECT_NEAR(readJsonFile(out / "asset.json")["mass_kg"].get<double>(), 200 * 0.05 * 0.04 * 0.03,
              1e-9);
  EXPECT_TRUE(fs::exists(out / "object.sdf"));
}

namespace {
// Starts `inhand ARGS` (output to LOG) and returns its pid.
pid_t spawn(const std::vector<std::string>& args, const fs::path& log) {
  return test::spawnInhand(args, log);
}
using test::waitExit;
}  // namespace

// SIGINT during a scan: it ends cleanly with the model so far, termination "interrupted", exit
// status 130 and its checkpoint; `inhand scan --resume` goes on and ends with the model of the
// scan that was never interrupted, byte for byte. Whenever the signal lands, the outcome must be
// the same.
TEST(Cli, ScanInterruptedBySigintResumesToTheUninterruptedModel) {
  test::TempDir dir;
  writeTextAtomically(dir.path() / "quick.json", kQuickConfig);
  const std::string common = "--object builtin:coffee_can --max-grasps 2 --max-views 2 --config " +
                             (dir.path() / "quick.json").string();
  const fs::path full = dir.path() / "full", cut = dir.path() / "cut";
  ASSERT_EQ(run("scan " + common + " --out " + full.string(), dir).code, 0);
  EXPECT_FALSE(fs::exists(full / "checkpoint.inhand"));  // a scan that ended keeps none

  const pid_t pid =
      spawn({"scan", "--object", "builtin:coffee_can", "--max-grasps", "2", "--max-views", "2",
             "--config", (dir.path() / "quick.json").string(), "--out", cut.string()},
            dir.path() / "cut.log");
  // The first checkpoint is written when the first grasp's views begin; stop a moment later,
  // during its views.
  for (int i = 0; i < 2400 && !fs::exists(cut / "checkpoint.inhand"); ++i) usleep(50000);
  ASSERT_TRUE(fs::exists(cut / "checkpoint.inhand"));
  usleep(300000);
  kill(pid, SIGINT);
  ASSERT_EQ(waitExit(pid), 130) << readTextFile(dir.path() / "cut.log");
  const Json stopped = readJsonFile(cut / "summary.json");
  EXPECT_EQ(stopped.at("termination"), "interrupted");
  EXPECT_TRUE(fs::exists(cut / "model.ply"));
  EXPECT_TRUE(fs::exists(cut / "checkpoint.inhand"));

  const Result resumed = run("scan --resume " + cut.string(), dir);
  ASSERT_EQ(resumed.code, 0) << resumed.output;
  EXPECT_NE(resumed.output.find("resumed after"), std::string::npos) << resumed.output;
  EXPECT_FALSE(fs::exists(cut / "checkpoint.inhand"));
  EXPECT_EQ(readTextFile(cut / "model.ply"), readTextFile(full / "model.ply"));
  const Json a = readJsonFile(full / "summary.json"), b = readJsonFile(cut / "summary.json");
  EXPECT_EQ(a.at("termination"), b.at("termination"));
  EXPECT_EQ(a.at("frames"), b.at("frames"));
  EXPECT_EQ(a.at("views").size(), b.at("views").size());
  EXPECT_EQ(a.at("options"), b.at("options"));
  // --resume takes no other options, and needs a checkpoint.
  Result r = run("scan --resume " + cut.string() + " --seed 3", dir);
  EXPECT_NE(r.code, 0);
  EXPECT_NE(r.output.find("--resume"), std::string::npos) << r.output;
  r = run("scan --resume " + full.string(), dir);
  EXPECT_NE(r.code, 0);
  EXPECT_NE(r.output.find("no checkpoint.inhand"), std::string::npos) << r.output;
}

// The bad inputs a user meets with files from other tools: each a clean non-zero exit whose
// message names the file (and the key or line), and nothing written.
TEST(Cli, BadFilesFromOtherToolsAreRefusedByName) {
  test::TempDir dir;
  auto expectError = [&](const std::string& args, const std::string& needle) {
    const Result r = run(args, dir);
    EXPECT_NE(r.code, 0) << args;
    EXPECT_NE(r.output.find(needle), std::string::npos) << args << "\n" << r.output;
  };
  const fs::path frames = dir.path() / "frames";
  ASSERT_EQ(run("render --object builtin:mug --views 2 --out " + frames.string(), dir).code, 0);
  // A truncated PNG.
  {
    const fs::path png = frames / "depth_0001.png";
    std::string bytes = readTextFile(png);
    ASSERT_GT(bytes.size(), 200u);
    std::ofstream(png, std::ios::binary | std::ios::trunc).write(bytes.data(), 200);
    expectError("fuse --frames " + frames.string() + " --out " + (dir.path() / "m.ply").string(),
                "depth_0001.png");
  }
  // A NaN in a pose (JSON has no NaN: written as NaN it is malformed, as null it is no number).
  fs::create_directories(dir.path() / "nan");
  for (const std::string nan : {"NaN", "null"}) {
    Json j = readJsonFile(frames / "frames.json");
    std::string text = j.dump();
    const std::string first = j["frames"][0]["T_O_C"][0].dump();
    text.replace(text.find("\"T_O_C\":[") + 9, first.size(), nan);
    writeTextAtomically(dir.path() / "nan" / "frames.json", text);
    fs::copy(frames / "depth_0000.png", dir.path() / "nan" / "depth_0000.png",
             fs::copy_options::overwrite_existing);
    expectError("fuse --frames " + (dir.path() / "nan").string() + " --out " +
                    (dir.path() / "m.ply").string(),
                "frames.json");
  }
  // A malformed OBJ.
  writeTextAtomically(dir.path() / "bad.obj", "v 0 0 0\nv 1 0 0\nf 1 2 7\nf a b c\n");
  expectError("scan --object " + (dir.path() / "bad.obj").string() + " --out " +
                  (dir.path() / "out").string(),
              "bad.obj");
  // A config value of the wrong type: the key is named.
  writeTextAtomically(dir.path() / "typed.json", R"({"planner": {"t_q": "high"}})");
  expectError("scan --object builtin:mug --config " + (dir.path() / "typed.json").string() +
                  " --out " + (dir.path() / "out").string(),
              "planner.t_q");
  // A URDF with a loop: a link that is its own ancestor.
  std::string urdf = readTextFile(fs::path(INHAND_SOURCE_DIR) / "data/robots/wam_barretthand.urdf");
  const std::string child = "<parent link=\"wam_link3\"/><child link=\"wam_link4\"/>";
  ASSERT_NE(urdf.find(child), std::string::npos);
  urdf.replace(urdf.find(child), child.size(),
               "<parent link=\"wam_link3\"/><child link=\"wam_link2\"/>");
  writeTextAtomically(dir.path() / "loop.urdf", urdf);
  expectError("robot --config " +
                  (fs::path(INHAND_SOURCE_DIR) / "data/robots/wam_barretthand.json").string() +
                  " --urdf " + (dir.path() / "loop.urdf").string(),
              "loop.urdf");
  // A checkpoint that is not one.
  fs::create_directories(dir.path() / "fake");
  writeTextAtomically(dir.path() / "fake" / "checkpoint.inhand", "INHAND-SESSION 1\n3\n{}x");
  expectError("scan --resume " + (dir.path() / "fake").string(), "checkpoint.inhand");
  // Nothing was written beside the inputs.
  EXPECT_FALSE(fs::exists(dir.path() / "m.ply"));
  EXPECT_FALSE(fs::exists(dir.path() / "out"));
  std::vector<std::string> left;
  for (const auto& e : fs::directory_iterator(dir.path()))
    left.push_back(e.path().filename().string());
  std::sort(left.begin(), left.end());
  EXPECT_EQ(left, (std::vector<std::string>{"bad.obj", "fake", "frames", "loop.urdf", "nan",
                                            "typed.json"}));
}

namespace {
// A model written by `inhand fuse` against the true mesh: vertices with variance under (1 cm)²
// count as observed.
SurfaceMetrics metricsOf(const fs::path& ply, const TriangleMesh& truth) {
  PlyData d = readPly(ply);
  ObjectModel m;
  m.mesh = d.mesh;
  m.variance = d.vertexProperties.at("variance");
  for (float v : m.variance) m.observed.push_back(v < 1e-4f ? 1 : 0);
  EvalOptions eo;
  eo.samples = 6000;
  return GroundTruth(truth, eo).evaluate(m);
}
}  // namespace

// Frames as a robot records them (`scan --save-frames`: depth, the joints it reported, the
// camera in its base frame, the grasp), with 1 cm of simulated arm error: `fuse --robot` tracks
// the hand and builds the model the scan built; fusing the same frames with the poses the
// reported joints give (plain `fuse`) smears it. Bad robot fields are refused by name.
TEST(Cli, FuseRobotTracksTheHandInFramesARobotRecorded) {
  test::TempDir dir;
  // The grasp whose two views the coverage bound below was measured on (with under_measured_only
  // the first grasp is another, and its two views cover 79 % of the can).
  Json quick = Json::parse(kQuickConfig);
  quick["table_top"]["under_measured_only"] = false;
  writeTextAtomically(dir.path() / "quick.json", quick.dump());
  const fs::path scan = dir.path() / "scan", frames = scan / "frames";
  Result r =
      run("scan --object builtin:coffee_can --max-grasps 1 --max-views 2 --arm-error 0.01 "
          "--tracking on --save-frames --config " +
              (dir.path() / "quick.json").string() + " --out " + scan.string(),
          dir);
  ASSERT_EQ(r.code, 0) << r.output;
  // The scan's own tracking figures against the simulator's truth.
  const Json tr = readJsonFile(scan / "summary.json").at("tracking");
  EXPECT_TRUE(tr.at("enabled").get<bool>());
  EXPECT_LT(tr["palm_error_mm"].at("median").get<double>(), 2.0) << tr;
  EXPECT_LT(tr["object_pose_error_mm"].at("median").get<double>(), 2.0) << tr;
  EXPECT_GT(tr.at("ms_per_frame").get<double>(), 0.0);
  const Json fj = readJsonFile(frames / "frames.json");
  ASSERT_GE(fj.at("frames").size(), 8u);
  const Json& f0 = fj["frames"][0];
  for (const char* k : {"q", "T_B_C", "T_O_palm", "T_O_C"}) EXPECT_TRUE(f0.contains(k)) << k;
  const std::string robot = std::string(INHAND_SOURCE_DIR) + "/data/robots/wam_barretthand.json";
  const fs::path tracked = dir.path() / "tracked.ply", reported = dir.path() / "reported.ply";
  r = run("fuse --frames " + frames.string() + " --robot " + robot + " --out " + tracked.string(),
          dir);
  ASSERT_EQ(r.code, 0) << r.output;
  const Json tj = readJsonFile(dir.path() / "frames_tracked.json");
  ASSERT_EQ(tj.at("frames").size(), fj["frames"].size());
  int fused = 0;
  for (const Json& t : tj["frames"]) fused += t.at("fused").get<bool>();
  EXPECT_GE(fused, int(fj["frames"].size()) * 8 / 10);
  EXPECT_EQ(readJsonFile(dir.path() / "tracked.json").at("frames_fused"), fused);
  r = run("fuse --frames " + frames.string() + " --out " + reported.string(), dir);
  ASSERT_EQ(r.code, 0) << r.output;

  const TriangleMesh truth = readPly(scan / "truth.ply").mesh;
  const SurfaceMetrics withRobot = metricsOf(tracked, truth);
  const SurfaceMetrics plain = metricsOf(reported, truth);
  std::printf(
      "fuse --robot: coverage %.3f, accuracy %.2f mm mean, %.2f p95; plain fuse: %.3f, "
      "%.2f mm, %.2f p95\n",
      withRobot.coverage, withRobot.accuracy_mean_mm, withRobot.accuracy_p95_mm, plain.coverage,
      plain.accuracy_mean_mm, plain.accuracy_p95_mm);
  // The scan's own model (100 %) also had the table-top frames, which are not recorded: the
  // in-hand frames of its two views cover 86-89 % of the can (the part under the fingers unseen).
  EXPECT_GT(withRobot.coverage, 0.85);
  EXPECT_GT(withRobot.coverage, plain.coverage + 0.1);
  EXPECT_LT(withRobot.accuracy_mean_mm, 2.0);
  EXPECT_GT(plain.accuracy_mean_mm, 2 * withRobot.accuracy_mean_mm);

  // Refused by name: a joint the robot lacks, a joint missing, no T_O_C without --robot, no
  // bounds with --robot.
  Json bad = fj;
  bad["frames"][1]["q"]["no_such_joint"] = 0.1;
  writeTextAtomically(frames / "frames.json", bad.dump());
  r = run("fuse --frames " + frames.string() + " --robot " + robot + " --out " +
              (dir.path() / "x.ply").string(),
          dir);
  EXPECT_EQ(r.code, 1);
  EXPECT_NE(r.output.find("frames[1].q.no_such_joint: the robot"), std::string::npos) << r.output;
  bad = fj;
  bad["frames"][2]["q"].erase(bad["frames"][2]["q"].begin());
  writeTextAtomically(frames / "frames.json", bad.dump());
  r = run("fuse --frames " + frames.string() + " --robot " + robot + " --out " +
              (dir.path() / "x.ply").string(),
          dir);
  EXPECT_EQ(r.code, 1);
  EXPECT_NE(r.output.find("frames[2].q: no value for joint"), std::string::npos) << r.output;
  bad = fj;
  bad["frames"][0].erase("T_O_C");
  writeTextAtomically(frames / "frames.json", bad.dump());
  r = run("fuse --frames " + frames.string() + " --out " + (dir.path() / "x.ply").string(), dir);
  EXPECT_EQ(r.code, 1);
  EXPECT_NE(r.output.find("frames[0] has no T_O_C"), std::string::npos) << r.output;
  bad = fj;
  bad.erase("bounds_O");
  writeTextAtomically(frames / "frames.json", bad.dump());
  r = run("fuse --frames " + frames.string() + " --robot " + robot + " --out " +
              (dir.path() / "x.ply").string(),
          dir);
  EXPECT_EQ(r.code, 1);
  EXPECT_NE(r.output.find("--bounds"), std::string::npos) << r.output;
  EXPECT_FALSE(fs::exists(dir.path() / "x.ply"));
  EXPECT_FALSE(fs::exists(dir.path() / "x.json"));
}

// `inhand compare`: a mesh against itself is exact; a 10 cm cube moved 5 mm along x leaves its ±x
// faces (a third of the surface) 5 mm from the truth and the rest on it: accuracy ≈ 5/3 mm,
// coverage ≈ 2/3 (less the 5 mm strips that overhang).
TEST(Cli, CompareScoresAModelAgainstTheTrueSurface) {
  test::TempDir dir;
  const TriangleMesh box = makeBox(Vec3(0.1, 0.1, 0.1));
  TriangleMesh moved = box;
  for (auto& v : moved.vertices) v.x() += 0.005f;
  writePly(dir.path() / "box.ply", box);
  writePly(dir.path() / "moved.ply", moved);
  Result r = run("compare " + (dir.path() / "box.ply").string() + " --truth " +
                     (dir.path() / "box.ply").string() + " --json",
                 dir);
  ASSERT_EQ(r.code, 0) << r.output;
  Json j = Json::parse(r.output);
  EXPECT_DOUBLE_EQ(j.at("coverage").get<double>(), 1.0);
  EXPECT_LT(j["accuracy_mm"].at("mean").get<double>(), 1e-3);
  r = run("compare " + (dir.path() / "moved.ply").string() + " --truth " +
              (dir.path() / "box.ply").string() + " --json",
          dir);
  ASSERT_EQ(r.code, 0) << r.output;
  j = Json::parse(r.output);
  EXPECT_NEAR(j["accuracy_mm"].at("mean").get<double>(), 5.0 / 3.0, 0.15);
  EXPECT_NEAR(j.at("coverage").get<double>(), 2.0 / 3.0 - 4 * 0.02 / 6.0, 0.03);
  r = run("compare " + (dir.path() / "nothing.ply").string() + " --truth builtin:mug", dir);
  EXPECT_EQ(r.code, 1);
  EXPECT_NE(r.output.find("nothing.ply"), std::string::npos) << r.output;
}

// `inhand compare` scores colours where the model and the truth both have them: a sphere whose
// top half is red and bottom half blue (vertex colours in the truth's PLY) against itself is
// exact; with the halves swapped, far off; a model without colours gets no colour score.
TEST(Cli, CompareScoresTheColoursWhereBothHaveThem) {
  test::TempDir dir;
  const TriangleMesh sphere = makeSphere(0.05, 4);
  std::vector<std::array<uint8_t, 4>> truth, swapped;
  for (const Vec3f& v : sphere.vertices) {
    const bool top = v.z() > 0;
    truth.push_back(top ? std::array<uint8_t, 4>{200, 30, 30, 255}
                        : std::array<uint8_t, 4>{30, 40, 200, 255});
    swapped.push_back(top ? std::array<uint8_t, 4>{30, 40, 200, 255}
                          : std::array<uint8_t, 4>{200, 30, 30, 255});
  }
  const std::vector<float> variance(sphere.vertices.size(), 0.f);
  writePly(dir.path() / "truth.ply", sphere, &variance, &truth);
  writePly(dir.path() / "same.ply", sphere, &variance, &truth);
  writePly(dir.path() / "swapped.ply", sphere, &variance, &swapped);
  writePly(dir.path() / "plain.ply", sphere, &variance);
  const std::string truthArg = " --truth " + (dir.path() / "truth.ply").string() + " --json";
  Result r = run("compare " + (dir.path() / "same.ply").string() + truthArg, dir);
  ASSERT_EQ(r.code, 0) << r.output;
  Json c = Json::parse(r.output).at("colour");
  EXPECT_EQ(c.at("vertices_compared").get<size_t>(), sphere.vertices.size());
  EXPECT_LT(c.at("delta_e76_mean").get<double>(), 0.5);
  EXPECT_GT(c.at("psnr_db_8_views").get<double>(), 30.0);
  r = run("compare " + (dir.path() / "swapped.ply").string() + truthArg, dir);
  ASSERT_EQ(r.code, 0) << r.output;
  c = Json::parse(r.output).at("colour");
  EXPECT_GT(c.at("delta_e76_mean").get<double>(), 50.0);
  EXPECT_GT(c.at("delta_e76_mean_off_edges").get<double>(), 50.0);
  r = run("compare " + (dir.path() / "plain.ply").string() + truthArg, dir);
  ASSERT_EQ(r.code, 0) << r.output;
  EXPECT_TRUE(Json::parse(r.output).at("colour").is_null()) << r.output;
  // A truth whose colours cannot be read (its mtllib is missing) still scores the shape.
  {
    std::ofstream obj(dir.path() / "truth.obj");
    obj << "mtllib missing.mtl\nusemtl red\n";
    for (const Vec3f& v : sphere.vertices)
      obj << "v " << v.x() << " " << v.y() << " " << v.z() << "\n";
    for (const Tri& t : sphere.triangles)
      obj << "f " << t[0] + 1 << " " << t[1] + 1 << " " << t[2] + 1 << "\n";
  }
  r = run("compare " + (dir.path() / "same.ply").string() + " --truth " +
              (dir.path() / "truth.obj").string(),
          dir);
  ASSERT_EQ(r.code, 0) << r.output;
  EXPECT_NE(r.output.find("no colour score"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("coverage 100.0%"), std::string::npos) << r.output;
}

namespace {
// Sets an environment variable for the lifetime of the object (unset when `value` is null) and
// puts back what was there.
class ScopedEnv {
 public:
  ScopedEnv(const char* name, const char* value) : name_(name) {
    const char* old = std::getenv(name);
    if (old) old_ = old;
    if (value)
      setenv(name, value, 1);
    else
      unsetenv(name);
  }
  ~ScopedEnv() {
    if (old_)
      setenv(name_.c_str(), old_->c_str(), 1);
    else
      unsetenv(name_.c_str());
  }

 private:
  std::string name_;
  std::optional<std::string> old_;
};

// Runs `inhand args` with the run-time AVX2 paths on (as this CPU allows) or off (inhand's own,
// Embree's and glibc's AVX2 and FMA kernels), whatever the test's own environment says.
Result runWithAvx2(bool on, const std::string& args, const test::TempDir& dir) {
  ScopedEnv avx2("INHAND_NO_AVX2", on ? "0" : "1");
  ScopedEnv glibc("GLIBC_TUNABLES", on ? nullptr : "glibc.cpu.hwcaps=-AVX2,-FMA,-AVX512F");
  return run(args, dir);
}

// The distances from the vertices of `a` to the surface of `b`: mean, 95th percentile, largest
// (all +inf when `a` has no vertex).
struct Apart {
  double mean, p95, max;
};
Apart vertexToSurface(const TriangleMesh& a, const TriangleMesh& b) {
  const TriangleDistanceIndex index(b);
  std::vector<double> d;
  for (const auto& v : a.vertices) d.push_back(index.distance(v.cast<double>()));
  if (d.empty()) return {INFINITY, INFINITY, INFINITY};
  std::sort(d.begin(), d.end());
  double sum = 0;
  for (double x : d) sum += x;
  return {sum / double(d.size()), d[d.size() * 95 / 100], d.back()};
}
}  // namespace

// A CPU without AVX2 and FMA (INHAND_NO_AVX2, as CI's second run): the same views rendered both
// ways agree to the millimetre the PNG keeps, and the same frames fused both ways, or the frames
// of each way fused its own way, give models within half a voxel of each other.
TEST(Cli, RenderAndFuseAgreeWithTheAvx2PathsOff) {
  test::TempDir dir;
  const fs::path on = dir.path() / "on", off = dir.path() / "off";
  const std::string render = "render --object builtin:pill_bottle --views 10 --out ";
  ASSERT_EQ(runWithAvx2(true, render + on.string(), dir).code, 0);
  ASSERT_EQ(runWithAvx2(false, render + off.string(), dir).code, 0);
  int64_t valid = 0, validDiffers = 0, apart = 0;
  for (int k = 0; k < 10; ++k) {
    char name[32];
    std::snprintf(name, sizeof name, "depth_%04d.png", k);
    const DepthImage a = readDepthPng(on / name), b = readDepthPng(off / name);
    ASSERT_EQ(a.depth_m.size(), b.depth_m.size());
    for (size_t i = 0; i < a.depth_m.size(); ++i) {
      const bool va = a.depth_m[i] > 0, vb = b.depth_m[i] > 0;
      valid += va || vb;
      validDiffers += va != vb;
      if (va && vb && std::abs(a.depth_m[i] - b.depth_m[i]) > 0.0015f) ++apart;
    }
  }
  ASSERT_GT(valid, 10000);
  EXPECT_LE(double(validDiffers) / double(valid), 0.005) << validDiffers << " of " << valid;
  EXPECT_LE(double(apart) / double(valid), 0.005) << apart << " of " << valid;
  const double voxel = 0.003;
  auto fuse = [&](bool avx2, const fs::path& frames, const std::string& name) {
    const fs::path model = dir.path() / (name + ".ply");
    const Result r = runWithAvx2(avx2,
                                 "fuse --voxel " + std::to_string(voxel) + " --frames " +
                                     frames.string() + " --out " + model.string(),
                                 dir);
    EXPECT_EQ(r.code, 0) << r.output;
    return readPly(model).mesh;
  };
  const TriangleMesh onOn = fuse(true, on, "on_on"), onOff = fuse(false, on, "on_off"),
                     offOff = fuse(false, off, "off_off");
  ASSERT_GT(onOn.vertices.size(), 1000u);
  for (const TriangleMesh* other : {&onOff, &offOff}) {
    const Apart d = vertexToSurface(*other, onOn);
    EXPECT_LE(d.mean, voxel / 2);
    EXPECT_LE(d.max, 2 * voxel);
  }
  // The fusion alone sees the same frames: its two paths differ by round-off.
  EXPECT_LE(vertexToSurface(onOff, onOn).mean, voxel / 20);
}

namespace {
// Whether two models are the same surface up to round-off: every vertex of each within half a
// voxel of the other, mean within a hundredth of a voxel, 95th percentile within a fortieth.
::testing::AssertionResult sameSurface(const TriangleMesh& a, const TriangleMesh& b, double voxel) {
  for (const auto& [x, y] : {std::pair{&a, &b}, std::pair{&b, &a}}) {
    const Apart d = vertexToSurface(*x, *y);
    if (!(d.mean <= voxel / 100 && d.p95 <= voxel / 40 && d.max <= voxel / 2))
      return ::testing::AssertionFailure()
             << "surfaces apart: mean " << 1000 * d.mean << " mm, p95 " << 1000 * d.p95
             << " mm, max " << 1000 * d.max << " mm (voxel " << 1000 * voxel << " mm)";
  }
  return ::testing::AssertionSuccess();
}
}  // namespace

// A replay against a record written on another machine (tests/record_replay.sh): ten in-hand
// frames of a coffee-can scan, with the joints, camera poses and grasp the robot reported, fused
// by `fuse --robot` (the ScanSession a scan fuses with: the robot's pixels carve only, the voxels
// inside it emptied), tracking off so that the poses are the recorded ones. The model is the
// recorded one up to round-off on any CPU; one frame fused 2 mm off is told apart.
TEST(Cli, RecordedFramesReplayToTheRecordedModel) {
  test::TempDir dir;
  const fs::path record = fs::path(INHAND_SOURCE_DIR) / "tests" / "data" / "replay";
  const std::string robot = std::string(INHAND_SOURCE_DIR) + "/data/robots/wam_barretthand.json";
  const double voxel = 0.004;
  auto replay = [&](const fs::path& frames, const std::string& name) {
    const fs::path model = dir.path() / (name + ".ply");
    const Result r =
        run("fuse --frames " + frames.string() + " --robot " + robot + " --tracking off --voxel " +
                std::to_string(voxel) + " --out " + model.string(),
            dir);
    EXPECT_EQ(r.code, 0) << r.output;
    return readPly(model).mesh;
  };
  const TriangleMesh recorded = readPly(record / "model.ply").mesh;
  ASSERT_GT(recorded.vertices.size(), 10000u);
  EXPECT_TRUE(sameSurface(replay(record, "replayed"), recorded, voxel));
  // The same frames with frame 0's camera 2 mm off along its x axis.
  const fs::path shifted = dir.path() / "shifted";
  fs::create_directories(shifted);
  for (const auto& e : fs::directory_iterator(record))
    if (e.path().extension() == ".png") fs::copy_file(e.path(), shifted / e.path().filename());
  Json fj = readJsonFile(record / "frames.json");
  Json& T = fj["frames"][0]["T_B_C"];
  for (int r = 0; r < 3; ++r)
    T[4 * r + 3] = T[4 * r + 3].get<double>() + 0.002 * T[4 * r].get<double>();
  writeTextAtomically(shifted / "frames.json", fj.dump());
  EXPECT_FALSE(sameSurface(replay(shifted, "shifted"), recorded, voxel));
}

// A one-grasp scan with dropped, corrupted and jumping frames: every frame it did not fuse is in
// summary.json's frames_not_fused under its reason (their sum is the number of "frame not fused"
// lines in the log), and repaired frames are counted (a ScanResult once copied the session's
// counters by hand and left six of them at 0).
TEST(Cli, OneGraspScanReportsEveryFrameItDidNotFuse) {
  test::TempDir dir;
  Json config = Json::parse(kQuickConfig);
  config["sim"]["frame_subsample"] = 3;
  config["sim"]["faults"] = {
      {"dropped_frames", 0.15}, {"corrupted_frames", 0.15}, {"pose_jumps", 0.2}};
  config["table_top"]["under_measured_only"] = false;  // the grasp whose views repair a frame
  writeTextAtomically(dir.path() / "faults.json", config.dump());
  const fs::path out = dir.path() / "scan";
  const Result r = run("scan --object builtin:coffee_can --max-grasps 1 --max-views 1 --config " +
                           (dir.path() / "faults.json").string() + " --out " + out.string(),
                       dir);
  ASSERT_EQ(r.code, 0) << r.output;
  const Json s = readJsonFile(out / "summary.json");
  const Json& nf = s.at("frames_not_fused");
  int sum = 0;
  for (const auto& [k, v] : nf.items()) sum += v.get<int>();
  int lines = 0;
  for (size_t at = r.output.find("frame not fused"); at != std::string::npos;
       at = r.output.find("frame not fused", at + 1))
    ++lines;
  EXPECT_EQ(sum, lines) << nf;
  EXPECT_GT(nf.at("dropped_or_empty").get<int>(), 0) << nf;
  EXPECT_GT(nf.at("off_path").get<int>(), 0) << nf;
  EXPECT_GT(s.at("frames_repaired").get<int>(), 0) << s.at("frames_repaired");
}

// The loop closed on an exported box (docs/asset.md): the true box resting on another face than
// the one its grasps were ranked on first, turned 30°, is found with the asset alone within
// 3 mm / 3° (up to the box's symmetry) and lifted with physics by the first grasp of the set.
// Bad input: exit 1 naming the problem, no report.
TEST(Cli, RegraspTestFindsAndLiftsAnExportedBoxInANewPose) {
  test::TempDir dir;
  writePly(dir.path() / "box.ply", makeBox(Vec3(0.06, 0.05, 0.10)));
  const fs::path asset = dir.path() / "asset", report = dir.path() / "report.json";
  Result r = run("export " + (dir.path() / "box.ply").string() +
                     " --format mjcf --ranked 3 --out " + asset.string(),
                 dir);
  ASSERT_EQ(r.code, 0) << r.output;
  const std::string box = (dir.path() / "box.ply").string();
  const std::vector<std::pair<std::string, std::string>> bad{
      {(dir.path() / "none").string() + " --object " + box, "not an asset directory"},
      {asset.string() + " --object " + box + " --rest-pose 99", "--rest-pose"},
      {asset.string() + " --object " + box + " --heading 1000", "--heading"},
      {asset.string() + " --object " + (dir.path() / "missing.obj").string(), "missing.obj"}};
  for (const auto& [args, message] : bad) {
    const Result b = run("regrasp-test " + args + " --out " + report.string(), dir);
    EXPECT_EQ(b.code, 1) << args << "\n" << b.output;
    EXPECT_NE(b.output.find(message), std::string::npos) << args << "\n" << b.output;
    EXPECT_FALSE(fs::exists(report)) << args;
  }
  r = run("regrasp-test " + asset.string() + " --object " + box +
              " --rest-pose 1 --heading 30 --out " + report.string(),
          dir);
  ASSERT_EQ(r.code, 0) << r.output;
  const Json j = readJsonFile(report);
  EXPECT_TRUE(j.at("held").get<bool>()) << r.output;
  EXPECT_GT(j.at("rose_m").get<double>(), 0.1);
  EXPECT_TRUE(j.at("robot_says_lifted").get<bool>()) << r.output;
  EXPECT_NEAR(j.at("weighed_kg").get<double>(), j.at("asset_mass_kg").get<double>(),
              0.5 * j.at("asset_mass_kg").get<double>());
  const Json& f = j.at("found");
  EXPECT_LT(f.at("centre_error_m").get<double>(), 0.003) << r.output;
  EXPECT_LT(f.at("adds_m").get<double>(), 0.001) << r.output;
  EXPECT_TRUE(f.at("within_3mm_3deg").get<bool>());
  EXPECT_GE(j.at("chosen").get<int>(), 0);
}
