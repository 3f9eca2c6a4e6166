// Faults injected in the simulator (SimOptions::faults): the scan survives each, says so in its
// counters, and the model stays the model of the object (docs/reliability.md has the figures).
#include <gtest/gtest.h>

#include <algorithm>
#include <cstdio>

#include "inhand/driver/simulated_scan.h"
#include "inhand/geometry/builtin_objects.h"
#include "test_util.h"

using namespace inhand;

namespace {

// A short two-grasp scan of the coffee can from the table.
ScanConfig fastConfig() {
  ScanConfig c = test::quickScanConfig(3);
  c.eval.samples = 6000;
  return c;
}

SimulatedScan scanWith(const SimFaults& faults, int max_grasps = 2, unsigned seed = 0) {
  static const TriangleMesh can = loadObject("builtin:coffee_can");
  ScanConfig c = fastConfig();
  c.sim.faults = faults;
  if (seed > 0) c.sim.seed = seed;
  c.multi.max_grasps = max_grasps;
  return runSimulatedScan(test::wam(), can, c);
}

const SimulatedScan& clean() {
  static const SimulatedScan s = scanWith(SimFaults{});
  return s;
}

// The model of a faulty scan against the clean one: nearly the same coverage and accuracy.
void expectNearTheCleanModel(const SimulatedScan& s) {
  EXPECT_GE(s.metrics.coverage, clean().metrics.coverage - 0.03);
  EXPECT_LE(s.metrics.accuracy_mean_mm, clean().metrics.accuracy_mean_mm + 0.5);
}

}  // namespace

TEST(Faults, TheCleanScanRefusesNoFrame) {
  const ScanResult& r = clean().result.scan;
  EXPECT_EQ(r.frames_dropped + r.frames_off_path + r.frames_unsupported + r.frames_repaired, 0);
  EXPECT_EQ(r.frames_moving, 0);  // no slip found where there was none
  EXPECT_TRUE(r.slips.empty());
  EXPECT_GE(clean().metrics.coverage, 0.95);
  EXPECT_EQ(clean().result.grasps.size(), 2u);
}

TEST(Faults, DroppedAndCorruptedFramesAreSkippedOrRepaired) {
  SimFaults f;
  f.dropped_frames = 0.15;
  f.corrupted_frames = 0.15;
  const SimulatedScan s = scanWith(f);
  EXPECT_GT(s.faults.dropped_frames, 0);
  EXPECT_GE(s.faults.corrupted_frames, 3);  // zeros, NaNs and a stripe at least once each
  const ScanResult& r = s.result.scan;
  EXPECT_GT(r.frames_dropped, 0);   // empty images and all-zero frames
  EXPECT_GT(r.frames_repaired, 0);  // NaN depths taken as no return
  EXPECT_NE(r.termination, Termination::kRunning);
  expectNearTheCleanModel(s);
}

TEST(Faults, JointStatesThatJumpAreNotFusedWith) {
  SimFaults f;
  f.pose_jumps = 0.1;
  const SimulatedScan s = scanWith(f);
  EXPECT_GT(s.faults.pose_jumps, 0);
  // Every jump reported during a view is refused (those during lifts never reach the fusion).
  EXPECT_GT(s.result.scan.frames_off_path, 0);
  EXPECT_LE(s.result.scan.frames_off_path, s.faults.pose_jumps);
  expectNearTheCleanModel(s);
}

// Half the motions stop between 20 and 80 % of the way: each is planned again from where the
// arm stands, the scan ends on its own, and the model is as accurate as the clean one. A view
// whose motion stopped short takes fewer frames (1–3 against 3–5 here), so the coverage may
// fall short of the clean scan's by more than the other faults': 94.3 against 99.97 % with
// AVX2/FMA off, 99.83 against 99.80 % with them.
TEST(Faults, MotionsStoppedShortAreReplannedFromWhereTheArmStands) {
  SimFaults f;
  f.stopped_short = 0.5;
  const SimulatedScan s = scanWith(f);
  std::printf("stopped short: coverage %.4f (clean %.4f), accuracy %.3f mm (clean %.3f mm)\n",
              s.metrics.coverage, clean().metrics.coverage, s.metrics.accuracy_mean_mm,
              clean().metrics.accuracy_mean_mm);
  EXPECT_GT(s.faults.stopped_short, 0);
  EXPECT_NE(s.result.scan.termination, Termination::kRunning);
  EXPECT_GE(s.metrics.coverage, clean().metrics.coverage - 0.08);
  EXPECT_LE(s.metrics.accuracy_mean_mm, clean().metrics.accuracy_mean_mm + 0.5);
}

