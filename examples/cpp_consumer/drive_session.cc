// Drives a ScanSession from one's own loop through an installed inhand. The simulator stands in
// for the robot and the depth camera; with a real robot, replace the SimRobot/SimSensor calls by
// the driver's (or implement RobotInterface and DepthSensor and call runGraspViews).
//   drive_session ROBOT_CONFIG.json [OUT_DIR]
#include <inhand/inhand.h>

#include <cstdio>
#include <filesystem>

int main(int argc, char** argv) {
  using namespace inhand;
  if (argc < 2) {
    std::fprintf(stderr, "usage: drive_session ROBOT_CONFIG.json [OUT_DIR]\n");
    return 2;
  }
  const std::filesystem::path out = argc > 2 ? argv[2] : "session_out";
  try {
    const RobotModel robot = RobotModel::load(argv[1]);
    const TriangleMesh object = loadObject("builtin:coffee_can");
    // The simulator: the robot holding the can at its default grasp.
    const DepthCameraOptions camera;
    const NoiseModelOptions noise;
    SimOptions so;
    so.frame_subsample = 6;
    auto [T_O_palm, q] = defaultGrasp(robot, object);
    SimWorld world(robot, object, T_O_palm, camera, noise, so);
    world.q = q;
    SimRobot arm(&world);
    SimSensor sensor(&world, camera);

    ScanOptions options;  // coarser than the defaults, so that the example runs in seconds
    options.voxel_m = 0.003;
    options.max_views = 3;
    options.planner.directions = 120;
    options.planner.rolls = 4;
    MultiGraspOptions multi;
    multi.grasp.approaches = 32;
    const Vec3 centre = T_O_palm * Vec3(0, 0, robot.graspOffset());
    ScanSession session(robot, camera, noise, options, multi, centre);
    for (int grasp = 0; grasp < 2; ++grasp) {
      session.beginGrasp(T_O_palm, arm.joints());
      sensor.setPose(session.cameraPose());
      // The loop: move where the session says, hand it every frame on the way.
      while (const std::optional<PlannedView> view = session.nextView(arm.joints())) {
        arm.execute(view->waypoints, [&](const JointVector& qNow) {
          session.addFrame(sensor.capture(), qNow, sensor.pose());
        });
        const ViewRecord& r = session.finishView();
        std::printf("  view %zu: %s, quality %.4f, %d frames, mean entropy %.3f\n",
                    session.views().size(), r.initial ? "initial" : "Alg. 1", r.quality, r.frames,
                    r.mean_entropy);
      }
      std::printf("grasp %d: views ended with %s\n", grasp + 1,
                  terminationName(session.summary().termination).c_str());
      if (grasp == 1 || !arm.putDown()) break;
      session.endGrasp();
      // The candidates in their order; a pick-up that does not hold is followed by the next.
      // A real robot checks the hold with its own sensing (`inhand scan` compares the depth
      // image with the model); here the simulator knows.
      const GraspPlan plan = session.planGrasps(world.restPose(), arm.joints());
      bool holding = false;
      for (int k = 0; k < plan.above_threshold && !holding; ++k) {
        const GraspCandidate& c = plan.candidates[size_t(k)];
        const std::optional<Iso3> achieved = arm.pickUp(c.T_O_palm, c.q_open);
        if (!achieved) continue;
        arm.execute({arm.joints(), robot.withArm(arm.joints(), robot.arm(c.q_lift))},
                    [](const JointVector&) {});  // lift
        if (!world.held) {
          std::printf("grasp candidate %d did not hold: the next\n", k + 1);
          continue;
        }
        T_O_palm = *achieved;
        holding = true;
      }
      if (!holding) break;
    }
    std::filesystem::create_directories(out);
    session.save(out / "scan.inhand");  // a checkpoint to resume from (ScanSession::load)
    const ObjectModel model = session.model();
    writePly(out / "model.ply", model.mesh, &model.variance);
    std::printf("%s; observed %.1f%% of the surface -> %s\n", session.summary().brief().c_str(),
                100 * model.observedAreaFraction(), (out / "model.ply").c_str());
    if (model.observedAreaFraction() < 0.9) return 1;
  } catch (const Error& e) {
    std::fprintf(stderr, "drive_session: error: %s\n", e.what());
    return 1;
  }
  return 0;
}
