// Checkpoints and resume (scan/checkpoint.h): a scan stopped during a view, during a re-grasp or
// during a later grasp's views, resumed from its last checkpoint, ends as the scan that was
// never stopped: the same views, grasps and model, voxel for voxel.
#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <string>

#include "inhand/core/error.h"
#include "inhand/core/pose.h"
#include "inhand/driver/simulated_scan.h"
#include "inhand/geometry/builtin_objects.h"
#include "inhand/scan/checkpoint.h"
#include "inhand/scan/records.h"
#include "test_util.h"

using namespace inhand;
namespace fs = std::filesystem;

namespace {

// A short two-grasp scan from the table: coarse voxels, few directions, two views per grasp.
ScanConfig fastConfig(bool tracking) {
  ScanConfig c = test::quickScanConfig();
  c.scan.tracking.enabled = tracking;
  c.scan.tracking.filter = tracking;  // its state goes through the checkpoint too
  if (tracking) c.sim.arm_error_m = 0.01;
  return c;
}

const TriangleMesh& object() {
  static const TriangleMesh m = loadObject("builtin:coffee_can");
  return m;
}

// Attempts as recorded, less when each was decided (wall-clock seconds, which no two runs share).
Json attemptsOf(const std::vector<PickAttempt>& attempts) {
  Json j = attemptsJson(attempts);
  for (Json& a : j) a.erase("at_s");
  return j;
}

void expectSameScan(const SimulatedScan& a, const SimulatedScan& b) {
  const MultiGraspResult &x = a.result, &y = b.result;
  EXPECT_EQ(terminationName(x.scan.termination), terminationName(y.scan.termination));
  ASSERT_EQ(x.grasps.size(), y.grasps.size());
  for (size_t g = 0; g < x.grasps.size(); ++g) {
    EXPECT_EQ(x.grasps[g].views, y.grasps[g].views) << g;
    EXPECT_TRUE(x.grasps[g].T_O_palm.isApprox(y.grasps[g].T_O_palm, 0)) << g;
    EXPECT_EQ(attemptsOf(x.grasps[g].attempts), attemptsOf(y.grasps[g].attempts)) << g;
    EXPECT_EQ(x.grasps[g].model.mesh.vertices.size(), y.grasps[g].model.mesh.vertices.size());
  }
  ASSERT_EQ(x.scan.views.size(), y.scan.views.size());
  for (size_t v = 0; v < x.scan.views.size(); ++v) {
    EXPECT_EQ(x.scan.views[v].dir_O, y.scan.views[v].dir_O) << v;
    EXPECT_EQ(x.scan.views[v].frames, y.scan.views[v].frames) << v;
  }
  EXPECT_EQ(x.scan.frames, y.scan.frames);
  EXPECT_EQ(a.frames_fused_in_hand, b.frames_fused_in_hand);
  EXPECT_EQ(a.palm_error_median_m, b.palm_error_median_m);
  ASSERT_EQ(x.scan.model.mesh.vertices.size(), y.scan.model.mesh.vertices.size());
  ASSERT_EQ(x.scan.model.mesh.triangles.size(), y.scan.model.mesh.triangles.size());
  for (size_t i = 0; i < x.scan.model.mesh.vertices.size(); ++i) {
    ASSERT_EQ(x.scan.model.mesh.vertices[i], y.scan.model.mesh.vertices[i]) << i;
    ASSERT_EQ(x.scan.model.variance[i], y.scan.model.variance[i]) << i;
  }
  EXPECT_EQ(x.table_top.has_value(), y.table_top.has_value());
  if (x.table_top && y.table_top) {
    EXPECT_EQ(attemptsOf(x.table_top->attempts), attemptsOf(y.table_top->attempts));
    EXPECT_EQ(x.table_top->poses.size(), y.table_top->poses.size());
    // The model aligned again with the table-top frame the checkpoint carries, as it was.
    EXPECT_EQ(tableTopRecordJson(*x.table_top).at("reanchor"),
              tableTopRecordJson(*y.table_top).at("reanchor"));
    EXPECT_TRUE(x.table_top->reanchor.found);
  }
}

// Where to stop a scan: at the n-th in-hand frame, or when the log says a grasp's views ended.
struct StopAt {
  int frame = -1;            // stop once this many in-hand frames were handled
  std::string log_contains;  // stop at the first log line containing this
};

SimulatedScan stoppedThenResumed(const ScanConfig& config, const StopAt& at,
                                 const fs::path& checkpoint, SimulatedScan* stopped) {
  bool stop = false;
  int frames = 0;
  ScanProgress p;
  p.frame = [&](const FrameReport&, const JointVector&, const Iso3&) {
    if (at.frame >= 0 && ++frames >= at.frame) stop = true;
  };
  p.log = [&](const std::string& line) {
    if (!at.log_contains.empty() && line.find(at.log_contains) != std::string::npos) stop = true;
  };
  p.interrupted = [&] { return stop; };
  SimulatedScanCheckpoints cp;
  cp.file = checkpoint;
  cp.extra = {{"who", "test"}};
  *stopped = runSimulatedScan(test::wam(), object(), config, p, cp);
  EXPECT_TRUE(fs::exists(checkpoint));
  EXPECT_EQ(readScanCheckpointExtra(checkpoint).at("caller").at("who"), "test");
  cp.resume = true;
  return runSimulatedScan(test::wam(), object(), config, {}, cp);
}

struct Reference {
  SimulatedScan scan;
  int frames = 0;  // in-hand frames
  explicit Reference(const ScanConfig& config) {
    ScanProgress p;
    p.frame = [&](const FrameReport&, const JointVector&, const Iso3&) { ++frames; };
    scan = runSimulatedScan(test::wam(), object(), config, p);
  }
};

const Reference& reference(bool tracking) {
  static const Reference plain(fastConfig(false)), tracked(fastConfig(true));
  return tracking ? tracked : plain;
}

}  // namespace

