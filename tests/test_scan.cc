// The scan loop in the simulator: the paper's Fig. 3 hand handling, termination, determinism.
#include <gtest/gtest.h>

#include <algorithm>

#include "inhand/geometry/builtin_objects.h"
#include "inhand/scan/multi_grasp.h"
#include "inhand/scan/scan.h"
#include "inhand/sim/sim_world.h"
#include "test_util.h"

using namespace inhand;
namespace fs = std::filesystem;

namespace {

using test::wam;

// A fast configuration for tests: coarser voxels and candidate sets than the defaults.
ScanOptions testOptions() {
  ScanOptions o;
  o.voxel_m = 0.003;
  o.planner.directions = 80;
  o.planner.rolls = 4;
  return o;
}

struct ScanRun {
  ScanResult result;
  Iso3 T_O_palm;
  JointVector q;
};

ScanRun scanCan(const ScanOptions& o, uint64_t seed = 1, const SimFaults& faults = {}) {
  TriangleMesh can = loadObject("builtin:coffee_can");
  auto [T_O_palm, q] = defaultGrasp(wam(), can);
  SimOptions so;
  so.seed = seed;
  so.frame_subsample = 4;
  so.faults = faults;
  SimWorld world(wam(), can, T_O_palm, DepthCameraOptions{}, NoiseModelOptions{}, so);
  world.q = q;
  SimRobot robot(&world);
  SimSensor sensor(&world, DepthCameraOptions{});
  ScanOptions opt = o;
  opt.planner.seed = seed;
  ScanRun r{scanSingleGrasp(robot, sensor, T_O_palm, T_O_palm * Vec3(0, 0, wam().graspOffset()),
                            opt, NoiseModelOptions{}),
            T_O_palm, q};
  return r;
}

// Distance to the coffee can (a cylinder Ø 102 × 139 mm centred at the origin, axis z).
double canDistance(const Vec3& p) {
  Vec2 e(std::hypot(p.x(), p.y()) - 0.051, std::abs(p.z()) - 0.0695);
  return e.cwiseMax(0.0).norm() + std::min(e.maxCoeff(), 0.0);
}

}  // namespace

// Paper Fig. 3: (a) fusing every measurement grows finger-shaped surface on the model; (c)
// carving with hand measurements and emptying the hand's volume leaves none, and the surface
// under the fingers stays uncertain (hole-filled).
TEST(Scan, HandAwareFusionRemovesFingersAndKeepsUncertaintyUnderThem) {
  ScanOptions o = testOptions();
  o.max_views = 0;  // the initial trajectory is enough to see the hand from all round
  int farObserved[2] = {0, 0}, holesNearHand[2] = {0, 0}, nearHand[2] = {0, 0};
  const HandMode modes[2] = {HandMode::kNaive, HandMode::kCarveAndEmpty};
  for (int k = 0; k < 2; ++k) {
    o.hand_mode = modes[k];
    ScanRun run = scanCan(o);
    HandGeometry hand(wam(), run.q, run.T_O_palm);
    const ObjectModel& m = run.result.model;
    for (size_t i = 0; i < m.mesh.vertices.size(); ++i) {
      Vec3 p = m.mesh.vertices[i].cast<double>();
      if (m.observed[i] && canDistance(p) > 0.006 && hand.distance(p) < 0.01) ++farObserved[k];
      if (hand.distance(p) < 0.01 && std::abs(canDistance(p)) < 0.01) {
        ++nearHand[k];
        holesNearHand[k] += !m.observed[i];
      }
    }
  }
  EXPECT_GT(farObserved[0], 500) << "naive fusion should put the hand's surface on the model";
  // Measured: about 23.5 k against 2.2 k (stray edge pixels along the arm remain).
  EXPECT_LT(farObserved[1], farObserved[0] / 5) << "hand-aware fusion leaves hand-shaped surface";
  // Of the model's surface near the hand (within 1 cm of both hand and can: under the fingers and
  // the can's measured surface beside them), hand-aware fusion leaves more than half uncertain
  // (measured: 60 %); naive fusion has put the fingers' measured surface there (18 %).
  const double uncertain[2] = {double(holesNearHand[0]) / std::max(1, nearHand[0]),
                               double(holesNearHand[1]) / std::max(1, nearHand[1])};
  EXPECT_GT(uncertain[1], 0.5) << "the surface under the hand should stay uncertain";
  EXPECT_GT(uncertain[1], 2 * uncertain[0]) << holesNearHand[0] << " of " << nearHand[0];
}

