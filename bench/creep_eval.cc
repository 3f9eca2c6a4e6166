// How far a held object creeps in the hand, in MuJoCo: an object resting on the table (a mesh
// file or builtin:NAME, in its N-th most probable stable pose), the first of its grasp candidates
// (on its true mesh, ranked by the hold test) that lifts it; the palm then held still for 5 s,
// then turned 60° each way about its x, y and z axes (TURN_S seconds a turn, 1.5 by default).
// Prints the object's pose in the palm's frame after each second and each turn against its pose
// after the lift (mm, degrees), and the physics computation time.
// Usage: creep_eval OBJECT [REST_POSE] [NOSLIP_ITERATIONS] [TURN_S] [TIMESTEP_S
// CONTACT_TIMECONST_S] (the simulator's defaults where not given: PhysicsOptions)
#include <cstdio>
#include <cstdlib>

#include "bench_world.h"
#include "inhand/core/clock.h"
#include "inhand/geometry/builtin_objects.h"
#include "inhand/grasp/grasp.h"
#include "inhand/physics/physics.h"
#include "inhand/sim/sim_world.h"

using namespace inhand;

int main(int argc, char** argv) {
  if (argc < 2) {
    std::fprintf(stderr,
                 "usage: creep_eval OBJECT [REST_POSE] [NOSLIP_ITERATIONS] [TURN_S] "
                 "[TIMESTEP_S CONTACT_TIMECONST_S]\n");
    return 2;
  }
  try {
    const RobotModel m = bench::wamBarrettHand();
    const TriangleMesh object = loadObject(argv[1]);
    const int pose = argc > 2 ? std::atoi(argv[2]) : 0;
    SimOptions so = bench::restingWithPhysics(object, pose);
    if (argc > 3) so.physics.noslip_iterations = std::atoi(argv[3]);
    if (argc > 6) {
      so.physics.timestep_s = std::atof(argv[5]);
      so.physics.contact_timeconst_s = std::atof(argv[6]);
      so.physics.table_contact_timeconst_s = so.physics.contact_timeconst_s;
    }
    SimWorld world(m, object, Iso3::Identity(), DepthCameraOptions{}, NoiseModelOptions{}, so);
    world.held = false;
    SimRobot robot(&world);
    const Iso3 T_B_O = world.restPose();
    const GraspGeneration gen =
        bench::rankedOnTrueMesh(m, object, T_B_O, HoldTestOptions().max_candidates);
    const Json start = world.state();
    PhysicsWorld& P = *world.physics();
    for (size_t k = 0; k < gen.candidates.size() && k < 12; ++k) {
      const GraspCandidate& c = gen.candidates[k];
      world.setState(start);
      if (!robot.pickUp(c.T_O_palm, c.q_open)) continue;
      robot.execute({robot.joints(), m.withArm(robot.joints(), m.arm(c.q_lift))},
                    [](const JointVector&) {});
      P.settle(0.3);
      if (!world.held) continue;
      const double w0 = P.wall_s();
      const Iso3 palm0 = P.palmPose();
      const Iso3 grip = palm0.inverse() * P.objectPose();
      std::printf("candidate %zu lifted; mass %.3f kg\n", k + 1, P.mass_kg());
      for (int k = 0; k < 5; ++k) {
        P.settle(0.0);
        P.movePalm(palm0, 1.0);  // held still
        const Iso3 now = P.palmPose().inverse() * P.objectPose();
        std::printf(
            "  still %d s: %.2f mm %.2f deg\n", k + 1,
            1000 * (now.translation() - grip.translation()).norm(),
            Eigen::AngleAxisd(grip.linear().transpose() * now.linear()).angle() * 180 / M_PI);
      }
      const double turnS = argc > 4 ? std::atof(argv[4]) : 1.5;
      const char* axes = "xyz";
      double worst = 0;
      for (int a = 0; a < 3; ++a)
        for (int sgn : {1, -1, 0}) {
          Iso3 T = palm0;
          T.linear() =
              palm0.linear() * Eigen::AngleAxisd(sgn * M_PI / 3, Vec3::Unit(a)).toRotationMatrix();
          P.movePalm(T, turnS);
          P.settle(0.3);
          const Iso3 now = P.palmPose().inverse() * P.objectPose();
          const double mm = 1000 * (now.translation() - grip.translation()).norm();
          const double deg =
              Eigen::AngleAxisd(grip.linear().transpose() * now.linear()).angle() * 180 / M_PI;
          worst = std::max(worst, mm);
          std::printf("  turn %c %+d: %.2f mm %.2f deg%s\n", axes[a], sgn, mm, deg,
                      P.objectTouchesHand() ? "" : " (not in the hand)");
        }
      std::printf("worst %.2f mm; physics computation %.2f s for at most %.1f s simulated\n", worst,
                  P.wall_s() - w0, 5 + 9 * (turnS + 0.3));
      return 0;
    }
    std::printf("no candidate lifted it\n");
  } catch (const std::exception& e) {
    std::fprintf(stderr, "creep_eval: %s\n", e.what());
    return 1;
  }
}