TEST(Checkpoint, TheReferenceScanHasTwoGraspsToStopIn) {
  const Reference& r = reference(false);
  ASSERT_EQ(r.scan.result.grasps.size(), 2u) << terminationName(r.scan.result.scan.termination);
  EXPECT_GE(r.scan.result.grasps[0].views, 2);
  EXPECT_GE(r.scan.result.grasps[1].views, 1);
}

TEST(Checkpoint, StoppedDuringTheFirstGraspsSecondViewResumesToTheSameScan) {
  const Reference& r = reference(false);
  const int firstView = r.scan.result.scan.views.at(0).frames;
  test::TempDir dir;
  SimulatedScan stopped;
  const SimulatedScan resumed = stoppedThenResumed(fastConfig(false), {firstView + 2, ""},
                                                   dir.path() / "scan.inhand", &stopped);
  EXPECT_EQ(stopped.result.scan.termination, Termination::kInterrupted);
  EXPECT_LT(stopped.result.scan.frames, r.scan.result.scan.frames);
  EXPECT_FALSE(stopped.result.scan.model.mesh.vertices.empty());  // the model so far
  expectSameScan(r.scan, resumed);
}

TEST(Checkpoint, StoppedDuringTheRegraspResumesToTheSameScan) {
  const Reference& r = reference(false);
  test::TempDir dir;
  SimulatedScan stopped;
  // "grasp 1: N views (...)" is logged when its views have ended, before the put-down, the
  // grasp planning and the pick-up: the stop comes during the re-grasp.
  const SimulatedScan resumed = stoppedThenResumed(fastConfig(false), {-1, "grasp 1: "},
                                                   dir.path() / "scan.inhand", &stopped);
  EXPECT_EQ(stopped.result.scan.termination, Termination::kInterrupted);
  EXPECT_EQ(stopped.result.grasps.size(), 1u);
  expectSameScan(r.scan, resumed);
}

TEST(Checkpoint, StoppedDuringTheSecondGraspWithTrackingResumesToTheSameScan) {
  const Reference& r = reference(true);
  ASSERT_EQ(r.scan.result.grasps.size(), 2u);
  test::TempDir dir;
  SimulatedScan stopped;
  const SimulatedScan resumed = stoppedThenResumed(fastConfig(true), {r.frames - 3, ""},
                                                   dir.path() / "scan.inhand", &stopped);
  EXPECT_EQ(stopped.result.scan.termination, Termination::kInterrupted);
  EXPECT_EQ(stopped.result.grasps.size(), 1u);  // the second grasp's views were under way
  expectSameScan(r.scan, resumed);
}

TEST(Checkpoint, RefusesAFileThatIsNotOneAndNamesIt) {
  test::TempDir dir;
  const fs::path bad = dir.path() / "not_a_checkpoint.inhand";
  std::ofstream(bad) << "INHAND-SESSION 1\n5\n{\"a\":";
  SimulatedScanCheckpoints cp;
  cp.file = bad;
  cp.resume = true;
  try {
    runSimulatedScan(test::wam(), object(), fastConfig(false), {}, cp);
    FAIL() << "no error";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("not_a_checkpoint.inhand"), std::string::npos) << e.what();
  }
  cp.file = dir.path() / "missing.inhand";
  EXPECT_THROW(runSimulatedScan(test::wam(), object(), fastConfig(false), {}, cp), Error);
}

