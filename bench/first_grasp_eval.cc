// Which first-grasp candidates hold the true object: the scan's own table-top stage (frames,
// the model they give, candidates, the planner's hold test on that model) in the simulator with
// physics, an object resting in its N-th most probable stable pose; each candidate the scan would
// try, in its order, picked up from the same start in MuJoCo, lifted 10 cm and turned a quarter
// turn (as the views turn it; each motion 1 s with the simulated arm's speed ramps), then the
// world put back as it was. The hold test's trial of each on the true object, where the guarded
// move put the palm, is printed beside it (with the hold test's physics and the simulator's).
// Prints one row per candidate (rank, the hold test's verdict, ε, outcome, how far it moved in the
// hand, where it failed the hold test, whether a pinch pose, the trials on the true mesh, whether
// it held the hold test's margin) and the hold rates by verdict. With `regrasp` last, the same for
// the second grasp's candidates: the first grasp is picked up, scanned and put down as in a scan,
// and the re-grasp's candidates are tried on the object where it then rests. Usage:
// [SEED=N] first_grasp_eval OBJECT [REST_POSE] [CANDIDATES] [CONFIG.json] [regrasp]
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <string>

#include "bench_world.h"
#include "inhand/config/scan_config.h"
#include "inhand/core/error.h"
#include "inhand/geometry/builtin_objects.h"
#include "inhand/grasp/hold_test.h"
#include "inhand/physics/physics.h"
#include "inhand/scan/multi_grasp.h"
#include "inhand/sim/sim_world.h"

using namespace inhand;

namespace {
// Tries each pick-up on the simulated world and puts the world back: the scan sees every
// candidate fail to reach the object (no_contact) and goes on to the next.
class ProbeRobot : public RobotInterface {
 public:
  ProbeRobot(SimWorld* w, const ScanConfig& c) : world_(w), robot_(w), config_(c) {}
  const RobotModel& model() const override { return robot_.model(); }
  JointVector joints() const override { return robot_.joints(); }
  void execute(const std::vector<JointVector>& w,
               const std::function<void(const JointVector&)>& f) override {
    ++motions_;
    robot_.execute(w, f);
  }
  // A put-down after more motions than the lift ends a grasp that was scanned (a pick-up that
  // failed is put down after the lift alone).
  bool putDown() override {
    if (motions_ > 1) ++grasps_scanned;
    return robot_.putDown();
  }
  std::optional<Iso3> pickUp(const Iso3& T_O_palm, const JointVector& q) override {
    motions_ = 0;
    if (grasps_scanned < probe_after_grasps) return robot_.pickUp(T_O_palm, q);
    const Json start = world_->state();
    outcomes.push_back(tryOne(T_O_palm, q));
    world_->setState(start);
    return std::nullopt;
  }
  struct Outcome {
    std::string what;  // held, dropped_in_lift, dropped_in_turn, slipped, no_contact
    double moved_mm = 0;
    // The hold test's trial on the true object (where the guarded move put the palm, closing to
    // where physics closed the fingers): with the hold test's physics, and with the simulator's.
    std::string true_trial = "-", true_trial_sim = "-";
    // … and with the palm where the plan put it on the object as it truly lies (the plan's pose
    // of the object exact, no guarded move).
    std::string true_trial_planned = "-";
  };
  std::vector<Outcome> outcomes;
  int grasps_scanned = 0;
  int probe_after_grasps = 0;  // pick-ups before this many grasps were scanned are real

 private:
  Outcome tryOne(const Iso3& T_O_palm, const JointVector& q) {
    Outcome o;
    // The true mesh as the hold test sees a model (its pieces above the table), resting where it
    // lies; a pick-up does not move world_->tablePose.
    const RobotModel& m = world_->model();
    const HoldTestOptions& ho = config_.multi.grasp.hold;
    const Iso3 T_B_O = world_->tablePose;
    PhysicsWorld trial(
        m, modelPiecesAboveTable(world_->objectMesh(), T_B_O, m, nullptr, ho.decomposition),
        config_.multi.grasp.friction, holdTrialPhysics(ho));
    auto verdict = [](const HoldTrial& t) { return t.held ? "held" : holdFailureName(t.failure); };
    o.true_trial_planned = verdict(tryHold(trial, T_B_O, T_O_palm, q, q, ho));
    if (!robot_.pickUp(T_O_palm, q)) {
      o.what = "no_contact";
      return o;
    }
    PhysicsWorld& ph = *world_->physics();
    {
      const Iso3 T_O_palmNow = T_B_O.inverse() * ph.palmPose();
      o.true_trial = verdict(tryHold(trial, T_B_O, T_O_palmNow, q, world_->q, ho));
      PhysicsWorld trialSim(m, world_->objectMesh(), config_.sim.friction, config_.sim.physics);
      o.true_trial_sim = verdict(tryHold(trialSim, T_B_O, T_O_palmNow, q, world_->q, ho));
    }
    const Iso3 grip = ph.palmPose().inverse() * ph.objectPose();
    auto moved = [&] {
      return 1000 * ((ph.palmPose().inverse() * ph.objectPose()).translation() - grip.translation())
                        .norm();
    };
    // The lift and the turn as the simulated arm moves (SimRobot::execute): each over 1 s plus
    // the speed ramps at both ends (PhysicsOptions::ramp_s), the palm placed at every frame time.
    const double ramp = config_.sim.physics.ramp_s, total = 1.0 + ramp;
    const double dt = 1.0 / config_.sim.frame_rate_hz;
    const int steps = std::max(1, int(std::ceil(total / dt)));
    auto along = [&](int k) {
      return k >= steps ? 1.0 : rampedFraction(total * k / steps, 1.0, ramp);
    };
    const Iso3 start = ph.palmPose();
    Iso3 up = start;
    up.translation().z() += 0.10;
    for (int k = 1; k <= steps; ++k) {
      Iso3 T = start;
      T.translation().z() += 0.10 * along(k);
      ph.movePalm(T, total / steps);
    }
    if (!ph.objectTouchesHand()) {
      o.what = "dropped_in_lift";
      o.moved_mm = moved();
      return o;
    }
    // The turn's axis as the hold test's trial takes it.
    const Vec3 axis = holdTurnAxis(ph.palmPose());
    const Vec3 pivot = ph.objectPose().translation();
    for (int k = 1; k <= steps; ++k) {
      const Mat3 R = Eigen::AngleAxisd(along(k) * M_PI / 2, axis).toRotationMatrix();
      Iso3 T = up;
      T.linear() = R * up.linear();
      T.translation() = pivot + R * (up.translation() - pivot);
      ph.movePalm(T, total / steps);
    }
    ph.movePalm(ph.palmPose(), 0.3);
    o.moved_mm = moved();
    o.what = !ph.objectTouchesHand() ? "dropped_in_turn" : o.moved_mm > 10 ? "slipped" : "held";
    return o;
  }
  SimWorld* world_;
  SimRobot robot_;
  int motions_ = 0;  // since the last pick-up
  ScanConfig config_;
};
}  // namespace