TEST(Faults, AnObjectDroppedDuringAViewEndsTheGraspAndIsPickedUpAgain) {
  SimFaults f;
  f.drop_in_motion = 2;  // the third motion with the object in the hand
  const SimulatedScan s = scanWith(f, 3);
  EXPECT_EQ(s.faults.object_drops, 1);
  ASSERT_GE(s.result.grasps.size(), 2u);
  EXPECT_EQ(s.result.grasps[0].termination, Termination::kObjectLost);
  EXPECT_GT(s.result.scan.frames_unsupported, 0);
  expectNearTheCleanModel(s);  // the frames without the object were not fused
}

// Physics: the object falls out of the hand during the third motion with it in the hand, lands
// beneath the hand and settles there, away from where it rested before the grasp. The scan
// notices (the frames stop showing it), looks for it beneath where the hand held it first, finds
// it there (the box bounces and tips over: 17 cm from beneath the hand, 24 cm from where it
// rested) and picks it up again, with no pick-up that met nothing.
TEST(Faults, AnObjectThatFallsFromTheHandIsFoundBeneathIt) {
  ScanConfig c = fastConfig();
  c.sim.physics.enabled = true;
  c.sim.faults.drop_in_motion = 2;
  c.multi.max_grasps = 2;
  std::vector<std::string> lines;
  ScanProgress progress;
  progress.log = [&](const std::string& line) { lines.push_back(line); };
  const SimulatedScan s =
      runSimulatedScan(test::wam(), loadObject("builtin:cracker_box"), c, progress);
  std::string log;
  for (const std::string& l : lines) log += l + "\n";
  EXPECT_EQ(s.faults.object_drops, 1);
  ASSERT_GE(s.result.grasps.size(), 1u) << log;
  EXPECT_EQ(s.result.grasps[0].termination, Termination::kObjectLost);
  // Found at the first place it was looked for: beneath the hand.
  const auto lost = std::find_if(lines.begin(), lines.end(),
                                 [](const std::string& l) { return l.rfind("grasp 1:", 0) == 0; });
  ASSERT_NE(lost, lines.end());
  ASSERT_NE(lost + 1, lines.end());
  EXPECT_EQ((lost + 1)->rfind("the object found on the table", 0), 0u) << *(lost + 1);
  // Picked up again where it was found: every re-grasp pick-up reached it (none met nothing),
  // whether or not its grasp held (the box lands lying, which the hand may fail to lift).
  std::vector<PickAttempt> regrasps = s.result.failed_regrasp_attempts;
  for (size_t g = 1; g < s.result.grasps.size(); ++g)
    regrasps.insert(regrasps.end(), s.result.grasps[g].attempts.begin(),
                    s.result.grasps[g].attempts.end());
  ASSERT_FALSE(regrasps.empty()) << log;
  EXPECT_EQ(countOutcome(regrasps, PickOutcome::kNoContact), 0) << log;
}

// The coffee can falls out of the hand during the third motion with it in the hand. Of the
// three frames in a row that end the grasp, two are frames tracking cannot align (the camera sees
// through the model's aligned points): they are checked where the last aligned frame held the
// can (without that check the grasp ran on to max_views with the hand empty).
TEST(Faults, AnObjectDroppedWithNoRegraspLeftEndsAsObjectLost) {
  SimFaults f;
  f.drop_in_motion = 2;
  const SimulatedScan s = scanWith(f, 1);
  EXPECT_EQ(s.faults.object_drops, 1);
  EXPECT_EQ(s.result.scan.termination, Termination::kObjectLost);
  EXPECT_GE(s.result.scan.frames_unsupported, ScanOptions{}.checks.lost_after);
  EXPECT_FALSE(s.result.scan.model.mesh.vertices.empty());  // the model so far
}