TEST(Scan, EndsOnItsOwnAndIsDeterministic) {
  ScanOptions o = testOptions();
  o.max_views = 25;
  ScanRun a = scanCan(o, 7), b = scanCan(o, 7);
  EXPECT_EQ(a.result.termination, Termination::kNoViewAboveThreshold);
  ASSERT_EQ(a.result.views.size(), b.result.views.size());
  for (size_t i = 0; i < a.result.views.size(); ++i) {
    EXPECT_EQ(a.result.views[i].dir_O, b.result.views[i].dir_O) << i;
    EXPECT_EQ(a.result.views[i].quality, b.result.views[i].quality) << i;
  }
  // Entropy falls from the first view to the last, and the chosen views met t_q.
  const auto& v = a.result.views;
  ASSERT_GE(v.size(), 5u);
  EXPECT_LT(v.back().mean_entropy, v.front().mean_entropy);
  for (const ViewRecord& r : v)
    if (!r.initial) {
      EXPECT_GE(r.quality, r.t_q);  // the threshold in force (relative rule: scaled by the area)
      EXPECT_EQ(r.gain, r.quality);
    }
  EXPECT_GT(a.result.model.observedAreaFraction(), 0.6);
}

// The cracker box on the table in the kinematic simulator (every 10th frame delivered), and the
// options of a one-grasp scan of it from there, its first view only, without the hold test (its
// trials in physics take seconds, and they reorder the candidates).
struct BoxOnTable {
  TriangleMesh box = loadObject("builtin:cracker_box");
  SimWorld world;
  ScanOptions o = testOptions();
  MultiGraspOptions multi;
  static SimOptions everyTenthFrame(SimOptions so) {
    so.frame_subsample = 10;
    return so;
  }
  explicit BoxOnTable(const SimOptions& so)
      : world(wam(), box, defaultGrasp(wam(), box).first, DepthCameraOptions{}, NoiseModelOptions{},
              everyTenthFrame(so)) {
    world.held = false;
    world.q = wam().home();
    o.initial_views = 1;
    o.max_views = 0;
    multi.max_grasps = 1;
    multi.grasp.approaches = 32;
    multi.grasp.hold.enabled = false;
  }
};

// The box scanned from the table by `robot` and `sensor`, with the scan's log.
struct LoggedScan {
  MultiGraspResult result;
  std::string log;
};
LoggedScan scanLogged(RobotInterface& robot, DepthSensor& sensor, BoxOnTable& b) {
  LoggedScan out;
  ScanProgress progress;
  progress.log = [&](const std::string& line) { out.log += line + "\n"; };
  out.result =
      scanFromTable(robot, sensor, b.world.restPose(), b.o, b.multi, NoiseModelOptions{}, progress);
  return out;
}

// Grasps that must hold, checked against the simulator's own record: with almost no friction
// (μ = 0.1) most grasps of the cracker box let it fall at the lift. The scan decides from the
// fingers and a depth frame only; the attempts it calls "dropped" are exactly the drops the
// simulator made, and when it goes on the box is in the hand.
TEST(Scan, DropsSeenInTheDepthFramesAreTheSimulatorsDrops) {
  SimOptions so;
  so.friction = 0.1;
  BoxOnTable b(so);
  SimWorld& world = b.world;
  SimRobot robot(&world);
  SimSensor sensor(&world, DepthCameraOptions{});
  // Without the hold test: with μ 0.5 assumed it would put the good ones first.
  const MultiGraspResult r =
      scanFromTable(robot, sensor, world.restPose(), b.o, b.multi, NoiseModelOptions{});
  ASSERT_TRUE(r.table_top);
  const std::vector<PickAttempt>& attempts = r.table_top->attempts;
  ASSERT_FALSE(attempts.empty());
  const int dropped = countOutcome(attempts, PickOutcome::kDropped);
  EXPECT_GT(dropped, 0) << "with μ = 0.1 some grasp should fail";
  EXPECT_EQ(dropped, world.drops);
  // Each attempt records when it was decided (in order) and on what: a drop on the lift's frame,
  // which bore out at most half of the object's points in the hand or more than half where it
  // rested.
  double before = 0;
  for (const PickAttempt& a : attempts) {
    EXPECT_FALSE(a.evidence.empty());
    EXPECT_GE(a.at_s, before);
    before = a.at_s;
    if (a.outcome == PickOutcome::kDropped) {
      EXPECT_TRUE(a.lift_in_hand <= 0.5 || a.lift_on_table > 0.5)
          << a.lift_in_hand << " " << a.lift_on_table;
      EXPECT_EQ(a.evidence.rfind("after the lift", 0), 0u) << a.evidence;
    }
  }
  // … and they survive the record's JSON.
  const std::vector<PickAttempt> back = attemptsFrom(attemptsJson(attempts));
  ASSERT_EQ(back.size(), attempts.size());
  for (size_t k = 0; k < back.size(); ++k) {
    EXPECT_EQ(back[k].evidence, attempts[k].evidence);
    EXPECT_NEAR(back[k].at_s, attempts[k].at_s, 1e-9);
    EXPECT_NEAR(back[k].lift_on_table, attempts[k].lift_on_table, 1e-9);
  }
  if (attempts.back().outcome == PickOutcome::kPicked) {
    EXPECT_TRUE(world.held);
    EXPECT_EQ(r.grasps.size(), 1u);
  } else {
    EXPECT_EQ(r.scan.termination, Termination::kPickUpFailed);
    EXPECT_FALSE(world.held);
  }
}

