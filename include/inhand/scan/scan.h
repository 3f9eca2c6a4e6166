#pragma once
// The autonomous scan against the robot and sensor interfaces (nothing here sees simulator state):
// the object is held at a known grasp; a simple initial trajectory, then Alg. 1 view after view
// until no view reaches t_q or a view limit; every depth frame along every trajectory is fused
// with the pose the robot reports (T_O_C = T_O_palm · T_palm_B(q) · T_B_C), hand-aware (§IV).
#include "inhand/scan/session.h"

namespace inhand {

// Scans with the object held at T_O_palm (palm pose in the object frame); the robot must be
// holding it already: a ScanSession around centre_O (the object's expected centre) driven by
// runGraspViews. `object_box_O`: where the object is believed to lie before any model exists (the
// initial trajectory keeps the arm clear of it); empty: a 10 cm cube around centre_O.
ScanResult scanSingleGrasp(RobotInterface& robot, DepthSensor& sensor, const Iso3& T_O_palm,
                           const Vec3& centre_O, const ScanOptions& options,
                           const NoiseModelOptions& noise, const ScanProgress& progress = {},
                           const Aabb& object_box_O = Aabb());

}  // namespace inhand