// The object slips 8 mm in the hand halfway through the grasp's second motion: the model
// aligned with each frame finds it (TrackingOptions::slip_check), the frames taken while it seems
// to move are not fused, and the grasp is corrected. Against the same scan with the check off
// (the model smeared by the slip) and the same object without a slip (nothing found). The mug:
// its handle shows a slip in any direction (a can's slip along its axis is seen only at its
// ends; on the cracker box held in a fingertip pinch, the first grasp's slip is found only at
// the third view and the correction leaves the 8 mm error: docs/physics.md). One grasp: a
// second grasp's slip, with the model nearly whole, is found only where the frames after it
// show the mug's handle or ends (without AVX2 the second grasp's slip went unfound and its
// frames were fused 8 mm off).
TEST(Faults, AnObjectThatSlipsIsFoundAndTheGraspCorrected) {
  SimFaults f;
  f.slip_m = 0.008;
  auto scan = [&](const SimFaults& faults, bool check) {
    ScanConfig c = fastConfig();
    c.sim.faults = faults;
    c.scan.tracking.slip_check = check;
    c.multi.max_grasps = 1;
    // The grasp this scenario was built on: the first candidate of the table-top model closed
    // down to the table behind the mug. With under_measured_only the kinematic simulator drops
    // the first candidate, the second holds by the body, and the 8 mm slip moves the mug's
    // surface by 2.7 mm as the frames see it: not found.
    c.multi.table_top.under_measured_only = false;
    return runSimulatedScan(test::wam(), loadObject("builtin:mug"), c);
  };
  const SimulatedScan s = scan(f, true), unchecked = scan(f, false), still = scan({}, true);
  EXPECT_TRUE(still.result.scan.slips.empty());
  EXPECT_EQ(still.result.scan.frames_moving, 0);
  EXPECT_GE(s.faults.slips, 1);
  const ScanResult& r = s.result.scan;
  ASSERT_FALSE(r.slips.empty());
  EXPECT_LE(int(r.slips.size()), s.faults.slips);  // nothing found that did not happen
  for (const SlipRecord& e : r.slips) {
    EXPECT_GT(e.moved_m, 0.004);  // the grasp moved by about the slip (8 mm)
    EXPECT_LT(e.moved_m, 0.016);
    EXPECT_GE(e.frames, 2);  // two frames bear a slip out before the grasp moves
  }
  EXPECT_GE(r.frames_moving, 2 * int(r.slips.size()));
  // The object's pose as fused and the model's accuracy clearly better than with the slip left
  // alone (recorded: 2.2 against 8.0 mm, 0.91 against 2.67 mm; with AVX2/FMA off 2.4 against
  // 8.0 mm, 1.11 against 2.03 mm). Its coverage, one grasp's, depends on the views the scan
  // chose after the slip, not on the check: 75.8 against 56.6 % within 3 mm, and with AVX2/FMA
  // off 58.9 against 65.8 % (the scan without a slip 74.9 and 74.8 %). At least half the mug.
  std::printf(
      "slip checked: object %.2f mm, coverage %.1f %%, %.2f mm; unchecked: %.2f mm, %.1f %%, "
      "%.2f mm; no slip: %.2f mm, %.1f %%, %.2f mm\n",
      1000 * s.object_error_median_m, 100 * s.metrics.coverage, s.metrics.accuracy_mean_mm,
      1000 * unchecked.object_error_median_m, 100 * unchecked.metrics.coverage,
      unchecked.metrics.accuracy_mean_mm, 1000 * still.object_error_median_m,
      100 * still.metrics.coverage, still.metrics.accuracy_mean_mm);
  EXPECT_LT(s.object_error_median_m, 0.7 * unchecked.object_error_median_m);
  EXPECT_GT(s.metrics.coverage, 0.5);
  EXPECT_LT(s.metrics.accuracy_mean_mm, 0.7 * unchecked.metrics.accuracy_mean_mm);
}

// Nothing moves in the kinematic simulator's hand: a scan whose frames are less noisy than the
// sensor model says (noise off) finds no slip and follows no creep. Comparing the slip check's
// residuals without the sensor's σ as a floor, two residuals of a few tenths of a millimetre
// told a "slip" from the held pose (recorded: 3 creeps followed, 2 frames not fused as moving).
TEST(Faults, AFrameLessNoisyThanTheSensorModelShowsNoSlip) {
  ScanConfig c;  // every default (the quick scan's 4 mm voxels showed no such slip) …
  setPhysics(false, Json(), &c);  // … but the kinematic simulator's hand
  c.eval.samples = 6000;
  c.sim.noise = false;
  c.multi.max_grasps = 2;
  const SimulatedScan s = runSimulatedScan(test::wam(), loadObject("builtin:cracker_box"), c);
  EXPECT_TRUE(s.result.scan.slips.empty());
  EXPECT_EQ(s.result.scan.creeps_followed, 0);
  EXPECT_EQ(s.result.scan.frames_moving, 0);
}