int main(int argc, char** argv) {
  if (argc < 2) {
    std::fprintf(stderr,
                 "usage: first_grasp_eval OBJECT [REST_POSE] [CANDIDATES] [CONFIG] [regrasp]\n");
    return 2;
  }
  try {
    const RobotModel m = bench::wamBarrettHand();
    const TriangleMesh object = loadObject(argv[1]);
    const int pose = argc > 2 ? std::atoi(argv[2]) : 0;
    const int n = argc > 3 ? std::atoi(argv[3]) : 24;
    ScanConfig c;
    if (argc > 4 && std::string(argv[4]) != "-") readScanConfigFile(argv[4], &c);
    const bool regrasp = argc > 5 && std::string(argv[5]) == "regrasp";
    // SEED: the noise and IK seed, as `inhand scan --seed` (1 by default).
    if (const char* seed = std::getenv("SEED")) {
      c.sim.seed = std::strtoull(seed, nullptr, 10);
      c.scan.planner.seed = c.sim.seed;
    }
    c.sim = bench::restingWithPhysics(object, pose, c.sim);
    c.multi.grasp.max_failed_pick_ups = n;
    c.multi.max_grasps = regrasp ? 2 : 1;
    const DepthCameraOptions camera;
    const NoiseModelOptions noise;
    auto [T_O_palm, q] = defaultGrasp(m, object);
    SimWorld world(m, object, T_O_palm, camera, noise, c.sim);
    world.held = false;
    world.q = m.home();
    ProbeRobot robot(&world, c);
    robot.probe_after_grasps = regrasp ? 1 : 0;
    SimSensor sensor(&world, camera);
    const MultiGraspResult r =
        scanFromTable(robot, sensor, world.restPose(), c.scan, c.multi, noise, ScanProgress{});
    if (!r.table_top) throw Error("no table-top stage");
    if (regrasp && r.grasps.empty()) throw Error("the first grasp was not picked up");
    const std::vector<PickAttempt>& a = regrasp ? r.failed_regrasp_attempts : r.table_top->attempts;
    std::printf(
        "rank,hold_test,epsilon,kind,outcome,moved_mm,hold_failure,pinch,two_finger,true_trial,"
        "true_trial_sim,true_trial_planned,margin,close_mm\n");
    int held[2] = {0, 0}, tested[2] = {0, 0};
    // Every attempt recorded is a probe (each ends no_contact); a re-grasp's poses are not kept.
    for (size_t k = 0; k < a.size() && k < robot.outcomes.size(); ++k) {
      const auto& o = robot.outcomes[k];
      const bool pinch = a[k].pinch;
      const bool two =
          !regrasp && a[k].pose >= 0 && r.table_top->poses[size_t(a[k].pose)].two_finger;
      std::printf("%d,%d,%.3f,%s,%s,%.1f,%s,%d,%d,%s,%s,%s,%d,%.1f\n", a[k].rank, a[k].hold_test,
                  a[k].epsilon, a[k].palm_contact ? "enveloping" : "fingertips", o.what.c_str(),
                  o.moved_mm, holdFailureName(a[k].hold_failure), int(pinch), int(two),
                  o.true_trial.c_str(), o.true_trial_sim.c_str(), o.true_trial_planned.c_str(),
                  a[k].hold_margin, 1000 * a[k].hold_close_m);
      const int v = a[k].hold_test == 1;
      held[v] += o.what == "held";
      ++tested[v];
    }
    std::printf("%s pose %d: first %s; hold test yes: %d of %d held; no: %d of %d held\n", argv[1],
                pose, robot.outcomes.empty() ? "none" : robot.outcomes[0].what.c_str(), held[1],
                tested[1], held[0], tested[0]);
  } catch (const std::exception& e) {
    std::fprintf(stderr, "first_grasp_eval: %s\n", e.what());
    return 1;
  }
}