// One JSON form per record (scan/records.h): a view's and a grasp's record round-trip exactly
// under summary.json's key names, and records written under the names checkpoints used before
// (dir_O, gain, tried, epsilon, hole_area_m2, attempts) read back the same.
TEST(Records, RoundTripAndReadTheNamesOlderCheckpointsUsed) {
  ViewRecord v;
  v.dir_O = Vec3(0.6, -0.8, 0);
  v.T_O_C = lookAt(Vec3(0.3, -0.2, 0.5), Vec3::Zero());
  v.quality = 0.25;
  v.gain = 0.125;
  v.t_q = 0.01;
  v.unresolved = 3.5;
  v.cost_s = 2;
  v.frames = 17;
  v.candidates = 400;
  Json j = viewRecordJson(v);
  EXPECT_EQ(j.at("direction_O").size(), 3u);
  EXPECT_EQ(j.at("predicted_gain").get<double>(), 0.125);
  ViewRecord back = viewRecordFrom(j);
  EXPECT_EQ(back.dir_O, v.dir_O);
  EXPECT_TRUE(back.T_O_C.isApprox(v.T_O_C, 0));
  EXPECT_EQ(back.gain, v.gain);
  EXPECT_EQ(back.frames, 17);
  j["dir_O"] = j.at("direction_O");
  j["gain"] = j.at("predicted_gain");
  j.erase("direction_O");
  j.erase("predicted_gain");
  back = viewRecordFrom(j);
  EXPECT_EQ(back.dir_O, v.dir_O);
  EXPECT_EQ(back.gain, v.gain);
  ViewRecord initial;  // an unknown gain is written as null and read back as NaN
  EXPECT_TRUE(viewRecordJson(initial).at("predicted_gain").is_null());
  EXPECT_TRUE(std::isnan(viewRecordFrom(viewRecordJson(initial)).gain));

  GraspRecord g;
  g.q = JointVector::LinSpaced(7, -1, 1);
  g.tried = 40;
  g.epsilon = 0.2;
  g.hole_area_m2 = 0.003;
  g.termination = Termination::kNoViewAboveThreshold;
  PickAttempt a;
  a.outcome = PickOutcome::kDropped;
  a.hold_test = 0;
  a.hold_failure = HoldFailure::kDroppedInTurn;
  a.hold_unseen = 0;
  a.pinch = true;
  g.attempts = {a};
  g.ranked.push_back({Iso3::Identity(), g.q, 0.5, 0.1});
  Json k = graspRecordJson(g);
  EXPECT_EQ(k.at("poses_tried").get<int>(), 40);
  EXPECT_EQ(k.at("pick_up_attempts").at(0).at("outcome"), "dropped");
  EXPECT_EQ(k.at("pick_up_attempts").at(0).at("hold_failure"), "dropped_in_turn");
  for (const auto& [now, before] : {std::pair{"poses_tried", "tried"},
                                    {"stability_epsilon", "epsilon"},
                                    {"unknown_area_m2", "hole_area_m2"},
                                    {"pick_up_attempts", "attempts"}}) {
    k[before] = k.at(now);
    k.erase(now);
  }
  const GraspRecord h = graspRecordFrom(k);
  EXPECT_EQ(h.q, g.q);
  EXPECT_EQ(h.tried, 40);
  EXPECT_EQ(h.epsilon, 0.2);
  EXPECT_EQ(h.hole_area_m2, 0.003);
  EXPECT_EQ(h.termination, Termination::kNoViewAboveThreshold);
  ASSERT_EQ(h.attempts.size(), 1u);
  EXPECT_EQ(h.attempts[0].outcome, PickOutcome::kDropped);
  EXPECT_EQ(h.attempts[0].hold_failure, HoldFailure::kDroppedInTurn);
  EXPECT_EQ(h.attempts[0].hold_unseen, 0);
  EXPECT_TRUE(h.attempts[0].pinch);
  Json older = k.at("attempts");  // written before hold_unseen and pinch were recorded
  older[0].erase("hold_unseen");
  older[0].erase("pinch");
  EXPECT_EQ(attemptsFrom(older)[0].hold_unseen, -1);
  EXPECT_FALSE(attemptsFrom(older)[0].pinch);
  ASSERT_EQ(h.ranked.size(), 1u);
  EXPECT_EQ(h.ranked[0].epsilon, 0.1);
  k["pick_up_attempts"] = Json::array({{{"outcome", "fell"}}});
  EXPECT_THROW(graspRecordFrom(k), std::exception);  // an outcome with no name

  TableTopRecord t;  // the model aligned again with the table-top frame
  t.reanchor.tried = t.reanchor.found = t.reanchor.applied = true;
  t.reanchor.gap_m = 0.0012;
  t.reanchor.shift_m = 0.0005;
  t.reanchor.turn_rad = 0.1;
  const TableTopRecord u = tableTopRecordFrom(tableTopRecordJson(t));
  EXPECT_TRUE(u.reanchor.applied);
  EXPECT_EQ(u.reanchor.gap_m, 0.0012);
  EXPECT_NEAR(u.reanchor.turn_rad, 0.1, 1e-12);
  Json old = tableTopRecordJson(t);  // a record written before it had one
  old.erase("reanchor");
  EXPECT_FALSE(tableTopRecordFrom(old).reanchor.tried);
}