// Physics: a held object creeps in the hand under the motions' accelerations, a millimetre or
// so at a time, too little for a slip (tracking.slip_m). Followed (tracking.creep_m), each creep
// moves the scan's grasp: nearer where the object truly sits in the hand, over four scans where
// it creeps (the pill bottle and the coffee can with MuJoCo's soft contacts without the no-slip
// pass, as the simulator's contacts were before they were made stiff, docs/physics.md; the
// cracker box with those and with the simulator's own). Recorded: 9 creeps, the grasp's error
// 24.3 mm summed before them and 13.9 mm after, 8 of 9 nearer; with AVX2/FMA off
// (INHAND_NO_AVX2=1) 6 creeps (the soft cracker box followed none), 13.1 -> 7.0 mm, 6 of 6
// nearer: the count of creeps differs between the two, hence four scans. The grasp is
// compared, not two whole scans: once a grasp moves, the rest of the scan takes another path,
// and two scans' medians differ by a millimetre either way (the pill bottle's: 3.2 mm with
// creep followed, 2.3 without). Not every creep followed is right: an alignment with a coarse
// model is biased by millimetres along what the frame constrains least (a 2.5 mm slip injected in
// the kinematic simulator, below the slip threshold, was followed to 4.1 mm off); the physics test
// set with creep_m 0 scanned worse (coverage >= 97 % on 19 of 33 against 22;
// docs/test_set_physics.md).
TEST(Faults, AnObjectThatCreepsInTheHandIsFollowed) {
  struct Case {
    const char* object;
    bool soft;
  };
  int creeps = 0, nearer = 0;
  double before = 0, after = 0;
  for (const Case& k : {Case{"builtin:pill_bottle", true}, Case{"builtin:cracker_box", true},
                        Case{"builtin:cracker_box", false}, Case{"builtin:coffee_can", true}}) {
    ScanConfig c = fastConfig();
    c.sim.physics.enabled = true;
    if (k.soft) {
      c.sim.physics.noslip_iterations = 0;
      c.sim.physics.timestep_s = 0.002;
      c.sim.physics.contact_timeconst_s = 0.005;
      c.sim.physics.table_contact_timeconst_s = 0.005;
      c.multi.table_top.under_measured_only = false;  // the grasp the scenario was built on
    }
    c.multi.max_grasps = 1;
    const SimulatedScan s = runSimulatedScan(test::wam(), loadObject(k.object), c);
    EXPECT_LE(int(s.creep_grasp_error_m.size()), s.result.scan.creeps_followed) << k.object;
    for (const auto& [b, a] : s.creep_grasp_error_m) {
      std::printf("%s%s: a creep followed, the grasp %.2f -> %.2f mm off\n", k.object,
                  k.soft ? " (soft contacts)" : "", 1000 * b, 1000 * a);
      ++creeps;
      nearer += a < b;
      before += b;
      after += a;
    }
  }
  EXPECT_GE(creeps, 4);
  EXPECT_GE(nearer, (3 * creeps + 3) / 4);  // three in four at least
  EXPECT_LT(after, 0.8 * before);
  // Off (creep_m 0), none is followed.
  ScanConfig c = fastConfig();
  c.sim.physics.enabled = true;
  c.scan.tracking.creep_m = 0;
  c.multi.max_grasps = 1;
  EXPECT_EQ(runSimulatedScan(test::wam(), loadObject("builtin:cracker_box"), c)
                .result.scan.creeps_followed,
            0);
}

TEST(Faults, RefusedMotionsAreReplannedAndFailedPickUpsTryTheNextCandidate) {
  SimFaults f;
  f.refused_motions = 0.5;
  f.failed_pickups = 0.5;
  // Whether a pick-up fails is drawn: the first of a few seeds whose scan had one.
  SimulatedScan s;
  for (unsigned seed = 1; seed <= 4; ++seed) {
    s = scanWith(f, 2, seed);
    if (s.faults.failed_pickups > 0) break;
  }
  EXPECT_GT(s.faults.refused_motions, 0);
  ASSERT_GT(s.faults.failed_pickups, 0);
  // Each failed pick-up is an attempt that met nothing; the scan went on to the next candidate.
  int noContact = 0;
  if (s.result.table_top)
    noContact += countOutcome(s.result.table_top->attempts, PickOutcome::kNoContact);
  for (const GraspRecord& g : s.result.grasps)
    noContact += countOutcome(g.attempts, PickOutcome::kNoContact);
  noContact += countOutcome(s.result.failed_regrasp_attempts, PickOutcome::kNoContact);
  EXPECT_GE(noContact, s.faults.failed_pickups);
  EXPECT_NE(s.result.scan.termination, Termination::kRunning);
  // Ending with regrasp_failed keeps the first grasp's model (the can seen from one grasp: about
  // half of it), with pick_up_failed (the budget of grasp.max_failed_pick_ups spent on the first
  // grasp: one time in eight at this rate) the table-top frames' model; else as good as the clean
  // scan.
  if (s.result.scan.termination == Termination::kPickUpFailed) {
    ASSERT_TRUE(s.result.table_top.has_value());
    EXPECT_EQ(int(s.result.table_top->attempts.size()), GraspOptions{}.max_failed_pick_ups);
  }
  if (s.result.scan.termination == Termination::kRegraspFailed ||
      s.result.scan.termination == Termination::kPickUpFailed)
    EXPECT_GE(s.metrics.coverage, 0.4);
  else
    EXPECT_GE(s.metrics.coverage, clean().metrics.coverage - 0.05)
        << terminationName(s.result.scan.termination);
}
