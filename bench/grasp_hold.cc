// Which grasp candidates hold in physics: an object resting on the table (a mesh file or
// builtin:NAME, in its N-th most probable stable pose), the first-grasp candidates generated on
// its true mesh, each picked up and lifted in MuJoCo from the same start. Prints one CSV row per
// candidate (rank by the generator's order, ε, links in contact, palm contact, approach, hold
// margin, outcome) and the hold rate per rank.
// Usage: grasp_hold OBJECT [REST_POSE] [CANDIDATES] [MASS_KG]
#include <cstdio>
#include <cstdlib>

#include "bench_world.h"
#include "inhand/geometry/builtin_objects.h"
#include "inhand/grasp/grasp.h"
#include "inhand/physics/physics.h"
#include "inhand/robot/collision.h"
#include "inhand/sim/sim_world.h"

using namespace inhand;

int main(int argc, char** argv) {
  if (argc < 2) {
    std::fprintf(stderr, "usage: grasp_hold OBJECT [REST_POSE] [CANDIDATES] [MASS_KG]\n");
    return 2;
  }
  try {
    const RobotModel m = bench::wamBarrettHand();
    const TriangleMesh object = loadObject(argv[1]);
    const int pose = argc > 2 ? std::atoi(argv[2]) : 0;
    const int n = argc > 3 ? std::atoi(argv[3]) : 12;
    SimOptions so = bench::restingWithPhysics(object, pose);
    if (argc > 4) so.physics.mass_kg = std::atof(argv[4]);
    SimWorld world(m, object, Iso3::Identity(), DepthCameraOptions{}, NoiseModelOptions{}, so);
    world.held = false;
    SimRobot robot(&world);
    const Iso3 T_B_O = world.restPose();
    double predS = 0;
    const GraspGeneration gen = bench::rankedOnTrueMesh(m, object, T_B_O, n, &predS);
    std::printf("hold test on the true mesh: %.2f s\n", predS);
    const Json start = world.state();
    std::printf("mass_kg %.3f candidates %zu\n", world.physics()->mass_kg(), gen.candidates.size());
    std::printf("rank,predicted,why,epsilon,links,palm,approach_up,outcome,rise_mm,slip_mm\n");
    int held = 0, tried = 0, predHeld[2] = {0, 0}, predN[2] = {0, 0};
    for (int k = 0; k < n && k < int(gen.candidates.size()); ++k) {
      const GraspCandidate& c = gen.candidates[size_t(k)];
      world.setState(start);
      const Iso3 before = world.physics()->objectPose();
      const std::optional<Iso3> got = robot.pickUp(c.T_O_palm, c.q_open);
      std::string outcome = "no_contact";
      double rise = 0, slip = 0;
      const HandContacts hc = handContacts(m, c.q, c.T_O_palm, world.objectSamples(), 0.003, 0.01);
      const bool palm = hc.palm_touching;
      if (got) {
        const Iso3 grip = world.T_O_palm;
        robot.execute({robot.joints(), m.withArm(robot.joints(), m.arm(c.q_lift))},
                      [](const JointVector&) {});
        world.physics()->settle(0.3);
        rise = 1000 * (world.physics()->objectPose().translation().z() - before.translation().z());
        slip = 1000 * (world.T_O_palm.translation() - grip.translation()).norm();
        outcome = world.held && rise > 50 ? (slip > 5 ? "slipped" : "held") : "dropped";
      }
      ++tried;
      held += outcome == "held" || outcome == "slipped";
      predHeld[c.hold == 1] += outcome == "held" || outcome == "slipped";
      predN[c.hold == 1] += 1;
      const double up = -(T_B_O.linear() * c.T_O_palm.linear().col(2)).z();
      std::printf("%d,%d,%s,%.4f,%d,%d,%.2f,%s,%.0f,%.1f\n", k + 1, c.hold,
                  holdFailureName(c.hold_failure), c.epsilon, c.links_in_contact, int(palm), up,
                  outcome.c_str(), rise, slip);
    }
    std::printf("held %d of %d; predicted to hold: %d of %d held; predicted not: %d of %d held\n",
                held, tried, predHeld[1], predN[1], predHeld[0], predN[0]);
  } catch (const std::exception& e) {
    std::fprintf(stderr, "grasp_hold: %s\n", e.what());
    return 1;
  }
}
