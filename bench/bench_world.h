#pragma once
// What the physics bench programs share: the robot of data/robots/wam_barretthand.json, and the
// simulator's options for an object resting on the table in its N-th most probable stable pose
// with MuJoCo physics on.
#include <filesystem>

#include "inhand/geometry/stable_poses.h"
#include "inhand/grasp/grasp.h"
#include "inhand/grasp/hold_test.h"
#include "inhand/robot/robot_model.h"
#include "inhand/sim/sim_world.h"

namespace inhand::bench {

inline RobotModel wamBarrettHand() {
  return RobotModel::load(std::filesystem::path(INHAND_SOURCE_DIR) /
                          "data/robots/wam_barretthand.json");
}

// `so` with physics on and the object resting in its `pose`-th stable pose.
inline SimOptions restingWithPhysics(const TriangleMesh& object, int pose, SimOptions so = {}) {
  so.physics.enabled = true;
  so.R_B_O_rest = stablePoses(object).at(size_t(pose)).R_B_O;
  return so;
}

// The first-grasp candidates on the object's true mesh, resting at T_B_O, with the arm at home,
// the first `tested` ranked by the hold test (its seconds in *hold_s).
inline GraspGeneration rankedOnTrueMesh(const RobotModel& m, const TriangleMesh& object,
                                        const Iso3& T_B_O, int tested, double* hold_s = nullptr) {
  const GraspOptions go;
  GraspGeneration gen = generateGrasps(m, object, T_B_O, m.home(), go);
  HoldTestOptions ho;
  ho.max_candidates = tested;
  const double s = rankByHold(m, object, T_B_O, nullptr, go.friction, ho, &gen.candidates);
  if (hold_s) *hold_s = s;
  return gen;
}

}  // namespace inhand::bench