// A camera that sees nothing above the table (no return there, as where the arm hides the hand
// nearer than the sensor's range) in its first `hidden` frames taken while the object is held.
class HandHiddenSensor : public SimSensor {
 public:
  HandHiddenSensor(SimWorld* w, int hidden)
      : SimSensor(w, DepthCameraOptions{}), w_(w), left_(hidden) {}
  DepthImage capture() override {
    DepthImage d = SimSensor::capture();
    if (!w_->held || left_ <= 0) return d;
    --left_;
    const CameraIntrinsics& K = camera().intrinsics;
    for (int v = 0; v < d.height; ++v)
      for (int u = 0; u < d.width; ++u) {
        float& z = d.depth_m[size_t(v) * size_t(d.width) + size_t(u)];
        if (z > 0 && (w_->T_B_C * (double(z) * K.rayZ1(u, v))).z() > wam().table().topZ() + 0.02)
          z = 0;
      }
    return d;
  }

 private:
  SimWorld* w_;
  int left_;
};

// The lift's frame shows nothing of the hand or the object (tracking refuses it), and where the
// box rested the camera sees the table through it: the box, which the fingers did not close on
// nothing for, is held out of the camera's sight. The pick-up counts as made, and the grasp's
// first frames in the hand confirm it by registration. With almost no friction (μ = 0.1) and
// every frame of the held box hidden so, the first pick-up lets the box fall back where it rested
// (the frame shows it there: a drop, the simulator's) and a later one holds it out of sight: the
// drops taken are the simulator's, and the scan goes on holding the box exactly when the
// simulator does, by the rule.
TEST(Scan, AnObjectHeldOutOfTheCamerasSightIsTakenAsHeldWhereItRestedNoLonger) {
  BoxOnTable b{SimOptions{}};
  b.o.tracking.enabled = true;
  b.o.tracking.in_hand = true;
  SimRobot robot(&b.world);
  HandHiddenSensor sensor(&b.world, 1);
  const auto [r, log] = scanLogged(robot, sensor, b);
  ASSERT_TRUE(r.table_top);
  ASSERT_EQ(r.grasps.size(), 1u) << log;
  EXPECT_EQ(r.table_top->attempts.back().outcome, PickOutcome::kPicked);
  EXPECT_EQ(countOutcome(r.table_top->attempts, PickOutcome::kDropped), b.world.drops) << log;
  EXPECT_NE(log.find("held out of the camera's sight"), std::string::npos) << log;
  EXPECT_NE(log.find("the grasp confirmed by registration"), std::string::npos) << log;
  EXPECT_TRUE(b.world.held);

  SimOptions slippery;
  slippery.friction = 0.1;
  BoxOnTable s(slippery);
  SimRobot robot2(&s.world);
  HandHiddenSensor hidden(&s.world, 1000);  // every held frame
  const MultiGraspResult r2 =
      scanFromTable(robot2, hidden, s.world.restPose(), s.o, s.multi, NoiseModelOptions{});
  ASSERT_TRUE(r2.table_top);
  const std::vector<PickAttempt>& attempts = r2.table_top->attempts;
  EXPECT_GT(s.world.drops, 0);
  EXPECT_EQ(countOutcome(attempts, PickOutcome::kDropped), s.world.drops);
  EXPECT_EQ(attempts.back().outcome == PickOutcome::kPicked, s.world.held);
  if (attempts.back().outcome == PickOutcome::kPicked) {
    EXPECT_NE(attempts.back().evidence.find("held out of the camera's sight"), std::string::npos)
        << attempts.back().evidence;
  }
}

// The first `slides` pick-ups slide out of the hand: while it holds still after the lift the
// object moves `by` in the hand (the kinematic simulator's grasp moved).
class SlidingRobot : public SimRobot {
 public:
  SlidingRobot(SimWorld* w, int slides, const Vec3& by)
      : SimRobot(w), w_(w), slides_(slides), by_(by) {}
  void holdStill(double seconds) override {
    SimRobot::holdStill(seconds);
    if (heldStill++ < slides_ && w_->held) w_->T_O_palm.translation() += by_;
  }
  int heldStill = 0;

 private:
  SimWorld* w_;
  int slides_;
  Vec3 by_;
};

struct SlideRun {
  std::vector<PickAttempt> attempts;
  int heldStill = 0;
  size_t grasps = 0;
};
SlideRun pickUpThatSlides(int slides, const Vec3& by) {
  BoxOnTable b{SimOptions{}};
  SlidingRobot robot(&b.world, slides, by);
  SimSensor sensor(&b.world, DepthCameraOptions{});
  b.multi.grasp.max_failed_pick_ups = 6;
  b.multi.grasp.settle_s = GraspOptions::kSettleSeconds;
  const MultiGraspResult r =
      scanFromTable(robot, sensor, b.world.restPose(), b.o, b.multi, NoiseModelOptions{});
  SlideRun out;
  if (r.table_top) out.attempts = r.table_top->attempts;
  out.heldStill = robot.heldStill;
  out.grasps = r.grasps.size();
  return out;
}

// After the lift the hand holds still and a second frame looks again (GraspOptions::settle_s):
// an object that moved 2 cm in the hand meanwhile (88 % of its pixels at another depth) is
// sliding out of a grasp that does not hold; the attempt is recorded as slid, the object put down
// and found again, and the next candidate picks it up. One that moved 2 mm (within the depth
// tolerance: no pixel changed) and one that did not move are held.
TEST(Scan, AnObjectThatSlidesAfterTheLiftIsPutDownAndTheNextCandidateTried) {
  // Those the lift's frame shows in the hand: the first slides, the next is picked.
  auto pastTheLift = [](const SlideRun& r) {
    std::vector<PickOutcome> out;
    for (const PickAttempt& a : r.attempts)
      if (a.outcome == PickOutcome::kSlid || a.outcome == PickOutcome::kPicked)
        out.push_back(a.outcome);
    return out;
  };
  const SlideRun slid = pickUpThatSlides(1, Vec3(0.02, 0.0, 0.0));
  EXPECT_EQ(pastTheLift(slid),
            (std::vector<PickOutcome>{PickOutcome::kSlid, PickOutcome::kPicked}));
  EXPECT_EQ(slid.heldStill, 2);
  EXPECT_EQ(slid.grasps, 1u);

  const SlideRun crept = pickUpThatSlides(1, Vec3(0.0, 0.002, 0.0));
  EXPECT_EQ(pastTheLift(crept), std::vector<PickOutcome>{PickOutcome::kPicked});
  const SlideRun still = pickUpThatSlides(0, Vec3::Zero());
  EXPECT_EQ(pastTheLift(still), std::vector<PickOutcome>{PickOutcome::kPicked});
}

// A put-down object that rolls away: after the first put-down the object comes to rest 35 cm
// along the table from where the hand set it down (farther than the search radius about where it
// was believed to lie and beneath the hand). The scan looks over the rest of the table, finds it
// there and picks it up again: every re-grasp pick-up reaches it (none meets nothing).
class RollingRobot : public SimRobot {
 public:
  RollingRobot(SimWorld* w, const Vec3& by) : SimRobot(w), w_(w), by_(by) {}
  bool putDown() override {
    const bool ok = SimRobot::putDown();
    if (putDowns++ == 0) w_->tablePose.translation() += by_;
    return ok;
  }
  int putDowns = 0;

 private:
  SimWorld* w_;
  Vec3 by_;
};

TEST(Scan, AnObjectThatRolledAwayAfterThePutDownIsFoundOnTheRestOfTheTable) {
  BoxOnTable b{SimOptions{}};
  RollingRobot robot(&b.world, Vec3(0, 0.35, 0));
  SimSensor sensor(&b.world, DepthCameraOptions{});
  b.multi.max_grasps = 2;
  b.multi.grasp.max_failed_pick_ups = 6;
  const auto [r, log] = scanLogged(robot, sensor, b);
  ASSERT_EQ(r.grasps.size(), 2u) << log;
  EXPECT_NE(log.find("looking over the rest of the table"), std::string::npos) << log;
  ASSERT_EQ(r.refind_residuals_m.size(), 1u);
  EXPECT_LT(r.refind_residuals_m[0], 0.003);
  EXPECT_EQ(countOutcome(r.grasps[1].attempts, PickOutcome::kNoContact), 0) << log;
  EXPECT_EQ(countOutcome(r.failed_regrasp_attempts, PickOutcome::kNoContact), 0) << log;
}

// A one-grasp scan reports every frame it did not fuse: a quarter of the frames dropped by the
// sensor reach ScanResult (scanSingleGrasp once left these counts at 0), and the counts add up.
TEST(Scan, SingleGraspScanReportsTheFramesItRejected) {
  ScanOptions o = testOptions();
  o.max_views = 1;
  SimFaults f;
  f.dropped_frames = 0.25;
  const ScanRun run = scanCan(o, 1, f);
  const ScanResult& r = run.result;
  EXPECT_GT(r.frames_dropped, 0);
  EXPECT_GT(r.frames, 0);
  int inViews = 0;
  for (const ViewRecord& v : r.views) inViews += v.frames;
  EXPECT_LE(inViews, r.frames);
}
